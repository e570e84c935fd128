//! A minimal glTF 2.0 writer for tests (`.gltf` with an external `.bin` or `.glb`), written by
//! hand from the specification and sharing no code with the reader (`voxlod-ingest` uses the
//! `gltf` crate): float positions, optional `u32` indices, `TEXCOORD_0`, `COLOR_0` (float
//! RGBA), one material per primitive with `baseColorFactor` and a `baseColorTexture` from a
//! file, a data URI or a buffer view, and nodes with a matrix or TRS and children.

use std::path::Path;

/// One mesh primitive.
#[derive(Clone, Debug, Default)]
pub struct Prim {
    /// `POSITION`.
    pub positions: Vec<[f32; 3]>,
    /// `indices` (`u32`); none: the vertices in order.
    pub indices: Option<Vec<u32>>,
    /// `TEXCOORD_0`.
    pub uv: Option<Vec<[f32; 2]>>,
    /// `COLOR_0`, linear RGBA.
    pub colors: Option<Vec<[f32; 4]>>,
    /// 4 triangles, 5 strip, 6 fan, 0 points.
    pub mode: u32,
    /// Index into the materials.
    pub material: Option<usize>,
}

impl Prim {
    /// The textured quad the texture tests share (a 256-unit square in z = 0.5, texture
    /// coordinates 0–1 across it, material 0), as two indexed triangles fanned from corner 0 as
    /// an OBJ `f 1/1 2/2 3/3 4/4` is. Its texture coordinates are glTF's (`v = 0` at the
    /// image's top row), so that it maps the image as the OBJ quad with `vt 0 0`, `vt 1 0`,
    /// `vt 1 1`, `vt 0 1` (OBJ's `v = 0` is the bottom row) does.
    pub fn textured_quad() -> Prim {
        Prim {
            positions: vec![
                [0., 0., 0.5],
                [256., 0., 0.5],
                [256., 256., 0.5],
                [0., 256., 0.5],
            ],
            indices: Some(vec![0, 1, 2, 0, 2, 3]),
            uv: Some(vec![[0., 1.], [1., 1.], [1., 0.], [0., 0.]]),
            mode: 4,
            material: Some(0),
            ..Prim::default()
        }
    }
}

/// Where a material's base colour texture is.
#[derive(Clone, Debug)]
pub enum Image {
    /// A file, by URI relative to the glTF.
    Uri(String),
    /// PNG bytes in a `data:` URI.
    DataUri(Vec<u8>),
    /// PNG bytes in a buffer view.
    View(Vec<u8>),
}

/// A material.
#[derive(Clone, Debug)]
pub struct Mat {
    /// `name`.
    pub name: String,
    /// `baseColorFactor`.
    pub base_color: [f32; 4],
    /// `baseColorTexture`'s image.
    pub texture: Option<Image>,
    /// Sampler `wrapS`, `wrapT` (10497 repeat, 33071 clamp, 33648 mirror).
    pub wrap: [u32; 2],
}

/// A node: a mesh, a transform (matrix, column-major, or TRS) and children.
#[derive(Clone, Debug, Default)]
pub struct Node {
    /// `mesh`.
    pub mesh: Option<usize>,
    /// `matrix`, column-major.
    pub matrix: Option<[f32; 16]>,
    /// `translation`.
    pub translation: Option<[f32; 3]>,
    /// `rotation`, a unit quaternion x, y, z, w.
    pub rotation: Option<[f32; 4]>,
    /// `scale`.
    pub scale: Option<[f32; 3]>,
    /// `children`.
    pub children: Vec<usize>,
}

/// Standard base64 with padding (RFC 4648).
pub fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

