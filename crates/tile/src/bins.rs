//! Passes 2 and 3 of tiling: per-chunk counts, the non-empty chunks in Morton order, and the
//! budgeted scatter of the triangles into the bins file (each chunk's triangles as
//! [blocks](crate::block) appended in pieces).

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use voxlod_geom::{morton3, Grid, Triangle, CHUNK};

use crate::block::{BlockEncoder, BlockHeader, BLOCK_HEADER};
use crate::{Passes, RecordLayout, TileError};

/// Pass 2: counts, per leaf chunk, the triangles of `src` whose chunk range (see
/// [`Grid::chunk_range`]) includes it. `progress(done, total)` is in triangles.
pub fn count(
    src: &dyn Passes,
    grid: &Grid,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ChunkCounts, TileError> {
    let mut counts = ChunkCounts::new(grid)?;
    let keys = counts.keys();
    let mut done = 0u64;
    let total = src.count();
    // the chunk ranges where the triangles are read, the counting here
    src.for_each_prepared(&|tris| keys.of_world(tris), &mut |tris, k| {
        counts.add_keyed(tris, &k);
        done += tris.len() as u64;
        progress(done, total);
        Ok(())
    })?;
    Ok(counts)
}

/// Pass 3: writes the bins file at `path` (world coordinates, records laid out by `layout`),
/// buffering at most `buffer_bytes` of records in memory between flushes. `src` must yield
/// the triangles `counts` was made from.
pub fn scatter(
    src: &dyn Passes,
    grid: &Grid,
    counts: &ChunkCounts,
    path: &Path,
    layout: RecordLayout,
    buffer_bytes: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Bins, TileError> {
    assert_eq!(
        counts.grid(),
        grid,
        "scatter: the counts were made on another grid"
    );
    let mut sc = Scatter::create(grid, counts, path, layout, buffer_bytes)?;
    let keys = counts.keys();
    let mut done = 0u64;
    let total = src.count();
    // the chunk ranges where the triangles are read, the binning here; with dropped chunks, a
    // triangle in none of the kept ones is rejected there. The records keep the input's world
    // coordinates (the voxelizer decides on them exactly: `ChunkVoxelizer::add_world`).
    let prepare = |tris: &mut [Triangle]| {
        if !counts.dropped.is_empty() {
            return tris.iter_mut().map(|t| counts.keep_key(keys, t)).collect();
        }
        keys.of_world(tris)
    };
    src.for_each_prepared(&prepare, &mut |tris, k| {
        sc.push_keyed(tris, &k)?;
        done += tris.len() as u64;
        progress(done, total);
        Ok(())
    })?;
    sc.finish()
}

/// Triangle counts per leaf chunk of one grid, dense over its `(R/CHUNK)³` chunks: what the count
/// pass ([`count`]) makes, or a caller that already passes over the triangles (e.g. the ingest
/// pass, when the grid is known before it) with [`ChunkCounts::add_triangles`], or with
/// [`ChunkCounts::add_keyed`] and keys taken on the threads that read the triangles.
pub struct ChunkCounts {
    grid: Grid,
    n: u32,
    counts: Vec<u64>,
    /// Chunks dropped by [`ChunkCounts::retain`]: their triangles are not binned.
    dropped: Vec<bool>,
}

impl ChunkCounts {
    /// Zero counts over `grid`'s chunks; refused if there are more than 2³² chunks.
    pub fn new(grid: &Grid) -> Result<ChunkCounts, TileError> {
        let n = grid.chunks_per_axis();
        let total = (n as u64).pow(3);
        if total > u32::MAX as u64 {
            return Err(TileError::TooManyChunks(total));
        }
        Ok(ChunkCounts {
            grid: *grid,
            n,
            counts: vec![0; total as usize],
            dropped: Vec::new(),
        })
    }

    /// The grid the counts are over.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Counts triangles (world coordinates) into every chunk of their chunk range
    /// ([`Grid::world_chunk_range`], the range of the triangle moved to the grid, without moving
    /// it). Adding all of a pass's triangles, in any batches, gives what [`count`] gives.
    pub fn add_triangles(&mut self, tris: &[Triangle]) {
        for t in tris {
            if let Some((lo, hi)) = self.grid.world_chunk_range(t) {
                self.add_range(lo, hi);
            }
        }
    }

    /// Counts triangles (world coordinates) given their [`ChunkKeys::of_world`]: what
    /// [`ChunkCounts::add_triangles`] counts.
    pub fn add_keyed(&mut self, tris: &[Triangle], keys: &[u32]) {
        assert_eq!(tris.len(), keys.len(), "one key per triangle");
        for (t, &k) in tris.iter().zip(keys) {
            if k != SPANS {
                self.counts[k as usize] += 1;
            } else if let Some((lo, hi)) = self.grid.world_chunk_range(t) {
                self.add_range(lo, hi);
            }
        }
    }

    /// The keys of this grid's chunks.
    pub fn keys(&self) -> ChunkKeys {
        ChunkKeys {
            grid: self.grid,
            n: self.n,
        }
    }

    #[inline]
    fn index(&self, c: [u32; 3]) -> usize {
        ((c[2] as usize * self.n as usize) + c[1] as usize) * self.n as usize + c[0] as usize
    }

    #[inline]
    pub(crate) fn add_range(&mut self, lo: [u32; 3], hi: [u32; 3]) {
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let i = self.index([x, y, z]);
                    self.counts[i] += 1;
                }
            }
        }
    }

    /// Keeps only the chunks for which `keep(coord)` holds (a sharded build bins the chunks of
    /// its own subtrees): the others' counts become 0, and [`scatter`] skips their triangles
    /// instead of taking them for a changed input.
    pub fn retain(&mut self, keep: impl Fn([u32; 3]) -> bool) {
        let n = self.n;
        self.dropped = vec![false; self.counts.len()];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let i = self.index([x, y, z]);
                    if !keep([x, y, z]) {
                        self.counts[i] = 0;
                        self.dropped[i] = true;
                    }
                }
            }
        }
    }

    /// Sets chunk `c`'s count (counts taken elsewhere, e.g. a sharded build's from its plan).
    pub fn set(&mut self, c: [u32; 3], count: u64) {
        let i = self.index(c);
        self.counts[i] = count;
    }

    /// For a scatter with dropped chunks (precondition): [`DROPPED`] if no chunk of triangle `t`'s range
    /// (world coordinates) is kept, else its key ([`ChunkKeys::of_grid`]); `t` stays in world
    /// coordinates. The range is [`Grid::world_chunk_range`], the one of the moved triangle.
    #[inline]
    fn keep_key(&self, keys: ChunkKeys, t: &mut Triangle) -> u32 {
        debug_assert!(!self.dropped.is_empty(), "no chunk was dropped");
        let Some((lo, hi)) = self.grid.world_chunk_range(t) else {
            return DROPPED;
        };
        let key = keys.key(Some((lo, hi)));
        let kept = if key != SPANS {
            !self.dropped[key as usize]
        } else {
            (lo[2]..=hi[2]).any(|z| {
                (lo[1]..=hi[1])
                    .any(|y| (lo[0]..=hi[0]).any(|x| !self.dropped[self.index([x, y, z])]))
            })
        };
        if !kept {
            return DROPPED;
        }
        key
    }

    /// Triangles binned into chunk `c`.
    pub fn get(&self, c: [u32; 3]) -> u64 {
        self.counts[self.index(c)]
    }

    /// Sum over all chunks (a triangle spanning k chunks counts k times).
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// The non-empty chunks, in Morton order of their coordinates (`start` is the first
    /// triangle of each as if their triangles were laid out back to back).
    pub fn layout(&self) -> Vec<ChunkBin> {
        let mut chunks: Vec<ChunkBin> = Vec::new();
        for z in 0..self.n {
            for y in 0..self.n {
                for x in 0..self.n {
                    let count = self.get([x, y, z]);
                    if count > 0 {
                        chunks.push(ChunkBin {
                            coord: [x, y, z],
                            morton: morton3(x, y, z),
                            start: 0,
                            count,
                        });
                    }
                }
            }
        }
        chunks.sort_unstable_by_key(|c| c.morton);
        let mut start = 0;
        for c in &mut chunks {
            c.start = start;
            start += c.count;
        }
        chunks
    }
}

