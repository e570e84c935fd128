//! The vertex data of a glTF primitive: accessors decoded here rather than by the `gltf`
//! crate's readers (which read a POSITION of any component type as FLOAT), with the component
//! types `KHR_mesh_quantization` allows, and buffer views compressed with
//! `EXT_meshopt_compression` (or its successor `KHR_meshopt_compression`) decoded by
//! meshoptimizer's decoders (the `meshopt` crate).
//!
//! Accessors (glTF 2.0, 3.6.2 and 3.11): each element is read at `byteOffset + i·stride` of its
//! buffer view (the stride is the view's `byteStride`, else the element size), each component
//! converted to `f32`: FLOAT as it is; a normalized integer as the specification's table
//! (`max(c/127, −1)`, `c/255`, `max(c/32767, −1)`, `c/65535`); an integer that is not
//! normalized as its value (`KHR_mesh_quantization`: the node's transform scales it). Sparse
//! accessors are applied over the view's elements (or zeros without a view).
//!
//! `EXT_meshopt_compression` (Khronos glTF extension registry): a buffer view with the
//! extension holds its `count × byteStride` bytes compressed in another buffer; mode
//! `ATTRIBUTES` is meshoptimizer's vertex codec, `TRIANGLES` its index codec, `INDICES` its
//! index sequence codec, and filters `OCTAHEDRAL`, `QUATERNION`, `EXPONENTIAL` (and `COLOR`
//! for `KHR_meshopt_compression`) are undone after the vertex codec. A buffer marked
//! `fallback` holds no data (its views are only ever read decompressed). Every view is decoded
//! when the file is opened, so corrupt data is an error naming the view before any triangle is
//! streamed; the decoders are meshoptimizer's, which are safe on untrusted input (they return
//! an error, or garbage that the checks downstream treat as any other data).

use gltf::accessor::{DataType, Dimensions};
use serde::Deserialize;

/// The compression extensions read: the vendor one and its Khronos successor (the same
/// layout; the latter adds the `COLOR` filter).
pub(crate) const MESHOPT: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// The extension object of a compressed buffer view.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct Compressed {
    buffer: u64,
    #[serde(default)]
    byte_offset: u64,
    byte_length: u64,
    byte_stride: u64,
    count: u64,
    mode: String,
    #[serde(default)]
    filter: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
struct Extensions<T> {
    #[serde(rename = "EXT_meshopt_compression")]
    ext: Option<T>,
    #[serde(rename = "KHR_meshopt_compression")]
    khr: Option<T>,
}

#[derive(Debug, Default, Deserialize)]
struct WithExtensions<T> {
    #[serde(default = "none")]
    extensions: Option<Extensions<T>>,
}

fn none<T>() -> Option<T> {
    None
}

#[derive(Debug, Deserialize)]
struct Fallback {
    #[serde(default)]
    fallback: bool,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
struct Partial {
    #[serde(default)]
    buffers: Vec<WithExtensions<Fallback>>,
    #[serde(default)]
    buffer_views: Vec<WithExtensions<Compressed>>,
}

/// The meshopt-compressed buffer views of a document and its fallback buffers.
#[derive(Debug, Default)]
pub(crate) struct Meshopt {
    /// Per buffer: it is a fallback buffer, which holds no data to load.
    pub fallback: Vec<bool>,
    /// Per buffer view: its compressed form and whether it came from `KHR_meshopt_compression`.
    views: Vec<Option<(Compressed, bool)>>,
}

impl Meshopt {
    /// The extension objects of `json` (a glTF document already checked to be valid JSON);
    /// `Err` is the rule an extension object breaks.
    pub fn parse(json: &str) -> Result<Meshopt, String> {
        let p: Partial = serde_json::from_str(json)
            .map_err(|e| format!("an EXT_meshopt_compression object is malformed: {e}"))?;
        let fallback = p
            .buffers
            .into_iter()
            .map(|b| {
                b.extensions
                    .and_then(|e| e.ext.or(e.khr))
                    .is_some_and(|f| f.fallback)
            })
            .collect();
        let views = p
            .buffer_views
            .into_iter()
            .map(|v| {
                v.extensions.and_then(|e| match (e.ext, e.khr) {
                    (_, Some(k)) => Some((k, true)),
                    (Some(x), None) => Some((x, false)),
                    (None, None) => None,
                })
            })
            .collect();
        Ok(Meshopt { fallback, views })
    }

