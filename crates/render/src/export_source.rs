//! Export of the source triangles stored beside the leaves (docs/FORMAT.md 14.4) as a binary
//! PLY, of one leaf or of every leaf: positions in world coordinates, and per vertex the
//! decoded normal and RGBA colour, per face the material id, where the file has them. Each
//! leaf's vertices are written as stored (shared within the leaf; a triangle stored whole in
//! two leaves appears twice, as in the file).
//!
//! Two passes over the leaves (count, then write), so memory holds one leaf at a time: the PLY
//! header needs the counts first.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use voxlod_format::triangles::{oct_decode, SourceMesh, ATTR_COLORS, ATTR_MATERIALS, ATTR_NORMALS};
use voxlod_format::{Reader, CHUNK};

use crate::RenderError;

/// What [`export_source_ply`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SourceExportSummary {
    /// Leaves whose triangles were written.
    pub leaves: u64,
    /// Triangles written.
    pub triangles: u64,
    /// Vertices written.
    pub vertices: u64,
    /// File size in bytes.
    pub bytes: u64,
}

/// World position of a stored vertex of leaf `(x, y, z)`: `origin + voxel_size · (256·chunk +
/// q/128 − 128)` (FORMAT.md 14.4), in f64.
pub fn source_world_position(
    reader: &Reader,
    chunk: [u32; 3],
    mesh: &SourceMesh,
    i: u32,
) -> [f64; 3] {
    let spec = reader.spec();
    let p = mesh.position(i);
    std::array::from_fn(|a| {
        spec.origin[a] + spec.voxel_size * (chunk[a] as f64 * CHUNK as f64 + p[a])
    })
}

/// Writes the source triangles of `nodes` (node indices; every leaf with source triangles if
/// `None`) to a binary little-endian PLY at `path`, calling `before_write` with the counts and
/// exact size before anything is written.
pub fn export_source_ply(
    reader: &Reader,
    nodes: Option<&[usize]>,
    path: &Path,
    before_write: &mut dyn FnMut(&SourceExportSummary) -> Result<(), RenderError>,
) -> Result<SourceExportSummary, RenderError> {
    if !reader.has_source_triangles() {
        return Err(RenderError::Option(format!(
            "{} has no source triangles (build it with --source-geometry)",
            reader.path().display()
        )));
    }
    let all: Vec<usize>;
    let nodes = match nodes {
        Some(n) => n,
        None => {
            all = (0..reader.nodes().len())
                .filter(|&i| reader.nodes()[i].level == 0)
                .collect();
            &all
        }
    };
    // pass 1: counts and the attributes every leaf has
    let (mut leaves, mut vertices, mut triangles, mut attrs) = (0u64, 0u64, 0u64, None);
    for &i in nodes {
        let Some(m) = reader.source_triangles(i)? else {
            continue;
        };
        leaves += 1;
        vertices += m.positions.len() as u64;
        triangles += m.triangles.len() as u64;
        attrs = Some(attrs.map_or(m.attributes(), |a: u32| a & m.attributes()));
    }
    if vertices > i32::MAX as u64 {
        return Err(RenderError::Option(format!(
            "{vertices} vertices, more than a PLY with int indices can hold; export one node (--node)"
        )));
    }
    let attrs = attrs.unwrap_or(0);
    let header = ply_header(reader, vertices, triangles, attrs);
    let vertex_bytes =
        12 + (attrs & ATTR_NORMALS != 0) as u64 * 12 + (attrs & ATTR_COLORS != 0) as u64 * 4;
    let face_bytes = 13 + (attrs & ATTR_MATERIALS != 0) as u64 * 2;
    let summary = SourceExportSummary {
        leaves,
        triangles,
        vertices,
        bytes: header.len() as u64 + vertices * vertex_bytes + triangles * face_bytes,
    };
    before_write(&summary)?;
    let io = |op| RenderError::io(op, path);
    let mut w = BufWriter::with_capacity(1 << 20, File::create(path).map_err(io("creating"))?);
    w.write_all(header.as_bytes()).map_err(io("writing"))?;
    // pass 2: vertices of every leaf, then the faces with their offsets
    let mut faces = Vec::new();
    let mut base = 0u32;
    for &i in nodes {
        let Some(m) = reader.source_triangles(i)? else {
            continue;
        };
        let chunk = reader.nodes()[i].pos();
        write_vertices(&mut w, reader, chunk, &m, attrs).map_err(io("writing"))?;
        for (k, t) in m.triangles.iter().enumerate() {
            faces.push(3u8);
            for &v in t {
                faces.extend_from_slice(&(base + v).to_le_bytes());
            }
            if attrs & ATTR_MATERIALS != 0 {
                let mat = m.materials.as_ref().map_or(0, |ms| ms[k]);
                faces.extend_from_slice(&mat.to_le_bytes());
            }
        }
        base += m.positions.len() as u32;
    }
    w.write_all(&faces).map_err(io("writing"))?;
    w.flush().map_err(io("writing"))?;
    Ok(summary)
}

fn ply_header(reader: &Reader, vertices: u64, triangles: u64, attrs: u32) -> String {
    let spec = reader.spec();
    let mut h = voxlod_io::PlyHeader::binary_le();
    h.comment(&format!(
        "voxlod export: source triangles of {}³ grid, voxel edge {}, positions within 1/256 voxel",
        spec.resolution, spec.voxel_size
    ))
    .element("vertex", vertices)
    .properties("float", &["x", "y", "z"]);
    if attrs & ATTR_NORMALS != 0 {
        h.properties("float", &["nx", "ny", "nz"]);
    }
    if attrs & ATTR_COLORS != 0 {
        h.properties("uchar", &["red", "green", "blue", "alpha"]);
    }
    h.element("face", triangles)
        .list("uchar", "int", "vertex_indices");
    if attrs & ATTR_MATERIALS != 0 {
        h.property("ushort", "material");
    }
    h.end()
}

fn write_vertices(
    w: &mut impl Write,
    reader: &Reader,
    chunk: [u32; 3],
    m: &SourceMesh,
    attrs: u32,
) -> std::io::Result<()> {
    let mut rec = Vec::with_capacity(28);
    for i in 0..m.positions.len() {
        rec.clear();
        for c in source_world_position(reader, chunk, m, i as u32) {
            rec.extend_from_slice(&(c as f32).to_le_bytes());
        }
        if let (true, Some(n)) = (attrs & ATTR_NORMALS != 0, &m.normals) {
            for c in oct_decode(n[i]) {
                rec.extend_from_slice(&c.to_le_bytes());
            }
        }
        if let (true, Some(c)) = (attrs & ATTR_COLORS != 0, &m.colors) {
            rec.extend_from_slice(&c[i]);
        }
        w.write_all(&rec)?;
    }
    Ok(())
}
