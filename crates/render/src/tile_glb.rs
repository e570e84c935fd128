//! One octree node as a compact glTF binary: the content of a 3D Tiles tile.
//!
//! The same visible faces as the PLY and `.glb` exports (each active face of each voxel's face
//! mask), stored for size:
//! - **Shared vertices**: the faces of one voxel share their corners (a voxel's vertices all
//!   carry its normal and colour), so a voxel with two faces has 6 vertices, not 8; a voxel
//!   whose normal is zero is shaded by each face's direction and keeps 4 vertices a face.
//! - **Separate streams** (position `u16`×3 in voxel units inside the node, with
//!   `KHR_mesh_quantization`; normal `i8`×3 normalized; colour RGBA as **linear** normalized
//!   `u16`, [`crate::color`]: 8 bits of linear light would merge the dark sRGB values, which
//!   then show visibly lifted; the material id as `u16` where the file has materials), each a
//!   buffer view compressed with meshoptimizer's vertex codec (version 0), the indices with its
//!   index codec: `EXT_meshopt_compression`, required (no uncompressed copy: its fallback
//!   buffer has no data). CesiumJS, three.js's `GLTFLoader` (with `MeshoptDecoder`) and
//!   `3d-tiles-renderer` decode it.
//! - **Material ids** as `EXT_mesh_features` feature ids (attribute `_FEATURE_ID_0`, label
//!   `material`; the id indexes the manifest's `"materials"`), one primitive per material as
//!   in the `.glb` export, so that a consumer can pick and style by material.
//!
//! The glTF node is placed at the node's corner in the tileset's frame ([`TileFrame`]) and
//! scaled by its voxel edge, turned −90° about x (glTF is y-up; the 3D Tiles consumer turns
//! it back: 3D Tiles 1.1, "glTF transforms").

use std::collections::BTreeMap;

use serde_json::{json, Value};
use voxlod_format::voxel::unpack_normal;
use voxlod_format::{Reader, Voxel};

use crate::color::srgb_to_linear_u16_table;
use crate::faces::unit_face_corners;
use crate::RenderError;

/// Where tile contents sit: content coordinates are `(file − anchor)·scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileFrame {
    /// The file point at the frame's origin.
    pub anchor: [f64; 3],
    /// Frame units per file unit (metres per file unit when the tileset is placed).
    pub scale: f64,
}

impl Default for TileFrame {
    fn default() -> Self {
        TileFrame {
            anchor: [0.0; 3],
            scale: 1.0,
        }
    }
}

impl TileFrame {
    /// File point `p` in the frame.
    pub fn map(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| (p[a] - self.anchor[a]) * self.scale)
    }
}

/// One node's tile content and its counts.
#[derive(Clone, Debug, Default)]
pub struct TileContent {
    /// The GLB (empty when the node has no active face).
    pub glb: Vec<u8>,
    /// Voxels of the node.
    pub voxels: u64,
    /// Quads (active faces).
    pub quads: u64,
    /// Vertices (shared by the faces of a voxel).
    pub vertices: u64,
    /// Bytes the vertex and index data would take uncompressed.
    pub raw_bytes: u64,
}

/// The streams of one material's primitive.
#[derive(Default)]
struct Streams {
    material: u32,
    pos: Vec<[u16; 4]>,
    nrm: Vec<[i8; 4]>,
    col: Vec<[u16; 4]>,
    indices: Vec<u32>,
    min: [u16; 3],
    max: [u16; 3],
}

/// The corner number (`x | y<<1 | z<<2`) of each corner of each face, in winding order.
fn face_corner_keys() -> [[usize; 4]; 6] {
    std::array::from_fn(|d| {
        unit_face_corners(d as u8)
            .map(|c| c[0] as usize | (c[1] as usize) << 1 | (c[2] as usize) << 2)
    })
}

/// The voxel's shading normal quantized to `i8` (none when it is zero).
fn normal_i8(packed: u32) -> Option<[i8; 4]> {
    let q = unpack_normal(packed);
    let len = ((q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) as f64).sqrt();
    (len > 0.0).then(|| {
        let c = q.map(|c| (c as f64 / len * 127.0).round() as i8);
        [c[0], c[1], c[2], 0]
    })
}

fn face_normal_i8(dir: u8) -> [i8; 4] {
    let mut n = [0i8; 4];
    n[(dir >> 1) as usize] = if dir & 1 == 0 { 127 } else { -127 };
    n
}

