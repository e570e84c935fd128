//! A mesh's textures inside a share of the memory budget: whole in memory when their decoded
//! pyramids, and the decoding of the largest image beside them, fit the share (as
//! [`TextureSet::load`]), otherwise decoded one at a time into the tile file
//! ([`crate::tile_file`]) — a non-interlaced PNG row by row ([`crate::png_rows`]), so even one
//! image bigger than the share is held to it; another image whole, refused with a warning when
//! its decoding alone exceeds the share — and sampled through one shared [`TileCache`] of the
//! share's bytes. The sizes are read from the image headers first, so the choice is made
//! before anything is decoded. A resumed build reuses a complete tile file of the same
//! sources (length, CRC and keys checked) and rebuilds any other.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use voxlod_geom::{Material, Wrap};
use voxlod_io::{fnv1a, mtime_ns, FNV1A_OFFSET};

use crate::png_rows::{is_png, PngRows};
use crate::pyramid::pyramid_bytes;
use crate::tile_cache::{CacheStats, TileCache, MIN_CAPACITY};
use crate::tile_file::{open_complete, Entry, TileWriter};
use crate::{Texture, TextureSet};

/// A tiled texture set's file and cache (see the module docs).
#[derive(Clone, Debug)]
pub struct TileSummary {
    /// The cache's share of the memory plan, bytes.
    pub share: u64,
    /// Bytes of the decoded pyramids (what holding them whole would take).
    pub decoded_bytes: u64,
    /// The tile file.
    pub file: PathBuf,
    /// Its size, bytes.
    pub file_bytes: u64,
    /// True if a complete tile file of an interrupted build was reused.
    pub reused: bool,
    cache: Arc<TileCache>,
}

impl TileSummary {
    /// What the cache did so far (its peak resident bytes among them).
    pub fn stats(&self) -> CacheStats {
        self.cache.stats()
    }

    /// The first read error of the tile file, naming it (see [`TileCache::error`]).
    pub fn error(&self) -> Option<String> {
        self.cache.error()
    }
}

/// One distinct texture source (file or embedded image) and the wrap it is sampled with.
struct Source<'a> {
    m: &'a Material,
    path: &'a Path,
    wrap: [Wrap; 2],
}

/// The distinct texture sources of `materials`, as `TextureSet::load` dedups them (same path
/// and wrap modes), and each material's source.
fn distinct_sources(materials: &[Material]) -> (Vec<Source<'_>>, Vec<Option<usize>>) {
    let mut sources: Vec<Source> = Vec::new();
    let mut of_material = Vec::with_capacity(materials.len());
    for m in materials {
        of_material.push(m.texture.as_deref().map(|path| {
            let found = sources
                .iter()
                .position(|s| s.path == path && s.wrap == m.wrap);
            found.unwrap_or_else(|| {
                sources.push(Source {
                    m,
                    path,
                    wrap: m.wrap,
                });
                sources.len() - 1
            })
        }));
    }
    (sources, of_material)
}

