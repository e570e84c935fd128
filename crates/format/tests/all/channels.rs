//! Optional channels (docs/FORMAT.md section 14): a file with the material channel reads
//! back what was written, its directory and payload placement are the documented bytes
//! (checked field by field here, not through the crate's own parser), a file without channels
//! is the version-1 bytes, an unknown channel is skipped by design, and corruption of the
//! directory or a channel payload is an error naming what is wrong.

use crate::common;

use common::{post_order, random_voxels, Rng};
use serde_json::json;
use voxlod_format::channel::{CHANNEL_MATERIAL, CHANNEL_TRIANGLES};
use voxlod_format::triangles::{oct_encode, SourceMesh};
use voxlod_format::{
    encode_materials, encode_node, encode_source, FileSpec, Reader, Writer, MODE_CONSERVATIVE,
};

type Node = (u32, [u32; 3], u8, Vec<voxlod_format::Voxel>, Vec<u32>);

/// A small random octree at 512³ with random per-voxel materials (runs of equal ids).
fn tree(seed: u64) -> Vec<Node> {
    let mut rng = Rng(seed);
    let leaves = [[0, 0, 0], [1, 0, 0], [1, 1, 1]];
    post_order(2, &leaves)
        .into_iter()
        .map(|(l, p, m)| {
            let len = 1 + rng.below(3000) as usize;
            let v = random_voxels(&mut rng, len);
            let mut mats = Vec::with_capacity(v.len());
            let mut cur = rng.below(5) as u32;
            for _ in 0..v.len() {
                if rng.below(20) == 0 {
                    cur = rng.below(300) as u32;
                }
                mats.push(cur);
            }
            (l, p, m, v, mats)
        })
        .collect()
}

fn spec() -> FileSpec {
    FileSpec::new(512, MODE_CONSERVATIVE, [1.0, 2.0, 3.0], 0.25)
}

fn write(path: &std::path::Path, nodes: &[Node], channels: &[u32]) -> Vec<u8> {
    let mut w = Writer::create_with_channels(path, spec(), channels).unwrap();
    for (l, p, m, v, mats) in nodes {
        let enc = encode_node(v, 3).unwrap();
        let mat = encode_materials(mats, 3).unwrap();
        // some bytes for the other channels, on leaves only
        let extra = encode_materials(&[9], 3).unwrap();
        let src = encode_source(&source_mesh(p[0] + 7 * p[1]), 3).unwrap();
        let cs: Vec<_> = channels
            .iter()
            .map(|&id| match id {
                CHANNEL_MATERIAL => Some(&mat),
                CHANNEL_TRIANGLES if *l == 0 => Some(&src),
                _ if *l == 0 => Some(&extra),
                _ => None,
            })
            .collect();
        w.write_node_with(*l, *p, *m, &enc, &cs).unwrap();
    }
    w.finish(&json!({"materials": ["", "a"]})).unwrap();
    std::fs::read(path).unwrap()
}