/// The node's faces, one [`Streams`] per material present, in material order.
fn node_streams(
    reader: &Reader,
    index: usize,
    part: &[u8],
    buf: &mut Vec<Voxel>,
) -> Result<Vec<Streams>, RenderError> {
    reader.read_node_into(index, buf)?;
    let materials = if reader.has_materials() {
        reader.read_materials(index)?
    } else {
        None
    };
    let keys = face_corner_keys();
    let linear = srgb_to_linear_u16_table();
    let mut by_material: BTreeMap<u32, Streams> = BTreeMap::new();
    for (j, v) in buf.iter().enumerate() {
        let mask = v.mask();
        if mask == 0 || !in_part(v, part) {
            continue;
        }
        let material = materials.as_ref().map_or(0, |m| m[j]);
        let s = by_material.entry(material).or_insert_with(|| Streams {
            material,
            min: [u16::MAX; 3],
            ..Streams::default()
        });
        let p = v.pos().map(u16::from);
        let rgba = v.rgba();
        let col = [
            linear[rgba[0] as usize],
            linear[rgba[1] as usize],
            linear[rgba[2] as usize],
            rgba[3] as u16 * 257,
        ];
        let shared = normal_i8(v.normal);
        let mut slot = [u32::MAX; 8];
        for dir in 0..6u8 {
            if mask >> dir & 1 == 0 {
                continue;
            }
            if shared.is_none() {
                slot = [u32::MAX; 8];
            }
            let n = shared.unwrap_or_else(|| face_normal_i8(dir));
            let ids = keys[dir as usize].map(|k| {
                if slot[k] == u32::MAX {
                    slot[k] = s.pos.len() as u32;
                    let g = [
                        p[0] + (k & 1) as u16,
                        p[1] + (k >> 1 & 1) as u16,
                        p[2] + (k >> 2 & 1) as u16,
                    ];
                    for a in 0..3 {
                        s.min[a] = s.min[a].min(g[a]);
                        s.max[a] = s.max[a].max(g[a]);
                    }
                    s.pos.push([g[0], g[1], g[2], 0]);
                    s.nrm.push(n);
                    s.col.push(col);
                }
                slot[k]
            });
            s.indices
                .extend_from_slice(&[ids[0], ids[1], ids[2], ids[0], ids[2], ids[3]]);
        }
    }
    Ok(by_material.into_values().collect())
}

/// The octant of its node a voxel lies in at depth `k` (`x | y<<1 | z<<2` of the position's
/// bit `7 − k`): at depth 0 the octant of the child node that holds its finer voxels.
pub fn voxel_octant(v: &Voxel, k: usize) -> u8 {
    let p = v.pos();
    let b = 7 - k;
    (p[0] >> b & 1) | (p[1] >> b & 1) << 1 | (p[2] >> b & 1) << 2
}

/// Whether voxel `v` lies in the part of its node given by the octant path `part` (the octant
/// at depth 0, then the octant inside that, …; empty: the whole node).
pub fn in_part(v: &Voxel, part: &[u8]) -> bool {
    part.iter()
        .enumerate()
        .all(|(k, &o)| voxel_octant(v, k) == o)
}

/// The binary chunk and the JSON arrays being laid out.
struct Layout {
    /// Compressed bytes (the GLB's binary chunk, buffer 0).
    bin: Vec<u8>,
    /// Uncompressed length so far (the fallback buffer, buffer 1).
    raw: u64,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Layout {
    /// Adds a buffer view of `count` elements of `stride` bytes, compressed as `encoded` in
    /// meshopt mode `mode`; returns its index.
    fn view(&mut self, encoded: &[u8], count: usize, stride: usize, mode: &str) -> usize {
        let len = (count * stride) as u64;
        let mut ext = json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": encoded.len(),
            "byteStride": stride,
            "count": count,
            "mode": mode,
        });
        if mode == "ATTRIBUTES" {
            ext["filter"] = json!("NONE");
        }
        let mut v = json!({
            "buffer": 1,
            "byteOffset": self.raw,
            "byteLength": len,
            "extensions": {"EXT_meshopt_compression": ext},
        });
        if mode == "ATTRIBUTES" {
            v["byteStride"] = json!(stride);
            v["target"] = json!(34962);
        } else {
            v["target"] = json!(34963);
        }
        self.bin.extend_from_slice(encoded);
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        self.raw += len.next_multiple_of(4);
        self.views.push(v);
        self.views.len() - 1
    }

    fn accessor(&mut self, a: Value) -> usize {
        self.accessors.push(a);
        self.accessors.len() - 1
    }
}

fn encode_vertices<T>(data: &[T]) -> Result<Vec<u8>, RenderError> {
    meshopt::encode_vertex_buffer(data)
        .map_err(|e| RenderError::Option(format!("meshopt vertex encoding: {e:?}")))
}

/// Material names from the manifest, indexed by material id.
pub(crate) fn material_names(reader: &Reader) -> Vec<String> {
    reader
        .manifest()
        .ok()
        .and_then(|m| {
            m.get("materials")?.as_array().map(|a| {
                a.iter()
                    .map(|n| n.as_str().unwrap_or_default().to_string())
                    .collect()
            })
        })
        .unwrap_or_default()
}

