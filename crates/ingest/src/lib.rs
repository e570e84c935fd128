//! The ingest stage of voxlod: streams the triangles of a mesh file, with per-vertex normals
//! and colours when the file has them, as [`voxlod_geom::Triangle`] records in world
//! coordinates, in file order, in batches.
//!
//! Formats (detected by extension, confirmed by the first bytes):
//! * **PLY** (`.ply`, `.ply.gz`): ascii, binary_little_endian, binary_big_endian, optionally
//!   gzip-compressed. Elements in any order, unknown elements and properties skipped, faces
//!   (polygons, fan-triangulated) and `tristrips` (restart at -1). Vertex normals `nx ny nz`;
//!   vertex colours `red green blue [alpha]` (or `diffuse_*`, `r g b a`), uchar 0–255 or
//!   float 0–1. Per-face `material` / `material_index` (named by `comment material N = NAME`)
//!   into [`MeshInfo::materials`], face colours, texture coordinates per vertex (`u v`, `s t`,
//!   `texture_u texture_v`, `texture_s texture_t`) or per face (`texcoord` lists) with
//!   `comment TextureFile NAME` (`ply_materials.rs`, `ply_face_data.rs`).
//! * **OBJ** (`.obj`) through `tobj`: polygons fan-triangulated, MTL `Kd` (times `d` as alpha)
//!   as the colour of the triangle, `vn` normals when every face corner has one; `vt`
//!   texture coordinates and the material's `map_Kd` texture (resolved relative to the MTL
//!   file, case-insensitively if the exact path does not exist) into [`MeshInfo::materials`]
//!   (docs/TEXTURES.md).
//! * **STL** (`.stl`): binary and ASCII; the facet normal is ignored.
//! * **glTF 2.0** (`.gltf` with external or data-URI buffers and images, `.glb`) through the
//!   `gltf` crate: the default scene's triangle primitives with their node transforms,
//!   `COLOR_0` times `baseColorFactor`, `baseColorTexture` and the materials by name.
//!
//! Memory: binary PLY and binary STL are memory-mapped and vertices are read in place —
//! memory use does not grow with the mesh. An input truncated while it is mapped ends the
//! process with a message naming it and exit status [`TRUNCATED_EXIT`], not a bare SIGBUS
//! (the first map installs a SIGBUS handler for the process). ASCII and gzip PLY can only be read front to back,
//! so their vertices are parsed into a compact array (12 bytes per vertex, +12 with normals,
//! +4 with colours): O(vertices) memory, freed when [`MeshSource::stream`] returns. ASCII
//! STL needs no vertex array. OBJ is loaded whole by `tobj`: O(file size) memory.
//!
//! [`MeshSource::stream_prepared`] runs a caller's step on each batch on the thread that
//! decoded it (in parallel, for a memory-mapped binary PLY) before the callback gets it.
//!
//! Triangles of exactly zero area (repeated vertex index or [`Triangle::is_degenerate`]) are
//! skipped and counted in [`IngestStats`]. NaN or infinite vertex coordinates are refused
//! with an error naming the vertex.
//!
//! ```
//! use voxlod_ingest::MeshSource;
//! let dir = std::env::temp_dir().join(format!("voxlod-ingest-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("quad.ply");
//! std::fs::write(&path, "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
//!     property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
//!     end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n").unwrap();
//!
//! let mesh = MeshSource::open(&path).unwrap();
//! assert_eq!(mesh.info().format, "ply ascii");
//! let mut tris = Vec::new();
//! let stats = mesh
//!     .stream(&mut |batch| { tris.extend_from_slice(batch); Ok(()) }, &mut |_done, _total| {})
//!     .unwrap();
//! assert_eq!((stats.polygons, stats.triangles), (1, 2)); // the quad is fanned from corner 0
//! assert_eq!(tris[1].v, [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]);
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

mod batch;
mod bounds;
mod error;
mod gltf;
mod gltf_check;
mod gltf_data;
mod map_guard;
mod obj;
mod ply;
mod ply_face_data;
mod ply_faces;
mod ply_header;
mod ply_materials;
mod ply_records;
mod ply_vertices;
mod refs;
mod stl;
mod texpath;