/// The key of a triangle whose chunk range ([`Grid::chunk_range`]) is more than one chunk, or
/// none: such a triangle's range is worked out again where the key is used (rare: most
/// triangles lie in one chunk).
pub const SPANS: u32 = u32::MAX;

/// The key of a triangle that lies in none of the kept chunks of a scatter with dropped chunks
/// ([`ChunkCounts::retain`]): it is skipped without being moved to the grid or encoded. Never
/// a chunk's index (a grid has at most 2³⁰ chunks: `n³` with `n` a power of two below 2¹¹).
pub const DROPPED: u32 = u32::MAX - 1;

/// Calls `put(i, t, li)` for every chunk (linear index `li`) that keyed triangle `t = tris[i]` goes to
/// (`keys` from [`ChunkKeys::of_world`] on `grid`, `n` chunks per axis): its key's chunk, every
/// chunk of its range for [`SPANS`], none for [`DROPPED`]; in order, stopping at an error.
#[inline]
pub(crate) fn for_each_keyed_chunk(
    grid: &Grid,
    n: u32,
    tris: &[Triangle],
    keys: &[u32],
    mut put: impl FnMut(usize, &Triangle, usize) -> Result<(), TileError>,
) -> Result<(), TileError> {
    assert_eq!(tris.len(), keys.len(), "one key per triangle");
    let n = n as usize;
    for (i, (t, &k)) in tris.iter().zip(keys).enumerate() {
        if k == DROPPED {
            continue;
        }
        if k != SPANS {
            put(i, t, k as usize)?;
            continue;
        }
        let Some((lo, hi)) = grid.world_chunk_range(t) else {
            continue;
        };
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    put(i, t, (z as usize * n + y as usize) * n + x as usize)?;
                }
            }
        }
    }
    Ok(())
}

/// A triangle's chunk range as one number, worked out where the triangles are read (in a
/// pass's prepare step, see [`Passes::for_each_prepared`]) and used where they are counted or
/// binned: the linear index `(z·n + y)·n + x` of its chunk if the range is that one chunk,
/// [`SPANS`] otherwise. Made by [`ChunkCounts::keys`], which holds fewer than 2³² chunks.
#[derive(Clone, Copy, Debug)]
pub struct ChunkKeys {
    grid: Grid,
    n: u32,
}

impl ChunkKeys {
    #[inline]
    fn key(&self, range: Option<([u32; 3], [u32; 3])>) -> u32 {
        match range {
            Some((lo, hi)) if lo == hi => (lo[2] * self.n + lo[1]) * self.n + lo[0],
            _ => SPANS,
        }
    }

    /// Keys of triangles in world coordinates ([`Grid::world_chunk_range`]).
    pub fn of_world(&self, tris: &[Triangle]) -> Vec<u32> {
        tris.iter()
            .map(|t| self.key(self.grid.world_chunk_range(t)))
            .collect()
    }

    /// Keys of triangles in grid coordinates ([`Grid::chunk_range`]).
    pub fn of_grid(&self, tris: &[Triangle]) -> Vec<u32> {
        tris.iter()
            .map(|t| self.key(self.grid.chunk_range(t)))
            .collect()
    }
}

/// One non-empty leaf chunk of the bins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkBin {
    /// Chunk coordinates (units of [`CHUNK`] voxels).
    pub coord: [u32; 3],
    /// `morton3(coord)`.
    pub morton: u64,
    /// In finished [`Bins`]: the byte offset of the chunk's first piece in the bins file.
    pub start: u64,
    /// Triangles binned to the chunk.
    pub count: u64,
}

impl ChunkBin {
    /// Minimum voxel corner of the chunk in grid coordinates.
    pub fn origin(&self) -> [u32; 3] {
        self.coord.map(|c| c * CHUNK)
    }
}

/// The scatter pass in progress: one arena of at most the byte budget, cut into one slice per
/// non-empty chunk in proportion to its count (at least one record). A chunk's slice is
/// encoded as blocks and appended to the file as one of its pieces when it fills up and at
/// the end, so nothing is allocated per triangle.
pub(crate) struct Scatter<'g> {
    grid: &'g Grid,
    path: PathBuf,
    file: File,
    chunks: Vec<ChunkBin>,
    /// Chunk linear index -> position in `chunks`.
    slot: Vec<u32>,
    /// Chunks whose triangles are skipped ([`ChunkCounts::retain`]).
    dropped: Vec<bool>,
    n: u32,
    layout: RecordLayout,
    /// Triangles already written per chunk.
    written: Vec<u64>,
    /// Per chunk: its pieces `[byte offset, bytes, triangles]`.
    pieces: Vec<Vec<[u64; 3]>>,
    /// Bytes written to the file (its end).
    end: u64,
    encoder: BlockEncoder,
    /// The blocks of the slice being written.
    out: Vec<u8>,
    arena: Vec<u8>,
    /// Per chunk: first record of its slice in the arena, slice capacity, records in it.
    slice_start: Vec<u64>,
    slice_cap: Vec<u32>,
    slice_len: Vec<u32>,
}

