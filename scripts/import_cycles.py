#!/usr/bin/env python3
"""Finds import circles between the modules of each crate under crates/.

Usage:
    python3 scripts/import_cycles.py [--with-root] [ROOT]
                                     # ROOT: the repository (default: this script's ..)
    python3 scripts/import_cycles.py --self-test

Exit status 0 when no crate has a circle, 1 when one has (each circle is printed with the
file and line of every edge in it), 2 on a usage error.

What the graph is
-----------------
Nodes: the modules of one crate. `src/lib.rs` and `src/main.rs` are each a crate root
(`crate`); `src/a.rs` or `src/a/mod.rs` is `crate::a`, `src/a/b.rs` is `crate::a::b`, found
through the `mod a;` declarations, as rustc finds them. An inline `mod name { ... }` (a test
module, say) is a node of its own, `crate::a::name`.

Edges: module M points to module T when M's code names a path that resolves to T:
  * `use` declarations (any visibility, with `{...}` groups expanded, `*` globs included);
  * paths written in code: `crate::x::f()`, `super::f`, `self::sub::f`, and `sub::f` where
    `sub` is a module declared in M (a relative path down);
  * a path resolves to the deepest module it walks through: `crate::a::b::Item` is
    `crate::a::b` when `b` is a module of `a`, else `crate::a`;
  * a name a module re-exports (`pub use b::Item;` in `a`) is followed to the module that
    defines it, so `use crate::Item` next to `pub use b::Item;` in lib.rs points at
    `crate::b`, not at the root: a re-export is an index, not a dependency;
  * `super::` from a submodule points up to its parent, `self::sub::`/`sub::` from a module
    points down to its submodule; both count, so a parent that calls into a submodule which
    imports something the parent defines is a circle of two.
Not edges: edges into or out of the crate root (lib.rs, main.rs), unless `--with-root` is
given: the root is the crate's index (it declares the modules, re-exports the public API,
and may hold the crate's shared vocabulary types and its entry points, which its modules
use while it calls them); the `mod` declarations themselves (containment is not a dependency), a module
naming itself, paths in comments, doc comments and string literals, a `use` under
`#[cfg(doc)]` (it only resolves doc links), `$crate::` in macros, and paths into other
crates.

A circle is a strongly connected component of two or more modules; for each, one cycle
through all its edges' evidence is printed.
"""

import os
import re
import sys
import tempfile

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


