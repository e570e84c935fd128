#!/usr/bin/env bash
# A sharded build timed step by step on one machine, for what a cluster of one node per shard
# would see (docs/BENCHMARKS.md, "Sharded build"): plan, then every shard one after another, then the
# merge, each under `/usr/bin/time` with the load average before it, the shards' and the
# merge's `--json` summaries kept for their stage times; at the end the merged file's SHA-256
# and size against a one-machine build's (a `sha256sum` line and the size, as in REF), and the
# shard files and the merged file are removed (the timings stay in OUT).
#
#   scripts/bench_shards.sh INPUT OUT SHARDS [build settings for plan ...]
#   BIN=target/release/voxlod REF=/work/big/single.sha256 \
#     scripts/bench_shards.sh /work/big/gen1e9.ply /work/big/p 16 -r 2048 --backend cpu
#
# Environment: BIN (voxlod binary; default target/release/voxlod), J (threads per shard and for
# the merge; default 2), REF (optional: file whose first word is the one-machine build's
# SHA-256 and whose second line is its size), KEEP=1 keeps the shard files and merged file.
# Writes OUT/times.txt: one line per step, `step wall_s user_s sys_s peak_KiB load1 load5`.
set -euo pipefail
[[ $# -ge 3 ]] || { sed -n 2,17p "$0"; exit 2; }
INPUT=$1 OUT=$2 SHARDS=$3
shift 3
BIN=${BIN:-target/release/voxlod}
J=${J:-2}
mkdir -p "$OUT"
TIMES="$OUT/times.txt"
: > "$TIMES"
step() { # step NAME JSON_OUT command...
  local name=$1 json=$2
  shift 2
  local load
  load=$(cut -d' ' -f1,2 /proc/loadavg)
  /usr/bin/time -o "$OUT/$name.time" -f "%e %U %S %M" "$@" > "$json"
  echo "$name $(cat "$OUT/$name.time") $load" | tee -a "$TIMES"
}
echo "start $(date -u +%FT%TZ) $(nproc) cores" | tee -a "$TIMES"
step plan "$OUT/plan.out.json" "$BIN" plan -q "$INPUT" -o "$OUT/plan.json" --shards "$SHARDS" --json "$@"
for ((i = 0; i < SHARDS; i++)); do
  step "shard$i" "$OUT/shard$i.json" "$BIN" build -q --plan "$OUT/plan.json" --shard "$i" -j "$J" --json
  echo "  $(stat -c %s "$OUT/shard-$(printf %04d "$i").vlshard") bytes" | tee -a "$TIMES"
done
step merge "$OUT/merge.json" "$BIN" merge -q "$OUT/plan.json" -o "$OUT/merged.voxlod" -j "$J" --json
sum=$(sha256sum "$OUT/merged.voxlod" | cut -d' ' -f1)
size=$(stat -c %s "$OUT/merged.voxlod")
echo "merged $sum $size" | tee -a "$TIMES"
if [[ -n "${REF:-}" ]]; then
  if [[ "$sum" == "$(head -1 "$REF" | cut -d' ' -f1)" && "$size" == "$(sed -n 2p "$REF")" ]]; then
    echo "identical to the one-machine build ($REF)" | tee -a "$TIMES"
  else
    echo "DIFFERS from the one-machine build ($REF)" | tee -a "$TIMES"
    exit 1
  fi
fi
if [[ "${KEEP:-0}" != 1 ]]; then
  rm -f "$OUT"/shard-*.vlshard "$OUT/merged.voxlod"
fi
echo "end $(date -u +%FT%TZ)" | tee -a "$TIMES"
