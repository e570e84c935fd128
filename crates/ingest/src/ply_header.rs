//! PLY header parsing (Greg Turk, "The PLY Polygon File Format", 1994) and the layout the
//! readers need from it: which element holds the vertices, which property is x, y, z, the
//! normal and the colour, and which elements hold faces or triangle strips.

use crate::error::quoted;
use crate::IngestError;
use std::io::{BufRead, Read};
use std::path::Path;

/// Longest header we accept; a file without `end_header` in its first MiB is not PLY.
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    /// Bytes in binary encodings.
    #[inline]
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    /// The values an integer type holds (`None` for floats).
    pub fn int_range(self) -> Option<std::ops::RangeInclusive<i64>> {
        Some(match self {
            Scalar::I8 => i8::MIN as i64..=i8::MAX as i64,
            Scalar::U8 => 0..=u8::MAX as i64,
            Scalar::I16 => i16::MIN as i64..=i16::MAX as i64,
            Scalar::U16 => 0..=u16::MAX as i64,
            Scalar::I32 => i32::MIN as i64..=i32::MAX as i64,
            Scalar::U32 => 0..=u32::MAX as i64,
            Scalar::F32 | Scalar::F64 => return None,
        })
    }
    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
    pub fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

impl Encoding {
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLe => "binary_little_endian",
            Encoding::BinaryBe => "binary_big_endian",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
pub(crate) struct Property {
    pub name: String,
    pub kind: Kind,
}

#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub name: String,
    pub count: u64,
    pub props: Vec<Property>,
    /// What a `face` element's records carry besides the vertex indices (empty otherwise).
    pub data: FaceData,
}

impl Element {
    /// Bytes per record in binary encodings, if no property is a list.
    pub fn fixed_size(&self) -> Option<usize> {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => Some(s.size()),
                Kind::List { .. } => None,
            })
            .sum()
    }
}

impl Element {
    /// The fewest bytes a record can take: binary, a scalar's size and a list's count (the
    /// list may be empty); ASCII, two characters per value (a digit and a separator).
    pub fn min_record_bytes(&self, ascii: bool) -> u64 {
        self.props
            .iter()
            .map(|p| match (ascii, p.kind) {
                (true, _) => 2,
                (false, Kind::Scalar(s)) => s.size() as u64,
                (false, Kind::List { count, .. }) => count.size() as u64,
            })
            .sum()
    }
}

/// What each vertex property means to us.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Role {
    /// Position (0..3), normal (3..6), colour (6..10: r, g, b, a), texture coordinates
    /// (10..12: u, v).
    Attr(usize),
    Skip,
}

/// Per-face data of a `face` element (docs/INGEST.md "Per-face data"): property indices of
/// the material key, the colour channels and the texture coordinate list, and the material
/// table's lookup once the file's values are known (`ply_materials.rs`).
#[derive(Clone, Debug, Default)]
pub(crate) struct FaceData {
    /// The property whose value selects the material (`material`, `material_index`, or
    /// `texnumber` with `comment TextureFile`), and its type.
    pub key: Option<(usize, Scalar)>,
    /// `red green blue [alpha]` of the face (used only without vertex colours).
    pub color: [Option<(usize, Scalar)>; 4],
    /// The `texcoord` list: two floats per corner.
    pub texcoord: Option<usize>,
    /// The key values in the material table, sorted: value `keys[i]` is material `i + 1`;
    /// other values are material 0.
    pub keys: Vec<i64>,
}

impl FaceData {
    /// True if the records carry anything the face reader must decode besides the indices.
    pub fn any(&self) -> bool {
        self.key.is_some() || self.color[0].is_some() || self.texcoord.is_some()
    }

    /// The material of key value `v`.
    #[inline]
    pub fn material(&self, v: i64) -> u32 {
        self.keys.binary_search(&v).map_or(0, |i| i as u32 + 1)
    }
}

/// Which elements and properties carry the mesh.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// Index of the `vertex` element.
    pub vertex: usize,
    /// Role of each vertex property, in property order.
    pub roles: Vec<Role>,
    pub has_normals: bool,
    pub has_colors: bool,
    /// The vertices have texture coordinates (u and v under one of their names).
    pub has_texcoords: bool,
    /// Elements that yield triangles, in file order: (element index, index of the vertex
    /// index list property, true for triangle strips).
    pub sources: Vec<(usize, usize, bool)>,
}

