//! A reader of the block world's OBJ written for the tests from the OBJ format alone (no code
//! shared with `voxlod-blocks` or `voxlod-ingest`), and the tests' own statement of which
//! faces a block world shows and with which material.

#![allow(dead_code)]

use std::path::Path;

use voxlod_blocks::{Block, World};

/// One face: two triangles `(a, b, c)`, `(a, c, d)` of the OBJ joined, corners in that order.
pub struct Quad {
    /// Corner positions (integers: the OBJ writes them so).
    pub corners: [[i64; 3]; 4],
    /// Texture coordinates of the corners.
    pub uv: [[f64; 2]; 4],
    /// The `usemtl` name in force.
    pub material: String,
}

impl Quad {
    /// The outward normal (from the winding) as (axis, sign).
    pub fn normal(&self) -> (usize, i64) {
        let c = self.corners;
        let e1: [i64; 3] = std::array::from_fn(|k| c[1][k] - c[0][k]);
        let e2: [i64; 3] = std::array::from_fn(|k| c[2][k] - c[0][k]);
        let n = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        let a = (0..3).find(|&a| n[a] != 0).expect("a degenerate face");
        assert_eq!(n.iter().filter(|&&v| v != 0).count(), 1, "not axis-aligned");
        assert_eq!(n[a].abs(), 1, "not a unit face");
        (a, n[a])
    }

    /// The block behind the face (on the side opposite its normal).
    pub fn block(&self) -> [i64; 3] {
        let (a, s) = self.normal();
        let mut b: [i64; 3] =
            std::array::from_fn(|k| self.corners.iter().map(|c| c[k]).min().unwrap());
        if s > 0 {
            b[a] -= 1;
        }
        b
    }
}

/// Reads `v`, `vt`, `usemtl` and `f v/vt` lines, pairing consecutive triangles into quads.
pub fn read_quads(path: &Path) -> Vec<Quad> {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut v, mut vt, mut mtl) = (Vec::new(), Vec::new(), String::new());
    let mut tris: Vec<([usize; 3], [usize; 3], String)> = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("v") => v.push([1, 2, 3].map(|i| t[i].parse::<i64>().unwrap())),
            Some("vt") => vt.push([1, 2].map(|i| t[i].parse::<f64>().unwrap())),
            Some("usemtl") => mtl = t[1].to_string(),
            Some("f") => {
                assert_eq!(t.len(), 4, "triangles only: {line}");
                let c = |i: usize, k: usize| -> usize {
                    t[i].split('/').nth(k).unwrap().parse::<usize>().unwrap() - 1
                };
                tris.push((
                    [1, 2, 3].map(|i| c(i, 0)),
                    [1, 2, 3].map(|i| c(i, 1)),
                    mtl.clone(),
                ));
            }
            _ => {}
        }
    }
    assert_eq!(tris.len() % 2, 0);
    tris.chunks_exact(2)
        .map(|p| {
            let (a, b) = (&p[0], &p[1]);
            assert_eq!(
                (a.0[0], a.0[2], a.2.as_str()),
                (b.0[0], b.0[1], b.2.as_str())
            );
            let ids = [a.0[0], a.0[1], a.0[2], b.0[2]];
            let tex = [a.1[0], a.1[1], a.1[2], b.1[2]];
            Quad {
                corners: ids.map(|i| v[i]),
                uv: tex.map(|i| vt[i]),
                material: a.2.clone(),
            }
        })
        .collect()
}

/// The tests' rule: a face is shown where the neighbour is air, or water seen from a block
/// that is not water.
pub fn shown(b: Block, n: Block) -> bool {
    b != Block::Air && (n == Block::Air || (n == Block::Water && b != Block::Water))
}

/// The tests' table of face materials: `axis`, `sign` of the outward normal.
pub fn material_name(b: Block, axis: usize, sign: i64) -> &'static str {
    let vertical = axis == 1;
    match b {
        Block::Grass if vertical && sign > 0 => "grass_top",
        Block::Grass if vertical => "dirt",
        Block::Grass => "grass_side",
        Block::Dirt => "dirt",
        Block::Stone => "stone",
        Block::Sand => "sand",
        Block::Water => "water",
        Block::Log if vertical => "log_top",
        Block::Log => "log_side",
        Block::Leaves => "leaves",
        Block::Air => panic!("air has no faces"),
    }
}

/// The world's block at `p`.
pub fn at(w: &World, p: [i64; 3]) -> Block {
    w.block(p[0], p[1], p[2])
}

/// The texture `NAME-MATERIAL.png` beside `obj`, decoded by the `image` crate: RGBA rows from
/// the top.
pub fn texture(obj: &Path, material: &str) -> image::RgbaImage {
    let stem = obj.file_stem().unwrap().to_string_lossy();
    let p = obj.with_file_name(format!("{stem}-{material}.png"));
    image::open(&p).unwrap().to_rgba8()
}
