//! Scatter in runs: binning without the per-chunk counts, so that the pass that reads the input
//! for its bounds can bin it too (one parse instead of two).
//!
//! [`crate::scatter`] (PotreeConverter 2's counting-sort chunker, Schütz et al. 2020) needs the
//! counts of a first pass to lay out one pre-sized region per chunk. When the grid is known
//! before the triangles are read (a binary PLY's vertex list gives it), the counting can move
//! into the buffer instead: triangles are encoded as compact records in arrival order into one
//! buffer; when it is full, a counting sort by the chunks' Morton rank (the keys kept beside
//! the records) writes the buffer as one *run* appended to the bins file, chunk after chunk in
//! Morton order. A chunk's bin is then the list of its pieces in the runs, in input order, so
//! [`Bins::read_chunk`] hands out the same triangles, in the same order and the same batches,
//! as the bins of [`crate::scatter`].
//!
//! The writer thread encodes each chunk's records of the sorted run as [blocks](crate::block)
//! (each distinct corner once, 16-bit indices) into a bounded output buffer appended to the
//! file; a chunk's part of a run is one piece `[byte offset, bytes, triangles]`.
//!
//! Bins of face indices ([`RunScatter::create_indexed`]): for an input whose triangles can be
//! found again by their face record (a memory-mapped PLY of fixed-size triangle records), a
//! run holds each (triangle, chunk) pair's face record (4 or 8 bytes) instead of its record,
//! sorted the same way and written as it is, without blocks: the same chunks, pieces and order,
//! about a quarter of the bytes, and no encoding; the reader rebuilds the triangles from the
//! input ([`crate::TriangleSource`]).
//!
//! Memory is bounded by design: the buffer (records, their keys and the sort's permutation)
//! has a byte budget, the writer's output buffer is [`OUT_BYTES`] plus a chunk's blocks, and
//! the pieces cost 24 bytes per chunk per run; the grid may have at most
//! [`RUN_SCATTER_MAX_CHUNKS`] chunks (dense per-chunk arrays).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use voxlod_geom::{morton3, Grid, Triangle};

use crate::block::BlockEncoder;
use crate::{Bins, ChunkBin, RecordLayout, TileError};

/// Most chunks a grid may have for [`RunScatter`] (its per-chunk arrays are dense): 32³, a
/// grid of 8192³ voxels.
pub const RUN_SCATTER_MAX_CHUNKS: u64 = 32 * 32 * 32;

/// The writer's output buffer is written to the file once it holds this many bytes.
const OUT_BYTES: usize = 4 << 20;

/// One run's records, in arrival order, and their chunks' Morton ranks.
#[derive(Default)]
struct Run {
    recs: Vec<u8>,
    ranks: Vec<u32>,
}

/// A scatter in runs in progress (see the module documentation). The caller's thread encodes
/// records into the current run; a full run goes to a writer thread, which sorts and writes it
/// while the next one fills (two runs in memory, so the kernel's copy of the bins into the
/// page cache runs beside the binning instead of after it).
pub struct RunScatter {
    grid: Grid,
    n: u32,
    layout: RecordLayout,
    /// 0: records, written as blocks; 4 or 8: face indices of that width, written as they are.
    index_bytes: usize,
    /// The run being filled, and the other buffer when the writer is not holding it.
    current: Run,
    spare: Option<Run>,
    /// Records one run holds at most.
    cap: usize,
    /// Chunk linear index `(z·n + y)·n + x` -> rank of the chunk in Morton order.
    rank_of: Vec<u32>,
    /// Full runs to the writer; emptied ones back.
    to_writer: Option<std::sync::mpsc::SyncSender<Run>>,
    from_writer: std::sync::mpsc::Receiver<Run>,
    writer: Option<std::thread::JoinHandle<Result<Writer, TileError>>>,
}

