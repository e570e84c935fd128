#!/usr/bin/env bash
# The browser viewer's bytes and time to a complete first frame: opens `voxlod serve FILE` in
# headless Chromium (tests/node/web-check.js; SwiftShader, Chromium's software GPU, unless the
# machine gives Chromium a GPU) for a whole view and a close-up, with and without occlusion
# culling, and prints a markdown table. Bytes are counted by the server.
#
# Usage: scripts/bench_web.sh FILE.voxlod [CLOSE_UP_QUERY] [SIZE]
#   CLOSE_UP_QUERY  viewer parameters of the close-up (default: the dragon's head,
#                   zoom=8&target=-0.06871,0.15317,-0.00599)
#   SIZE            picture size (default 320x240)
# Needs a release binary (cargo build --release -p voxlod), node with `npm ci` in tests/node,
# and chromium.
set -euo pipefail
cd "$(dirname "$0")/.."
file=$1
close=${2:-zoom=8&target=-0.06871,0.15317,-0.00599}
size=${3:-320x240}
bin=${VOXLOD:-target/release/voxlod}
out=$(mktemp -d)
trap 'kill "$pid" 2>/dev/null || true; rm -rf "$out"' EXIT
"$bin" serve "$file" --port 0 >"$out/serve.txt" &
pid=$!
for _ in $(seq 50); do grep -q http "$out/serve.txt" 2>/dev/null && break; sleep 0.1; done
url=$(grep -o 'http://[^ ]*' "$out/serve.txt")
total=$(stat -c %s "$file")
echo "| view | occlusion | nodes drawn | nodes hidden | bytes fetched | of the file | complete first frame |"
echo "| --- | --- | --- | --- | --- | --- | --- |"
for view in whole close-up; do
  q="size=$size&progressive=0"
  [ "$view" = close-up ] && q="$q&$close"
  for occ in 1 0; do
    before=$(curl -s "${url}.voxlod/stats" | python3 -c 'import json,sys; print(json.load(sys.stdin)["bytes_sent"])')
    status=$(node tests/node/web-check.js --url "${url}?$q&occlusion=$occ" "$out/shot.png")
    after=$(curl -s "${url}.voxlod/stats" | python3 -c 'import json,sys; print(json.load(sys.stdin)["bytes_sent"])')
    python3 - "$status" "$((after - before))" "$total" "$view" "$occ" <<'EOF'
import json, sys
s = json.loads(sys.argv[1])
sent, total = int(sys.argv[2]), int(sys.argv[3])
print(f"| {sys.argv[4]} | {'on' if sys.argv[5] == '1' else 'off'} | {s['nodes']} | {s['occluded']} "
      f"| {sent / 1e6:.2f} MB | {100 * sent / total:.1f} % | {s['firstCompleteMs'] / 1000:.1f} s |")
EOF
  done
done
