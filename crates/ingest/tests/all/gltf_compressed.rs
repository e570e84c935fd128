//! glTF with `KHR_mesh_quantization` and `EXT_meshopt_compression` (docs/INGEST.md "glTF"),
//! on GLBs written here by a tiny writer of its own: every component type the quantization
//! extension allows against the same mesh with FLOAT attributes holding the values the
//! specification's normalization gives (computed here, not by the reader), the same mesh
//! compressed by meshoptimizer's encoders (vertex codec with and without filters, the index
//! codecs of both modes) against the uncompressed file, and damaged compressed data giving
//! errors that name the file, never a panic.

use crate::common::{read, read_err, TempDir};
use serde_json::{json, Value};
use voxlod_testkit::Rng;

const BYTE: u32 = 5120;
const UNSIGNED_BYTE: u32 = 5121;
const SHORT: u32 = 5122;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const FLOAT: u32 = 5126;

/// One vertex attribute: `count` elements of `stride` bytes (a multiple of 4).
#[derive(Clone)]
struct Attr {
    name: &'static str,
    comp: u32,
    ty: &'static str,
    normalized: bool,
    stride: usize,
    data: Vec<u8>,
    /// A meshopt filter this attribute's bytes are already encoded with.
    filter: Option<&'static str>,
}

