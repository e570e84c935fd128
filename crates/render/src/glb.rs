//! Export of voxel quads as glTF 2.0 binary (GLB, Khronos glTF 2.0 specification, section 4.4
//! "GLB file format"), for Blender, three.js, engines and 3D Tiles content: the same quads as
//! the PLY export ([`crate::export_ply`]: one per active face of each voxel's face mask, the
//! voxel's normal and RGBA colour on its four vertices), one glTF mesh per octree node and one
//! primitive per material (FORMAT.md 14.3; the names from the manifest's `"materials"`).
//!
//! The cubes sit on the node's grid, so vertex data is compact with `KHR_mesh_quantization`:
//! a vertex is 24 bytes, interleaved: position as unsigned shorts in voxel units inside the
//! node (`0 ..= 256`, the glTF node's `translation` is the node's corner and its `scale` the
//! voxel edge), normal as normalized shorts, colour (`COLOR_0`) as normalized unsigned shorts
//! holding the **linear** value of the stored sRGB colour ([`crate::color`]: glTF vertex
//! colours are linear; 16 bits so that every sRGB byte comes back exactly).
//! Quads are two triangles over four vertices (`u16` indices where a primitive has at most
//! 65536 vertices, `u32` above).
//!
//! The JSON document is built with `gltf-json`; the GLB container (a 12-byte header and two
//! chunk headers) is written here so that the binary chunk streams: a level is two passes over
//! its nodes (sizes, then bytes), memory bounded by one node.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use gltf_json as json;
use json::validation::{Checked, USize64};
use voxlod_format::{Reader, Voxel};

use crate::export::{shading_normal, ExportSummary};
use crate::faces::{level_nodes, unit_face_corners, Face};
use crate::RenderError;

/// Bytes of one vertex: position `u16×3` + pad, normal `i16×3` + pad, linear colour `u16×4`.
pub const GLB_VERTEX_BYTES: u64 = 24;

/// The quads of one node for one material: interleaved vertex records, 4 per quad.
#[derive(Clone, Debug, Default)]
struct Primitive {
    material: u32,
    quads: u64,
    vertices: Vec<u8>,
    min: [u16; 3],
    max: [u16; 3],
}

/// What the document needs of a primitive (its bytes are made again when they are written).
#[derive(Clone, Copy, Debug)]
struct PrimitiveShape {
    material: u32,
    quads: u64,
    min: [u16; 3],
    max: [u16; 3],
}

impl Primitive {
    fn shape(&self) -> PrimitiveShape {
        PrimitiveShape {
            material: self.material,
            quads: self.quads,
            min: self.min,
            max: self.max,
        }
    }
}

impl PrimitiveShape {
    fn vertex_bytes(&self) -> u64 {
        4 * self.quads * GLB_VERTEX_BYTES
    }
    fn wide_indices(&self) -> bool {
        4 * self.quads > 1 << 16
    }
    fn index_bytes(&self) -> u64 {
        let b = 6 * self.quads * if self.wide_indices() { 4 } else { 2 };
        b.next_multiple_of(4)
    }
}

/// How the glTF nodes are placed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpAxis {
    /// The file's coordinates as they are (like the PLY export).
    AsIs,
    /// The file's coordinates are z-up (3D Tiles): each node is rotated −90° about x, which a
    /// 3D Tiles consumer undoes with its y-up to z-up rotation (3D Tiles 1.1, "glTF
    /// transforms").
    ZUp,
}

