//! glTF 2.0 checked before the `gltf` crate's document and readers touch it: the GLB
//! container (header and chunk lengths), UTF-8 JSON, and every buffer, buffer view, accessor,
//! mesh primitive and node against the rules of the specification (Khronos, "glTF 2.0
//! Specification", 2021: 3.6 buffers and accessors, 3.7.2.1 the attribute table, 3.5 nodes,
//! 4.4 GLB). The crate's readers trust what they read (a `byteStride` smaller than the element
//! panics in a slice index, an index accessor of FLOAT type reaches an `unreachable!`, a
//! POSITION of UNSIGNED_BYTE SCALAR is read as FLOAT VEC3), so a file breaking a rule is refused
//! here with the rule it breaks, and the readers only ever see what the rules allow.

use serde_json::Value;

/// `glTF` little-endian, the GLB magic.
const GLB_MAGIC: &[u8; 4] = b"glTF";
/// Chunk type `JSON`.
const CHUNK_JSON: u32 = 0x4E4F_534A;
/// Chunk type `BIN\0`.
const CHUNK_BIN: u32 = 0x004E_4942;

/// The JSON and the binary chunk (if any) of a GLB, or the whole file as JSON for `.gltf`.
#[derive(Debug)]
pub(crate) struct Container<'a> {
    /// The JSON text, checked to be UTF-8.
    pub json: &'a str,
    /// The GLB's binary chunk.
    pub bin: Option<&'a [u8]>,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Splits a GLB (4.4) into its chunks, or takes the whole file as JSON; `Err` is the rule broken.
pub(crate) fn container(bytes: &[u8]) -> Result<Container<'_>, String> {
    let json_bytes: &[u8];
    let mut bin = None;
    if bytes.starts_with(GLB_MAGIC) {
        if bytes.len() < 12 {
            return Err(format!(
                "a GLB header is 12 bytes; the file has {}",
                bytes.len()
            ));
        }
        let version = u32_at(bytes, 4);
        if version != 2 {
            return Err(format!("GLB version {version}; only version 2 is glTF 2.0"));
        }
        let length = u32_at(bytes, 8) as u64;
        if length != bytes.len() as u64 {
            return Err(format!(
                "the GLB header gives the file's length as {length} bytes, but it has {}",
                bytes.len()
            ));
        }
        let mut at = 12usize;
        let mut chunks: Vec<(u32, &[u8])> = Vec::new();
        while at < bytes.len() {
            if bytes.len() - at < 8 {
                return Err(format!(
                    "{} bytes at offset {at} are too few for a GLB chunk header (8 bytes)",
                    bytes.len() - at
                ));
            }
            let len = u32_at(bytes, at) as usize;
            let kind = u32_at(bytes, at + 4);
            let start = at + 8;
            if len > bytes.len() - start {
                return Err(format!(
                    "GLB chunk {} at offset {at} declares {len} bytes, but only {} follow",
                    chunks.len(),
                    bytes.len() - start
                ));
            }
            chunks.push((kind, &bytes[start..start + len]));
            at = start + len;
        }
        match chunks.first() {
            Some(&(CHUNK_JSON, j)) => json_bytes = j,
            _ => return Err("the first GLB chunk must be the JSON chunk".into()),
        }
        if let Some(&(kind, data)) = chunks.get(1) {
            if kind == CHUNK_BIN {
                bin = Some(data);
            }
        }
        if let Some(i) = chunks
            .iter()
            .enumerate()
            .skip(1)
            .find(|(i, c)| c.0 == CHUNK_JSON || (c.0 == CHUNK_BIN && *i != 1))
            .map(|(i, _)| i)
        {
            return Err(format!(
                "GLB chunk {i} is a second JSON chunk or a BIN chunk that is not the second chunk"
            ));
        }
    } else {
        json_bytes = bytes;
    }
    let json = std::str::from_utf8(json_bytes).map_err(|e| {
        format!(
            "the JSON is not valid UTF-8 (byte {} of the JSON text)",
            e.valid_up_to()
        )
    })?;
    Ok(Container { json, bin })
}

// --- the document ---

const BYTE: u64 = 5120;
const UNSIGNED_BYTE: u64 = 5121;
const SHORT: u64 = 5122;
const UNSIGNED_SHORT: u64 = 5123;
const UNSIGNED_INT: u64 = 5125;
const FLOAT: u64 = 5126;
/// Primitive mode TRIANGLES, the default.
const TRIANGLES: u64 = 4;

fn component_name(c: u64) -> &'static str {
    match c {
        BYTE => "BYTE",
        UNSIGNED_BYTE => "UNSIGNED_BYTE",
        SHORT => "SHORT",
        UNSIGNED_SHORT => "UNSIGNED_SHORT",
        UNSIGNED_INT => "UNSIGNED_INT",
        FLOAT => "FLOAT",
        _ => "unknown",
    }
}