/// How the views are stored.
#[derive(Clone, Copy, PartialEq)]
enum Store {
    Plain,
    /// meshopt: vertices with the vertex codec, indices with the TRIANGLES or INDICES codec.
    Meshopt(&'static str),
}

fn comp_size(c: u32) -> usize {
    match c {
        BYTE | UNSIGNED_BYTE => 1,
        SHORT | UNSIGNED_SHORT => 2,
        _ => 4,
    }
}

fn dims(ty: &str) -> usize {
    match ty {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        _ => 4,
    }
}

/// Raw component `j` of element `i` as a number (the value `min`/`max` are given in).
fn raw(a: &Attr, i: usize, j: usize) -> f64 {
    let at = i * a.stride + j * comp_size(a.comp);
    let b = &a.data[at..];
    match a.comp {
        BYTE => b[0] as i8 as f64,
        UNSIGNED_BYTE => b[0] as f64,
        SHORT => i16::from_le_bytes([b[0], b[1]]) as f64,
        UNSIGNED_SHORT => u16::from_le_bytes([b[0], b[1]]) as f64,
        _ => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
    }
}

/// The value glTF 2.0 (3.11) gives a component: normalized integers mapped to [−1, 1] or
/// [0, 1], others as they are.
fn value(a: &Attr, i: usize, j: usize) -> f32 {
    let r = raw(a, i, j);
    let v = match (a.comp, a.normalized) {
        (BYTE, true) => (r / 127.0).max(-1.0),
        (UNSIGNED_BYTE, true) => r / 255.0,
        (SHORT, true) => (r / 32767.0).max(-1.0),
        (UNSIGNED_SHORT, true) => r / 65535.0,
        _ => r,
    };
    v as f32
}

/// The same attribute with FLOAT components holding [`value`]s.
fn as_float(a: &Attr, count: usize) -> Attr {
    let k = dims(a.ty);
    let mut data = Vec::new();
    for i in 0..count {
        for j in 0..k {
            data.extend_from_slice(&value(a, i, j).to_le_bytes());
        }
    }
    Attr {
        comp: FLOAT,
        normalized: false,
        stride: 4 * k,
        data,
        filter: None,
        ..a.clone()
    }
}

/// Little-endian bytes as elements of `W` words.
fn words<const W: usize>(data: &[u8]) -> Vec<[u32; W]> {
    data.chunks_exact(4 * W)
        .map(|e| {
            std::array::from_fn(|k| u32::from_le_bytes(e[4 * k..4 * k + 4].try_into().unwrap()))
        })
        .collect()
}

// meshoptimizer's encoders and filters through the `meshopt` crate's bindings (its safe
// wrappers take fixed element types); each call gets buffers of the sizes it reads and writes.

/// meshoptimizer's vertex codec (version 0, the one `EXT_meshopt_compression` allows) over
/// elements of `stride` bytes.
fn encode_vertices(data: &[u8], stride: usize) -> Vec<u8> {
    let n = data.len() / stride;
    // SAFETY: a size computation only
    let bound = unsafe { meshopt::ffi::meshopt_encodeVertexBufferBound(n, stride) };
    let mut out = vec![0u8; bound];
    // SAFETY: `out` holds the bound the encoder may write; `data` holds n × stride bytes.
    let len = unsafe {
        meshopt::ffi::meshopt_encodeVertexBufferLevel(
            out.as_mut_ptr(),
            out.len(),
            data.as_ptr().cast(),
            n,
            stride,
            2,
            0,
        )
    };
    assert!(len > 0);
    out.truncate(len);
    out
}

/// meshoptimizer's index sequence codec.
fn encode_index_sequence(idx: &[u32], vertices: usize) -> Vec<u8> {
    // SAFETY: a size computation only
    let bound = unsafe { meshopt::ffi::meshopt_encodeIndexSequenceBound(idx.len(), vertices) };
    let mut out = vec![0u8; bound];
    // SAFETY: `out` holds the bound the encoder may write; `idx` its indices.
    let len = unsafe {
        meshopt::ffi::meshopt_encodeIndexSequence(
            out.as_mut_ptr(),
            out.len(),
            idx.as_ptr(),
            idx.len(),
        )
    };
    assert!(len > 0);
    out.truncate(len);
    out
}

/// A filter's decoder run over elements of `stride` bytes in `words`.
fn filter_words(
    words: &mut [u32],
    stride: usize,
    f: unsafe extern "C" fn(*mut std::ffi::c_void, usize, usize),
) {
    // SAFETY: `words` holds whole elements of `stride` bytes, aligned to 4.
    unsafe { f(words.as_mut_ptr().cast(), words.len() * 4 / stride, stride) }
}

/// A GLB of one triangle primitive under a node with `scale` and `translation`.
fn glb(
    attrs: &[Attr],
    count: usize,
    indices: &[u32],
    store: Store,
    scale: [f64; 3],
    translation: [f64; 3],
) -> Vec<u8> {
    let mut bin: Vec<u8> = Vec::new(); // the GLB's binary chunk (buffer 0)
    let mut fallback_len = 0usize; // buffer 1 when compressed
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attributes = serde_json::Map::new();
    let mut put = |bytes: &[u8], stride: Option<usize>, mode: &str, filter: Option<&str>| {
        let index = views.len();
        match store {
            Store::Plain => {
                let mut v =
                    json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
                if let Some(s) = stride {
                    v["byteStride"] = json!(s);
                }
                bin.extend_from_slice(bytes);
                bin.resize(bin.len().next_multiple_of(4), 0);
                views.push(v);
            }
            Store::Meshopt(index_mode) => {
                let (enc, s, m) = match stride {
                    Some(s) => (encode_vertices(bytes, s), s, "ATTRIBUTES"),
                    None => {
                        let idx: Vec<u32> = words::<1>(bytes).into_iter().map(|w| w[0]).collect();
                        let enc = if index_mode == "TRIANGLES" {
                            meshopt::encode_index_buffer(&idx, count).unwrap()
                        } else {
                            encode_index_sequence(&idx, count)
                        };
                        (enc, 4, index_mode)
                    }
                };
                let _ = mode;
                let mut ext = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": enc.len(),
                    "byteStride": s, "count": bytes.len() / s, "mode": m});
                if let Some(f) = filter {
                    ext["filter"] = json!(f);
                }
                let mut v = json!({"buffer": 1, "byteOffset": fallback_len, "byteLength": bytes.len(),
                    "extensions": {"EXT_meshopt_compression": ext}});
                if let Some(s) = stride {
                    v["byteStride"] = json!(s);
                }
                bin.extend_from_slice(&enc);
                bin.resize(bin.len().next_multiple_of(4), 0);
                fallback_len += bytes.len().next_multiple_of(4);
                views.push(v);
            }
        }
        index
    };
    for a in attrs {
        let view = put(&a.data, Some(a.stride), "ATTRIBUTES", a.filter);
        let k = dims(a.ty);
        let mut acc =
            json!({"bufferView": view, "componentType": a.comp, "count": count, "type": a.ty});
        if a.normalized {
            acc["normalized"] = json!(true);
        }
        if a.name == "POSITION" {
            let lo: Vec<f64> = (0..k)
                .map(|j| (0..count).map(|i| raw(a, i, j)).fold(f64::MAX, f64::min))
                .collect();
            let hi: Vec<f64> = (0..k)
                .map(|j| (0..count).map(|i| raw(a, i, j)).fold(f64::MIN, f64::max))
                .collect();
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        attributes.insert(a.name.into(), json!(accessors.len()));
        accessors.push(acc);
    }
    let ibytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let iview = put(&ibytes, None, "", None);
    accessors.push(json!({"bufferView": iview, "componentType": UNSIGNED_INT,
        "count": indices.len(), "type": "SCALAR"}));
    let mut buffers = vec![json!({"byteLength": bin.len().max(4)})];
    let mut used = vec!["KHR_mesh_quantization"];
    if let Store::Meshopt(_) = store {
        buffers.push(json!({"byteLength": fallback_len,
            "extensions": {"EXT_meshopt_compression": {"fallback": true}}}));
        used.push("EXT_meshopt_compression");
    }
    let doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": used,
        "extensionsRequired": used,
        "buffers": buffers,
        "bufferViews": views,
        "accessors": accessors,
        "meshes": [{"primitives": [{"attributes": attributes, "indices": accessors.len() - 1}]}],
        "nodes": [{"mesh": 0, "scale": scale, "translation": translation}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    });
    container(&doc, &bin)
}

