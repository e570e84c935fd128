//! Export of the octree as an OGC 3D Tiles 1.1 tileset (OGC 22-025r4, "3D Tiles
//! Specification 1.1"): `tileset.json`, an **explicit** tile tree that is the file's node tree,
//! and one glTF binary per node ([`NodeGlb`]: the node's face-culled cubes with normals,
//! colours and materials, quantized on the node's grid).
//!
//! - Explicit rather than implicit tiling: the octree is sparse and its node index already
//!   lists every node and its children, so the explicit tree says exactly which tiles exist
//!   (implicit tiling would need subtree files with availability bitstreams to say the same,
//!   and every consumer reads explicit tilesets). The cost is a `tileset.json` that grows with
//!   the node count (about 250 bytes per node).
//! - Coordinates: the file's world coordinates are taken as the tileset's z-up frame; each
//!   tile's glTF node is rotated −90° about x (glTF is y-up), which the consumer's y-up to
//!   z-up rotation undoes (3D Tiles 1.1, "glTF transforms"). No root transform: the model
//!   sits at its own coordinates (CesiumJS users place it with `modelMatrix`).
//! - `boundingVolume.box`: the node's tight voxel bounds (NodeEntry bounds), grown to hold its
//!   children's (so every child lies inside its parent's volume).
//! - `geometricError`: a tile at level `l` with children is off by at most its voxel edge
//!   (`voxel_size · 2^l`) from them; a leaf of the cut has 0; the tileset's is the root
//!   node's extent. Refinement `REPLACE` (children cover their parent: FORMAT.md, face masks
//!   OR'd upwards).
//! - The cut: nodes at `min_level` and coarser (`--level` / `--error`).
//!
//! Streamed: pass 1 sizes every tile (the exact bytes of each GLB) and lays out
//! `tileset.json`; pass 2 writes the tiles in file order, one node in memory at a time.

use std::io::Write;
use std::path::Path;

use serde_json::{json, Value};
use voxlod_format::Reader;

use crate::glb::{NodeGlb, UpAxis};
use crate::RenderError;

/// What a tileset export writes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TilesetSummary {
    /// Tiles in the tree.
    pub tiles: u64,
    /// Tiles with content (a `.glb`); a node whose voxels have no active face has none.
    pub contents: u64,
    /// Quads in all contents.
    pub quads: u64,
    /// Bytes of all files: the GLBs and `tileset.json`.
    pub bytes: u64,
    /// The `tileset.json` text.
    pub tileset_json: String,
}

/// The relative path of node `index`'s content.
pub fn tile_uri(reader: &Reader, index: usize) -> String {
    let e = reader.nodes()[index];
    format!("{}/{}-{}-{}.glb", e.level, e.x, e.y, e.z)
}

/// World box (min, max) of node `index`'s voxels.
fn node_box(reader: &Reader, index: usize) -> ([f64; 3], [f64; 3]) {
    let e = reader.nodes()[index];
    let spec = reader.spec();
    let lo = spec.voxel_min_corner(
        e.level,
        e.pos(),
        [e.bounds_min[0], e.bounds_min[1], e.bounds_min[2]],
    );
    let hi = spec.voxel_min_corner(
        e.level,
        e.pos(),
        [e.bounds_max[0], e.bounds_max[1], e.bounds_max[2]],
    );
    let edge = spec.voxel_size_at(e.level);
    (lo, hi.map(|c| c + edge))
}

