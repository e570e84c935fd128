#!/usr/bin/env bash
# What an export costs: PLY and GLB of one level, and a 3D Tiles tileset of every level down
# to it, of one octree, interleaved (2 rounds); with OLD_BIN, also the old binary's PLY export
# beside them (the size guard and glTF change must not slow the PLY).
# Usage: scripts/bench_export.sh OCTREE [LEVEL]
# Prints one line per run: what, wall s, user s, sys s, peak KiB, bytes written, load1.
set -euo pipefail
file=$1 level=${2:-0}
bin=${BIN:-target/release/voxlod}
dir=$(mktemp -d "${TMPDIR:-/tmp}/bench_export.XXXXXX")
trap 'rm -rf "$dir"' EXIT
run() {  # name output binary args...
  local name=$1 out=$2 b=$3; shift 3
  local load; load=$(cut -d' ' -f1 /proc/loadavg)
  /usr/bin/time -f '%e %U %S %M' -o "$dir/time" "$b" export "$file" --level "$level" "$@" --max-size 64GiB >/dev/null 2>&1
  read -r wall user sys peak < "$dir/time"
  local bytes; bytes=$(du -sb "$out" | cut -f1)
  echo "$name wall=$wall user=$user sys=$sys peak_KiB=$peak bytes=$bytes load1=$load"
  rm -rf "$out"
}
for round in 1 2; do
  echo "# round $round"
  run ply "$dir/out.ply" "$bin" -o "$dir/out.ply"
  run glb "$dir/out.glb" "$bin" -o "$dir/out.glb"
  run 3d-tiles "$dir/tiles" "$bin" --3d-tiles "$dir/tiles"
  if [ -n "${OLD_BIN:-}" ]; then
    load=$(cut -d' ' -f1 /proc/loadavg)
    /usr/bin/time -f '%e %U %S %M' -o "$dir/time" "$OLD_BIN" export "$file" --level "$level" -o "$dir/old.ply" >/dev/null 2>&1
    read -r wall user sys peak < "$dir/time"
    echo "old-ply wall=$wall user=$user sys=$sys peak_KiB=$peak bytes=$(stat -c %s "$dir/old.ply") load1=$load"
    rm -f "$dir/old.ply"
  fi
done
