//! The generated block world against the tests' own reading of it: the same size and seed
//! give the same bytes (another seed another world); the OBJ's faces are exactly the exposed
//! faces of the block grid, found by brute force over every block and its six neighbours,
//! each with the material of its side of its block and the texture upright; the textures
//! decode to the generator's texels; bad outputs are clear errors that leave nothing behind.

use crate::common;

use std::collections::HashSet;
use std::path::Path;

use common::{at, material_name, read_quads, shown};
use voxlod_blocks::{write_world, Block, Material, World, DIRS};

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn the_same_seed_gives_the_same_bytes() {
    let write = |seed: u64| {
        let d = tempfile::tempdir().unwrap();
        let w = World::generate(48, seed).unwrap();
        let out = write_world(&w, &d.path().join("w.obj"), false).unwrap();
        assert_eq!(out.files.len(), 11);
        (files(d.path()), d)
    };
    let (a, _da) = write(5);
    let (b, _db) = write(5);
    let (c, _dc) = write(6);
    assert_eq!(a.len(), 11, "OBJ, MTL, 9 textures and nothing else");
    assert!(a == b, "same seed, different bytes");
    assert_ne!(
        a[a.len() - 1].1,
        c[c.len() - 1].1,
        "another seed, the same OBJ"
    );
}

#[test]
fn faces_are_exactly_the_exposed_ones() {
    let d = tempfile::tempdir().unwrap();
    let w = World::generate(64, 3).unwrap();
    let obj = d.path().join("world.obj");
    let written = write_world(&w, &obj, false).unwrap();
    let quads = read_quads(&obj);
    assert_eq!(quads.len() as u64, written.faces);

    let mut seen = HashSet::new();
    let mut materials = HashSet::new();
    for q in &quads {
        let (axis, sign) = q.normal();
        let b = q.block();
        let mut n = b;
        n[axis] += sign;
        let (block, neighbour) = (at(&w, b), at(&w, n));
        assert!(
            shown(block, neighbour),
            "face of {block:?} at {b:?} towards {neighbour:?}"
        );
        assert_eq!(
            q.material,
            material_name(block, axis, sign),
            "block {b:?} axis {axis}"
        );
        assert!(
            seen.insert((b, axis, sign)),
            "face {b:?} {axis} {sign} twice"
        );
        materials.insert(q.material.clone());
        // the texture spans the face: (0,0) (1,0) (1,1) (0,1) in order, upright on the sides
        assert_eq!(q.uv, [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        if axis != 1 {
            assert_eq!(
                q.corners[3][1] - q.corners[0][1],
                1,
                "texture upside down at {b:?}"
            );
            assert_eq!(q.corners[2][1] - q.corners[1][1], 1);
        }
    }
    // brute force: every block of the grid and the air around it, every neighbour
    let s = w.size() as i64;
    let mut exposed = 0;
    for z in -1..=s {
        for y in -1..=w.top() as i64 {
            for x in -1..=s {
                let b = at(&w, [x, y, z]);
                for d in DIRS {
                    exposed += shown(b, at(&w, [x + d[0], y + d[1], z + d[2]])) as usize;
                }
            }
        }
    }
    assert_eq!(exposed, quads.len(), "faces missing from the OBJ");
    // a world of this size shows every material
    assert_eq!(materials.len(), Material::ALL.len(), "{materials:?}");
    assert!(w.trees() > 0);
    assert_eq!(at(&w, [0, 0, 0]), Block::Stone);
}

#[test]
fn textures_decode_to_the_generated_texels() {
    let d = tempfile::tempdir().unwrap();
    let w = World::generate(32, 1).unwrap();
    let obj = d.path().join("t.obj");
    write_world(&w, &obj, false).unwrap();
    let mtl = std::fs::read_to_string(d.path().join("t.mtl")).unwrap();
    for m in Material::ALL {
        assert!(mtl.contains(&format!(
            "newmtl {}\nKd 1 1 1\nmap_Kd -clamp on t-{}.png\n",
            m.name(),
            m.name()
        )));
        let img = common::texture(&obj, m.name());
        assert_eq!(img.dimensions(), (16, 16));
        let got: Vec<[u8; 4]> = img.pixels().map(|p| p.0).collect();
        assert_eq!(got, voxlod_blocks::texels(m), "{m:?}");
    }
}

#[test]
fn bad_outputs_are_clear_errors_and_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    let w = World::generate(32, 1).unwrap();
    let err = |p: &Path| write_world(&w, p, false).unwrap_err().to_string();
    let e = err(&d.path().join("w.ply"));
    assert!(e.contains("w.ply") && e.contains("OBJ"), "{e}");
    let e = err(&d.path().join("no/such/w.obj"));
    assert!(e.contains("no such folder"), "{e}");
    let e = err(&d.path().join("a b.obj"));
    assert!(e.contains("white space"), "{e}");
    assert!(files(d.path()).is_empty());
    // an existing texture is not replaced without force, and nothing else is written
    std::fs::write(d.path().join("w-sand.png"), b"mine").unwrap();
    let e = err(&d.path().join("w.obj"));
    assert!(e.contains("w-sand.png") && e.contains("--force"), "{e}");
    assert_eq!(files(d.path()).len(), 1);
    // a part file left by a killed run (no such process) is removed, one of a live one kept
    let stale = d.path().join(".w.mtl.part-4294967295");
    let live = d.path().join(".w.obj.part-1"); // pid 1 always runs
    std::fs::write(&stale, b"half").unwrap();
    std::fs::write(&live, b"busy").unwrap();
    write_world(&w, &d.path().join("w.obj"), true).unwrap();
    assert!(!stale.exists());
    std::fs::remove_file(&live).unwrap();
    assert_eq!(files(d.path()).len(), 11);
    for (s, e) in [(31, "31"), (4096, "4096")] {
        let m = World::generate(s, 1).err().unwrap().to_string();
        assert!(m.contains(e) && m.contains("32 to 2048"), "{m}");
    }
}
