//! Bad input is an error with a useful message, never a panic: the writer refuses invalid
//! voxels and trees, an unfinished writer leaves nothing behind, and the reader refuses every
//! single corrupted byte, every truncation and crafted files that pass the checksums.

use crate::common;

use std::path::Path;

use common::{assemble, fix_crcs, post_order, put, random_voxels, reference_block, RawNode, Rng};
use serde_json::json;
use voxlod_format::voxel::Voxel;
use voxlod_format::{
    encode_node, temp_path, FileSpec, FormatError, Reader, Writer, MODE_CONSERVATIVE,
};

fn spec(resolution: u32) -> FileSpec {
    FileSpec::new(resolution, MODE_CONSERVATIVE, [0.0; 3], 1.0)
}

fn err_of<T: std::fmt::Debug>(r: Result<T, FormatError>) -> String {
    r.expect_err("expected an error").to_string()
}

fn v(p: [u8; 3]) -> Voxel {
    Voxel::new(p, 1, 0, 0)
}

#[test]
fn encode_rejects_bad_voxels() {
    let e = err_of(encode_node(&[v([0, 1, 0]), v([1, 0, 0])], 3)); // Morton 2 then 1
    assert!(
        e.contains("voxel 1") && e.contains("not in Morton order"),
        "{e}"
    );
    let e = err_of(encode_node(&[v([1, 0, 0]), v([2, 0, 0]), v([2, 0, 0])], 3));
    assert!(e.contains("voxel 2") && e.contains("duplicate"), "{e}");
    let e = err_of(encode_node(&[], 3));
    assert!(e.contains("at least one voxel"), "{e}");
    let e = err_of(encode_node(
        &[Voxel {
            pos_mask: 1 << 30,
            normal: 0,
            color: 0,
        }],
        3,
    ));
    assert!(e.contains("reserved bits"), "{e}");
    let e = err_of(encode_node(
        &[Voxel {
            pos_mask: 0,
            normal: 1 << 31,
            color: 0,
        }],
        3,
    ));
    assert!(e.contains("reserved bits"), "{e}");
    let e = err_of(encode_node(&[v([0, 0, 0])], 1000));
    assert!(e.contains("zstd level"), "{e}");
}

#[test]
fn writer_rejects_bad_specs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.voxlod");
    for (s, what) in [
        (
            FileSpec {
                resolution: 300,
                ..spec(256)
            },
            "resolution",
        ),
        (
            FileSpec {
                levels: 2,
                ..spec(256)
            },
            "levels",
        ),
        (
            FileSpec {
                mode: 2,
                ..spec(256)
            },
            "mode",
        ),
        (
            FileSpec {
                voxel_size: -1.0,
                ..spec(256)
            },
            "voxel size",
        ),
        (
            FileSpec {
                origin: [0.0, f64::INFINITY, 0.0],
                ..spec(256)
            },
            "origin",
        ),
    ] {
        let e = err_of(Writer::create(&path, s));
        assert!(e.contains(what) && e.contains("x.voxlod"), "{e}");
    }
    assert!(!temp_path(&path).exists());
}

