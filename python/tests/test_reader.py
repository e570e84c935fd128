"""The `voxlod` Python package against independent references.

Files are built by the `voxlod` command line (``VOXLOD_BIN``, else the newest of
``target/{release,debug}/voxlod``) from the Stanford bunny of ``../shared/data/meshes`` and from
a made-up OBJ world with three materials. Every node the package decodes is compared with
``scripts/voxlod_read.py``, the pure-Python reader written from docs/FORMAT.md alone (so a
mistake in the Rust reader or in the bindings shows as a difference), and the index, the
header and the verify report with ``voxlod inspect --json`` and ``voxlod verify --json``.

Under ``CI=true`` a missing package, binary or shared mesh is a failure, never a skip.
"""

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
UNDER_CI = os.environ.get("CI") == "true"  # as voxlod_testkit::under_ci


def _missing(what):
    """Fails under CI, skips elsewhere."""
    if UNDER_CI:
        pytest.fail(f"CI=true but {what}", pytrace=False)
    pytest.skip(what)


try:
    import voxlod
except ImportError as e:  # pragma: no cover - the CI path fails here
    if UNDER_CI:
        raise ImportError(f"CI=true but the voxlod package is not installed (pip install ./python): {e}")
    pytest.skip(f"the voxlod package is not installed (pip install ./python): {e}", allow_module_level=True)


