//! Writing and reading back: random octrees, node sizes from 1 voxel to a full chunk, the
//! documented layout (the writer's bytes equal an independent field-by-field assembly),
//! determinism, and the sphere's compressed size.

use crate::common;

use common::{assemble, post_order, random_voxels, reference_block, sphere, RawNode, Rng};
use serde_json::json;
use voxlod_format::voxel::Voxel;
use voxlod_format::{
    encode_node, temp_path, FileSpec, Reader, Writer, DEFAULT_ZSTD_LEVEL, MODE_CONSERVATIVE,
    MODE_THIN,
};

/// A random octree over a `resolution`³ grid: leaves picked at random, every node with
/// random voxels of a size drawn from `sizes`. Returns the nodes in write order.
fn random_tree(
    rng: &mut Rng,
    resolution: u32,
    leaf_fraction: f64,
    sizes: &[usize],
) -> Vec<(u32, [u32; 3], u8, Vec<Voxel>)> {
    let spec = FileSpec::new(resolution, MODE_CONSERVATIVE, [0.0; 3], 1.0);
    let c = spec.chunks_per_axis(0);
    let mut leaves = Vec::new();
    for z in 0..c {
        for y in 0..c {
            for x in 0..c {
                if (rng.below(1000) as f64) < leaf_fraction * 1000.0 {
                    leaves.push([x, y, z]);
                }
            }
        }
    }
    post_order(spec.levels, &leaves)
        .into_iter()
        .map(|(l, p, m)| {
            let n = sizes[rng.below(sizes.len() as u64) as usize];
            (l, p, m, random_voxels(rng, n))
        })
        .collect()
}

fn write(
    path: &std::path::Path,
    spec: FileSpec,
    nodes: &[(u32, [u32; 3], u8, Vec<Voxel>)],
    level: i32,
) -> u64 {
    let mut w = Writer::create(path, spec).unwrap();
    for (l, p, m, v) in nodes {
        w.write_node(*l, *p, *m, &encode_node(v, level).unwrap())
            .unwrap();
    }
    let written = w.bytes_written();
    let size = w
        .finish(&json!({ "tool": "roundtrip test", "nodes": nodes.len() }))
        .unwrap();
    assert!(size > written);
    size
}

#[test]
fn random_octrees_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for (case, &(resolution, fraction)) in [(256u32, 1.0), (512, 0.5), (1024, 0.15), (2048, 0.01)]
        .iter()
        .enumerate()
    {
        let nodes = random_tree(
            &mut rng,
            resolution,
            fraction,
            &[1, 2, 3, 17, 255, 256, 1000, 4099],
        );
        let spec = FileSpec::new(resolution, MODE_THIN, [-1.5, 2.0, 1e6], 0.125);
        let path = dir.path().join(format!("case{case}.voxlod"));
        let size = write(&path, spec, &nodes, 1);
        assert!(!temp_path(&path).exists());

        let r = Reader::open(&path).unwrap();
        assert_eq!(r.file_size(), size);
        assert_eq!(r.spec(), spec);
        assert_eq!(r.nodes().len(), nodes.len());
        assert_eq!(
            r.total_voxels(),
            nodes.iter().map(|n| n.3.len() as u64).sum::<u64>()
        );
        assert_eq!(
            r.manifest().unwrap(),
            json!({ "tool": "roundtrip test", "nodes": nodes.len() })
        );
        assert_eq!(r.root(), nodes.len().checked_sub(1));
        let mut buf = Vec::new();
        for (i, (l, p, m, v)) in nodes.iter().enumerate() {
            let e = r.nodes()[i];
            assert_eq!(
                (e.level, e.pos(), e.child_mask, e.voxel_count),
                (*l, *p, *m as u32, v.len() as u32)
            );
            // bounds by brute force
            let lo: [u8; 3] = std::array::from_fn(|a| v.iter().map(|x| x.pos()[a]).min().unwrap());
            let hi: [u8; 3] = std::array::from_fn(|a| v.iter().map(|x| x.pos()[a]).max().unwrap());
            assert_eq!(e.bounds(), (lo, hi));
            assert_eq!(r.find(*l, *p), Some(i));
            r.read_node_into(i, &mut buf).unwrap();
            assert_eq!(&buf, v, "node {i}");
            for (o, child) in r.children(i).iter().enumerate() {
                assert_eq!(child.is_some(), m >> o & 1 == 1);
                if let Some(c) = child {
                    assert_eq!(r.nodes()[*c].pos(), e.child_pos(o as u32));
                    assert_eq!(r.nodes()[*c].level + 1, e.level);
                }
            }
        }
        // absent nodes
        let present: std::collections::HashSet<_> = nodes.iter().map(|n| (n.0, n.1)).collect();
        for l in 0..spec.levels {
            let c = spec.chunks_per_axis(l);
            for p in [
                [0, 0, 0],
                [c - 1, c - 1, c - 1],
                [c / 2, 0, c - 1],
                [c, 0, 0],
                [0, u32::MAX, 0],
            ] {
                let expect = present.contains(&(l, p));
                assert_eq!(r.find(l, p).is_some(), expect, "find({l}, {p:?})");
            }
        }
        assert_eq!(r.find(spec.levels, [0, 0, 0]), None);
        assert!(r
            .read_node(nodes.len())
            .unwrap_err()
            .to_string()
            .contains("no node"));
    }
}