#[test]
fn writer_rejects_bad_trees_and_stays_usable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tree.voxlod");
    let node = encode_node(&[v([3, 3, 3])], 3).unwrap();
    let mut w = Writer::create(&path, spec(512)).unwrap(); // 2 levels, 2³ leaves
    let e = err_of(w.write_node(0, [2, 0, 0], 0, &node));
    assert!(e.contains("outside the grid"), "{e}");
    let e = err_of(w.write_node(2, [0, 0, 0], 0, &node));
    assert!(e.contains("outside the grid"), "{e}");
    let e = err_of(w.write_node(0, [0, 0, 0], 1, &node));
    assert!(e.contains("child mask"), "{e}");
    w.write_node(0, [1, 0, 0], 0, &node).unwrap();
    let e = err_of(w.write_node(0, [1, 0, 0], 0, &node));
    assert!(e.contains("written twice"), "{e}");
    let e = err_of(w.write_node(0, [0, 0, 0], 0, &node)); // octant 0 after octant 1
    assert!(
        e.contains("out of order") && e.contains("level 0 at [1, 0, 0]"),
        "{e}"
    );
    let e = err_of(w.write_node(1, [0, 0, 0], 0b11, &node)); // child 0 was never written
    assert!(e.contains("child mask") && e.contains("0b00000010"), "{e}");
    let before = w.bytes_written();
    w.write_node(0, [1, 1, 1], 0, &node).unwrap();
    assert_eq!(w.bytes_written(), before + node.payload().len() as u64);
    // finishing without the parent of the leaves fails, and leaves no file at all
    let e = err_of(w.finish(&json!({})));
    assert!(
        e.contains("parent was never written") && e.contains("position [1, 0, 0]"),
        "{e}"
    );
    assert!(!path.exists() && !temp_path(&path).exists());

    let mut w = Writer::create(&path, spec(512)).unwrap();
    w.write_node(0, [1, 0, 0], 0, &node).unwrap();
    w.write_node(0, [1, 1, 1], 0, &node).unwrap();
    w.write_node(1, [0, 0, 0], 0b1000_0010, &node).unwrap();
    let e = err_of(w.write_node(0, [1, 1, 1], 0, &node)); // after the root
    assert!(
        e.contains("written twice") || e.contains("out of order"),
        "{e}"
    );
    w.finish(&json!({})).unwrap();
    assert_eq!(Reader::open(&path).unwrap().nodes().len(), 3);
}

#[test]
fn unfinished_writer_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.voxlod");
    let node = encode_node(&[v([3, 3, 3])], 3).unwrap();
    {
        let mut w = Writer::create(&path, spec(256)).unwrap();
        w.write_node(0, [0, 0, 0], 0, &node).unwrap();
        assert!(temp_path(&path).exists() && !path.exists());
    } // dropped without finish
    assert!(!path.exists() && !temp_path(&path).exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

    // A killed process runs no Drop: the temp file stays, `path` still doesn't exist, and the
    // next writer for the same path truncates and reuses the temp name.
    let mut w = Writer::create(&path, spec(256)).unwrap();
    w.write_node(0, [0, 0, 0], 0, &node).unwrap();
    std::mem::forget(w);
    assert!(temp_path(&path).exists() && !path.exists());
    assert!(Reader::open(&temp_path(&path)).is_err()); // header still all zeros
    let mut w = Writer::create(&path, spec(256)).unwrap();
    w.write_node(0, [0, 0, 0], 0, &node).unwrap();
    w.finish(&json!({})).unwrap();
    assert!(path.exists() && !temp_path(&path).exists());

    // finishing replaces an existing file atomically
    let w = Writer::create(&path, spec(256)).unwrap();
    w.finish(&json!({"second": true})).unwrap();
    assert_eq!(
        Reader::open(&path).unwrap().manifest().unwrap(),
        json!({"second": true})
    );
}

/// A small valid file: 512³ grid, 3 leaves + root, a few voxels each.
fn small_file(dir: &Path) -> (std::path::PathBuf, Vec<u8>) {
    let mut rng = Rng(11);
    let path = dir.join("small.voxlod");
    let mut w = Writer::create(&path, spec(512)).unwrap();
    for (l, p, m) in post_order(2, &[[0, 0, 0], [1, 0, 1], [1, 1, 1]]) {
        let n = 1 + rng.below(6) as usize;
        w.write_node(
            l,
            p,
            m,
            &encode_node(&random_voxels(&mut rng, n), 3).unwrap(),
        )
        .unwrap();
    }
    w.finish(&json!({ "k": 1 })).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    (path, bytes)
}

/// Opens `bytes` (written to `path`) and reads every node; the first error, if any.
fn open_and_read_all(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    std::fs::write(path, bytes).unwrap();
    let r = Reader::open(path)?;
    let mut buf = Vec::new();
    for i in 0..r.nodes().len() {
        r.read_node_into(i, &mut buf)?;
    }
    r.manifest()?;
    Ok(())
}