    /// Decodes every compressed view of `doc` from `buffers` (index by buffer view: `None` for
    /// a view that is not compressed). `Err` names the view and what is wrong.
    pub fn decode(
        &self,
        doc: &gltf::Document,
        buffers: &[Vec<u8>],
    ) -> Result<Vec<Option<Vec<u8>>>, String> {
        let mut out = Vec::with_capacity(self.views.len());
        for v in doc.views() {
            match self.views.get(v.index()).and_then(Option::as_ref) {
                None => out.push(None),
                Some((c, khr)) => {
                    let what = format!("bufferView {} ({})", v.index(), MESHOPT[usize::from(*khr)]);
                    let data = decode_view(c, *khr, v.length() as u64, buffers)
                        .map_err(|e| format!("{what}: {e}"))?;
                    out.push(Some(data));
                }
            }
        }
        Ok(out)
    }
}

/// How many times its compressed bytes a decoded view may be, plus [`MAX_SMALL`]: the decoders
/// allocate the whole output from the declared `count × byteStride`, so a few bytes declaring
/// terabytes would end the process. meshoptimizer's codecs spend at least 2 bits on each 256
/// bytes of a channel (the vertex codec's densest block) and at least half a byte on each
/// triangle, so real data stays far below this.
const MAX_RATIO: u64 = 4096;
/// Decoded bytes allowed whatever the compressed size.
const MAX_SMALL: u64 = 1 << 20;

fn decode_view(
    c: &Compressed,
    khr: bool,
    view_length: u64,
    buffers: &[Vec<u8>],
) -> Result<Vec<u8>, String> {
    let src = buffers.get(c.buffer as usize).ok_or_else(|| {
        format!(
            "buffer {} does not exist (the file has {})",
            c.buffer,
            buffers.len()
        )
    })?;
    let end = c.byte_offset.checked_add(c.byte_length);
    let data = end
        .filter(|&e| e <= src.len() as u64)
        .map(|e| &src[c.byte_offset as usize..e as usize])
        .ok_or_else(|| {
            format!(
                "bytes {}..{}+{} lie outside buffer {} ({} bytes)",
                c.byte_offset,
                c.byte_offset,
                c.byte_length,
                c.buffer,
                src.len()
            )
        })?;
    let (n, stride) = (c.count, c.byte_stride);
    match (c.mode.as_str(), stride) {
        ("ATTRIBUTES", s) if s == 0 || s % 4 != 0 || s > 256 => {
            return Err(format!(
                "mode ATTRIBUTES needs a byteStride that is a multiple of 4 up to 256, not {s}"
            ))
        }
        ("TRIANGLES" | "INDICES", s) if s != 2 && s != 4 => {
            return Err(format!(
                "mode {} needs a byteStride of 2 or 4, not {s}",
                c.mode
            ))
        }
        ("ATTRIBUTES" | "TRIANGLES" | "INDICES", _) => {}
        (m, _) => {
            return Err(format!(
                "mode {m:?} is not ATTRIBUTES, TRIANGLES or INDICES"
            ))
        }
    }
    let size = n.checked_mul(stride);
    if size != Some(view_length) {
        return Err(format!(
            "count {n} × byteStride {stride} must equal the view's byteLength {view_length}"
        ));
    }
    if view_length > MAX_SMALL + MAX_RATIO * c.byte_length {
        return Err(format!(
            "{view_length} bytes decoded from {} compressed bytes is more than meshoptimizer's \
             codecs can make (at most {MAX_RATIO} times, plus 1 MiB): the data is corrupt",
            c.byte_length
        ));
    }
    let filter = c.filter.as_deref().unwrap_or("NONE");
    let n = n as usize;
    let bytes = match c.mode.as_str() {
        "ATTRIBUTES" => {
            let mut w = vertices(data, n, stride as usize)?;
            unfilter(&mut w, filter, stride as usize, khr)?;
            w.iter().flat_map(|w| w.to_ne_bytes()).collect()
        }
        _ => {
            if filter != "NONE" {
                return Err(format!("mode {} takes no filter, not {filter}", c.mode));
            }
            if c.mode == "TRIANGLES" && n % 3 != 0 {
                return Err(format!(
                    "mode TRIANGLES needs a count divisible by 3, not {n}"
                ));
            }
            indices(data, n, stride as usize, c.mode == "TRIANGLES")?
        }
    };
    Ok(bytes)
}

fn corrupt(code: i32) -> String {
    format!("the compressed data is corrupt or truncated (meshoptimizer's decoder returned {code})")
}

// meshoptimizer's decoders through the `meshopt` crate's bindings (its safe wrappers cover
// only fixed element types; the glTF extension's strides and filters need the C functions).
// Each call gets a destination of exactly the size it writes, aligned to 4 bytes (the filters
// read 16- and 32-bit words), and the source slice with its length; meshoptimizer documents
// its decoders as safe on untrusted input (they return an error code, or garbage data).

/// meshoptimizer's vertex codec: `n` elements of `stride` bytes (a multiple of 4 up to 256),
/// as native-endian words.
fn vertices(data: &[u8], n: usize, stride: usize) -> Result<Vec<u32>, String> {
    let mut out = vec![0u32; n * stride / 4];
    // SAFETY: `out` holds n × stride bytes, which the decoder writes; it reads at most
    // `data.len()` bytes of `data`.
    let rc = unsafe {
        meshopt::ffi::meshopt_decodeVertexBuffer(
            out.as_mut_ptr().cast(),
            n,
            stride,
            data.as_ptr(),
            data.len(),
        )
    };
    if rc != 0 {
        return Err(corrupt(rc));
    }
    Ok(out)
}

/// meshoptimizer's index codecs (`triangles`: the index buffer codec, else the index sequence
/// codec): `n` indices as little-endian bytes of `size` (2 or 4) each.
fn indices(data: &[u8], n: usize, size: usize, triangles: bool) -> Result<Vec<u8>, String> {
    let mut out = vec![0u32; n];
    let decode = if triangles {
        meshopt::ffi::meshopt_decodeIndexBuffer
    } else {
        meshopt::ffi::meshopt_decodeIndexSequence
    };
    // SAFETY: `out` holds n × 4 ≥ n × size bytes, which the decoder writes; it reads at most
    // `data.len()` bytes of `data`.
    let rc = unsafe { decode(out.as_mut_ptr().cast(), n, size, data.as_ptr(), data.len()) };
    if rc != 0 {
        return Err(corrupt(rc));
    }
    let mut bytes: Vec<u8> = out.iter().flat_map(|w| w.to_ne_bytes()).collect();
    bytes.truncate(n * size);
    // the decoder wrote native-endian integers: glTF's are little-endian
    if cfg!(target_endian = "big") {
        bytes.chunks_exact_mut(size).for_each(<[u8]>::reverse);
    }
    Ok(bytes)
}

/// Undoes a meshopt filter in place on `words` (elements of `stride` bytes).
fn unfilter(words: &mut [u32], filter: &str, stride: usize, khr: bool) -> Result<(), String> {
    let f = match (filter, stride) {
        ("NONE", _) => return Ok(()),
        ("OCTAHEDRAL", 4 | 8) => meshopt::ffi::meshopt_decodeFilterOct,
        ("QUATERNION", 8) => meshopt::ffi::meshopt_decodeFilterQuat,
        ("COLOR", 4 | 8) if khr => meshopt::ffi::meshopt_decodeFilterColor,
        ("EXPONENTIAL", _) => meshopt::ffi::meshopt_decodeFilterExp,
        (f @ ("OCTAHEDRAL" | "QUATERNION" | "COLOR"), s) if f != "COLOR" || khr => {
            return Err(format!(
                "filter {f} needs a byteStride of {}, not {s}",
                if f == "QUATERNION" { "8" } else { "4 or 8" }
            ))
        }
        (f, _) => return Err(format!("filter {f:?} is not one the extension defines")),
    };
    let n = words.len() * 4 / stride;
    // SAFETY: `words` holds n elements of `stride` bytes, aligned to 4, a stride the filter
    // takes (4 or 8 for OCTAHEDRAL and COLOR, 8 for QUATERNION, a multiple of 4 for
    // EXPONENTIAL); the filter rewrites them in place.
    unsafe { f(words.as_mut_ptr().cast(), n, stride) };
    Ok(())
}

/// The data accessors read: the loaded buffers and the decoded compressed views.
pub(crate) struct Data<'a> {
    pub buffers: &'a [Vec<u8>],
    pub decoded: &'a [Option<Vec<u8>>],
}