#[test]
fn writer_bytes_match_the_documented_layout() {
    // An independent assembly of the bytes from docs/FORMAT.md (common::assemble, using the
    // documented transform common::reference_block) must equal the writer's output.
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(77);
    let nodes = random_tree(&mut rng, 512, 0.4, &[1, 5, 300, 2000]);
    let spec = FileSpec::new(512, MODE_THIN, [0.25, -8.0, 3.5], 0.002);
    let path = dir.path().join("layout.voxlod");
    let level = 5;
    write(&path, spec, &nodes, level);
    let raw: Vec<RawNode> = nodes
        .iter()
        .map(|(l, p, m, v)| RawNode::from_voxels(*l, *p, *m as u32, v, level))
        .collect();
    let manifest =
        serde_json::to_vec(&json!({ "tool": "roundtrip test", "nodes": nodes.len() })).unwrap();
    let expected = assemble(512, 2, 1, [0.25, -8.0, 3.5], 0.002, &raw, &manifest);
    let got = std::fs::read(&path).unwrap();
    assert_eq!(got.len(), expected.len());
    assert!(
        got == expected,
        "first difference at byte {:?}",
        got.iter().zip(&expected).position(|(a, b)| a != b)
    );
}

#[test]
fn payload_is_the_documented_transform_in_one_zstd_frame() {
    let mut rng = Rng(5);
    for n in [1usize, 2, 3, 64, 5000] {
        let v = random_voxels(&mut rng, n);
        let e = encode_node(&v, 3).unwrap();
        let block = zstd::bulk::decompress(e.payload(), 12 * n).unwrap();
        assert_eq!(block, reference_block(&v));
        assert_eq!(e.block_crc32(), crc32fast::hash(&block));
        assert_eq!(e.payload_crc32(), crc32fast::hash(e.payload()));
        assert_eq!(e.voxel_count() as usize, n);
        // the frame records its content size
        assert_eq!(
            zstd::zstd_safe::get_frame_content_size(e.payload()).ok(),
            Some(Some(12 * n as u64))
        );
    }
}

