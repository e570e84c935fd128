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
//! Memory is bounded by design: the buffer (records, their keys and the sort's permutation)
//! has a byte budget, the writes go through a fixed staging buffer, and the pieces cost 16
//! bytes per chunk per run; the grid may have at most [`RUN_SCATTER_MAX_CHUNKS`] chunks (dense
//! per-chunk arrays).

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use voxlod_geom::{morton3, Grid, Triangle};

use crate::{Bins, ChunkBin, RecordLayout, TileError, DROPPED, SPANS};

/// Most chunks a grid may have for [`RunScatter`] (its per-chunk arrays are dense): 32³, a
/// grid of 8192³ voxels.
pub const RUN_SCATTER_MAX_CHUNKS: u64 = 32 * 32 * 32;

/// Bytes of the staging buffer through which a run is written.
const STAGING_BYTES: usize = 8 << 20;

/// A scatter in runs in progress (see the module documentation).
pub struct RunScatter {
    grid: Grid,
    n: u32,
    path: PathBuf,
    file: File,
    layout: RecordLayout,
    /// Records of the current run, in arrival order, and their chunks' Morton ranks.
    recs: Vec<u8>,
    ranks: Vec<u32>,
    /// Records the current run holds at most.
    cap: usize,
    /// Chunk linear index `(z·n + y)·n + x` -> rank of the chunk in Morton order.
    rank_of: Vec<u32>,
    /// Per Morton rank: its pieces so far, `[first record, records]`.
    pieces: Vec<Vec<[u64; 2]>>,
    /// Records written to the file.
    written: u64,
    /// Scratch of the sort: records per rank, then each rank's next slot; the permutation.
    slots: Vec<u32>,
    perm: Vec<u32>,
    staging: Vec<u8>,
}

impl RunScatter {
    /// Starts the bins file at `path` (created or truncated) for `grid`, buffering at most
    /// about `buffer_bytes` (records, keys and the sort's permutation; at least 1024 records)
    /// between runs. Refused if the grid has more than [`RUN_SCATTER_MAX_CHUNKS`] chunks.
    pub fn create(
        grid: &Grid,
        path: &Path,
        layout: RecordLayout,
        buffer_bytes: u64,
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
        let rec = layout.bytes();
        // each buffered record: its bytes, its rank and its place in the permutation
        let cap = (buffer_bytes as usize / (rec + 8)).max(1024);
        Ok(RunScatter {
            grid: *grid,
            n,
            path: path.to_path_buf(),
            file,
            layout,
            recs: Vec::with_capacity(cap * rec),
            ranks: Vec::with_capacity(cap),
            cap,
            rank_of,
            pieces: vec![Vec::new(); total as usize],
            written: 0,
            slots: vec![0; total as usize + 1],
            perm: Vec::with_capacity(cap),
            staging: vec![0u8; STAGING_BYTES.max(rec)],
        })
    }