impl Source<'_> {
    /// The image's size from its header alone.
    fn probe(&self) -> Result<(u32, u32), String> {
        let size = match &self.m.embedded {
            Some(b) => image::ImageReader::new(std::io::Cursor::new(&b.0[..]))
                .with_guessed_format()
                .map_err(|e| e.to_string())?
                .into_dimensions(),
            None => crate::open_image(self.path)?.into_dimensions(),
        };
        size.map_err(|e| e.to_string())
    }

    /// Adds the texture's pyramid to the tile file, decoding it within `share` bytes: a
    /// non-interlaced PNG row by row ([`crate::png_rows`], a few rows of each level in memory),
    /// any other image whole as the in-memory path decodes it, if its texels and their RGBA8
    /// copy fit the share. `Ok(Err)` is a texture that cannot be read (a warning).
    fn add_tiles(
        &self,
        out: &mut TileWriter,
        key: u64,
        size: (u32, u32),
        share: u64,
    ) -> std::io::Result<Result<Entry, String>> {
        // the PNG decoder's own buffers (chunks, a row) stay far below this
        const PNG_DECODER_BYTES: usize = 64 << 20;
        let streamed = match &self.m.embedded {
            Some(b) if is_png(&b.0) => {
                PngRows::open(std::io::Cursor::new(&b.0[..]), PNG_DECODER_BYTES)
                    .map(|r| r.map(Rows::Embedded))
            }
            Some(_) => Ok(None),
            None => match png_file(self.path) {
                Ok(Some(f)) => PngRows::open(f, PNG_DECODER_BYTES).map(|r| r.map(Rows::File)),
                Ok(None) => Ok(None),
                Err(e) => Err(e),
            },
        };
        let mut rows = match streamed {
            Ok(Some(rows)) => rows,
            Ok(None) => {
                // whole: the decoded image and its RGBA8 copy
                let (w, h) = size;
                let whole = 2 * w as u64 * h as u64 * 4;
                if whole > share {
                    return Ok(Err(format!(
                        "{w}×{h} texels take {} to decode whole, more than the {} of the memory \
                         budget for textures (only non-interlaced PNGs are decoded by rows); \
                         raise --memory or convert it to a non-interlaced PNG",
                        mib(whole),
                        mib(share)
                    )));
                }
                let img = match crate::read_image(self.path, self.m.embedded.as_ref()) {
                    Ok(img) => img.into_rgba8(),
                    Err(e) => return Ok(Err(e)),
                };
                let (w, h) = img.dimensions();
                return out
                    .add(key, bytemuck::cast_slice(img.as_raw()), w, h)
                    .map(Ok);
            }
            Err(e) => return Ok(Err(e)),
        };
        let (w, h) = rows.size();
        out.add_rows(key, w, h, &mut |r| rows.next(r))
    }

    /// The identity the tile file records: the path with the file's size and modification
    /// time, or the embedded bytes.
    fn key(&self) -> u64 {
        let h = fnv1a(self.path.as_os_str().as_encoded_bytes(), FNV1A_OFFSET);
        match &self.m.embedded {
            Some(b) => fnv1a(&b.0, h),
            None => {
                let meta = std::fs::metadata(self.path).ok();
                let len = meta.as_ref().map_or(0, |m| m.len());
                let mtime = meta.as_ref().map_or(0, |m| mtime_ns(m) as u64);
                fnv1a(&mtime.to_le_bytes(), fnv1a(&len.to_le_bytes(), h))
            }
        }
    }

    fn warning(&self, e: &str) -> String {
        format!(
            "texture {} of material {:?} cannot be read ({e}); the material's colour is used",
            self.path.display(),
            self.m.name
        )
    }
}

/// The rows of a PNG texture, from its embedded bytes or its file.
enum Rows<'a> {
    Embedded(PngRows<std::io::Cursor<&'a [u8]>>),
    File(PngRows<std::io::BufReader<std::fs::File>>),
}

impl Rows<'_> {
    fn size(&self) -> (u32, u32) {
        match self {
            Rows::Embedded(r) => r.size(),
            Rows::File(r) => r.size(),
        }
    }

    fn next(&mut self, out: &mut [[u8; 4]]) -> Result<(), String> {
        match self {
            Rows::Embedded(r) => r.next(out),
            Rows::File(r) => r.next(out),
        }
    }
}

/// The texture file at `path`, opened at its start, if it is a PNG (a regular file only).
fn png_file(path: &Path) -> Result<Option<std::io::BufReader<std::fs::File>>, String> {
    use std::io::{Read, Seek};
    let mut f = voxlod_io::open_regular(path).map_err(|e| e.to_string())?;
    let mut head = Vec::with_capacity(8);
    (&mut f)
        .take(8)
        .read_to_end(&mut head)
        .map_err(|e| e.to_string())?;
    f.rewind().map_err(|e| e.to_string())?;
    Ok(is_png(&head).then(|| std::io::BufReader::new(f)))
}

/// `bytes` in MiB, for messages.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
}

/// Bytes of the decoded pyramids of textures of `sizes` (those whose header was read).
fn decoded_bytes(sizes: &[Option<(u32, u32)>]) -> u64 {
    sizes
        .iter()
        .flatten()
        .map(|&(w, h)| pyramid_bytes(w, h))
        .sum()
}

/// True if textures of `sizes` are held whole within `share`: their pyramids and, beside
/// them, the whole decoding of the largest image (its texels and their RGBA8 copy: a 16384²
/// PNG is 1 GiB of RGBA8 before its pyramid).
fn held_whole(sizes: &[Option<(u32, u32)>], share: u64) -> bool {
    let decoding: u64 = sizes
        .iter()
        .flatten()
        .map(|&(w, h)| 2 * w as u64 * h as u64 * 4)
        .max()
        .unwrap_or(0);
    decoded_bytes(sizes) + decoding <= share
}

