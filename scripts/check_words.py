#!/usr/bin/env python3
"""Refuses the words of a lab notebook in code and reference docs.

Usage:
    python3 scripts/check_words.py [ROOT]      # ROOT: the repository (default: this script's ..)
    python3 scripts/check_words.py --self-test

Exit status 0 when nothing is found, 1 when something is (each hit printed as
`path:line: rule: text`), 2 on a usage error.

Why
---
Code comments and reference docs say what is and why. The story of how it got there (which
issue asked for it, which commit or branch tried what, what a figure was before, what was
measured on which day) belongs in commit messages and in `docs/journal/`, where it cannot go
stale in place. This check keeps it out of:

    crates/  tests/  scripts/  .ci/  docs/ (except docs/journal/)  README.md  CONTRIBUTING.md
    python/ (its sources and docs)

(text files only: .rs .md .py .sh .toml .wgsl .js .cpp .yml .yaml .json, and scripts
without an extension; `target/`, `node_modules/` and this script itself are skipped).

The rules
---------
  issue     "issue 12", "issues 3 and 4", "Issue #12", "(#12)": an issue number.
  commit    a word of 7 to 40 hex digits, with at least one digit and one letter, that is
            a commit of this repository (`git cat-file`, abbreviations included), or any such
            word right after "commit", "main at", "commits" or "branch at". Checksums and test
            vectors are not commits, so they pass: a 64-digit SHA-256, a `0x…` literal, a
            CRC that no commit starts with.
  today     "today" (and "today's"), "yesterday", "this morning", "this afternoon".
  branch    "this branch", "branch `NAME`", "branch NAME" where NAME has a digit or a
            slash (`s30`, `try/fused-probe`), and "try/NAME" anywhere.
  date      an ISO date 2000-01-01 … 2099-12-31 (a notebook's day).
  was       "(was 71)", ", was 71": an old figure beside the new one.

A line that must keep such words (a test of this very rule, a quoted third-party name) ends
with the marker `check-words: allow`.
"""

import os
import re
import subprocess
import sys
import tempfile

ALLOW = "check-words: allow"
SCOPE_DIRS = ["crates", "tests", "scripts", ".ci", "docs", "python"]
SCOPE_FILES = ["README.md", "CONTRIBUTING.md"]
SKIP_DIRS = {"target", "node_modules", ".git", "__pycache__", "journal", ".venv"}
TEXT_EXT = {".rs", ".md", ".py", ".sh", ".toml", ".wgsl", ".js", ".mjs", ".cpp", ".h",
            ".yml", ".yaml", ".json", ".txt", ".pyi"}

RULES = [
    ("issue", re.compile(r"\bissues?\s+#?\d+|\(#\d+\)", re.I)),
    ("today", re.compile(r"\btoday\b|\byesterday\b|\bthis (?:morning|afternoon|evening)\b",
                         re.I)),
    ("branch", re.compile(
        r"\bthis branch\b"
        r"|\bbranch(?:es)?\s+(?:`[^`\s]+`|[A-Za-z]*\d[\w./-]*|[\w.-]+/[\w./-]+)"
        r"|(?<![\w/.-])try/[\w.-]+", re.I)),
    ("date", re.compile(r"\b20\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b")),
    ("was", re.compile(r"[(,;]\s*was\s+\d")),
]
HEX = re.compile(r"(?<![\w./#-])([0-9a-fA-F]{7,40})(?![\w-])")
COMMIT_PHRASE = re.compile(
    r"\b(?:commits?|main at|branch at)\s+`?([0-9a-fA-F]{7,40})\b", re.I)


def files_in_scope(root):
    """Every text file the rules apply to, as paths relative to root."""
    out = []
    me = os.path.abspath(__file__)
    for name in SCOPE_FILES:
        if os.path.isfile(os.path.join(root, name)):
            out.append(name)
    for top in SCOPE_DIRS:
        base = os.path.join(root, top)
        for dirpath, dirnames, filenames in os.walk(base):
            rel_dir = os.path.relpath(dirpath, root)
            dirnames[:] = sorted(d for d in dirnames
                                 if d not in SKIP_DIRS or (d == "journal" and top != "docs"))
            for f in sorted(filenames):
                path = os.path.join(dirpath, f)
                if os.path.abspath(path) == me:
                    continue
                ext = os.path.splitext(f)[1]
                if ext in TEXT_EXT or (ext == "" and top == "scripts" and is_text(path)):
                    out.append(os.path.join(rel_dir, f))
    return out


def is_text(path):
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return b"\0" not in head


def hex_words(text):
    """Candidate commit abbreviations: 7–40 hex digits with a digit and a letter."""
    for m in HEX.finditer(text):
        w = m.group(1)
        if re.search(r"\d", w) and re.search(r"[a-fA-F]", w):
            yield m


