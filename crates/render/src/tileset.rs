//! Export of the octree as an OGC 3D Tiles 1.1 tileset (OGC 22-025r4, "3D Tiles
//! Specification 1.1"): `tileset.json`, an **explicit** tile tree that is the file's node tree,
//! and one glTF binary per node ([`crate::tile_content`]: the node's visible faces with shared
//! vertices, linear colours and material feature ids, compressed with
//! `EXT_meshopt_compression`).
//!
//! - Explicit rather than implicit tiling: the octree is sparse and its node index already
//!   lists every node and its children, so the explicit tree says exactly which tiles exist
//!   (implicit tiling would need subtree files with availability bitstreams to say the same).
//!   Its cost is a `tileset.json` of about 200 bytes per node, under 1 % of the tiles' bytes.
//! - Up: the tiles' frame is z-up with the model's up (the same as `voxlod render`'s:
//!   [`TilesetOptions::up`]) turned onto +z by the root `transform`; each tile's glTF node is
//!   turned −90° about x (glTF is y-up), which the consumer undoes (3D Tiles 1.1, "glTF
//!   transforms").
//! - Placement: with [`TilesetOptions::origin`] (longitude, latitude, height on WGS 84) the
//!   root transform is also the east-north-up frame at that point, and the model's bottom
//!   centre sits there; [`TilesetOptions::scale`] (metres per file unit) scales the contents.
//! - `boundingVolume.box`: the node's tight voxel bounds (NodeEntry bounds), grown to hold its
//!   children's (so every child lies inside its parent's volume).
//! - `geometricError`: [`GEOMETRIC_ERROR_PER_EDGE`] times the tile's voxel edge, so that at the
//!   consumers' default maximum screen-space error of 16 pixels (CesiumJS
//!   `maximumScreenSpaceError`, 3d-tiles-renderer `errorTarget`) a tile is drawn while its
//!   voxels are at most 2 pixels and is replaced by its children beyond; 0 at the leaves of the
//!   cut. Refinement `REPLACE` (children cover their parent: FORMAT.md, face masks OR'd up).
//! - The cut: nodes at `min_level` and coarser (`--level` / `--error`).
//!
//! Streamed: each tile is made and written into the folder in file order (one node in memory
//! at a time), then `tileset.json`.

use std::path::Path;

use serde_json::{json, Value};
use voxlod_format::Reader;

use crate::tile_glb::{material_names, tile_content, TileFrame};
use crate::RenderError;

/// A tile's `geometricError` over its voxel edge: at a maximum screen-space error of 16
/// pixels the voxels drawn are at most `16 / 8 = 2` pixels.
pub const GEOMETRIC_ERROR_PER_EDGE: f64 = 8.0;

/// The consumers' default maximum screen-space error, in pixels.
pub const DEFAULT_MAX_SSE: f64 = 16.0;

/// The largest tile content written whole: a node whose content is larger is split into its
/// eight octants (one content each), so that a first frame waits for no more than this.
pub const MAX_TILE_BYTES: u64 = 4_000_000;

/// How a tileset is cut and placed.
#[derive(Clone, Debug, PartialEq)]
pub struct TilesetOptions {
    /// The finest level written.
    pub min_level: u32,
    /// The model's up in file coordinates (turned onto the tileset's +z).
    pub up: [f64; 3],
    /// Longitude and latitude in degrees and height in metres (WGS 84) where the model's
    /// bottom centre is placed, east-north-up; `None`: the file's coordinates, turned.
    pub origin: Option<[f64; 3]>,
    /// Metres (tileset units) per file unit.
    pub scale: f64,
    /// The most bytes written (tiles and `tileset.json`); past it no further tile is written
    /// and the export fails, after sizing the rest.
    pub max_bytes: u64,
}

impl Default for TilesetOptions {
    fn default() -> Self {
        TilesetOptions {
            min_level: 0,
            up: [0.0, 0.0, 1.0],
            origin: None,
            scale: 1.0,
            max_bytes: u64::MAX,
        }
    }
}