fn container(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(doc).unwrap();
    j.resize(j.len().next_multiple_of(4), b' ');
    let mut b = bin.to_vec();
    if b.is_empty() {
        b.resize(4, 0);
    }
    b.resize(b.len().next_multiple_of(4), 0);
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + j.len() + 8 + b.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// A bumpy height field of `n × n` vertices: the grid positions in `0..=max` and the
/// triangles' indices (two per cell).
fn height_field(n: usize, max: f64) -> (Vec<[f64; 3]>, Vec<u32>) {
    let mut p = Vec::new();
    for z in 0..n {
        for x in 0..n {
            let (u, v) = (x as f64 / (n - 1) as f64, z as f64 / (n - 1) as f64);
            let h = 0.5 + 0.25 * (6.0 * u).sin() * (5.0 * v).cos();
            p.push([u * max, h * max, v * max]);
        }
    }
    let mut idx = Vec::new();
    for z in 0..n - 1 {
        for x in 0..n - 1 {
            let a = (z * n + x) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            idx.extend_from_slice(&[a, c, b, b, c, d]);
        }
    }
    (p, idx)
}

/// Elements of `k` components of type `comp` from `f(i, j)`, padded to a multiple of 4 bytes.
fn pack(count: usize, k: usize, comp: u32, f: impl Fn(usize, usize) -> f64) -> (Vec<u8>, usize) {
    let stride = (k * comp_size(comp)).next_multiple_of(4);
    let mut data = vec![0u8; count * stride];
    for i in 0..count {
        for j in 0..k {
            let x = f(i, j);
            let at = i * stride + j * comp_size(comp);
            let bytes: Vec<u8> = match comp {
                BYTE => vec![x.round() as i8 as u8],
                UNSIGNED_BYTE => vec![x.round() as u8],
                SHORT => (x.round() as i16).to_le_bytes().to_vec(),
                UNSIGNED_SHORT => (x.round() as u16).to_le_bytes().to_vec(),
                _ => (x as f32).to_le_bytes().to_vec(),
            };
            data[at..at + bytes.len()].copy_from_slice(&bytes);
        }
    }
    (data, stride)
}

fn normals(p: &[[f64; 3]], n: usize) -> Vec<[f64; 3]> {
    // the height field's normal by central differences, unit length
    (0..p.len())
        .map(|i| {
            let (x, z) = (i % n, i / n);
            let dx = p[z * n + (x + 1).min(n - 1)][1] - p[z * n + x.saturating_sub(1)][1];
            let dz = p[(z + 1).min(n - 1) * n + x][1] - p[z.saturating_sub(1) * n + x][1];
            let v = [-dx, 2.0 * p[1][0], -dz];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / l, v[1] / l, v[2] / l]
        })
        .collect()
}

