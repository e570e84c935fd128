//! Decoded textures for voxlod's colour-from-texture path (docs/TEXTURES.md).
//!
//! * [`Texture`]: an RGBA8 image and its mip pyramid. The colour channels are sRGB-encoded,
//!   as image files store them; every mip level is the **exact box filter of level 0 in
//!   linear light** (each level-`k` texel averages its block of level-0 texels, converted to
//!   linear with the sRGB transfer function, in f64, rounded to sRGB8 once), so a black and
//!   white checkerboard averages to sRGB 188, not 128, and the rounding does not accumulate
//!   from level to level. Alpha is straight (not premultiplied) and linear: averaged as is.
//! * [`Texture::sample`]: trilinear filtering (bilinear within the two levels around the
//!   requested level of detail, linear between them) in linear light, with the wrap modes of
//!   [`Wrap`] per axis; texture coordinates follow OBJ and glTF: texel centres at
//!   `((i + ½)/W, 1 − (j + ½)/H)`, row `j = 0` the image's top row.
//! * [`TextureSet`]: the textures of a mesh's material table, loaded once (PNG and JPEG via
//!   the `image` crate); a texture that cannot be read is a warning naming the file, and its
//!   material is untextured.
//!
//! The level of detail is chosen by the caller (the voxelizer): `log2` of the texel
//! footprint of one voxel edge, so that a voxel averages the texels it covers (Williams,
//! "Pyramidal Parametrics", SIGGRAPH 1983).
//!
//! ```
//! use voxlod_texture::{Texture, linear_to_srgb8};
//! use voxlod_geom::Wrap;
//! // a 2×2 black and white checkerboard: its 1×1 mip is 50 % grey in linear light
//! let t = Texture::from_rgba8(2, 2, vec![[0, 0, 0, 255], [255, 255, 255, 255],
//!     [255, 255, 255, 255], [0, 0, 0, 255]], [Wrap::Repeat; 2]).unwrap();
//! assert_eq!(t.levels(), 2);
//! let c = t.sample(0.5, 0.5, 1.0);
//! assert_eq!(linear_to_srgb8(c[0]), 188);
//! ```

use std::path::Path;
use std::sync::Arc;
use voxlod_geom::{Material, Wrap};

/// sRGB-encoded value in 0..=1 to linear light (IEC 61966-2-1).
#[inline]
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light in 0..=1 to the sRGB encoding (IEC 61966-2-1); clamped to 0..=1.
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        x * 12.92
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear light in 0..=1 to the nearest sRGB8 code.
#[inline]
pub fn linear_to_srgb8(x: f32) -> u8 {
    (linear_to_srgb(x) * 255.0).round() as u8
}

/// The linear value of every sRGB8 code.
fn lut() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

/// One mip level: `w × h` RGBA8 texels (sRGB colour, linear alpha), row 0 at the top.
#[derive(Clone, Debug)]
struct Level {
    w: u32,
    h: u32,
    texels: Vec<[u8; 4]>,
}

/// An RGBA8 texture and its mip pyramid (see the crate docs).
#[derive(Clone, Debug)]
pub struct Texture {
    levels: Vec<Level>,
    wrap: [Wrap; 2],
}

