"""`Reader.level`, `__version__`, the exceptions, the type stubs and the README examples.

`level(k)` is checked against the reference reader (``scripts/voxlod_read.py``, written from
docs/FORMAT.md alone): the concatenation of every level-k node it decodes, in index order, each
voxel's position made absolute; the stubs against the runtime with mypy's ``stubtest`` and a
script type-checked with ``mypy --strict``; the README's Python examples are run exactly as
written, after ``voxlod build`` of the bundled sample.

Under ``CI=true`` a missing binary, mesh or mypy is a failure, never a skip.
"""

import importlib.metadata
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_reader import REPO, _bin, _run, _missing, bunny1024, world, ref  # noqa: F401 (fixtures)

import voxlod


def _reference_level(f, k):
    """Level k by the reference reader: every node of that level, concatenated."""
    cols = {"pos": [], "face_mask": [], "normal": [], "color": [], "material": [], "node": []}
    for i, fe in enumerate(f.nodes):
        if int(fe["level"]) != k:
            continue
        d = f.decode(fe)
        chunk = 256 * np.array([fe["x"], fe["y"], fe["z"]], dtype=np.int64)
        cols["pos"].append(d["pos"].astype(np.int64) + chunk)
        cols["face_mask"].append(d["mask"])
        cols["normal"].append(d["normal"].astype(np.float32) / np.float32(511))
        cols["color"].append(d["color"])
        m = f.materials(fe)
        if m is not None:
            cols["material"].append(m)
        cols["node"].append(np.full(len(d["pos"]), i))
    return {k: np.concatenate(v) if v else None for k, v in cols.items()}


@pytest.mark.parametrize("which", ["bunny1024", "world"])
def test_level_is_every_node_of_the_level_concatenated(which, request, ref):
    path = request.getfixturevalue(which)
    r = voxlod.Reader(path)
    f = ref.VoxlodFile(path)
    nodes = r.nodes()
    total = 0
    for k in range(r.levels):
        got = r.level(k)
        want = _reference_level(f, k)
        n = int(nodes["voxels"][nodes["level"] == k].sum())
        assert n > 0
        total += n
        assert got["pos"].dtype == np.uint32 and got["pos"].shape == (n, 3)
        assert np.array_equal(got["pos"], want["pos"])
        # absolute grid units of the level: inside the grid of R / 2^k voxels
        assert int(got["pos"].max()) < r.resolution >> k
        assert got["face_mask"].dtype == np.uint8 and np.array_equal(got["face_mask"], want["face_mask"])
        assert got["normal"].dtype == np.float32 and np.array_equal(got["normal"], want["normal"])
        assert got["color"].dtype == np.uint8 and np.array_equal(got["color"], want["color"])
        assert got["node"].dtype == np.uint32 and np.array_equal(got["node"], want["node"])
        # `node` rows name nodes of this level, and their voxel counts add up
        assert (nodes["level"][got["node"]] == k).all()
        assert np.array_equal(np.bincount(got["node"], minlength=len(nodes))[nodes["level"] == k],
                              nodes["voxels"][nodes["level"] == k])
        if r.has_materials:
            assert got["material"].dtype == np.uint32
            assert np.array_equal(got["material"], want["material"])
        else:
            assert "material" not in got
    assert total == r.total_voxels
    # a voxel's position maps to world units as decode's do
    lv = r.level(0)
    assert np.allclose(r.world(0, lv["pos"][:5]), np.asarray(r.origin) + r.voxel_size * lv["pos"][:5])


def test_a_level_the_file_has_not_is_a_value_error(bunny1024):
    r = voxlod.Reader(bunny1024)
    for k in (-1, -5, r.levels, 99):
        for call in (lambda: r.level(k), lambda: r.decode(k, 0, 0, 0),
                     lambda: r.source_triangles(k, 0, 0, 0)):
            with pytest.raises(ValueError) as e:
                call()
            msg = str(e.value)
            assert str(bunny1024) in msg and f"no level {k}" in msg and "0 (the leaves) to 2" in msg, msg
    # numpy integers are levels too
    assert len(r.level(np.uint32(2))["pos"]) == int(r.nodes()[-1]["voxels"])


