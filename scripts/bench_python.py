#!/usr/bin/env python3
"""Decoding every node of a voxlod file from Python: the `voxlod` package (the Rust reader,
python/) against scripts/voxlod_read.py (the pure-Python reader of docs/FORMAT.md), three
interleaved rounds, CPU seconds (time.process_time) beside wall seconds. Figures in
docs/BENCHMARKS.md ("Reading from Python").

Usage: python3 scripts/bench_python.py FILE.voxlod   (needs `pip install ./python zstandard`)
"""

import importlib.util
import sys
import time
from pathlib import Path

import voxlod

HERE = Path(__file__).resolve().parent
spec = importlib.util.spec_from_file_location("voxlod_read", HERE / "voxlod_read.py")
reference = importlib.util.module_from_spec(spec)
spec.loader.exec_module(reference)


def package(path):
    r = voxlod.Reader(path)
    return sum(len(r.decode(e["level"], e["x"], e["y"], e["z"])["pos"]) for e in r.nodes())


def pure_python(path):
    f = reference.VoxlodFile(path)
    return sum(len(f.decode(e)["pos"]) for e in f.nodes)


def main():
    path = sys.argv[1]
    runs = {"voxlod package": [], "scripts/voxlod_read.py": []}
    voxels = {}
    for _ in range(3):
        for name, decode in (("voxlod package", package), ("scripts/voxlod_read.py", pure_python)):
            cpu, wall = time.process_time(), time.perf_counter()
            voxels[name] = decode(path)
            runs[name].append((time.process_time() - cpu, time.perf_counter() - wall))
    assert len(set(voxels.values())) == 1, voxels
    n = voxels["voxlod package"]
    for name, r in runs.items():
        cpu = sorted(c for c, _ in r)[1]
        wall = sorted(w for _, w in r)[1]
        each = ", ".join(f"{c:.3f}" for c, _ in r)
        print(f"{name}: {n} voxels; CPU s median {cpu:.3f} ({each}), wall s median {wall:.3f}; "
              f"{n / cpu / 1e6:.1f} M voxels per CPU-s")


if __name__ == "__main__":
    main()