impl Texture {
    /// The texture of a `w × h` image (`texels` row by row from the top) with its pyramid:
    /// level `k` is `max(1, w >> k) × max(1, h >> k)`, down to 1×1; its texel `(i, j)`
    /// averages, in linear light, the level-0 texels `(x, y)` with `⌊x·w_k/w⌋ = i` and
    /// `⌊y·h_k/h⌋ = j` (a partition of the image, so odd sizes lose nothing). `Err` if the sizes do not match or are zero.
    pub fn from_rgba8(
        w: u32,
        h: u32,
        texels: Vec<[u8; 4]>,
        wrap: [Wrap; 2],
    ) -> Result<Texture, String> {
        if w == 0 || h == 0 || texels.len() as u64 != w as u64 * h as u64 {
            return Err(format!(
                "a {w}×{h} texture needs {} texels, got {}",
                w as u64 * h as u64,
                texels.len()
            ));
        }
        let lut = lut();
        let mut levels = vec![Level { w, h, texels }];
        let mut k = 1;
        while levels.last().is_some_and(|l| l.w > 1 || l.h > 1) {
            let (wk, hk) = ((w >> k).max(1), (h >> k).max(1));
            let base = &levels[0];
            let mut out = Vec::with_capacity(wk as usize * hk as usize);
            // column block of each level-0 column
            let col: Vec<u32> = (0..w)
                .map(|x| (x as u64 * wk as u64 / w as u64) as u32)
                .collect();
            let col = |x: u32| col[x as usize];
            let mut sums = vec![[0f64; 4]; wk as usize];
            let mut counts = vec![0u64; wk as usize];
            for j in 0..hk {
                let y0 = (j as u64 * h as u64).div_ceil(hk as u64) as u32;
                let y1 = ((j as u64 + 1) * h as u64).div_ceil(hk as u64) as u32;
                sums.iter_mut().for_each(|s| *s = [0.0; 4]);
                counts.iter_mut().for_each(|c| *c = 0);
                for y in y0..y1 {
                    let row = &base.texels[(y * w) as usize..((y + 1) * w) as usize];
                    for (x, t) in row.iter().enumerate() {
                        let i = col(x as u32) as usize;
                        let s = &mut sums[i];
                        s[0] += lut[t[0] as usize] as f64;
                        s[1] += lut[t[1] as usize] as f64;
                        s[2] += lut[t[2] as usize] as f64;
                        s[3] += t[3] as f64;
                        counts[i] += 1;
                    }
                }
                for (s, &n) in sums.iter().zip(&counts) {
                    let inv = 1.0 / n.max(1) as f64;
                    out.push([
                        linear_to_srgb8((s[0] * inv) as f32),
                        linear_to_srgb8((s[1] * inv) as f32),
                        linear_to_srgb8((s[2] * inv) as f32),
                        (s[3] * inv).round() as u8,
                    ]);
                }
            }
            levels.push(Level {
                w: wk,
                h: hk,
                texels: out,
            });
            k += 1;
        }
        Ok(Texture { levels, wrap })
    }

    /// Decodes a PNG or JPEG file (the format is taken from its content) into a texture.
    pub fn load(path: &Path, wrap: [Wrap; 2]) -> Result<Texture, String> {
        let img = image::ImageReader::open(path)
            .map_err(|e| e.to_string())?
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .decode()
            .map_err(|e| e.to_string())?;
        Self::from_image(img, wrap)
    }

    /// Decodes PNG or JPEG bytes held in memory (a glTF embedded image) into a texture.
    pub fn decode(bytes: &[u8], wrap: [Wrap; 2]) -> Result<Texture, String> {
        let img = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .decode()
            .map_err(|e| e.to_string())?;
        Self::from_image(img, wrap)
    }

    fn from_image(img: image::DynamicImage, wrap: [Wrap; 2]) -> Result<Texture, String> {
        let img = img.into_rgba8();
        let (w, h) = img.dimensions();
        let texels: Vec<[u8; 4]> = img
            .into_raw()
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        Texture::from_rgba8(w, h, texels, wrap)
    }

    /// Width and height of level 0.
    pub fn size(&self) -> (u32, u32) {
        (self.levels[0].w, self.levels[0].h)
    }

    /// Number of mip levels (level 0 up to 1×1).
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Bytes the decoded pyramid holds.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * 4).sum()
    }

    /// The texel of level `k` at `(x, y)` (row 0 at the top).
    pub fn texel(&self, k: usize, x: u32, y: u32) -> [u8; 4] {
        let l = &self.levels[k];
        l.texels[(y * l.w + x) as usize]
    }

    /// The filtered colour at texture coordinates `(u, v)` and level of detail `lod`
    /// (`log2` of the footprint in level-0 texels; clamped to the pyramid): linear-light RGB in
    /// 0..=1 and straight alpha in 0..=1. Trilinear: bilinear in levels `⌊lod⌋` and `⌊lod⌋+1`,
    /// blended by the fraction.
    pub fn sample(&self, u: f64, v: f64, lod: f32) -> [f32; 4] {
        let top = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() {
            lod.clamp(0.0, top)
        } else {
            0.0
        };
        let k = lod.floor();
        let f = lod - k;
        let a = self.bilinear(k as usize, u, v);
        if f <= 0.0 {
            return a;
        }
        let b = self.bilinear(k as usize + 1, u, v);
        [0, 1, 2, 3].map(|c| a[c] + (b[c] - a[c]) * f)
    }

    fn bilinear(&self, k: usize, u: f64, v: f64) -> [f32; 4] {
        let l = &self.levels[k];
        let lut = lut();
        let x = u * l.w as f64 - 0.5;
        let y = (1.0 - v) * l.h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let xs = [
            wrap(x0, l.w, self.wrap[0]),
            wrap(x0 + 1.0, l.w, self.wrap[0]),
        ];
        let ys = [
            wrap(y0, l.h, self.wrap[1]),
            wrap(y0 + 1.0, l.h, self.wrap[1]),
        ];
        let mut out = [0f32; 4];
        for (j, wy) in [(0, 1.0 - fy), (1, fy)] {
            for (i, wx) in [(0, 1.0 - fx), (1, fx)] {
                let wgt = wx * wy;
                if wgt == 0.0 {
                    continue;
                }
                let t = l.texels[(ys[j] * l.w + xs[i]) as usize];
                out[0] += wgt * lut[t[0] as usize];
                out[1] += wgt * lut[t[1] as usize];
                out[2] += wgt * lut[t[2] as usize];
                out[3] += wgt * (t[3] as f32 / 255.0);
            }
        }
        out
    }
}

