#!/usr/bin/env bash
# What a 3D Tiles export costs against the octree it comes from: for each MESH:RESOLUTION,
# build the .voxlod (timed), then `export --3d-tiles` of every level with BIN and, with OLD_BIN,
# with the old binary beside it (same file, one after the other). Prints one markdown row per
# input: .voxlod bytes and build CPU, tileset bytes, ratio, largest tile, export CPU and its
# ratio to the build's (CPU = user + sys seconds; wall beside it).
# Usage: scripts/bench_tiles.sh MESH:RES [MESH:RES ...]
set -euo pipefail
bin=${BIN:-target/release/voxlod}
dir=$(mktemp -d "${TMPDIR:-/tmp}/bench_tiles.XXXXXX")
trap 'rm -rf "$dir"' EXIT
timed() {  # prints "wall cpu" of the command
  /usr/bin/time -f '%e %U %S' -o "$dir/time" "$@" >/dev/null 2>&1
  read -r wall user sys < "$dir/time"
  echo "$wall $(echo "$user + $sys" | bc)"
}
largest() { find "$1" -name '*.glb' -printf '%s\n' | sort -n | tail -1; }
mb() { echo "scale=1; $1 / 1000000" | bc; }
echo "| input | .voxlod | build wall / CPU s | tileset | × .voxlod | largest tile | export wall / CPU s | × build CPU | old tileset | old export wall / CPU s |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
for spec in "$@"; do
  mesh=${spec%:*} res=${spec##*:}
  read -r bw bc < <(timed "$bin" build -q "$mesh" -o "$dir/m.voxlod" -r "$res")
  vb=$(stat -c %s "$dir/m.voxlod")
  read -r ew ec < <(timed "$bin" export "$dir/m.voxlod" --3d-tiles "$dir/t" --max-size 64GiB)
  tb=$(du -sb "$dir/t" | cut -f1)
  lt=$(largest "$dir/t")
  rm -rf "$dir/t"
  old="–" oldt="–"
  if [ -n "${OLD_BIN:-}" ]; then
    read -r ow oc < <(timed "$OLD_BIN" export "$dir/m.voxlod" --3d-tiles "$dir/o" --max-size 64GiB)
    old="$(mb "$(du -sb "$dir/o" | cut -f1)") MB"
    oldt="$ow / $oc"
    rm -rf "$dir/o"
  fi
  echo "| $(basename "$mesh") $res³ | $(mb "$vb") MB | $bw / $bc | $(mb "$tb") MB | $(echo "scale=1; $tb / $vb" | bc) | $(mb "$lt") MB | $ew / $ec | $(echo "scale=2; $ec / $bc" | bc) | $old | $oldt |"
  rm -f "$dir/m.voxlod"
done