impl TextureSet {
    /// The size of the tile file [`TextureSet::load_within`] writes for `materials` within
    /// `share` bytes, from the images' headers (nothing is decoded): 0 when the textures are
    /// held whole, else their pyramids' tiles, which is the most it writes (a texture that
    /// turns out unreadable writes fewer). A build counts it in its temporary disk before any
    /// texture is decoded.
    pub fn tile_file_bytes(materials: &[Material], share: u64) -> u64 {
        let (sources, _) = distinct_sources(materials);
        let sizes: Vec<Option<(u32, u32)>> = sources.iter().map(|s| s.probe().ok()).collect();
        if held_whole(&sizes, share) {
            return 0;
        }
        let read: Vec<(u32, u32)> = sizes.into_iter().flatten().collect();
        crate::tile_file::file_bytes(&read)
    }

    /// The textures of `materials` within `share` bytes (≥ [`MIN_CAPACITY`]): whole in memory
    /// if their decoded pyramids fit, otherwise through a tile cache of `share` bytes over the
    /// tile file `tile_file` (reused if complete, else written; see the module docs). A
    /// texture that cannot be read is a warning, as with [`TextureSet::load`]; an error is a
    /// failure to write or read the tile file, naming it.
    pub fn load_within(
        materials: &[Material],
        share: u64,
        tile_file: &Path,
    ) -> Result<TextureSet, String> {
        assert!(share >= MIN_CAPACITY, "a texture share of {share} bytes");
        let (sources, of_material) = distinct_sources(materials);
        let mut warnings = Vec::new();
        let sizes: Vec<Option<(u32, u32)>> = sources
            .iter()
            .map(|s| s.probe().map_err(|e| warnings.push(s.warning(&e))).ok())
            .collect();
        let decoded = decoded_bytes(&sizes);
        if held_whole(&sizes, share) {
            return Ok(TextureSet::load(materials));
        }
        let probed: Vec<usize> = (0..sources.len()).filter(|&i| sizes[i].is_some()).collect();
        let keys: Vec<u64> = probed.iter().map(|&i| sources[i].key()).collect();
        let what =
            |e: std::io::Error| format!("{}: writing the texture tiles: {e}", tile_file.display());
        let (entries, reused) = match open_complete(tile_file, &keys) {
            Some(entries) => (probed.iter().copied().zip(entries).collect(), true),
            None => {
                let mut out = TileWriter::create(tile_file).map_err(what)?;
                let mut written = Vec::new();
                for (&i, &key) in probed.iter().zip(&keys) {
                    // one texture at a time, by rows where it can be, dropped once its tiles
                    // are written
                    let size = sizes[i].expect("probed");
                    match sources[i]
                        .add_tiles(&mut out, key, size, share)
                        .map_err(what)?
                    {
                        Ok(_) => written.push(i),
                        Err(e) => warnings.push(sources[i].warning(&e)),
                    }
                }
                let entries = out.finish().map_err(what)?;
                (written.into_iter().zip(entries).collect::<Vec<_>>(), false)
            }
        };
        let cache = Arc::new(
            TileCache::open(tile_file, share)
                .map_err(|e| format!("{}: opening the texture tiles: {e}", tile_file.display()))?,
        );
        let mut textures: Vec<Option<Arc<Texture>>> = vec![None; sources.len()];
        for (i, e) in &entries {
            textures[*i] = Some(Arc::new(Texture::tiled(e, cache.clone(), sources[*i].wrap)));
        }
        let file_bytes = std::fs::metadata(tile_file).map_or(0, |m| m.len());
        Ok(TextureSet {
            by_material: of_material
                .into_iter()
                .map(|s| s.and_then(|i| textures[i].clone()))
                .collect(),
            warnings,
            tiles: Some(TileSummary {
                share,
                decoded_bytes: decoded,
                file: tile_file.to_path_buf(),
                file_bytes,
                reused,
                cache,
            }),
        })
    }

    /// The tile file and cache, if the textures are read by tile.
    pub fn tiles(&self) -> Option<&TileSummary> {
        self.tiles.as_ref()
    }
}
