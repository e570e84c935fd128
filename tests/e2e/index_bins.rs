//! Bins of face indices (a memory-mapped binary PLY of fixed-size triangle records: the bins
//! hold each triangle's face record, the voxelize stage reads the triangle from the input by
//! it): the same bytes as bins of blocks (`VOXLOD_BINS=blocks`, the internal switch) in both
//! modes and with source geometry, a quarter or less of the temporary bytes, and any other
//! face layout takes the bins of blocks.

use super::*;

/// Builds `input` with `extra`, with the index bins or (`blocks`) without; the summary and
/// the output's bytes.
fn build(d: &Path, input: &Path, extra: &[&str], blocks: bool) -> (serde_json::Value, Vec<u8>) {
    let out = d.join(if blocks {
        "blocks.voxlod"
    } else {
        "index.voxlod"
    });
    let mut a = build_args(input, &out, extra);
    a.push("--json".into());
    let mut c = Command::new(BIN);
    c.args(&a).current_dir(d).env("NO_COLOR", "1");
    if blocks {
        c.env("VOXLOD_BINS", "blocks");
    }
    let o = c.output().unwrap();
    ok(&o);
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    (s, bytes)
}

/// A generated scan (colours, straddling triangles at 1024³, degenerate faces none or some)
/// builds to the same bytes with index bins as with blocks: conservative and thin, with
/// `--source-geometry`, and on the sample (no colours); the index bins are 4 bytes per
/// binned triangle, the temporary bytes written.
#[test]
fn index_bins_build_the_bytes_of_block_bins() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&voxlod(
        &["gen", "-q", "-n", "200000", "--seed", "5", "-o", "g.ply"],
        d,
    ));
    let gen = d.join("g.ply");
    let cases: [(&Path, &[&str]); 4] = [
        (&gen, &["-r", "1024"]),
        (&gen, &["-r", "2048", "-m", "thin"]),
        (&gen, &["-r", "512", "--source-geometry"]),
        (&sample(), &["-r", "2048"]),
    ];
    for (input, extra) in cases {
        let what = format!("{} {extra:?}", input.display());
        let (si, index) = build(d, input, extra, false);
        let (sb, blocks) = build(d, input, extra, true);
        assert_eq!(si["bin_index_bytes"], 4, "{what}");
        assert_eq!(sb["bin_index_bytes"], 0, "{what}");
        assert_eq!(si["binned_during_ingest"], true, "{what}");
        assert_eq!(si["binned_triangles"], sb["binned_triangles"], "{what}");
        let binned = si["binned_triangles"].as_u64().unwrap();
        assert!(binned > 0);
        assert_eq!(si["temp_bytes_written"], binned * 4, "{what}");
        assert!(
            sb["temp_bytes_written"].as_u64().unwrap() > binned * 8,
            "{what}: blocks are larger than indices"
        );
        assert!(index == blocks, "{what}: the index bins changed the output");
        // the planned upper bound of the temporary disk counts 4-byte entries, not records
        // (1.5 entries per estimated triangle, two estimated triangles per face)
        let faces = si["triangles"].as_u64().unwrap() + si["degenerate_skipped"].as_u64().unwrap();
        let record = sb["record_bytes"].as_u64().unwrap();
        assert_eq!(si["temp_disk"], faces * 2 * 3 * 4 / 2, "{what}");
        assert_eq!(sb["temp_disk"], faces * 2 * 3 * record / 2, "{what}");
    }
}

/// Faces that are not all triangle records of one size (a quad among them), and inputs that
/// are not mapped (gzip), are binned as blocks and build as before.
#[test]
fn other_face_layouts_take_block_bins() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tris = sample_triangles();
    // the sample's triangles, the first two as one quad (its fourth corner is the second
    // triangle's): the records are not all 13 bytes
    let mut out = voxlod_io::PlyHeader::binary_le()
        .element("vertex", (tris.len() * 3 + 1) as u64)
        .properties("float", &["x", "y", "z"])
        .element("face", tris.len() as u64)
        .list("uchar", "int", "vertex_indices")
        .end()
        .into_bytes();
    for p in tris.iter().flat_map(|t| t.v.iter()) {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for c in [1.0f32, 2.0, 3.0] {
        out.extend_from_slice(&c.to_le_bytes());
    }
    for i in 0..tris.len() as i32 {
        if i == 0 {
            out.push(4);
            for k in [0, 1, 2, 3 * tris.len() as i32] {
                out.extend_from_slice(&k.to_le_bytes());
            }
            continue;
        }
        out.push(3);
        for k in 0..3 {
            out.extend_from_slice(&(3 * i + k).to_le_bytes());
        }
    }
    let quad = d.join("quad.ply");
    std::fs::write(&quad, out).unwrap();
    let (s, index) = build(d, &quad, &["-r", "1024"], false);
    assert_eq!(s["bin_index_bytes"], 0, "a quad: blocks");
    assert_eq!(s["binned_during_ingest"], true);
    let (_, blocks) = build(d, &quad, &["-r", "1024"], true);
    assert!(index == blocks);
    // gzip: spooled, blocks
    let gz = d.join("sample.ply.gz");
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut e, &std::fs::read(sample()).unwrap()).unwrap();
    std::fs::write(&gz, e.finish().unwrap()).unwrap();
    let (s, _) = build(d, &gz, &["-r", "1024"], false);
    assert_eq!(s["bin_index_bytes"], 0, "gzip: blocks");
    assert_eq!(s["tile_source"], "spool");
}
