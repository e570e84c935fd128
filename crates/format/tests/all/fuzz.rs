//! Seeded mutation fuzzing of the octree reader, bounded to a few seconds so it runs in CI
//! (a fuzz target per parser). A small valid file (512³, two levels, made here) is
//! mutated three ways: raw bytes (bit flips, truncation, insertion, deletion, big 4- and
//! 8-byte fields), the same with the header, index and manifest checksums recomputed (so the
//! structural checks behind them run), and a node's decompressed block mutated and
//! recompressed with correct checksums (so the payload rules and the decoder's checks run).
//! `Reader::open`, reading every node and the manifest must return — no panic — and errors
//! must name the file. `VOXLOD_FUZZ_ITERS` sets the mutants per mode (default 300).

use crate::common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use common::{assemble, fix_crcs, post_order, random_voxels, reference_block, RawNode, Rng};
use voxlod_format::{Reader, MODE_CONSERVATIVE};

fn iters() -> usize {
    std::env::var("VOXLOD_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(300)
}

fn read_all(path: &Path) -> Result<(), voxlod_format::FormatError> {
    let r = Reader::open(path)?;
    let mut buf = Vec::new();
    for i in 0..r.nodes().len() {
        r.read_node_into(i, &mut buf)?;
    }
    r.manifest()?;
    let _ = r.depth_first().count();
    Ok(())
}

/// Reads `bytes` as `path`; panics (with the input saved) if the reader panicked, and checks
/// that an error names the file. True if the file was accepted.
fn check(path: &Path, bytes: &[u8], what: &str) -> bool {
    std::fs::write(path, bytes).unwrap();
    match catch_unwind(AssertUnwindSafe(|| read_all(path))) {
        Ok(Ok(())) => true,
        Ok(Err(e)) => {
            let msg = e.to_string();
            assert!(
                msg.contains("fuzz.voxlod"),
                "{what}: error without the file name: {msg}"
            );
            false
        }
        Err(_) => {
            let keep = std::env::temp_dir().join("voxlod-fuzz-panic.voxlod");
            std::fs::write(&keep, bytes).unwrap();
            panic!(
                "{what}: the reader panicked; input saved as {}",
                keep.display()
            );
        }
    }
}

/// The nodes of a small valid file: 3 leaves and the root of a 512³ grid.
fn nodes(rng: &mut Rng) -> Vec<RawNode> {
    post_order(2, &[[0, 0, 0], [1, 0, 1], [1, 1, 1]])
        .into_iter()
        .map(|(l, p, m)| {
            let n = 1 + rng.below(12) as usize;
            RawNode::from_voxels(l, p, m as u32, &random_voxels(rng, n), 3)
        })
        .collect()
}

fn file(nodes: &[RawNode]) -> Vec<u8> {
    assemble(
        512,
        2,
        MODE_CONSERVATIVE,
        [0.0; 3],
        1.0,
        nodes,
        br#"{"k":[1,2,{"a":"b"}]}"#,
    )
}

fn mutate(rng: &mut Rng, data: &mut Vec<u8>) {
    for _ in 0..1 + rng.below(3) {
        let at = rng.below(data.len() as u64 + 1) as usize;
        match rng.below(6) {
            0 if at < data.len() => data[at] ^= 1 << rng.below(8),
            1 => data.truncate(at),
            2 => data.insert(at, rng.next_u64() as u8),
            3 if at < data.len() => {
                data.remove(at);
            }
            4 if at + 4 <= data.len() => {
                let v = [u32::MAX, 1 << 31, 0, 1 << 24][rng.below(4) as usize];
                data[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
            _ if at + 8 <= data.len() => {
                let v = [u64::MAX, 1 << 63, 1 << 40, 0][rng.below(4) as usize];
                data[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
            _ => {}
        }
    }
}

#[test]
fn fuzz_octree_reader() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.voxlod");
    let mut rng = Rng(2026);
    let good_nodes = nodes(&mut rng);
    let good = file(&good_nodes);
    assert!(
        check(&path, &good, "the seed"),
        "the unmutated file must read"
    );
    let mut accepted = [0usize; 3];
    for i in 0..iters() {
        // raw bytes: mostly the checksums catch them
        let mut f = good.clone();
        mutate(&mut rng, &mut f);
        if check(&path, &f, &format!("raw mutant {i}")) && f != good {
            accepted[0] += 1;
        }
        // checksums recomputed: the structural checks must catch them
        let mut f = good.clone();
        mutate(&mut rng, &mut f);
        if f.len() >= 128 {
            fix_crcs(&mut f);
        }
        accepted[1] += check(&path, &f, &format!("re-checksummed mutant {i}")) as usize;
        // a node's block mutated, recompressed, every checksum right: the decoder's checks
        let k = rng.below(good_nodes.len() as u64) as usize;
        let mut nodes: Vec<RawNode> = good_nodes.clone();
        let voxels = Reader::open(&{
            std::fs::write(&path, &good).unwrap();
            path.clone()
        })
        .unwrap()
        .read_node(k)
        .unwrap();
        let mut block = reference_block(&voxels);
        mutate(&mut rng, &mut block);
        let n = &mut nodes[k];
        n.payload = zstd::bulk::compress(&block, 1).unwrap();
        n.block_crc32 = crc32fast::hash(&block);
        accepted[2] += check(
            &path,
            &file(&nodes),
            &format!("block mutant {i} of node {k}"),
        ) as usize;
    }
    eprintln!(
        "{} mutants per mode; accepted (raw, re-checksummed, block): {accepted:?}",
        iters()
    );
    // a raw mutation is always caught (every byte is under a checksum or a structural check)
    assert_eq!(accepted[0], 0);
}
