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

mod png_rows;
mod pyramid;
mod tile_cache;
mod tile_file;
mod tiled_set;

pub use tile_cache::{CacheStats, Tile, TileCache, MIN_CAPACITY, TILE, TILE_BYTES};
pub use tiled_set::TileSummary;

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
pub(crate) fn lut() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

/// Where a texture's texels are: every level in memory, or tiles of the tile file read
/// through the shared tile cache.
#[derive(Clone, Debug)]
enum Store {
    /// Each level's `w × h` texels, row 0 at the top.
    Memory(Vec<Vec<[u8; 4]>>),
    /// The pyramid's tiles from `first_tile` on in the tile file ([`tile_file`]).
    Tiles {
        cache: Arc<TileCache>,
        /// index of each level's first tile
        first: Vec<u64>,
    },
}

/// An RGBA8 texture and its mip pyramid (see the crate docs), held whole in memory or read
/// by tile through a [`TileCache`]; both sample with the same arithmetic.
#[derive(Clone, Debug)]
pub struct Texture {
    /// each level's size, level 0 first
    sizes: Vec<(u32, u32)>,
    store: Store,
    wrap: [Wrap; 2],
}

impl Texture {
    /// The texture of a `w × h` image (`texels` row by row from the top) with its pyramid:
    /// level `k` is `max(1, w >> k) × max(1, h >> k)`, down to 1×1; its texel `(i, j)`
    /// averages, in linear light, the level-0 texels `(x, y)` with `⌊x·w_k/w⌋ = i` and
    /// `⌊y·h_k/h⌋ = j` (a partition of the image, so odd sizes lose nothing; [`pyramid`]).
    /// `Err` if the sizes do not match or are zero.
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
        let sizes = pyramid::level_sizes(w, h);
        let mut levels = Vec::with_capacity(sizes.len());
        for k in 1..sizes.len() {
            levels.push(pyramid::box_level(&texels, w, h, k as u32));
        }
        levels.insert(0, texels);
        Ok(Texture {
            sizes,
            store: Store::Memory(levels),
            wrap,
        })
    }

    /// The texture of a tile file's entry, read through `cache`.
    fn tiled(e: &tile_file::Entry, cache: Arc<TileCache>, wrap: [Wrap; 2]) -> Texture {
        let sizes = pyramid::level_sizes(e.w, e.h);
        let mut first = Vec::with_capacity(sizes.len());
        let mut next = e.first_tile;
        for &(w, h) in &sizes {
            first.push(next);
            let (tx, ty) = tile_file::level_tiles(w, h);
            next += tx as u64 * ty as u64;
        }
        Texture {
            sizes,
            store: Store::Tiles { cache, first },
            wrap,
        }
    }

    /// True if the texture is read by tile through a cache (not held whole in memory).
    pub fn is_tiled(&self) -> bool {
        matches!(self.store, Store::Tiles { .. })
    }

    /// Decodes a PNG or JPEG file (the format is taken from its content) into a texture.
    pub fn load(path: &Path, wrap: [Wrap; 2]) -> Result<Texture, String> {
        Self::from_image(read_image(path, None)?, wrap)
    }

    /// Decodes PNG or JPEG bytes held in memory (a glTF embedded image) into a texture.
    pub fn decode(bytes: &[u8], wrap: [Wrap; 2]) -> Result<Texture, String> {
        Self::from_image(decode_bytes(bytes)?, wrap)
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
        self.sizes[0]
    }

    /// Number of mip levels (level 0 up to 1×1).
    pub fn levels(&self) -> usize {
        self.sizes.len()
    }

    /// Bytes the decoded pyramid takes (RGBA8, every level), held in memory or not.
    pub fn bytes(&self) -> usize {
        self.sizes
            .iter()
            .map(|&(w, h)| w as usize * h as usize * 4)
            .sum()
    }

    /// The texel of level `k` at `(x, y)` (row 0 at the top).
    pub fn texel(&self, k: usize, x: u32, y: u32) -> [u8; 4] {
        let (w, h) = self.sizes[k];
        assert!(x < w && y < h, "texel ({x}, {y}) of a {w}×{h} level");
        match &self.store {
            Store::Memory(levels) => levels[k][(y * w + x) as usize],
            Store::Tiles { cache, first } => TileReader::new(cache, first[k], w).texel(x, y),
        }
    }

    /// The filtered colour at texture coordinates `(u, v)` and level of detail `lod`
    /// (`log2` of the footprint in level-0 texels; clamped to the pyramid): linear-light RGB in
    /// 0..=1 and straight alpha in 0..=1. Trilinear: bilinear in levels `⌊lod⌋` and `⌊lod⌋+1`,
    /// blended by the fraction.
    pub fn sample(&self, u: f64, v: f64, lod: f32) -> [f32; 4] {
        let top = (self.sizes.len() - 1) as f32;
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
        let (w, h) = self.sizes[k];
        let x = u * w as f64 - 0.5;
        let y = (1.0 - v) * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let xs = [wrap(x0, w, self.wrap[0]), wrap(x0 + 1.0, w, self.wrap[0])];
        let ys = [wrap(y0, h, self.wrap[1]), wrap(y0 + 1.0, h, self.wrap[1])];
        match &self.store {
            Store::Memory(levels) => {
                let l = &levels[k];
                weigh(xs, ys, fx, fy, |x, y| l[(y * w + x) as usize])
            }
            Store::Tiles { cache, first } => {
                let mut tiles = TileReader::new(cache, first[k], w);
                weigh(xs, ys, fx, fy, |x, y| tiles.texel(x, y))
            }
        }
    }
}