#[derive(Clone, Debug)]
pub(crate) struct Header {
    pub encoding: Encoding,
    pub elements: Vec<Element>,
    /// Bytes up to and including the `end_header` line (in the decompressed stream for gzip).
    pub bytes: u64,
    /// Lines up to and including `end_header`.
    pub lines: u64,
    pub layout: Layout,
    /// The text of each `comment` line, after the keyword (material names, `TextureFile`).
    pub comments: Vec<String>,
}

/// Reads the header from `r`, leaving `r` at the first body byte.
pub(crate) fn parse_header(path: &Path, r: &mut dyn BufRead) -> Result<Header, IngestError> {
    // The header grammar, line by line: one match over the keywords.
    let herr = |line: u64, message: String| IngestError::Header {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut buf = Vec::new();
    let mut bytes = 0u64;
    let mut line_no = 0u64;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    loop {
        buf.clear();
        let n = (&mut *r)
            .take(MAX_HEADER_BYTES + 1 - bytes)
            .read_until(b'\n', &mut buf)
            .map_err(|e| IngestError::io(path, e))?;
        line_no += 1;
        bytes += n as u64;
        if n == 0 || buf.last() != Some(&b'\n') {
            let why = if bytes > MAX_HEADER_BYTES {
                format!("no end_header within the first {MAX_HEADER_BYTES} bytes")
            } else {
                "the file ends inside the header (no end_header line)".to_string()
            };
            return Err(herr(line_no, why));
        }
        let text = String::from_utf8_lossy(&buf);
        let toks: Vec<&str> = text.split_ascii_whitespace().collect();
        if line_no == 1 {
            if toks != ["ply"] {
                return Err(herr(
                    1,
                    format!("the first line is {}, not \"ply\"", quoted(text.trim_end())),
                ));
            }
            continue;
        }
        match toks.first().copied() {
            None => continue,
            Some("comment") => {
                let rest = text.trim_start().strip_prefix("comment").unwrap_or("");
                comments.push(rest.trim().to_string());
                continue;
            }
            Some("obj_info") => continue,
            Some("format") => {
                if toks.len() != 3 {
                    return Err(herr(line_no, "expected \"format <encoding> 1.0\"".into()));
                }
                encoding = Some(match toks[1] {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLe,
                    "binary_big_endian" => Encoding::BinaryBe,
                    other => {
                        return Err(herr(line_no, format!("unknown encoding {}", quoted(other))))
                    }
                });
                if toks[2] != "1.0" {
                    return Err(herr(
                        line_no,
                        format!("unsupported PLY version {}", quoted(toks[2])),
                    ));
                }
            }
            Some("element") => {
                if toks.len() != 3 {
                    return Err(herr(line_no, "expected \"element <name> <count>\"".into()));
                }
                let count = toks[2].parse::<u64>().map_err(|_| {
                    herr(
                        line_no,
                        format!(
                            "element count {} is not a non-negative integer",
                            quoted(toks[2])
                        ),
                    )
                })?;
                elements.push(Element {
                    name: toks[1].to_string(),
                    count,
                    props: Vec::new(),
                    data: FaceData::default(),
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(herr(line_no, "property before any element".into()));
                };
                let ty = |name: &str| {
                    Scalar::parse(name).ok_or_else(|| {
                        herr(line_no, format!("unknown property type {}", quoted(name)))
                    })
                };
                let prop = match toks.get(1).copied() {
                    Some("list") if toks.len() == 5 => {
                        let count = ty(toks[2])?;
                        if count.is_float() {
                            return Err(herr(line_no, format!("list count type {} is not an integer type", toks[2])));
                        }
                        Property { name: toks[4].to_string(), kind: Kind::List { count, item: ty(toks[3])? } }
                    }
                    Some(t) if t != "list" && toks.len() == 3 => {
                        Property { name: toks[2].to_string(), kind: Kind::Scalar(ty(t)?) }
                    }
                    _ => {
                        return Err(herr(
                            line_no,
                            "expected \"property <type> <name>\" or \"property list <count type> <item type> <name>\""
                                .into(),
                        ))
                    }
                };
                el.props.push(prop);
            }
            Some("end_header") => break,
            Some(other) => {
                return Err(herr(
                    line_no,
                    format!("unknown header keyword {}", quoted(other)),
                ))
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(herr(line_no, "no format line before end_header".into()));
    };
    let layout = layout(&mut elements).map_err(|m| herr(line_no, m))?;
    Ok(Header {
        encoding,
        elements,
        bytes,
        lines: line_no,
        layout,
        comments,
    })
}

/// Finds the vertex attributes and the triangle-bearing elements.
fn layout(elements: &mut [Element]) -> Result<Layout, String> {
    let vertex = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| "no \"vertex\" element".to_string())?;
    let vel = &elements[vertex];
    let mut roles = Vec::with_capacity(vel.props.len());
    let mut found = [false; 12];
    for p in &vel.props {
        let slot = match p.name.as_str() {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            "nx" => Some(3),
            "ny" => Some(4),
            "nz" => Some(5),
            "red" | "diffuse_red" | "r" => Some(6),
            "green" | "diffuse_green" | "g" => Some(7),
            "blue" | "diffuse_blue" | "b" => Some(8),
            "alpha" | "diffuse_alpha" | "a" => Some(9),
            "u" | "s" | "texture_u" | "texture_s" => Some(10),
            "v" | "t" | "texture_v" | "texture_t" => Some(11),
            _ => None,
        };
        match (slot, p.kind) {
            (Some(s), Kind::Scalar(_)) if !found[s] => {
                found[s] = true;
                roles.push(Role::Attr(s));
            }
            (Some(s), Kind::List { .. }) if s < 3 => {
                return Err(format!(
                    "vertex property {} is a list, expected a scalar",
                    quoted(&p.name)
                ));
            }
            _ => roles.push(Role::Skip),
        }
    }
    if !(found[0] && found[1] && found[2]) {
        return Err("the vertex element lacks one of the scalar properties x, y, z".into());
    }
    let has_normals = found[3] && found[4] && found[5];
    let has_colors = found[6] && found[7] && found[8];
    let has_texcoords = found[10] && found[11];
    // Partial normals, colours or texture coordinates are ignored rather than half-used.
    for r in roles.iter_mut() {
        if let Role::Attr(s) = *r {
            if (3..6).contains(&s) && !has_normals
                || (6..10).contains(&s) && !has_colors
                || (10..12).contains(&s) && !has_texcoords
            {
                *r = Role::Skip;
            }
        }
    }
    let mut sources = Vec::new();
    for (i, e) in elements.iter_mut().enumerate() {
        let strips = match e.name.as_str() {
            "face" => false,
            "tristrips" => true,
            _ => continue,
        };
        let list = e.props.iter().position(|p| {
            matches!(p.kind, Kind::List { .. })
                && (p.name == "vertex_indices" || p.name == "vertex_index")
        });
        let Some(list) = list else {
            return Err(format!(
                "element {} has no list property vertex_indices or vertex_index",
                quoted(&e.name)
            ));
        };
        if let Kind::List { item, .. } = e.props[list].kind {
            if item.is_float() {
                return Err(format!(
                    "{}.{} has float index type {}",
                    e.name,
                    e.props[list].name,
                    item.name()
                ));
            }
        }
        if !strips {
            e.data = face_data(&e.props);
        }
        sources.push((i, list, strips));
    }
    Ok(Layout {
        vertex,
        roles,
        has_normals,
        has_colors,
        has_texcoords,
        sources,
    })
}

/// The per-face properties of a `face` element's records: `material` or `material_index`
/// (an integer), `red green blue [alpha]` (or `diffuse_*`, `r g b a`; all of r, g, b or none
/// are used), the `texcoord` list (floats). `texnumber` is recorded as the key only later,
/// if the header has `TextureFile` comments and no material property (`ply_materials.rs`).
fn face_data(props: &[Property]) -> FaceData {
    let mut d = FaceData::default();
    for (pi, p) in props.iter().enumerate() {
        match (p.name.as_str(), p.kind) {
            ("material" | "material_index", Kind::Scalar(t))
                if !t.is_float() && d.key.is_none() =>
            {
                d.key = Some((pi, t))
            }
            ("texcoord", Kind::List { item, .. }) if item.is_float() && d.texcoord.is_none() => {
                d.texcoord = Some(pi)
            }
            (name, Kind::Scalar(t)) => {
                let ch = match name {
                    "red" | "diffuse_red" | "r" => 0,
                    "green" | "diffuse_green" | "g" => 1,
                    "blue" | "diffuse_blue" | "b" => 2,
                    "alpha" | "diffuse_alpha" | "a" => 3,
                    _ => continue,
                };
                d.color[ch].get_or_insert((pi, t));
            }
            _ => {}
        }
    }
    if d.color[..3].iter().any(|c| c.is_none()) {
        d.color = [None; 4];
    }
    d
}
