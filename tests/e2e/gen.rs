//! `voxlod gen`: generated meshes.

use super::*;

/// `gen --no-colors` writes the same geometry as `gen` (same seed), only without the vertex
/// colour properties, and builds to the same voxel positions with 40-byte instead of 52-byte
/// triangle records.
#[test]
fn gen_without_colors_has_the_same_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut tris = Vec::new();
    for (name, extra) in [("c.ply", None), ("nc.ply", Some("--no-colors"))] {
        let mut args = vec!["gen", "-q", "-n", "30000", "--seed", "3", "-o", name];
        args.extend(extra);
        ok(&voxlod(&args, d));
        let src = voxlod_ingest::MeshSource::open(&d.join(name)).unwrap();
        assert_eq!(src.info().has_colors, extra.is_none(), "{name}");
        let mut t = Vec::new();
        src.stream(
            &mut |b| {
                t.extend(b.iter().map(|t| (t.v, t.c, t.flags)));
                Ok(())
            },
            &mut |_, _| {},
        )
        .unwrap();
        tris.push(t);
    }
    let (c, nc) = (&tris[0], &tris[1]);
    assert_eq!(c.len(), nc.len());
    assert!(c.len() >= 29_000, "{} triangles", c.len());
    assert!(
        c.iter().zip(nc).all(|(a, b)| a.0 == b.0),
        "positions differ"
    );
    assert!(c.iter().all(|t| t.2 & voxlod_geom::TRI_HAS_COLORS != 0));
    assert!(nc.iter().all(|t| t.2 & voxlod_geom::TRI_HAS_COLORS == 0));
    // the coloured copies are not all one colour
    assert!(c.iter().any(|t| t.1[0] != c[0].1[0]));

    let mut positions = Vec::new();
    for (name, rec) in [("c.ply", 52), ("nc.ply", 40)] {
        let out = d.join(format!("{name}.voxlod"));
        let o = voxlod(
            &[
                "build",
                "-q",
                "--json",
                name,
                "-o",
                out.to_str().unwrap(),
                "-r",
                "512",
            ],
            d,
        );
        ok(&o);
        let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(s["record_bytes"], rec, "{name}");
        // the bins' blocks share the corners of a scan-like mesh: well under a record each
        let written = s["temp_bytes_written"].as_u64().unwrap();
        let binned = s["binned_triangles"].as_u64().unwrap();
        assert!(
            written > 0 && written * 2 < binned * rec,
            "{name}: {written} temporary bytes for {binned} binned triangles"
        );
        let (_, nodes) = read_nodes(&out);
        let p: Vec<_> = nodes
            .iter()
            .flat_map(|(k, (_, v))| v.iter().map(move |x| (*k, x.pos())))
            .collect();
        positions.push(p);
    }
    assert!(!positions[0].is_empty());
    assert_eq!(positions[0], positions[1], "voxel positions differ");
}

/// `gen` reports progress with the pipeline's progress display: on a piped stderr, a plain
/// closing line counting the records; nothing with `-q`.
#[test]
fn gen_progress_is_the_pipelines() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = voxlod(&["gen", "-n", "2000", "-o", "a.ply"], d);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.trim_start().starts_with("gen 100% ") && last.ends_with("(done)"),
        "{err}"
    );
    assert!(last.contains(" records, "), "{err}");
    let o = voxlod(&["gen", "-q", "-n", "2000", "-o", "b.ply"], d);
    ok(&o);
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