/// What a tileset export writes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TilesetSummary {
    /// Tiles in the tree.
    pub tiles: u64,
    /// Tiles with content (a `.glb`); a node whose voxels have no active face has none.
    pub contents: u64,
    /// Voxels of the nodes in the cut.
    pub voxels: u64,
    /// Quads in all contents.
    pub quads: u64,
    /// Bytes of all files: the GLBs and `tileset.json`.
    pub bytes: u64,
    /// The largest content, in bytes.
    pub largest_tile: u64,
    /// The vertex and index bytes the contents would have uncompressed.
    pub raw_bytes: u64,
    /// The `tileset.json` text.
    pub tileset_json: String,
}

/// The relative path of node `index`'s content.
pub fn tile_uri(reader: &Reader, index: usize) -> String {
    let e = reader.nodes()[index];
    format!("{}/{}-{}-{}.glb", e.level, e.x, e.y, e.z)
}

/// The relative path of the content of part `part` (an octant path) of node `index` (a node
/// split for size): `L/X-Y-Z-o1-o2….glb`.
pub fn tile_part_uri(reader: &Reader, index: usize, part: &[u8]) -> String {
    let e = reader.nodes()[index];
    let mut s = format!("{}/{}-{}-{}", e.level, e.x, e.y, e.z);
    for o in part {
        s += &format!("-{o}");
    }
    s + ".glb"
}

/// What a node's tile (or a part of it) holds.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
enum Content {
    /// No active face.
    #[default]
    None,
    /// One content.
    Whole,
    /// Split into its eight octants.
    Split(Box<[Content; 8]>),
}

/// File box (min, max) of node `index`'s voxels.
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

/// The rotation (rows) that turns unit vector `up` onto +z by the shortest turn (for −z: half
/// a turn about x).
pub fn rotation_to_z(up: [f64; 3]) -> [[f64; 3]; 3] {
    let len = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
    let u = up.map(|c| c / len);
    let c = u[2];
    if c < -1.0 + 1e-12 {
        return [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
    }
    // v = u × z; R = I + [v]× + [v]×² / (1 + c)
    let v = [u[1], -u[0], 0.0];
    let k = [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let k2: f64 = (0..3).map(|m| k[i][m] * k[m][j]).sum();
            (if i == j { 1.0 } else { 0.0 }) + k[i][j] + k2 / (1.0 + c)
        })
    })
}

/// Earth-centred, earth-fixed coordinates of a WGS 84 point (degrees, metres).
pub fn wgs84_to_ecef(lon_deg: f64, lat_deg: f64, height: f64) -> [f64; 3] {
    let a = 6_378_137.0;
    let f = 1.0 / 298.257_223_563;
    let e2 = f * (2.0 - f);
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    let n = a / (1.0 - e2 * lat.sin().powi(2)).sqrt();
    [
        (n + height) * lat.cos() * lon.cos(),
        (n + height) * lat.cos() * lon.sin(),
        (n * (1.0 - e2) + height) * lat.sin(),
    ]
}

/// The root transform (4×4, column-major as `tileset.json` has it): the up turn, then with an
/// origin the east-north-up frame there. `None` when it is the identity.
pub fn root_transform(up: [f64; 3], origin: Option<[f64; 3]>) -> Option<[f64; 16]> {
    let r = rotation_to_z(up);
    // columns of the 3×3 part and the translation
    let (mut cols, mut t) = ([0, 1, 2].map(|j| [r[0][j], r[1][j], r[2][j]]), [0.0; 3]);
    if let Some([lon, lat, h]) = origin {
        let (l, p) = (lon.to_radians(), lat.to_radians());
        let east = [-l.sin(), l.cos(), 0.0];
        let north = [-p.sin() * l.cos(), -p.sin() * l.sin(), p.cos()];
        let upv = [p.cos() * l.cos(), p.cos() * l.sin(), p.sin()];
        let enu = |v: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|a| east[a] * v[0] + north[a] * v[1] + upv[a] * v[2])
        };
        cols = cols.map(enu);
        t = wgs84_to_ecef(lon, lat, h);
    }
    let identity = origin.is_none()
        && (0..3).all(|j| (0..3).all(|i| cols[j][i] == if i == j { 1.0 } else { 0.0 }));
    if identity {
        return None;
    }
    let mut m = [0.0; 16];
    for j in 0..3 {
        m[4 * j..4 * j + 3].copy_from_slice(&cols[j]);
    }
    m[12..15].copy_from_slice(&t);
    m[15] = 1.0;
    Some(m)
}

