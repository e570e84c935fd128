//! The markers of a work folder: each stage's result as a small JSON file, written (with
//! [`WorkDir::set_marker`]) only once the stage's data is complete. A resumed build reads
//! them all at once ([`crate::resume::Resume::read`]); no stage reads another's.

use serde::{Deserialize, Serialize};
use voxlod_tile::{Bins, ChunkBin, RecordLayout};

#[cfg(doc)]
use super::work::WorkDir;
use super::work::{Marker, WorkFile};
use crate::stages::source::mesh::SourceCounts;

/// The ingest stage's result (`spool.json`): what the pass over the input found, and whether
/// it wrote a spool.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct IngestMarker {
    /// True if the triangles were written to `spool.tri`; false if the tile stage reads the
    /// input again.
    pub spooled: bool,
    /// Non-degenerate triangles (those the tile stage bins).
    pub count: u64,
    /// The triangles' bounds.
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// Triangles read, degenerate ones included.
    pub triangles: u64,
    /// Zero-area triangles skipped.
    pub degenerate_skipped: u64,
    /// The stage's warnings (shown again by a resumed build).
    pub warnings: Vec<String>,
}

impl Marker for IngestMarker {
    const FILE: WorkFile = WorkFile::IngestMarker;
}

/// The bins layout (`bins.json`): `[x, y, z, start, count]` per non-empty chunk (`start`: the
/// byte offset of its first piece) and each chunk's pieces `[byte offset, bytes, triangles]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct BinsMarker {
    chunks: Vec<[u64; 5]>,
    #[serde(default)]
    pieces: Vec<Vec<[u64; 3]>>,
    /// The records hold world coordinates (bins of an older work format hold grid coordinates:
    /// without this flag they are not trusted and are written again).
    #[serde(default)]
    world: bool,
    /// 0: the pieces hold blocks of triangle records; 4 or 8: the face records of the
    /// triangles as integers of that width (bins of face indices, read with the input).
    #[serde(default)]
    index_bytes: usize,
}

impl Marker for BinsMarker {
    const FILE: WorkFile = WorkFile::BinsMarker;
}

impl BinsMarker {
    /// The layout of `bins`.
    pub(crate) fn of(bins: &Bins) -> BinsMarker {
        let chunks = bins
            .chunks()
            .iter()
            .map(|c| {
                let [x, y, z] = c.coord.map(u64::from);
                [x, y, z, c.start, c.count]
            })
            .collect();
        BinsMarker {
            chunks,
            pieces: bins.pieces().to_vec(),
            world: true,
            index_bytes: bins.index_bytes().unwrap_or(0),
        }
    }

    /// The bins this marker describes, opened (None if the file does not match it, or if it
    /// holds face indices and the input's faces cannot be found by index: `indexable` false).
    pub(crate) fn open(
        self,
        path: &std::path::Path,
        layout: RecordLayout,
        indexable: bool,
    ) -> Option<Bins> {
        if !self.world || !matches!(self.index_bytes, 0 | 4 | 8) {
            return None;
        }
        if self.index_bytes > 0 && !indexable {
            return None;
        }
        let chunks = self.chunks()?;
        Bins::open_pieces_of(path, chunks, layout, self.index_bytes, self.pieces).ok()
    }

    /// The chunks of the layout (None if a coordinate is out of range: the marker is not ours).
    pub(crate) fn chunks(&self) -> Option<Vec<ChunkBin>> {
        self.chunks
            .iter()
            .map(|c| {
                let coord = [
                    u32::try_from(c[0]).ok()?,
                    u32::try_from(c[1]).ok()?,
                    u32::try_from(c[2]).ok()?,
                ];
                Some(ChunkBin {
                    coord,
                    morton: voxlod_geom::morton3(coord[0], coord[1], coord[2]),
                    start: c[3],
                    count: c[4],
                })
            })
            .collect()
    }
}

/// The voxelize stage's totals (`leaves.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct LeavesMarker {
    /// Leaf chunks in the log (one per non-empty bin).
    pub records: u64,
    /// Triangle/chunk pairs the voxelizer skipped.
    pub skipped: u64,
    /// Triangle records in the bins.
    pub binned_triangles: u64,
    /// 0 if the bins held blocks of triangle records; 4 or 8 if they held face indices of
    /// that width (read with the input).
    #[serde(default)]
    pub bin_index_bytes: usize,
    /// Bytes of the leaves' payloads in the log (what the octree file holds of them).
    pub leaf_payload_bytes: u64,
}

impl Marker for LeavesMarker {
    const FILE: WorkFile = WorkFile::LeavesMarker;
}

/// The source-geometry stage's totals (`source.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct SourceMarker {
    /// Records in the source log (one per non-empty bin).
    pub records: u64,
    /// Triangles kept, clipped and stored, over all chunks.
    pub counts: SourceCounts,
    /// Compressed payload bytes in the log.
    pub payload_bytes: u64,
}

impl Marker for SourceMarker {
    const FILE: WorkFile = WorkFile::SourceMarker;
}