fn component_size(c: u64) -> Option<u64> {
    match c {
        BYTE | UNSIGNED_BYTE => Some(1),
        SHORT | UNSIGNED_SHORT => Some(2),
        UNSIGNED_INT | FLOAT => Some(4),
        _ => None,
    }
}

/// Columns and rows of an accessor type.
fn shape(t: &str) -> Option<(u64, u64)> {
    Some(match t {
        "SCALAR" => (1, 1),
        "VEC2" => (1, 2),
        "VEC3" => (1, 3),
        "VEC4" => (1, 4),
        "MAT2" => (2, 2),
        "MAT3" => (3, 3),
        "MAT4" => (4, 4),
        _ => return None,
    })
}

/// The element size of an accessor (3.6.2.4: each matrix column starts at a multiple of 4
/// bytes, so MAT2 and MAT3 of 1- and 2-byte components are padded).
fn element_size(t: &str, c: u64) -> Option<u64> {
    let (cols, rows) = shape(t)?;
    let cs = component_size(c)?;
    let column = rows * cs;
    Some(if cols > 1 {
        cols * column.div_ceil(4) * 4
    } else {
        column
    })
}

/// The most elements an accessor may have: voxlod indexes vertices with 32 bits.
const MAX_COUNT: u64 = u32::MAX as u64;

struct Doc<'a> {
    v: &'a Value,
}

impl<'a> Doc<'a> {
    fn list(&self, key: &str) -> &'a [Value] {
        self.v
            .get(key)
            .and_then(Value::as_array)
            .map_or(&[][..], Vec::as_slice)
    }
}

/// A non-negative integer field; `Ok(None)` if absent.
fn uint(o: &Value, key: &str, what: &str) -> Result<Option<u64>, String> {
    match o.get(key) {
        None => Ok(None),
        Some(x) => x
            .as_u64()
            .map(Some)
            .ok_or_else(|| format!("{what}: {key} is not a non-negative integer ({x})")),
    }
}

fn index(o: &Value, key: &str, what: &str, n: usize, of: &str) -> Result<Option<usize>, String> {
    match uint(o, key, what)? {
        Some(i) if i >= n as u64 => Err(format!(
            "{what}: {key} {i} names {of} {i}, but the file has {n}"
        )),
        i => Ok(i.map(|i| i as usize)),
    }
}

/// What an accessor is, once checked.
#[derive(Clone)]
struct Acc {
    ty: String,
    comp: u64,
    normalized: bool,
    count: u64,
    view: Option<usize>,
}

/// Checks the document's buffers, views, accessors, meshes, nodes and scenes, the buffer
/// without a URI against the GLB's binary chunk (`bin`); `Err` is the rule broken, naming the
/// object.
pub(crate) fn document(json: &str, bin: Option<&[u8]>) -> Result<(), String> {
    let root: Value =
        serde_json::from_str(json).map_err(|e| format!("not a valid glTF 2.0 file: {e}"))?;
    if !root.is_object() {
        return Err("not a valid glTF 2.0 file: the JSON is not an object".into());
    }
    // Compressed geometry first: its accessors and buffers break the rules below on purpose
    // (data that only the extension's decoder makes), and that is not what the user must hear.
    let names = |key: &str| -> Vec<String> {
        let list = root.get(key).and_then(Value::as_array);
        let strings = list.map_or(&[][..], Vec::as_slice).iter();
        strings
            .filter_map(|v| v.as_str().map(str::to_owned))
            .collect()
    };
    let (required, used) = (names("extensionsRequired"), names("extensionsUsed"));
    let compressed = |list: &[String]| {
        list.iter()
            .find(|e| COMPRESSION.iter().any(|(c, _)| c == e))
            .cloned()
    };
    if let Some(ext) = compressed(&required) {
        return Err(format!(
            "the geometry is compressed with {ext} ({}), which voxlod does not decode: \
             decompress the file first (for example with gltf-transform, or by exporting it \
             again from Blender without compression) and build from that",
            COMPRESSION
                .iter()
                .find(|(c, _)| *c == ext)
                .map_or("", |(_, w)| w)
        ));
    }
    let optional = compressed(&used);
    let quantized = used.iter().any(|e| e == "KHR_mesh_quantization");
    rules(&root, bin, quantized).map_err(|rule| match optional {
        Some(ext) => format!(
            "the file uses {ext} (compressed geometry, which voxlod does not decode) and its \
             uncompressed fallback is broken; decompress the file first (for example with \
             gltf-transform): {rule}"
        ),
        None => rule,
    })
}

/// Geometry compression extensions voxlod does not decode (name, what they are): a file
/// requiring one holds its vertices only in the compressed form. (meshoptimizer's,
/// `EXT_meshopt_compression` and `KHR_meshopt_compression`, are decoded: `gltf_data`.)
const COMPRESSION: [(&str, &str); 1] = [("KHR_draco_mesh_compression", "Draco")];

