//! glTF 2.0 (Khronos, "glTF 2.0 Specification", 2021): `.gltf` with external or data-URI
//! buffers and images, and `.glb` with its binary chunk: the JSON read and validated by the
//! `gltf` crate; buffers and images loaded here, accessors decoded by `gltf_data` (with
//! `KHR_mesh_quantization`'s component types and `EXT_meshopt_compression`'s views).
//!
//! Every mesh primitive of the default scene (else the first scene) is streamed in world
//! coordinates: node transforms (matrix or TRS, nested) composed in f64; a transform whose
//! determinant is negative flips the winding back (spec 3.7.4). Triangles, strips and fans
//! become triangles; points and lines are a warning. Colour: `baseColorFactor` times `COLOR_0`
//! (both linear in glTF), stored sRGB-encoded as every voxlod colour is; the texture
//! `baseColorTexture` with its sampler's wrap modes and its `texCoord` set. Each glTF material
//! is an entry of the material table, by name. glTF is Y-up (`MeshInfo::up`).
//!
//! Texture coordinates: glTF puts `v = 0` at the image's first (top) row, OBJ and voxlod's
//! sampler at its last (bottom) row, so `v` is stored as `1 − v` (after `KHR_texture_transform`,
//! which is applied: offset, rotation, scale and its `texCoord` set, spec of the extension).
//!
//! Before the `gltf` crate reads anything, the file is checked by `gltf_check` (GLB chunk
//! lengths, UTF-8 JSON, every accessor, view and buffer against the specification's tables,
//! node cycles); a panic of the crate's readers all the same is caught and becomes an error
//! naming the file. Buffers and images named by URI are read only inside the mesh's folder
//! (or folders the caller allows: `refs`), only regular files, and only the declared bytes.

use crate::batch::Emitter;
use crate::refs::Scope;
use crate::{IngestError, Location, MeshInfo};
use gltf::mesh::Mode;
use std::path::{Path, PathBuf};
use voxlod_geom::{
    Embedded, Material, Triangle, Wrap, MAX_MATERIAL, TRI_HAS_COLORS, TRI_HAS_NORMALS, TRI_HAS_UV,
};

pub(crate) struct GltfSource {
    path: PathBuf,
    doc: gltf::Document,
    buffers: Vec<Vec<u8>>,
    /// Per buffer view: its bytes decoded, if it is compressed (`gltf_data`).
    decoded: Vec<Option<Vec<u8>>>,
    /// Per glTF material: the texture coordinate set of its base colour texture and its
    /// `KHR_texture_transform`, if the texture is usable.
    uv_set: Vec<Option<(u32, Option<UvTransform>)>>,
    /// The material table is kept (two or more materials, or a texture): triangles carry their
    /// material index.
    keep_materials: bool,
}

fn bad(path: &Path, message: impl Into<String>) -> IngestError {
    IngestError::malformed(path, Location::File, message)
}

/// The bytes of a `data:` URI (base64 only), or `None` if `uri` is not one.
fn data_uri(path: &Path, uri: &str) -> Option<Result<Vec<u8>, IngestError>> {
    use base64::Engine;
    let rest = uri.strip_prefix("data:")?;
    Some(match rest.split_once(";base64,") {
        Some((_, b64)) => base64::engine::general_purpose::STANDARD
            .decode(b64)
            .map_err(|e| bad(path, format!("a data URI is not valid base64 ({e})"))),
        None => Err(bad(path, "a data URI is not base64-encoded")),
    })
}

