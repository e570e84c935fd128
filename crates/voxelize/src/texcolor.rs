//! Colour from a base colour texture for one (triangle, voxel) contribution (docs/TEXTURES.md).
//!
//! In a build with textures ([`crate::ChunkVoxelizer::set_textures`]) every colour is
//! accumulated in **linear light** and the voxel's mean is stored sRGB-encoded: the value of a
//! contribution at the interpolation point `q` (the clipped polygon's centroid, as for the
//! untextured attributes) is
//! `linear(c(q)) · T(uv(q))` for the colour channels and `a(q) · T_a(uv(q))` for alpha, where
//! `c(q)` is the vertex colour (the material's factor, e.g. MTL `Kd`) interpolated like every
//! attribute, `linear` the sRGB transfer function, and `T` the texture sampled trilinearly
//! ([`voxlod_texture::Texture::sample`]) at the level of detail that matches the part's
//! footprint: a part of area `w` voxel² covers `w·ρ²` texel², `ρ² = A_uv / A` the triangle's
//! texel area over its area (voxel²); the footprint's edge is `ρ·√min(w, 1)` texels and the
//! level of detail its `log2` (isotropic: the geometric mean of the two axes' scales). A
//! triangle without a usable texture contributes `linear(c(q))`.
//!
//! Williams, "Pyramidal Parametrics", SIGGRAPH 1983 (mip maps and the level of detail).

use voxlod_geom::{Triangle, TRI_HAS_UV};
use voxlod_texture::{srgb_to_linear, Texture, TextureSet};

/// The texture of one triangle and its texture coordinates as affine functions of the
/// swizzled point, like [`crate::chunk`]'s other attributes.
pub(crate) struct TexAt<'a> {
    tex: &'a Texture,
    /// `(u, v)` at v0 and their gradients along swizzled x and y
    uv0: [f64; 2],
    gx: [f64; 2],
    gy: [f64; 2],
    /// `log2 ρ`: the level of detail of a one-voxel² footprint
    lod1: f32,
}

impl<'a> TexAt<'a> {
    /// The texture lookup of `t`, if it has texture coordinates and its material a usable
    /// texture. `grad` maps per-vertex values to their gradients (the caller's barycentrics);
    /// `area2` is twice the triangle's area in voxel².
    pub(crate) fn new(
        t: &Triangle,
        set: &'a TextureSet,
        grad: impl Fn([f64; 3]) -> (f64, f64),
        area2: f64,
    ) -> Option<TexAt<'a>> {
        if t.flags & TRI_HAS_UV == 0 {
            return None;
        }
        let tex = set.get(t.material())?;
        let mut uv0 = [0.0; 2];
        let mut gx = [0.0; 2];
        let mut gy = [0.0; 2];
        for k in 0..2 {
            let a = [0, 1, 2].map(|i| t.uv[i][k] as f64);
            uv0[k] = a[0];
            (gx[k], gy[k]) = grad(a);
        }
        Some(TexAt {
            tex,
            uv0,
            gx,
            gy,
            lod1: lod_of(t, tex, area2),
        })
    }

    /// The texture lookup of `t` at its centroid (for a triangle inside one voxel).
    pub(crate) fn centroid(t: &Triangle, set: &'a TextureSet, area2: f64) -> Option<[f32; 4]> {
        if t.flags & TRI_HAS_UV == 0 {
            return None;
        }
        let tex = set.get(t.material())?;
        let uv = [0, 1].map(|k| (t.uv[0][k] as f64 + t.uv[1][k] as f64 + t.uv[2][k] as f64) / 3.0);
        let lod = lod_of(t, tex, area2) + 0.5 * (0.5 * area2).min(1.0).log2() as f32;
        Some(tex.sample(uv[0], uv[1], lod))
    }

    /// The filtered texture at the offset `(dx, dy)` from v0 for a part of `w` voxel².
    #[inline]
    pub(crate) fn sample(&self, dx: f64, dy: f64, w: f64) -> [f32; 4] {
        let u = self.uv0[0] + self.gx[0] * dx + self.gy[0] * dy;
        let v = self.uv0[1] + self.gx[1] * dx + self.gy[1] * dy;
        let lod = self.lod1 + 0.5 * w.min(1.0).log2() as f32;
        self.tex.sample(u, v, lod)
    }
}

/// `log2 ρ` of triangle `t` on `tex`: `ρ² = A_uv / A` in texel² per voxel².
fn lod_of(t: &Triangle, tex: &Texture, area2: f64) -> f32 {
    let (w, h) = tex.size();
    let d1 = [0, 1].map(|k| t.uv[1][k] as f64 - t.uv[0][k] as f64);
    let d2 = [0, 1].map(|k| t.uv[2][k] as f64 - t.uv[0][k] as f64);
    let uv2 = (d1[0] * d2[1] - d1[1] * d2[0]).abs() * w as f64 * h as f64;
    (0.5 * (uv2 / area2).log2()) as f32
}

/// The linear-light value (0..255 scale) of a contribution: vertex colour `c` (sRGB-encoded,
/// 0..255) times the texture sample `tex` (linear, 0..1) if any; alpha straight.
#[inline]
pub(crate) fn linear_color(c: [f64; 4], tex: Option<[f32; 4]>) -> [f64; 4] {
    let lin = |x: f64| srgb_to_linear((x / 255.0).clamp(0.0, 1.0) as f32) as f64 * 255.0;
    let mut out = [lin(c[0]), lin(c[1]), lin(c[2]), c[3]];
    if let Some(t) = tex {
        for k in 0..4 {
            out[k] *= t[k] as f64;
        }
    }
    out
}