impl<'g> Scatter<'g> {
    pub(crate) fn create(
        grid: &'g Grid,
        counts: &ChunkCounts,
        path: &Path,
        layout: RecordLayout,
        buffer_bytes: u64,
    ) -> Result<Scatter<'g>, TileError> {
        let chunks = counts.layout();
        let mut slot = vec![u32::MAX; counts.counts.len()];
        for (i, c) in chunks.iter().enumerate() {
            slot[counts.index(c.coord)] = i as u32;
        }
        let rec = layout.bytes() as u64;
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)
            .map_err(TileError::io("create", path))?;
        let caps = slice_caps(&chunks, rec, buffer_bytes);
        let mut slice_start = Vec::with_capacity(chunks.len());
        let mut slice_cap = Vec::with_capacity(chunks.len());
        let mut at = 0u64;
        for cap in caps {
            slice_start.push(at);
            slice_cap.push(cap as u32);
            at += cap;
        }
        let k = chunks.len();
        Ok(Scatter {
            grid,
            path: path.to_path_buf(),
            file,
            chunks,
            slot,
            dropped: counts.dropped.clone(),
            n: counts.n,
            layout,
            written: vec![0; k],
            pieces: vec![Vec::new(); k],
            end: 0,
            encoder: BlockEncoder::new(layout),
            out: Vec::new(),
            arena: vec![0u8; (at * rec) as usize],
            slice_start,
            slice_cap,
            slice_len: vec![0; k],
        })
    }

    /// Bins a batch of world-space triangles given their [`ChunkKeys::of_world`].
    pub(crate) fn push_keyed(&mut self, tris: &[Triangle], keys: &[u32]) -> Result<(), TileError> {
        let (grid, n) = (self.grid, self.n);
        for_each_keyed_chunk(grid, n, tris, keys, |_, t, li| self.put(t, li))
    }

    /// Adds triangle `t` to the slice of the chunk of linear index `li`.
    #[inline]
    fn put(&mut self, t: &Triangle, li: usize) -> Result<(), TileError> {
        let rec = self.layout.bytes();
        let s = self.slot[li];
        if s == u32::MAX {
            if self.dropped.get(li).copied().unwrap_or(false) {
                return Ok(());
            }
            let n = self.n as usize;
            return Err(TileError::CountChanged {
                coord: [li % n, li / n % n, li / (n * n)].map(|c| c as u32),
                received: 1,
                counted: 0,
            });
        }
        let s = s as usize;
        let at = (self.slice_start[s] + self.slice_len[s] as u64) as usize * rec;
        self.layout.encode_into(t, &mut self.arena[at..at + rec])?;
        self.slice_len[s] += 1;
        if self.slice_len[s] == self.slice_cap[s] {
            self.write_slice(s)?;
        }
        Ok(())
    }

    /// Appends chunk `s`'s slice to the file as blocks (one piece of the chunk) and empties it.
    fn write_slice(&mut self, s: usize) -> Result<(), TileError> {
        let n = self.slice_len[s] as u64;
        if n == 0 {
            return Ok(());
        }
        let c = &self.chunks[s];
        if self.written[s] + n > c.count {
            return Err(TileError::CountChanged {
                coord: c.coord,
                received: self.written[s] + n,
                counted: c.count,
            });
        }
        let rec = self.layout.bytes();
        let from = self.slice_start[s] as usize * rec;
        let arena = &self.arena;
        self.out.clear();
        self.encoder.encode(
            n as usize,
            |i| &arena[from + i * rec..from + (i + 1) * rec],
            &mut self.out,
        );
        self.file
            .write_all_at(&self.out, self.end)
            .map_err(TileError::io("write", &self.path))?;
        let bytes = self.out.len() as u64;
        self.pieces[s].push([self.end, bytes, n]);
        self.end += bytes;
        self.written[s] += n;
        self.slice_len[s] = 0;
        Ok(())
    }

    pub(crate) fn finish(mut self) -> Result<Bins, TileError> {
        for s in 0..self.chunks.len() {
            self.write_slice(s)?;
        }
        for (i, c) in self.chunks.iter().enumerate() {
            if self.written[i] != c.count {
                return Err(TileError::CountChanged {
                    coord: c.coord,
                    received: self.written[i],
                    counted: c.count,
                });
            }
        }
        self.file
            .sync_data()
            .map_err(TileError::io("sync", &self.path))?;
        for (c, ps) in self.chunks.iter_mut().zip(&self.pieces) {
            c.start = ps[0][0];
        }
        Ok(Bins::from_runs(
            self.path,
            self.file,
            self.chunks,
            self.layout,
            0,
            self.pieces,
            self.end,
        ))
    }
}

/// Records per chunk in the scatter's arena (same order as `chunks`): slices in proportion to
/// the counts, at least one record; a chunk whose triangles all fit is written once.
fn slice_caps(chunks: &[ChunkBin], rec: u64, buffer_bytes: u64) -> Vec<u64> {
    let total: u64 = chunks.iter().map(|c| c.count).sum();
    let arena_records = (buffer_bytes.max(rec * 1024) / rec).min(total.max(1));
    chunks
        .iter()
        .map(|c| {
            ((c.count as u128 * arena_records as u128 / total.max(1) as u128) as u64)
                .clamp(1, c.count.min(u32::MAX as u64))
        })
        .collect()
}

/// Largest size of the bins file [`scatter`] writes for `counts` with records of `layout` and
/// a buffer of `buffer_bytes`: blocks are never larger than their records plus a header, and
/// each flush of a chunk's slice is one piece.
pub fn scatter_bound(counts: &ChunkCounts, layout: RecordLayout, buffer_bytes: u64) -> u64 {
    let chunks = counts.layout();
    let rec = layout.bytes() as u64;
    let caps = slice_caps(&chunks, rec, buffer_bytes);
    let pieces: u64 = chunks
        .iter()
        .zip(&caps)
        .map(|(c, &cap)| c.count.div_ceil(cap))
        .sum();
    layout.blocks_bound(counts.total(), pieces)
}

/// Where the triangles of bins of face indices come from: the input, which finds a triangle
/// by its face record (the tile crate does not know the input's format).
pub trait TriangleSource: Sync {
    /// Appends to `out` the triangle of each face record of `faces`, in order: the triangle
    /// the pass that binned it was given for that record, bit for bit.
    fn triangles_at(&self, faces: &[u64], out: &mut Vec<Triangle>) -> Result<(), TileError>;
}