/// A small source mesh (FORMAT.md 14.4) that differs with `seed`: a strip of triangles.
fn source_mesh(seed: u32) -> SourceMesh {
    let n = 3 + seed as usize % 17;
    let positions: Vec<[u16; 3]> = (0..n as u16 + 2)
        .map(|k| [16384 + 100 * k, 16384 + (k % 2) * 128 + seed as u16, 20000])
        .collect();
    SourceMesh {
        normals: Some(
            positions
                .iter()
                .map(|_| oct_encode([0.0, 0.6, 0.8]))
                .collect(),
        ),
        colors: None,
        triangles: (0..n as u32).map(|k| [k, k + 1, k + 2]).collect(),
        materials: Some((0..n as u16).map(|k| k % 2).collect()),
        positions,
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

#[test]
fn material_channel_roundtrip_and_layout() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.voxlod");
    let nodes = tree(7);
    let bytes = write(&path, &nodes, &[CHANNEL_MATERIAL]);
    let r = Reader::open(&path).unwrap();
    assert_eq!(r.channel_ids(), vec![CHANNEL_MATERIAL]);
    assert!(r.has_materials());
    for (i, n) in nodes.iter().enumerate() {
        assert_eq!(r.read_node(i).unwrap(), n.3);
        assert_eq!(r.read_materials(i).unwrap().unwrap(), n.4);
    }

    // the documented bytes, read by hand: version 2, directory after the index
    assert_eq!(u32_at(&bytes, 8), 2);
    let node_count = u64_at(&bytes, 64) as usize;
    let index_end = (u64_at(&bytes, 72) + u64_at(&bytes, 80)) as usize;
    let manifest_offset = u64_at(&bytes, 88) as usize;
    let dir_bytes = &bytes[index_end..manifest_offset];
    assert_eq!(u32_at(&bytes, 120), crc32fast::hash(dir_bytes));
    assert_eq!(dir_bytes.len(), 8 + 16 + 24 * node_count);
    assert_eq!((u32_at(dir_bytes, 0), u32_at(dir_bytes, 4)), (1, 0));
    assert_eq!(
        &dir_bytes[8..24],
        &[1, 0, 0, 0, 24, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    );
    // payloads back to back: voxel payload, then the material payload of the same node
    let mut at = 128u64;
    for (i, n) in nodes.iter().enumerate() {
        let e = u64_at(&bytes, index_end - 64 * node_count + 64 * i + 24);
        let size = u64_at(&bytes, index_end - 64 * node_count + 64 * i + 32);
        assert_eq!(e, at);
        at += size;
        let c = 24 + 24 * i;
        assert_eq!(
            u64_at(dir_bytes, c),
            at,
            "material payload follows the voxel payload"
        );
        let csize = u64_at(dir_bytes, c + 8);
        let payload = &bytes[at as usize..(at + csize) as usize];
        assert_eq!(u32_at(dir_bytes, c + 16), crc32fast::hash(payload));
        let mut table = n.4.clone();
        table.sort();
        table.dedup();
        assert_eq!(u32_at(dir_bytes, c + 20) as usize, table.len());
        // the block: the ascending table, then the low and high bytes of each index
        let block = zstd::bulk::decompress(payload, 1 << 24).unwrap();
        let nv = n.3.len();
        assert_eq!(block.len(), 4 * table.len() + 2 * nv);
        for (k, m) in table.iter().enumerate() {
            assert_eq!(u32_at(&block, 4 * k), *m);
        }
        for j in 0..nv {
            let idx = block[4 * table.len() + j] as usize
                | (block[4 * table.len() + nv + j] as usize) << 8;
            assert_eq!(table[idx], n.4[j]);
        }
        at += csize;
    }
    assert!(index_end - 64 * node_count - at as usize <= 7);
}

#[test]
fn no_channels_is_version_1_and_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = tree(3);
    let a = dir.path().join("a.voxlod");
    let mut w = Writer::create(&a, spec()).unwrap();
    for (l, p, m, v, _) in &nodes {
        w.write_node(*l, *p, *m, &encode_node(v, 3).unwrap())
            .unwrap();
    }
    w.finish(&json!({"materials": ["", "a"]})).unwrap();
    let b = dir.path().join("b.voxlod");
    let bytes = write(&b, &nodes, &[]);
    assert_eq!(std::fs::read(&a).unwrap(), bytes);
    assert_eq!(u32_at(&bytes, 8), 1);
    let r = Reader::open(&b).unwrap();
    assert!(!r.has_materials() && r.channel_ids().is_empty());
    assert_eq!(r.read_materials(0).unwrap(), None);
}

#[test]
fn unknown_channels_are_skipped_by_design() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("u.voxlod");
    let nodes = tree(11);
    write(&path, &nodes, &[CHANNEL_MATERIAL, CHANNEL_TRIANGLES, 40]);
    let r = Reader::open(&path).unwrap();
    assert_eq!(r.channel_ids(), vec![1, 2, 40]);
    for (i, n) in nodes.iter().enumerate() {
        assert_eq!(r.read_node(i).unwrap(), n.3);
        assert_eq!(r.read_materials(i).unwrap().unwrap(), n.4);
        assert_eq!(r.read_channel_payload(i, 40).unwrap().is_some(), n.0 == 0);
    }
}

#[test]
fn corrupt_channels_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.voxlod");
    let nodes = tree(5);
    let good = write(&path, &nodes, &[CHANNEL_MATERIAL]);
    let index_end = (u64_at(&good, 72) + u64_at(&good, 80)) as usize;
    let open = |bytes: &[u8]| {
        let p = dir.path().join("bad.voxlod");
        std::fs::write(&p, bytes).unwrap();
        Reader::open(&p).map(|r| {
            (0..r.nodes().len())
                .map(|i| r.read_materials(i))
                .collect::<Result<Vec<_>, _>>()
        })
    };
    // a flipped directory byte: checksum
    let mut b = good.clone();
    b[index_end + 30] ^= 1;
    assert!(open(&b)
        .unwrap_err()
        .to_string()
        .contains("channel directory checksum"));
    // a flipped material payload byte: that node's checksum
    let mut b = good.clone();
    let first = u64_at(&good, index_end + 24) as usize;
    b[first + 5] ^= 1;
    let e = open(&b).unwrap().unwrap_err().to_string();
    assert!(e.contains("channel 1 payload checksum"), "{e}");
    // version 1 claimed for a file with a directory: the manifest does not follow the index
    let mut b = good.clone();
    b[8] = 1;
    b[120..124].copy_from_slice(&[0; 4]);
    let crc = crc32fast::hash(&b[..124]);
    b[124..128].copy_from_slice(&crc.to_le_bytes());
    assert!(open(&b)
        .unwrap_err()
        .to_string()
        .contains("does not follow the index"));
    // version 3: unsupported, said clearly
    let mut b = good.clone();
    b[8] = 3;
    let crc = crc32fast::hash(&b[..124]);
    b[124..128].copy_from_slice(&crc.to_le_bytes());
    assert!(open(&b)
        .unwrap_err()
        .to_string()
        .contains("version 3 is not supported"));
}