/// Texel index `i` (any integer value, as f64) wrapped into `0..n`.
#[inline]
fn wrap(i: f64, n: u32, mode: Wrap) -> u32 {
    let n64 = n as f64;
    let r = match mode {
        Wrap::Repeat => i.rem_euclid(n64),
        Wrap::Clamp => i.clamp(0.0, n64 - 1.0),
        Wrap::Mirror => {
            let m = i.rem_euclid(2.0 * n64);
            if m >= n64 {
                2.0 * n64 - 1.0 - m
            } else {
                m
            }
        }
    };
    // NaN (a non-finite coordinate) becomes texel 0
    (r as u32).min(n - 1)
}

/// The decoded textures of a mesh's material table.
#[derive(Clone, Debug, Default)]
pub struct TextureSet {
    by_material: Vec<Option<Arc<Texture>>>,
    /// What could not be used, each naming the file (the material's colour factor is used).
    pub warnings: Vec<String>,
}

impl TextureSet {
    /// Loads the texture of every material that has one (each file once).
    pub fn load(materials: &[Material]) -> TextureSet {
        let mut set = TextureSet::default();
        let mut seen: Vec<(std::path::PathBuf, [Wrap; 2], Option<Arc<Texture>>)> = Vec::new();
        for m in materials {
            let Some(path) = &m.texture else {
                set.by_material.push(None);
                continue;
            };
            if let Some((_, _, t)) = seen.iter().find(|(p, w, _)| p == path && *w == m.wrap) {
                set.by_material.push(t.clone());
                continue;
            }
            let loaded = match &m.embedded {
                Some(bytes) => Texture::decode(&bytes.0, m.wrap),
                None => Texture::load(path, m.wrap),
            };
            let t = match loaded {
                Ok(t) => Some(Arc::new(t)),
                Err(e) => {
                    set.warnings.push(format!(
                        "texture {} of material {:?} cannot be read ({e}); the material's colour is used",
                        path.display(),
                        m.name
                    ));
                    None
                }
            };
            seen.push((path.clone(), m.wrap, t.clone()));
            set.by_material.push(t);
        }
        set
    }

    /// A set from textures already decoded (`None`: an untextured material), for tests.
    pub fn from_textures(by_material: Vec<Option<Texture>>) -> TextureSet {
        TextureSet {
            by_material: by_material.into_iter().map(|t| t.map(Arc::new)).collect(),
            warnings: Vec::new(),
        }
    }

    /// The texture of material `m`, if it has a usable one.
    #[inline]
    pub fn get(&self, m: u32) -> Option<&Texture> {
        self.by_material.get(m as usize).and_then(|t| t.as_deref())
    }

    /// True if no material has a usable texture.
    pub fn is_empty(&self) -> bool {
        self.by_material.iter().all(|t| t.is_none())
    }