/// The finished bins file: non-empty leaf chunks in Morton order, each with its triangles
/// (world coordinates, in input order) as [blocks](crate::block) of one [`RecordLayout`], in
/// pieces: runs of consecutive blocks, `[byte offset, bytes, triangles]`, read one after
/// another. [`scatter`] writes a piece per flush of a chunk's slice, [`crate::RunScatter`] a
/// piece per chunk per run.
///
/// Bins of *face indices* ([`crate::RunScatter::create_indexed`], for an input whose triangles
/// can be found again by their face record) hold, in the same chunks and pieces, each
/// triangle's face record as a little-endian integer of [`Bins::index_bytes`] bytes instead of
/// blocks; [`Bins::read_chunk_from`] rebuilds the triangles from the input through a
/// [`TriangleSource`].
///
/// Bins *read in place* ([`Bins::open_in_place`]) are pieces of other bins files (a sharded
/// build's map outputs), read where they lie instead of copied into a file of their own.
pub struct Bins {
    /// The files the pieces lie in, in order: a piece's byte offset counts in their
    /// concatenation (file k starts at the sum of the lengths of the files before it). One
    /// file except for bins read in place.
    files: Vec<BinFile>,
    /// True if the single file is these bins' own (written for them; [`Bins::remove`] deletes
    /// it); false for bins read in place.
    owned: bool,
    chunks: Vec<ChunkBin>,
    layout: RecordLayout,
    /// 0 for blocks of records; 4 or 8 for face indices of that width.
    index_bytes: usize,
    /// Per chunk (same order as `chunks`): its pieces `[byte offset, bytes, triangles]`, in
    /// input order.
    pieces: Vec<Vec<[u64; 3]>>,
    /// Length of the file; for bins read in place, the bytes of their pieces.
    bytes: u64,
    /// Per chunk (same order), the CRC-32 of each of its pieces, when they were taken
    /// ([`crate::RunScatter::create_with_piece_crcs`], [`Bins::open_in_place`]): then each
    /// piece read is checked against its own.
    pub(crate) crcs: Option<Vec<Vec<u32>>>,
}

/// One file of a [`Bins`]: its bytes are `base..base + len` of the pieces' offsets.
struct BinFile {
    path: PathBuf,
    file: File,
    base: u64,
    len: u64,
}

impl Bins {
    /// Reopens a finished bins file with its chunks and each chunk's pieces (what
    /// [`Bins::pieces`] gave; e.g. to resume a build). The pieces must add up to each chunk's
    /// count, lie inside the file and cover it exactly (their bytes add up to its length).
    pub fn open_pieces(
        path: &Path,
        chunks: Vec<ChunkBin>,
        layout: RecordLayout,
        pieces: Vec<Vec<[u64; 3]>>,
    ) -> Result<Bins, TileError> {
        Bins::open_pieces_of(path, chunks, layout, 0, pieces)
    }

    /// [`Bins::open_pieces`] for bins of blocks (`index_bytes` 0) or of face indices of
    /// `index_bytes` (4 or 8) bytes each, whose pieces must then hold exactly their triangles'
    /// indices.
    pub fn open_pieces_of(
        path: &Path,
        chunks: Vec<ChunkBin>,
        layout: RecordLayout,
        index_bytes: usize,
        pieces: Vec<Vec<[u64; 3]>>,
    ) -> Result<Bins, TileError> {
        assert!(
            matches!(index_bytes, 0 | 4 | 8),
            "blocks, u32 or u64 indices"
        );
        let file = File::open(path).map_err(TileError::io("open", path))?;
        let len = file.metadata().map_err(TileError::io("stat", path))?.len();
        let fits = pieces.len() == chunks.len()
            && chunks.iter().zip(&pieces).all(|(c, ps)| {
                !ps.is_empty()
                    && c.start == ps[0][0]
                    && ps.iter().map(|p| p[2]).sum::<u64>() == c.count
                    && ps
                        .iter()
                        .all(|p| p[0].checked_add(p[1]).is_some_and(|e| e <= len))
                    && (index_bytes == 0
                        || ps
                            .iter()
                            .all(|p| Some(p[1]) == p[2].checked_mul(index_bytes as u64)))
            });
        let covered: u64 = pieces.iter().flatten().map(|p| p[1]).sum();
        if !fits || covered != len {
            return Err(TileError::BadBins {
                path: path.to_path_buf(),
                problem: format!(
                    "its {len} bytes do not match the {} pieces of its {} chunks",
                    pieces.iter().map(Vec::len).sum::<usize>(),
                    chunks.len()
                ),
            });
        }
        Ok(Bins::from_runs(
            path.to_path_buf(),
            file,
            chunks,
            layout,
            index_bytes,
            pieces,
            len,
        ))
    }

    /// Bins of blocks read in place from `files` (other writers' finished bins files, opened by
    /// the caller, e.g. a sharded build's map outputs; each read here only where a piece lies):
    /// per chunk its pieces as `(file index, [byte offset in that file, bytes, triangles],
    /// CRC-32 of the piece's bytes)`, in input order. Each piece must lie inside its file and
    /// the pieces must add up to each chunk's count; a chunk's `start` is set to its first
    /// piece. Reading a chunk checks each piece's bytes against its CRC-32 (a piece changed
    /// since it was written is a [`TileError::BadBins`] naming its file). [`Bins::remove`]
    /// leaves the files alone.
    pub fn open_in_place(
        files: Vec<(PathBuf, File)>,
        mut chunks: Vec<ChunkBin>,
        layout: RecordLayout,
        pieces: Vec<Vec<(usize, [u64; 3], u32)>>,
    ) -> Result<Bins, TileError> {
        assert!(
            !files.is_empty(),
            "bins read in place from at least one file"
        );
        // one offset space: file k's bytes follow those of the files before it
        let mut opened = Vec::with_capacity(files.len());
        let mut base = 0u64;
        for (path, file) in files {
            let len = file.metadata().map_err(TileError::io("stat", &path))?.len();
            opened.push(BinFile {
                path,
                file,
                base,
                len,
            });
            base += len;
        }
        if pieces.len() != chunks.len() {
            return Err(TileError::BadBins {
                path: opened[0].path.clone(),
                problem: format!("{} chunks but {} piece lists", chunks.len(), pieces.len()),
            });
        }
        let mut flat = Vec::with_capacity(pieces.len());
        let mut crcs = Vec::with_capacity(pieces.len());
        let mut bytes = 0u64;
        for (c, ps) in chunks.iter_mut().zip(pieces) {
            let mut out = Vec::with_capacity(ps.len());
            crcs.push(ps.iter().map(|p| p.2).collect());
            for (k, [off, n, count], _) in ps {
                let Some(f) = opened.get(k) else {
                    return Err(TileError::BadBins {
                        path: opened[0].path.clone(),
                        problem: format!(
                            "chunk {:?}: a piece of file {k} of {}",
                            c.coord,
                            opened.len()
                        ),
                    });
                };
                if off.checked_add(n).is_none_or(|e| e > f.len) {
                    return Err(TileError::BadBins {
                        path: f.path.clone(),
                        problem: format!(
                            "chunk {:?}: a piece of {n} bytes at {off} past the end of its {} bytes",
                            c.coord, f.len
                        ),
                    });
                }
                out.push([f.base + off, n, count]);
                bytes += n;
            }
            if out.is_empty() || out.iter().map(|p| p[2]).sum::<u64>() != c.count {
                return Err(TileError::BadBins {
                    path: opened[0].path.clone(),
                    problem: format!(
                        "chunk {:?}: its pieces do not add up to its {} triangles",
                        c.coord, c.count
                    ),
                });
            }
            c.start = out[0][0];
            flat.push(out);
        }
        let pieces = flat;
        Ok(Bins {
            files: opened,
            owned: false,
            chunks,
            layout,
            index_bytes: 0,
            pieces,
            bytes,
            crcs: Some(crcs),
        })
    }