/// Whether buffer `b` is a fallback buffer of meshopt compression (no data of its own: its
/// views are decoded from another buffer).
fn meshopt_fallback(b: &Value) -> bool {
    crate::gltf_data::MESHOPT.iter().any(|ext| {
        b.get("extensions")
            .and_then(|e| e.get(ext))
            .and_then(|e| e.get("fallback"))
            .and_then(Value::as_bool)
            == Some(true)
    })
}

/// The rules of [`document`] after the compression check; `quantized`: the file uses
/// `KHR_mesh_quantization`, which widens the attribute table.
fn rules(root: &Value, bin: Option<&[u8]>, quantized: bool) -> Result<(), String> {
    let d = Doc { v: root };
    let mut buffer_len = Vec::new();
    for (i, b) in d.list("buffers").iter().enumerate() {
        let what = format!("buffer {i}");
        let len =
            uint(b, "byteLength", &what)?.ok_or_else(|| format!("{what} has no byteLength"))?;
        if len == 0 {
            return Err(format!("{what}: byteLength must be at least 1"));
        }
        if b.get("uri").is_none() && !meshopt_fallback(b) {
            // 4.4.3.3: only the first buffer may be the GLB's binary chunk, which may be up to
            // 3 bytes longer (padding)
            match bin {
                Some(data) if i == 0 && (data.len() as u64) >= len => {}
                Some(data) if i == 0 => {
                    return Err(format!(
                        "{what} declares {len} bytes, but the GLB's binary chunk has {}",
                        data.len()
                    ))
                }
                _ => {
                    return Err(format!(
                        "{what} has no uri, but it is not the first buffer of a GLB with a binary chunk"
                    ))
                }
            }
        }
        buffer_len.push(len);
    }
    // (length, stride) of each buffer view
    let mut views: Vec<(u64, Option<u64>)> = Vec::new();
    for (i, v) in d.list("bufferViews").iter().enumerate() {
        let what = format!("bufferView {i}");
        let b = index(v, "buffer", &what, buffer_len.len(), "buffer")?
            .ok_or_else(|| format!("{what} has no buffer"))?;
        let off = uint(v, "byteOffset", &what)?.unwrap_or(0);
        let len =
            uint(v, "byteLength", &what)?.ok_or_else(|| format!("{what} has no byteLength"))?;
        if len == 0 {
            return Err(format!("{what}: byteLength must be at least 1"));
        }
        if off.checked_add(len).is_none_or(|e| e > buffer_len[b]) {
            return Err(format!(
                "{what}: bytes {off}..{off}+{len} lie outside buffer {b} ({} bytes)",
                buffer_len[b]
            ));
        }
        let stride = uint(v, "byteStride", &what)?;
        if let Some(s) = stride {
            if !(4..=252).contains(&s) || s % 4 != 0 {
                return Err(format!(
                    "{what}: byteStride {s} is not a multiple of 4 from 4 to 252"
                ));
            }
        }
        views.push((len, stride));
    }
    // 3.9.1: an image has a uri or a bufferView (then also a mimeType), not both
    for (i, im) in d.list("images").iter().enumerate() {
        let what = format!("image {i}");
        index(im, "bufferView", &what, views.len(), "bufferView")?;
        match (im.get("uri").is_some(), im.get("bufferView").is_some()) {
            (true, true) => return Err(format!("{what} has both a uri and a bufferView")),
            (false, false) => return Err(format!("{what} has neither a uri nor a bufferView")),
            (false, true) if im.get("mimeType").and_then(Value::as_str).is_none() => {
                return Err(format!("{what} is in a bufferView but has no mimeType"))
            }
            _ => {}
        }
    }
    let mut accs = Vec::new();
    for (i, a) in d.list("accessors").iter().enumerate() {
        accs.push(accessor(a, i, &views)?);
    }
    let view_stride = |v: Option<usize>| v.and_then(|v| views[v].1);
    for (mi, m) in d.list("meshes").iter().enumerate() {
        let prims = m.get("primitives").and_then(Value::as_array);
        for (pi, p) in prims.map_or(&[][..], Vec::as_slice).iter().enumerate() {
            let what = format!("mesh {mi} primitive {pi}");
            let mut count = None;
            if let Some(attrs) = p.get("attributes").and_then(Value::as_object) {
                for (name, x) in attrs {
                    let ai = x
                        .as_u64()
                        .filter(|&k| k < accs.len() as u64)
                        .ok_or_else(|| {
                            format!("{what}: attribute {name} names no accessor ({x})")
                        })? as usize;
                    let a = &accs[ai];
                    attribute(name, a, quantized).map_err(|rule| {
                        format!("{what}: attribute {name} (accessor {ai}): {rule}")
                    })?;
                    match count {
                        None => count = Some((name.clone(), a.count)),
                        Some((ref first, n)) if n != a.count => {
                            return Err(format!(
                                "{what}: attribute {name} has {} elements but {first} has {n}; all attributes of a primitive must have the same count",
                                a.count
                            ))
                        }
                        _ => {}
                    }
                }
            }
            if let Some(ii) = index(p, "indices", &what, accs.len(), "accessor")? {
                let a = &accs[ii];
                let rule = if a.ty != "SCALAR" {
                    Some(format!("its type is {}, indices must be SCALAR", a.ty))
                } else if !matches!(a.comp, UNSIGNED_BYTE | UNSIGNED_SHORT | UNSIGNED_INT) {
                    Some(format!(
                        "its componentType is {}, indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT",
                        component_name(a.comp)
                    ))
                } else if a.normalized {
                    Some("indices must not be normalized".into())
                } else if view_stride(a.view).is_some() {
                    Some("the bufferView of indices must not have a byteStride".into())
                } else {
                    None
                };
                if let Some(rule) = rule {
                    return Err(format!("{what}: indices (accessor {ii}): {rule}"));
                }
            }
            let mode = uint(p, "mode", &what)?.unwrap_or(TRIANGLES);
            if mode > 6 {
                return Err(format!("{what}: mode {mode} is not 0 to 6"));
            }
            // 3.7.2.1: TRIANGLES takes its vertices in threes; a remainder is no triangle
            let indices = index(p, "indices", &what, accs.len(), "accessor")?;
            let vertices = match indices {
                Some(ii) => Some(("indices", accs[ii].count)),
                None => count.as_ref().map(|(_, n)| ("vertices", *n)),
            };
            if let Some((of, n)) = vertices.filter(|&(_, n)| mode == TRIANGLES && n % 3 != 0) {
                return Err(format!(
                    "{what}: mode TRIANGLES takes {of} in threes (glTF 2.0, 3.7.2.1), but it has {n}"
                ));
            }
        }
    }
    nodes(&d)
}

