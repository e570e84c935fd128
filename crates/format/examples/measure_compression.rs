//! Measures bytes per voxel of node payloads on synthetic but realistic voxels: the surface of
//! a sphere (smooth normals, face masks with caps, Morton order) under three colour models,
//! for the transform of format v1 against simpler ones, at several zstd levels; then a whole
//! file with all LOD levels (built by the sort-and-compact rule of docs/FORMAT.md).
//!
//! `cargo run -p voxlod-format --release --example measure_compression`

#[path = "../tests/all/common/mod.rs"]
mod common;

use std::time::Instant;

use common::sphere::{sphere, sphere_grid, Colour};
use voxlod_format::{encode_node, FileSpec, Reader, Writer, MODE_CONSERVATIVE};

fn shuffled(words: impl Iterator<Item = u32>, n: usize) -> Vec<u8> {
    let mut out = vec![0u8; 4 * n];
    for (j, w) in words.enumerate() {
        for k in 0..4 {
            out[k * n + j] = w.to_le_bytes()[k];
        }
    }
    out
}

fn main() {
    println!("single chunk: sphere r=120 in a 256³ chunk, bytes per voxel (compression MB/s of the 12 B/voxel input)");
    for colour in [Colour::White, Colour::Smooth, Colour::Noisy] {
        let v = sphere([128.3, 127.6, 128.9], 120.0, colour);
        let n = v.len();
        let soa: Vec<u8> = [
            v.iter()
                .flat_map(|x| x.pos_mask.to_le_bytes())
                .collect::<Vec<u8>>(),
            v.iter().flat_map(|x| x.normal.to_le_bytes()).collect(),
            v.iter().flat_map(|x| x.color.to_le_bytes()).collect(),
        ]
        .concat();
        let shuf = [
            shuffled(v.iter().map(|x| x.pos_mask), n),
            shuffled(v.iter().map(|x| x.normal), n),
            shuffled(v.iter().map(|x| x.color), n),
        ]
        .concat();
        println!("{colour:?} colour, {n} voxels:");
        let raw: [(&str, &[u8]); 3] = [
            (
                "12-byte records (AoS), plain zstd",
                bytemuck::cast_slice(&v),
            ),
            ("SoA, no shuffle", &soa),
            ("SoA + byte shuffle only", &shuf),
        ];
        for level in [3, 9, 19] {
            let mut line = format!("  zstd {level:2}:");
            for (name, bytes) in raw {
                let t = Instant::now();
                let c = zstd::bulk::compress(bytes, level).unwrap();
                let mbs = bytes.len() as f64 / t.elapsed().as_secs_f64() / 1e6;
                line += &format!(
                    "  {name}: {:.2} ({mbs:.0} MB/s) |",
                    c.len() as f64 / n as f64
                );
            }
            let t = Instant::now();
            let e = encode_node(&v, level).unwrap();
            let mbs = 12.0 * n as f64 / t.elapsed().as_secs_f64() / 1e6;
            line += &format!(
                "  format v1 (Morton delta + shuffle + plane delta): {:.2} ({mbs:.0} MB/s)",
                e.payload().len() as f64 / n as f64
            );
            println!("{line}");
        }
    }

    println!(
        "\nwhole file, all LOD levels: sphere r=1000 in a 2048³ grid (8³ leaf chunks, 4 levels)"
    );
    let res = 2048u32;
    let spec = FileSpec::new(res, MODE_CONSERVATIVE, [0.0; 3], 1.0);
    for colour in [Colour::White, Colour::Smooth, Colour::Noisy] {
        let leaves = sphere_grid(res, [1024.3, 1023.6, 1024.9], 1000.0, colour)
            .into_iter()
            .map(|(g, v)| (g, v.mask(), v.normal, v.color));
        let levels = common::build_levels(&spec, leaves);
        let dir = std::env::temp_dir().join(format!("voxlod-measure-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sphere.voxlod");
        let leaves: Vec<[u32; 3]> = levels[0].keys().copied().collect();
        let t = Instant::now();
        let mut w = Writer::create(&path, spec).unwrap();
        let mut total = 0u64;
        for (l, p, m) in common::post_order(spec.levels, &leaves) {
            let vs = &levels[l as usize][&p];
            total += vs.len() as u64;
            w.write_node(
                l,
                p,
                m,
                &encode_node(vs, voxlod_format::DEFAULT_ZSTD_LEVEL).unwrap(),
            )
            .unwrap();
        }
        let size = w
            .finish(&serde_json::json!({ "example": "measure_compression" }))
            .unwrap();
        let write_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let r = Reader::open(&path).unwrap();
        let mut buf = Vec::new();
        for i in 0..r.nodes().len() {
            r.read_node_into(i, &mut buf).unwrap();
        }
        let read_s = t.elapsed().as_secs_f64();
        println!(
            "  {colour:?}: {} nodes, {total} voxels ({} leaf), file {size} bytes = {:.2} bytes/voxel at the default level; write {:.1} M voxels/s, read {:.1} M voxels/s (one thread)",
            r.nodes().len(),
            levels[0].values().map(|v| v.len()).sum::<usize>(),
            size as f64 / total as f64,
            total as f64 / write_s / 1e6,
            total as f64 / read_s / 1e6,
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
