//! voxlod reads what it writes, and glTF compressed by an independent tool (docs/INGEST.md
//! "glTF").
//!
//! Round trip: a level exported as GLB (`KHR_mesh_quantization`: unsigned-short positions,
//! normalized-short normals) and built again at that level's resolution gives the level's
//! voxels back within what the round trip allows. The grids are not the same (the build fits
//! its cube to the quads' bounds, which are the voxels' bounds, not the mesh's), and every
//! exported face lies on a voxel boundary, where a conservative build marks the voxels on both
//! sides; so, asserted in world coordinates: every voxel of each file has its centre within one
//! voxel (Chebyshev, in the other file's grid) of a voxel of the other, the built-back file has
//! 1 to 2.2 times the voxels (the shell thickens to both sides of each face), matched voxels'
//! normals agree (mean dot > 0.9), and every quad is read (two triangles each).
//!
//! Independent producer: gltf-transform (npm `@gltf-transform/cli`, pinned in tests/node)
//! turns that GLB into FLOAT attributes (`dequantize`), and compresses the plain file with
//! `EXT_meshopt_compression` (`meshopt`: `KHR_mesh_quantization` with 14-bit positions and
//! 10-bit normals, vertex and index codecs, filters). Built at the same resolution, the plain
//! file gives exactly the voxels of voxlod's own GLB; the compressed one stays within one voxel of
//! the plain file's, and at least 70 % are the very same voxels (the quantization moves faces
//! lying on voxel boundaries to one side). A scan's triangles (the bundled bunny, written as a
//! plain GLB by the test kit) and their meshopt-compressed copy: every voxel within one voxel
//! of the other's and at least 98 % the same.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use voxlod_format::Reader;

use super::{build_ok, ok, sample, voxlod, REPO};

/// A file's voxels of `level`: integer positions in that level's grid and their normals.
struct Voxels {
    origin: [f64; 3],
    edge: f64,
    pos: Vec<[i64; 3]>,
    normal: Vec<[f32; 3]>,
    set: HashSet<[i64; 3]>,
}

fn voxels(path: &Path, level: u32) -> Voxels {
    let r = Reader::open(path).unwrap();
    let s = r.spec();
    let (mut pos, mut normal) = (Vec::new(), Vec::new());
    for (i, n) in r.nodes().iter().enumerate() {
        if n.level != level {
            continue;
        }
        for v in r.read_node(i).unwrap() {
            let (p, chunk) = (v.pos(), [n.x, n.y, n.z]);
            pos.push(std::array::from_fn(|a| chunk[a] as i64 * 256 + p[a] as i64));
            normal.push(v.normal_f32());
        }
    }
    let set = pos.iter().copied().collect();
    Voxels {
        origin: s.origin,
        edge: s.voxel_size * (1u64 << level) as f64,
        pos,
        normal,
        set,
    }
}

/// How `a`'s voxels sit in `b`: the share whose centre is within one voxel (Chebyshev, in
/// `b`'s grid) of a voxel of `b`, the share exactly on one (the centre inside it), and the
/// mean dot product of the normals of the voxel of `b` the centre falls in (where it does).
fn within(a: &Voxels, b: &Voxels) -> (f64, f64, f64) {
    let (mut near, mut exact, mut dots, mut dot_n) = (0usize, 0usize, 0.0f64, 0usize);
    let normal_of: std::collections::HashMap<[i64; 3], [f32; 3]> = b
        .pos
        .iter()
        .copied()
        .zip(b.normal.iter().copied())
        .collect();
    for (p, n) in a.pos.iter().zip(&a.normal) {
        let c: [i64; 3] = std::array::from_fn(|k| {
            let world = a.origin[k] + (p[k] as f64 + 0.5) * a.edge;
            ((world - b.origin[k]) / b.edge).floor() as i64
        });
        if let Some(m) = normal_of.get(&c) {
            exact += 1;
            dots += (0..3).map(|k| (m[k] * n[k]) as f64).sum::<f64>();
            dot_n += 1;
        }
        let hit = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| (-1..=1).any(|dz| b.set.contains(&[c[0] + dx, c[1] + dy, c[2] + dz])))
        });
        near += usize::from(hit);
    }
    let n = a.pos.len().max(1) as f64;
    (
        near as f64 / n,
        exact as f64 / n,
        dots / dot_n.max(1) as f64,
    )
}