struct Bin {
    data: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl Bin {
    fn view(&mut self, bytes: &[u8]) -> usize {
        while self.data.len() % 4 != 0 {
            self.data.push(0);
        }
        self.views.push(format!(
            r#"{{"buffer":0,"byteOffset":{},"byteLength":{}}}"#,
            self.data.len(),
            bytes.len()
        ));
        self.data.extend_from_slice(bytes);
        self.views.len() - 1
    }
    fn floats(&mut self, xs: &[f32], n: usize, ty: &str, minmax: bool) -> usize {
        let bytes: Vec<u8> = xs.iter().flat_map(|x| x.to_le_bytes()).collect();
        let v = self.view(&bytes);
        let mut extra = String::new();
        if minmax {
            let (mut lo, mut hi) = (vec![f32::MAX; n], vec![f32::MIN; n]);
            for c in xs.chunks(n) {
                for k in 0..n {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            extra = format!(r#","min":{lo:?},"max":{hi:?}"#);
        }
        self.accessors.push(format!(
            r#"{{"bufferView":{v},"componentType":5126,"count":{},"type":"{ty}"{extra}}}"#,
            xs.len() / n
        ));
        self.accessors.len() - 1
    }
}

/// Writes the scene (one scene of roots `roots`, the default) to `path`: a `.glb` if it ends
/// in `.glb`, else a `.gltf` whose buffer is `NAME.bin` beside it.
pub fn write(path: &Path, meshes: &[Vec<Prim>], nodes: &[Node], roots: &[usize], mats: &[Mat]) {
    // The glTF JSON in the specification's order.
    let mut bin = Bin {
        data: Vec::new(),
        views: Vec::new(),
        accessors: Vec::new(),
    };
    let mut mesh_json = Vec::new();
    for m in meshes {
        let mut prims = Vec::new();
        for p in m {
            let flat: Vec<f32> = p.positions.iter().flatten().copied().collect();
            let mut attrs = format!(r#""POSITION":{}"#, bin.floats(&flat, 3, "VEC3", true));
            if let Some(uv) = &p.uv {
                let flat: Vec<f32> = uv.iter().flatten().copied().collect();
                attrs += &format!(r#","TEXCOORD_0":{}"#, bin.floats(&flat, 2, "VEC2", false));
            }
            if let Some(c) = &p.colors {
                let flat: Vec<f32> = c.iter().flatten().copied().collect();
                attrs += &format!(r#","COLOR_0":{}"#, bin.floats(&flat, 4, "VEC4", false));
            }
            let mut s = format!(r#"{{"attributes":{{{attrs}}},"mode":{}"#, p.mode);
            if let Some(ix) = &p.indices {
                let bytes: Vec<u8> = ix.iter().flat_map(|i| i.to_le_bytes()).collect();
                let v = bin.view(&bytes);
                bin.accessors.push(format!(
                    r#"{{"bufferView":{v},"componentType":5125,"count":{},"type":"SCALAR"}}"#,
                    ix.len()
                ));
                s += &format!(r#","indices":{}"#, bin.accessors.len() - 1);
            }
            if let Some(m) = p.material {
                s += &format!(r#","material":{m}"#);
            }
            prims.push(s + "}");
        }
        mesh_json.push(format!(r#"{{"primitives":[{}]}}"#, prims.join(",")));
    }
    let (mut images, mut textures, mut samplers, mut mat_json) = (vec![], vec![], vec![], vec![]);
    for m in mats {
        let mut pbr = format!(r#""baseColorFactor":{:?}"#, m.base_color);
        if let Some(img) = &m.texture {
            images.push(match img {
                Image::Uri(u) => format!(r#"{{"uri":"{u}"}}"#),
                Image::DataUri(b) => format!(r#"{{"uri":"data:image/png;base64,{}"}}"#, base64(b)),
                Image::View(b) => {
                    format!(r#"{{"bufferView":{},"mimeType":"image/png"}}"#, bin.view(b))
                }
            });
            samplers.push(format!(
                r#"{{"wrapS":{},"wrapT":{}}}"#,
                m.wrap[0], m.wrap[1]
            ));
            textures.push(format!(
                r#"{{"source":{},"sampler":{}}}"#,
                images.len() - 1,
                samplers.len() - 1
            ));
            pbr += &format!(r#","baseColorTexture":{{"index":{}}}"#, textures.len() - 1);
        }
        mat_json.push(format!(
            r#"{{"name":"{}","pbrMetallicRoughness":{{{pbr}}}}}"#,
            m.name
        ));
    }
    let node_json: Vec<String> = nodes
        .iter()
        .map(|n| {
            let mut f = Vec::new();
            if let Some(m) = n.mesh {
                f.push(format!(r#""mesh":{m}"#));
            }
            if let Some(m) = n.matrix {
                f.push(format!(r#""matrix":{m:?}"#));
            }
            if let Some(t) = n.translation {
                f.push(format!(r#""translation":{t:?}"#));
            }
            if let Some(r) = n.rotation {
                f.push(format!(r#""rotation":{r:?}"#));
            }
            if let Some(s) = n.scale {
                f.push(format!(r#""scale":{s:?}"#));
            }
            if !n.children.is_empty() {
                f.push(format!(r#""children":{:?}"#, n.children));
            }
            format!("{{{}}}", f.join(","))
        })
        .collect();
    while bin.data.len() % 4 != 0 {
        bin.data.push(0);
    }
    let glb = path.extension().is_some_and(|e| e == "glb");
    let bin_name = format!("{}.bin", path.file_stem().unwrap().to_string_lossy());
    let buffer = if glb {
        format!(r#"{{"byteLength":{}}}"#, bin.data.len())
    } else {
        format!(r#"{{"byteLength":{},"uri":"{bin_name}"}}"#, bin.data.len())
    };
    let list = |v: &[String]| v.join(",");
    let mut json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":{roots:?}}}],"nodes":[{}],"meshes":[{}],"buffers":[{buffer}],"bufferViews":[{}],"accessors":[{}]"#,
        list(&node_json),
        list(&mesh_json),
        list(&bin.views),
        list(&bin.accessors)
    );
    if !mat_json.is_empty() {
        json += &format!(r#","materials":[{}]"#, list(&mat_json));
    }
    if !images.is_empty() {
        json += &format!(
            r#","images":[{}],"textures":[{}],"samplers":[{}]"#,
            list(&images),
            list(&textures),
            list(&samplers)
        );
    }
    json += "}";
    if !glb {
        std::fs::write(path, json).unwrap();
        std::fs::write(path.with_file_name(bin_name), &bin.data).unwrap();
        return;
    }
    let mut j = json.into_bytes();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let total = 12 + 8 + j.len() + 8 + bin.data.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&j);
    out.extend((bin.data.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(&bin.data);
    std::fs::write(path, out).unwrap();
}