/// The quads of node `index`, one primitive per material present, in material order.
fn node_primitives(
    reader: &Reader,
    index: usize,
    buf: &mut Vec<Voxel>,
) -> Result<(u64, Vec<Primitive>), RenderError> {
    reader.read_node_into(index, buf)?;
    let materials = if reader.has_materials() {
        reader.read_materials(index)?
    } else {
        None
    };
    let linear = crate::color::srgb_to_linear_u16_table();
    let mut by_material: BTreeMap<u32, Primitive> = BTreeMap::new();
    for (j, v) in buf.iter().enumerate() {
        let mask = v.mask();
        if mask == 0 {
            continue;
        }
        let material = materials.as_ref().map_or(0, |m| m[j]);
        let p = by_material.entry(material).or_insert_with(|| Primitive {
            material,
            min: [u16::MAX; 3],
            ..Primitive::default()
        });
        let pos = v.pos();
        for dir in 0..6u8 {
            if mask >> dir & 1 == 0 {
                continue;
            }
            let face = Face {
                min: [0.0; 3],
                edge: 1.0,
                dir,
                normal: v.normal,
                rgba: v.rgba(),
            };
            let n = shading_normal(&face).map(|c| (c * 32767.0).round() as i16);
            for c in unit_face_corners(dir) {
                let g: [u16; 3] = std::array::from_fn(|a| pos[a] as u16 + c[a] as u16);
                for a in 0..3 {
                    p.min[a] = p.min[a].min(g[a]);
                    p.max[a] = p.max[a].max(g[a]);
                }
                let mut rec = [0u8; GLB_VERTEX_BYTES as usize];
                for a in 0..3 {
                    rec[2 * a..2 * a + 2].copy_from_slice(&g[a].to_le_bytes());
                    rec[8 + 2 * a..10 + 2 * a].copy_from_slice(&n[a].to_le_bytes());
                }
                for (k, &c) in face.rgba.iter().enumerate() {
                    let c = if k < 3 {
                        linear[c as usize]
                    } else {
                        c as u16 * 257
                    };
                    rec[16 + 2 * k..18 + 2 * k].copy_from_slice(&c.to_le_bytes());
                }
                p.vertices.extend_from_slice(&rec);
            }
            p.quads += 1;
        }
    }
    Ok((buf.len() as u64, by_material.into_values().collect()))
}

/// The index bytes of `quads` quads (two counter-clockwise triangles each), padded to 4.
fn write_indices(w: &mut impl Write, s: &PrimitiveShape) -> std::io::Result<()> {
    let mut out = Vec::with_capacity(s.index_bytes() as usize);
    for q in 0..s.quads {
        let b = 4 * q;
        for i in [b, b + 1, b + 2, b, b + 2, b + 3] {
            if s.wide_indices() {
                out.extend_from_slice(&(i as u32).to_le_bytes());
            } else {
                out.extend_from_slice(&(i as u16).to_le_bytes());
            }
        }
    }
    out.resize(s.index_bytes() as usize, 0);
    w.write_all(&out)
}

/// A glTF document being built: buffer views and accessors are laid out in the binary chunk
/// in the order meshes are added.
struct Document {
    root: json::Root,
    bin: u64,
    materials: BTreeMap<u32, json::Index<json::Material>>,
    names: Vec<String>,
}

impl Document {
    fn new(reader: &Reader) -> Document {
        let mut root = json::Root {
            asset: json::Asset {
                generator: Some(format!("voxlod {}", env!("CARGO_PKG_VERSION"))),
                ..json::Asset::default()
            },
            ..json::Root::default()
        };
        root.extensions_used = vec!["KHR_mesh_quantization".into()];
        root.extensions_required = vec!["KHR_mesh_quantization".into()];
        let names = reader
            .manifest()
            .ok()
            .and_then(|m| {
                m.get("materials")?.as_array().map(|a| {
                    a.iter()
                        .map(|n| n.as_str().unwrap_or_default().to_string())
                        .collect()
                })
            })
            .unwrap_or_default();
        Document {
            root,
            bin: 0,
            materials: BTreeMap::new(),
            names,
        }
    }

    /// The glTF material of file material `id`: white base colour (the vertex colour shows),
    /// not metallic, rough; named as in the manifest (`"voxel"` for id 0).
    fn material(&mut self, id: u32) -> json::Index<json::Material> {
        if let Some(&m) = self.materials.get(&id) {
            return m;
        }
        let name = match self.names.get(id as usize) {
            Some(n) if !n.is_empty() => n.clone(),
            _ if id == 0 => "voxel".into(),
            _ => format!("material {id}"),
        };
        let mut m = json::Material {
            name: Some(name),
            ..json::Material::default()
        };
        m.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
        m.pbr_metallic_roughness.roughness_factor = json::material::StrengthFactor(1.0);
        let i = self.root.push(m);
        self.materials.insert(id, i);
        i
    }