#[test]
fn an_exported_glb_builds_back_to_the_levels_voxels() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let file = d.join("bunny.voxlod");
    build_ok(&sample(), &file, &["-r", "512"], d);
    // level 1 (256³, the smallest grid a build makes): its node scale is two leaf voxels
    let level = 1u32;
    let glb = d.join("l1.glb");
    let said = ok(&voxlod(
        &[
            "export",
            file.to_str().unwrap(),
            "--level",
            "1",
            "-o",
            glb.to_str().unwrap(),
        ],
        d,
    ));
    round_trip(&file, level, &glb, &said, d);
}

/// Builds `glb`, the export of `level` of `file` (`said`: what the export printed), at that
/// level's resolution and checks the voxels against the level's.
fn round_trip(file: &Path, level: u32, glb: &Path, said: &str, d: &Path) -> Voxels {
    let back = glb.with_extension("voxlod");
    let res = (Reader::open(file).unwrap().spec().resolution >> level).to_string();
    let o = build_ok(glb, &back, &["-r", &res, "--json"], d);
    // every quad of the export is read: two triangles each
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let quads: u64 = said
        .split_whitespace()
        .collect::<Vec<_>>()
        .windows(2)
        .find(|w| w[1].starts_with("quads"))
        .map(|w| w[0].parse().unwrap())
        .unwrap_or_else(|| panic!("no quad count in: {said}"));
    assert_eq!(summary["triangles"].as_u64(), Some(2 * quads), "{summary}");
    let a = voxels(file, level);
    let b = voxels(&back, 0);
    let (ab, _, dot_ab) = within(&a, &b);
    let (ba, _, dot_ba) = within(&b, &a);
    eprintln!(
        "level {level}: {} voxels, built back {}: within one voxel {ab:.4} / {ba:.4}, normals {dot_ab:.3} / {dot_ba:.3}",
        a.pos.len(),
        b.pos.len()
    );
    assert_eq!(ab, 1.0, "level {level}: a voxel lost in the round trip");
    assert_eq!(ba, 1.0, "level {level}: a voxel made up by the round trip");
    let ratio = b.pos.len() as f64 / a.pos.len() as f64;
    assert!((1.0..2.2).contains(&ratio), "level {level}: {ratio}");
    assert!(dot_ab > 0.9 && dot_ba > 0.9, "{dot_ab} {dot_ba}");
    b
}

/// gltf-transform from tests/node, or None (skipped; a failure under CI) when it or node is not
/// installed.
fn gltf_transform() -> Option<PathBuf> {
    let bin = Path::new(REPO).join("tests/node/node_modules/.bin/gltf-transform");
    let works = bin.is_file()
        && Command::new(&bin)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if !works {
        assert!(
            !voxlod_testkit::under_ci(),
            "gltf-transform is not installed (node and `npm ci` in tests/node: .ci/run does both)"
        );
        voxlod_testkit::skipped(
            "gltf_round_trip (gltf-transform's files)",
            "gltf-transform is not installed (run `npm ci` in tests/node)",
        );
        return None;
    }
    Some(bin)
}

/// `gltf-transform COMMAND INPUT OUTPUT` with the command's defaults.
fn transform(bin: &Path, command: &str, input: &Path, output: &Path) {
    let o = Command::new(bin)
        .args([command.as_ref(), input.as_os_str(), output.as_os_str()])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "gltf-transform {command} {}: {}{}",
        input.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The extensions a GLB requires, from its JSON chunk.
fn required(glb: &Path) -> Vec<String> {
    let b = std::fs::read(glb).unwrap();
    let len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&b[20..20 + len]).unwrap();
    doc["extensionsRequired"]
        .as_array()
        .map(|a| a.iter().map(|e| e.as_str().unwrap().to_string()).collect())
        .unwrap_or_default()
}