#[test]
fn full_chunk_round_trip() {
    // the largest node: every one of the 256³ positions
    let v: Vec<Voxel> = (0..1u32 << 24)
        .map(|m| {
            let p = common::unmorton(m);
            Voxel::new(
                p,
                (m % 63) as u8,
                common::no_minus_512(m & 0x3fff_ffff),
                m.wrapping_mul(2_654_435_761),
            )
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("full.voxlod");
    let spec = FileSpec::new(256, MODE_CONSERVATIVE, [0.0; 3], 1.0);
    let mut w = Writer::create(&path, spec).unwrap();
    let enc = encode_node(&v, 1).unwrap();
    assert_eq!(enc.bounds(), ([0; 3], [255; 3]));
    w.write_node(0, [0, 0, 0], 0, &enc).unwrap();
    w.finish(&json!({})).unwrap();
    let r = Reader::open(&path).unwrap();
    assert_eq!(r.total_voxels(), 1 << 24);
    let back = r.read_node(0).unwrap();
    assert!(back == v);
}

#[test]
fn empty_file_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.voxlod");
    let spec = FileSpec::new(4096, MODE_CONSERVATIVE, [1.0, 2.0, 3.0], 0.5);
    let size = Writer::create(&path, spec)
        .unwrap()
        .finish(&json!({}))
        .unwrap();
    assert_eq!(size, 128 + 2); // header, no payloads, no index, "{}"
    let r = Reader::open(&path).unwrap();
    assert_eq!((r.nodes().len(), r.root(), r.total_voxels()), (0, None, 0));
    assert_eq!(r.manifest().unwrap(), json!({}));
    assert_eq!(r.spec(), spec);
}

#[test]
fn output_is_deterministic_and_encoding_thread_independent() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(99);
    let nodes = random_tree(&mut rng, 1024, 0.1, &[10, 3000]);
    let spec = FileSpec::new(1024, MODE_CONSERVATIVE, [0.0; 3], 1.0);
    let (a, b) = (dir.path().join("a.voxlod"), dir.path().join("b.voxlod"));
    write(&a, spec, &nodes, 3);
    // encode on two threads (in the other order), write in index order
    let encoded: Vec<_> = std::thread::scope(|s| {
        let half = nodes.len() / 2;
        let nodes = &nodes;
        let t1 = s.spawn(move || {
            nodes[half..]
                .iter()
                .rev()
                .map(|n| encode_node(&n.3, 3).unwrap())
                .collect::<Vec<_>>()
        });
        let t0 = s.spawn(move || {
            nodes[..half]
                .iter()
                .map(|n| encode_node(&n.3, 3).unwrap())
                .collect::<Vec<_>>()
        });
        let mut e = t0.join().unwrap();
        e.extend(t1.join().unwrap().into_iter().rev());
        e
    });
    let mut w = Writer::create(&b, spec).unwrap();
    for ((l, p, m, _), e) in nodes.iter().zip(&encoded) {
        w.write_node(*l, *p, *m, e).unwrap();
    }
    w.finish(&json!({ "tool": "roundtrip test", "nodes": nodes.len() }))
        .unwrap();
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap());
}

#[test]
fn reader_is_shared_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Reader>();
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(3);
    let nodes = random_tree(&mut rng, 512, 0.6, &[100, 4000]);
    let path = dir.path().join("mt.voxlod");
    write(&path, FileSpec::new(512, 0, [0.0; 3], 1.0), &nodes, 1);
    let r = Reader::open(&path).unwrap();
    std::thread::scope(|s| {
        for t in 0..2 {
            let (r, nodes) = (&r, &nodes);
            s.spawn(move || {
                for (i, n) in nodes.iter().enumerate().filter(|(i, _)| i % 2 == t) {
                    assert_eq!(r.read_node(i).unwrap(), n.3);
                }
            });
        }
    });
}

