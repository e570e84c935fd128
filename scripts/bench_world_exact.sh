#!/usr/bin/env bash
# The cost of exact decisions in the input's own coordinates (the voxelize crate's docs).
# Builds each input with an old binary (OLD_BIN) and a new one (NEW_BIN), interleaved, `--backend cpu`,
# and prints CPU seconds (user + sys), wall seconds and the voxel count of each build.
# Usage: scripts/bench_world_exact.sh OLD_BIN NEW_BIN ROUNDS INPUT... (resolution 1024)
set -euo pipefail
old=$1 new=$2 rounds=$3
shift 3
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for ((r = 1; r <= rounds; r++)); do
  for input in "$@"; do
    for which in old new; do
      bin=$old
      [[ $which == new ]] && bin=$new
      /usr/bin/time -f "%U %S %e" -o "$out/t" "$bin" build -q "$input" -o "$out/o.voxlod" \
        -r 1024 --backend cpu --tmp "$out" --force
      read -r u s e < "$out/t"
      voxels=$("$bin" inspect "$out/o.voxlod" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["voxels"])' 2>/dev/null || echo "?")
      printf '%s\t%s\tround %d\tcpu %.2f s (user %.2f + sys %.2f)\twall %.2f s\tvoxels %s\n' \
        "$(basename "$input")" "$which" "$r" "$(echo "$u + $s" | bc)" "$u" "$s" "$e" "$voxels"
    done
  done
done