pub use batch::BATCH;
pub use error::{IngestError, Location};
pub use map_guard::TRUNCATED_EXIT;

use std::io::Read;
use std::path::{Path, PathBuf};
use voxlod_geom::{Bounds, Material, Triangle};

/// What [`MeshSource::open`] learnt about a mesh before reading its body.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MeshInfo {
    /// The file, as given.
    pub path: PathBuf,
    /// `"ply ascii"`, `"ply binary_little_endian"`, `"ply binary_big_endian"` (each with
    /// `" (gzip)"` appended for `.ply.gz`), `"obj"`, `"stl binary"` or `"stl ascii"`.
    pub format: String,
    /// Vertex count as declared (PLY) or read (OBJ `v` lines); 3 per facet for binary STL,
    /// 0 for ASCII STL (unknown before reading).
    pub vertices: u64,
    /// Polygon count as declared (PLY `face` elements; `tristrips` not counted), OBJ `f`
    /// lines, binary STL facets; 0 for ASCII STL.
    pub faces: u64,
    /// Triangles carry vertex normals (`TRI_HAS_NORMALS`).
    pub has_normals: bool,
    /// Triangles carry vertex or material colours (`TRI_HAS_COLORS`), for at least some.
    pub has_colors: bool,
    /// Triangles carry texture coordinates (`TRI_HAS_UV`), for at least some.
    pub has_texcoords: bool,
    /// The material table [`voxlod_geom::Triangle::material`] indexes: entry 0 is "no
    /// material", then every material faces use (OBJ `usemtl`), with its texture if it has a
    /// usable one. Empty for a mesh with at most one material and no texture: then every
    /// material index is 0. Its names become the manifest's `"materials"` (FORMAT.md 14.3).
    pub materials: Vec<Material>,
    /// Things that did not stop reading but the user should know (missing MTL file,
    /// ignored partial normals, trailing bytes, no faces).
    pub warnings: Vec<String>,
    /// The up axis the format defines, if it defines one (glTF: `+Y`); the build's manifest
    /// gives it to `render` as `input.up`.
    pub up: Option<[f32; 3]>,
    /// Bytes of memory the reader holds from opening to streaming, at most (the file, its
    /// parsed document, its buffers and the decoding of one primitive, for glTF); counted
    /// against [`ReadOptions::memory`] before they are read. 0 for the other formats, which
    /// map the file or hold O(vertices) ([`MeshSource::stream`]).
    pub held: u64,
}

/// How [`MeshSource::open_with`] reads the files a mesh refers to (OBJ `mtllib` and `map_Kd`,
/// PLY `comment TextureFile`, glTF buffer and image URIs).
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Folders besides the mesh's own that referenced files may lie in. A referenced file is
    /// read only if, after resolving symlinks, it lies inside the mesh's folder or one of
    /// these; otherwise it is refused (a warning for a texture or MTL, an error for a glTF
    /// buffer) with a message that names it and says how to allow it.
    pub allow: Vec<PathBuf>,
    /// The most memory the reader may hold ([`MeshInfo::held`]), if bounded: a glTF file whose
    /// document, buffers or decoding would need more is refused before that part is read,
    /// naming each part and the limit.
    pub memory: Option<u64>,
}

/// Counts of one [`MeshSource::stream`] run.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct IngestStats {
    /// Triangles handed to the callback.
    pub triangles: u64,
    /// Triangles of exactly zero area that were skipped (includes `repeated_index`).
    pub degenerate_skipped: u64,
    /// Polygons read (PLY face records, OBJ `f` lines, STL facets).
    pub polygons: u64,
    /// The part of `degenerate_skipped` whose corners repeat a vertex index (what
    /// `meshstat.py` counts as degenerate); the rest have distinct indices but zero area.
    pub repeated_index: u64,
}

/// A part of the input's face records that can be read on its own
/// ([`MeshSource::face_parts`]): its records and where they lie in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FacePart {
    /// First record and the record after the last.
    pub records: [u64; 2],
    /// Byte offsets in the file of the first record and of the end of the last.
    pub bytes: [u64; 2],
}