/// The file point placed at the origin: the bottom centre of box `(lo, hi)` along `up`.
pub fn bottom_centre(lo: [f64; 3], hi: [f64; 3], up: [f64; 3]) -> [f64; 3] {
    let len = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
    let u = up.map(|c| c / len);
    let h: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) / 2.0);
    let support: f64 = (0..3).map(|a| u[a].abs() * h[a]).sum();
    std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0 - u[a] * support)
}

/// The content of octant path `part`: `make(part)` sizes it and writes it when it is kept
/// whole (at most [`MAX_TILE_BYTES`], or with a child node below it, which a finer split
/// would not match, or a single voxel); otherwise it is split into its octants.
fn split_part(
    make: &mut dyn FnMut(&[u8]) -> Result<(u64, u64), RenderError>,
    part: &[u8],
    has_child: bool,
) -> Result<Content, RenderError> {
    let (quads, bytes) = make(part)?;
    if quads == 0 {
        return Ok(Content::None);
    }
    if bytes <= MAX_TILE_BYTES || has_child || part.len() == 8 {
        return Ok(Content::Whole);
    }
    let mut sub: [Content; 8] = Default::default();
    for o in 0..8u8 {
        let mut p = part.to_vec();
        p.push(o);
        sub[o as usize] = split_part(make, &p, false)?;
    }
    Ok(Content::Split(Box::new(sub)))
}

/// Tiles in the tree under `t`, itself included.
fn count_tiles(t: &Value) -> u64 {
    1 + t
        .get("children")
        .and_then(Value::as_array)
        .map_or(0, |c| c.iter().map(count_tiles).sum())
}

struct Tree<'a> {
    reader: &'a Reader,
    min_level: u32,
    frame: TileFrame,
    content: &'a [Content],
}