/// The writer thread's state: the file and where each chunk's pieces are.
struct Writer {
    path: PathBuf,
    file: File,
    /// Bytes of one item of a run: a record, or a face index.
    rec: usize,
    /// True if the items are face indices (copied as they are, no blocks).
    indexed: bool,
    /// Per Morton rank: its pieces so far, `[byte offset, bytes, triangles]`.
    pieces: Vec<Vec<[u64; 3]>>,
    /// Bytes written to the file.
    written: u64,
    /// Scratch of the sort: records per rank, then each rank's next slot; the permutation.
    slots: Vec<u32>,
    perm: Vec<u32>,
    encoder: BlockEncoder,
    /// Blocks not yet written to the file (they start at `written`).
    out: Vec<u8>,
    /// With [`RunScatter::with_piece_crcs`]: per Morton rank, the CRC-32 of each of its pieces.
    crcs: Option<Vec<Vec<u32>>>,
}

impl RunScatter {
    /// Starts the bins file at `path` (created or truncated) for `grid`, buffering at most
    /// about `buffer_bytes` (two runs of records and keys, and the sort's permutation; at least
    /// 1024 records a run). Refused if the grid has more than [`RUN_SCATTER_MAX_CHUNKS`]
    /// chunks.
    pub fn create(
        grid: &Grid,
        path: &Path,
        layout: RecordLayout,
        buffer_bytes: u64,
    ) -> Result<RunScatter, TileError> {
        Self::create_as(grid, path, layout, 0, buffer_bytes, false)
    }

    /// [`RunScatter::create`] that also takes the CRC-32 of every piece as it is written
    /// ([`Bins::piece_crcs`]): for bins another process reads (a sharded build's map outputs),
    /// which [`Bins::open_in_place`] then checks piece by piece as it reads them.
    pub fn create_with_piece_crcs(
        grid: &Grid,
        path: &Path,
        layout: RecordLayout,
        buffer_bytes: u64,
    ) -> Result<RunScatter, TileError> {
        Self::create_as(grid, path, layout, 0, buffer_bytes, true)
    }

    /// [`RunScatter::create`] for bins of face indices of `index_bytes` (4 or 8) bytes each
    /// ([`RunScatter::push_indexed`]); `layout` is that of the triangles the indices stand for.
    pub fn create_indexed(
        grid: &Grid,
        path: &Path,
        layout: RecordLayout,
        index_bytes: usize,
        buffer_bytes: u64,
    ) -> Result<RunScatter, TileError> {
        assert!(matches!(index_bytes, 4 | 8), "u32 or u64 face indices");
        Self::create_as(grid, path, layout, index_bytes, buffer_bytes, false)
    }