    fn view(
        &mut self,
        len: u64,
        stride: Option<usize>,
        target: json::buffer::Target,
    ) -> json::Index<json::buffer::View> {
        let v = json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64(len),
            byte_offset: Some(USize64(self.bin)),
            byte_stride: stride.map(json::buffer::Stride),
            name: None,
            target: Some(Checked::Valid(target)),
            extensions: None,
            extras: Default::default(),
        };
        self.bin += len;
        self.root.push(v)
    }

    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        view: json::Index<json::buffer::View>,
        offset: u64,
        count: u64,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        normalized: bool,
        bounds: Option<([u16; 3], [u16; 3])>,
    ) -> json::Index<json::Accessor> {
        let a = json::Accessor {
            buffer_view: Some(view),
            byte_offset: Some(USize64(offset)),
            count: USize64(count),
            component_type: Checked::Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Checked::Valid(type_),
            min: bounds.map(|(lo, _)| json::Value::from(lo.to_vec())),
            max: bounds.map(|(_, hi)| json::Value::from(hi.to_vec())),
            name: None,
            normalized,
            sparse: None,
        };
        self.root.push(a)
    }

    /// A node placed at `corner` with voxel edge `edge`, with one primitive per shape (none:
    /// no node).
    fn add_node(
        &mut self,
        name: String,
        shapes: &[PrimitiveShape],
        corner: [f64; 3],
        edge: f64,
        up: UpAxis,
    ) -> Option<json::Index<json::Node>> {
        use json::accessor::{ComponentType as C, Type as T};
        use json::buffer::Target;
        use json::mesh::Semantic;
        if shapes.is_empty() {
            return None;
        }
        let mut primitives = Vec::new();
        for s in shapes {
            let v = 4 * s.quads;
            let verts = self.view(
                s.vertex_bytes(),
                Some(GLB_VERTEX_BYTES as usize),
                Target::ArrayBuffer,
            );
            let idx = self.view(s.index_bytes(), None, Target::ElementArrayBuffer);
            let pos = self.accessor(verts, 0, v, C::U16, T::Vec3, false, Some((s.min, s.max)));
            let nrm = self.accessor(verts, 8, v, C::I16, T::Vec3, true, None);
            let col = self.accessor(verts, 16, v, C::U16, T::Vec4, true, None);
            let wide = if s.wide_indices() { C::U32 } else { C::U16 };
            let ind = self.accessor(idx, 0, 6 * s.quads, wide, T::Scalar, false, None);
            let mut attributes = BTreeMap::new();
            attributes.insert(Checked::Valid(Semantic::Positions), pos);
            attributes.insert(Checked::Valid(Semantic::Normals), nrm);
            attributes.insert(Checked::Valid(Semantic::Colors(0)), col);
            primitives.push(json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: Default::default(),
                indices: Some(ind),
                material: Some(self.material(s.material)),
                mode: Checked::Valid(json::mesh::Mode::Triangles),
                targets: None,
            });
        }
        let mesh = self.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(name.clone()),
            primitives,
            weights: None,
        });
        let (translation, rotation) = match up {
            UpAxis::AsIs => (corner, None),
            UpAxis::ZUp => (
                [corner[0], corner[2], -corner[1]],
                Some(json::scene::UnitQuaternion([
                    -std::f32::consts::FRAC_1_SQRT_2,
                    0.0,
                    0.0,
                    std::f32::consts::FRAC_1_SQRT_2,
                ])),
            ),
        };
        Some(self.root.push(json::Node {
            mesh: Some(mesh),
            name: Some(name),
            translation: Some(translation.map(|c| c as f32)),
            rotation,
            scale: Some([edge as f32; 3]),
            ..json::Node::default()
        }))
    }

    /// The JSON chunk: the document with its one buffer and one scene over `nodes`, padded
    /// with spaces to 4 bytes.
    fn finish(mut self, nodes: Vec<json::Index<json::Node>>) -> Result<Vec<u8>, RenderError> {
        if self.bin > 0 {
            self.root.push(json::Buffer {
                byte_length: USize64(self.bin),
                name: None,
                uri: None,
                extensions: None,
                extras: Default::default(),
            });
        }
        let scene = self.root.push(json::Scene {
            extensions: None,
            extras: Default::default(),
            name: None,
            nodes,
        });
        self.root.scene = Some(scene);
        let mut j = json::serialize::to_vec(&self.root)
            .map_err(|e| RenderError::Option(format!("serializing the glTF document: {e}")))?;
        while j.len() % 4 != 0 {
            j.push(b' ');
        }
        Ok(j)
    }
}