#[test]
fn writer_refuses_missing_or_mismatched_material_payloads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.voxlod");
    let v = random_voxels(&mut Rng(1), 10);
    let enc = encode_node(&v, 3).unwrap();
    let mut w =
        Writer::create_with_channels(&path, FileSpec::new(256, 0, [0.0; 3], 1.0), &[1]).unwrap();
    assert!(w
        .write_node(0, [0; 3], 0, &enc)
        .unwrap_err()
        .to_string()
        .contains("no material payload"));
    let short = encode_materials(&[1; 9], 3).unwrap();
    assert!(w
        .write_node_with(0, [0; 3], 0, &enc, &[Some(&short)])
        .unwrap_err()
        .to_string()
        .contains("encoded for 9 voxels"));
    assert!(
        Writer::create_with_channels(&path, FileSpec::new(256, 0, [0.0; 3], 1.0), &[2, 1]).is_err()
    );
}

#[test]
fn source_channel_roundtrip_and_corruption() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.voxlod");
    let nodes = tree(5);
    let bytes = write(&path, &nodes, &[CHANNEL_TRIANGLES]);
    let r = Reader::open(&path).unwrap();
    assert!(r.has_source_triangles() && !r.has_materials());
    let mut total = 0;
    for (i, n) in nodes.iter().enumerate() {
        let got = r.source_triangles(i).unwrap();
        if n.0 == 0 {
            let want = source_mesh(n.1[0] + 7 * n.1[1]);
            total += want.triangles.len() as u64;
            assert_eq!(got.unwrap(), want);
        } else {
            assert!(got.is_none());
        }
    }
    assert_eq!(r.source_triangle_count(), total);
    // the first leaf's source payload: right after its voxel payload
    let dir_at = (u64_at(&bytes, 72) + u64_at(&bytes, 80)) as usize;
    let entry = dir_at + 8 + 16;
    let (off, size) = (
        u64_at(&bytes, entry) as usize,
        u64_at(&bytes, entry + 8) as usize,
    );
    let index = u64_at(&bytes, 72) as usize;
    assert_eq!(
        off as u64,
        u64_at(&bytes, index + 24) + u64_at(&bytes, index + 32)
    );
    // a flipped payload byte: the checksum names the channel and the node
    let mut b = bytes.clone();
    b[off + size / 2] ^= 0x40;
    std::fs::write(&path, &b).unwrap();
    let e = Reader::open(&path)
        .unwrap()
        .source_triangles(0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("node 0") && e.contains("channel 2 payload checksum mismatch"),
        "{e}"
    );
    // a valid frame and CRC around a bad block (an index code past the vertices used): the
    // decoder's check, named
    let mesh = source_mesh(0);
    let mut block = mesh.to_block();
    let codes = 16 + mesh.positions.len() * 10;
    block[codes + 3] = 200;
    let frame = zstd::bulk::compress(&block, 3).unwrap();
    let e = voxlod_format::triangles::decode_source(&frame, 3).unwrap_err();
    assert!(e.contains("reaches before the first vertex"), "{e}");
    // a source payload on a parent is refused by the writer
    let mut w =
        Writer::create_with_channels(&dir.path().join("p.voxlod"), spec(), &[CHANNEL_TRIANGLES])
            .unwrap();
    let (l, p, m, v, _) = &nodes[0];
    let enc = encode_node(v, 3).unwrap();
    let src = encode_source(&source_mesh(1), 3).unwrap();
    w.write_node_with(*l, *p, *m, &enc, &[Some(&src)]).unwrap();
    let parent = nodes.iter().find(|n| n.0 == 1).unwrap();
    let e = w
        .write_node_with(
            parent.0,
            parent.1,
            parent.2,
            &encode_node(&parent.3, 3).unwrap(),
            &[Some(&src)],
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("leaf chunks (level 0) only"), "{e}");
}