#[test]
fn every_corrupted_byte_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let (_, good) = small_file(dir.path());
    let probe = dir.path().join("probe.voxlod");
    open_and_read_all(&probe, &good).unwrap();
    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
    for i in 0..good.len() {
        for flip in [0x01u8, 0x80, 0xff] {
            let mut bad = good.clone();
            bad[i] ^= flip;
            let e = open_and_read_all(&probe, &bad)
                .expect_err(&format!("flip {flip:#x} at byte {i} went unnoticed"));
            let msg = e.to_string();
            assert!(msg.contains("probe.voxlod"), "{msg}");
            *kinds
                .entry(msg.split(": ").nth(1).unwrap_or("").to_string())
                .or_default() += 1;
        }
    }
    eprintln!("{} bytes × 3 flips, errors by kind: {kinds:?}", good.len());
}

#[test]
fn every_truncation_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let (_, good) = small_file(dir.path());
    let probe = dir.path().join("probe.voxlod");
    for cut in 0..good.len() {
        let e = open_and_read_all(&probe, &good[..cut])
            .expect_err(&format!("truncation to {cut} bytes went unnoticed"));
        let msg = e.to_string();
        assert!(msg.contains("bad header"), "cut {cut}: {msg}");
        if cut < 128 {
            assert!(msg.contains("shorter than the 128-byte header"), "{msg}");
        }
    }
    // and appended garbage
    let mut long = good.clone();
    long.push(0);
    assert!(err_of(open_and_read_all(&probe, &long)).contains("should end with the manifest"));
}

#[test]
fn header_faults_have_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let (_, good) = small_file(dir.path());
    let probe = dir.path().join("probe.voxlod");
    let check = |edit: &dyn Fn(&mut Vec<u8>), fix: bool, expect: &str| {
        let mut f = good.clone();
        edit(&mut f);
        if fix {
            fix_crcs(&mut f);
        }
        let e = err_of(open_and_read_all(&probe, &f));
        assert!(e.contains(expect), "expected {expect:?} in: {e}");
    };
    check(&|f| f[0] = b'X', false, "magic");
    check(
        &|f| f.splice(0..8, *b"PK\x03\x04\0\0\0\0").for_each(drop),
        false,
        "not a voxlod file",
    );
    check(
        &|f| put(f, 8, &3u32.to_le_bytes()),
        false,
        "version 3 is not supported",
    );
    check(&|f| put(f, 12, &64u32.to_le_bytes()), false, "header size");
    check(
        &|f| put(f, 16, &1000u32.to_le_bytes()),
        false,
        "checksum mismatch",
    );
    check(
        &|f| put(f, 16, &1000u32.to_le_bytes()),
        true,
        "resolution 1000",
    );
    check(&|f| put(f, 20, &5u32.to_le_bytes()), true, "levels is 5");
    check(&|f| put(f, 24, &7u32.to_le_bytes()), true, "mode 7");
    check(
        &|f| put(f, 28, &1u32.to_le_bytes()),
        true,
        "reserved fields",
    );
    check(&|f| put(f, 56, &f64::NAN.to_le_bytes()), true, "voxel size");
    check(
        &|f| put(f, 72, &u64::MAX.to_le_bytes()),
        true,
        "index offset",
    );
    check(
        &|f| put(f, 72, &(u64::MAX - 7).to_le_bytes()),
        true,
        "past the end",
    );
    check(
        &|f| put(f, 72, &(1u64 << 40).to_le_bytes()),
        true,
        "past the end",
    );
    check(
        &|f| put(f, 64, &(1u64 << 60).to_le_bytes()),
        true,
        "index size",
    );
    check(
        &|f| put(f, 88, &0u64.to_le_bytes()),
        true,
        "does not follow the index",
    );
    check(&|f| put(f, 96, &u64::MAX.to_le_bytes()), true, "manifest");
    check(&|f| put(f, 104, &1u64.to_le_bytes()), true, "header says 1");
    check(
        &|f| {
            let n = f.len();
            f[n - 1] = b'#';
        },
        true,
        "not valid JSON",
    );
}