/// The GLB header and the JSON chunk, for a binary chunk of `bin` bytes (a multiple of 4).
fn glb_head(json_chunk: &[u8], bin: u64) -> Result<Vec<u8>, RenderError> {
    debug_assert!(json_chunk.len() % 4 == 0 && bin % 4 == 0);
    let total = 12 + 8 + json_chunk.len() as u64 + if bin > 0 { 8 + bin } else { 0 };
    let total = u32::try_from(total).map_err(|_| {
        RenderError::Option(format!(
            "the glTF binary would be {total} bytes, more than the 4 GiB a GLB can hold; export a coarser level"
        ))
    })?;
    let mut h = Vec::with_capacity(28 + json_chunk.len());
    h.extend_from_slice(b"glTF");
    h.extend_from_slice(&2u32.to_le_bytes());
    h.extend_from_slice(&total.to_le_bytes());
    h.extend_from_slice(&(json_chunk.len() as u32).to_le_bytes());
    h.extend_from_slice(b"JSON");
    h.extend_from_slice(json_chunk);
    if bin > 0 {
        h.extend_from_slice(&(bin as u32).to_le_bytes());
        h.extend_from_slice(b"BIN\0");
    }
    Ok(h)
}

fn node_corner(reader: &Reader, index: usize) -> ([f64; 3], f64) {
    let e = reader.nodes()[index];
    let spec = reader.spec();
    (
        spec.voxel_min_corner(e.level, e.pos(), [0; 3]),
        spec.voxel_size_at(e.level),
    )
}

fn node_name(reader: &Reader, index: usize) -> String {
    let e = reader.nodes()[index];
    format!("node {} {} {} {}", e.level, e.x, e.y, e.z)
}

/// Node `index` alone as a GLB (a 3D Tiles tile's content), built but not yet written: the
/// header and JSON chunk, and the binary chunk's parts, so that it streams to a file without a
/// second copy.
pub struct NodeGlb {
    head: Vec<u8>,
    prims: Vec<Primitive>,
    shapes: Vec<PrimitiveShape>,
    /// Its counts; `bytes` is the GLB's size.
    pub summary: ExportSummary,
}

impl NodeGlb {
    /// Builds node `index`'s GLB.
    pub fn new(reader: &Reader, index: usize, up: UpAxis) -> Result<NodeGlb, RenderError> {
        let mut buf = Vec::new();
        let (voxels, prims) = node_primitives(reader, index, &mut buf)?;
        let shapes: Vec<PrimitiveShape> = prims.iter().map(Primitive::shape).collect();
        let mut doc = Document::new(reader);
        let (corner, edge) = node_corner(reader, index);
        let node = doc.add_node(node_name(reader, index), &shapes, corner, edge, up);
        let bin = doc.bin;
        let head = glb_head(&doc.finish(node.into_iter().collect())?, bin)?;
        let quads = shapes.iter().map(|s| s.quads).sum::<u64>();
        let summary = ExportSummary {
            voxels,
            quads,
            vertices: 4 * quads,
            bytes: head.len() as u64 + bin,
        };
        Ok(NodeGlb {
            head,
            prims,
            shapes,
            summary,
        })
    }

    /// Writes the GLB to `w`.
    pub fn write_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        w.write_all(&self.head)?;
        for (p, s) in self.prims.iter().zip(&self.shapes) {
            w.write_all(&p.vertices)?;
            write_indices(w, s)?;
        }
        Ok(())
    }
}

/// Node `index` alone as a GLB in memory, with its counts.
pub fn node_glb(
    reader: &Reader,
    index: usize,
    up: UpAxis,
) -> Result<(Vec<u8>, ExportSummary), RenderError> {
    let g = NodeGlb::new(reader, index, up)?;
    let mut out = Vec::with_capacity(g.summary.bytes as usize);
    g.write_to(&mut out).expect("writing to memory");
    debug_assert_eq!(out.len() as u64, g.summary.bytes);
    Ok((out, g.summary))
}