    /// The grid the triangles are binned on.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Bins a batch of grid-space triangles given their [`crate::ChunkKeys::of_grid`] (keys
    /// of this grid): a one-chunk key goes to that chunk, [`SPANS`] to every chunk of the
    /// triangle's range, [`DROPPED`] nowhere.
    pub fn push_keyed(&mut self, tris: &[Triangle], keys: &[u32]) -> Result<(), TileError> {
        assert_eq!(tris.len(), keys.len(), "one key per triangle");
        for (t, &k) in tris.iter().zip(keys) {
            if k == DROPPED {
                continue;
            }
            if k != SPANS {
                self.put(t, k as usize)?;
                continue;
            }
            let Some((lo, hi)) = self.grid.chunk_range(t) else {
                continue;
            };
            let n = self.n as usize;
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        self.put(t, (z as usize * n + y as usize) * n + x as usize)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Adds triangle `t` to the current run for the chunk of linear index `li`.
    #[inline]
    fn put(&mut self, t: &Triangle, li: usize) -> Result<(), TileError> {
        if self.ranks.len() == self.cap {
            self.write_run()?;
        }
        self.layout.encode(t, &mut self.recs)?;
        self.ranks.push(self.rank_of[li]);
        Ok(())
    }

    /// Writes the buffered records as one run, chunk after chunk in Morton order (a counting
    /// sort by rank, stable: input order inside a chunk), and empties the buffer.
    fn write_run(&mut self) -> Result<(), TileError> {
        if self.ranks.is_empty() {
            return Ok(());
        }
        let rec = self.layout.bytes();
        self.slots.fill(0);
        for &r in &self.ranks {
            self.slots[r as usize + 1] += 1;
        }
        for r in 0..self.pieces.len() {
            let k = self.slots[r + 1];
            if k > 0 {
                let first = self.written + self.slots[r] as u64;
                self.pieces[r].push([first, k as u64]);
            }
            self.slots[r + 1] += self.slots[r];
        }
        self.perm.clear();
        self.perm.resize(self.ranks.len(), 0);
        for (i, &r) in self.ranks.iter().enumerate() {
            let s = &mut self.slots[r as usize];
            self.perm[*s as usize] = i as u32;
            *s += 1;
        }
        let per_write = self.staging.len() / rec;
        for part in self.perm.chunks(per_write) {
            for (k, &i) in part.iter().enumerate() {
                let i = i as usize;
                self.staging[k * rec..(k + 1) * rec]
                    .copy_from_slice(&self.recs[i * rec..(i + 1) * rec]);
            }
            self.file
                .write_all_at(&self.staging[..part.len() * rec], self.written * rec as u64)
                .map_err(TileError::io("write", &self.path))?;
            self.written += part.len() as u64;
        }
        self.recs.clear();
        self.ranks.clear();
        Ok(())
    }

    /// Writes the last run and returns the bins: the non-empty chunks in Morton order with
    /// their pieces.
    pub fn finish(mut self) -> Result<Bins, TileError> {
        self.write_run()?;
        self.file
            .sync_data()
            .map_err(TileError::io("sync", &self.path))?;
        let n = self.n;
        let mut by_rank = vec![0u32; self.rank_of.len()];
        for (li, &r) in self.rank_of.iter().enumerate() {
            by_rank[r as usize] = li as u32;
        }
        let (mut chunks, mut pieces) = (Vec::new(), Vec::new());
        for (r, ps) in std::mem::take(&mut self.pieces).into_iter().enumerate() {
            if ps.is_empty() {
                continue;
            }
            let li = by_rank[r];
            let coord = [li % n, li / n % n, li / (n * n)];
            chunks.push(ChunkBin {
                coord,
                morton: morton3(coord[0], coord[1], coord[2]),
                start: ps[0][0],
                count: ps.iter().map(|p| p[1]).sum(),
            });
            pieces.push(ps);
        }
        Ok(Bins::from_runs(
            self.path,
            self.file,
            chunks,
            self.layout,
            pieces,
        ))
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
            // batches of another size than the spool's, moved to the grid as the passes do
            for b in tris.chunks(333) {
                let moved: Vec<Triangle> = b.iter().map(|t| crate::to_grid(&grid, t)).collect();
                rs.push_keyed(&moved, &keys.of_grid(&moved)).unwrap();
            }
            let bins = rs.finish().unwrap();
            let runs = bins.pieces().unwrap().iter().map(Vec::len).max().unwrap();
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
            assert_eq!(
                std::fs::metadata(&path).unwrap().len(),
                reference.total() * rec
            );
            let again = Bins::open_pieces(
                &path,
                bins.chunks().to_vec(),
                layout,
                bins.pieces().unwrap().to_vec(),
            )
            .unwrap();
            assert_eq!(read_all(&again, 1000), read_all(&bins, 1000));
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
        let moved: Vec<Triangle> = tris.iter().map(|t| crate::to_grid(&grid, t)).collect();
        let keys = ChunkCounts::new(&grid).unwrap().keys().of_grid(&moved);
        rs.push_keyed(&moved, &keys).unwrap();
        let bins = rs.finish().unwrap();
        let (chunks, pieces) = (bins.chunks().to_vec(), bins.pieces().unwrap().to_vec());
        assert!(Bins::open_pieces(&path, chunks.clone(), layout, pieces.clone()).is_ok());
        let mut short = pieces.clone();
        short[0][0][1] -= 1;
        let e = Bins::open_pieces(&path, chunks.clone(), layout, short)
            .err()
            .unwrap();
        assert!(matches!(e, TileError::Truncated { .. }), "{e:?}");
        let mut past = pieces.clone();
        past[0][0][0] += 1 << 40;
        assert!(Bins::open_pieces(&path, chunks.clone(), layout, past).is_err());
        assert!(Bins::open_pieces(&path, chunks[1..].to_vec(), layout, pieces).is_err());
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
