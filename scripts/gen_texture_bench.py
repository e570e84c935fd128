#!/usr/bin/env python3
"""Inputs of a texture-cache benchmark (decoded textures larger than the `--memory` plan).

Writes into OUT: sixteen distinct 4096² RGB PNGs (smooth gradients with a fine pattern;
1.33 GiB of decoded mip pyramids) and `plane.obj` + `plane.mtl`: a 1024-unit plane of 64×64
quads in z = 0.5, each mapped to a random 16×16-texel patch of one of the textures, so that at
`-r 1024` every voxel covers one texel and the lookups read level 0 all over all sixteen
textures (the worst case for a tile cache). Needs numpy.

    python3 scripts/gen_texture_bench.py /tmp/tex && \
    voxlod build /tmp/tex/plane.obj -r 1024 -j 2 --memory 341MiB --json
"""
import numpy as np, zlib, struct, sys, os
out = sys.argv[1]; n = 4096; T = 16
def png(path, rgb):
    h, w, _ = rgb.shape
    raw = np.zeros((h, 1 + 3 * w), np.uint8); raw[:, 1:] = rgb.reshape(h, 3 * w)
    def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1)) + chunk(b"IEND", b""))
y, x = np.mgrid[0:n, 0:n].astype(np.uint32)
mtl = []
for t in range(T):
    rgb = np.stack([((x * (t + 1)) >> 4) ^ ((x ^ y) & 7), ((y * (17 - t)) >> 4), ((x + y + 97 * t) >> 5) ^ (((x * y) >> 7) & 15)], -1).astype(np.uint8)
    png(os.path.join(out, f"tex{t:02}.png"), rgb)
    mtl.append(f"newmtl m{t}\nKd 1 1 1\nmap_Kd tex{t:02}.png\n")
open(os.path.join(out, "plane.mtl"), "w").write("".join(mtl))
rng = np.random.default_rng(1)
lines = ["mtllib plane.mtl"]; faces = [[] for _ in range(T)]; k = 1
for j in range(64):
    for i in range(64):
        u, v = rng.integers(0, n - 16, 2)
        for dx, dy in [(0, 0), (16, 0), (16, 16), (0, 16)]:
            lines.append(f"v {16*i+dx} {16*j+dy} 0.5"); lines.append(f"vt {(u+dx)/n} {(v+dy)/n}")
        faces[(i * 7 + j * 3) % T].append(f"f {k}/{k} {k+1}/{k+1} {k+2}/{k+2} {k+3}/{k+3}"); k += 4
for t in range(T):
    lines.append(f"usemtl m{t}"); lines += faces[t]
open(os.path.join(out, "plane.obj"), "w").write("\n".join(lines) + "\n")