fn accessor(a: &Value, i: usize, views: &[(u64, Option<u64>)]) -> Result<Acc, String> {
    let what = format!("accessor {i}");
    let comp =
        uint(a, "componentType", &what)?.ok_or_else(|| format!("{what} has no componentType"))?;
    let cs = component_size(comp)
        .ok_or_else(|| format!("{what}: componentType {comp} is not one glTF 2.0 defines"))?;
    let ty = a
        .get("type")
        .and_then(Value::as_str)
        .ok_or_else(|| format!("{what} has no type"))?;
    let elem = element_size(ty, comp)
        .ok_or_else(|| format!("{what}: type {ty:?} is not SCALAR, VEC2-4 or MAT2-4"))?;
    let normalized = a.get("normalized").and_then(Value::as_bool) == Some(true);
    if normalized && matches!(comp, FLOAT | UNSIGNED_INT) {
        return Err(format!(
            "{what}: normalized is true for a {} accessor; only integer components of 8 or 16 bits may be normalized",
            component_name(comp)
        ));
    }
    let count = uint(a, "count", &what)?.ok_or_else(|| format!("{what} has no count"))?;
    if count == 0 {
        return Err(format!("{what}: count must be at least 1"));
    }
    if count > MAX_COUNT {
        return Err(format!(
            "{what}: count {count} is more than the {MAX_COUNT} elements voxlod reads (vertices are indexed with 32 bits)"
        ));
    }
    let off = uint(a, "byteOffset", &what)?.unwrap_or(0);
    let view = index(a, "bufferView", &what, views.len(), "bufferView")?;
    if view.is_none() && a.get("byteOffset").is_some() {
        return Err(format!("{what}: byteOffset without a bufferView"));
    }
    if let Some(v) = view {
        let (len, stride) = views[v];
        if off % cs != 0 {
            return Err(format!(
                "{what}: byteOffset {off} is not a multiple of the component size {cs}"
            ));
        }
        let step = stride.unwrap_or(elem);
        if step < elem {
            return Err(format!(
                "{what}: bufferView {v} has byteStride {step}, less than the {elem} bytes of one {ty} of {}",
                component_name(comp)
            ));
        }
        let end = (count - 1)
            .checked_mul(step)
            .and_then(|x| x.checked_add(off))
            .and_then(|x| x.checked_add(elem));
        if end.is_none_or(|e| e > len) {
            return Err(format!(
                "{what}: {count} elements of {elem} bytes every {step} from byte {off} do not fit in bufferView {v} ({len} bytes)"
            ));
        }
    }
    if let Some(s) = a.get("sparse") {
        let what = format!("{what} sparse");
        let n = uint(s, "count", &what)?.ok_or_else(|| format!("{what} has no count"))?;
        if n == 0 || n > count {
            return Err(format!(
                "{what}: count {n} is not from 1 to the accessor's {count}"
            ));
        }
        let ix = s
            .get("indices")
            .ok_or_else(|| format!("{what} has no indices"))?;
        let iw = format!("{what} indices");
        let ic = uint(ix, "componentType", &iw)?.unwrap_or(0);
        if !matches!(ic, UNSIGNED_BYTE | UNSIGNED_SHORT | UNSIGNED_INT) {
            return Err(format!(
                "{iw}: componentType {ic} is not UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT"
            ));
        }
        let vals = s
            .get("values")
            .ok_or_else(|| format!("{what} has no values"))?;
        for (o, w, size) in [
            (ix, iw, component_size(ic).unwrap_or(4)),
            (vals, format!("{what} values"), elem),
        ] {
            let v = index(o, "bufferView", &w, views.len(), "bufferView")?
                .ok_or_else(|| format!("{w} has no bufferView"))?;
            let off = uint(o, "byteOffset", &w)?.unwrap_or(0);
            let end = n.checked_mul(size).and_then(|x| x.checked_add(off));
            if end.is_none_or(|e| e > views[v].0) {
                return Err(format!(
                    "{w}: {n} elements of {size} bytes from byte {off} do not fit in bufferView {v} ({} bytes)",
                    views[v].0
                ));
            }
            if views[v].1.is_some() {
                return Err(format!("{w}: its bufferView must not have a byteStride"));
            }
        }
    }
    Ok(Acc {
        ty: ty.to_string(),
        comp,
        normalized,
        count,
        view,
    })
}

