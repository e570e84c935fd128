//! Colour from textures (docs/TEXTURES.md, `voxlod_voxelize::texcolor`): quads with made-up
//! textures voxelized by the chunk voxelizer, each voxel's colour compared with an
//! independent computation from the texels (exact averages in linear light, f64).

use std::collections::HashMap;
use voxlod_geom::{Triangle, Wrap, TRI_HAS_COLORS, TRI_HAS_UV};
use voxlod_texture::{linear_to_srgb8, srgb_to_linear, Texture, TextureSet};
use voxlod_voxelize::{ChunkVoxelizer, Mode};

/// The two triangles of the quad `p` (corners in order) with texture coordinates `uv`,
/// material `m`, vertex colour `c`.
fn quad(p: [[f32; 3]; 4], uv: [[f32; 2]; 4], m: u32, c: [u8; 4]) -> Vec<Triangle> {
    [[0, 1, 2], [0, 2, 3]]
        .iter()
        .map(|ix| {
            let mut t = Triangle::new(ix.map(|i| p[i]));
            t.uv = ix.map(|i| uv[i]);
            t.c = [c; 3];
            t.flags = TRI_HAS_UV | TRI_HAS_COLORS;
            t.set_material(m);
            t
        })
        .collect()
}

/// Voxelizes `tris` (chunk at the origin) with `textures`; colour by position.
fn voxelize(tris: &[Triangle], textures: TextureSet, mode: Mode) -> HashMap<[u8; 3], [u8; 4]> {
    let mut cv = ChunkVoxelizer::new(mode);
    cv.set_textures(Some(std::sync::Arc::new(textures)));
    cv.begin([0; 3]);
    cv.add(tris);
    cv.finish().iter().map(|v| (v.pos(), v.rgba())).collect()
}

fn lin(c: u8) -> f64 {
    srgb_to_linear(c as f32 / 255.0) as f64
}

/// The exact linear-light mean of texel block `[x0, x0+n) × [y0, y0+n)` of `texels` (`w` wide),
/// sRGB8-encoded.
fn block_mean(texels: &[[u8; 4]], w: usize, x0: usize, y0: usize, n: usize) -> [u8; 3] {
    let mut s = [0f64; 3];
    for y in y0..y0 + n {
        for x in x0..x0 + n {
            for k in 0..3 {
                s[k] += lin(texels[y * w + x][k]);
            }
        }
    }
    s.map(|v| linear_to_srgb8((v / (n * n) as f64) as f32))
}

fn close(a: [u8; 4], b: [u8; 3], tol: i32) -> bool {
    (0..3).all(|k| (a[k] as i32 - b[k] as i32).abs() <= tol)
}

/// A 64×64 texture on an 8×8-voxel quad in the plane z = 10.5 (8 texels per voxel edge: mip
/// level 3). Voxel `(4+i, 4+j)` covers texel columns `8i..8i+8` and rows `56−8j..64−8j`
/// (v points up, row 0 is the top).
fn aligned(tex: Texture) -> HashMap<[u8; 3], [u8; 4]> {
    let z = 10.5;
    let p = [
        [4.0, 4.0, z],
        [12.0, 4.0, z],
        [12.0, 12.0, z],
        [4.0, 12.0, z],
    ];
    let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let set = TextureSet::from_textures(vec![None, Some(tex)]);
    voxelize(&quad(p, uv, 1, [255; 4]), set, Mode::Conservative)
}

/// Black and white (and red and blue) one-texel checkerboards: every voxel is the linear
/// mean, sRGB 188, not the 128 of averaging the encoded values.
#[test]
fn aligned_checkerboard_is_averaged_in_linear_light() {
    for (a, b, mean) in [
        ([0, 0, 0, 255], [255, 255, 255, 255], [188, 188, 188]),
        ([255, 0, 0, 255], [0, 0, 255, 255], [188, 0, 188]),
    ] {
        let texels: Vec<[u8; 4]> = (0..64 * 64)
            .map(|i| if (i % 64 + i / 64) % 2 == 0 { a } else { b })
            .collect();
        let v = aligned(Texture::from_rgba8(64, 64, texels.clone(), [Wrap::Repeat; 2]).unwrap());
        for j in 0..8u8 {
            for i in 0..8u8 {
                let got = v[&[4 + i, 4 + j, 10]];
                let want = block_mean(&texels, 64, 8 * i as usize, 56 - 8 * j as usize, 8);
                assert!(close(got, want, 1), "voxel {i},{j}: {got:?} vs {want:?}");
                assert_eq!(got[3], 255);
            }
        }
        assert!(close(v[&[5, 5, 10]], mean, 1), "{:?}", v[&[5, 5, 10]]);
    }
}