#[test]
fn gltf_transforms_quantized_and_meshopt_files_read_as_the_plain_file() {
    let Some(gt) = gltf_transform() else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    let build = |glb: &Path| {
        let out = glb.with_extension("voxlod");
        build_ok(glb, &out, &["-r", "256"], d);
        voxels(&out, 0)
    };
    // (1) voxlod's own GLB (level 0 at 256³, built back as in the round trip) made plain and
    // compressed by gltf-transform
    let file = d.join("bunny.voxlod");
    build_ok(&sample(), &file, &["-r", "256"], d);
    let ours = d.join("ours.glb");
    let said = ok(&voxlod(
        &[
            "export",
            file.to_str().unwrap(),
            "-o",
            ours.to_str().unwrap(),
        ],
        d,
    ));
    let v_ours = round_trip(&file, 0, &ours, &said, d);
    let (plain, meshopt) = (d.join("plain.glb"), d.join("m.glb"));
    // FLOAT attributes; then meshopt (quantized and compressed)
    transform(&gt, "dequantize", &ours, &plain);
    transform(&gt, "meshopt", &plain, &meshopt);
    assert!(required(&plain).is_empty(), "{:?}", required(&plain));
    let has = |p: &Path, e: &str| required(p).iter().any(|r| r == e);
    assert!(
        has(&meshopt, "EXT_meshopt_compression"),
        "{:?}",
        required(&meshopt)
    );
    assert!(
        has(&meshopt, "KHR_mesh_quantization"),
        "{:?}",
        required(&meshopt)
    );
    eprintln!(
        "bytes: voxlod's GLB {}, plain {}, meshopt {}",
        size(&ours),
        size(&plain),
        size(&meshopt)
    );
    assert!(size(&meshopt) < size(&plain) / 3);
    let v_plain = build(&plain);
    assert_eq!(v_ours.origin, v_plain.origin);
    assert!(
        v_ours.set == v_plain.set,
        "voxlod's GLB and gltf-transform's plain copy give other voxels"
    );
    // every face of this mesh lies on a voxel boundary, where a conservative build marks both
    // sides; gltf-transform's 14-bit quantization moves it off by a fraction of a voxel, onto
    // one side: the voxels stay within one voxel, not the same ones
    compare(&v_plain, &build(&meshopt), &meshopt, 0.7);
    // (2) a scan's triangles (the bundled bunny) as a plain GLB, and meshopt-compressed: here
    // quantization moves few triangles across a voxel boundary
    let (v, f) = voxlod_testkit::mesh::read_ply(&sample());
    let scan = d.join("scan.glb");
    let prim = voxlod_testkit::gltf::Prim {
        positions: v.iter().map(|p| p.map(|x| x as f32)).collect(),
        indices: Some(f.iter().flatten().copied().collect()),
        mode: 4,
        ..Default::default()
    };
    let node = voxlod_testkit::gltf::Node {
        mesh: Some(0),
        ..Default::default()
    };
    voxlod_testkit::gltf::write(&scan, &[vec![prim]], &[node], &[0], &[]);
    let scan_m = d.join("scan-m.glb");
    transform(&gt, "meshopt", &scan, &scan_m);
    assert!(has(&scan_m, "EXT_meshopt_compression"));
    eprintln!("bytes: scan GLB {}, meshopt {}", size(&scan), size(&scan_m));
    compare(&build(&scan), &build(&scan_m), &scan_m, 0.98);
}

/// `b` (built from the compressed file `glb`) against `a` (from the plain one): every voxel
/// within one voxel of the other's, at least `same` of them the very same voxel.
fn compare(a: &Voxels, b: &Voxels, glb: &Path, same: f64) {
    let (near_a, exact_a, _) = within(a, b);
    let (near_b, exact_b, _) = within(b, a);
    eprintln!(
        "{}: {} voxels against {}: within one voxel {near_a:.4} / {near_b:.4}, the same {exact_a:.4} / {exact_b:.4}",
        glb.display(),
        b.pos.len(),
        a.pos.len()
    );
    assert_eq!((near_a, near_b), (1.0, 1.0), "{}", glb.display());
    assert!(exact_a >= same && exact_b >= same, "{}", glb.display());
}