/// The quantized attributes of the height field: positions of `pos_comp` (normalized or not),
/// normals of `nrm_comp` normalized, colours of UNSIGNED_SHORT normalized VEC3.
fn quantized(n: usize, pos_comp: u32, pos_norm: bool, nrm_comp: u32) -> Vec<Attr> {
    let range = match pos_comp {
        BYTE => 127.0,
        UNSIGNED_BYTE => 255.0,
        SHORT => 32767.0,
        _ => 65535.0,
    };
    let (p, _) = height_field(n, range);
    let nrm = normals(&p, n);
    let signed = matches!(pos_comp, BYTE | SHORT);
    let (pd, ps) = pack(p.len(), 3, pos_comp, |i, j| {
        if signed {
            p[i][j] - range / 2.0
        } else {
            p[i][j]
        }
    });
    let nmax = if nrm_comp == BYTE { 127.0 } else { 32767.0 };
    let (nd, ns) = pack(p.len(), 3, nrm_comp, |i, j| nrm[i][j] * nmax);
    let (cd, cs) = pack(p.len(), 3, UNSIGNED_SHORT, |i, j| {
        ((i * 7 + j * 13) % 100) as f64 / 100.0 * 65535.0
    });
    vec![
        Attr {
            name: "POSITION",
            comp: pos_comp,
            ty: "VEC3",
            normalized: pos_norm,
            stride: ps,
            data: pd,
            filter: None,
        },
        Attr {
            name: "NORMAL",
            comp: nrm_comp,
            ty: "VEC3",
            normalized: true,
            stride: ns,
            data: nd,
            filter: None,
        },
        Attr {
            name: "COLOR_0",
            comp: UNSIGNED_SHORT,
            ty: "VEC3",
            normalized: true,
            stride: cs,
            data: cd,
            filter: None,
        },
    ]
}