def commits_of(root, words):
    """The subset of `words` that name a commit of the repository at root (empty when git or
    the history is not there)."""
    words = sorted(set(w.lower() for w in words))
    if not words:
        return set()
    try:
        p = subprocess.run(["git", "-C", root, "cat-file", "--batch-check"],
                           input="".join(w + "^{commit}\n" for w in words),
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return set()
    if p.returncode != 0:
        return set()
    found = set()
    for w, line in zip(words, p.stdout.splitlines()):
        parts = line.split()
        # "<sha> commit <size>" when it resolves; "<name> ambiguous" when the abbreviation
        # names several objects (a commit prefix at this length is no accident either).
        if (len(parts) == 3 and parts[1] == "commit") or line.endswith(" ambiguous"):
            found.add(w)
    return found


def scan(root, paths, read=None):
    """Hits as (path, line number, rule, line text)."""
    read = read or (lambda p: open(os.path.join(root, p), encoding="utf-8",
                                   errors="replace").read())
    texts = {p: read(p) for p in paths}
    words = [m.group(1) for t in texts.values() for m in hex_words(t)]
    commits = commits_of(root, words)
    hits = []
    for p in paths:
        for n, line in enumerate(texts[p].splitlines(), 1):
            if ALLOW in line:
                continue
            for rule, rx in RULES:
                if rx.search(line):
                    hits.append((p, n, rule, line.strip()))
            flagged = {m.group(1).lower() for m in COMMIT_PHRASE.finditer(line)}
            flagged |= {m.group(1).lower() for m in hex_words(line)
                        if m.group(1).lower() in commits}
            if flagged:
                hits.append((p, n, "commit", line.strip()))
    return hits


def self_test():
    """The rules on made-up lines: what must be refused and what must pass."""
    bad = [
        "// see iss" "ue 30 §1 for the design",
        "/// (Iss" "ue #12) the reader",
        "docs say (#4" "4) here",
        "# measured to" "day on the EPYC",
        "// to" "day's figures",
        "built by this bra" "nch's release build",
        "(bra" "nch `s30`, merged)",
        "bra" "nch i30 bins face indices",
        "the probe (tr" "y/fused-probe) used one decode",
        "measured 202" "6-12-04 at 14:50",
        "24 test executables (wa" "s 71)",
        "main a" "t 0581a13 against d25491b",
        "since comm" "it d25491b the bins",
    ]
    good = [
        "// the branch-free word pass runs in SIMD lanes",
        "// a branch of the octree holds eight children",
        "// the trailer's CRC is 0x1edc6f41 (Castagnoli)",
        "sha256 = 3f79bb7b435b05321651daefd374cdc681dc06faa65e374e38337b88ca046dea",
        "// FNV-1a offset basis cbf29ce484222325",
        "// decade-old meshes and defaced ones",
        "/// 26-separating, per issue of the format, version 3",
        "// the run was cut (a torn tail) and resumed",
        "# try the next part; retry/backoff stays as it is",
        "// the header's date field is not written",
        "let was = 3; // was it set?",
        "// the match arm for ASCII, the other branch for binary",
    ]
    with tempfile.TemporaryDirectory() as d:
        lines = {f"b{i}.rs": line for i, line in enumerate(bad)}
        lines.update({f"g{i}.rs": line for i, line in enumerate(good)})
        # no git history in d: only the phrases find commits, no hex word is a commit.
        hits = scan(d, sorted(lines), read=lambda p: lines[p] + "\n")
    got = {p for p, _, _, _ in hits}
    missed = [lines[p] for p in lines if p.startswith("b") and p not in got]
    wrong = [lines[p] for p in lines if p.startswith("g") and p in got]
    if missed or wrong:
        for line in missed:
            print(f"self-test: not refused: {line}")
        for line in wrong:
            print(f"self-test: refused but legitimate: {line}")
        return 1
    # A hex word that is a commit of this repository is refused without a phrase.
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    p = subprocess.run(["git", "-C", root, "rev-parse", "--short=9", "HEAD"],
                       capture_output=True, text=True)
    if p.returncode == 0 and p.stdout.strip():
        head = p.stdout.strip()
        line = f"// measured against {head} on the dragon"
        hits = scan(root, ["x.rs"], read=lambda _: line + "\n")
        if not any(rule == "commit" for _, _, rule, _ in hits):
            print(f"self-test: a commit of this repository ({head}) was not refused")
            return 1
    print(f"self-test: {len(bad)} refused, {len(good)} passed")
    return 0


def main(argv):
    args = argv[1:]
    if args == ["--self-test"]:
        return self_test()
    if len(args) > 1 or (args and args[0].startswith("-")):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    root = args[0] if args else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    hits = scan(root, files_in_scope(root))
    for path, n, rule, text in hits:
        print(f"{path}:{n}: {rule}: {text[:160]}")
    if hits:
        print(f"{len(hits)} line(s) with a notebook's words: say what and why instead "
              "(the history goes in the commit message or docs/journal/)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