enum Reader {
    Gltf(Box<gltf::GltfSource>),
    Ply(ply::PlySource),
    Obj(obj::ObjSource),
    Stl(stl::StlSource),
}

/// An opened mesh file, ready to stream its triangles (any number of times).
pub struct MeshSource {
    info: MeshInfo,
    reader: Reader,
    file_len: u64,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Format {
    Gltf,
    Ply { gz: bool },
    Obj,
    Stl,
}

fn detect(path: &Path, head: &[u8], len: u64) -> Result<Format, IngestError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let gz = head.starts_with(&[0x1f, 0x8b]);
    let starts_ply = head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n");
    let unknown = |reason: String| {
        Err(IngestError::UnknownFormat {
            path: path.to_path_buf(),
            reason,
        })
    };
    if name.ends_with(".ply") || name.ends_with(".ply.gz") {
        // the header parser reports a file that is neither gzip nor starts with "ply"
        return Ok(Format::Ply { gz });
    }
    if name.ends_with(".gltf") || name.ends_with(".glb") || head.starts_with(b"glTF") {
        return Ok(Format::Gltf);
    }
    if name.ends_with(".obj.gz") || name.ends_with(".stl.gz") {
        return unknown("gzip-compressed OBJ/STL is not supported; decompress it first".into());
    }
    if name.ends_with(".obj") || name.ends_with(".stl") {
        if gz {
            return unknown("gzip-compressed OBJ/STL is not supported; decompress it first".into());
        }
        return Ok(if name.ends_with(".obj") {
            Format::Obj
        } else {
            Format::Stl
        });
    }
    if starts_ply || (gz && ply::gz_holds_ply(path)) {
        return Ok(Format::Ply { gz });
    }
    if stl::is_ascii_stl(head, len)
        || (head.len() >= 84
            && len == 84 + 50 * u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64)
    {
        return Ok(Format::Stl);
    }
    unknown(format!(
        "the extension of {} is not .ply, .ply.gz, .obj, .stl, .gltf or .glb, and the content is not PLY, STL or GLB",
        crate::error::quoted(&name)
    ))
}

/// An upper bound of the memory that parsing a glTF JSON text takes beside the text (the
/// checks' tree, then the `gltf` crate's document), bytes: the part of [`MeshInfo::held`]
/// counted for the document before it is parsed.
pub fn gltf_document_bound(json: &[u8]) -> u64 {
    gltf_check::document_bound(json)
}

impl MeshSource {
    /// Opens a mesh: detects the format by extension (and magic bytes) and reads the header
    /// (PLY), the counts (OBJ: one pass over the file) or the facet count (binary STL). Files
    /// the mesh refers to are read only inside its folder ([`MeshSource::open_with`] allows
    /// more).
    pub fn open(path: &Path) -> Result<MeshSource, IngestError> {
        Self::open_with(path, &ReadOptions::default())
    }

    /// [`MeshSource::open`] with the files the mesh refers to read as `opts` says.
    pub fn open_with(path: &Path, opts: &ReadOptions) -> Result<MeshSource, IngestError> {
        let scope = refs::Scope::new(path, &opts.allow);
        let meta = std::fs::metadata(path).map_err(|e| IngestError::io(path, e))?;
        // A mesh is read more than once (header, then passes) and its size sets the plan: a
        // directory, device (/dev/zero) or FIFO cannot be, and has no meaningful size.
        if !meta.is_file() {
            let what = if meta.is_dir() {
                "a directory"
            } else {
                use std::os::unix::fs::FileTypeExt;
                let t = meta.file_type();
                if t.is_fifo() {
                    "a FIFO (named pipe)"
                } else if t.is_char_device() || t.is_block_device() {
                    "a device"
                } else {
                    "not a regular file"
                }
            };
            return Err(IngestError::NotAFile {
                path: path.to_path_buf(),
                what,
            });
        }
        let file_len = meta.len();
        if file_len == 0 {
            return Err(IngestError::Empty {
                path: path.to_path_buf(),
            });
        }
        let mut head = Vec::with_capacity(512);
        std::fs::File::open(path)
            .and_then(|f| f.take(512).read_to_end(&mut head))
            .map_err(|e| IngestError::io(path, e))?;
        let (reader, info) = match detect(path, &head, file_len)? {
            Format::Ply { gz } => {
                let (s, i) = ply::PlySource::open(path, gz, file_len, &scope)?;
                (Reader::Ply(s), i)
            }
            Format::Obj => {
                let (s, i) = obj::ObjSource::open(path, &scope)?;
                (Reader::Obj(s), i)
            }
            Format::Gltf => {
                let (s, i) = gltf::GltfSource::open(path, &scope, opts.memory)?;
                (Reader::Gltf(Box::new(s)), i)
            }
            Format::Stl => {
                let (s, i) = stl::StlSource::open(path, &head, file_len)?;
                (Reader::Stl(s), i)
            }
        };
        Ok(MeshSource {
            info,
            reader,
            file_len,
        })
    }