    /// Bytes of the decoded pyramids (each file counted once).
    pub fn bytes(&self) -> usize {
        let mut seen: Vec<*const Texture> = Vec::new();
        let mut n = 0;
        for t in self.by_material.iter().flatten() {
            let p = Arc::as_ptr(t);
            if !seen.contains(&p) {
                seen.push(p);
                n += t.bytes();
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(s: &mut u64) -> u8 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 56) as u8
    }

    #[test]
    fn transfer_functions_round_trip_every_code() {
        for i in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb_to_linear(i as f32 / 255.0)), i);
        }
    }

    /// Every mip texel is the linear-light mean of its level-0 block, rounded once (compared
    /// with a direct f64 average), on a power-of-two and an odd-sized random image.
    #[test]
    fn mips_are_box_filters_of_level_0() {
        let mut s = 7u64;
        for (w, h) in [(16u32, 8u32), (13, 7)] {
            let texels: Vec<[u8; 4]> = (0..w * h)
                .map(|_| [lcg(&mut s), lcg(&mut s), lcg(&mut s), lcg(&mut s)])
                .collect();
            let t = Texture::from_rgba8(w, h, texels.clone(), [Wrap::Repeat; 2]).unwrap();
            for k in 1..t.levels() {
                let (wk, hk) = ((w >> k).max(1), (h >> k).max(1));
                for j in 0..hk {
                    for i in 0..wk {
                        let mut sum = [0f64; 4];
                        let mut n = 0;
                        for y in 0..h {
                            for x in 0..w {
                                if (x as u64 * wk as u64 / w as u64) as u32 == i
                                    && (y as u64 * hk as u64 / h as u64) as u32 == j
                                {
                                    let c = texels[(y * w + x) as usize];
                                    for q in 0..3 {
                                        sum[q] += srgb_to_linear(c[q] as f32 / 255.0) as f64;
                                    }
                                    sum[3] += c[3] as f64;
                                    n += 1;
                                }
                            }
                        }
                        let want = [
                            linear_to_srgb8((sum[0] / n as f64) as f32),
                            linear_to_srgb8((sum[1] / n as f64) as f32),
                            linear_to_srgb8((sum[2] / n as f64) as f32),
                            (sum[3] / n as f64).round() as u8,
                        ];
                        assert_eq!(t.texel(k, i, j), want, "{w}×{h} level {k} ({i}, {j})");
                    }
                }
            }
        }
    }

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1.0, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(9.0, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1.0, 4, Wrap::Clamp), 0);
        assert_eq!(wrap(9.0, 4, Wrap::Clamp), 3);
        assert_eq!(wrap(4.0, 4, Wrap::Mirror), 3);
        assert_eq!(wrap(-1.0, 4, Wrap::Mirror), 0);
        assert_eq!(wrap(f64::NAN, 4, Wrap::Repeat), 0);
    }

    #[test]
    fn texel_centres_and_v_up() {
        // 2×2: top row red, green; bottom row blue, white
        let t = Texture::from_rgba8(
            2,
            2,
            vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 255],
            ],
            [Wrap::Clamp; 2],
        )
        .unwrap();
        // u = 0.25, v = 0.75: the centre of the top-left texel
        assert_eq!(t.sample(0.25, 0.75, 0.0), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(t.sample(0.25, 0.25, 0.0), [0.0, 0.0, 1.0, 1.0]);
        // repeat wraps a whole period
        let r = Texture::from_rgba8(2, 2, t.levels[0].texels.clone(), [Wrap::Repeat; 2]).unwrap();
        assert_eq!(r.sample(3.25, -0.25, 0.0), [1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn load_reports_bad_files() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("bad.png");
        std::fs::write(&p, b"not an image").unwrap();
        let set = TextureSet::load(&[
            Material::default(),
            Material {
                name: "m".into(),
                texture: Some(p.clone()),
                wrap: [Wrap::Repeat; 2],
                embedded: None,
            },
        ]);
        assert!(set.get(1).is_none() && set.is_empty());
        assert_eq!(set.warnings.len(), 1);
        assert!(set.warnings[0].contains("bad.png"), "{:?}", set.warnings);
    }

    #[test]
    fn embedded_bytes_decode_as_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("g.png");
        image::RgbaImage::from_fn(5, 3, |x, y| {
            image::Rgba([(40 * x) as u8, (80 * y) as u8, 7, 200])
        })
        .save(&p)
        .unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let m = Material {
            name: "e".into(),
            texture: Some(std::path::PathBuf::from("scene.glb#image 0")),
            wrap: [Wrap::Clamp; 2],
            embedded: Some(voxlod_geom::Embedded(bytes.into())),
        };
        let set = TextureSet::load(&[Material::default(), m]);
        assert!(set.warnings.is_empty(), "{:?}", set.warnings);
        let file = Texture::load(&p, [Wrap::Clamp; 2]).unwrap();
        let t = set.get(1).unwrap();
        assert_eq!(t.size(), (5, 3));
        for k in 0..t.levels() {
            let (w, h) = (t.levels[k].w, t.levels[k].h);
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(t.texel(k, x, y), file.texel(k, x, y));
                }
            }
        }
        assert_eq!(t.texel(0, 4, 2), [160, 160, 7, 200]);
    }
}