/// `%XX` escapes of a relative URI decoded (glTF URIs are RFC 3986).
fn unescape(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).and_then(|&c| hex(c)),
            b.get(i + 2).and_then(|&c| hex(c)),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, _, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn load_buffers(
    path: &Path,
    doc: &gltf::Document,
    mut blob: Option<Vec<u8>>,
    scope: &Scope,
    fallback: &[bool],
) -> Result<Vec<Vec<u8>>, IngestError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for b in doc.buffers() {
        if fallback.get(b.index()).copied().unwrap_or(false) {
            // EXT_meshopt_compression's fallback: read only through the decoded views
            out.push(Vec::new());
            continue;
        }
        let data = match b.source() {
            // the checks allow only the first buffer to be the binary chunk: moved, not copied
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                bad(
                    path,
                    format!(
                        "buffer {} refers to the binary chunk, which the file does not have",
                        b.index()
                    ),
                )
            })?,
            gltf::buffer::Source::Uri(uri) => match data_uri(path, uri) {
                Some(d) => d?,
                None => {
                    // only the declared bytes are read: a URI naming a huge file costs no more
                    let cannot = |e: String| {
                        bad(
                            path,
                            format!("buffer {} ({uri:?}) cannot be read: {e}", b.index()),
                        )
                    };
                    let f = crate::texpath::resolve(dir, &unescape(uri)).map_err(cannot)?;
                    scope.read_prefix(&f, b.length() as u64).map_err(cannot)?
                }
            },
        };
        if data.len() < b.length() {
            return Err(bad(
                path,
                format!(
                    "buffer {} holds {} bytes, but the file declares {} (truncated?)",
                    b.index(),
                    data.len(),
                    b.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// A `KHR_texture_transform` as the affine map `(u, v) ↦ (a·u + b·v + c, d·u + e·v + f)` in
/// glTF's texture space: `T(offset) · R(rotation) · S(scale)`, the extension's matrix. The
/// rotation is `u' = cos·u + sin·v`, `v' = −sin·u + cos·v`: counter-clockwise as the image is
/// seen (its `v` runs down), as the extension's prose and three.js's loader turn it; its GLSL
/// listing read column-major turns the other way (docs/INGEST.md, "Texture coordinates").
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UvTransform([f64; 6]);

impl UvTransform {
    fn new(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> UvTransform {
        let (s, c) = (rotation as f64).sin_cos();
        let (sx, sy) = (scale[0] as f64, scale[1] as f64);
        UvTransform([
            c * sx,
            s * sy,
            offset[0] as f64,
            -s * sx,
            c * sy,
            offset[1] as f64,
        ])
    }

    fn apply(&self, [u, v]: [f32; 2]) -> [f32; 2] {
        let [a, b, c, d, e, f] = self.0;
        let (u, v) = (u as f64, v as f64);
        [(a * u + b * v + c) as f32, (d * u + e * v + f) as f32]
    }
}

fn wrap(m: gltf::texture::WrappingMode) -> Wrap {
    match m {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::Clamp,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::Mirror,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

/// The material table entry of glTF material `m` and its texture coordinate set.
fn material(
    path: &Path,
    m: &gltf::Material,
    buffers: &[Vec<u8>],
    scope: &Scope,
    warnings: &mut Vec<String>,
) -> (Material, Option<(u32, Option<UvTransform>)>) {
    let name = m.name().map_or(
        format!("material {}", m.index().unwrap_or(0)),
        str::to_string,
    );
    let mut e = Material {
        name,
        ..Material::default()
    };
    let Some(info) = m.pbr_metallic_roughness().base_color_texture() else {
        return (e, None);
    };
    let tex = info.texture();
    let s = tex.sampler();
    e.wrap = [wrap(s.wrap_s()), wrap(s.wrap_t())];
    let img = tex.source();
    let dir = path.parent().unwrap_or(Path::new("."));
    let label = PathBuf::from(format!("{}#image {}", path.display(), img.index()));
    let found: Result<(PathBuf, Option<Embedded>), String> = match img.source() {
        gltf::image::Source::View { view, .. } => {
            let b = &buffers[view.buffer().index()];
            b.get(view.offset()..view.offset() + view.length())
                .map(|s| (label, Some(Embedded(s.into()))))
                .ok_or_else(|| "its buffer view lies outside the buffer".to_string())
        }
        gltf::image::Source::Uri { uri, .. } => match data_uri(path, uri) {
            Some(Ok(d)) => Ok((label, Some(Embedded(d.into())))),
            Some(Err(err)) => Err(err.to_string()),
            None => crate::texpath::resolve(dir, &unescape(uri))
                .and_then(|f| scope.check(&f).map(|()| (f, None))),
        },
    };
    match found {
        Ok((file, embedded)) => {
            e.texture = Some(file);
            e.embedded = embedded;
            let (set, transform) = match info.texture_transform() {
                Some(t) => (
                    t.tex_coord().unwrap_or(info.tex_coord()),
                    Some(UvTransform::new(t.offset(), t.rotation(), t.scale())),
                ),
                None => (info.tex_coord(), None),
            };
            (e, Some((set, transform)))
        }
        Err(err) => {
            warnings.push(format!(
                "the base colour texture of material {:?} cannot be used ({err}); its baseColorFactor is used",
                e.name
            ));
            (e, None)
        }
    }
}

/// The nodes of the scene to read, each with its world transform (column-major, f64).
fn scene_nodes(doc: &gltf::Document) -> Vec<(gltf::Node<'_>, [[f64; 4]; 4])> {
    let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut stack: Vec<(gltf::Node, [[f64; 4]; 4])> =
        scene.nodes().map(|n| (n, IDENTITY)).collect();
    stack.reverse();
    while let Some((n, parent)) = stack.pop() {
        let local = n.transform().matrix().map(|c| c.map(f64::from));
        let world = mul(&parent, &local);
        let children: Vec<_> = n.children().map(|c| (c, world)).collect();
        out.push((n, world));
        stack.extend(children.into_iter().rev());
    }
    out
}

const IDENTITY: [[f64; 4]; 4] = [
    [1., 0., 0., 0.],
    [0., 1., 0., 0.],
    [0., 0., 1., 0.],
    [0., 0., 0., 1.],
];

/// `a · b` of column-major 4×4 matrices.
fn mul(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for c in 0..4 {
        for r in 0..4 {
            m[c][r] = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

/// The most vertex and index records one glTF file's scene may read, over all the instances
/// of its primitives: about what a billion-triangle mesh reads. Nodes instancing a mesh and
/// primitives sharing accessors multiply the records read without growing the file, so a few
/// kilobytes could otherwise ask for hours of work.
pub(crate) const MAX_INSTANCED_RECORDS: u64 = 1 << 32;

/// Bytes of decoded attributes per vertex while a primitive is read: position and normal
/// (12 bytes each), colour (16) and its bytes (4), texture coordinates (8).
const DECODED_PER_VERTEX: u64 = 52;

/// What the scene asks for, counted over every instance of every primitive.
#[derive(Clone, Copy, Debug, Default)]
struct Instanced {
    /// Vertex records (one per attribute) and indices read.
    records: u64,
    /// Triangles made (TRIANGLES: a third of the indices; strips and fans: two fewer).
    triangles: u64,
}

/// The scene's instanced work and the most bytes decoding one primitive holds.
fn instanced_work(doc: &gltf::Document) -> (Instanced, u64) {
    let (mut w, mut largest) = (Instanced::default(), 0u64);
    for (node, _) in scene_nodes(doc) {
        for p in node.mesh().iter().flat_map(|m| m.primitives()) {
            if !matches!(
                p.mode(),
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let v = p
                .get(&gltf::Semantic::Positions)
                .map_or(0, |a| a.count() as u64);
            let i = p.indices().map_or(v, |a| a.count() as u64);
            w.records = w
                .records
                .saturating_add(v.saturating_mul(p.attributes().count() as u64) + i);
            w.triangles += match p.mode() {
                Mode::Triangles => i / 3,
                _ => i.saturating_sub(2),
            };
            largest = largest.max(v * DECODED_PER_VERTEX + i * 4);
        }
    }
    (w, largest)
}

/// Bytes the buffers and images read besides the file itself take: buffers named by URI (a
/// data URI decodes to at most three quarters of its text), images copied out of buffer views
/// or decoded from data URIs.
fn referenced_bytes(doc: &gltf::Document) -> u64 {
    let from_uri = |uri: &str| uri.len() as u64 / 4 * 3 + 3;
    let buffers: u64 = doc
        .buffers()
        .map(|b| match b.source() {
            gltf::buffer::Source::Bin => 0,
            gltf::buffer::Source::Uri(u) if u.starts_with("data:") => {
                (b.length() as u64).max(from_uri(u))
            }
            gltf::buffer::Source::Uri(_) => b.length() as u64,
        })
        .sum();
    let images: u64 = doc
        .images()
        .map(|i| match i.source() {
            gltf::image::Source::View { view, .. } => view.length() as u64,
            gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => from_uri(uri),
            gltf::image::Source::Uri { .. } => 0,
        })
        .sum();
    buffers + images
}

/// The memory a glTF reader holds, bytes, counted against the caller's budget
/// ([`crate::ReadOptions::memory`]) before each part is read.
#[derive(Clone, Copy, Debug, Default)]
struct Held {
    /// The file read whole (a GLB's binary chunk stays as buffer 0).
    file: u64,
    /// Parsing the JSON document ([`crate::gltf_check::document_bound`]).
    document: u64,
    /// Buffers and images read besides the file ([`referenced_bytes`]).
    buffers: u64,
    /// Decoding the largest primitive.
    decoding: u64,
}

/// `bytes` in MiB, for messages.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
}

impl Held {
    fn total(&self) -> u64 {
        self.file + self.document + self.buffers + self.decoding
    }

    /// Refuses what does not fit `memory`, naming each part and the budget.
    fn check(&self, path: &Path, memory: Option<u64>) -> Result<(), IngestError> {
        let Some(m) = memory.filter(|&m| self.total() > m) else {
            return Ok(());
        };
        let parts: Vec<String> = [
            (self.file, "the file"),
            (self.document, "parsing its JSON document"),
            (self.buffers, "the buffers and images it names"),
            (self.decoding, "decoding its largest primitive"),
        ]
        .iter()
        .filter(|(b, _)| *b > 0)
        .map(|(b, what)| format!("{what} {}", mib(*b)))
        .collect();
        Err(bad(
            path,
            format!(
                "reading this glTF file needs up to {} of memory ({}), more than the {} the memory budget leaves for reading the input; nothing was read past that: raise --memory by at least {}",
                mib(self.total()),
                parts.join(", "),
                mib(m),
                mib(self.total() - m)
            ),
        ))
    }
}

/// Sparse accessors' indices (glTF 2.0, 3.6.2.3): each less than the accessor's count and
/// strictly increasing. The `gltf` crate's reader drops an index past the count silently, so
/// a file breaking the rule would lose the values it substitutes without a word.
fn sparse_indices(
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
    decoded: &[Option<Vec<u8>>],
) -> Result<(), String> {
    use gltf::accessor::sparse::IndexType;
    for a in doc.accessors() {
        let Some(sp) = a.sparse() else { continue };
        let ix = sp.indices();
        let view = ix.view();
        let size = match ix.index_type() {
            IndexType::U8 => 1,
            IndexType::U16 => 2,
            IndexType::U32 => 4,
        };
        // a meshopt-compressed view is read decoded, the others from their buffer
        let (bytes, start) = match decoded.get(view.index()).and_then(Option::as_ref) {
            Some(d) => (Some(d), ix.offset()),
            None => (
                buffers.get(view.buffer().index()),
                view.offset() + ix.offset(),
            ),
        };
        let data = bytes
            .and_then(|b| b.get(start..start + sp.count() * size))
            .ok_or_else(|| {
                format!(
                    "accessor {}: its sparse indices lie outside their buffer",
                    a.index()
                )
            })?;
        let mut last: Option<u64> = None;
        for (k, c) in data.chunks_exact(size).enumerate() {
            let x = c
                .iter()
                .rev()
                .fold(0u64, |acc, &byte| (acc << 8) | byte as u64);
            let rule = if x >= a.count() as u64 {
                Some(format!(
                    "is {x}, but the accessor has {} elements",
                    a.count()
                ))
            } else if last.is_some_and(|l| x <= l) {
                Some(format!("is {x}, not more than the index before it"))
            } else {
                None
            };
            if let Some(rule) = rule {
                return Err(format!(
                    "accessor {} sparse index {k} {rule}; sparse indices must be less than the accessor's count and strictly increasing (glTF 2.0, 3.6.2.3)",
                    a.index()
                ));
            }
            last = Some(x);
        }
    }
    Ok(())
}

/// The extensions voxlod reads.
const READ_EXTENSIONS: [&str; 4] = [
    "KHR_texture_transform",
    "KHR_mesh_quantization",
    crate::gltf_data::MESHOPT[0],
    crate::gltf_data::MESHOPT[1],
];

/// A panic of the `gltf` crate (which the checks should leave none of) as an error naming the
/// file, so that no input ends the process.
fn caught<T>(path: &Path, f: impl FnOnce() -> Result<T, IngestError>) -> Result<T, IngestError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|_| {
        Err(bad(
            path,
            "the glTF reader failed on this file (a panic of the gltf crate, caught): it is malformed in a way voxlod's checks do not name",
        ))
    })
}

impl GltfSource {
    pub fn open(
        path: &Path,
        scope: &Scope,
        memory: Option<u64>,
    ) -> Result<(GltfSource, MeshInfo), IngestError> {
        caught(path, || Self::open_checked(path, scope, memory))
    }

    fn open_checked(
        path: &Path,
        scope: &Scope,
        memory: Option<u64>,
    ) -> Result<(GltfSource, MeshInfo), IngestError> {
        let file_len = std::fs::metadata(path)
            .map_err(|e| IngestError::io(path, e))?
            .len();
        let mut held = Held {
            file: file_len,
            ..Held::default()
        };
        held.check(path, memory)?;
        // The container and document checked, then the gltf crate's parse.
        let mut bytes = voxlod_io::read_bounded(path, u64::MAX).map_err(|e| match e {
            voxlod_io::BoundError::Io(e) => IngestError::io(path, e),
            e => bad(path, e.to_string()),
        })?;
        let binary = bytes.starts_with(b"glTF");
        let c = crate::gltf_check::container(&bytes).map_err(|m| bad(path, m))?;
        held.document = crate::gltf_check::document_bound(c.json.as_bytes());
        held.check(path, memory)?;
        crate::gltf_check::document(c.json, c.bin).map_err(|m| bad(path, m))?;
        let meshopt = crate::gltf_data::Meshopt::parse(c.json).map_err(|m| bad(path, m))?;
        let not_gltf = |e: gltf::Error| bad(path, format!("not a valid glTF 2.0 file: {e}"));
        let mut root: gltf::json::Root = gltf::json::deserialize::from_slice(c.json.as_bytes())
            .map_err(|e| not_gltf(gltf::Error::Deserialize(e)))?;
        if let Some(ext) = root
            .extensions_required
            .iter()
            .find(|e| !READ_EXTENSIONS.contains(&e.as_str()))
        {
            return Err(bad(
                path,
                format!("the file requires the extension {ext:?}, which voxlod does not read"),
            ));
        }
        // every required extension is read here: the gltf crate's check of them (it knows
        // none of KHR_mesh_quantization and meshopt's) is not needed
        root.extensions_required.clear();
        let doc = gltf::Document::from_json(root).map_err(not_gltf)?;
        // the binary chunk becomes buffer 0 in place: the file's other bytes are dropped
        let bin = c.bin.map(|b| {
            let start = b.as_ptr() as usize - bytes.as_ptr() as usize;
            (start, b.len())
        });
        let blob = bin.map(|(start, len)| {
            bytes.truncate(start + len);
            bytes.drain(..start);
            bytes.shrink_to_fit();
            bytes
        });
        held.buffers = referenced_bytes(&doc);
        let (instanced, largest) = instanced_work(&doc);
        held.decoding = largest;
        held.check(path, memory)?;
        if instanced.records > MAX_INSTANCED_RECORDS {
            return Err(bad(
                path,
                format!(
                    "the scene reads {} vertex and index records for {} triangles (its nodes instance meshes and primitives share accessors), more than the {} voxlod reads from one glTF file",
                    instanced.records, instanced.triangles, MAX_INSTANCED_RECORDS
                ),
            ));
        }
        let buffers = load_buffers(path, &doc, blob, scope, &meshopt.fallback)?;
        let decoded = meshopt.decode(&doc, &buffers).map_err(|m| bad(path, m))?;
        sparse_indices(&doc, &buffers, &decoded).map_err(|m| bad(path, m))?;
        let mut warnings = Vec::new();
        let mut materials = vec![Material::default()];
        let mut uv_set = Vec::new();
        for m in doc.materials() {
            let (e, set) = material(path, &m, &buffers, scope, &mut warnings);
            materials.push(e);
            uv_set.push(set);
        }
        let mut src = GltfSource {
            path: path.to_path_buf(),
            doc,
            buffers,
            decoded,
            uv_set,
            keep_materials: true,
        };
        let (mut vertices, mut has_normals, mut has_colors, mut has_uv) = (0, false, false, false);
        let faces = instanced.triangles;
        let (mut skipped, mut no_uv) = (0, 0u64);
        for (node, _) in scene_nodes(&src.doc) {
            for p in node.mesh().iter().flat_map(|m| m.primitives()) {
                if !matches!(
                    p.mode(),
                    Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
                ) {
                    skipped += 1;
                    continue;
                }
                let n = p
                    .get(&gltf::Semantic::Positions)
                    .map_or(0, |a| a.count() as u64);
                vertices += n;
                has_normals |= p.get(&gltf::Semantic::Normals).is_some();
                has_colors |=
                    p.get(&gltf::Semantic::Colors(0)).is_some() || p.material().index().is_some();
                has_uv |= src.uv_of(&p).is_some();
                let textured = p.material().index().and_then(|i| src.uv_set[i]).is_some();
                no_uv += u64::from(textured && src.uv_of(&p).is_none());
            }
        }
        if no_uv > 0 {
            warnings.push(format!(
                "{no_uv} primitives of textured materials lack the texture coordinate set the texture reads; their baseColorFactor is used"
            ));
        }
        let used: Vec<&str> = src
            .doc
            .extensions_used()
            .filter(|e| !READ_EXTENSIONS.contains(e))
            .collect();
        if !used.is_empty() {
            warnings.push(format!(
                "extensions used by the file are not read: {}",
                used.join(", ")
            ));
        }
        if skipped > 0 {
            warnings.push(format!(
                "{skipped} primitives of points or lines are not triangles and are skipped"
            ));
        }
        if !has_uv {
            materials
                .iter_mut()
                .for_each(|m| (m.texture, m.embedded) = (None, None));
        }
        if !has_uv && materials.len() <= 2 {
            materials.clear();
            src.keep_materials = false;
        }
        if materials.len() > MAX_MATERIAL as usize + 1 {
            warnings.push(format!(
                "more than {MAX_MATERIAL} materials: the others count as no material (id 0)"
            ));
            materials.truncate(MAX_MATERIAL as usize + 1);
        }
        let info = MeshInfo {
            path: path.to_path_buf(),
            format: if binary { "glb" } else { "gltf" }.into(),
            vertices,
            faces,
            has_normals,
            has_colors,
            has_texcoords: has_uv,
            materials,
            warnings,
            up: Some([0.0, 1.0, 0.0]),
            held: held.total(),
        };
        Ok((src, info))
    }

    /// The texture coordinate set primitive `p` reads, if its material has a usable texture
    /// and the primitive has that set.
    fn uv_of(&self, p: &gltf::Primitive) -> Option<(u32, Option<UvTransform>)> {
        let (set, t) = (*self.uv_set.get(p.material().index()?)?)?;
        p.get(&gltf::Semantic::TexCoords(set)).map(|_| (set, t))
    }

    pub fn stream(&self, em: &mut Emitter) -> Result<(), IngestError> {
        caught(&self.path, || self.stream_checked(em))
    }

    fn stream_checked(&self, em: &mut Emitter) -> Result<(), IngestError> {
        for (node, world) in scene_nodes(&self.doc) {
            for p in node.mesh().iter().flat_map(|m| m.primitives()) {
                self.primitive(&p, &world, em)?;
            }
        }
        Ok(())
    }
}

/// The upper 3×3 of `m` (column-major) and the matrix normals are transformed by: its
/// cofactor matrix (the inverse transpose times the determinant) times the determinant's sign.
fn linear_parts(m: &[[f64; 4]; 4]) -> ([[f64; 3]; 3], [[f64; 3]; 3], f64) {
    let a = |c: usize, r: usize| m[c][r];
    let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(2, 1) * a(1, 2))
        - a(1, 0) * (a(0, 1) * a(2, 2) - a(2, 1) * a(0, 2))
        + a(2, 0) * (a(0, 1) * a(1, 2) - a(1, 1) * a(0, 2));
    let mut cof = [[0.0; 3]; 3];
    for c in 0..3 {
        for r in 0..3 {
            let (c1, c2, r1, r2) = ((c + 1) % 3, (c + 2) % 3, (r + 1) % 3, (r + 2) % 3);
            cof[c][r] = (a(c1, r1) * a(c2, r2) - a(c2, r1) * a(c1, r2)) * det.signum();
        }
    }
    let lin = [0, 1, 2].map(|c| [m[c][0], m[c][1], m[c][2]]);
    (lin, cof, det)
}

/// A linear-light channel 0–1 to an sRGB-encoded byte.
fn srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0) as f64;
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

impl GltfSource {
    /// Streams one primitive's triangles, transformed by `world`.
    fn primitive(
        &self,
        p: &gltf::Primitive,
        world: &[[f64; 4]; 4],
        em: &mut Emitter,
    ) -> Result<(), IngestError> {
        let mode = p.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Ok(()); // warned at open
        }
        let err = |m: String| bad(&self.path, format!("mesh primitive {}: {m}", p.index()));
        let data = crate::gltf_data::Data {
            buffers: &self.buffers,
            decoded: &self.decoded,
        };
        let (lin, cof, det) = linear_parts(world);
        let apply = |m: &[[f64; 3]; 3], v: [f32; 3], t: [f64; 3]| -> [f32; 3] {
            [0, 1, 2]
                .map(|row| ((0..3).map(|c| m[c][row] * v[c] as f64).sum::<f64>() + t[row]) as f32)
        };
        let origin = [world[3][0], world[3][1], world[3][2]];
        let attribute = |sem: gltf::Semantic| p.get(&sem);
        let pos: Vec<[f32; 3]> = data
            .floats::<3>(
                &attribute(gltf::Semantic::Positions)
                    .ok_or_else(|| err("no POSITION attribute".into()))?,
            )
            .map_err(err)?
            .into_iter()
            .map(|v| apply(&lin, v, origin))
            .collect();
        if let Some((i, _)) = pos
            .iter()
            .enumerate()
            .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
        {
            return Err(err(format!("vertex {i} has a position that is not finite")));
        }
        let nrm: Option<Vec<[f32; 3]>> = attribute(gltf::Semantic::Normals)
            .map(|a| data.floats::<3>(&a))
            .transpose()
            .map_err(err)?
            .map(|n| n.into_iter().map(|v| apply(&cof, v, [0.0; 3])).collect());
        let factor = p.material().pbr_metallic_roughness().base_color_factor();
        let colored = p.material().index().is_some() || p.get(&gltf::Semantic::Colors(0)).is_some();
        let col: Option<Vec<[f32; 4]>> = attribute(gltf::Semantic::Colors(0))
            .map(|a| data.floats::<4>(&a))
            .transpose()
            .map_err(err)?;
        let uv_set = self.uv_of(p);
        // glTF's v runs down the image, voxlod's (OBJ's) up: v becomes 1 − v, after the
        // material's KHR_texture_transform
        let uv: Option<Vec<[f32; 2]>> = match uv_set {
            Some((s, t)) => attribute(gltf::Semantic::TexCoords(s))
                .map(|a| data.floats::<2>(&a))
                .transpose()
                .map_err(err)?
                .map(|c| {
                    c.into_iter()
                        .map(|uv| t.map_or(uv, |t| t.apply(uv)))
                        .map(|[u, v]| [u, 1.0 - v])
                        .collect()
                }),
            None => None,
        };
        let n = pos.len();
        let idx: Vec<u32> = match p.indices() {
            Some(a) => data.indices(&a).map_err(err)?,
            None => (0..n as u32).collect(),
        };
        if let Some(i) = idx.iter().find(|&&i| i as usize >= n) {
            return Err(err(format!("index {i} is out of range ({n} vertices)")));
        }
        for a in [
            nrm.as_ref().map(Vec::len),
            col.as_ref().map(Vec::len),
            uv.as_ref().map(Vec::len),
        ]
        .into_iter()
        .flatten()
        {
            if a != n {
                return Err(err(format!("an attribute has {a} values for {n} vertices")));
            }
        }
        let mut flags = if nrm.is_some() { TRI_HAS_NORMALS } else { 0 }
            | if colored { TRI_HAS_COLORS } else { 0 };
        if uv.is_some() {
            flags |= TRI_HAS_UV;
        }
        let material = p.material().index().map_or(0, |i| i as u32 + 1);
        // the colour bytes once per vertex (or once for the primitive), not per corner
        let bytes = |c: [f32; 4]| {
            let lc = [0, 1, 2, 3].map(|ch| c[ch] * factor[ch]);
            [
                srgb8(lc[0]),
                srgb8(lc[1]),
                srgb8(lc[2]),
                (lc[3].clamp(0.0, 1.0) * 255.0).round() as u8,
            ]
        };
        let vertex_bytes: Option<Vec<[u8; 4]>> =
            col.as_ref().map(|c| c.iter().map(|&c| bytes(c)).collect());
        let uniform = bytes([1.0; 4]);
        let corner = |t: &mut Triangle, k: usize, i: usize| {
            t.v[k] = pos[i];
            if let Some(nv) = &nrm {
                t.n[k] = nv[i];
            }
            t.c[k] = vertex_bytes.as_ref().map_or(uniform, |b| b[i]);
            if let Some(u) = &uv {
                t.uv[k] = u[i];
            }
        };
        let tris: Box<dyn Iterator<Item = [u32; 3]>> = match mode {
            Mode::Triangles => Box::new(idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]])),
            Mode::TriangleStrip => Box::new((2..idx.len()).map(|j| {
                if j % 2 == 0 {
                    [idx[j - 2], idx[j - 1], idx[j]]
                } else {
                    [idx[j - 2], idx[j], idx[j - 1]]
                }
            })),
            _ => Box::new((2..idx.len()).map(|j| [idx[j - 1], idx[j], idx[0]])),
        };
        for mut tri in tris {
            em.stats.polygons += 1;
            if det < 0.0 {
                tri.swap(1, 2);
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                em.repeated_index();
                continue;
            }
            let mut t = Triangle::new([[0.0; 3]; 3]);
            t.flags = flags;
            for (k, &i) in tri.iter().enumerate() {
                corner(&mut t, k, i as usize);
            }
            if self.keep_materials && material <= MAX_MATERIAL {
                t.set_material(material);
            }
            em.push(t)?;
        }
        Ok(())
    }
}