/// The attribute table of 3.7.2.1, widened by `KHR_mesh_quantization`'s table when the file
/// uses it (`quantized`): `Err` says what `name` allows.
fn attribute(name: &str, a: &Acc, quantized: bool) -> Result<(), String> {
    let base = name.split('_').next().unwrap_or(name);
    let set = name.strip_prefix(base).and_then(|s| s.strip_prefix('_'));
    // types, and the integer components allowed: (normalized, not normalized)
    const U8_16: &[u64] = &[UNSIGNED_BYTE, UNSIGNED_SHORT];
    const ALL: &[u64] = &[BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT];
    const SIGNED: &[u64] = &[BYTE, SHORT];
    let q = quantized;
    let (types, float, norm, plain): (&[&str], bool, &[u64], &[u64]) = match (base, set) {
        ("POSITION", None) if q => (&["VEC3"], true, ALL, ALL),
        ("POSITION", None) => (&["VEC3"], true, &[], &[]),
        ("NORMAL", None) => (&["VEC3"], true, if q { SIGNED } else { &[] }, &[]),
        ("TANGENT", None) => (&["VEC4"], true, if q { SIGNED } else { &[] }, &[]),
        ("TEXCOORD", Some(_)) if q => (
            &["VEC2"],
            true,
            ALL,
            &[BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT],
        ),
        ("TEXCOORD", Some(_)) => (&["VEC2"], true, U8_16, &[]),
        ("COLOR", Some(_)) => (&["VEC3", "VEC4"], true, U8_16, &[]),
        ("JOINTS", Some(_)) => (&["VEC4"], false, &[], U8_16),
        ("WEIGHTS", Some(_)) => (&["VEC4"], true, U8_16, &[]),
        // application-specific (`_NAME`) or unknown: not read, only its bounds checked
        _ => return Ok(()),
    };
    if set.is_some_and(|s| s.parse::<u32>().is_err()) {
        return Err(format!("{name} does not end in a set number"));
    }
    let ok_type = types.contains(&a.ty.as_str());
    let ok_comp = match a.comp {
        FLOAT => float && !a.normalized,
        c if a.normalized => norm.contains(&c),
        c => plain.contains(&c),
    };
    if ok_type && ok_comp {
        return Ok(());
    }
    let names = |list: &[u64]| {
        let n: Vec<&str> = list.iter().map(|&c| component_name(c)).collect();
        n.join(" or ")
    };
    let mut comps = Vec::new();
    if float {
        comps.push("FLOAT".to_string());
    }
    if !norm.is_empty() {
        comps.push(format!("{} normalized", names(norm)));
    }
    if !plain.is_empty() {
        comps.push(names(plain));
    }
    let hint = if quantized || matches!(base, "COLOR" | "JOINTS" | "WEIGHTS") {
        ""
    } else {
        " (integer components need the file to use KHR_mesh_quantization)"
    };
    Err(format!(
        "it is {}{} {}; {base} must be {} of {}{hint}",
        if a.normalized { "normalized " } else { "" },
        component_name(a.comp),
        a.ty,
        types.join(" or "),
        comps.join(", or ")
    ))
}

