//! Textured OBJ to textured PLY, for tests that compare the PLY texture conventions against
//! the OBJ reading of the same mesh (docs/TEXTURES.md). Written from the two formats'
//! descriptions, sharing no code with `voxlod-ingest`: `v` and `vt` lines and `f` corners
//! `v/vt[/vn]` (positive indices), polygons kept whole; positions and texture coordinates are
//! parsed as `f32` as an OBJ reader does and written as binary little-endian `float`, so both
//! readers see the same bits.

use std::io::Write;
use std::path::Path;

/// Where the PLY carries the texture coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Convention {
    /// Per vertex (`float s`, `float t`): each distinct (`v`, `vt`) pair of the OBJ becomes one
    /// PLY vertex (seams split).
    VertexST,
    /// Per face (`list uchar float texcoord`, two per corner, MeshLab/OpenMVS): the OBJ's
    /// vertices as they are.
    FaceTexcoord,
}

/// A textured OBJ read into positions, texture coordinates and polygons of (v, vt) corners.
struct Obj {
    v: Vec<[f32; 3]>,
    vt: Vec<[f32; 2]>,
    faces: Vec<Vec<(usize, usize)>>,
}

fn read_obj(path: &Path) -> Obj {
    let text = std::fs::read_to_string(path).unwrap();
    let mut o = Obj {
        v: Vec::new(),
        vt: Vec::new(),
        faces: Vec::new(),
    };
    let num = |s: &str| s.parse::<f32>().unwrap();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("v") => o.v.push([num(t[1]), num(t[2]), num(t[3])]),
            Some("vt") => o.vt.push([num(t[1]), num(t[2])]),
            Some("f") => o.faces.push(
                t[1..]
                    .iter()
                    .map(|c| {
                        let mut p = c.split('/');
                        let mut ix = || p.next().unwrap().parse::<usize>().unwrap() - 1;
                        (ix(), ix())
                    })
                    .collect(),
            ),
            _ => {}
        }
    }
    o
}

/// Writes `obj` (every face with `vt` indices) as a binary little-endian PLY at `out` with
/// `comment TextureFile texture`, the texture coordinates in `convention`, and every vertex
/// coloured `rgba` (the OBJ material's `Kd` and `d` as bytes, so that both meshes carry the
/// same colour).
pub fn obj_to_textured_ply(
    obj: &Path,
    out: &Path,
    texture: &str,
    convention: Convention,
    rgba: [u8; 4],
) {
    let o = read_obj(obj);
    // the PLY's vertices (position index, vt index) and each face's corners among them
    let (verts, faces): (Vec<(usize, usize)>, Vec<Vec<usize>>) = match convention {
        Convention::FaceTexcoord => (
            (0..o.v.len()).map(|i| (i, 0)).collect(),
            o.faces
                .iter()
                .map(|f| f.iter().map(|c| c.0).collect())
                .collect(),
        ),
        Convention::VertexST => {
            let mut ids = std::collections::HashMap::new();
            let mut verts = Vec::new();
            let faces = o
                .faces
                .iter()
                .map(|f| {
                    f.iter()
                        .map(|&c| {
                            *ids.entry(c).or_insert_with(|| {
                                verts.push(c);
                                verts.len() - 1
                            })
                        })
                        .collect()
                })
                .collect();
            (verts, faces)
        }
    };
    let st = convention == Convention::VertexST;
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\ncomment TextureFile {texture}\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        verts.len()
    );
    if st {
        h += "property float s\nproperty float t\n";
    }
    h += "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n";
    h += &format!(
        "element face {}\nproperty list uchar int vertex_indices\n",
        faces.len()
    );
    if !st {
        h += "property list uchar float texcoord\n";
    }
    h += "end_header\n";
    let mut b = h.into_bytes();
    let f32s = |b: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| b.extend(x.to_le_bytes()));
    for &(vi, ti) in &verts {
        f32s(&mut b, &o.v[vi]);
        if st {
            f32s(&mut b, &o.vt[ti]);
        }
        b.extend(rgba);
    }
    for (f, src) in faces.iter().zip(&o.faces) {
        b.push(f.len() as u8);
        f.iter().for_each(|&i| b.extend((i as i32).to_le_bytes()));
        if !st {
            b.push(2 * src.len() as u8);
            for c in src {
                f32s(&mut b, &o.vt[c.1]);
            }
        }
    }
    std::fs::File::create(out).unwrap().write_all(&b).unwrap();
}