impl Tree<'_> {
    /// The file box of octant path `part` of node `index`: the node's voxel box cut to it.
    fn cell_box(&self, index: usize, part: &[u8]) -> ([f64; 3], [f64; 3]) {
        let r = self.reader;
        let e = r.nodes()[index];
        let (mut lo, mut hi) = node_box(r, index);
        let mut cell = [0u32; 3];
        let mut size = 256u32;
        for &o in part {
            size /= 2;
            for a in 0..3 {
                cell[a] += size * (o as u32 >> a & 1);
            }
        }
        let spec = r.spec();
        let clo = spec.voxel_min_corner(e.level, e.pos(), [0; 3]);
        let edge = spec.voxel_size_at(e.level);
        for a in 0..3 {
            lo[a] = lo[a].max(clo[a] + edge * cell[a] as f64);
            hi[a] = hi[a].min(clo[a] + edge * (cell[a] + size) as f64);
        }
        (lo, hi)
    }

    /// The tile of a part without a child node (error 0): its content, or where it is split
    /// a tile without content whose error is `wrapper_error` (so that it is always refined when
    /// reached) over its octants' parts.
    fn part_tile(&self, index: usize, part: &[u8], c: &Content, wrapper_error: f64) -> Value {
        let (lo, hi) = self.cell_box(index, part);
        match c {
            Content::Split(sub) => {
                let mut t = self.tile_json(lo, hi, wrapper_error);
                let mut kids = Vec::new();
                for o in 0..8u8 {
                    if sub[o as usize] != Content::None {
                        let mut p = part.to_vec();
                        p.push(o);
                        kids.push(self.part_tile(index, &p, &sub[o as usize], wrapper_error));
                    }
                }
                t["children"] = Value::Array(kids);
                t
            }
            _ => {
                let mut t = self.tile_json(lo, hi, 0.0);
                t["content"] = json!({"uri": tile_part_uri(self.reader, index, part)});
                t
            }
        }
    }

    /// A tile of file box `(lo, hi)`.
    fn tile_json(&self, lo: [f64; 3], hi: [f64; 3], error: f64) -> Value {
        let (flo, fhi) = (self.frame.map(lo), self.frame.map(hi));
        let c: [f64; 3] = std::array::from_fn(|a| (flo[a] + fhi[a]) / 2.0);
        let h: [f64; 3] = std::array::from_fn(|a| (fhi[a] - flo[a]) / 2.0);
        json!({
            "boundingVolume": {"box": [c[0], c[1], c[2], h[0], 0.0, 0.0, 0.0, h[1], 0.0, 0.0, 0.0, h[2]]},
            "geometricError": error,
        })
    }

    /// The tile of node `index` and its subtree down to `min_level`, with its file box;
    /// `parent_error` is the geometric error of the tile above it. A node split into octants
    /// is a tile without content whose error is its parent's (so it is always refined when
    /// reached), with one child per octant: that octant's content, the node's error, and the
    /// child node of that octant below it.
    fn tile(&self, index: usize, parent_error: f64) -> (Value, ([f64; 3], [f64; 3])) {
        let r = self.reader;
        let e = r.nodes()[index];
        let (nlo, nhi) = node_box(r, index);
        let kids: [Option<usize>; 8] = if e.level > self.min_level {
            r.children(index)
        } else {
            [None; 8]
        };
        let error = if kids.iter().any(Option::is_some) {
            GEOMETRIC_ERROR_PER_EDGE * r.spec().voxel_size_at(e.level) * self.frame.scale
        } else {
            0.0
        };
        let (mut lo, mut hi) = (nlo, nhi);
        let mut grow = |(clo, chi): ([f64; 3], [f64; 3])| {
            for a in 0..3 {
                lo[a] = lo[a].min(clo[a]);
                hi[a] = hi[a].max(chi[a]);
            }
        };
        let mut children = Vec::new();
        if let Content::Split(parts) = &self.content[index] {
            // the octant's box: the node's voxel box cut to that octant, grown by its child's
            for o in 0..8u8 {
                let child = kids[o as usize].map(|c| self.tile(c, error));
                let part = &parts[o as usize];
                if *part == Content::None && child.is_none() {
                    continue;
                }
                let (mut olo, mut ohi) = self.cell_box(index, &[o]);
                if *part == Content::None {
                    // no faces here: the child's box alone
                    (olo, ohi) = child.as_ref().expect("a child").1;
                }
                let mut t = match part {
                    Content::Split(_) => self.part_tile(index, &[o], part, parent_error),
                    _ => self.tile_json(olo, ohi, if child.is_some() { error } else { 0.0 }),
                };
                if *part == Content::Whole {
                    t["content"] = json!({"uri": tile_part_uri(r, index, &[o])});
                }
                if let Some((ct, cb)) = child {
                    for a in 0..3 {
                        olo[a] = olo[a].min(cb.0[a]);
                        ohi[a] = ohi[a].max(cb.1[a]);
                    }
                    let b = self.tile_json(olo, ohi, 0.0)["boundingVolume"].clone();
                    t["boundingVolume"] = b;
                    t["children"] = json!([ct]);
                }
                grow((olo, ohi));
                children.push(t);
            }
            let mut t = self.tile_json(lo, hi, parent_error);
            t["children"] = Value::Array(children);
            return (t, (lo, hi));
        }
        for c in kids.into_iter().flatten() {
            let (t, b) = self.tile(c, error);
            grow(b);
            children.push(t);
        }
        let mut t = self.tile_json(lo, hi, error);
        if self.content[index] == Content::Whole {
            t["content"] = json!({"uri": tile_uri(r, index)});
        }
        if !children.is_empty() {
            t["children"] = Value::Array(children);
        }
        (t, (lo, hi))
    }
}

