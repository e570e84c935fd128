//! `verify` on files with the material channel (FORMAT.md 14.3): a file whose parents follow
//! the material LOD rule passes with every parent's materials checked; a parent whose stored
//! materials break the rule, a file with a corrupt material payload, and a parent whose
//! materials were written for the wrong voxels are each reported, naming the node.

use voxlod_format::voxel::{pack_color, pack_normal, Voxel};
use voxlod_format::{encode_materials, encode_node, FileSpec, Writer, CHANNEL_MATERIAL};
use voxlod_lod::{merge_children, merge_materials};
use voxlod_testkit::Rng;

/// Two leaves of a 512³ grid with random voxels and materials in runs, and their root.
fn leaves(seed: u64) -> Vec<(Vec<Voxel>, Vec<u32>)> {
    let mut rng = Rng(seed);
    (0..2)
        .map(|_| {
            let mut codes: Vec<u32> = (0..4000).map(|_| rng.below(1 << 15) as u32).collect();
            codes.sort_unstable();
            codes.dedup();
            let n = pack_normal([0.0, 0.0, 1.0]);
            let v: Vec<Voxel> = codes
                .iter()
                .map(|&c| {
                    let p: [u8; 3] = std::array::from_fn(|a| {
                        (0..8).map(|b| ((c >> (3 * b + a)) & 1) << b).sum::<u32>() as u8
                    });
                    let mask =
                        voxlod_format::voxel::face_mask(n) | voxlod_format::voxel::border_caps(p);
                    Voxel::new(p, mask, n, pack_color([9, 9, 9, 255]))
                })
                .collect();
            let m: Vec<u32> = v.iter().map(|_| rng.below(3) as u32).collect();
            (v, m)
        })
        .collect()
}

/// Writes the file; `tamper` may change the root's materials before they are encoded.
fn write(path: &std::path::Path, tamper: &dyn Fn(&mut Vec<u32>)) {
    let l = leaves(4);
    let mut w = Writer::create_with_channels(
        path,
        FileSpec::new(512, 0, [0.0; 3], 1.0),
        &[CHANNEL_MATERIAL],
    )
    .unwrap();
    for (i, (v, m)) in l.iter().enumerate() {
        let mat = encode_materials(m, 3).unwrap();
        w.write_node_with(
            0,
            [i as u32, 0, 0],
            0,
            &encode_node(v, 3).unwrap(),
            &[Some(&mat)],
        )
        .unwrap();
    }
    let mut kids: [&[Voxel]; 8] = [&[]; 8];
    let mut kmats: [&[u32]; 8] = [&[]; 8];
    for o in 0..2 {
        kids[o] = &l[o].0;
        kmats[o] = &l[o].1;
    }
    let root = merge_children(&kids);
    let mut rm = merge_materials(&kids, &kmats);
    tamper(&mut rm);
    let mat = encode_materials(&rm, 3).unwrap();
    w.write_node_with(
        1,
        [0; 3],
        0b11,
        &encode_node(&root, 3).unwrap(),
        &[Some(&mat)],
    )
    .unwrap();
    w.finish(&serde_json::json!({"materials": ["", "a", "b"]}))
        .unwrap();
}

#[test]
fn verify_checks_the_material_lod_rule() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ok.voxlod");
    write(&path, &|_| {});
    let r = voxlod_check::verify(&path);
    assert!(r.ok(), "{:?}", r.problems);
    assert_eq!((r.parents_checked, r.materials_checked), (1, 1));

    // one root voxel with another material than the rule's
    let bad = dir.path().join("bad.voxlod");
    write(&bad, &|m| m[100] = if m[100] == 0 { 1 } else { 0 });
    let r = voxlod_check::verify(&bad);
    assert!(!r.ok());
    let p = &r.problems[0];
    assert_eq!((p.level, p.pos), (Some(1), Some([0, 0, 0])));
    assert!(
        p.what.contains("first difference at voxel 100"),
        "{}",
        p.what
    );

    // a flipped byte in the first leaf's material payload: that leaf, and its parent unchecked
    let mut bytes = std::fs::read(&path).unwrap();
    let reader = voxlod_format::Reader::open(&path).unwrap();
    let at = 128 + reader.nodes()[0].payload_size as usize + 3;
    bytes[at] ^= 1;
    let corrupt = dir.path().join("corrupt.voxlod");
    std::fs::write(&corrupt, bytes).unwrap();
    let r = voxlod_check::verify(&corrupt);
    let whats: Vec<_> = r
        .problems
        .iter()
        .map(|p| (p.index, p.what.clone()))
        .collect();
    assert!(
        whats[0].0 == Some(0) && whats[0].1.contains("channel 1 payload checksum"),
        "{whats:?}"
    );
    assert!(
        whats
            .iter()
            .any(|w| w.0 == Some(2) && w.1.contains("materials not compared")),
        "{whats:?}"
    );
}