    pub(crate) fn from_runs(
        path: PathBuf,
        file: File,
        chunks: Vec<ChunkBin>,
        layout: RecordLayout,
        index_bytes: usize,
        pieces: Vec<Vec<[u64; 3]>>,
        bytes: u64,
    ) -> Bins {
        debug_assert_eq!(chunks.len(), pieces.len());
        Bins {
            files: vec![BinFile {
                path,
                file,
                base: 0,
                len: bytes,
            }],
            owned: true,
            chunks,
            layout,
            index_bytes,
            pieces,
            bytes,
            crcs: None,
        }
    }

    /// Each chunk's pieces' CRC-32 (same order as [`Bins::pieces`]), if they were taken.
    pub fn piece_crcs(&self) -> Option<&[Vec<u32>]> {
        self.crcs.as_deref()
    }

    /// Bytes of one face index for bins of face indices; `None` for bins of blocks.
    pub fn index_bytes(&self) -> Option<usize> {
        (self.index_bytes > 0).then_some(self.index_bytes)
    }

    /// Each chunk's pieces `[byte offset, bytes, triangles]` (for a resume marker).
    pub fn pieces(&self) -> &[Vec<[u64; 3]>] {
        &self.pieces
    }

    /// The layout of the records the blocks encode.
    pub fn layout(&self) -> RecordLayout {
        self.layout
    }

    /// The non-empty chunks, in Morton order.
    pub fn chunks(&self) -> &[ChunkBin] {
        &self.chunks
    }

    /// The bins file (the first file for bins read in place).
    pub fn path(&self) -> &Path {
        &self.files[0].path
    }

    /// True if the bins are their own file (not read in place from others').
    pub fn owned(&self) -> bool {
        self.owned
    }

    /// Bytes of the bins file (what was written to it); for bins read in place, the bytes of
    /// their pieces (what reading them all reads).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The file that byte `at` of the pieces' offsets lies in.
    fn file_at(&self, at: u64) -> &BinFile {
        let k = self.files.partition_point(|f| f.base + f.len <= at);
        &self.files[k.min(self.files.len() - 1)]
    }

    /// Reads `buf.len()` bytes at `at` (in the pieces' offsets; never across two files, as
    /// every piece lies inside one).
    fn read_at(&self, buf: &mut [u8], at: u64) -> Result<(), TileError> {
        let f = self.file_at(at);
        f.file
            .read_exact_at(buf, at - f.base)
            .map_err(TileError::io("read", &f.path))
    }

    /// Total triangle records in the file.
    pub fn total(&self) -> u64 {
        self.chunks.iter().map(|c| c.count).sum()
    }

    /// Hands chunk `i`'s triangles to `f` in input order, `batch` at a time (the last batch
    /// may be smaller), decoding one block at a time (memory is bounded whatever the chunk
    /// holds). A block that does not match its piece or the layout is a [`TileError::BadBins`].
    /// Bins of face indices need their source: [`Bins::read_chunk_from`].
    pub fn read_chunk(
        &self,
        i: usize,
        batch: usize,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        self.read_chunk_from(i, batch, None, f)
    }

    /// [`Bins::read_chunk`] for bins of either kind: bins of face indices rebuild each batch's
    /// triangles from `source` (the input they index; the same batches as blocks would give).
    pub fn read_chunk_from(
        &self,
        i: usize,
        batch: usize,
        source: Option<&dyn TriangleSource>,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        assert!(batch > 0);
        if self.index_bytes > 0 {
            let Some(src) = source else {
                return Err(TileError::BadBins {
                    path: self.path().to_path_buf(),
                    problem: "bins of face indices read without the input they index".into(),
                });
            };
            return self.read_indices(i, batch, src, f);
        }
        let c = self.chunks[i];
        let cap = batch.min(c.count as usize).max(1);
        let mut tris: Vec<Triangle> = Vec::with_capacity(cap);
        let mut body = Vec::new();
        let bad = |at: u64, problem: String| {
            let f = self.file_at(at);
            TileError::BadBins {
                path: f.path.clone(),
                problem: format!("chunk {:?}, byte {}: {problem}", c.coord, at - f.base),
            }
        };
        let mut done = 0u64;
        for (p, &[start, bytes, count]) in self.pieces[i].iter().enumerate() {
            let (mut at, end, mut got) = (start, start + bytes, 0u64);
            let want_crc = self.crcs.as_ref().map(|c| c[i][p]);
            let mut crc = crc32fast::Hasher::new();
            // a piece whose bytes changed since they were written: named as such (whatever
            // its decoding found first), once the rest of it has been read into the checksum
            let changed = |at: u64, crc: crc32fast::Hasher, e: TileError| {
                match want_crc {
                Some(want) => match self.crc_from(at, end, crc) {
                    Ok(got) if got != want => bad(
                        start,
                        format!(
                            "the piece's CRC-32 is {got:08x}, {want:08x} when it was written (changed or damaged since)"
                        ),
                    ),
                    Ok(_) => e,
                    Err(io) => io,
                },
                None => e,
            }
            };
            while at < end {
                let mut h = [0u8; BLOCK_HEADER];
                self.read_at(&mut h, at)?;
                let head = match BlockHeader::parse(&h) {
                    Ok(head) => head,
                    Err(e) => return Err(changed(at, crc, bad(at, e))),
                };
                let n = head.body_bytes(self.layout);
                let next = at + (BLOCK_HEADER + n) as u64;
                if next > end {
                    let e = bad(at, format!("a block of {n} bytes past its piece's end"));
                    return Err(changed(at, crc, e));
                }
                if want_crc.is_some() {
                    crc.update(&h);
                }
                body.resize(n, 0);
                self.read_at(&mut body, at + BLOCK_HEADER as u64)?;
                if want_crc.is_some() {
                    crc.update(&body);
                }
                if let Err(e) = head.decode(self.layout, &body, &mut tris) {
                    return Err(changed(next, crc, bad(at, e)));
                }
                got += head.triangles as u64;
                at = next;
                if tris.len() >= cap {
                    let mut from = 0;
                    while tris.len() - from >= cap {
                        f(&tris[from..from + cap])?;
                        from += cap;
                    }
                    tris.drain(..from);
                }
            }
            if let Some(want) = want_crc {
                let got = crc.finalize();
                if got != want {
                    return Err(bad(
                        start,
                        format!(
                            "the piece's CRC-32 is {got:08x}, {want:08x} when it was written (changed or damaged since)"
                        ),
                    ));
                }
            }
            if got != count {
                return Err(bad(
                    start,
                    format!("a piece of {got} triangles where {count} were written"),
                ));
            }
            done += got;
        }
        if done != c.count {
            return Err(bad(c.start, format!("{done} triangles, not {}", c.count)));
        }
        if !tris.is_empty() {
            f(&tris)?;
        }
        Ok(())
    }