fn dims(d: Dimensions) -> usize {
    match d {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        Dimensions::Mat2 => 4,
        Dimensions::Mat3 => 9,
        Dimensions::Mat4 => 16,
    }
}

/// One component at `b[0..size]` as `f32`, normalized integers mapped as glTF 3.11 says.
fn component(t: DataType, normalized: bool, b: &[u8]) -> f32 {
    match (t, normalized) {
        (DataType::F32, _) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        (DataType::U32, _) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        (DataType::I8, false) => b[0] as i8 as f32,
        (DataType::U8, false) => b[0] as f32,
        (DataType::I16, false) => i16::from_le_bytes([b[0], b[1]]) as f32,
        (DataType::U16, false) => u16::from_le_bytes([b[0], b[1]]) as f32,
        (DataType::I8, true) => (b[0] as i8 as f32 / 127.0).max(-1.0),
        (DataType::U8, true) => b[0] as f32 / 255.0,
        (DataType::I16, true) => (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0),
        (DataType::U16, true) => u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
    }
}

impl Data<'_> {
    /// The bytes of buffer view `v`: decoded if it is compressed, else its slice of its buffer.
    fn view(&self, v: &gltf::buffer::View) -> Result<&[u8], String> {
        if let Some(Some(d)) = self.decoded.get(v.index()) {
            return Ok(d);
        }
        let b = self.buffers.get(v.buffer().index()).map_or(&[][..], |b| b);
        b.get(v.offset()..v.offset() + v.length()).ok_or_else(|| {
            format!(
                "bufferView {} lies outside its buffer ({} bytes loaded{})",
                v.index(),
                b.len(),
                if b.is_empty() {
                    ": a fallback buffer of EXT_meshopt_compression holds no data"
                } else {
                    ""
                }
            )
        })
    }

    /// `count` elements of `size` bytes every `stride` bytes from `offset` of view `v`,
    /// each handed to `each(i, bytes)`.
    fn elements(
        &self,
        v: &gltf::buffer::View,
        offset: usize,
        stride: usize,
        size: usize,
        count: usize,
        mut each: impl FnMut(usize, &[u8]),
    ) -> Result<(), String> {
        let bytes = self.view(v)?;
        let fits = count == 0
            || (count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(offset + size))
                .is_some_and(|e| e <= bytes.len());
        if !fits {
            return Err(format!(
                "{count} elements of {size} bytes every {stride} from byte {offset} do not fit in bufferView {} ({} bytes)",
                v.index(),
                bytes.len()
            ));
        }
        for i in 0..count {
            let at = offset + i * stride;
            each(i, &bytes[at..at + size]);
        }
        Ok(())
    }

    /// The elements of accessor `a` as `N` floats each (`a` must have `N` components, or
    /// 3 when `N` is 4: the fourth is then 1, for RGB colours).
    pub fn floats<const N: usize>(&self, a: &gltf::Accessor) -> Result<Vec<[f32; N]>, String> {
        let what = format!("accessor {}", a.index());
        let (t, norm) = (a.data_type(), a.normalized());
        let k = dims(a.dimensions());
        if !(k == N || (N == 4 && k == 3)) {
            return Err(format!("{what}: {k} components where {N} are read"));
        }
        let cs = t.size();
        let elem = k * cs;
        let mut fill = [0.0f32; N];
        if N == 4 && k == 3 {
            fill[3] = 1.0;
        }
        let mut out = vec![fill; a.count()];
        let read = |out: &mut [f32; N], b: &[u8]| {
            for j in 0..k {
                out[j] = component(t, norm, &b[j * cs..]);
            }
        };
        if let Some(v) = a.view() {
            let stride = v.stride().unwrap_or(elem);
            self.elements(&v, a.offset(), stride, elem, a.count(), |i, b| {
                read(&mut out[i], b)
            })
            .map_err(|e| format!("{what}: {e}"))?;
        }
        if let Some(s) = a.sparse() {
            let at = self.sparse_indices(&s, a.count())?;
            let vals = s.values();
            let mut values = vec![fill; s.count()];
            self.elements(
                &vals.view(),
                vals.offset(),
                elem,
                elem,
                s.count(),
                |i, b| read(&mut values[i], b),
            )
            .map_err(|e| format!("{what} sparse values: {e}"))?;
            for (i, v) in at.into_iter().zip(values) {
                out[i] = v;
            }
        }
        Ok(out)
    }

    /// The target indices of a sparse accessor of `count` elements, each checked to be less.
    fn sparse_indices(
        &self,
        s: &gltf::accessor::sparse::Sparse,
        count: usize,
    ) -> Result<Vec<usize>, String> {
        use gltf::accessor::sparse::IndexType;
        let ix = s.indices();
        let size = match ix.index_type() {
            IndexType::U8 => 1,
            IndexType::U16 => 2,
            IndexType::U32 => 4,
        };
        let mut at = Vec::with_capacity(s.count());
        self.elements(&ix.view(), ix.offset(), size, size, s.count(), |_, b| {
            at.push(match size {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            })
        })
        .map_err(|e| format!("sparse indices: {e}"))?;
        if let Some(i) = at.iter().find(|&&i| i >= count) {
            return Err(format!(
                "a sparse index {i} is out of range ({count} elements)"
            ));
        }
        Ok(at)
    }

    /// The indices of accessor `a` (SCALAR of unsigned integers, checked by `gltf_check`).
    pub fn indices(&self, a: &gltf::Accessor) -> Result<Vec<u32>, String> {
        let what = format!("indices (accessor {})", a.index());
        let t = a.data_type();
        let size = t.size();
        let mut out = vec![0u32; a.count()];
        let read = |b: &[u8]| match t {
            DataType::U8 => b[0] as u32,
            DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as u32,
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        };
        if let Some(v) = a.view() {
            self.elements(&v, a.offset(), size, size, a.count(), |i, b| {
                out[i] = read(b)
            })
            .map_err(|e| format!("{what}: {e}"))?;
        }
        if let Some(s) = a.sparse() {
            let at = self.sparse_indices(&s, a.count())?;
            let vals = s.values();
            let mut values = Vec::with_capacity(s.count());
            self.elements(
                &vals.view(),
                vals.offset(),
                size,
                size,
                s.count(),
                |_, b| values.push(read(b)),
            )
            .map_err(|e| format!("{what} sparse values: {e}"))?;
            for (i, v) in at.into_iter().zip(values) {
                out[i] = v;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalized_components_follow_the_specification() {
        assert_eq!(component(DataType::I8, true, &[0x81]), -1.0);
        assert_eq!(component(DataType::I8, true, &[0x80]), -1.0); // −128 clamps to −1
        assert_eq!(component(DataType::I8, true, &[127]), 1.0);
        assert_eq!(component(DataType::U8, true, &[255]), 1.0);
        assert_eq!(
            component(DataType::I16, true, &(-32767i16).to_le_bytes()),
            -1.0
        );
        assert_eq!(
            component(DataType::I16, true, &(-32768i16).to_le_bytes()),
            -1.0
        );
        assert_eq!(component(DataType::U16, true, &65535u16.to_le_bytes()), 1.0);
        assert_eq!(
            component(DataType::U16, false, &256u16.to_le_bytes()),
            256.0
        );
        assert_eq!(
            component(DataType::I16, false, &(-5i16).to_le_bytes()),
            -5.0
        );
        assert_eq!(component(DataType::I8, false, &[0xfb]), -5.0);
        assert_eq!(component(DataType::F32, false, &1.5f32.to_le_bytes()), 1.5);
    }

    #[test]
    fn meshopt_codecs_round_trip_and_refuse_garbage() {
        // vertices of a 12-byte stride through meshoptimizer's encoder, decoded here
        let verts: Vec<[u32; 3]> = (0..100u32).map(|i| [i, i * 7, 1000 - i]).collect();
        let enc = meshopt::encode_vertex_buffer(&verts).unwrap();
        let got = vertices(&enc, 100, 12).unwrap();
        assert_eq!(got, verts.concat());
        // a damaged stream is an error, not a panic
        assert!(vertices(&enc[..enc.len() / 2], 100, 12).is_err());
        let mut bad = enc.clone();
        bad[0] ^= 0xff;
        assert!(vertices(&bad, 100, 12).is_err());
        // indices: the triangle codec, written as 16-bit indices
        let idx: Vec<u32> = (0..99u32).collect();
        let enc = meshopt::encode_index_buffer(&idx, 100).unwrap();
        let c = Compressed {
            buffer: 0,
            byte_offset: 0,
            byte_length: enc.len() as u64,
            byte_stride: 2,
            count: 99,
            mode: "TRIANGLES".into(),
            filter: None,
        };
        let out = decode_view(&c, false, 198, std::slice::from_ref(&enc)).unwrap();
        let want: Vec<u8> = idx.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect();
        assert_eq!(out, want);
        let e = decode_view(&c, false, 200, std::slice::from_ref(&enc)).unwrap_err();
        assert!(e.contains("must equal the view's byteLength 200"), "{e}");
        let e = decode_view(&c, false, 198, &[enc[..4].to_vec()]).unwrap_err();
        assert!(e.contains("outside buffer 0"), "{e}");
    }

    #[test]
    fn filters_undo_meshopts_encoders() {
        // octahedral normals (8-bit): unit vectors back within the 8-bit precision
        let n: [[f32; 4]; 3] = [
            [0.0, 0.0, 1.0, 0.0],
            [0.6, 0.8, 0.0, 0.0],
            [-0.48, 0.6, -0.64, 0.0],
        ];
        let mut words = vec![0u32; 3];
        // SAFETY: 3 elements of 4 bytes written from 3 × 4 floats.
        unsafe {
            meshopt::ffi::meshopt_encodeFilterOct(
                words.as_mut_ptr().cast(),
                3,
                4,
                8,
                n.as_ptr().cast(),
            )
        };
        unfilter(&mut words, "OCTAHEDRAL", 4, false).unwrap();
        for (i, w) in n.iter().enumerate() {
            let b = words[i].to_ne_bytes();
            for a in 0..3 {
                let g = b[a] as i8 as f32 / 127.0;
                assert!((g - w[a]).abs() < 0.03, "{i} {a}: {g} vs {}", w[a]);
            }
        }
        // KHR_meshopt_compression's COLOR filter (YCoCg, 8 bits): RGBA back within a few
        // steps of 8 bits; EXT_meshopt_compression does not define it
        let rgba: [[f32; 4]; 3] = [
            [1.0, 0.0, 0.0, 1.0],
            [0.2, 0.6, 0.9, 0.5],
            [0.5, 0.5, 0.5, 0.0],
        ];
        let mut words = vec![0u32; 3];
        // SAFETY: 3 elements of 4 bytes written from 3 × 4 floats.
        unsafe {
            meshopt::ffi::meshopt_encodeFilterColor(
                words.as_mut_ptr().cast(),
                3,
                4,
                8,
                rgba.as_ptr().cast(),
            )
        };
        let encoded = words.clone();
        unfilter(&mut words, "COLOR", 4, true).unwrap();
        assert_ne!(words, encoded);
        for (i, w) in rgba.iter().enumerate() {
            let b = words[i].to_ne_bytes();
            for c in 0..4 {
                let g = b[c] as f32 / 255.0;
                assert!((g - w[c]).abs() < 0.03, "{i} {c}: {g} vs {}", w[c]);
            }
        }
        let e = unfilter(&mut words, "COLOR", 4, false).unwrap_err();
        assert!(e.contains("not one the extension defines"), "{e}");
        let e = unfilter(&mut [0; 3], "OCTAHEDRAL", 12, false).unwrap_err();
        assert!(e.contains("byteStride of 4 or 8"), "{e}");
        let e = unfilter(&mut [0; 1], "COLOR", 4, false).unwrap_err();
        assert!(e.contains("not one the extension defines"), "{e}");
    }
}