/// Nodes form disjoint trees (3.5.3): a node is the child of at most one node, never its own
/// ancestor, and the nodes a scene lists are roots. A cycle would make the traversal endless,
/// a node shared by two parents doubles the work at each level.
fn nodes(d: &Doc) -> Result<(), String> {
    let nodes = d.list("nodes");
    let n = nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for (i, node) in nodes.iter().enumerate() {
        let what = format!("node {i}");
        let kids = node.get("children").and_then(Value::as_array);
        for c in kids.map_or(&[][..], Vec::as_slice) {
            let c = c
                .as_u64()
                .filter(|&c| c < n as u64)
                .ok_or_else(|| format!("{what}: child {c} names no node (the file has {n})"))?
                as usize;
            if c == i {
                return Err(format!("{what} lists itself as a child (a cycle)"));
            }
            if let Some(p) = parent[c] {
                return Err(format!(
                    "node {c} is a child of both node {p} and node {i}; each node has at most one parent"
                ));
            }
            parent[c] = Some(i);
        }
    }
    // with at most one parent each, a cycle is a walk up the parents that comes back
    let mut state = vec![0u8; n]; // 0 unseen, 1 on the current walk, 2 known to reach a root
    for start in 0..n {
        let mut walk = Vec::new();
        let mut at = Some(start);
        while let Some(i) = at {
            match state[i] {
                2 => break,
                1 => {
                    return Err(format!(
                        "node {i} is its own ancestor (a cycle of nodes through node {start})"
                    ))
                }
                _ => {
                    state[i] = 1;
                    walk.push(i);
                    at = parent[i];
                }
            }
        }
        walk.into_iter().for_each(|i| state[i] = 2);
    }
    for (s, scene) in d.list("scenes").iter().enumerate() {
        let list = scene.get("nodes").and_then(Value::as_array);
        // 3.5.2: a scene's nodes are unique; a root listed twice would be read twice
        let mut listed = vec![false; n];
        for x in list.map_or(&[][..], Vec::as_slice) {
            let i =
                x.as_u64().filter(|&c| c < n as u64).ok_or_else(|| {
                    format!("scene {s}: node {x} names no node (the file has {n})")
                })? as usize;
            if std::mem::replace(&mut listed[i], true) {
                return Err(format!(
                    "scene {s} lists node {i} twice; the root nodes of a scene must be unique (glTF 2.0, 3.5.2)"
                ));
            }
            if let Some(p) = parent[i] {
                return Err(format!(
                    "scene {s} lists node {i}, a child of node {p}; a scene lists root nodes only"
                ));
            }
        }
    }
    Ok(())
}

/// The tokens of a JSON text that its parsed forms allocate for.
#[derive(Debug, Default, PartialEq)]
struct Tokens {
    objects: u64,
    arrays: u64,
    /// Object members (`:`).
    members: u64,
    /// Separators (`,`): with `arrays`, a bound of the array elements.
    commas: u64,
    strings: u64,
    string_bytes: u64,
}

fn tokens(json: &[u8]) -> Tokens {
    let mut t = Tokens::default();
    let (mut in_string, mut escaped) = (false, false);
    for &b in json {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => t.string_bytes += 1,
            }
            continue;
        }
        match b {
            b'"' => {
                in_string = true;
                t.strings += 1;
            }
            b'{' => t.objects += 1,
            b'[' => t.arrays += 1,
            b':' => t.members += 1,
            b',' => t.commas += 1,
            _ => {}
        }
    }
    t
}

/// The most bytes a parsed element of the `gltf` crate's document takes inline (its largest
/// object type: every `{` may be one).
fn largest_object() -> u64 {
    use gltf::json;
    [
        std::mem::size_of::<json::Node>(),
        std::mem::size_of::<json::Accessor>(),
        std::mem::size_of::<json::Mesh>(),
        std::mem::size_of::<json::mesh::Primitive>(),
        std::mem::size_of::<json::Material>(),
        std::mem::size_of::<json::Texture>(),
        std::mem::size_of::<json::Image>(),
        std::mem::size_of::<json::Buffer>(),
        std::mem::size_of::<json::buffer::View>(),
        std::mem::size_of::<json::Scene>(),
        std::mem::size_of::<json::texture::Sampler>(),
        std::mem::size_of::<json::Camera>(),
        std::mem::size_of::<json::Skin>(),
        std::mem::size_of::<json::Animation>(),
        std::mem::size_of::<json::animation::Channel>(),
        std::mem::size_of::<json::animation::Sampler>(),
        std::mem::size_of::<json::accessor::sparse::Sparse>(),
    ]
    .into_iter()
    .max()
    .unwrap_or(0) as u64
}