/// Entry `i`'s field at `field` offset of `good`, overwritten, with checksums fixed.
fn edit_entry(good: &[u8], i: usize, field: usize, bytes: &[u8]) -> Vec<u8> {
    let mut f = good.to_vec();
    let io = u64::from_le_bytes(f[72..80].try_into().unwrap()) as usize;
    put(&mut f, io + 64 * i + field, bytes);
    fix_crcs(&mut f);
    f
}

#[test]
fn index_entry_faults_name_the_node() {
    let dir = tempfile::tempdir().unwrap();
    let (_, good) = small_file(dir.path());
    let probe = dir.path().join("probe.voxlod");
    let check = |f: Vec<u8>, expect: &[&str]| {
        let e = err_of(open_and_read_all(&probe, &f));
        for x in expect {
            assert!(e.contains(x), "expected {x:?} in: {e}");
        }
    };
    // node 1 is the leaf (1,0,1); node 3 the root
    check(
        edit_entry(&good, 1, 0, &9u32.to_le_bytes()),
        &["node 1", "level 9"],
    );
    check(
        edit_entry(&good, 1, 4, &2u32.to_le_bytes()),
        &["node 1", "outside the level's grid"],
    );
    check(
        edit_entry(&good, 1, 16, &0u32.to_le_bytes()),
        &["node 1", "voxel count 0"],
    );
    check(
        edit_entry(&good, 1, 16, &u32::MAX.to_le_bytes()),
        &["node 1", "voxel count"],
    );
    check(
        edit_entry(&good, 1, 20, &1u32.to_le_bytes()),
        &["node 1", "child mask"],
    );
    check(
        edit_entry(&good, 3, 20, &0xffu32.to_le_bytes()),
        &[
            "node 3",
            "child mask 0b11111111 but the stored children are",
        ],
    );
    check(
        edit_entry(&good, 2, 24, &u64::MAX.to_le_bytes()),
        &["node 2", "payload"],
    );
    check(
        edit_entry(&good, 2, 32, &(1u64 << 50).to_le_bytes()),
        &["node 2", "payload"],
    );
    check(
        edit_entry(&good, 0, 32, &0u64.to_le_bytes()),
        &["node 0", "payload"],
    );
    check(
        edit_entry(&good, 1, 48, &[9, 9, 9, 0]),
        &["node 1", "bounds"],
    );
    check(
        edit_entry(&good, 1, 52, &[0, 0, 0, 1]),
        &["node 1", "bounds"],
    );
    check(edit_entry(&good, 1, 56, &[1]), &["node 1", "reserved"]);
    // swap leaves 1 and 2 (positions only): out of order
    let f = edit_entry(&good, 1, 4, &[1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]);
    check(
        edit_entry(&f, 2, 4, &[1, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0]),
        &["node 2", "out of index order"],
    );
    // move leaf 2 to (0,1,1), which the root's child mask does not list
    check(
        edit_entry(&good, 2, 4, &[0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]),
        &["node 3", "child mask"],
    );
    // checksums that do not match what they cover
    check(
        edit_entry(&good, 2, 40, &[0, 0, 0, 0]),
        &["node 2", "payload checksum mismatch"],
    );
    check(
        edit_entry(&good, 2, 44, &[0, 0, 0, 0]),
        &["node 2", "block checksum mismatch"],
    );
}

