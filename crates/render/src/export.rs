//! Export of one level as a quad mesh in binary PLY, to look at in MeshLab or Blender: each
//! active face of each voxel (its face mask, FORMAT.md section 6) becomes one quad of four
//! vertices in world coordinates. Vertices are not shared between quads, so every quad carries
//! its voxel's attributes: the **vertex normal is the voxel's normal** (normalized; the face
//! direction where the voxel's normal is zero), which shades like the Chajdas renderer, and the
//! colour is the voxel's RGBA. A file with the material channel (FORMAT.md 14.3) also gives
//! each vertex its voxel's material id (`property uint material`; the names are in the file's
//! manifest, `"materials"`).
//!
//! Two passes over the level's nodes (count, then write), so memory does not grow with the
//! level: the PLY header needs the counts first.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use voxlod_format::voxel::unpack_normal;
use voxlod_format::{Reader, Voxel};

use crate::faces::{face_direction, level_nodes, node_faces, unit_face_corners, Face};
use crate::RenderError;

/// What [`export_ply`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExportSummary {
    /// Voxels of the level.
    pub voxels: u64,
    /// Quads written (active faces).
    pub quads: u64,
    /// Vertices written (4 per quad).
    pub vertices: u64,
    /// File size in bytes.
    pub bytes: u64,
}

/// Bytes per vertex record: 6 floats and 4 colour bytes.
const VERTEX_BYTES: u64 = 6 * 4 + 4;
/// Bytes per face record: a count byte and 4 ints.
const FACE_BYTES: u64 = 1 + 4 * 4;

/// Writes the voxels of `level` as quads to a binary little-endian PLY at `path`.
pub fn export_ply(reader: &Reader, level: u32, path: &Path) -> Result<ExportSummary, RenderError> {
    export_ply_with(reader, level, path, &mut |_| Ok(()))
}

/// [`export_ply`], calling `before_write` with the counts and the exact file size once the
/// faces are counted and before anything is written (to tell the user how big the file will
/// be, or to refuse); an error from it is returned and nothing is written.
pub fn export_ply_with(
    reader: &Reader,
    level: u32,
    path: &Path,
    before_write: &mut dyn FnMut(&ExportSummary) -> Result<(), RenderError>,
) -> Result<ExportSummary, RenderError> {
    // Two passes over the same nodes: count, then write.
    let nodes = level_nodes(reader, level)?;
    let mut buf = Vec::new();
    let mut quads = 0u64;
    let mut voxels = 0u64;
    for &i in &nodes {
        node_faces(reader, i, &mut buf, &mut |_| quads += 1)?;
        voxels += buf.len() as u64;
    }
    let vertices = 4 * quads;
    if vertices > u32::MAX as u64 {
        return Err(RenderError::Option(format!(
            "level {level} has {quads} faces, more than a PLY with int indices can hold; export a coarser level"
        )));
    }
    let spec = reader.spec();
    let materials = reader.has_materials();
    let vertex_bytes = VERTEX_BYTES + if materials { 4 } else { 0 };
    let mut header = voxlod_io::PlyHeader::binary_le();
    header
        .comment(&format!(
            "voxlod export: level {level} of {}³ grid, voxel edge {}, {voxels} voxels",
            spec.resolution,
            spec.voxel_size_at(level)
        ))
        .comment("one quad per active voxel face; vertex normal = voxel normal")
        .element("vertex", vertices)
        .properties("float", &["x", "y", "z", "nx", "ny", "nz"])
        .properties("uchar", &["red", "green", "blue", "alpha"]);
    if materials {
        header.property("uint", "material");
    }
    let header = header
        .element("face", quads)
        .list("uchar", "int", "vertex_indices")
        .end();
    let summary = ExportSummary {
        voxels,
        quads,
        vertices,
        bytes: header.len() as u64 + vertices * vertex_bytes + quads * FACE_BYTES,
    };
    before_write(&summary)?;
    let io = |op| RenderError::io(op, path);
    let file = File::create(path).map_err(io("creating"))?;
    let mut w = BufWriter::with_capacity(1 << 20, file);
    w.write_all(header.as_bytes()).map_err(io("writing"))?;

    // vertices, node by node, in the same order as counted
    let mut err = None;
    let mut written = 0u64;
    let mut face_materials = Vec::new();
    for &i in &nodes {
        if materials {
            face_materials = faces_materials(reader, i, &mut buf)?;
        }
        let mut k = 0;
        node_faces(reader, i, &mut buf, &mut |f: Face| {
            if err.is_some() {
                return;
            }
            let m = face_materials.get(k).copied();
            k += 1;
            if let Err(e) = write_quad_vertices(&mut w, &f, m) {
                err = Some(e);
            }
            written += 1;
        })?;
        if let Some(e) = err.take() {
            return Err(io("writing")(e));
        }
    }
    debug_assert_eq!(written, quads);
    if written != quads {
        return Err(RenderError::Option(format!(
            "the file changed between passes: {quads} faces counted, {written} read"
        )));
    }
    let mut rec = [0u8; FACE_BYTES as usize];
    rec[0] = 4;
    for q in 0..quads as u32 {
        for k in 0..4u32 {
            let at = 1 + 4 * k as usize;
            rec[at..at + 4].copy_from_slice(&(4 * q + k).to_le_bytes());
        }
        w.write_all(&rec).map_err(io("writing"))?;
    }
    w.flush().map_err(io("writing"))?;
    Ok(summary)
}

/// The normal a face is drawn with: the voxel's, or the face direction if that is zero.
pub fn shading_normal(f: &Face) -> [f32; 3] {
    let q = unpack_normal(f.normal);
    let len = ((q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) as f32).sqrt();
    if len == 0.0 {
        face_direction(f.dir)
    } else {
        q.map(|c| c as f32 / len)
    }
}

/// The material of each active face of node `index`, in the order [`node_faces`] gives them.
fn faces_materials(
    reader: &Reader,
    index: usize,
    buf: &mut Vec<Voxel>,
) -> Result<Vec<u32>, RenderError> {
    reader.read_node_into(index, buf)?;
    let m = reader.read_materials(index)?.unwrap_or_default();
    Ok(buf
        .iter()
        .zip(&m)
        .flat_map(|(v, &m)| std::iter::repeat_n(m, v.mask().count_ones() as usize))
        .collect())
}

fn write_quad_vertices(w: &mut impl Write, f: &Face, material: Option<u32>) -> std::io::Result<()> {
    let n = shading_normal(f);
    let mut rec = [0u8; VERTEX_BYTES as usize + 4];
    let len = VERTEX_BYTES as usize + if material.is_some() { 4 } else { 0 };
    for c in unit_face_corners(f.dir) {
        for a in 0..3 {
            let p = (f.min[a] + f.edge * c[a] as f64) as f32;
            rec[4 * a..4 * a + 4].copy_from_slice(&p.to_le_bytes());
            rec[12 + 4 * a..16 + 4 * a].copy_from_slice(&n[a].to_le_bytes());
        }
        rec[24..28].copy_from_slice(&f.rgba);
        if let Some(m) = material {
            rec[28..32].copy_from_slice(&m.to_le_bytes());
        }
        w.write_all(&rec[..len])?;
    }
    Ok(())
}