    fn create_as(
        grid: &Grid,
        path: &Path,
        layout: RecordLayout,
        index_bytes: usize,
        buffer_bytes: u64,
        piece_crcs: bool,
    ) -> Result<RunScatter, TileError> {
        let n = grid.chunks_per_axis();
        let total = (n as u64).pow(3);
        if total > RUN_SCATTER_MAX_CHUNKS {
            return Err(TileError::TooManyChunks(total));
        }
        let mut by_morton: Vec<u32> = (0..total as u32).collect();
        let coord = |li: u32| [li % n, li / n % n, li / (n * n)];
        by_morton.sort_unstable_by_key(|&li| {
            let [x, y, z] = coord(li);
            morton3(x, y, z)
        });
        let mut rank_of = vec![0u32; total as usize];
        for (r, &li) in by_morton.iter().enumerate() {
            rank_of[li as usize] = r as u32;
        }
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)
            .map_err(TileError::io("create", path))?;
        let rec = if index_bytes > 0 {
            index_bytes
        } else {
            layout.bytes()
        };
        // per record of a run: its bytes and rank twice (two runs), its place in the permutation
        let cap = (buffer_bytes as usize / (2 * (rec + 4) + 4)).max(1024);
        let mut w = Writer {
            path: path.to_path_buf(),
            file,
            rec,
            indexed: index_bytes > 0,
            pieces: vec![Vec::new(); total as usize],
            written: 0,
            slots: vec![0; total as usize + 1],
            perm: Vec::new(),
            encoder: BlockEncoder::new(layout),
            out: Vec::new(),
            crcs: piece_crcs.then(|| vec![Vec::new(); total as usize]),
        };
        let (to_writer, runs) = std::sync::mpsc::sync_channel::<Run>(1);
        let (back, from_writer) = std::sync::mpsc::channel::<Run>();
        let writer = std::thread::Builder::new()
            .name("bins-writer".into())
            .spawn(move || {
                for mut run in runs {
                    w.write_run(&run)?;
                    run.recs.clear();
                    run.ranks.clear();
                    // the binning side may be gone (an error there): nothing to hand back to
                    let _ = back.send(run);
                }
                Ok(w)
            })
            .map_err(TileError::io("starting the writer thread of", path))?;
        Ok(RunScatter {
            grid: *grid,
            n,
            layout,
            index_bytes,
            current: Run::default(),
            spare: Some(Run::default()),
            cap,
            rank_of,
            to_writer: Some(to_writer),
            from_writer,
            writer: Some(writer),
        })
    }

    /// The grid the triangles are binned on.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Bins a batch of world-space triangles given their [`crate::ChunkKeys::of_world`] (keys
    /// of this grid): a one-chunk key goes to that chunk, [`crate::SPANS`] to every chunk of
    /// the triangle's range, [`crate::DROPPED`] nowhere.
    pub fn push_keyed(&mut self, tris: &[Triangle], keys: &[u32]) -> Result<(), TileError> {
        assert_eq!(self.index_bytes, 0, "bins of records");
        let (grid, n) = (self.grid, self.n);
        crate::bins::for_each_keyed_chunk(&grid, n, tris, keys, |_, t, li| {
            self.reserve()?;
            self.layout.encode(t, &mut self.current.recs)?;
            self.current.ranks.push(self.rank_of[li]);
            Ok(())
        })
    }

    /// [`RunScatter::push_keyed`] for bins of face indices ([`RunScatter::create_indexed`]):
    /// `faces[i]` is the face record of `tris[i]`, what the bins hold for it.
    pub fn push_indexed(
        &mut self,
        tris: &[Triangle],
        keys: &[u32],
        faces: &[u64],
    ) -> Result<(), TileError> {
        assert!(self.index_bytes > 0, "bins of face indices");
        assert_eq!(tris.len(), faces.len(), "one face record per triangle");
        let (grid, n, w) = (self.grid, self.n, self.index_bytes);
        assert!(
            w == 8 || faces.iter().all(|&f| f <= u32::MAX as u64),
            "face records fit the index width"
        );
        crate::bins::for_each_keyed_chunk(&grid, n, tris, keys, |i, _, li| {
            self.reserve()?;
            self.current
                .recs
                .extend_from_slice(&faces[i].to_le_bytes()[..w]);
            self.current.ranks.push(self.rank_of[li]);
            Ok(())
        })
    }

    /// Makes room for one more item in the current run (sending it to the writer if full).
    #[inline]
    fn reserve(&mut self) -> Result<(), TileError> {
        if self.current.ranks.len() == self.cap {
            self.send_run()?;
        }
        if self.current.ranks.capacity() == 0 {
            let rec = if self.index_bytes > 0 {
                self.index_bytes
            } else {
                self.layout.bytes()
            };
            self.current.recs.reserve_exact(self.cap * rec);
            self.current.ranks.reserve_exact(self.cap);
        }
        Ok(())
    }

    /// Hands the current run to the writer and takes the other buffer (waiting for the writer
    /// to finish with it).
    fn send_run(&mut self) -> Result<(), TileError> {
        let next = match self.spare.take() {
            Some(r) => r,
            None => match self.from_writer.recv() {
                Ok(r) => r,
                Err(_) => return Err(self.writer_error()),
            },
        };
        let full = std::mem::replace(&mut self.current, next);
        let sent = self.to_writer.as_ref().map(|tx| tx.send(full));
        match sent {
            Some(Ok(())) => Ok(()),
            _ => Err(self.writer_error()),
        }
    }

    /// The error with which the writer thread stopped (it stops only on one).
    fn writer_error(&mut self) -> TileError {
        match self.join_writer() {
            Err(e) => e,
            Ok(_) => TileError::Callback("the bins writer thread stopped".into()),
        }
    }

    /// Closes the writer's channel and waits for the thread: its state, or its error (a
    /// panic there is resumed here).
    fn join_writer(&mut self) -> Result<Writer, TileError> {
        self.to_writer = None;
        match self.writer.take().map(|h| h.join()) {
            Some(Ok(r)) => r,
            Some(Err(panic)) => std::panic::resume_unwind(panic),
            None => Err(TileError::Callback("the bins writer thread stopped".into())),
        }
    }

    /// Writes the last run and returns the bins: the non-empty chunks in Morton order with
    /// their pieces.
    pub fn finish(mut self) -> Result<Bins, TileError> {
        if !self.current.ranks.is_empty() {
            self.send_run()?;
        }
        let w = self.join_writer()?;
        w.file.sync_data().map_err(TileError::io("sync", &w.path))?;
        let n = self.n;
        let mut by_rank = vec![0u32; self.rank_of.len()];
        for (li, &r) in self.rank_of.iter().enumerate() {
            by_rank[r as usize] = li as u32;
        }
        let (mut chunks, mut pieces) = (Vec::new(), Vec::new());
        let mut crcs = w.crcs.as_ref().map(|_| Vec::new());
        for (r, ps) in w.pieces.into_iter().enumerate() {
            if ps.is_empty() {
                continue;
            }
            if let (Some(out), Some(all)) = (&mut crcs, &w.crcs) {
                out.push(all[r].clone());
            }
            let li = by_rank[r];
            let coord = [li % n, li / n % n, li / (n * n)];
            chunks.push(ChunkBin {
                coord,
                morton: morton3(coord[0], coord[1], coord[2]),
                start: ps[0][0],
                count: ps.iter().map(|p| p[2]).sum(),
            });
            pieces.push(ps);
        }
        let mut bins = Bins::from_runs(
            w.path,
            w.file,
            chunks,
            self.layout,
            self.index_bytes,
            pieces,
            w.written,
        );
        bins.crcs = crcs;
        Ok(bins)
    }
}

