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

use crate::pyramid::{box_level, level_sizes};
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
            out: BufWriter::with_capacity(1 << 20, File::create(&part)?),
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
        let (tx, ty) = level_tiles(w, h);
        let mut tile = vec![[0u8; 4]; (TILE * TILE) as usize];
        for j in 0..ty {
            for i in 0..tx {
                tile.iter_mut().for_each(|t| *t = [0; 4]);
                let x0 = i * TILE;
                let x1 = (x0 + TILE).min(w);
                for y in j * TILE..((j + 1) * TILE).min(h) {
                    let src = &texels[(y * w + x0) as usize..(y * w + x1) as usize];
                    let row = ((y - j * TILE) * TILE) as usize;
                    tile[row..row + src.len()].copy_from_slice(src);
                }
                self.put(bytemuck::cast_slice(&tile))?;
                self.tiles += 1;
            }
        }
        Ok(())
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