#[test]
fn every_quantized_component_type_reads_as_its_float_values() {
    let d = TempDir::new("gltfquant");
    let n = 12;
    let (_, idx) = height_field(n, 1.0);
    let count = n * n;
    let (scale, translation) = ([0.01, 0.02, 0.01], [1.0, -2.0, 3.5]);
    for pos_comp in [BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT] {
        for pos_norm in [false, true] {
            for nrm_comp in [BYTE, SHORT] {
                let q = quantized(n, pos_comp, pos_norm, nrm_comp);
                let f: Vec<Attr> = q.iter().map(|a| as_float(a, count)).collect();
                let qp = d.write(
                    "q.glb",
                    glb(&q, count, &idx, Store::Plain, scale, translation),
                );
                let (got, st) = read(&qp).unwrap();
                let fp = d.write(
                    "f.glb",
                    glb(&f, count, &idx, Store::Plain, scale, translation),
                );
                let (want, _) = read(&fp).unwrap();
                let case = format!("POSITION {pos_comp} normalized {pos_norm}, NORMAL {nrm_comp}");
                assert_eq!(st.triangles as usize, idx.len() / 3, "{case}");
                assert_eq!(got.len(), want.len(), "{case}");
                for (g, w) in got.iter().zip(&want) {
                    assert_eq!((g.v, g.n, g.c, g.flags), (w.v, w.n, w.c, w.flags), "{case}");
                }
                // the node's transform applies to the integers: a vertex from its raw values
                let a = &q[0];
                let v0 = got[0].v[0];
                let i0 = idx[0] as usize;
                for k in 0..3 {
                    let want = value(a, i0, k) as f64 * scale[k] + translation[k];
                    assert!(
                        (v0[k] as f64 - want).abs() < 1e-5 + 1e-6 * want.abs(),
                        "{case}: {v0:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn integer_attributes_need_the_quantization_extension() {
    let d = TempDir::new("gltfnoquant");
    let n = 4;
    let (_, idx) = height_field(n, 1.0);
    let q = quantized(n, UNSIGNED_SHORT, false, BYTE);
    let bytes = glb(&q, n * n, &idx, Store::Plain, [1.0; 3], [0.0; 3]);
    // the same file without KHR_mesh_quantization declared
    let p = d.write(
        "plain.glb",
        edited(&bytes, |doc| {
            let o = doc.as_object_mut().unwrap();
            o.remove("extensionsUsed").unwrap();
            o.remove("extensionsRequired").unwrap();
        }),
    );
    let e = read_err(&p);
    assert!(
        e.contains("must be VEC3 of FLOAT") && e.contains("KHR_mesh_quantization"),
        "{e}"
    );
    assert!(e.contains("plain.glb"), "{e}");
}

/// The height field's quantized attributes plus a normal encoded with meshopt's octahedral
/// filter and a float attribute with its exponential filter: (the attributes as compressed,
/// the same attributes with the filters undone, for the uncompressed file).
fn filtered(n: usize) -> (Vec<Attr>, Vec<Attr>) {
    let q = quantized(n, UNSIGNED_SHORT, false, SHORT);
    let count = n * n;
    let (p, _) = height_field(n, 65535.0);
    let nrm = normals(&p, n);
    let oct_in: Vec<f32> = nrm
        .iter()
        .flat_map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
        .collect();
    let mut oct = vec![0u32; 2 * count];
    // SAFETY: `count` elements of 8 bytes written from `count` × 4 floats.
    unsafe {
        meshopt::ffi::meshopt_encodeFilterOct(
            oct.as_mut_ptr().cast(),
            count,
            8,
            12,
            oct_in.as_ptr(),
        )
    };
    let mut oct_plain = oct.clone();
    filter_words(&mut oct_plain, 8, meshopt::ffi::meshopt_decodeFilterOct);
    let uv: Vec<f32> = (0..count)
        .flat_map(|i| [(i % n) as f32 / n as f32, (i / n) as f32 * 0.37])
        .collect();
    let mut exp = vec![0u32; 2 * count];
    // SAFETY: `count` elements of 8 bytes written from `count` × 2 floats.
    unsafe {
        meshopt::ffi::meshopt_encodeFilterExp(
            exp.as_mut_ptr().cast(),
            count,
            8,
            15,
            uv.as_ptr(),
            meshopt::ffi::meshopt_EncodeExpMode_meshopt_EncodeExpSeparate,
        )
    };
    let mut exp_plain = exp.clone();
    filter_words(&mut exp_plain, 8, meshopt::ffi::meshopt_decodeFilterExp);
    let bytes = |w: &[u32]| -> Vec<u8> { w.iter().flat_map(|x| x.to_ne_bytes()).collect() };
    let normal = |data: Vec<u8>, filter| Attr {
        name: "NORMAL",
        comp: SHORT,
        ty: "VEC3",
        normalized: true,
        stride: 8,
        data,
        filter,
    };
    let uv_attr = |data: Vec<u8>, filter| Attr {
        name: "TEXCOORD_0",
        comp: FLOAT,
        ty: "VEC2",
        normalized: false,
        stride: 8,
        data,
        filter,
    };
    let pos = q[0].clone();
    let col = q[2].clone();
    let compressed = vec![
        pos.clone(),
        normal(bytes(&oct), Some("OCTAHEDRAL")),
        col.clone(),
        uv_attr(bytes(&exp), Some("EXPONENTIAL")),
    ];
    let plain = vec![
        pos,
        normal(bytes(&oct_plain), None),
        col,
        uv_attr(bytes(&exp_plain), None),
    ];
    (compressed, plain)
}

#[test]
fn meshopt_compressed_views_read_as_the_uncompressed_file() {
    let d = TempDir::new("gltfmeshopt");
    let n = 16;
    let (_, idx) = height_field(n, 1.0);
    let count = n * n;
    let (compressed, plain) = filtered(n);
    let want_path = d.write(
        "plain.glb",
        glb(&plain, count, &idx, Store::Plain, [1e-3; 3], [0.0; 3]),
    );
    let (want, _) = read(&want_path).unwrap();
    assert_eq!(want.len(), idx.len() / 3);
    for mode in ["TRIANGLES", "INDICES"] {
        let bytes = glb(
            &compressed,
            count,
            &idx,
            Store::Meshopt(mode),
            [1e-3; 3],
            [0.0; 3],
        );
        let plain_len = std::fs::metadata(&want_path).unwrap().len() as usize;
        assert!(
            bytes.len() < plain_len,
            "{mode}: {} vs {plain_len}",
            bytes.len()
        );
        let p = d.write("c.glb", &bytes);
        let (got, _) = read(&p).unwrap();
        assert_eq!(got.len(), want.len(), "{mode}");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.v, g.n, g.c), (w.v, w.n, w.c), "{mode}");
        }
        let info = voxlod_ingest::MeshSource::open(&p).unwrap();
        assert!(
            info.info().warnings.is_empty(),
            "{:?}",
            info.info().warnings
        );
    }
}

/// The GLB `glb` with its JSON changed by `f`.
fn edited(glb: &[u8], f: impl FnOnce(&mut Value)) -> Vec<u8> {
    let bin = bin_range(glb);
    let mut doc: Value = serde_json::from_slice(&glb[20..bin.start - 8]).unwrap();
    f(&mut doc);
    container(&doc, &glb[bin])
}

/// The byte range of the GLB's binary chunk.
fn bin_range(glb: &[u8]) -> std::ops::Range<usize> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let start = 20 + json_len + 8;
    start..glb.len()
}

#[test]
fn damaged_compressed_data_is_an_error_naming_the_file_never_a_panic() {
    let d = TempDir::new("gltfmeshoptfuzz");
    let n = 10;
    let (_, idx) = height_field(n, 1.0);
    let (compressed, _) = filtered(n);
    let good = glb(
        &compressed,
        n * n,
        &idx,
        Store::Meshopt("TRIANGLES"),
        [1.0; 3],
        [0.0; 3],
    );
    let bin = bin_range(&good);
    let mut rng = Rng(0x6d65_7368);
    let (mut errors, mut read_ok) = (0, 0);
    for round in 0..300 {
        let mut b = good.clone();
        match round % 3 {
            // flip a few bytes of the compressed data
            0 | 1 => {
                for _ in 0..1 + round % 4 {
                    let at = bin.start + rng.below((bin.end - bin.start) as u64) as usize;
                    b[at] ^= 1 + rng.below(255) as u8;
                }
            }
            // zero a run of it
            _ => {
                let at = bin.start + rng.below((bin.end - bin.start) as u64) as usize;
                let end = (at + 1 + rng.below(64) as usize).min(bin.end);
                b[at..end].fill(0);
            }
        }
        let p = d.write("m.glb", &b);
        // the decoders return an error or other data: either way no panic, and an error names
        // the file
        match read(&p) {
            Ok(_) => read_ok += 1,
            Err(e) => {
                let m = e.to_string();
                assert!(m.contains("m.glb") && !m.contains("panic"), "{m}");
                errors += 1;
            }
        }
    }
    assert!(errors > 0, "no damage was noticed ({read_ok} read)");
    // a compressed view cut short, a wrong count, an unknown mode or filter: the rule is named
    // views 0..3: POSITION, NORMAL (OCTAHEDRAL), COLOR_0, TEXCOORD_0 (EXPONENTIAL); 4: indices
    let ext = |doc: &mut Value, view: usize| -> Value {
        doc["bufferViews"][view]["extensions"]["EXT_meshopt_compression"].take()
    };
    type Edit = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|c| c["mode"] = json!("TRIANGLE")),
            "mode \"TRIANGLE\" is not ATTRIBUTES, TRIANGLES or INDICES",
        ),
        (
            Box::new(|c| c["filter"] = json!("OCTAHEDRON")),
            "filter \"OCTAHEDRON\" is not one the extension defines",
        ),
        (
            Box::new(|c| c["byteStride"] = json!(6)),
            "multiple of 4 up to 256, not 6",
        ),
        (
            Box::new(|c| c["count"] = json!(7)),
            "must equal the view's byteLength",
        ),
        (
            Box::new(|c| c["byteLength"] = json!(c["byteLength"].as_u64().unwrap() / 2)),
            "corrupt or truncated",
        ),
        (
            Box::new(|c| c["byteOffset"] = json!(1u64 << 40)),
            "lie outside buffer 0",
        ),
    ];
    // a few bytes declaring 8 GiB: refused before anything is allocated
    let bomb = edited(&good, |doc| {
        let n = 1u64 << 30;
        let stride = doc["bufferViews"][0]["byteStride"].as_u64().unwrap();
        doc["buffers"][1]["byteLength"] = json!(n * stride);
        doc["bufferViews"][0]["byteOffset"] = json!(0);
        doc["bufferViews"][0]["byteLength"] = json!(n * stride);
        doc["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(n);
    });
    let e = read_err(&d.write("bomb.glb", bomb));
    assert!(
        e.contains("bomb.glb") && e.contains("more than meshoptimizer's codecs can make"),
        "{e}"
    );
    for (view, file) in [(1, "n.glb"), (0, "p.glb")] {
        for (edit, says) in &cases {
            let b = edited(&good, |doc| {
                let mut c = ext(doc, view);
                edit(&mut c);
                doc["bufferViews"][view]["extensions"]["EXT_meshopt_compression"] = c;
            });
            let p = d.write(file, &b);
            let e = read_err(&p);
            assert!(
                e.contains(says) && e.contains(file) && e.contains(&format!("bufferView {view}")),
                "{says}: {e}"
            );
        }
    }
}