impl Drop for RunScatter {
    /// Stops the writer thread of a scatter that is not finished (an error or an interrupt
    /// in the pass): the channel closes, the thread ends after the run in hand.
    fn drop(&mut self) {
        self.to_writer = None;
        if let Some(h) = self.writer.take() {
            let _ = h.join();
        }
    }
}

impl Writer {
    /// Appends `run` to the file, chunk after chunk in Morton order (a counting sort by rank,
    /// stable: input order inside a chunk), each chunk's records as blocks, and notes each
    /// chunk's piece.
    fn write_run(&mut self, run: &Run) -> Result<(), TileError> {
        if run.ranks.is_empty() {
            return Ok(());
        }
        let rec = self.rec;
        self.slots.fill(0);
        for &r in &run.ranks {
            self.slots[r as usize + 1] += 1;
        }
        for r in 0..self.pieces.len() {
            self.slots[r + 1] += self.slots[r];
        }
        self.perm.clear();
        self.perm.resize(run.ranks.len(), 0);
        for (i, &r) in run.ranks.iter().enumerate() {
            let s = &mut self.slots[r as usize];
            self.perm[*s as usize] = i as u32;
            *s += 1;
        }
        // now `slots[r]` is the end of rank r's records in `perm`
        let mut first = 0usize;
        for r in 0..self.pieces.len() {
            let end = self.slots[r] as usize;
            if end == first {
                continue;
            }
            let (recs, perm) = (&run.recs, &self.perm[first..end]);
            let at = self.out.len();
            if self.indexed {
                // face indices as they are, in the chunk's input order
                for &j in perm {
                    let j = j as usize;
                    self.out.extend_from_slice(&recs[j * rec..(j + 1) * rec]);
                }
            } else {
                self.encoder.encode(
                    perm.len(),
                    |i| {
                        let j = perm[i] as usize;
                        &recs[j * rec..(j + 1) * rec]
                    },
                    &mut self.out,
                );
            }
            let bytes = (self.out.len() - at) as u64;
            self.pieces[r].push([self.written + at as u64, bytes, perm.len() as u64]);
            if let Some(crcs) = &mut self.crcs {
                crcs[r].push(crc32fast::hash(&self.out[at..]));
            }
            first = end;
            if self.out.len() >= OUT_BYTES {
                self.flush()?;
            }
        }
        self.flush()
    }