#[test]
fn crafted_payloads_with_valid_checksums_are_rejected() {
    // Files assembled by hand (common::assemble) whose checksums are all right but whose
    // payload breaks a rule: the reader must say which node and what.
    let dir = tempfile::tempdir().unwrap();
    let probe = dir.path().join("crafted.voxlod");
    let good = [v([1, 0, 0]), v([0, 1, 0]), v([1, 1, 0])];
    let one = |node: RawNode| assemble(256, 1, 0, [0.0; 3], 1.0, &[node], b"{}");
    let check = |f: Vec<u8>, expect: &str| {
        let e = err_of(open_and_read_all(&probe, &f));
        assert!(
            e.contains("node 0 (level 0, position [0, 0, 0])") && e.contains(expect),
            "expected {expect:?} in: {e}"
        );
    };
    open_and_read_all(&probe, &one(RawNode::from_voxels(0, [0; 3], 0, &good, 3))).unwrap();

    let raw = |block: &[u8], count: u32| RawNode {
        level: 0,
        pos: [0; 3],
        child_mask: 0,
        voxel_count: count,
        payload: zstd::bulk::compress(block, 3).unwrap(),
        block_crc32: crc32fast::hash(block),
        bounds_min: [0, 0, 0],
        bounds_max: [1, 1, 0],
    };
    // unsorted (a Morton delta that wraps past 24 bits) and duplicate voxels
    let mut b = reference_block(&[v([0, 1, 0]), v([1, 0, 0])]);
    check(one(raw(&b, 2)), "exceeds 24 bits");
    b = reference_block(&[v([1, 0, 0]), v([1, 0, 0])]);
    check(one(raw(&b, 2)), "duplicate");
    // reserved bits
    b = reference_block(&good);
    b[3 * 3 + 2] |= 0x40; // position plane 3 (mask byte) of voxel 2
    check(one(raw(&b, 3)), "reserved position bits");
    b = reference_block(&good);
    b[12 + 9] = 0x40; // normal plane 3 of voxel 0
    check(one(raw(&b, 3)), "reserved normal bits");
    // a normal component of −512 (FORMAT.md section 6: [−511, 511]); and the encoder refuses it
    b = reference_block(&[
        v([1, 0, 0]),
        Voxel::new([0, 1, 0], 1, 0x200 << 10, 0),
        v([1, 1, 0]),
    ]);
    check(one(raw(&b, 3)), "normal component is -512");
    let e = err_of(encode_node(&[Voxel::new([0, 1, 0], 1, 0x200, 0)], 3));
    assert!(e.contains("-512"), "{e}");
    // bounds that are not tight
    let mut n = RawNode::from_voxels(0, [0; 3], 0, &good, 3);
    n.bounds_max = [2, 1, 0];
    check(one(n), "bounds");
    // size mismatch, both ways
    check(one(raw(&reference_block(&good), 2)), "expected 12·2 = 24");
    check(one(raw(&reference_block(&good), 4)), "expected 12·4 = 48");
    // not zstd at all, and a zstd frame claiming a huge size
    let mut n = raw(&reference_block(&good), 3);
    n.payload = b"definitely not a zstd frame".to_vec();
    check(one(n), "does not start with the zstd magic");
    let mut n = raw(&reference_block(&good), 3);
    n.payload = zstd::bulk::compress(&vec![0u8; 1 << 20], 3).unwrap();
    check(one(n), "content size is 1048576 bytes, expected 12·3 = 36");
    // FORMAT.md 11.2: one frame, nothing before or after it, a content size
    let frame = zstd::bulk::compress(&reference_block(&good), 3).unwrap();
    let mut n = raw(&reference_block(&good), 3);
    n.payload = [&frame[..], &zstd::bulk::compress(&[], 3).unwrap()].concat();
    check(one(n), "a second frame or trailing bytes follow");
    let mut n = raw(&reference_block(&good), 3);
    n.payload = [&frame[..], &[0]].concat();
    check(one(n), "trailing bytes");
    let mut n = raw(&reference_block(&good), 3);
    n.payload = [&[0x5e, 0x2a, 0x4d, 0x18, 1, 0, 0, 0, 9][..], &frame].concat();
    check(one(n), "skippable");
    let mut n = raw(&reference_block(&good), 3);
    let mut e = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
    e.include_contentsize(false).unwrap();
    std::io::Write::write_all(&mut e, &reference_block(&good)).unwrap();
    n.payload = e.finish().unwrap();
    check(one(n), "no content size");
}
