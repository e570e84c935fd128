//! One validation rule set for every reader (docs/FORMAT.md 11.2):
//! the same corrupted files go to the Rust `Reader` (open and read every node), `voxlod
//! verify`, `voxlod inspect` (which only opens: manifest cases) and the Python reader
//! (`scripts/voxlod_read.py --check`); all must reject each one, and all must accept the good
//! file. Every corrupted file has all its checksums right, so only the rules catch it. The
//! files are assembled here byte by byte from FORMAT.md (one 256³ chunk, one node), not by the
//! Rust writer.
//!
//! The Python reader must also stay bounded: no RecursionError on a 100,000-deep manifest,
//! and no allocation from a zstd header claiming 1 GiB or 16 TiB (it runs under a 1 GiB
//! address-space limit), and its errors name the file. Needs python3 with numpy and
//! zstandard: under CI=true a missing one is a failure, elsewhere those parts say they skipped.

use std::path::Path;
use std::process::Command;

use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};
use voxlod_format::Reader;

use super::{BIN, REPO};

/// The 12·n-byte block of `voxels` (Morton-sorted) as FORMAT.md 5.2 transforms it.
fn block_of(voxels: &[Voxel]) -> Vec<u8> {
    let n = voxels.len();
    let mut words = [vec![], vec![], vec![]];
    let mut prev = 0;
    for v in voxels {
        let m = v.morton();
        words[0].push((m - prev) | (v.pos_mask & 0x3f00_0000));
        prev = m;
        words[1].push(v.normal);
        words[2].push(v.color);
    }
    let mut block = vec![0u8; 12 * n];
    for (a, w) in words.iter().enumerate() {
        for b in 0..4 {
            let plane = &mut block[4 * n * a + n * b..][..n];
            for (j, word) in w.iter().enumerate() {
                plane[j] = (word >> (8 * b)) as u8;
            }
            if a > 0 {
                for j in (1..n).rev() {
                    plane[j] = plane[j].wrapping_sub(plane[j - 1]);
                }
            }
        }
    }
    block
}

fn voxels() -> Vec<Voxel> {
    let mut v: Vec<Voxel> = [[3u8, 200, 17], [4, 200, 17], [10, 11, 12]]
        .iter()
        .map(|&p| {
            let n = pack_normal([0.6, -0.8, 0.0]);
            Voxel::new(
                p,
                face_mask(n) | border_caps(p),
                n,
                pack_color([200, 150, 100, 255]),
            )
        })
        .collect();
    v.sort_by_key(|v| v.morton());
    v
}

/// A whole one-node file (resolution 256, one level) per FORMAT.md sections 2–4, with every
/// checksum computed for the given payload and manifest.
fn file(payload: &[u8], block: &[u8], n: u32, manifest: &[u8]) -> Vec<u8> {
    let v = voxels();
    let lo: [u8; 3] = std::array::from_fn(|a| v.iter().map(|v| v.pos()[a]).min().unwrap());
    let hi: [u8; 3] = std::array::from_fn(|a| v.iter().map(|v| v.pos()[a]).max().unwrap());
    let pad = (8 - (128 + payload.len()) % 8) % 8;
    let index_offset = (128 + payload.len() + pad) as u64;
    let mut entry = Vec::new();
    for w in [0u32, 0, 0, 0, n, 0] {
        entry.extend(w.to_le_bytes());
    }
    entry.extend(128u64.to_le_bytes());
    entry.extend((payload.len() as u64).to_le_bytes());
    entry.extend(crc32fast::hash(payload).to_le_bytes());
    entry.extend(crc32fast::hash(block).to_le_bytes());
    entry.extend([lo[0], lo[1], lo[2], 0, hi[0], hi[1], hi[2], 0]);
    entry.extend([0u8; 8]);
    assert_eq!(entry.len(), 64);
    let mut h = Vec::new();
    h.extend(b"VOXLOD\0\x01");
    for w in [1u32, 128, 256, 1, 0, 0] {
        h.extend(w.to_le_bytes());
    }
    for f in [0.0f64, 0.0, 0.0, 1.0] {
        h.extend(f.to_le_bytes());
    }
    let manifest_offset = index_offset + 64;
    for q in [
        1u64,
        index_offset,
        64,
        manifest_offset,
        manifest.len() as u64,
        n as u64,
    ] {
        h.extend(q.to_le_bytes());
    }
    h.extend(crc32fast::hash(&entry).to_le_bytes());
    h.extend(crc32fast::hash(manifest).to_le_bytes());
    h.extend(0u32.to_le_bytes());
    h.extend(crc32fast::hash(&h).to_le_bytes());
    assert_eq!(h.len(), 128);
    [h, payload.to_vec(), vec![0; pad], entry, manifest.to_vec()].concat()
}

/// A zstd frame (RFC 8878) of one raw block holding `data`, whose header claims
/// `content_size` bytes (8-byte field, single segment).
fn raw_frame(data: &[u8], content_size: u64) -> Vec<u8> {
    let mut f = 0xFD2F_B528u32.to_le_bytes().to_vec();
    f.push(0b1110_0000); // FCS field 8 bytes, single segment, no checksum, no dictionary
    f.extend(content_size.to_le_bytes());
    let header = (data.len() as u32) << 3 | 1; // last block, raw
    f.extend(&header.to_le_bytes()[..3]);
    f.extend(data);
    f
}