def strip_code(text):
    """The text with comments, string and char literals blanked (newlines kept, so line
    numbers stay right)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:i + 300]) and (
                i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'r(#*)"', text[i:])
            end = text.find('"' + m.group(1), i + len(m.group(0)))
            end = n if end < 0 else end + 1 + len(m.group(1))
            out.append(re.sub(r"[^\n]", " ", text[i:end]))
            i = end
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(re.sub(r"[^\n]", " ", text[i:j + 1]))
            i = j + 1
        elif c == "'":
            m = re.match(r"'(\\(x[0-9a-fA-F]{2}|u\{[0-9a-fA-F]+\}|.)|[^\\'\n])'", text[i:])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:  # a lifetime
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


class Module:
    def __init__(self, path, file, parent):
        self.path = path  # tuple of names below the crate root
        self.file = file
        self.parent = parent
        self.children = {}  # name -> Module
        self.refs = []  # (base module, [segments], line, glob, reexport name or None)
        self.defined = set()  # names of items defined here (for re-export resolution)


def module_file(dir_, name, owner_is_dir):
    """The file of `mod name;` declared in a file whose submodules live in `dir_`."""
    for cand in (os.path.join(dir_, name + ".rs"), os.path.join(dir_, name, "mod.rs")):
        if os.path.isfile(cand):
            return cand
    return None


def expand_use(tree):
    """`a::{b, c::{d, e}}` -> [[a, b], [a, c, d], [a, c, e]]; `self` in a group is its
    prefix; `as` renames are kept as (segments, alias)."""
    tree = tree.strip()
    m = re.match(r"^(.*?)::\s*\{(.*)\}$", tree, re.S)
    if m:
        prefix = [s.strip() for s in m.group(1).split("::") if s.strip()]
        inner, parts, depth, cur = m.group(2), [], 0, ""
        for ch in inner:
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        parts.append(cur)
        out = []
        for p in parts:
            if not p.strip():
                continue
            for segs, alias in expand_use(p):
                if segs == ["self"]:
                    out.append((prefix, alias or (prefix[-1] if prefix else None)))
                else:
                    out.append((prefix + segs, alias))
        return out
    if tree.startswith("{") and tree.endswith("}"):
        return expand_use("::" + tree)
    alias = None
    m = re.match(r"^(.*?)\s+as\s+(" + IDENT + r")$", tree, re.S)
    if m:
        tree, alias = m.group(1), m.group(2)
    segs = [s.strip() for s in tree.split("::") if s.strip()]
    return [(segs, alias)]


ITEM_RE = re.compile(
    r"\b(?:fn|struct|enum|trait|type|const|static|union|macro_rules!)\s+(" + IDENT + ")")
USE_RE = re.compile(r"\b(pub(?:\s*\([^)]*\))?\s+)?use\s+([^;]+);")
PATH_RE = re.compile(r"(?<![A-Za-z0-9_$:])((?:" + IDENT + r")(?:\s*::\s*" + IDENT + r")+)")
MOD_DECL_RE = re.compile(r"\bmod\s+(" + IDENT + r")\s*;")
MOD_INLINE_RE = re.compile(r"\bmod\s+(" + IDENT + r")\s*\{")


def line_of(text, pos):
    return text.count("\n", 0, pos) + 1


def parse_file(crate, file, module, dir_):
    """Reads `file` as `module` (submodule files in `dir_`), adding inline modules and
    declared file modules to the crate."""
    with open(file, encoding="utf-8") as f:
        text = strip_code(f.read())
    # Inline modules: spans by brace depth.
    spans = []  # (start, end, name, depth)
    stack, depth = [], 0
    inline_at = {m.end() - 1: m.group(1) for m in MOD_INLINE_RE.finditer(text)}
    for i, ch in enumerate(text):
        if ch == "{":
            depth += 1
            if i in inline_at:
                stack.append((i, inline_at[i], depth))
        elif ch == "}":
            if stack and stack[-1][2] == depth:
                s, name, d = stack.pop()
                spans.append((s, i, name, len(stack)))
            depth -= 1
    spans.sort()

    def owner(pos):
        """The module at text position `pos`."""
        chain = [sp for sp in spans if sp[0] < pos < sp[1]]
        m = module
        for sp in sorted(chain, key=lambda sp: sp[3]):
            m = m.children[sp[2]]
        return m

    # Create inline module nodes (outer first).
    for sp in sorted(spans, key=lambda sp: sp[3]):
        par = owner(sp[0])
        child = Module(par.path + (sp[2],), file, par)
        par.children[sp[2]] = child
    # File modules.
    for m in MOD_DECL_RE.finditer(text):
        par = owner(m.start())
        if par is not module:
            continue  # `mod x;` inside an inline module: not used in this workspace
        name = m.group(1)
        sub = module_file(dir_, name, True)
        if sub is None:
            continue
        child = Module(module.path + (name,), sub, module)
        module.children[name] = child
        crate.append(child)
        parse_file(crate, sub, child, os.path.join(dir_, name))
    for m in ITEM_RE.finditer(text):
        owner(m.start()).defined.add(m.group(1))
    used = []
    for m in USE_RE.finditer(text):
        used.append((m.start(), m.end()))
        if re.search(r"#\[cfg\(doc\)\]\s*$", text[:m.start()]):
            continue
        own = owner(m.start())
        for segs, alias in expand_use(m.group(2)):
            if not segs:
                continue
            name = alias or (segs[-1] if segs[-1] not in ("*", "self") else None)
            reexport = name if m.group(1) else None
            own.refs.append((segs, line_of(text, m.start()), reexport))
    for m in PATH_RE.finditer(text):
        if any(a <= m.start() < b for a, b in used):
            continue
        segs = [s.strip() for s in m.group(1).split("::")]
        own = owner(m.start())
        own.refs.append((segs, line_of(text, m.start()), None))


def build_crate(src):
    """All modules of the crate(s) rooted in `src` (lib.rs and main.rs are separate roots)."""
    roots = []
    for root_name in ("lib.rs", "main.rs"):
        f = os.path.join(src, root_name)
        if os.path.isfile(f):
            root = Module((), f, None)
            mods = [root]
            parse_file(mods, f, root, src)
            for mod in list(mods):
                mods.extend(all_inline(mod, mods))
            roots.append((root_name, root, mods))
    return roots


def all_inline(mod, known):
    out = []
    for c in mod.children.values():
        if c not in known and c not in out:
            out.append(c)
            out.extend(all_inline(c, known + out))
    return out


def resolve(root, mod, segs, seen=None):
    """The module `segs` (a path written in `mod`) resolves to, or None when it leaves the
    crate. Returns (module, rest of the path)."""
    if segs[0] == "crate":
        cur, rest = root, segs[1:]
    elif segs[0] == "self":
        cur, rest = mod, segs[1:]
    elif segs[0] == "super":
        cur, rest = mod, segs
        while rest and rest[0] == "super":
            if cur.parent is None:
                return None
            cur, rest = cur.parent, rest[1:]
        if rest and rest[0] == "self":
            rest = rest[1:]
    elif segs[0] in mod.children:
        cur, rest = mod.children[segs[0]], segs[1:]
    else:
        return None
    while rest and rest[0] in cur.children:
        cur, rest = cur.children[rest[0]], rest[1:]
    # A name `cur` re-exports (and does not define): follow it to its origin.
    if rest and rest[0] not in cur.defined:
        seen = seen or set()
        key = (cur.path, rest[0])
        if key not in seen:
            seen.add(key)
            for segs2, _line, reexport in cur.refs:
                if reexport == rest[0]:
                    r = resolve(root, cur, segs2, seen)
                    if r is not None:
                        return r[0], r[1] + rest[1:]
    return cur, rest


def edges_of(root, mods, with_root=False):
    """{(from path, to path): [line evidence]}."""
    edges = {}
    for mod in mods:
        for segs, line, _ in mod.refs:
            r = resolve(root, mod, segs)
            if r is None:
                continue
            target = r[0]
            if target is mod or (not with_root and root in (mod, target)):
                continue
            edges.setdefault((mod.path, target.path), []).append(
                "%s:%d" % (mod.file, line))
    return edges


def sccs(nodes, succ):
    """Tarjan's strongly connected components (iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for v in nodes:
        if v in index:
            continue
        work = [(v, iter(succ.get(v, ())))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(succ.get(nxt, ()))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == node:
                            break
                    out.append(comp)
    return out


def a_cycle(comp, succ):
    """One cycle inside the component `comp`, as a list of nodes (first repeated last)."""
    comp = set(comp)
    start = min(comp)
    # breadth-first from start's successors back to start
    prev, frontier = {}, [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(succ.get(v, ())):
                if w not in comp:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return [start] + list(reversed(path[:-1])) + [start] if len(path) > 1 \
                        else [start, v, start] if v != start else [start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    return [start]


def name(path):
    return "crate" + "".join("::" + p for p in path)


def check_crate(crate_dir, rel=None, with_root=False, base=None):
    """The circles of one crate, as printable lines (empty when there is none)."""
    lines = []
    for root_name, root, mods in build_crate(os.path.join(crate_dir, "src")):
        edges = edges_of(root, mods, with_root)
        succ = {}
        for (a, b) in edges:
            succ.setdefault(a, set()).add(b)
        for comp in sccs([m.path for m in mods], succ):
            if len(comp) < 2:
                continue
            cyc = a_cycle(comp, succ)
            lines.append("%s (%s): circle of %d modules: %s" % (
                rel or crate_dir, root_name, len(comp),
                ", ".join(sorted(name(p) for p in comp))))
            for a, b in zip(cyc, cyc[1:]):
                ev = [os.path.relpath(e, base) if base else e for e in edges[(a, b)]]
                lines.append("    %s -> %s  (%s%s)" % (
                    name(a), name(b), ev[0], ", +%d more" % (len(ev) - 1) if len(ev) > 1 else ""))
    return lines


def main(repo, with_root=False):
    crates = os.path.join(repo, "crates")
    if not os.path.isdir(crates):
        print("import_cycles: no crates/ folder in %s" % repo, file=sys.stderr)
        return 2
    bad = 0
    for c in sorted(os.listdir(crates)):
        d = os.path.join(crates, c)
        if not os.path.isdir(os.path.join(d, "src")):
            continue
        lines = check_crate(d, os.path.join("crates", c), with_root, repo)
        if lines:
            bad += 1
            print("\n".join(lines))
        else:
            print("crates/%s: no import circle" % c)
    if bad:
        print("import_cycles: %d crate(s) with import circles" % bad, file=sys.stderr)
        return 1
    return 0


def write_tree(base, files):
    for rel, text in files.items():
        p = os.path.join(base, rel)
        os.makedirs(os.path.dirname(p), exist_ok=True)
        with open(p, "w", encoding="utf-8") as f:
            f.write(text)


def self_test():
    """Made-up crates: each must give the stated answer, or the test fails."""
    cases = {
        # a.rs uses b, b.rs uses a through crate:: -> a circle of two
        "circle": ({
            "src/lib.rs": "mod a;\nmod b;\n",
            "src/a.rs": "use crate::b::Thing;\npub struct Other;\n",
            "src/b.rs": "pub struct Thing;\nfn f() -> crate::a::Other { todo!() }\n",
        }, 1),
        # a parent calling into its submodule which imports the parent's type via super
        "parent-child": ({
            "src/lib.rs": "mod s;\n",
            "src/s/mod.rs": "mod k;\npub struct Ctx;\npub fn run() { k::go(); }\n",
            "src/s/k.rs": "use super::Ctx;\npub fn go() {}\n",
        }, 1),
        # down-only imports, a test module using super::*, a re-export used via the root,
        # paths in comments and strings, a lifetime and a char literal: no circle
        "clean": ({
            "src/lib.rs": "mod a;\nmod b;\npub use b::Thing;\n"
                          "/// see crate::a::f and crate::b\npub fn g<'x>(s: &'x str) -> char {"
                          " a::f(); let _ = \"crate::a::f\"; '{' }\n",
            "src/a.rs": "use crate::Thing;\npub fn f() {}\n"
                        "#[cfg(test)]\nmod tests {\n    use super::*;\n    #[test]\n"
                        "    fn t() { f(); let _ = crate::b::Thing; }\n}\n",
            "src/b.rs": "// crate::a is named here only in a comment\npub struct Thing;\n"
                        "#[cfg(doc)]\nuse crate::a::f;\n",
        }, 0),
        # a circle of three through a `use` group
        "three": ({
            "src/lib.rs": "mod x;\nmod y;\nmod z;\n",
            "src/x.rs": "use crate::{y::Y, z};\npub struct X;\n",
            "src/y.rs": "pub struct Y;\n",
            "src/z.rs": "pub struct Z;\npub fn f(_: crate::x::X) {}\n",
        }, 1),
    }
    # the root defines a type a module uses while calling into it: found only with_root
    root_case = {
        "src/lib.rs": "mod m;\npub struct Shared;\npub fn go() { m::f(); }\n",
        "src/m.rs": "use crate::Shared;\npub fn f() {}\n",
    }
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        d = os.path.join(tmp, "root")
        write_tree(d, root_case)
        for wr, want in ((False, 0), (True, 1)):
            got = sum(1 for l in check_crate(d, "root", wr) if "circle of" in l)
            print("self-test %-12s want %d circle(s), got %d: %s" % (
                "root" + (" --with-root" if wr else ""), want, got,
                "ok" if got == want else "FAILED"))
            failed += got != want
        for label, (files, want) in cases.items():
            d = os.path.join(tmp, label)
            write_tree(d, files)
            lines = check_crate(d, label)
            got = sum(1 for l in lines if "circle of" in l)
            status = "ok" if got == want else "FAILED"
            failed += got != want
            print("self-test %-12s want %d circle(s), got %d: %s" % (label, want, got, status))
            for l in lines:
                print("    " + l)
        # the whole-repository entry point reports a circle with a non-zero exit
        write_tree(os.path.join(tmp, "repo", "crates", "c"), cases["circle"][0])
        write_tree(os.path.join(tmp, "repo", "crates", "d"), cases["clean"][0])
        rc = main(os.path.join(tmp, "repo"))
        print("self-test main on a repo with one circle: exit %d: %s" % (rc, "ok" if rc == 1 else "FAILED"))
        failed += rc != 1
    return 1 if failed else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    if args == ["--self-test"]:
        sys.exit(self_test())
    with_root = "--with-root" in args
    args = [a for a in args if a != "--with-root"]
    if len(args) > 1 or (args and args[0].startswith("-")):
        print(__doc__.strip().split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    repo = args[0] if args else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    sys.exit(main(os.path.normpath(repo), with_root))