/// A texture whose linear-light value is affine in the texel position (quantized to sRGB8):
/// the mean over any part is the value at its centroid, so every voxel equals the exact mean
/// of its 8×8 texels within one step, including the voxels the quad's diagonal cuts. Not the
/// voxels on the texture's border: there the bilinear filter at a part's centroid reaches
/// across the edge, into the other side of the repeated texture, as any bilinear filter does.
#[test]
fn aligned_affine_texture_gives_each_voxels_texel_mean() {
    let texels: Vec<[u8; 4]> = (0..64 * 64)
        .map(|i| {
            let (x, y) = ((i % 64) as f32 + 0.5, (i / 64) as f32 + 0.5);
            let f = |a: f32, b: f32, c: f32| linear_to_srgb8(a + b * x / 64.0 + c * y / 64.0);
            [
                f(0.05, 0.9, 0.0),
                f(0.9, -0.4, -0.45),
                f(0.1, 0.3, 0.55),
                255,
            ]
        })
        .collect();
    let v = aligned(Texture::from_rgba8(64, 64, texels.clone(), [Wrap::Repeat; 2]).unwrap());
    for j in 1..7u8 {
        for i in 1..7u8 {
            let got = v[&[4 + i, 4 + j, 10]];
            let want = block_mean(&texels, 64, 8 * i as usize, 56 - 8 * j as usize, 8);
            assert!(close(got, want, 1), "voxel {i},{j}: {got:?} vs {want:?}");
        }
    }
}

/// The affine texture on a quad rotated by 30° in its plane, 3 texels per voxel edge: every
/// voxel wholly inside the quad is the texture's mean over the voxel's square, which for an
/// affine texture is its value at the square's centre (computed here from the inverse of the
/// quad's parametrization). Tolerance: 2 steps (the texels are sRGB8-quantized, and the
/// trilinear blend between levels 1 and 2 of a quantized pyramid adds up to one more).
#[test]
fn rotated_affine_texture_within_two_steps() {
    let n = 96usize;
    let f = |x: f64, y: f64| {
        let g = |a: f64, b: f64, c: f64| a + b * x / n as f64 + c * y / n as f64;
        [g(0.05, 0.9, 0.0), g(0.9, -0.4, -0.45), g(0.1, 0.3, 0.55)]
    };
    let texels: Vec<[u8; 4]> = (0..n * n)
        .map(|i| {
            let c = f((i % n) as f64 + 0.5, (i / n) as f64 + 0.5);
            [
                linear_to_srgb8(c[0] as f32),
                linear_to_srgb8(c[1] as f32),
                linear_to_srgb8(c[2] as f32),
                255,
            ]
        })
        .collect();
    let tex = Texture::from_rgba8(n as u32, n as u32, texels, [Wrap::Repeat; 2]).unwrap();
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let side = 32.0; // voxels: 96 texels / 32 = 3 texels per voxel edge
    let o = [100.0, 80.0];
    let at = |a: f64, b: f64| [o[0] + a * c - b * s, o[1] + a * s + b * c];
    let z = 20.5;
    let corners = [at(0.0, 0.0), at(side, 0.0), at(side, side), at(0.0, side)];
    let p = corners.map(|q| [q[0] as f32, q[1] as f32, z as f32]);
    let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let set = TextureSet::from_textures(vec![None, Some(tex)]);
    let v = voxelize(&quad(p, uv, 1, [255; 4]), set, Mode::Conservative);
    // quad coordinates (a, b) of a point
    let inv = |x: f64, y: f64| {
        let (dx, dy) = (x - o[0], y - o[1]);
        (dx * c + dy * s, -dx * s + dy * c)
    };
    let mut checked = 0;
    for (pos, got) in &v {
        let inside = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
            .iter()
            .all(|(ex, ey)| {
                let (a, b) = inv(pos[0] as f64 + ex, pos[1] as f64 + ey);
                a > 0.0 && a < side && b > 0.0 && b < side
            });
        if !inside {
            continue;
        }
        let (a, b) = inv(pos[0] as f64 + 0.5, pos[1] as f64 + 0.5);
        // texel position: u = a/side → x = u·n; v = b/side → row from the top (1 − v)·n
        let lin = f(a / side * n as f64, (1.0 - b / side) * n as f64);
        let want = lin.map(|x| linear_to_srgb8(x as f32));
        assert!(close(*got, want, 2), "voxel {pos:?}: {got:?} vs {want:?}");
        checked += 1;
    }
    assert!(checked > 500, "{checked}");
}