/// The corrupted files, each with its name.
fn cases() -> Vec<(&'static str, Vec<u8>)> {
    let v = voxels();
    let n = v.len() as u32;
    let block = block_of(&v);
    let frame = zstd::bulk::compress(&block, 3).unwrap();
    let good_manifest = br#"{"tool":"validation test"}"#;
    let with_payload = |p: Vec<u8>| file(&p, &block, n, good_manifest);
    let with_manifest = |m: &[u8]| file(&frame, &block, n, m);
    let half = block.len() / 2;
    let no_size = {
        let mut e = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
        e.include_contentsize(false).unwrap();
        std::io::Write::write_all(&mut e, &block).unwrap();
        e.finish().unwrap()
    };
    let deep = |d: usize| ["[".repeat(d), "]".repeat(d)].concat().into_bytes();
    vec![
        ("manifest-empty", with_manifest(b"")),
        ("manifest-not-json", with_manifest(b"{\"tool\": ")),
        (
            "manifest-not-utf8",
            with_manifest(b"{\"tool\":\"\xff\xfe\"}"),
        ),
        ("manifest-deep-100000", with_manifest(&deep(100_000))),
        ("manifest-deep-65", with_manifest(&deep(65))),
        ("manifest-not-object", with_manifest(b"[1, 2]")),
        ("manifest-two-values", with_manifest(b"{} {}")),
        (
            "payload-two-frames",
            with_payload(
                [
                    zstd::bulk::compress(&block[..half], 3).unwrap(),
                    zstd::bulk::compress(&block[half..], 3).unwrap(),
                ]
                .concat(),
            ),
        ),
        (
            "payload-skippable-then-frame",
            with_payload([&[0x50, 0x2A, 0x4D, 0x18, 2, 0, 0, 0, 7, 7][..], &frame].concat()),
        ),
        (
            "payload-trailing-byte",
            with_payload([&frame[..], &[0]].concat()),
        ),
        ("payload-no-content-size", with_payload(no_size)),
        (
            "payload-claims-1GiB",
            with_payload(raw_frame(&block, 1 << 30)),
        ),
        (
            "payload-claims-16TiB",
            with_payload(raw_frame(&block, 1 << 44)),
        ),
        (
            "payload-not-zstd",
            with_payload(b"not a zstd frame at all".to_vec()),
        ),
    ]
}

#[test]
fn all_readers_apply_the_same_rules() {
    let dir = tempfile::tempdir().unwrap();
    let v = voxels();
    let block = block_of(&v);
    let good = dir.path().join("good.voxlod");
    std::fs::write(
        &good,
        file(
            &raw_frame(&block, block.len() as u64),
            &block,
            v.len() as u32,
            br#"{"tool":"validation test"}"#,
        ),
    )
    .unwrap();
    let python = voxlod_testkit::python_ready("validation: Python reader");
    let script = Path::new(REPO).join("scripts/voxlod_read.py");
    // each reader's verdict: Ok or the error text
    let rust = |p: &Path| -> Result<(), String> {
        let r = Reader::open(p).map_err(|e| e.to_string())?;
        for i in 0..r.nodes().len() {
            r.read_node(i).map_err(|e| e.to_string())?;
        }
        Ok(())
    };
    let tool = |cmd: &str, p: &Path| -> Result<(), String> {
        let o = Command::new(BIN).arg(cmd).arg(p).output().unwrap();
        if o.status.success() {
            Ok(())
        } else {
            Err(String::from_utf8_lossy(&o.stderr).into_owned()
                + &String::from_utf8_lossy(&o.stdout))
        }
    };
    let py = |p: &Path| -> Result<(), String> {
        // under a 1 GiB address-space limit: the 1 GiB and 16 TiB claims must not allocate
        let o = Command::new("sh")
            .arg("-c")
            .arg("ulimit -v 1048576; exec python3 \"$0\" \"$1\" --check")
            .arg(&script)
            .arg(p)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        match o.status.code() {
            Some(0) => Ok(()),
            Some(2) => Err(err),
            _ => panic!(
                "{}: the Python reader crashed instead of rejecting: {err}",
                p.display()
            ),
        }
    };

    assert_eq!(rust(&good), Ok(()));
    assert_eq!(tool("verify", &good), Ok(()));
    assert_eq!(tool("inspect", &good), Ok(()));
    if python {
        assert_eq!(py(&good), Ok(()));
    }
    for (name, bytes) in cases() {
        let path = dir.path().join(format!("{name}.voxlod"));
        std::fs::write(&path, bytes).unwrap();
        let file_name = path.file_name().unwrap().to_str().unwrap();
        let mut verdicts = vec![("Reader", rust(&path)), ("verify", tool("verify", &path))];
        if name.starts_with("manifest") {
            verdicts.push(("inspect", tool("inspect", &path)));
        }
        if python {
            verdicts.push(("Python", py(&path)));
        }
        for (who, verdict) in verdicts {
            let e = verdict.expect_err(&format!("{who} accepted {name}"));
            assert!(
                e.contains(file_name),
                "{who} on {name}: error does not name the file: {e}"
            );
            assert!(!e.contains("Traceback"), "{who} on {name}: {e}");
            eprintln!("{name:30} {who:8} {}", e.lines().last().unwrap_or(""));
        }
    }
}