/// The tile of node `index` and its subtree down to `min_level`, with its box.
fn tile(
    reader: &Reader,
    index: usize,
    min_level: u32,
    quads: &[u64],
) -> (Value, ([f64; 3], [f64; 3])) {
    let e = reader.nodes()[index];
    let (mut lo, mut hi) = node_box(reader, index);
    let mut children = Vec::new();
    if e.level > min_level {
        for c in reader.children(index).into_iter().flatten() {
            let (t, (clo, chi)) = tile(reader, c, min_level, quads);
            for a in 0..3 {
                lo[a] = lo[a].min(clo[a]);
                hi[a] = hi[a].max(chi[a]);
            }
            children.push(t);
        }
    }
    let error = if children.is_empty() {
        0.0
    } else {
        reader.spec().voxel_size_at(e.level)
    };
    let c: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    let h: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) / 2.0);
    let mut t = json!({
        "boundingVolume": {"box": [c[0], c[1], c[2], h[0], 0.0, 0.0, 0.0, h[1], 0.0, 0.0, 0.0, h[2]]},
        "geometricError": error,
    });
    if quads[index] > 0 {
        t["content"] = json!({"uri": tile_uri(reader, index)});
    }
    if !children.is_empty() {
        t["children"] = Value::Array(children);
    }
    (t, (lo, hi))
}

/// Writes the tileset of the nodes at `min_level` and coarser into the existing empty folder
/// `dir`, calling `before_write` with the summary (exact sizes) before anything is written;
/// an error from it is returned and nothing is written.
pub fn export_tileset_with(
    reader: &Reader,
    min_level: u32,
    dir: &Path,
    before_write: &mut dyn FnMut(&TilesetSummary) -> Result<(), RenderError>,
) -> Result<TilesetSummary, RenderError> {
    let levels = reader.spec().levels;
    if min_level >= levels {
        return Err(RenderError::Option(format!(
            "level {min_level} is not in the file (it has levels 0..={})",
            levels - 1
        )));
    }
    let root = reader
        .root()
        .ok_or_else(|| RenderError::Option("the file has no root node".into()))?;
    let in_cut: Vec<usize> = (0..reader.nodes().len())
        .filter(|&i| reader.nodes()[i].level >= min_level)
        .collect();
    // pass 1: the size of every tile's content
    let mut quads = vec![0u64; reader.nodes().len()];
    let mut s = TilesetSummary::default();
    for &i in &in_cut {
        let g = NodeGlb::new(reader, i, UpAxis::ZUp)?.summary;
        quads[i] = g.quads;
        s.tiles += 1;
        if g.quads > 0 {
            s.contents += 1;
            s.quads += g.quads;
            s.bytes += g.bytes;
        }
    }
    let (mut root_tile, _) = tile(reader, root, min_level, &quads);
    root_tile["refine"] = json!("REPLACE");
    let r = reader.nodes()[root];
    let tileset = json!({
        "asset": {"version": "1.1", "generator": format!("voxlod {}", env!("CARGO_PKG_VERSION"))},
        "geometricError": reader.spec().voxel_size_at(r.level) * 256.0,
        "root": root_tile,
    });
    s.tileset_json = serde_json::to_string(&tileset)
        .map_err(|e| RenderError::Option(format!("serializing tileset.json: {e}")))?;
    s.bytes += s.tileset_json.len() as u64;
    before_write(&s)?;

    // pass 2: the contents in file order, then tileset.json
    for l in min_level..levels {
        let d = dir.join(l.to_string());
        std::fs::create_dir(&d).map_err(RenderError::io("creating", &d))?;
    }
    let mut written = 0u64;
    for &i in &in_cut {
        let g = NodeGlb::new(reader, i, UpAxis::ZUp)?;
        if g.summary.quads != quads[i] {
            return Err(RenderError::Option(
                "the file changed between the two passes of the export".into(),
            ));
        }
        if g.summary.quads == 0 {
            continue;
        }
        let p = dir.join(tile_uri(reader, i));
        let f = std::fs::File::create(&p).map_err(RenderError::io("creating", &p))?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
        g.write_to(&mut w)
            .and_then(|()| w.flush())
            .map_err(RenderError::io("writing", &p))?;
        written += g.summary.bytes;
    }
    let p = dir.join("tileset.json");
    std::fs::write(&p, &s.tileset_json).map_err(RenderError::io("writing", &p))?;
    debug_assert_eq!(written + s.tileset_json.len() as u64, s.bytes);
    Ok(s)
}
