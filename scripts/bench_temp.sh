#!/usr/bin/env bash
# Temporary disk and CPU of a build, old binary against new, interleaved in one run.
# Usage: scripts/bench_temp.sh OLD_BIN NEW_BIN INPUT [build settings...]
# Prints one line per run: binary, wall s, user s, sys s, peak KiB, temp_bytes_written (new
# binaries; "-" where the summary has no such field), binned triangles, load1, output sha256.
set -euo pipefail
old=$1 new=$2 input=$3; shift 3
dir=$(mktemp -d "${TMPDIR:-/tmp}/bench_temp.XXXXXX")
trap 'rm -rf "$dir"' EXIT
for round in 1 2; do
  for side in new old; do
    bin=$new; [ "$side" = old ] && bin=$old
    load=$(cut -d' ' -f1 /proc/loadavg)
    /usr/bin/time -f '%e %U %S %M' -o "$dir/time" "$bin" build "$input" -o "$dir/out.voxlod" \
      --json -q --force --tmp "$dir" "$@" > "$dir/summary.json"
    read -r wall user sys peak < "$dir/time"
    tw=$(python3 -c 'import json,sys; s=json.load(open(sys.argv[1])); print(s.get("temp_bytes_written","-"), s.get("binned_triangles","-"))' "$dir/summary.json")
    sum=$(sha256sum "$dir/out.voxlod" | cut -c1-16)
    echo "round$round $side wall=$wall user=$user sys=$sys peak_KiB=$peak temp_written,binned=$tw load1=$load sha=$sum"
    rm -f "$dir/out.voxlod"
  done
done
