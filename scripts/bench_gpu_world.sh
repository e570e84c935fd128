#!/usr/bin/env bash
# The cost of GPU sets exact for the input's own coordinates (near-ties listed and decided on
# the host; the voxelize crate's docs, "Exact in the input's own coordinates"). Builds each
# input with `--backend gpu` (lavapipe on a machine without a GPU) with the binary before the
# change and with this tree's, interleaved, and prints CPU seconds (user + sys), wall seconds,
# the triangles decided on the host (`gpu_cpu_fallback_triangles`, per chunk), the chunks that
# fell back as a whole, and the voxel count; then the CPU backend's voxel count for reference.
# Usage: scripts/bench_gpu_world.sh OLD_BIN NEW_BIN ROUNDS RES MODE INPUT...
set -euo pipefail
old=$1 new=$2 rounds=$3 res=$4 mode=$5
shift 5
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
field() { python3 -c "import json,sys; d=json.load(open('$1')); print(d.get('$2', '?'))"; }
for ((r = 1; r <= rounds; r++)); do
  for input in "$@"; do
    for which in old new; do
      bin=$old
      [[ $which == new ]] && bin=$new
      /usr/bin/time -f "%U %S %e" -o "$out/t" "$bin" build -q --json "$input" -o "$out/o.voxlod" \
        -r "$res" -m "$mode" --backend gpu --tmp "$out" --force > "$out/j"
      read -r u s e < "$out/t"
      voxels=$("$bin" inspect "$out/o.voxlod" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["voxels"])')
      printf '%s\t%s\tround %d\tcpu %.2f s (user %.2f + sys %.2f)\twall %.2f s\thost triangles %s\tchunks fallen back %s\tvoxels %s\n' \
        "$(basename "$input")" "$which" "$r" "$(echo "$u + $s" | bc)" "$u" "$s" "$e" \
        "$(field "$out/j" gpu_cpu_fallback_triangles)" "$(field "$out/j" gpu_cpu_fallback_chunks)" "$voxels"
    done
  done
done
for input in "$@"; do
  "$new" build -q "$input" -o "$out/c.voxlod" -r "$res" -m "$mode" --backend cpu --tmp "$out" --force > /dev/null
  printf '%s\tcpu backend\tvoxels %s\n' "$(basename "$input")" \
    "$("$new" inspect "$out/c.voxlod" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["voxels"])')"
done