    /// What was learnt from the header (format, counts, properties).
    pub fn info(&self) -> &MeshInfo {
        &self.info
    }

    /// True if streaming the mesh again costs about as much as reading a copy of its triangles
    /// from disk would: the input is a memory-mapped binary PLY or binary STL, decoded in place
    /// with no vertex array built in memory. A tiler can then pass over the input several times
    /// instead of spooling it.
    pub fn rereadable(&self) -> bool {
        match &self.reader {
            Reader::Ply(p) => p.is_mapped(),
            Reader::Stl(s) => s.is_mapped(),
            Reader::Obj(_) | Reader::Gltf(_) => false,
        }
    }

    /// The bounds of all vertex positions, if they can be read cheaply before the faces (a
    /// memory-mapped binary PLY with fixed-size vertex records: its vertex list; a binary STL:
    /// every facet corner), all of them finite; `None` otherwise. The bounds of the streamed
    /// triangles lie inside it, and equal it when every vertex is used by a non-degenerate
    /// triangle (the usual case): a caller can then set up what depends on the bounds (the
    /// grid) before the first pass.
    pub fn vertex_bounds(&self) -> Option<Bounds> {
        match &self.reader {
            Reader::Ply(p) => p.vertex_bounds(),
            Reader::Stl(s) => s.vertex_bounds(),
            Reader::Obj(_) | Reader::Gltf(_) => None,
        }
    }

    /// Streams every triangle in file order, in batches of up to [`BATCH`] triangles,
    /// calling `f` per batch. Degenerate triangles (exactly zero area) are skipped and
    /// counted. `progress(bytes_done, bytes_total)` is called after each batch (input bytes;
    /// compressed bytes for gzip; a two-pass read counts the file twice). Stops with the
    /// first error, including one returned by `f`.
    pub fn stream(
        &self,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), IngestError>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<IngestStats, IngestError> {
        self.stream_prepared(&|_| (), &mut |tris, ()| f(tris), progress)
    }

    /// [`MeshSource::stream`] with a step `prepare` run on each batch before `f`, on the thread
    /// that decoded the batch: for a memory-mapped binary PLY, a worker of the current rayon
    /// pool, while `f` takes the batch before on the calling thread; for the other readers,
    /// the calling thread. `prepare` may change the triangles (`f` sees them changed) and
    /// returns what `f` gets with them: work that does not depend on the order of the batches
    /// belongs in `prepare`, so that it runs in parallel with `f`.
    ///
    /// ```no_run
    /// # fn main() -> Result<(), voxlod_ingest::IngestError> {
    /// // the bounds of each batch on the workers; their union on the calling thread
    /// let src = voxlod_ingest::MeshSource::open(std::path::Path::new("scan.ply"))?;
    /// let mut bounds = voxlod_geom::Bounds::default();
    /// src.stream_prepared(
    ///     &|tris| {
    ///         let mut b = voxlod_geom::Bounds::default();
    ///         tris.iter().for_each(|t| b.add_triangle(t));
    ///         b
    ///     },
    ///     &mut |_tris, b| Ok(bounds.merge(&b)),
    ///     &mut |_, _| {},
    /// )?;
    /// # Ok(()) }
    /// ```
    pub fn stream_prepared<P: Send + 'static>(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> P + Sync),
        f: &mut dyn FnMut(&[Triangle], P) -> Result<(), IngestError>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<IngestStats, IngestError> {
        self.stream_some(None, prepare, f, progress)
    }

