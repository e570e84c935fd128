//! `voxlod build` with the per-voxel material channel (docs/FORMAT.md 14): a made-up block
//! world (a floor of unit cubes, each with one of three OBJ materials) gives a version-2 file
//! that `verify` accepts with every parent's materials checked, whose manifest names the
//! materials, whose voxels are exactly those of the same world with one material (a version-1
//! file), whose leaf materials are each one of the blocks touching the voxel (and the block's
//! own wherever only one block is near), and whose bytes do not depend on the thread count.

use std::path::Path;
use std::process::Command;

use voxlod_format::Reader;

use super::BIN;

const NAMES: [&str; 3] = ["stone", "grass", "dirt"];

/// The floor: 4 × 4 unit cubes at (x, 0, z), material (x + 2z) % 3 (one name for all with
/// `one`), every Kd the same grey so that colours do not depend on the material.
fn world(dir: &Path, one: bool) -> std::path::PathBuf {
    let mtl: String = NAMES
        .iter()
        .map(|n| format!("newmtl {n}\nKd 0.5 0.5 0.5\n"))
        .collect();
    std::fs::write(dir.join("w.mtl"), mtl).unwrap();
    let mut obj = String::from("mtllib w.mtl\n");
    let mut nv = 0;
    for z in 0..4 {
        for x in 0..4 {
            let m = if one { 0 } else { block_material(x, z) };
            obj += &format!("usemtl {}\n", NAMES[m as usize]);
            for c in 0..8 {
                let (dx, dy, dz) = (c & 1, c >> 1 & 1, c >> 2 & 1);
                obj += &format!("v {} {} {}\n", x + dx, dy, z + dz);
            }
            let v = |c: usize| nv + c + 1;
            // the six faces, counter-clockwise from outside
            for f in [
                [0, 2, 3, 1],
                [4, 5, 7, 6],
                [0, 1, 5, 4],
                [2, 6, 7, 3],
                [0, 4, 6, 2],
                [1, 3, 7, 5],
            ] {
                obj += &format!("f {} {} {} {}\n", v(f[0]), v(f[1]), v(f[2]), v(f[3]));
            }
            nv += 8;
        }
    }
    let p = dir.join(if one { "one.obj" } else { "w.obj" });
    std::fs::write(&p, obj).unwrap();
    p
}

fn block_material(x: i32, z: i32) -> u32 {
    ((x + 2 * z) % 3) as u32
}