/// Writes the voxels of `level` as a GLB at `path` (one glTF node per octree node under one
/// root node), calling `before_write` with the counts and the exact file size before anything
/// is written; an error from it is returned and nothing is written.
pub fn export_glb_with(
    reader: &Reader,
    level: u32,
    path: &Path,
    before_write: &mut dyn FnMut(&ExportSummary) -> Result<(), RenderError>,
) -> Result<ExportSummary, RenderError> {
    let nodes = level_nodes(reader, level)?;
    let mut buf = Vec::new();
    // pass 1: the primitives' shapes, which lay out the document and the binary chunk
    let mut doc = Document::new(reader);
    let mut children = Vec::new();
    let mut shapes_of = Vec::with_capacity(nodes.len());
    let (mut voxels, mut quads) = (0u64, 0u64);
    for &i in &nodes {
        let (n, prims) = node_primitives(reader, i, &mut buf)?;
        let shapes: Vec<PrimitiveShape> = prims.iter().map(Primitive::shape).collect();
        voxels += n;
        quads += shapes.iter().map(|s| s.quads).sum::<u64>();
        let (corner, edge) = node_corner(reader, i);
        children.extend(doc.add_node(node_name(reader, i), &shapes, corner, edge, UpAxis::AsIs));
        shapes_of.push(shapes);
    }
    let top = doc.root.push(json::Node {
        name: Some(format!("voxlod level {level}")),
        children: Some(children),
        ..json::Node::default()
    });
    let bin = doc.bin;
    let json_chunk = doc.finish(vec![top])?;
    // the size is told before the header is made: a GLB past 4 GiB is refused by the caller's
    // size guard, which names the level that fits
    let summary = ExportSummary {
        voxels,
        quads,
        vertices: 4 * quads,
        bytes: 12 + 8 + json_chunk.len() as u64 + if bin > 0 { 8 + bin } else { 0 },
    };
    before_write(&summary)?;
    let head = glb_head(&json_chunk, bin)?;
    debug_assert_eq!(head.len() as u64 + bin, summary.bytes);

    // pass 2: the bytes, node by node in the same order
    let io = |op| RenderError::io(op, path);
    let file = File::create(path).map_err(io("creating"))?;
    let mut w = BufWriter::with_capacity(1 << 20, file);
    w.write_all(&head).map_err(io("writing"))?;
    let mut written = 0u64;
    for (&i, shapes) in nodes.iter().zip(&shapes_of) {
        let (_, prims) = node_primitives(reader, i, &mut buf)?;
        let again: Vec<PrimitiveShape> = prims.iter().map(Primitive::shape).collect();
        if again.len() != shapes.len()
            || again
                .iter()
                .zip(shapes)
                .any(|(a, b)| a.quads != b.quads || a.material != b.material)
        {
            return Err(RenderError::Option(
                "the file changed between the two passes of the export".into(),
            ));
        }
        for (p, s) in prims.iter().zip(shapes) {
            w.write_all(&p.vertices).map_err(io("writing"))?;
            write_indices(&mut w, s).map_err(io("writing"))?;
            written += s.vertex_bytes() + s.index_bytes();
        }
    }
    debug_assert_eq!(written, bin);
    w.flush().map_err(io("writing"))?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_format::voxel::{pack_color, pack_normal, Voxel};
    use voxlod_format::{encode_node, FileSpec, Writer, MODE_THIN};

    /// A one-node file: voxel (4, 5, 6) with faces +z and −x, origin (10, 20, 30), edge 0.5.
    fn one_voxel(dir: &Path) -> Reader {
        let path = dir.join("one.voxlod");
        let n = pack_normal([0.0, 0.0, 1.0]);
        let v = Voxel::new([4, 5, 6], 0b01_0010, n, pack_color([200, 100, 50, 255]));
        let mut w = Writer::create(
            &path,
            FileSpec::new(256, MODE_THIN, [10.0, 20.0, 30.0], 0.5),
        )
        .unwrap();
        w.write_node(0, [0, 0, 0], 0, &encode_node(&[v], 3).unwrap())
            .unwrap();
        w.finish(&serde_json::json!({})).unwrap();
        Reader::open(&path).unwrap()
    }

    /// The GLB's JSON and binary chunk, checking the container's lengths.
    fn chunks(glb: &[u8]) -> (serde_json::Value, &[u8]) {
        let u = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
        assert_eq!(&glb[0..4], b"glTF");
        assert_eq!(u(4), 2);
        assert_eq!(u(8), glb.len());
        let jl = u(12);
        assert_eq!(&glb[16..20], b"JSON");
        assert_eq!(jl % 4, 0);
        let bl = u(20 + jl);
        assert_eq!(&glb[24 + jl..28 + jl], b"BIN\0");
        assert_eq!(28 + jl + bl, glb.len());
        (
            serde_json::from_slice(&glb[20..20 + jl]).unwrap(),
            &glb[28 + jl..],
        )
    }

    /// World corners of the quads in the GLB (node transform applied; for `ZUp` also the
    /// consumer's y-up to z-up turn, (x, y, z) → (x, −z, y)), in index order.
    fn corners(glb: &[u8], up: UpAxis) -> Vec<[f64; 3]> {
        let (j, bin) = chunks(glb);
        let node = &j["nodes"][0];
        let f = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (t, s) = (f(&node["translation"]), f(&node["scale"]));
        let q = node.get("rotation").map_or(vec![0.0, 0.0, 0.0, 1.0], f);
        let prim = &j["meshes"][0]["primitives"][0];
        let acc = &j["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize];
        let view = &j["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let (off, stride) = (
            view["byteOffset"].as_u64().unwrap() as usize,
            view["byteStride"].as_u64().unwrap() as usize,
        );
        let ia = &j["accessors"][prim["indices"].as_u64().unwrap() as usize];
        assert_eq!(
            ia["componentType"], 5123,
            "u16 indices for a small primitive"
        );
        let iv = &j["bufferViews"][ia["bufferView"].as_u64().unwrap() as usize];
        let ioff = iv["byteOffset"].as_u64().unwrap() as usize;
        (0..ia["count"].as_u64().unwrap() as usize)
            .map(|k| {
                let i = u16::from_le_bytes([bin[ioff + 2 * k], bin[ioff + 2 * k + 1]]) as usize;
                let g: [f64; 3] = std::array::from_fn(|a| {
                    let at = off + i * stride + 2 * a;
                    u16::from_le_bytes([bin[at], bin[at + 1]]) as f64 * s[a]
                });
                // rotate g by the unit quaternion q = (x, y, z, w): g + 2w(v×g) + 2v×(v×g)
                let v = [q[0], q[1], q[2]];
                let cross = |a: [f64; 3], b: [f64; 3]| {
                    [
                        a[1] * b[2] - a[2] * b[1],
                        a[2] * b[0] - a[0] * b[2],
                        a[0] * b[1] - a[1] * b[0],
                    ]
                };
                let c1 = cross(v, g);
                let c2 = cross(v, c1);
                let p: [f64; 3] =
                    std::array::from_fn(|a| g[a] + 2.0 * q[3] * c1[a] + 2.0 * c2[a] + t[a]);
                match up {
                    UpAxis::AsIs => p,
                    UpAxis::ZUp => [p[0], -p[2], p[1]],
                }
            })
            .collect()
    }

    #[test]
    fn one_voxel_two_faces_in_world_coordinates_either_way_up() {
        let dir = tempfile::tempdir().unwrap();
        let r = one_voxel(dir.path());
        // the +z face: z = 30 + 0.5·7, x in 12..12.5, y in 22.5..23; the −x face: x = 12
        for up in [UpAxis::AsIs, UpAxis::ZUp] {
            let (glb, s) = node_glb(&r, 0, up).unwrap();
            assert_eq!(
                (s.voxels, s.quads, s.vertices, s.bytes),
                (1, 2, 8, glb.len() as u64)
            );
            let c = corners(&glb, up);
            assert_eq!(c.len(), 12);
            let close = |a: f64, b: f64| (a - b).abs() < 1e-5;
            let within = |x: f64, lo: f64, hi: f64| x > lo - 1e-5 && x < hi + 1e-5;
            let tris: Vec<&[[f64; 3]]> = c.chunks(3).collect();
            for t in &tris {
                // counter-clockwise seen from outside: the right-hand normal is the face's
                let e1: [f64; 3] = std::array::from_fn(|a| t[1][a] - t[0][a]);
                let e2: [f64; 3] = std::array::from_fn(|a| t[2][a] - t[0][a]);
                let n = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                if t.iter().all(|p| close(p[2], 33.5)) {
                    assert!(
                        n[2] > 0.0
                            && t.iter()
                                .all(|p| within(p[0], 12.0, 12.5) && within(p[1], 22.5, 23.0)),
                        "{t:?}"
                    );
                } else {
                    assert!(t.iter().all(|p| close(p[0], 12.0)), "{up:?}: {t:?}");
                    assert!(
                        n[0] < 0.0
                            && t.iter()
                                .all(|p| within(p[1], 22.5, 23.0) && within(p[2], 33.0, 33.5)),
                        "{t:?}"
                    );
                }
            }
            assert_eq!(
                tris.iter()
                    .filter(|t| t.iter().all(|p| close(p[2], 33.5)))
                    .count(),
                2
            );
        }
    }
}
