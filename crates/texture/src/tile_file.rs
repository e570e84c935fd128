//! The tile file: the decoded mip pyramids of a build's textures, cut into 64×64 RGBA8 tiles
//! (sRGB colour, linear alpha, as the samplers read them), written once to the work folder
//! and read back tile by tile through [`crate::tile_cache::TileCache`].
//!
//! Layout (little-endian): the tiles, 16,384 bytes each, texture after texture, level 0 first,
//! each level's tiles row by row (`⌈w_k/64⌉ × ⌈h_k/64⌉`; a level's edge tiles padded with
//! zeros, which no lookup reads); then one entry per texture (`key` u64, `w` u32, `h` u32,
//! `first_tile` u64); then the entry count u64, the tile count u64, the CRC-32 of every byte
//! before it, and the magic `VXTILES1`. The file is written as `NAME.part` and renamed when
//! complete, and a resumed build trusts it only if its length, CRC and keys (the sources'
//! identities) all match: a truncated or corrupt file is rebuilt.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::pyramid::{box_level, level_sizes, LevelRows};
use crate::tile_cache::{TILE, TILE_BYTES};

const MAGIC: &[u8; 8] = b"VXTILES1";
const ENTRY_BYTES: u64 = 24;
const TAIL_BYTES: u64 = 8 + 8 + 4 + 8;

/// One texture of the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Entry {
    /// The identity of its source (path, size and modification time, or embedded bytes).
    pub key: u64,
    pub w: u32,
    pub h: u32,
    /// Index of its first tile (level 0's top-left).
    pub first_tile: u64,
}

/// Tiles of a `w × h` level: across and down.
pub(crate) fn level_tiles(w: u32, h: u32) -> (u32, u32) {
    (w.div_ceil(TILE), h.div_ceil(TILE))
}

/// Bytes of a tile file holding the pyramids of textures of `sizes`: their tiles, an entry
/// each and the tail.
pub(crate) fn file_bytes(sizes: &[(u32, u32)]) -> u64 {
    let tiles: u64 = sizes.iter().map(|&(w, h)| pyramid_tiles(w, h)).sum();
    tiles * TILE_BYTES + sizes.len() as u64 * ENTRY_BYTES + TAIL_BYTES
}

/// Tiles of the whole pyramid of a `w × h` texture.
pub(crate) fn pyramid_tiles(w: u32, h: u32) -> u64 {
    level_sizes(w, h)
        .iter()
        .map(|&(a, b)| {
            let (x, y) = level_tiles(a, b);
            x as u64 * y as u64
        })
        .sum()
}

/// The tiles of one band of a level `w` texels wide (up to 64 of its rows, row 0 of the band
/// at the top of the tiles), left to right, into `out`: each tile's rows of 64 texels, padded
/// with zeros past the level's right and bottom edges.
fn band_tiles(band: &[[u8; 4]], w: u32, out: &mut Vec<u8>) {
    let rows = band.len() / w as usize;
    assert!(rows as u32 <= TILE && rows * w as usize == band.len());
    let tx = w.div_ceil(TILE);
    out.clear();
    out.resize(tx as usize * TILE_BYTES as usize, 0);
    let tile_row_bytes = (TILE * 4) as usize;
    for i in 0..tx {
        let (x0, x1) = (i * TILE, ((i + 1) * TILE).min(w));
        let tile = &mut out[i as usize * TILE_BYTES as usize..][..TILE_BYTES as usize];
        for y in 0..rows {
            let src = &band[y * w as usize + x0 as usize..y * w as usize + x1 as usize];
            tile[y * tile_row_bytes..][..src.len() * 4].copy_from_slice(bytemuck::cast_slice(src));
        }
    }
}

/// Writes a tile file: textures added one at a time, the file renamed into place by
/// [`TileWriter::finish`].
pub(crate) struct TileWriter {
    out: BufWriter<File>,
    crc: crc32fast::Hasher,
    tiles: u64,
    entries: Vec<Entry>,
    part: PathBuf,
    path: PathBuf,
}