    /// The face records cut into `n` parts of consecutive records that can each be streamed
    /// on its own ([`MeshSource::stream_part_prepared`]) without reading the others' bytes, if
    /// the input allows it: a memory-mapped binary PLY with fixed-size vertex records and one
    /// face element of triangle records of one size, the file's last element. `None` for any
    /// other input (a part would have to read the faces before it).
    pub fn face_parts(&self, n: u64) -> Option<Vec<FacePart>> {
        match &self.reader {
            Reader::Ply(p) => p.face_parts(n),
            Reader::Obj(_) | Reader::Gltf(_) | Reader::Stl(_) => None,
        }
    }

    /// What part `part` of [`MeshSource::face_parts`] reads besides its face records: the
    /// indices of the pages of `page` bytes (a power of two; counted from byte 0 of the file, up to the first
    /// face record) that hold the file's header and the elements before the vertex list, or a
    /// vertex record that one of the part's face records names (an index out of range names
    /// none: the stream reports it). `faces` is handed the part's face record bytes, in order,
    /// as they are read. `None` for an input that cannot be cut into parts.
    pub fn part_footprint(
        &self,
        part: &FacePart,
        page: u64,
        faces: &mut dyn FnMut(&[u8]),
    ) -> Option<Vec<u64>> {
        match &self.reader {
            Reader::Ply(p) => p.part_footprint(part, page, faces),
            Reader::Obj(_) | Reader::Gltf(_) | Reader::Stl(_) => None,
        }
    }

    /// The whole file's bytes as mapped, for a memory-mapped binary PLY (the input of
    /// [`MeshSource::face_parts`]); `None` otherwise. Touching them makes them resident:
    /// [`MeshSource::release_pages`] after.
    pub fn mapped_bytes(&self) -> Option<&[u8]> {
        match &self.reader {
            Reader::Ply(p) => p.mapped_bytes(),
            Reader::Obj(_) | Reader::Gltf(_) | Reader::Stl(_) => None,
        }
    }

    /// For a sample of scattered records (the plan's): `true` reads a memory-mapped PLY without
    /// readahead, `false` with it again. Nothing for other inputs.
    pub fn advise_random(&self, random: bool) {
        if let Reader::Ply(p) = &self.reader {
            p.advise_random(random);
        }
    }

    /// Drops this process's resident pages of a memory-mapped input (they stay in the page
    /// cache): for a caller that reads many small parts, between which the streams' own
    /// release (every few thousand triangles) never comes. Nothing for other inputs.
    pub fn release_pages(&self) {
        match &self.reader {
            Reader::Ply(p) => p.release_pages(),
            Reader::Stl(s) => s.release_pages(),
            Reader::Obj(_) | Reader::Gltf(_) => {}
        }
    }

    /// [`MeshSource::stream_prepared`] over the triangles of one part of
    /// [`MeshSource::face_parts`] only: the same triangles, in the same order, as those records
    /// give in a whole stream. Only that part's records and the vertices they use are read.
    pub fn stream_part_prepared<P: Send + 'static>(
        &self,
        part: &FacePart,
        prepare: &(dyn Fn(&mut [Triangle]) -> P + Sync),
        f: &mut dyn FnMut(&[Triangle], P) -> Result<(), IngestError>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<IngestStats, IngestError> {
        assert!(
            matches!(&self.reader, Reader::Ply(p) if p.is_mapped()),
            "parts are cut from memory-mapped PLY files only"
        );
        self.stream_some(Some(part), prepare, f, progress)
    }

    /// The number of face records if they are fixed-size triangle records that can be found
    /// by index (the input of [`MeshSource::face_parts`]: a memory-mapped binary PLY with
    /// fixed-size vertex records and one face element, the last, of triangle records of one
    /// size that fill the file): then [`MeshSource::stream_indexed_prepared`] gives each
    /// triangle's face record and [`MeshSource::triangles_at`] the triangles of records.
    /// `None` for any other input.
    pub fn fixed_face_count(&self) -> Option<u64> {
        match &self.reader {
            Reader::Ply(p) => p.fixed_face_count(),
            Reader::Obj(_) | Reader::Gltf(_) | Reader::Stl(_) => None,
        }
    }