    /// Appends the output buffer to the file.
    fn flush(&mut self) -> Result<(), TileError> {
        (&self.file)
            .write_all(&self.out)
            .map_err(TileError::io("write", &self.path))?;
        self.written += self.out.len() as u64;
        self.out.clear();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{scatter, ChunkCounts, Spooler};
    use voxlod_geom::Bounds;

    /// Random triangles over a 10-unit cube: most small, every 40th large (over several
    /// chunks at 1024³), each with its index in its colour.
    fn triangles(n: usize) -> Vec<Triangle> {
        let mut s = 11u64;
        let mut f = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        (0..n)
            .map(|i| {
                let c = [f() * 10.0, f() * 10.0, f() * 10.0];
                let r = if i % 40 == 0 { 5.0 } else { 0.2 };
                let mut t = Triangle::new([
                    c,
                    [c[0] + r * f(), c[1], c[2] + r],
                    [c[0], c[1] + r * f(), c[2]],
                ]);
                t.c[1] = [(i % 256) as u8, (i / 256 % 256) as u8, (i >> 16) as u8, 255];
                t
            })
            .collect()
    }

    /// Each chunk's triangles, read back in batches of `batch`, with the batch sizes seen.
    fn read_all(bins: &Bins, batch: usize) -> Vec<(ChunkBin, Vec<Triangle>, Vec<usize>)> {
        (0..bins.chunks().len())
            .map(|i| {
                let (mut got, mut sizes) = (Vec::new(), Vec::new());
                bins.read_chunk(i, batch, &mut |b| {
                    got.extend_from_slice(b);
                    sizes.push(b.len());
                    Ok(())
                })
                .unwrap();
                (bins.chunks()[i], got, sizes)
            })
            .collect()
    }

    /// Against the counted scatter (itself checked against brute force in `bins.rs`): for
    /// any buffer size (one run, many runs, runs of the minimum 1024 records), every chunk
    /// holds the same triangles in the same order and is handed out in the same batches; the
    /// file holds exactly the binned records, and reopening it from its pieces gives the same.
    #[test]
    fn runs_give_the_bins_of_the_counted_scatter() {
        let dir = tempfile::tempdir().unwrap();
        let tris = triangles(6000);
        let layout = RecordLayout {
            normals: false,
            colors: true,
            texcoords: false,
        };
        let mut sp = Spooler::create(&dir.path().join("spool"), layout).unwrap();
        sp.push(&tris).unwrap();
        let spool = sp.finish().unwrap();
        let mut bounds = Bounds::default();
        tris.iter().for_each(|t| bounds.add_triangle(t));
        let grid = Grid::fit(&bounds, 1024).unwrap();
        let mut counts = ChunkCounts::new(&grid).unwrap();
        counts.add_triangles(&tris);
        let reference = scatter(
            &spool,
            &grid,
            &counts,
            &dir.path().join("bins-counted"),
            layout,
            1 << 20,
            &mut |_, _| {},
        )
        .unwrap();
        let want = read_all(&reference, 97);
        let keys = counts.keys();
        let rec = layout.bytes() as u64;
        for buffer in [1u64 << 30, 100 * 1024, 0] {
            let path = dir.path().join(format!("bins-runs-{buffer}"));
            let mut rs = RunScatter::create(&grid, &path, layout, buffer).unwrap();
            // batches of another size than the spool's, keyed as the passes do (world
            // coordinates)
            for b in tris.chunks(333) {
                rs.push_keyed(b, &keys.of_world(b)).unwrap();
            }
            let bins = rs.finish().unwrap();
            let runs = bins.pieces().iter().map(Vec::len).max().unwrap();
            assert!(
                (buffer == 1 << 30) == (runs == 1),
                "buffer {buffer}: at most {runs} pieces per chunk"
            );
            let got = read_all(&bins, 97);
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(
                    (g.0.coord, g.0.morton, g.0.count),
                    (w.0.coord, w.0.morton, w.0.count)
                );
                assert_eq!(g.1, w.1, "chunk {:?}: other triangles or order", w.0.coord);
                assert_eq!(g.2, w.2, "chunk {:?}: other batches", w.0.coord);
            }
            // blocks: never more than the records and their headers (these triangles share no
            // corners: raw blocks)
            let len = std::fs::metadata(&path).unwrap().len();
            assert_eq!(len, bins.bytes());
            let pieces = bins.pieces().iter().map(Vec::len).sum::<usize>() as u64;
            assert!(len <= layout.blocks_bound(reference.total(), pieces));
            assert!(len >= reference.total() * rec, "{len} bytes");
            let again = Bins::open_pieces(
                &path,
                bins.chunks().to_vec(),
                layout,
                bins.pieces().to_vec(),
            )
            .unwrap();
            assert_eq!(read_all(&again, 1000), read_all(&bins, 1000));
            assert!(bins.piece_crcs().is_none());
            // with the pieces' CRC-32: the same file, and each CRC that of its piece's bytes
            let checked = dir.path().join(format!("bins-crc-{buffer}"));
            let mut rs =
                RunScatter::create_with_piece_crcs(&grid, &checked, layout, buffer).unwrap();
            for b in tris.chunks(333) {
                rs.push_keyed(b, &keys.of_world(b)).unwrap();
            }
            let with = rs.finish().unwrap();
            let bytes = std::fs::read(&checked).unwrap();
            assert!(bytes == std::fs::read(&path).unwrap());
            assert_eq!(with.pieces(), bins.pieces());
            let crcs = with.piece_crcs().unwrap();
            assert_eq!(crcs.len(), with.pieces().len());
            for (ps, cs) in with.pieces().iter().zip(crcs) {
                let want: Vec<u32> = ps
                    .iter()
                    .map(|p| crc32fast::hash(&bytes[p[0] as usize..(p[0] + p[1]) as usize]))
                    .collect();
                assert_eq!(cs, &want);
            }
        }
    }