def _reference():
    """scripts/voxlod_read.py as a module."""
    spec = importlib.util.spec_from_file_location("voxlod_read", REPO / "scripts" / "voxlod_read.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _bin():
    env = os.environ.get("VOXLOD_BIN")
    if env:
        return env
    found = [p for p in (REPO / "target/release/voxlod", REPO / "target/debug/voxlod") if p.is_file()]
    if not found:
        _missing("no voxlod binary: set VOXLOD_BIN or build one (cargo build --release)")
    return str(max(found, key=lambda p: p.stat().st_mtime))


def _run(*args, check=True):
    o = subprocess.run([_bin(), *map(str, args)], capture_output=True, text=True, env={**os.environ, "NO_COLOR": "1"})
    if check and o.returncode != 0:
        raise AssertionError(f"voxlod {' '.join(map(str, args))} failed:\n{o.stderr}")
    return o


def _shared(rel):
    p = REPO.parent / "shared" / "data" / "meshes" / rel
    if not p.is_file():
        _missing(f"{p} is missing (the shared test meshes)")
    return p


@pytest.fixture(scope="module")
def ref():
    try:
        return _reference()
    except ImportError as e:
        _missing(f"scripts/voxlod_read.py needs numpy and zstandard: {e}")


@pytest.fixture(scope="module")
def bunny256(tmp_path_factory):
    """The bunny at 256³ (one chunk: the root is the leaf) with its source triangles."""
    out = tmp_path_factory.mktemp("b256") / "bunny.voxlod"
    _run("build", _shared("stanford-bunny/bun_zipper.ply"), "-o", out, "-r", 256, "--source-geometry")
    return out


@pytest.fixture(scope="module")
def bunny1024(tmp_path_factory):
    """The bunny at 1024³: three levels, dozens of leaves."""
    out = tmp_path_factory.mktemp("b1024") / "bunny.voxlod"
    _run("build", _shared("stanford-bunny/bun_zipper.ply"), "-o", out, "-r", 1024, "--source-geometry")
    return out


NAMES = ["stone", "grass", "dirt"]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A 4 × 4 floor of unit cubes, cube (x, z) of material NAMES[(x + 2z) % 3]."""
    d = tmp_path_factory.mktemp("world")
    (d / "w.mtl").write_text("".join(f"newmtl {n}\nKd 0.{i + 3} 0.5 0.5\n" for i, n in enumerate(NAMES)))
    lines, nv = ["mtllib w.mtl"], 0
    for z in range(4):
        for x in range(4):
            lines.append(f"usemtl {NAMES[(x + 2 * z) % 3]}")
            lines += [f"v {x + (c & 1)} {c >> 1 & 1} {z + (c >> 2 & 1)}" for c in range(8)]
            for f in ([0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]):
                lines.append("f " + " ".join(str(nv + c + 1) for c in f))
            nv += 8
    (d / "w.obj").write_text("\n".join(lines) + "\n")
    out = d / "w.voxlod"
    _run("build", d / "w.obj", "-o", out, "-r", 512)
    return out


def _compare_every_node(path, ref):
    """Every node of `path`: the package's decode against voxlod_read.py's, field by field."""
    r = voxlod.Reader(path)
    f = ref.VoxlodFile(path)
    nodes = r.nodes()
    assert len(nodes) == len(f.nodes) > 0
    for k in ("level", "x", "y", "z", "child_mask", "payload_offset", "payload_size"):
        assert np.array_equal(nodes[k], f.nodes[k]), k
    assert np.array_equal(nodes["voxels"], f.nodes["voxel_count"])
    assert np.array_equal(nodes["bounds_min"], f.nodes["bounds_min"][:, :3])
    assert np.array_equal(nodes["bounds_max"], f.nodes["bounds_max"][:, :3])
    voxels = 0
    for e, fe in zip(nodes, f.nodes):
        got = r.decode(e["level"], e["x"], e["y"], e["z"])
        want = f.decode(fe)
        n = int(e["voxels"])
        chunk = 256 * np.array([e["x"], e["y"], e["z"]], dtype=np.uint32)
        assert got["pos"].shape == (n, 3) and got["pos"].dtype == np.uint32
        assert np.array_equal(got["pos"], want["pos"].astype(np.uint32) + chunk)
        assert got["face_mask"].dtype == np.uint8 and np.array_equal(got["face_mask"], want["mask"])
        assert got["normal"].dtype == np.float32 and got["normal"].shape == (n, 3)
        assert np.array_equal(got["normal"], want["normal"].astype(np.float32) / np.float32(511))
        assert got["color"].dtype == np.uint8 and np.array_equal(got["color"], want["color"])
        mats = f.materials(fe)
        if mats is None:
            assert "material" not in got
        else:
            assert np.array_equal(got["material"], mats)
        voxels += n
    assert voxels == r.total_voxels == f.header["total_voxels"]
    return r, f


def test_header_and_index_match_inspect(bunny1024):
    r = voxlod.Reader(bunny1024)
    info = json.loads(_run("inspect", bunny1024, "--json").stdout)
    assert (r.resolution, r.levels, r.mode) == (info["resolution"], info["levels"], info["mode"])
    assert list(r.origin) == info["origin"] and r.voxel_size == info["voxel_size"]
    assert (r.total_voxels, r.format_version) == (info["voxels"], info["format_version"])
    assert r.manifest == info["manifest"]
    nodes = r.nodes()
    assert len(nodes) == info["nodes"] and r.levels == 3
    for lv in info["per_level"]:
        at = nodes[nodes["level"] == lv["level"]]
        assert len(at) == lv["nodes"] and int(at["voxels"].sum()) == lv["voxels"]
    # the root is last and covers the grid
    assert tuple(nodes[-1][["level", "x", "y", "z"]].tolist()) == (2, 0, 0, 0)
    assert r.has_source_triangles and not r.has_materials and r.materials is None


def test_every_node_of_bunny_256_matches_the_reference(bunny256, ref):
    r, _ = _compare_every_node(bunny256, ref)
    assert r.levels == 1 and len(r.nodes()) == 1


def test_every_node_of_bunny_1024_matches_the_reference(bunny1024, ref):
    _compare_every_node(bunny1024, ref)


def test_materials_match_the_reference(world, ref):
    r, f = _compare_every_node(world, ref)
    assert r.has_materials and r.materials[1:] == NAMES and r.materials == f.manifest["materials"]
    leaves = r.nodes()[r.nodes()["level"] == 0]
    e = leaves[0]
    v = r.decode(e["level"], e["x"], e["y"], e["z"])
    assert v["material"].dtype == np.uint32 and set(v["material"].tolist()) <= {1, 2, 3}


def test_source_triangles_match_the_reference(bunny1024, ref):
    r = voxlod.Reader(bunny1024)
    f = ref.VoxlodFile(bunny1024)
    triangles = 0
    for e, fe in zip(r.nodes(), f.nodes):
        got = r.source_triangles(e["level"], e["x"], e["y"], e["z"])
        want = f.source(fe)
        if want is None:
            assert got is None
            continue
        assert e["level"] == 0
        chunk = 256.0 * np.array([e["x"], e["y"], e["z"]], dtype=np.float64)
        assert np.array_equal(got["positions"], want["positions"] + chunk)
        assert np.array_equal(got["triangles"], want["triangles"])
        assert len(got["triangles"]) == e["source_triangles"]
        for k in ("normals", "colors", "materials"):
            assert (got[k] is None) == (want[k] is None), k
        if want["normals"] is not None:
            assert np.allclose(got["normals"], want["normals"], atol=1e-6)
        if want["colors"] is not None:
            assert np.array_equal(got["colors"], want["colors"])
        triangles += len(got["triangles"])
    assert triangles > 0
    # the bunny's triangles (69451) are each stored in every leaf they touch: at least once
    assert triangles >= 69451


def test_world_coordinates(bunny1024):
    r = voxlod.Reader(bunny1024)
    root = r.nodes()[-1]
    v = r.decode(root["level"], 0, 0, 0)
    w = r.world(root["level"], v["pos"])
    edge = r.voxel_size * 4
    assert np.allclose(w, np.asarray(r.origin) + edge * v["pos"])
    # the voxels' corners lie inside the grid's cube
    assert (w >= np.asarray(r.origin) - 1e-12).all()
    assert (w < np.asarray(r.origin) + r.voxel_size * r.resolution).all()


def test_verify_matches_the_command_line(bunny1024, world):
    for path in (bunny1024, world):
        got = voxlod.Reader(path).verify()
        want = json.loads(_run("verify", path, "--json").stdout)
        assert got["ok"] and got["problems"] == []
        for k in ("nodes", "nodes_decoded", "voxels", "parents_checked", "leaf_voxels_checked",
                  "materials_checked", "source_triangles_checked"):
            assert got[k] == want[k], k
        assert got["parents_checked"] > 0


def test_errors_are_exceptions_with_the_rust_message(bunny1024, tmp_path):
    bad = tmp_path / "bad.voxlod"
    shutil.copy(bunny1024, bad)
    r0 = voxlod.Reader(bad)
    e = r0.nodes()[0]
    # one byte inside the first payload: the file opens, that node fails its checksum
    with open(bad, "r+b") as fh:
        fh.seek(int(e["payload_offset"]) + int(e["payload_size"]) // 2)
        b = fh.read(1)
        fh.seek(-1, 1)
        fh.write(bytes([b[0] ^ 0x55]))
    r = voxlod.Reader(bad)
    with pytest.raises(voxlod.VoxlodError) as err:
        r.decode(e["level"], e["x"], e["y"], e["z"])
    cli = _run("verify", bad, check=False)
    assert cli.returncode != 0
    msg = str(err.value)
    assert str(bad) in msg and "checksum mismatch" in msg, msg
    # the same words as `voxlod verify` (which names the node by its index number)
    assert msg.split("): ", 1)[1] in cli.stdout, (msg, cli.stdout)
    report = r.verify()
    assert not report["ok"] and any("checksum" in p for p in report["problems"])
    # a node the file does not have
    with pytest.raises(KeyError, match="no node at level 0"):
        r.decode(0, 99, 0, 0)
    # not a voxlod file; a missing file; a directory
    text = tmp_path / "not.voxlod"
    text.write_text("hello, this is not an octree\n" * 10)
    with pytest.raises(voxlod.VoxlodError, match="not a voxlod file"):
        voxlod.Reader(text)
    with pytest.raises(voxlod.VoxlodError, match="missing.voxlod"):
        voxlod.Reader(tmp_path / "missing.voxlod")
    with pytest.raises(voxlod.VoxlodError):
        voxlod.Reader(tmp_path)


def test_docstrings():
    for f in (voxlod.Reader, voxlod.Reader.nodes, voxlod.Reader.decode, voxlod.Reader.source_triangles,
              voxlod.Reader.verify, voxlod.Reader.world, voxlod):
        assert f.__doc__ and len(f.__doc__) > 40, f


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