/// Repeat wrap and a UV seam. An 8×8 texture, left half red, right half blue, on a 24-voxel
/// strip with u from 0 to 3 (one texel per voxel, so level 0): voxel `i` shows texel column
/// `i mod 8`. Beside it two quads meet at x = 60.5, the middle of a voxel column, the left
/// mapped to the red half, the right to the blue half: the seam's voxels are the linear-light
/// mean of red and blue (188, 0, 188).
#[test]
fn repeat_wrap_and_uv_seam() {
    let mut texels = vec![[0u8; 4]; 64];
    for (i, t) in texels.iter_mut().enumerate() {
        *t = if i % 8 < 4 {
            [255, 0, 0, 255]
        } else {
            [0, 0, 255, 255]
        };
    }
    let tex = || Texture::from_rgba8(8, 8, texels.clone(), [Wrap::Repeat; 2]).unwrap();
    let z = 5.5;
    let strip = quad(
        [[0.0, 0.0, z], [24.0, 0.0, z], [24.0, 8.0, z], [0.0, 8.0, z]],
        [[0.0, 0.0], [3.0, 0.0], [3.0, 1.0], [0.0, 1.0]],
        1,
        [255; 4],
    );
    let v = voxelize(
        &strip,
        TextureSet::from_textures(vec![None, Some(tex())]),
        Mode::Thin,
    );
    for i in 0..24u8 {
        // columns 1, 2 (red) and 5, 6 (blue) of each copy: both neighbours the same colour
        let want = match i % 8 {
            1 | 2 => [255, 0, 0],
            5 | 6 => [0, 0, 255],
            _ => continue,
        };
        for j in 1..7u8 {
            let got = v[&[i, j, 5]];
            assert!(close(got, want, 1), "strip voxel {i},{j}: {got:?}");
        }
    }
    // the seam: two quads sharing the edge x = 60.5 with unrelated texture coordinates
    let h = [
        [40.0, 0.0, z],
        [60.5, 0.0, z],
        [60.5, 8.0, z],
        [40.0, 8.0, z],
    ];
    let k = [
        [60.5, 0.0, z],
        [80.0, 0.0, z],
        [80.0, 8.0, z],
        [60.5, 8.0, z],
    ];
    let mut tris = quad(
        h,
        [[0.1, 0.1], [0.4, 0.1], [0.4, 0.9], [0.1, 0.9]],
        1,
        [255; 4],
    );
    tris.extend(quad(
        k,
        [[0.6, 0.1], [0.9, 0.1], [0.9, 0.9], [0.6, 0.9]],
        1,
        [255; 4],
    ));
    let v = voxelize(
        &tris,
        TextureSet::from_textures(vec![None, Some(tex())]),
        Mode::Thin,
    );
    for j in 1..7u8 {
        assert!(
            close(v[&[60, j, 5]], [188, 0, 188], 1),
            "{:?}",
            v[&[60, j, 5]]
        );
        assert!(close(v[&[55, j, 5]], [255, 0, 0], 1));
        assert!(close(v[&[65, j, 5]], [0, 0, 255], 1));
    }
}

/// The vertex colour (MTL `Kd`) multiplies the texture in linear light; a triangle whose
/// material has no texture keeps its colour; without textures the voxelizer is unchanged
/// (sRGB-encoded values averaged as stored).
#[test]
fn factor_untextured_materials_and_no_textures() {
    let white = Texture::from_rgba8(1, 1, vec![[255; 4]], [Wrap::Repeat; 2]).unwrap();
    let set = || TextureSet::from_textures(vec![None, Some(white.clone())]);
    let z = 3.5;
    let p = [[0.0, 0.0, z], [4.0, 0.0, z], [4.0, 4.0, z], [0.0, 4.0, z]];
    let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let kd = [163, 100, 20, 255];
    // textured with a white texture: Kd itself
    let v = voxelize(&quad(p, uv, 1, kd), set(), Mode::Thin);
    assert!(
        close(v[&[1, 1, 3]], [163, 100, 20], 1),
        "{:?}",
        v[&[1, 1, 3]]
    );
    // material 0 has no texture: Kd
    let v = voxelize(&quad(p, uv, 0, kd), set(), Mode::Thin);
    assert!(close(v[&[1, 1, 3]], [163, 100, 20], 1));
    // half black, half white vertex colours in one voxel: linear mean with textures on,
    // encoded mean without
    let mut tris = quad(p, uv, 0, [0, 0, 0, 255]);
    for t in &mut tris[1..] {
        t.c = [[255; 4]; 3];
    }
    assert!(close(
        voxelize(&tris, set(), Mode::Thin)[&[1, 1, 3]],
        [188; 3],
        1
    ));
    let mut cv = ChunkVoxelizer::new(Mode::Thin);
    cv.begin([0; 3]);
    cv.add(&tris);
    let plain: HashMap<_, _> = cv.finish().iter().map(|v| (v.pos(), v.rgba())).collect();
    assert!(
        close(plain[&[1, 1, 3]], [128; 3], 1),
        "{:?}",
        plain[&[1, 1, 3]]
    );
}
