//! A tiny independent PLY/OBJ/STL writer for the tests: it shares no code with the reader.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use voxlod_geom::Triangle;
use voxlod_ingest::{IngestError, IngestStats, MeshSource};

#[derive(Clone, Debug)]
pub enum V {
    S(f64),
    L(Vec<f64>),
}

pub struct El {
    pub name: &'static str,
    /// Property declarations as written after "property ".
    pub props: Vec<&'static str>,
    pub rows: Vec<Vec<V>>,
}

fn put(out: &mut Vec<u8>, ty: &str, v: f64, be: bool) {
    macro_rules! w {
        ($t:ty) => {{
            let x = v as $t;
            out.extend_from_slice(&if be { x.to_be_bytes() } else { x.to_le_bytes() });
        }};
    }
    match ty {
        "char" | "int8" => w!(i8),
        "uchar" | "uint8" => w!(u8),
        "short" | "int16" => w!(i16),
        "ushort" | "uint16" => w!(u16),
        "int" | "int32" => w!(i32),
        "uint" | "uint32" => w!(u32),
        "float" | "float32" => w!(f32),
        "double" | "float64" => w!(f64),
        _ => panic!("bad type {ty}"),
    }
}

fn text(ty: &str, v: f64) -> String {
    match ty {
        "float" | "float32" => format!("{}", v as f32),
        "double" | "float64" => format!("{v}"),
        _ => format!("{}", v as i64),
    }
}

/// Encodes a PLY file; `enc` is "ascii", "binary_little_endian" or "binary_big_endian".
pub fn ply(enc: &str, els: &[El]) -> Vec<u8> {
    ply_commented(enc, &[], els)
}

/// [`ply`] with the header comment lines `comments` (each written after "comment ").
pub fn ply_commented(enc: &str, comments: &[&str], els: &[El]) -> Vec<u8> {
    let mut out = Vec::new();
    write!(
        out,
        "ply\nformat {enc} 1.0\ncomment written by the voxlod-ingest tests\n"
    )
    .unwrap();
    for c in comments {
        writeln!(out, "comment {c}").unwrap();
    }
    for e in els {
        writeln!(out, "element {} {}", e.name, e.rows.len()).unwrap();
        for p in &e.props {
            writeln!(out, "property {p}").unwrap();
        }
    }
    out.extend_from_slice(b"end_header\n");
    let be = enc == "binary_big_endian";
    for e in els {
        for row in &e.rows {
            assert_eq!(row.len(), e.props.len());
            let mut line = Vec::new();
            for (p, v) in e.props.iter().zip(row) {
                let t: Vec<&str> = p.split_whitespace().collect();
                match v {
                    V::S(x) => {
                        if enc == "ascii" {
                            line.push(text(t[0], *x));
                        } else {
                            put(&mut out, t[0], *x, be);
                        }
                    }
                    V::L(xs) => {
                        assert_eq!(t[0], "list");
                        if enc == "ascii" {
                            line.push(xs.len().to_string());
                            line.extend(xs.iter().map(|x| text(t[2], *x)));
                        } else {
                            put(&mut out, t[1], xs.len() as f64, be);
                            for x in xs {
                                put(&mut out, t[2], *x, be);
                            }
                        }
                    }
                }
            }
            if enc == "ascii" {
                writeln!(out, "{}", line.join(" ")).unwrap();
            }
        }
    }
    out
}

pub fn gzip(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

pub fn stl_binary(tris: &[[[f32; 3]; 3]], header: &[u8]) -> Vec<u8> {
    let mut out = vec![b' '; 80];
    out[..header.len()].copy_from_slice(header);
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        out.extend_from_slice(&[0u8; 12]); // facet normal, ignored
        for v in t {
            for x in v {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

pub fn stl_ascii(tris: &[[[f32; 3]; 3]]) -> String {
    let mut s = String::from("solid test\n");
    for t in tris {
        s += "  facet normal 0 0 1\n    outer loop\n";
        for v in t {
            s += &format!("      vertex {} {} {}\n", v[0], v[1], v[2]);
        }
        s += "    endloop\n  endfacet\n";
    }
    s + "endsolid test\n"
}

pub struct TempDir(pub tempfile::TempDir);
impl TempDir {
    pub fn new(tag: &str) -> Self {
        TempDir(
            tempfile::Builder::new()
                .prefix(&format!("voxlod-ingest-{tag}-"))
                .tempdir()
                .unwrap(),
        )
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }
    pub fn write(&self, name: &str, data: impl AsRef<[u8]>) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, data).unwrap();
        p
    }
}

pub fn read(path: &Path) -> Result<(Vec<Triangle>, IngestStats), IngestError> {
    let src = MeshSource::open(path)?;
    let mut tris = Vec::new();
    let st = src.stream(
        &mut |b| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )?;
    Ok((tris, st))
}

/// Opens and streams, expecting an error; returns its message.
pub fn read_err(path: &Path) -> String {
    match read(path) {
        Ok((t, _)) => panic!(
            "{} read fine ({} triangles) but should fail",
            path.display(),
            t.len()
        ),
        Err(e) => e.to_string(),
    }
}
