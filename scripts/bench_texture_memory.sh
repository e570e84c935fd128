#!/usr/bin/env bash
# Peak memory of a build whose one texture is bigger than the memory budget, old binary against
# new (docs/BENCHMARKS.md, "A texture bigger than the budget"): a textured quad (OBJ + MTL)
# whose map_Kd is an N×N RGB PNG of one colour (a 0.4–0.8 MB file that inflates to 3·N² bytes,
# like a zlib bomb), built at 256³ under --memory BUDGET, each binary in turn.
#   scripts/bench_texture_memory.sh OLD_BIN NEW_BIN [N] [BUDGET]     (default 11000, 512MiB)
set -euo pipefail
old=${1:?OLD_BIN}; new=${2:?NEW_BIN}; n=${3:-11000}; budget=${4:-512MiB}
dir=$(mktemp -d); trap 'rm -rf "$dir"' EXIT
python3 - "$dir" "$n" <<'PY'
import struct, sys, zlib
d, n = sys.argv[1], int(sys.argv[2])
def chunk(t, b):
    return struct.pack('>I', len(b)) + t + b + struct.pack('>I', zlib.crc32(t + b) & 0xffffffff)
z = zlib.compressobj(9)
row = b'\0' + bytes([200, 120, 40]) * n
idat = b''.join([z.compress(row) for _ in range(n)] + [z.flush()])
ihdr = struct.pack('>IIBBBBB', n, n, 8, 2, 0, 0, 0)
open(f'{d}/big.png', 'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', ihdr) + chunk(b'IDAT', idat) + chunk(b'IEND', b''))
open(f'{d}/quad.mtl', 'w').write('newmtl m\nKd 1 1 1\nmap_Kd big.png\n')
open(f'{d}/quad.obj', 'w').write('mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n'
    'vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n')
PY
echo "input: ${n}² RGB PNG ($(stat -c %s "$dir/big.png") bytes), --memory $budget, $(nproc) cores"
for b in "$old" "$new"; do
  echo "== $b  (load $(cut -d' ' -f1-3 /proc/loadavg))"
  /usr/bin/time -f "   wall %e s, CPU %U + %S s, peak %M KiB" \
    "$b" build "$dir/quad.obj" -o "$dir/out.voxlod" -r 256 --memory "$budget" --backend cpu -q 2>&1 \
    | grep -E "wall|warning|textures  " || true
done