    /// [`MeshSource::stream_prepared`] that also gives `f` the face record of each triangle of
    /// the batch (a face record holds one triangle, or none if it is degenerate), for an input
    /// with [`MeshSource::fixed_face_count`]. The same triangles, counts and errors as
    /// [`MeshSource::stream_prepared`], except that a face record found not to be a triangle
    /// record of the fixed size stops the stream with [`IngestError::NotFixedRecords`] (the
    /// caller then streams the general way).
    pub fn stream_indexed_prepared<P: Send + 'static>(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> P + Sync),
        f: &mut dyn FnMut(&[Triangle], &[u64], P) -> Result<(), IngestError>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<IngestStats, IngestError> {
        let Reader::Ply(p) = &self.reader else {
            panic!("triangles with their face records from fixed-size PLY face records only");
        };
        assert!(p.fixed_face_count().is_some(), "fixed-size face records");
        let release = || p.release_pages();
        let erased = |tris: &mut [Triangle]| -> batch::Prepared { Box::new(prepare(tris)) };
        let mut g = |tris: &[Triangle], faces: &[u64], prep: batch::Prepared| {
            assert_eq!(
                faces.len(),
                tris.len(),
                "every triangle has its face record"
            );
            let prep = prep
                .downcast::<P>()
                .expect("the emitter hands on what prepare returned");
            f(tris, faces, *prep)
        };
        let mut em = batch::Emitter::new(&erased, &mut g, progress, p.progress_total())
            .with_release(Some(&release));
        p.stream_indexed(&mut em)?;
        em.finish()
    }

    /// Appends to `out` the triangle of each face record of `faces` (records
    /// [`MeshSource::stream_indexed_prepared`] gave; an input with
    /// [`MeshSource::fixed_face_count`]): bit for bit the triangle the stream gave for it, by
    /// the same decode. A record that is no longer a non-degenerate triangle (the input
    /// changed) is [`IngestError::FaceChanged`]. May be called from several threads at once.
    pub fn triangles_at(&self, faces: &[u64], out: &mut Vec<Triangle>) -> Result<(), IngestError> {
        match &self.reader {
            Reader::Ply(p) => p.triangles_at(faces, out),
            Reader::Obj(_) | Reader::Gltf(_) | Reader::Stl(_) => {
                panic!("triangles by face record from fixed-size PLY face records only")
            }
        }
    }

    /// A stream of every triangle, or of `part`'s.
    fn stream_some<P: Send + 'static>(
        &self,
        part: Option<&FacePart>,
        prepare: &(dyn Fn(&mut [Triangle]) -> P + Sync),
        f: &mut dyn FnMut(&[Triangle], P) -> Result<(), IngestError>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<IngestStats, IngestError> {
        let total = match &self.reader {
            Reader::Ply(p) => p.progress_total(),
            _ => self.file_len,
        };
        let release = || self.release_pages();
        let erased = |tris: &mut [Triangle]| -> batch::Prepared { Box::new(prepare(tris)) };
        let mut g = |tris: &[Triangle], _: &[u64], p: batch::Prepared| {
            let p = p
                .downcast::<P>()
                .expect("the emitter hands on what prepare returned");
            f(tris, *p)
        };
        let mut em =
            batch::Emitter::new(&erased, &mut g, progress, total).with_release(Some(&release));
        match (&self.reader, part) {
            (Reader::Ply(p), Some(part)) => p.stream_part(part, &mut em)?,
            (_, Some(_)) => unreachable!("checked by stream_part_prepared"),
            (Reader::Ply(p), None) => p.stream(&mut em)?,
            (Reader::Obj(o), None) => o.stream(&mut em)?,
            (Reader::Gltf(g), None) => g.stream(&mut em)?,
            (Reader::Stl(s), None) => s.stream(&mut em)?,
        }
        em.finish()
    }
}