impl TileWriter {
    pub(crate) fn create(path: &Path) -> std::io::Result<TileWriter> {
        let mut part = path.as_os_str().to_owned();
        part.push(".part");
        let part = PathBuf::from(part);
        Ok(TileWriter {
            // read too: a texture added by rows is read back for the CRC
            out: BufWriter::with_capacity(
                1 << 20,
                std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&part)?,
            ),
            crc: crc32fast::Hasher::new(),
            tiles: 0,
            entries: Vec::new(),
            part,
            path: path.to_path_buf(),
        })
    }

    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.crc.update(bytes);
        self.out.write_all(bytes)
    }

    /// Adds the texture of level-0 texels `base` (`w × h`, row 0 at the top): every level of
    /// its pyramid ([`crate::pyramid`]) in tiles, one level in memory beside level 0.
    pub(crate) fn add(
        &mut self,
        key: u64,
        base: &[[u8; 4]],
        w: u32,
        h: u32,
    ) -> std::io::Result<Entry> {
        let entry = Entry {
            key,
            w,
            h,
            first_tile: self.tiles,
        };
        self.write_level(base, w, h)?;
        for (k, &(wk, hk)) in level_sizes(w, h).iter().enumerate().skip(1) {
            let level = box_level(base, w, h, k as u32);
            self.write_level(&level, wk, hk)?;
        }
        debug_assert_eq!(self.tiles - entry.first_tile, pyramid_tiles(w, h));
        self.entries.push(entry);
        Ok(entry)
    }

    /// The tiles of one `w × h` level, row by row.
    fn write_level(&mut self, texels: &[[u8; 4]], w: u32, h: u32) -> std::io::Result<()> {
        assert_eq!(texels.len() as u64, w as u64 * h as u64);
        let mut tiles = Vec::new();
        for band in texels.chunks((w * TILE) as usize) {
            band_tiles(band, w, &mut tiles);
            self.put(&tiles)?;
            self.tiles += w.div_ceil(TILE) as u64;
        }
        Ok(())
    }

    /// Adds a `w × h` texture whose level-0 rows `next_row` writes one at a time, top to
    /// bottom (a PNG decoded row by row): level 0 and every other level of its pyramid are cut
    /// into tiles as their rows complete and written in place, so memory holds 64 rows of each
    /// level, not the image. The tiles are the bytes [`add`](Self::add) writes for the same
    /// texels. When `next_row` fails, nothing of the texture stays in the file and its error
    /// is returned as `Ok(Err(..))`; `Err` is a failure to write or read the file.
    pub(crate) fn add_rows(
        &mut self,
        key: u64,
        w: u32,
        h: u32,
        next_row: &mut dyn FnMut(&mut [[u8; 4]]) -> Result<(), String>,
    ) -> std::io::Result<Result<Entry, String>> {
        use std::os::unix::fs::FileExt;
        self.out.flush()?;
        let first_tile = self.tiles;
        let sizes = level_sizes(w, h);
        // the first tile of each level, from the texture's first
        let mut level_first = Vec::with_capacity(sizes.len());
        let mut n = 0u64;
        for &(a, b) in &sizes {
            level_first.push(n);
            let (x, y) = level_tiles(a, b);
            n += x as u64 * y as u64;
        }
        let mut levels: Vec<LevelRows> = (1..sizes.len() as u32)
            .map(|k| LevelRows::new(w, h, k))
            .collect();
        // per level: the band of up to 64 rows being filled, and rows done
        let mut bands: Vec<(Vec<[u8; 4]>, u32)> = sizes
            .iter()
            .map(|&(a, _)| (Vec::with_capacity((a * TILE) as usize), 0))
            .collect();
        let mut row = vec![[0u8; 4]; w as usize];
        let (mut level_row, mut tiles) = (Vec::new(), Vec::new());
        let file = self.out.get_ref();
        // a finished row of level `k` goes into its band; a full (or last) band is written
        let mut put_row =
            |k: usize, texels: &[[u8; 4]], tiles: &mut Vec<u8>| -> std::io::Result<()> {
                let (wk, hk) = sizes[k];
                let (band, done) = &mut bands[k];
                band.extend_from_slice(texels);
                *done += 1;
                if *done % TILE == 0 || *done == hk {
                    band_tiles(band, wk, tiles);
                    let tile_row = (*done - 1) / TILE;
                    let at =
                        first_tile + level_first[k] + tile_row as u64 * wk.div_ceil(TILE) as u64;
                    file.write_all_at(tiles, at * TILE_BYTES)?;
                    band.clear();
                }
                Ok(())
            };
        for _ in 0..h {
            if let Err(e) = next_row(&mut row) {
                // nothing of this texture stays: the file ends where it began
                file.set_len(first_tile * TILE_BYTES)?;
                return Ok(Err(e));
            }
            put_row(0, &row, &mut tiles)?;
            for (k, level) in levels.iter_mut().enumerate() {
                if level.push(&row, &mut level_row) {
                    put_row(k + 1, &level_row, &mut tiles)?;
                }
            }
        }
        // the CRC runs over the file in order: read the texture's tiles back (from the page
        // cache, just written) and go on writing after them
        let (start, end) = (first_tile * TILE_BYTES, (first_tile + n) * TILE_BYTES);
        let mut buf = vec![0u8; 1 << 20];
        let mut at = start;
        while at < end {
            let len = ((end - at) as usize).min(buf.len());
            file.read_exact_at(&mut buf[..len], at)?;
            self.crc.update(&buf[..len]);
            at += len as u64;
        }
        self.out.seek(SeekFrom::Start(end))?;
        self.tiles += n;
        debug_assert_eq!(n, pyramid_tiles(w, h));
        let entry = Entry {
            key,
            w,
            h,
            first_tile,
        };
        self.entries.push(entry);
        Ok(Ok(entry))
    }

    /// Writes the entries and the tail, syncs and renames the file into place.
    pub(crate) fn finish(mut self) -> std::io::Result<Vec<Entry>> {
        let entries = std::mem::take(&mut self.entries);
        for e in &entries {
            let mut b = [0u8; ENTRY_BYTES as usize];
            b[0..8].copy_from_slice(&e.key.to_le_bytes());
            b[8..12].copy_from_slice(&e.w.to_le_bytes());
            b[12..16].copy_from_slice(&e.h.to_le_bytes());
            b[16..24].copy_from_slice(&e.first_tile.to_le_bytes());
            self.put(&b)?;
        }
        self.put(&(entries.len() as u64).to_le_bytes())?;
        let tiles = self.tiles;
        self.put(&tiles.to_le_bytes())?;
        let crc = self.crc.clone().finalize();
        self.out.write_all(&crc.to_le_bytes())?;
        self.out.write_all(MAGIC)?;
        let file = self.out.into_inner().map_err(|e| e.into_error())?;
        voxlod_io::commit(file, &self.part, &self.path)?;
        Ok(entries)
    }
}