/// Writes the tileset of the nodes at `opts.min_level` and coarser into the existing empty
/// folder `dir`: the tiles as they are made (at most `opts.max_bytes`), then `before_write`
/// is called with the summary (exact sizes), then `tileset.json` is written. An error from
/// `before_write`, or a size over `max_bytes`, is returned and `tileset.json` is not written
/// (the caller removes the folder).
pub fn export_tileset_with(
    reader: &Reader,
    opts: &TilesetOptions,
    dir: &Path,
    before_write: &mut dyn FnMut(&TilesetSummary) -> Result<(), RenderError>,
) -> Result<TilesetSummary, RenderError> {
    let levels = reader.spec().levels;
    let min_level = opts.min_level;
    if min_level >= levels {
        return Err(RenderError::Option(format!(
            "level {min_level} is not in the file (it has levels 0..={})",
            levels - 1
        )));
    }
    if !(opts.scale.is_finite() && opts.scale > 0.0) {
        return Err(RenderError::Option(format!(
            "scale {}: give a positive number of metres per unit",
            opts.scale
        )));
    }
    let root = reader
        .root()
        .ok_or_else(|| RenderError::Option("the file has no root node".into()))?;
    let (rlo, rhi) = node_box(reader, root);
    let frame = TileFrame {
        anchor: if opts.origin.is_some() {
            bottom_centre(rlo, rhi, opts.up)
        } else {
            [0.0; 3]
        },
        scale: opts.scale,
    };
    let names = material_names(reader);
    let mut content: Vec<Content> = vec![Content::None; reader.nodes().len()];
    let mut s = TilesetSummary::default();
    let mut over = false;
    let mut write = |uri: String, c: &crate::TileContent, s: &mut TilesetSummary| {
        s.contents += 1;
        s.voxels += c.voxels;
        s.quads += c.quads;
        s.raw_bytes += c.raw_bytes;
        let len = c.glb.len() as u64;
        s.largest_tile = s.largest_tile.max(len);
        s.bytes += len;
        over |= s.bytes > opts.max_bytes;
        if over {
            return Ok(());
        }
        let p = dir.join(uri);
        let d = p.parent().expect("a level folder");
        if !d.is_dir() {
            std::fs::create_dir(d).map_err(RenderError::io("creating", d))?;
        }
        std::fs::write(&p, &c.glb).map_err(RenderError::io("writing", &p))
    };
    for i in 0..reader.nodes().len() {
        if reader.nodes()[i].level < min_level {
            continue;
        }
        let c = tile_content(reader, i, &[], &frame, &names)?;
        if c.quads == 0 {
            s.voxels += c.voxels;
            continue;
        }
        if (c.glb.len() as u64) <= MAX_TILE_BYTES {
            content[i] = Content::Whole;
            write(tile_uri(reader, i), &c, &mut s)?;
            continue;
        }
        drop(c);
        let has_children =
            reader.nodes()[i].level > min_level && reader.children(i).iter().any(Option::is_some);
        let mut parts: [Content; 8] = Default::default();
        for o in 0..8u8 {
            let child = has_children && reader.children(i)[o as usize].is_some();
            parts[o as usize] = split_part(
                &mut |p: &[u8]| {
                    let c = tile_content(reader, i, p, &frame, &names)?;
                    if c.quads > 0
                        && (c.glb.len() as u64 <= MAX_TILE_BYTES || child || p.len() == 8)
                    {
                        write(tile_part_uri(reader, i, p), &c, &mut s)?;
                    }
                    Ok((c.quads, c.glb.len() as u64))
                },
                &[o],
                child,
            )?;
        }
        content[i] = Content::Split(Box::new(parts));
    }
    let tree = Tree {
        reader,
        min_level,
        frame,
        content: &content,
    };
    // the tileset's error: 16 times the model's extent, so that the root is refined (and a
    // split root's octants drawn) until the whole model is under a pixel
    let r = reader.nodes()[root];
    let extent = reader.spec().voxel_size_at(r.level) * 256.0 * opts.scale;
    let tileset_error = DEFAULT_MAX_SSE * extent;
    let (mut root_tile, _) = tree.tile(root, tileset_error);
    s.tiles = count_tiles(&root_tile);
    root_tile["refine"] = json!("REPLACE");
    if let Some(m) = root_transform(opts.up, opts.origin) {
        root_tile["transform"] = json!(m.to_vec());
    }
    let tileset = json!({
        "asset": {
            "version": "1.1",
            "generator": format!("voxlod {}", env!("CARGO_PKG_VERSION")),
            "extras": {"voxlod": {
                "up": opts.up,
                "metresPerUnit": opts.scale,
                "origin": opts.origin,
                "geometricErrorPerVoxelEdge": GEOMETRIC_ERROR_PER_EDGE,
                "maximumScreenSpaceError": DEFAULT_MAX_SSE,
                "note": "at a maximum screen-space error of 16 px (CesiumJS and 3d-tiles-renderer's default) voxels are drawn at most 2 px before finer tiles replace them; the model's up is the tileset's +z",
            }},
        },
        "geometricError": tileset_error,
        "root": root_tile,
    });
    s.tileset_json = serde_json::to_string(&tileset)
        .map_err(|e| RenderError::Option(format!("serializing tileset.json: {e}")))?;
    s.bytes += s.tileset_json.len() as u64;
    over |= s.bytes > opts.max_bytes;
    before_write(&s)?;
    if over {
        return Err(RenderError::Option(format!(
            "the tileset would be {} bytes, more than the {} allowed",
            s.bytes, opts.max_bytes
        )));
    }
    let p = dir.join("tileset.json");
    std::fs::write(&p, &s.tileset_json).map_err(RenderError::io("writing", &p))?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apply(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|j| r[i][j] * v[j]).sum())
    }

    #[test]
    fn the_up_turn_takes_up_to_z_and_is_a_rotation() {
        let s = 0.5f64.sqrt();
        for up in [
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, -2.0, 0.0],
            [s, s, 0.0],
            [0.3, -0.4, 0.5],
        ] {
            let r = rotation_to_z(up);
            let len = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
            let z = apply(&r, up.map(|c| c / len));
            assert!(
                (z[0].abs() + z[1].abs() + (z[2] - 1.0).abs()) < 1e-12,
                "{up:?}: {z:?}"
            );
            // orthonormal with determinant +1
            for i in 0..3 {
                for j in 0..3 {
                    let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                    assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
                }
            }
            let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
                - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
            assert!((det - 1.0).abs() < 1e-12);
        }
        // y up: x stays east, +y up, +z towards the viewer goes south (−y)
        let r = rotation_to_z([0.0, 1.0, 0.0]);
        assert_eq!(apply(&r, [1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
        assert_eq!(apply(&r, [0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]);
        assert_eq!(root_transform([0.0, 0.0, 1.0], None), None);
    }

    #[test]
    fn ecef_and_east_north_up_agree_with_known_points() {
        // the equator at the prime meridian, the north pole (semi-minor axis b = 6356752.3142)
        let p = wgs84_to_ecef(0.0, 0.0, 0.0);
        assert!((p[0] - 6_378_137.0).abs() < 1e-6 && p[1].abs() < 1e-6 && p[2].abs() < 1e-6);
        let p = wgs84_to_ecef(0.0, 90.0, 10.0);
        assert!((p[2] - 6_356_762.314_2).abs() < 1e-3, "{p:?}");
        // 45° N 90° E: on the y-z plane; its up is the ellipsoid normal (0, cos45, sin45)
        let m = root_transform([0.0, 0.0, 1.0], Some([90.0, 45.0, 0.0])).unwrap();
        let up = [m[8], m[9], m[10]];
        let s = 0.5f64.sqrt();
        assert!(up[0].abs() < 1e-12 && (up[1] - s).abs() < 1e-12 && (up[2] - s).abs() < 1e-12);
        let east = [m[0], m[1], m[2]];
        assert!((east[0] + 1.0).abs() < 1e-12 && east[1].abs() < 1e-12);
        let t = [m[12], m[13], m[14]];
        assert!(t[0].abs() < 1e-6 && t == wgs84_to_ecef(90.0, 45.0, 0.0));
        // the file's y up becomes the local up
        let m = root_transform([0.0, 1.0, 0.0], Some([90.0, 45.0, 0.0])).unwrap();
        assert!(((m[4] - 0.0).abs() + (m[5] - s).abs() + (m[6] - s).abs()) < 1e-12);
    }

    #[test]
    fn bottom_centre_is_the_low_face_along_up() {
        let (lo, hi) = ([0.0, 10.0, 20.0], [2.0, 14.0, 26.0]);
        assert_eq!(bottom_centre(lo, hi, [0.0, 1.0, 0.0]), [1.0, 10.0, 23.0]);
        assert_eq!(bottom_centre(lo, hi, [0.0, 0.0, -1.0]), [1.0, 12.0, 26.0]);
    }
}