/// Node `index` as a tile content GLB in `frame`: the voxels of `part` ([`in_part`]; empty:
/// all).
pub fn tile_content(
    reader: &Reader,
    index: usize,
    part: &[u8],
    frame: &TileFrame,
    names: &[String],
) -> Result<TileContent, RenderError> {
    let mut buf = Vec::new();
    let streams = node_streams(reader, index, part, &mut buf)?;
    let mut out = TileContent {
        voxels: buf.iter().filter(|v| in_part(v, part)).count() as u64,
        ..TileContent::default()
    };
    if streams.is_empty() {
        return Ok(out);
    }
    let features = reader.has_materials();
    let mut l = Layout {
        bin: Vec::new(),
        raw: 0,
        views: Vec::new(),
        accessors: Vec::new(),
    };
    let mut primitives = Vec::new();
    let mut materials = Vec::new();
    for s in &streams {
        let n = s.pos.len();
        out.vertices += n as u64;
        out.quads += s.indices.len() as u64 / 6;
        let pv = l.view(&encode_vertices(&s.pos)?, n, 8, "ATTRIBUTES");
        let nv = l.view(&encode_vertices(&s.nrm)?, n, 4, "ATTRIBUTES");
        let cv = l.view(&encode_vertices(&s.col)?, n, 8, "ATTRIBUTES");
        let wide = n > 1 << 16;
        let encoded = meshopt::encode_index_buffer(&s.indices, n)
            .map_err(|e| RenderError::Option(format!("meshopt index encoding: {e:?}")))?;
        let iv = l.view(
            &encoded,
            s.indices.len(),
            if wide { 4 } else { 2 },
            "TRIANGLES",
        );
        let mut attributes = json!({
            "POSITION": l.accessor(json!({"bufferView": pv, "componentType": 5123, "count": n,
                "type": "VEC3", "min": s.min, "max": s.max})),
            "NORMAL": l.accessor(json!({"bufferView": nv, "componentType": 5120, "count": n,
                "type": "VEC3", "normalized": true})),
            "COLOR_0": l.accessor(json!({"bufferView": cv, "componentType": 5123, "count": n,
                "type": "VEC4", "normalized": true})),
        });
        let mut prim = json!({
            "indices": l.accessor(json!({"bufferView": iv,
                "componentType": if wide { 5125 } else { 5123 },
                "count": s.indices.len(), "type": "SCALAR"})),
            "material": materials.len(),
            "mode": 4,
        });
        if features {
            let id = u16::try_from(s.material).map_err(|_| {
                RenderError::Option(format!(
                    "material id {} is over the 65535 a feature id attribute holds",
                    s.material
                ))
            })?;
            let fv = l.view(&encode_vertices(&vec![[id, 0u16]; n])?, n, 4, "ATTRIBUTES");
            attributes["_FEATURE_ID_0"] = json!(l.accessor(
                json!({"bufferView": fv, "componentType": 5123, "count": n, "type": "SCALAR"})
            ));
            prim["extensions"] = json!({"EXT_mesh_features": {"featureIds": [
                {"featureCount": 1, "attribute": 0, "label": "material"}
            ]}});
        }
        prim["attributes"] = attributes;
        primitives.push(prim);
        let name = match names.get(s.material as usize) {
            Some(n) if !n.is_empty() => n.clone(),
            _ if s.material == 0 => "voxel".into(),
            _ => format!("material {}", s.material),
        };
        materials.push(json!({
            "name": name,
            "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
        }));
    }
    out.raw_bytes = l.raw;
    let e = reader.nodes()[index];
    let spec = reader.spec();
    let corner = frame.map(spec.voxel_min_corner(e.level, e.pos(), [0; 3]));
    let edge = spec.voxel_size_at(e.level) * frame.scale;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let mut name = format!("node {} {} {} {}", e.level, e.x, e.y, e.z);
    if !part.is_empty() {
        name += &format!(" part {part:?}");
    }
    let mut used = vec!["EXT_meshopt_compression", "KHR_mesh_quantization"];
    if features {
        used.push("EXT_mesh_features");
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": format!("voxlod {}", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": used,
        "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
        "buffers": [
            {"byteLength": l.bin.len()},
            {"byteLength": l.raw, "extensions": {"EXT_meshopt_compression": {"fallback": true}}},
        ],
        "bufferViews": l.views,
        "accessors": l.accessors,
        "materials": materials,
        "meshes": [{"name": name, "primitives": primitives}],
        // y-up glTF in a z-up tileset: the node turned −90° about x, its corner likewise
        "nodes": [{"mesh": 0, "name": name,
            "translation": [corner[0], corner[2], -corner[1]],
            "rotation": [-h, 0.0, 0.0, h],
            "scale": [edge, edge, edge]}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    });
    let mut j = serde_json::to_vec(&doc)
        .map_err(|e| RenderError::Option(format!("serializing the glTF document: {e}")))?;
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let total = 12 + 8 + j.len() + 8 + l.bin.len();
    let total = u32::try_from(total).map_err(|_| {
        RenderError::Option(format!(
            "the tile of {name} would be {total} bytes, more than a GLB holds"
        ))
    })?;
    let mut g = Vec::with_capacity(total as usize);
    g.extend_from_slice(b"glTF");
    g.extend_from_slice(&2u32.to_le_bytes());
    g.extend_from_slice(&total.to_le_bytes());
    g.extend_from_slice(&(j.len() as u32).to_le_bytes());
    g.extend_from_slice(b"JSON");
    g.extend_from_slice(&j);
    g.extend_from_slice(&(l.bin.len() as u32).to_le_bytes());
    g.extend_from_slice(b"BIN\0");
    g.extend_from_slice(&l.bin);
    out.glb = g;
    Ok(out)
}