def test_a_missing_file_is_file_not_found_and_a_voxlod_error(tmp_path):
    p = tmp_path / "missing.voxlod"
    for catch in (FileNotFoundError, voxlod.VoxlodError, voxlod.VoxlodFileNotFoundError, OSError):
        with pytest.raises(catch) as e:
            voxlod.Reader(p)
        assert str(p) in str(e.value)
    with pytest.raises(FileNotFoundError) as e:
        voxlod.Reader(str(p))
    assert e.value.errno == 2 and e.value.filename == str(p)
    # a directory is not "not found": a VoxlodError that is no FileNotFoundError
    with pytest.raises(voxlod.VoxlodError) as e:
        voxlod.Reader(tmp_path)
    assert not isinstance(e.value, FileNotFoundError)


def test_version_is_the_packages_and_the_command_lines():
    assert re.fullmatch(r"\d+\.\d+\.\d+.*", voxlod.__version__)
    assert voxlod.__version__ == importlib.metadata.version("voxlod")
    cli = subprocess.run([_bin(), "--version"], capture_output=True, text=True, check=True).stdout
    assert cli.split()[-1] == voxlod.__version__, cli


def _python_blocks(readme, heading):
    """The ```python blocks of the section of `readme` under `heading`."""
    text = readme.read_text()
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    section = text[start : end if end > 0 else len(text)]
    return re.findall(r"```python\n(.*?)```", section, re.S)


@pytest.mark.parametrize("readme,heading", [(REPO / "README.md", "\n## Python\n"),
                                            (REPO / "python" / "README.md", "# voxlod for Python")])
def test_readme_example_runs_on_the_bundled_sample(readme, heading, tmp_path):
    blocks = _python_blocks(readme, heading)
    assert blocks, f"{readme}: no python example under {heading.strip()}"
    # `voxlod build` with no input builds the bundled sample into ./bunny.voxlod
    subprocess.run([_bin(), "build", "-q"], cwd=tmp_path, check=True, capture_output=True)
    assert (tmp_path / "bunny.voxlod").is_file()
    for code in blocks:
        o = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
        assert o.returncode == 0, f"{readme}'s example failed:\n{code}\n{o.stderr}"


def _mypy():
    try:
        import mypy  # noqa: F401
    except ImportError:
        _missing("mypy is not installed (pip install mypy): the type stubs are not checked")


def test_type_stubs_match_the_package():
    _mypy()
    # the stubs against the runtime: every name, signature and property
    o = subprocess.run([sys.executable, "-m", "mypy.stubtest", "voxlod"],
                       capture_output=True, text=True)
    assert o.returncode == 0, o.stdout + o.stderr


def test_a_script_type_checks_strictly_against_the_stubs(tmp_path):
    _mypy()
    script = tmp_path / "use.py"
    script.write_text(
        "import numpy as np\n"
        "import numpy.typing as npt\n"
        "import voxlod\n\n"
        "def voxels(path: str) -> int:\n"
        "    r = voxlod.Reader(path)\n"
        "    lv: dict[str, npt.NDArray[np.generic]] = r.level(r.levels - 1)\n"
        "    n: int = r.total_voxels + len(lv['pos'])\n"
        "    s: str = voxlod.__version__\n"
        "    return n + len(s)\n\n"
        "try:\n"
        "    voxels('x.voxlod')\n"
        "except voxlod.VoxlodFileNotFoundError as e:\n"
        "    print(e.filename)\n"
    )
    o = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--no-incremental", str(script)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert o.returncode == 0, o.stdout + o.stderr
    # and a wrong use is caught: the stubs are read, not Any
    script.write_text("import voxlod\nx: str = voxlod.Reader('a').levels\n")
    o = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--no-incremental", str(script)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert o.returncode != 0 and "incompatible types" in o.stdout.lower(), o.stdout