/// The entries of the complete tile file at `path` if its keys are `keys` in order, every
/// texture has texels, and its length and CRC-32 match what it says; `None` otherwise (no file,
/// another build's, truncated or corrupt): the caller rebuilds it.
pub(crate) fn open_complete(path: &Path, keys: &[u64]) -> Option<Vec<Entry>> {
    let mut f = File::open(path).ok()?;
    let len = f.metadata().ok()?.len();
    if len < TAIL_BYTES {
        return None;
    }
    let mut tail = [0u8; TAIL_BYTES as usize];
    f.seek(SeekFrom::Start(len - TAIL_BYTES)).ok()?;
    f.read_exact(&mut tail).ok()?;
    let u64_at = |b: &[u8], i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap());
    let (n, tiles) = (u64_at(&tail, 0), u64_at(&tail, 8));
    let crc = u32::from_le_bytes(tail[16..20].try_into().unwrap());
    if &tail[20..28] != MAGIC || n != keys.len() as u64 {
        return None;
    }
    let body = tiles
        .checked_mul(TILE_BYTES)?
        .checked_add(n * ENTRY_BYTES)?;
    if body.checked_add(TAIL_BYTES)? != len {
        return None;
    }
    // the CRC covers the tiles, the entries and the two counts
    f.seek(SeekFrom::Start(0)).ok()?;
    let mut hasher = crc32fast::Hasher::new();
    let mut rest = len - 12;
    let mut buf = vec![0u8; 1 << 20];
    let mut entries_bytes = Vec::with_capacity((n * ENTRY_BYTES) as usize);
    while rest > 0 {
        let m = rest.min(buf.len() as u64) as usize;
        f.read_exact(&mut buf[..m]).ok()?;
        hasher.update(&buf[..m]);
        let at = len - 12 - rest; // offset of buf[0]
        let lo = (tiles * TILE_BYTES).max(at);
        let hi = (tiles * TILE_BYTES + n * ENTRY_BYTES).min(at + m as u64);
        if lo < hi {
            entries_bytes.extend_from_slice(&buf[(lo - at) as usize..(hi - at) as usize]);
        }
        rest -= m as u64;
    }
    if hasher.finalize() != crc {
        return None;
    }
    let mut next = 0u64;
    let mut entries = Vec::with_capacity(n as usize);
    for (b, &key) in entries_bytes.chunks_exact(ENTRY_BYTES as usize).zip(keys) {
        let e = Entry {
            key: u64_at(b, 0),
            w: u32::from_le_bytes(b[8..12].try_into().unwrap()),
            h: u32::from_le_bytes(b[12..16].try_into().unwrap()),
            first_tile: u64_at(b, 16),
        };
        if e.key != key || e.w == 0 || e.h == 0 || e.first_tile != next {
            return None;
        }
        next += pyramid_tiles(e.w, e.h);
        entries.push(e);
    }
    (next == tiles).then_some(entries)
}