fn build(input: &Path, out: &Path, threads: &str) {
    let o = Command::new(BIN)
        .arg("build")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["-q", "-r", "512", "-j", threads])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn block_world_materials() {
    let dir = tempfile::tempdir().unwrap();
    let input = world(dir.path(), false);
    let out = dir.path().join("w.voxlod");
    build(&input, &out, "2");
    let r = Reader::open(&out).unwrap();
    assert_eq!(r.header().version, 2);
    assert!(r.has_materials());
    let manifest = r.manifest().unwrap();
    assert_eq!(
        manifest["materials"],
        serde_json::json!(["", "stone", "grass", "dirt"])
    );

    let report = voxlod_check::verify(&out);
    assert!(report.ok(), "{:?}", report.problems);
    assert!(report.materials_checked >= 1 && report.materials_checked == report.parents_checked);

    // the same world with one material: a version-1 file with the same voxels in every node
    let one = dir.path().join("one.voxlod");
    build(&world(dir.path(), true), &one, "2");
    let r1 = Reader::open(&one).unwrap();
    assert_eq!(r1.header().version, 1);
    assert!(!r1.has_materials());
    assert_eq!(r1.nodes().len(), r.nodes().len());
    for i in 0..r.nodes().len() {
        assert_eq!(
            r.read_node(i).unwrap(),
            r1.read_node(i).unwrap(),
            "node {i}"
        );
    }

    // leaf materials against the blocks: a voxel's material (id − 1 = block material) is that
    // of a block whose box, grown by one voxel, contains the voxel; where only one block does,
    // it is that block's
    let spec = r.spec();
    let s = spec.voxel_size;
    let (mut checked, mut sole) = (0, 0);
    for i in r.level_nodes(0).collect::<Vec<_>>() {
        let e = r.nodes()[i];
        let voxels = r.read_node(i).unwrap();
        let mats = r.read_materials(i).unwrap().unwrap();
        for (v, m) in voxels.iter().zip(&mats) {
            let lo = spec.voxel_min_corner(0, e.pos(), v.pos());
            let near: Vec<u32> = (0..4)
                .flat_map(|z| (0..4).map(move |x| (x, z)))
                .filter(|&(x, z)| {
                    let b = [x as f64, 0.0, z as f64];
                    (0..3).all(|a| lo[a] + s >= b[a] - s && lo[a] <= b[a] + 1.0 + s)
                })
                .map(|(x, z)| block_material(x, z) + 1)
                .collect();
            assert!(
                near.contains(m),
                "voxel {:?} of node {i}: material {m}, blocks {near:?}",
                v.pos()
            );
            if near.iter().all(|n| n == &near[0]) {
                assert_eq!(*m, near[0]);
                sole += 1;
            }
            checked += 1;
        }
    }
    assert!(
        sole * 2 > checked,
        "{sole} of {checked} voxels near one block"
    );

    // export carries the materials: 4 vertices per active face, each with its voxel's id
    let ply = dir.path().join("w.ply");
    let o = Command::new(BIN)
        .args(["export"])
        .arg(&out)
        .args(["--level", "1", "-o"])
        .arg(&ply)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&ply).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = String::from_utf8_lossy(&bytes[..end]);
    assert!(header.contains("property uchar alpha\nproperty uint material\nelement face"));
    let mut want = Vec::new();
    for i in r.level_nodes(1).collect::<Vec<_>>() {
        let mats = r.read_materials(i).unwrap().unwrap();
        for (v, m) in r.read_node(i).unwrap().iter().zip(mats) {
            want.extend(std::iter::repeat_n(m, 4 * v.mask().count_ones() as usize));
        }
    }
    let got: Vec<u32> = bytes[end..end + 32 * want.len()]
        .chunks_exact(32)
        .map(|rec| u32::from_le_bytes(rec[28..32].try_into().unwrap()))
        .collect();
    assert_eq!(got, want);

    // inspect lists the channel: its id, name, and payload bytes equal to the sum of the
    // per-node material payloads read back; the one-material file lists none
    let inspect = |f: &Path| -> serde_json::Value {
        let o = Command::new(BIN)
            .arg("inspect")
            .arg(f)
            .arg("--json")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let payload: u64 = (0..r.nodes().len())
        .map(|i| {
            r.read_channel_payload(i, 1)
                .unwrap()
                .map_or(0, |p| p.len() as u64)
        })
        .sum();
    assert!(payload > 0);
    assert_eq!(
        inspect(&out)["channels"],
        serde_json::json!([{"id": 1, "name": "materials", "payload_bytes": payload, "triangles": 0}])
    );
    assert_eq!(inspect(&one)["channels"], serde_json::json!([]));
    let o = Command::new(BIN).arg("inspect").arg(&out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("channel 1    materials ("), "{text}");
    assert!(text.contains(", 4 materials)"), "{text}");
    // the legend names every material with its id and the colour `render --color material`
    // paints it with, in inspect's text and after render's summary
    let names = r.manifest().unwrap()["materials"].clone();
    let names: Vec<&str> = names
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 4);
    let legend: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(id, name)| {
            let c = voxlod_render::material_color(id as u32);
            let name = if id == 0 { "(no material)" } else { name };
            format!("{id:>5}  #{:02x}{:02x}{:02x}  {name}", c[0], c[1], c[2])
        })
        .collect();
    for n in NAMES {
        assert!(legend.iter().any(|l| l.ends_with(&format!("  {n}"))), "{n}");
    }
    for line in &legend {
        assert!(
            text.lines().any(|l| l.trim_end() == format!("  {line}")),
            "{line:?} not in:\n{text}"
        );
    }
    let png = dir.path().join("w.png");
    let o = Command::new(BIN)
        .arg("render")
        .arg(&out)
        .args(["--color", "material", "-o"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stdout);
    let tail: Vec<&str> = said
        .lines()
        .skip_while(|l| !l.starts_with("legend"))
        .skip(1)
        .collect();
    assert_eq!(tail, legend, "{said}");

    // render --color material on a file without the channel: a clear error, nothing written
    let png = dir.path().join("one.png");
    let o = Command::new(BIN)
        .arg("render")
        .arg(&one)
        .args(["--color", "material", "-o"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(!o.status.success() && !png.exists());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no material channel"));

    // the same bytes on one thread
    let single = dir.path().join("w1.voxlod");
    build(&input, &single, "1");
    assert!(std::fs::read(&single).unwrap() == std::fs::read(&out).unwrap());
}