    /// The triangles of a list, found by their index (the face records of a test input).
    struct ByIndex<'a>(&'a [Triangle]);

    impl crate::TriangleSource for ByIndex<'_> {
        fn triangles_at(&self, faces: &[u64], out: &mut Vec<Triangle>) -> Result<(), TileError> {
            out.extend(faces.iter().map(|&f| self.0[f as usize]));
            Ok(())
        }
    }

    /// Bins of face indices hold the same chunks, triangles (read back through the source),
    /// order and batches as bins of records, for one run and many, u32 and u64 indices; each
    /// piece is exactly its triangles' indices; they need their source to be read, and reopen
    /// from their pieces only as indices of the same width.
    #[test]
    fn indexed_runs_give_the_bins_of_records() {
        let dir = tempfile::tempdir().unwrap();
        let tris = triangles(6000);
        let layout = RecordLayout {
            normals: false,
            colors: true,
            texcoords: false,
        };
        let mut bounds = Bounds::default();
        tris.iter().for_each(|t| bounds.add_triangle(t));
        let grid = Grid::fit(&bounds, 1024).unwrap();
        let keys = ChunkCounts::new(&grid).unwrap().keys();
        let path = dir.path().join("bins-records");
        let mut rs = RunScatter::create(&grid, &path, layout, 0).unwrap();
        // the face records of the input: every triangle's index, less the dropped ones, as
        // the stream skips degenerate faces (so indices and batch positions differ)
        let faces: Vec<u64> = (0..tris.len() as u64).filter(|f| f % 7 != 3).collect();
        let kept: Vec<Triangle> = faces.iter().map(|&f| tris[f as usize]).collect();
        for (b, f) in kept.chunks(333).zip(faces.chunks(333)) {
            assert_eq!(b.len(), f.len());
            rs.push_keyed(b, &keys.of_world(b)).unwrap();
        }
        let want = read_all(&rs.finish().unwrap(), 97);
        let source = ByIndex(&tris);
        for (buffer, width) in [(1u64 << 30, 4), (0, 4), (0, 8)] {
            let path = dir.path().join(format!("bins-indices-{buffer}-{width}"));
            let mut rs = RunScatter::create_indexed(&grid, &path, layout, width, buffer).unwrap();
            for (b, f) in kept.chunks(333).zip(faces.chunks(333)) {
                rs.push_indexed(b, &keys.of_world(b), f).unwrap();
            }
            let bins = rs.finish().unwrap();
            assert_eq!(bins.index_bytes(), Some(width));
            let binned: u64 = want.iter().map(|w| w.0.count).sum();
            assert_eq!(bins.bytes(), binned * width as u64, "only the indices");
            assert_eq!(std::fs::metadata(&path).unwrap().len(), bins.bytes());
            let read = |bins: &Bins| -> Vec<(ChunkBin, Vec<Triangle>, Vec<usize>)> {
                (0..bins.chunks().len())
                    .map(|i| {
                        let (mut got, mut sizes) = (Vec::new(), Vec::new());
                        bins.read_chunk_from(i, 97, Some(&source), &mut |b| {
                            got.extend_from_slice(b);
                            sizes.push(b.len());
                            Ok(())
                        })
                        .unwrap();
                        (bins.chunks()[i], got, sizes)
                    })
                    .collect()
            };
            let got = read(&bins);
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                assert_eq!((g.0.coord, g.0.count), (w.0.coord, w.0.count));
                assert!(
                    g.1 == w.1,
                    "chunk {:?}: other triangles or order",
                    w.0.coord
                );
                assert_eq!(g.2, w.2, "chunk {:?}: other batches", w.0.coord);
            }
            // without the source: an error naming the file, not blocks misread
            let e = bins.read_chunk(0, 97, &mut |_| Ok(())).unwrap_err();
            assert!(matches!(e, TileError::BadBins { .. }), "{e:?}");
            let (chunks, pieces) = (bins.chunks().to_vec(), bins.pieces().to_vec());
            let again =
                Bins::open_pieces_of(&path, chunks.clone(), layout, width, pieces.clone()).unwrap();
            assert!(read(&again) == got);
            let other = 12 - width;
            assert!(
                Bins::open_pieces_of(&path, chunks.clone(), layout, other, pieces.clone()).is_err()
            );
        }
    }

    /// Pieces that do not add up to a chunk's count, or reach past the file, are refused
    /// when reopening (a marker that is not the file's).
    #[test]
    fn reopening_with_pieces_that_do_not_fit_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let tris = triangles(3000);
        let layout = RecordLayout {
            normals: false,
            colors: true,
            texcoords: false,
        };
        let mut bounds = Bounds::default();
        tris.iter().for_each(|t| bounds.add_triangle(t));
        let grid = Grid::fit(&bounds, 512).unwrap();
        let path = dir.path().join("bins");
        let mut rs = RunScatter::create(&grid, &path, layout, 0).unwrap();
        let keys = ChunkCounts::new(&grid).unwrap().keys().of_world(&tris);
        rs.push_keyed(&tris, &keys).unwrap();
        let bins = rs.finish().unwrap();
        let (chunks, pieces) = (bins.chunks().to_vec(), bins.pieces().to_vec());
        assert!(Bins::open_pieces(&path, chunks.clone(), layout, pieces.clone()).is_ok());
        let mut short = pieces.clone();
        short[0][0][1] -= 1;
        let e = Bins::open_pieces(&path, chunks.clone(), layout, short)
            .err()
            .unwrap();
        assert!(matches!(e, TileError::BadBins { .. }), "{e:?}");
        let mut fewer = pieces.clone();
        fewer[0][0][2] -= 1;
        assert!(Bins::open_pieces(&path, chunks.clone(), layout, fewer).is_err());
        let mut past = pieces.clone();
        past[0][0][0] += 1 << 40;
        assert!(Bins::open_pieces(&path, chunks.clone(), layout, past).is_err());
        assert!(Bins::open_pieces(&path, chunks[1..].to_vec(), layout, pieces.clone()).is_err());
        // a damaged block header is found when the chunk is read, naming the file
        drop(bins);
        let mut bytes = std::fs::read(&path).unwrap();
        let at = pieces[0][0][0] as usize;
        bytes[at..at + 4].copy_from_slice(&0u32.to_le_bytes());
        std::fs::write(&path, bytes).unwrap();
        let bins = Bins::open_pieces(&path, chunks, layout, pieces).unwrap();
        let e = bins.read_chunk(0, 100, &mut |_| Ok(())).unwrap_err();
        assert!(matches!(e, TileError::BadBins { .. }), "{e:?}");
        assert!(e.to_string().contains("bins"), "{e}");
    }

    /// A grid with more chunks than the dense arrays allow is refused with a typed error.
    #[test]
    fn too_many_chunks_is_refused() {
        let bounds = Bounds {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let grid = Grid::fit(&bounds, 16384).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let layout = RecordLayout::FULL;
        let e = RunScatter::create(&grid, &dir.path().join("b"), layout, 1 << 20)
            .err()
            .unwrap();
        assert!(matches!(e, TileError::TooManyChunks(262144)), "{e:?}");
    }
}
