#!/usr/bin/env bash
# A sharded build timed task by task on one machine, for what a cluster of one node per task
# would see (docs/BENCHMARKS.md, "The sharded chain"): the plan, every map task, every shard, the
# merge, one after another, each under `/usr/bin/time` with the load average before it and the
# bytes it read from the input; the tasks' `--json` summaries kept; at the end the merged
# file's SHA-256 and size against a one-machine build's (a `sha256sum` line and the size, as in
# REF).
#
#   scripts/bench_shards.sh INPUT OUT N [build settings for plan ...]
#   BIN=target/release/voxlod REF=/work/big/single.sha256 \
#     scripts/bench_shards.sh /work/big/gen1e8nc.ply /work/big/p 16 -r 2048 --backend cpu
#
# Environment: BIN (voxlod binary; default target/release/voxlod), J (threads per task; default
# 2), PARTS (parts of the plan, one map task each; default N; 0 or a binary without `map`: no
# map phase, every shard reads the input), REF (optional: file whose first word is the
# one-machine build's SHA-256 and whose second line is its size), KEEP=1 keeps the map
# outputs, shard files and OUT/merged.voxlod (otherwise removed; the timings stay in OUT).
#
# Writes OUT/times.txt: one line per task, `step wall_s user_s sys_s peak_KiB load1 load5
# input_read_bytes`, the step named by its phase and index (`plan`, `map3`, `shard3`, `merge`).
# input_read_bytes: the input is dropped from the page cache before each task
# (posix_fadvise DONTNEED) and its resident bytes counted after it (`fincore`), so each task
# reads what it touches from the disk and the count is what it read (the readahead included);
# nothing else may read INPUT meanwhile.
set -euo pipefail
[[ $# -ge 3 ]] || { sed -n 2,25p "$0"; exit 2; }
INPUT=$1 OUT=$2 SHARDS=$3
shift 3
BIN=${BIN:-target/release/voxlod}
J=${J:-2}
PARTS=${PARTS:-$SHARDS}
if ! "$BIN" map --help >/dev/null 2>&1; then PARTS=0; fi
mkdir -p "$OUT"
TIMES="$OUT/times.txt"
: > "$TIMES"
drop() { python3 -c 'import os, sys
fd = os.open(sys.argv[1], os.O_RDONLY); os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED); os.close(fd)' "$INPUT"; }
resident() { fincore --bytes --noheadings --output RES "$INPUT" | tr -d ' '; }
step() { # step NAME JSON_OUT command...
  local name=$1 json=$2
  shift 2
  local load
  load=$(cut -d' ' -f1,2 /proc/loadavg)
  drop
  /usr/bin/time -o "$OUT/$name.time" -f "%e %U %S %M" "$@" > "$json"
  echo "$name $(cat "$OUT/$name.time") $load $(resident)" | tee -a "$TIMES"
}
echo "start $(date -u +%FT%TZ) $(nproc) cores, input $(stat -c %s "$INPUT") bytes, $PARTS parts" | tee -a "$TIMES"
plan_parts=()
if ((PARTS > 0)); then plan_parts=(--parts "$PARTS"); fi
step plan "$OUT/plan.out.json" "$BIN" plan -q "$INPUT" -o "$OUT/plan.json" --shards "$SHARDS" "${plan_parts[@]}" --json "$@"
parts=$(sed -n 's/^  "parts": \([0-9]*\),\{0,1\}$/\1/p' "$OUT/plan.out.json" | head -n 1)
for ((i = 0; i < ${parts:-0}; i++)); do
  step "map$i" "$OUT/map$i.json" "$BIN" map -q "$OUT/plan.json" --part "$i" -j "$J" --json
done
for ((i = 0; i < SHARDS; i++)); do
  step "shard$i" "$OUT/shard$i.json" "$BIN" build -q --plan "$OUT/plan.json" --shard "$i" -j "$J" --json
  echo "  $(stat -c %s "$OUT/shard-$(printf %04d "$i").vlshard") bytes" | tee -a "$TIMES"
done
step merge "$OUT/merge.json" "$BIN" merge -q "$OUT/plan.json" -o "$OUT/merged.voxlod" -j "$J" --json
sum=$(sha256sum "$OUT/merged.voxlod" | cut -d' ' -f1)
size=$(stat -c %s "$OUT/merged.voxlod")
echo "merged $sum $size" | tee -a "$TIMES"
awk '$1 ~ /^(plan|map[0-9]+|shard[0-9]+|merge)$/ {
    cpu = $3 + $4; all += cpu; ph = $1; sub(/[0-9]+$/, "", ph)
    if (cpu > worst[ph]) worst[ph] = cpu; if ($8 > rd[ph]) rd[ph] = $8 }
  END { printf "all tasks %.2f CPU-s; critical path (plan + slowest map + slowest shard + merge) %.2f CPU-s; most input bytes read: map %d, shard %d\n",
    all, worst["plan"] + worst["map"] + worst["shard"] + worst["merge"], rd["map"], rd["shard"] }' "$TIMES" | tee -a "$TIMES"
status=0
if [[ -n "${REF:-}" ]]; then
  if [[ "$sum" == "$(head -1 "$REF" | cut -d' ' -f1)" && "$size" == "$(sed -n 2p "$REF")" ]]; then
    echo "identical to the one-machine build ($REF)" | tee -a "$TIMES"
  else
    echo "DIFFERS from the one-machine build ($REF)" | tee -a "$TIMES"
    status=1
  fi
fi
if [[ "${KEEP:-0}" != 1 ]]; then
  rm -f "$OUT"/shard-*.vlshard "$OUT"/part-*.bins "$OUT"/part-*.json "$OUT/merged.voxlod"
fi
echo "end $(date -u +%FT%TZ)" | tee -a "$TIMES"
exit $status