    /// `crc` (the CRC-32 of a piece's bytes before `at`) continued over the bytes `at..end`.
    fn crc_from(
        &self,
        mut at: u64,
        end: u64,
        mut crc: crc32fast::Hasher,
    ) -> Result<u32, TileError> {
        let mut buf = vec![0u8; (end - at).min(1 << 20) as usize];
        while at < end {
            let n = ((end - at) as usize).min(buf.len());
            self.read_at(&mut buf[..n], at)?;
            crc.update(&buf[..n]);
            at += n as u64;
        }
        Ok(crc.finalize())
    }

    /// Chunk `i`'s triangles from bins of face indices: the indices of up to `batch` triangles
    /// at a time, their triangles from `src`.
    fn read_indices(
        &self,
        i: usize,
        batch: usize,
        src: &dyn TriangleSource,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        let c = self.chunks[i];
        let w = self.index_bytes;
        let cap = batch.min(c.count as usize).max(1);
        let (mut raw, mut faces) = (Vec::new(), Vec::with_capacity(cap));
        let mut tris: Vec<Triangle> = Vec::with_capacity(cap);
        let mut give = |faces: &mut Vec<u64>| -> Result<(), TileError> {
            tris.clear();
            src.triangles_at(faces, &mut tris)?;
            assert_eq!(tris.len(), faces.len(), "one triangle per face record");
            faces.clear();
            f(&tris)
        };
        for &[start, bytes, count] in &self.pieces[i] {
            debug_assert_eq!(bytes, count * w as u64, "checked when opened or written");
            let (mut at, end) = (start, start + bytes);
            while at < end {
                let n = ((end - at) as usize / w).min(cap - faces.len());
                raw.resize(n * w, 0);
                self.read_at(&mut raw, at)?;
                if w == 4 {
                    faces.extend(
                        raw.chunks_exact(4)
                            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as u64),
                    );
                } else {
                    faces.extend(
                        raw.chunks_exact(8)
                            .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes"))),
                    );
                }
                at += (n * w) as u64;
                if faces.len() == cap {
                    give(&mut faces)?;
                }
            }
        }
        if !faces.is_empty() {
            give(&mut faces)?;
        }
        Ok(())
    }

    /// Removes the bins file; bins read in place leave their files alone.
    pub fn remove(self) -> Result<(), TileError> {
        if !self.owned {
            return Ok(());
        }
        let path = &self.files[0].path;
        std::fs::remove_file(path).map_err(TileError::io("remove", path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Spooler;
    use voxlod_geom::{demorton3, Bounds};

    fn lcg(s: &mut u64) -> f32 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*s >> 40) as f32) / (1u64 << 24) as f32
    }

    /// 4000 small triangles at random in a 10-unit cube, every 40th twenty times larger.
    fn scattered_triangles(seed: u64) -> Vec<Triangle> {
        let mut s = seed;
        (0..4000)
            .map(|i| {
                let c = [lcg(&mut s) * 10.0, lcg(&mut s) * 10.0, lcg(&mut s) * 10.0];
                let r = if i % 40 == 0 { 4.0 } else { 0.2 };
                let d = lcg(&mut s);
                Triangle::new([c, [c[0] + r, c[1], c[2] + r * d], [c[0], c[1] + r, c[2]]])
            })
            .collect()
    }

    /// Every triangle of chunk `i` of `bins`, in order.
    fn chunk_triangles(bins: &Bins, i: usize) -> Vec<Triangle> {
        let mut got = Vec::new();
        bins.read_chunk(i, 64, &mut |b| {
            got.extend_from_slice(b);
            Ok(())
        })
        .unwrap();
        got
    }

    /// Brute force: a chunk must hold exactly the triangles whose chunk range contains it, in
    /// input order, for any scatter budget (several flushes vs one).
    #[test]
    fn bins_match_brute_force_for_any_budget() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = 7u64;
        let mut tris = Vec::new();
        for i in 0..3000 {
            let c = [lcg(&mut s) * 10.0, lcg(&mut s) * 10.0, lcg(&mut s) * 10.0];
            let r = if i % 50 == 0 { 6.0 } else { 0.3 };
            let mut t = Triangle::new([
                c,
                [c[0] + r * lcg(&mut s), c[1], c[2] + r],
                [c[0], c[1] + r * lcg(&mut s), c[2]],
            ]);
            t.c[0] = [(i % 256) as u8, (i / 256) as u8, 0, 255];
            tris.push(t);
        }
        let spool_layout = RecordLayout {
            normals: false,
            colors: true,
            texcoords: false,
        };
        let mut sp = Spooler::create(&dir.path().join("spool"), spool_layout).unwrap();
        for b in tris.chunks(700) {
            sp.push(b).unwrap();
        }
        let spool = sp.finish().unwrap();
        let mut bounds = Bounds::default();
        tris.iter().for_each(|t| bounds.add_triangle(t));
        assert_eq!(spool.bounds, bounds);
        assert_eq!(
            std::fs::metadata(&spool.path).unwrap().len(),
            3000 * spool_layout.bytes() as u64
        );
        let grid = Grid::fit(&spool.bounds, 1024).unwrap();
        let counts = count(&spool, &grid, &mut |_, _| {}).unwrap();
        // the keyed counting (one key per single-chunk triangle) counts what the chunk ranges do
        let mut direct = ChunkCounts::new(&grid).unwrap();
        direct.add_triangles(&tris);
        assert_eq!(counts.counts, direct.counts);
        let keys = counts.keys().of_world(&tris);
        let spans = keys.iter().filter(|&&k| k == SPANS).count();
        assert!(
            spans > 50 && spans < 2900,
            "{spans} triangles over several chunks"
        );
        let moved: Vec<Triangle> = tris.iter().map(|t| crate::to_grid(&grid, t)).collect();
        assert_eq!(counts.keys().of_grid(&moved), keys);
        let mut previous: Option<Vec<Vec<Triangle>>> = None;
        // small budget (many flushes) and large (one), compact and full records
        for (budget, layout) in [
            (52 * 1024, spool_layout),
            (1 << 30, spool_layout),
            (88 * 1024, RecordLayout::FULL),
        ] {
            let path = dir.path().join(format!("bins{budget}-{}", layout.bytes()));
            let bins = scatter(
                &spool,
                &grid,
                &counts,
                &path,
                layout,
                budget,
                &mut |_, _| {},
            )
            .unwrap();
            assert_eq!(std::fs::metadata(&path).unwrap().len(), bins.bytes());
            assert!(bins.bytes() <= scatter_bound(&counts, layout, budget));
            let mut all = Vec::new();
            let mut last = None;
            for (i, c) in bins.chunks().iter().enumerate() {
                assert!(
                    last.map_or(true, |m| m < c.morton),
                    "chunks not in Morton order"
                );
                last = Some(c.morton);
                assert_eq!(demorton3(c.morton), c.coord);
                let mut got = Vec::new();
                bins.read_chunk(i, 100, &mut |b| {
                    got.extend_from_slice(b);
                    Ok(())
                })
                .unwrap();
                // the bins keep world coordinates
                let want: Vec<Triangle> = tris
                    .iter()
                    .filter(|t| {
                        let (lo, hi) = grid.chunk_range(&crate::to_grid(&grid, t)).unwrap();
                        (0..3).all(|a| lo[a] <= c.coord[a] && c.coord[a] <= hi[a])
                    })
                    .copied()
                    .collect();
                assert_eq!(got, want, "chunk {:?}", c.coord);
                all.push(got);
            }
            // every chunk with a triangle in range is present
            let mut expect_chunks = 0;
            for z in 0..4 {
                for y in 0..4 {
                    for x in 0..4 {
                        expect_chunks += (counts.get([x, y, z]) > 0) as usize;
                    }
                }
            }
            assert_eq!(bins.chunks().len(), expect_chunks);
            if let Some(p) = &previous {
                assert_eq!(p, &all, "scatter result depends on the buffer budget");
            }
            previous = Some(all);
        }
    }

    /// `tris` spooled as positions only in `dir`, and the grid of resolution `r` fitted to
    /// them.
    fn positions_spool(
        dir: &Path,
        tris: &[Triangle],
        r: u32,
    ) -> (crate::Spool, Grid, RecordLayout) {
        let layout = RecordLayout {
            normals: false,
            colors: false,
            texcoords: false,
        };
        let mut sp = Spooler::create(&dir.join("spool"), layout).unwrap();
        sp.push(tris).unwrap();
        let spool = sp.finish().unwrap();
        let grid = Grid::fit(&spool.bounds, r).unwrap();
        (spool, grid, layout)
    }

    /// Bins read in place from two files (each half of the input scattered on its own, as two
    /// map tasks do) give every chunk the triangles of one scatter of the whole input, in
    /// order; they report the bytes of their pieces, leave the files when removed, and refuse a
    /// piece past the end of its file or of a file they were not given.
    #[test]
    fn bins_read_in_place_from_several_files_read_as_one_scatter() {
        let dir = tempfile::tempdir().unwrap();
        let tris = scattered_triangles(5);
        let read = chunk_triangles;
        let (spool, grid, layout) = positions_spool(dir.path(), &tris, 1024);
        let whole = |src: &crate::Spool, name: &str| {
            let counts = count(src, &grid, &mut |_, _| {}).unwrap();
            let path = dir.path().join(name);
            scatter(src, &grid, &counts, &path, layout, 40 * 300, &mut |_, _| {}).unwrap()
        };
        let full = whole(&spool, "full");
        let mut halves = Vec::new();
        for (k, half) in tris.chunks(2000).enumerate() {
            let d = dir.path().join(format!("h{k}"));
            std::fs::create_dir_all(&d).unwrap();
            let (sp, _, _) = positions_spool(&d, half, 1024);
            halves.push(whole(&sp, &format!("h{k}/bins")));
        }
        let paths: Vec<PathBuf> = halves.iter().map(|h| h.path().to_path_buf()).collect();
        let open = || -> Vec<(PathBuf, File)> {
            paths
                .iter()
                .map(|p| (p.clone(), File::open(p).unwrap()))
                .collect()
        };
        // each piece's CRC-32, from the bytes in its file (these bins were not written with them)
        let crc = |k: usize, p: [u64; 3]| {
            let bytes = std::fs::read(&paths[k]).unwrap();
            crc32fast::hash(&bytes[p[0] as usize..(p[0] + p[1]) as usize])
        };
        let (mut chunks, mut pieces) = (Vec::new(), Vec::new());
        for c in full.chunks() {
            let mut ps: Vec<(usize, [u64; 3], u32)> = Vec::new();
            for (k, h) in halves.iter().enumerate() {
                if let Some(j) = h.chunks().iter().position(|d| d.morton == c.morton) {
                    ps.extend(h.pieces()[j].iter().map(|&p| (k, p, crc(k, p))));
                }
            }
            // `start` is set from the first piece
            chunks.push(ChunkBin { start: 7, ..*c });
            pieces.push(ps);
        }
        // some chunks take triangles from both files
        assert!(
            pieces
                .iter()
                .filter(|ps| ps[0].0 == 0 && ps.last().unwrap().0 == 1)
                .count()
                > 5
        );
        let in_place = Bins::open_in_place(open(), chunks.clone(), layout, pieces.clone()).unwrap();
        assert!(!in_place.owned() && full.owned());
        assert_eq!(in_place.bytes(), halves[0].bytes() + halves[1].bytes());
        for i in 0..full.chunks().len() {
            assert_eq!(read(&in_place, i), read(&full, i), "chunk {i}");
        }
        in_place.remove().unwrap();
        assert!(paths.iter().all(|f| f.is_file()));
        // one bit flipped in a piece of the second file (same length): reading a chunk with
        // that piece is refused naming the file and the checksum, whichever bit it is
        let i = (0..pieces.len())
            .find(|&i| pieces[i].iter().any(|p| p.0 == 1))
            .unwrap();
        let (_, p, _) = *pieces[i].iter().find(|p| p.0 == 1).unwrap();
        let keep = std::fs::read(&paths[1]).unwrap();
        for at in [p[0], p[0] + 3, p[0] + 17, p[0] + p[1] / 2, p[0] + p[1] - 1] {
            let mut b = keep.clone();
            b[at as usize] ^= 0x10;
            std::fs::write(&paths[1], &b).unwrap();
            let bins = Bins::open_in_place(open(), chunks.clone(), layout, pieces.clone()).unwrap();
            let e = bins.read_chunk(i, 100, &mut |_| Ok(())).unwrap_err();
            let text = e.to_string();
            assert!(
                text.contains(&paths[1].display().to_string()) && text.contains("CRC-32"),
                "byte {at}: {text}"
            );
        }
        std::fs::write(&paths[1], &keep).unwrap();
        // a piece past the end of its file (the first, and the last), and one of a third file
        let (len0, len1) = (halves[0].bytes(), halves[1].bytes());
        for bad in [
            (0, [len0 - 4, 8, 1], 0),
            (1, [len1 - 4, 8, 1], 0),
            (2, [0, 8, 1], 0),
        ] {
            let mut ps = pieces.clone();
            ps[0] = vec![bad];
            let mut cs = chunks.clone();
            cs[0].count = 1;
            let e = Bins::open_in_place(open(), cs, layout, ps).err().unwrap();
            assert!(matches!(e, TileError::BadBins { .. }), "{e:?}");
        }
    }

    /// A scatter that keeps some chunks only (a sharded build's) writes exactly the kept
    /// chunks' bins of the full scatter (same triangles, same order), with the triangles of
    /// no kept chunk rejected before binning and those across a kept and a dropped chunk
    /// binned into the kept one.
    #[test]
    fn a_scatter_keeping_some_chunks_writes_their_bins_of_the_full_scatter() {
        let dir = tempfile::tempdir().unwrap();
        let tris = scattered_triangles(11);
        let (spool, grid, layout) = positions_spool(dir.path(), &tris, 1024);
        let read = chunk_triangles;
        let full_counts = count(&spool, &grid, &mut |_, _| {}).unwrap();
        let full = scatter(
            &spool,
            &grid,
            &full_counts,
            &dir.path().join("full"),
            layout,
            1 << 20,
            &mut |_, _| {},
        )
        .unwrap();
        let keep = |c: [u32; 3]| (c[0] + 2 * c[1] + c[2]) % 3 == 0;
        let mut counts = count(&spool, &grid, &mut |_, _| {}).unwrap();
        counts.retain(keep);
        let part = scatter(
            &spool,
            &grid,
            &counts,
            &dir.path().join("part"),
            layout,
            40 * 100,
            &mut |_, _| {},
        )
        .unwrap();
        let kept: Vec<usize> = (0..full.chunks().len())
            .filter(|&i| keep(full.chunks()[i].coord))
            .collect();
        assert!(kept.len() >= 5 && kept.len() < full.chunks().len());
        assert_eq!(part.chunks().len(), kept.len());
        for (j, &i) in kept.iter().enumerate() {
            assert_eq!(part.chunks()[j].coord, full.chunks()[i].coord);
            assert_eq!(read(&part, j), read(&full, i), "chunk {i}");
        }
        // some triangles were rejected whole, and some spanned a kept and a dropped chunk
        let keys = counts.keys();
        let (mut rejected, mut mixed) = (0, 0);
        for t in &tris {
            let (lo, hi) = grid.world_chunk_range(t).unwrap();
            let mut cs = Vec::new();
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        cs.push(keep([x, y, z]));
                    }
                }
            }
            rejected += (!cs.contains(&true)) as u32;
            mixed += (cs.contains(&true) && cs.contains(&false)) as u32;
            assert_eq!(
                counts.keep_key(keys, &mut t.clone()) == DROPPED,
                !cs.contains(&true)
            );
        }
        assert!(
            rejected > 1000 && mixed > 20,
            "{rejected} rejected, {mixed} mixed"
        );
    }

    #[test]
    fn truncated_spool_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("spool");
        std::fs::write(&p, vec![0u8; 52 * 3 + 5]).unwrap();
        let layout = RecordLayout {
            normals: false,
            colors: true,
            texcoords: false,
        };
        let e = crate::Spool::open(&p, layout).unwrap_err();
        assert!(
            e.to_string().contains("not the expected whole number"),
            "{e}"
        );
    }

    /// Counts that do not match the scattered triangles (the input changed between the count
    /// and the scatter pass) end the scatter with `CountChanged` naming the chunk: a chunk
    /// counted empty, one with fewer triangles counted than it gets, one with more.
    #[test]
    fn counts_that_do_not_match_are_a_typed_error() {
        let dir = tempfile::tempdir().unwrap();
        // 8 small triangles near each of two opposite corners: chunks [0,0,0] and [1,1,1] at 512³
        let mut tris = Vec::new();
        for (corner, step) in [(0.0f32, 0.1f32), (10.0, -0.1)] {
            for i in 0..8 {
                let c = [corner + step * i as f32; 3];
                let t = [c, [c[0] + 0.05, c[1], c[2]], [c[0], c[1] + 0.05, c[2]]];
                tris.push(Triangle::new(t));
            }
        }
        let (spool, grid, layout) = positions_spool(dir.path(), &tris, 512);
        let scatter_with = |counted: &[Triangle]| {
            let mut counts = ChunkCounts::new(&grid).unwrap();
            counts.add_triangles(counted);
            let path = dir.path().join("bins");
            scatter(
                &spool,
                &grid,
                &counts,
                &path,
                layout,
                1 << 20,
                &mut |_, _| {},
            )
        };
        let mismatch = |counted: &[Triangle]| match scatter_with(counted).err() {
            Some(TileError::CountChanged {
                coord,
                received,
                counted,
            }) => (coord, received, counted),
            other => panic!("expected CountChanged, got {other:?}"),
        };
        // the second corner's chunk counted empty: its first triangle is found at once
        assert_eq!(mismatch(&tris[..8]), ([1, 1, 1], 1, 0));
        // one triangle fewer counted than it gets, and one more
        assert_eq!(mismatch(&tris[..15]), ([1, 1, 1], 8, 7));
        let more: Vec<Triangle> = tris.iter().chain(&tris[15..]).copied().collect();
        assert_eq!(mismatch(&more), ([1, 1, 1], 8, 9));
        // the counts of the triangles themselves scatter
        let bins = scatter_with(&tris).unwrap();
        assert_eq!(bins.total(), 16);
    }
}