#[test]
fn sphere_compresses_below_six_bytes_per_voxel() {
    // the brief's size target, on the worst colour model (noisy scan colours), default level
    let v = sphere::sphere([128.3, 127.6, 128.9], 120.0, sphere::Colour::Noisy);
    assert!(v.len() > 200_000);
    let e = encode_node(&v, DEFAULT_ZSTD_LEVEL).unwrap();
    let bpv = e.payload().len() as f64 / v.len() as f64;
    assert!(bpv < 6.0, "{bpv} bytes per voxel");
    // and the transform matters: plain zstd of the 12-byte records is far bigger
    let plain = zstd::bulk::compress(bytemuck::cast_slice(&v), DEFAULT_ZSTD_LEVEL).unwrap();
    assert!((plain.len() as f64) > 2.0 * e.payload().len() as f64);
}

#[test]
fn sphere_generator_matches_brute_force() {
    // the column-restricted generator (test helper) against testing every cube of the chunk
    let (c, r) = ([100.3, 131.7, 90.2], 61.0);
    let fast = sphere::sphere(c, r, sphere::Colour::White);
    let mut brute = 0;
    for z in 0..256 {
        for y in 0..256 {
            for x in 0..256 {
                let p = [x as f64, y as f64, z as f64];
                let (mut near, mut far) = (0.0, 0.0);
                for a in 0..3 {
                    let (lo, hi) = (p[a] - c[a], p[a] + 1.0 - c[a]);
                    let n: f64 = if lo > 0.0 {
                        lo
                    } else if hi < 0.0 {
                        hi
                    } else {
                        0.0
                    };
                    near += n * n;
                    far += lo.abs().max(hi.abs()).powi(2);
                }
                if near <= r * r && far >= r * r {
                    brute += 1;
                }
            }
        }
    }
    assert_eq!(fast.len(), brute);
}

#[test]
fn worked_example_of_format_md() {
    use voxlod_format::voxel::{border_caps, face_mask, morton8, pack_color, pack_normal};
    // docs/FORMAT.md section 12
    let n = pack_normal([0.6, -0.8, 0.0]);
    assert_eq!(n, 0x0009_9D33);
    let p = [3u8, 200, 17];
    let mask = face_mask(n) | border_caps(p);
    assert_eq!(mask, 0x09);
    let v = Voxel::new(p, mask, n, pack_color([200, 150, 100, 255]));
    assert_eq!(
        bytemuck::bytes_of(&v),
        &[0x03, 0xC8, 0x11, 0x09, 0x33, 0x9D, 0x09, 0x00, 0xC8, 0x96, 0x64, 0xFF]
    );
    assert_eq!(morton8(3, 200, 17), 0x48_440D);
    let e = encode_node(&[v], 3).unwrap();
    let block = zstd::bulk::decompress(e.payload(), 12).unwrap();
    assert_eq!(
        block,
        [0x0D, 0x44, 0x48, 0x09, 0x33, 0x9D, 0x09, 0x00, 0xC8, 0x96, 0x64, 0xFF]
    );
    let spec = FileSpec::new(1024, MODE_CONSERVATIVE, [-10.0, 0.0, 0.0], 0.5);
    assert_eq!(
        spec.voxel_min_corner(0, [2, 0, 5], p),
        [247.5, 100.0, 648.5]
    );
    // the two-voxel block
    let a = Voxel::new([1, 0, 0], 0x01, 0x0000_01FF, 0x1122_3344);
    let b = Voxel::new([0, 1, 0], 0x04, 0x0007_FC00, 0x1122_3355);
    let e = encode_node(&[a, b], 3).unwrap();
    #[rustfmt::skip]
    let expected = [
        0x01, 0x01, 0x00, 0x00, 0x00, 0x00, 0x01, 0x04,
        0xFF, 0x01, 0x01, 0xFB, 0x00, 0x07, 0x00, 0x00,
        0x44, 0x11, 0x33, 0x00, 0x22, 0x00, 0x11, 0x00,
    ];
    assert_eq!(zstd::bulk::decompress(e.payload(), 24).unwrap(), expected);
}

#[test]
fn crc_variant_is_zlib_crc32() {
    assert_eq!(crc32fast::hash(b"123456789"), 0xCBF4_3926);
}