/// The bilinear filter of the texels `(xs[i], ys[j])` with the fractions `(fx, fy)`, in
/// linear light (straight alpha); texels of weight 0 are not looked up.
#[inline]
fn weigh(
    xs: [u32; 2],
    ys: [u32; 2],
    fx: f32,
    fy: f32,
    mut texel: impl FnMut(u32, u32) -> [u8; 4],
) -> [f32; 4] {
    let lut = lut();
    let mut out = [0f32; 4];
    for (j, wy) in [(0, 1.0 - fy), (1, fy)] {
        for (i, wx) in [(0, 1.0 - fx), (1, fx)] {
            let wgt = wx * wy;
            if wgt == 0.0 {
                continue;
            }
            let t = texel(xs[i], ys[j]);
            out[0] += wgt * lut[t[0] as usize];
            out[1] += wgt * lut[t[1] as usize];
            out[2] += wgt * lut[t[2] as usize];
            out[3] += wgt * (t[3] as f32 / 255.0);
        }
    }
    out
}

/// Texel lookups in one level of a tiled texture: the tile of the last lookup is kept, so
/// the four texels of a bilinear lookup cost one cache lookup unless they straddle tiles.
struct TileReader<'a> {
    cache: &'a TileCache,
    first: u64,
    across: u64,
    held: Option<(u64, Tile)>,
}

impl<'a> TileReader<'a> {
    fn new(cache: &'a TileCache, first: u64, w: u32) -> TileReader<'a> {
        TileReader {
            cache,
            first,
            across: w.div_ceil(TILE) as u64,
            held: None,
        }
    }

    #[inline]
    fn texel(&mut self, x: u32, y: u32) -> [u8; 4] {
        let id = self.first + (y / TILE) as u64 * self.across + (x / TILE) as u64;
        let tile = match &self.held {
            Some((i, t)) if *i == id => t,
            _ => &self.held.insert((id, self.cache.tile(id))).1,
        };
        tile[((y % TILE) * TILE + x % TILE) as usize]
    }
}

/// The image of a material's texture: its embedded bytes if any, else the file `path`, the
/// format taken from the content (PNG or JPEG).
pub(crate) fn read_image(
    path: &Path,
    embedded: Option<&voxlod_geom::Embedded>,
) -> Result<image::DynamicImage, String> {
    if let Some(b) = embedded {
        return decode_bytes(&b.0);
    }
    open_image(path)?.decode().map_err(|e| e.to_string())
}

/// A reader of the image file `path`, its format guessed from the content; only a regular
/// file is opened (a FIFO would block the reader, a device never end).
pub(crate) fn open_image(
    path: &Path,
) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>, String> {
    let f = voxlod_io::open_regular(path).map_err(|e| e.to_string())?;
    image::ImageReader::new(std::io::BufReader::new(f))
        .with_guessed_format()
        .map_err(|e| e.to_string())
}

fn decode_bytes(bytes: &[u8]) -> Result<image::DynamicImage, String> {
    image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| e.to_string())
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
    /// The tile file and cache of a set read by tile ([`TextureSet::load_within`]).
    tiles: Option<TileSummary>,
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
            tiles: None,
        }
    }

    /// The texture of material `m`, if it has a usable one.
    #[inline]
    pub fn get(&self, m: u32) -> Option<&Texture> {
        self.by_material.get(m as usize).and_then(|t| t.as_deref())
    }

    /// The usable textures, material by material (a texture shared by materials repeats).
    pub fn textures(&self) -> impl Iterator<Item = &Texture> {
        self.by_material.iter().flatten().map(|t| &**t)
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
        let r = Texture::from_rgba8(
            2,
            2,
            match &t.store {
                Store::Memory(l) => l[0].clone(),
                _ => unreachable!(),
            },
            [Wrap::Repeat; 2],
        )
        .unwrap();
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
            let (w, h) = t.sizes[k];
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(t.texel(k, x, y), file.texel(k, x, y));
                }
            }
        }
        assert_eq!(t.texel(0, 4, 2), [160, 160, 7, 200]);
    }
}