/// An upper bound of the memory that parsing the glTF JSON text `json` takes, beside the text
/// itself: the checks' `serde_json` tree ([`document`]) and then the `gltf` crate's document,
/// one after the other, each bounded by the text's tokens. A tree value is 32 bytes and an
/// array's vector grows by doubling (at most 3 values' room per element while it moves), an
/// object is a B-tree of at most 640 bytes a node, at least 5 members a node past its first,
/// a string its bytes and an allocation's rounding; the crate's document holds at most one of
/// its objects per `{` and no more in its vectors and maps than the tree does, and the reader lists
/// each node once with its transform. A 50 MB chain of
/// a million nodes is bounded at about 1.5 GB, so it is refused under a budget that cannot
/// hold it instead of being parsed past it.
pub(crate) fn document_bound(json: &[u8]) -> u64 {
    let t = tokens(json);
    let tree = 96 * (t.commas + t.arrays + 1)
        + 640 * t.objects
        + 256 * t.members
        + t.string_bytes
        + 32 * t.strings;
    // the reader's list of the scene's nodes with their world transforms, one per node
    let nodes = std::mem::size_of::<(gltf::Node, [[f64; 4]; 4])>() as u64;
    tree + (largest_object() + nodes) * t.objects
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(accessors: &str, views: &str, prim: &str, nodes: &str) -> String {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":64}}],
            "bufferViews":{views},"accessors":{accessors},
            "meshes":[{{"primitives":[{prim}]}}],"nodes":{nodes},"scenes":[{{"nodes":[0]}}]}}"#
        )
    }

    const VIEW: &str = r#"[{"buffer":0,"byteLength":64}]"#;
    const POS: &str = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}"#;
    const NODE: &str = r#"[{"mesh":0}]"#;

    fn refused(accessors: &str, views: &str, prim: &str, nodes: &str) -> String {
        document(&doc(accessors, views, prim, nodes), Some(&[0; 64])).unwrap_err()
    }

    #[test]
    fn compression_used_with_a_valid_fallback_passes() {
        // an optional compression extension leaves the uncompressed data readable
        let d = doc(
            &format!("[{POS}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        let d = d.replacen(
            '{',
            r#"{"extensionsUsed":["KHR_draco_mesh_compression"],"#,
            1,
        );
        document(&d, Some(&[0; 64])).unwrap();
        let req = d.replacen(
            '{',
            r#"{"extensionsRequired":["KHR_draco_mesh_compression"],"#,
            1,
        );
        let e = document(&req, Some(&[0; 64])).unwrap_err();
        assert!(
            e.starts_with("the geometry is compressed with KHR_draco_mesh_compression (Draco)"),
            "{e}"
        );
    }

    #[test]
    fn a_valid_primitive_passes() {
        let d = doc(
            &format!("[{POS}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        document(&d, Some(&[0; 64])).unwrap();
    }

    #[test]
    fn attribute_and_index_tables() {
        let ub_scalar = r#"{"bufferView":0,"componentType":5121,"count":3,"type":"SCALAR"}"#;
        let e = refused(
            &format!("[{ub_scalar}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        assert!(e.contains("POSITION must be VEC3 of FLOAT"), "{e}");
        let e = refused(
            &format!("[{POS}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0},"indices":0}"#,
            NODE,
        );
        assert!(e.contains("indices must be SCALAR"), "{e}");
        let f_scalar = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"SCALAR"}"#;
        let e = refused(
            &format!("[{POS},{f_scalar}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0},"indices":1}"#,
            NODE,
        );
        assert!(e.contains("componentType is FLOAT"), "{e}");
        let uint_uv = r#"{"bufferView":0,"componentType":5125,"count":3,"type":"VEC2"}"#;
        let e = refused(
            &format!("[{POS},{uint_uv}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0,"TEXCOORD_0":1}}"#,
            NODE,
        );
        assert!(e.contains("TEXCOORD must be VEC2"), "{e}");
        let ub_uv = r#"{"bufferView":0,"componentType":5121,"count":3,"type":"VEC2"}"#;
        let e = refused(
            &format!("[{POS},{ub_uv}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0,"TEXCOORD_0":1}}"#,
            NODE,
        );
        assert!(e.contains("normalized"), "{e}");
        let col = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"SCALAR"}"#;
        let e = refused(
            &format!("[{POS},{col}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0,"COLOR_0":1}}"#,
            NODE,
        );
        assert!(e.contains("COLOR must be VEC3 or VEC4"), "{e}");
    }

    #[test]
    fn quantization_widens_the_attribute_table() {
        let acc = |comp: u32, ty: &str, norm: bool| {
            format!(
                r#"{{"bufferView":0,"componentType":{comp},"count":3,"type":"{ty}","normalized":{norm}}}"#
            )
        };
        let with =
            |d: String| d.replacen('{', r#"{"extensionsUsed":["KHR_mesh_quantization"],"#, 1);
        // (attribute, accessor, allowed with KHR_mesh_quantization)
        for (name, a, ok) in [
            ("POSITION", acc(5122, "VEC3", false), true),
            ("POSITION", acc(5120, "VEC3", true), true),
            ("POSITION", acc(5123, "VEC3", false), true),
            ("POSITION", acc(5125, "VEC3", false), false),
            ("NORMAL", acc(5120, "VEC3", true), true),
            ("NORMAL", acc(5122, "VEC3", true), true),
            ("NORMAL", acc(5122, "VEC3", false), false),
            ("NORMAL", acc(5121, "VEC3", true), false),
            ("TEXCOORD_0", acc(5122, "VEC2", false), true),
            ("TEXCOORD_0", acc(5120, "VEC2", true), true),
            ("TEXCOORD_0", acc(5122, "VEC3", false), false),
            ("COLOR_0", acc(5120, "VEC4", true), false),
        ] {
            let d = doc(
                &format!("[{POS},{a}]"),
                VIEW,
                &format!(r#"{{"attributes":{{"POSITION":0,"{name}":1}}}}"#)
                    .replace(r#""POSITION":0,"POSITION":1"#, r#""POSITION":1"#),
                NODE,
            );
            // without the extension, none of these integer attributes is allowed
            let e = document(&d, Some(&[0; 64])).unwrap_err();
            assert!(e.contains(name.split('_').next().unwrap()), "{name}: {e}");
            let got = document(&with(d), Some(&[0; 64]));
            assert_eq!(got.is_ok(), ok, "{name} {a}: {got:?}");
        }
    }

    #[test]
    fn strides_and_bounds() {
        let strided = r#"[{"buffer":0,"byteLength":64,"byteStride":4}]"#;
        let e = refused(
            &format!("[{POS}]"),
            strided,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        assert!(e.contains("byteStride 4, less than the 12 bytes"), "{e}");
        let odd = r#"[{"buffer":0,"byteLength":64,"byteStride":6}]"#;
        let e = refused(&format!("[{POS}]"), odd, r#"{"attributes":{}}"#, NODE);
        assert!(e.contains("multiple of 4"), "{e}");
        let outside = r#"[{"buffer":0,"byteOffset":60,"byteLength":8}]"#;
        let e = refused("[]", outside, r#"{"attributes":{}}"#, NODE);
        assert!(e.contains("outside buffer 0"), "{e}");
        let huge =
            r#"{"bufferView":0,"componentType":5126,"count":18446744073709551615,"type":"VEC3"}"#;
        let e = refused(
            &format!("[{huge}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        assert!(e.contains("count 18446744073709551615"), "{e}");
        let long = r#"{"bufferView":0,"componentType":5126,"count":6,"type":"VEC3"}"#;
        let e = refused(
            &format!("[{long}]"),
            VIEW,
            r#"{"attributes":{"POSITION":0}}"#,
            NODE,
        );
        assert!(e.contains("do not fit in bufferView 0"), "{e}");
    }

    #[test]
    fn node_cycles_and_shared_children() {
        let pos = format!("[{POS}]");
        let prim = r#"{"attributes":{"POSITION":0}}"#;
        let e = refused(&pos, VIEW, prim, r#"[{"mesh":0,"children":[0]}]"#);
        assert!(e.contains("lists itself"), "{e}");
        let e = refused(
            &pos,
            VIEW,
            prim,
            r#"[{"mesh":0},{"children":[2]},{"children":[1]}]"#,
        );
        assert!(e.contains("own ancestor"), "{e}");
        let e = refused(
            &pos,
            VIEW,
            prim,
            r#"[{"children":[2]},{"children":[2]},{"mesh":0}]"#,
        );
        assert!(e.contains("child of both"), "{e}");
    }

    #[test]
    fn glb_container_rules() {
        let json = br#"{"asset":{"version":"2.0"}}   "#;
        let mut glb = Vec::new();
        glb.extend_from_slice(b"glTF");
        glb.extend_from_slice(&2u32.to_le_bytes());
        let total = 12 + 8 + json.len() as u32;
        glb.extend_from_slice(&total.to_le_bytes());
        glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
        glb.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        glb.extend_from_slice(json);
        assert!(container(&glb).is_ok());
        let mut short = glb.clone();
        short[8..12].copy_from_slice(&20u32.to_le_bytes());
        assert!(container(&short).unwrap_err().contains("length as 20"));
        let mut trailing = glb.clone();
        trailing[8..12].copy_from_slice(&(total + 8).to_le_bytes());
        trailing.extend_from_slice(&0xffff_fff0u32.to_le_bytes());
        trailing.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        assert!(container(&trailing)
            .unwrap_err()
            .contains("declares 4294967280 bytes"));
        let mut bad = glb.clone();
        bad[22] = 0xff;
        assert!(container(&bad).unwrap_err().contains("UTF-8"));
    }
}
