//! Sharded builds on cluster schedulers: the same four commands (`voxlod
//! plan --parts`, `voxlod map --part I`, `voxlod build --plan --shard I`, `voxlod merge`) driven
//! by Slurm and by Kubernetes.
//!
//! Slurm, for real: `scripts/slurm/submit.sh` plans a generated mesh, runs the map tasks as a
//! Slurm job array, the shards as an array that depends on it and the merge as a job that
//! depends on the shards, and the merged file must equal a one-machine `voxlod build` byte for
//! byte. A shard that fails must keep the merge job from running, `wait.sh` must name that
//! shard, and rerunning only it (`rerun.sh`, an `--array=K` job) must finish the same file; a
//! map task that fails must keep the shards and the merge from running, `wait.sh` must name it,
//! and `rerun.sh WORK map K` must rerun it and the shards, to the same file. The cluster is the single-node one of `.ci/slurm-up.sh`
//! (slurmctld, slurmd and munge on localhost), which `.ci/run` starts before `cargo test`; its
//! jobs run as the same user on the same file system, so they run this test's own `voxlod`
//! binary on the test's temporary files. Under CI (`CI=true`) a cluster that does not answer is
//! a failure; elsewhere the test says it was skipped and why.
//!
//! Kubernetes: no cluster here, so the manifests of `scripts/k8s/` are parsed (PyYAML, which
//! `.ci/run` installs), checked against each other, and their containers' commands run
//! locally the way the pods would (index in `JOB_COMPLETION_INDEX`), to the same bytes.
//!
//! The file sits in `crates/voxlod/tests/`, where cargo finds it without a `[[test]]` entry.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use super::BIN;

fn repo() -> PathBuf {
    voxlod_testkit::repo_root()
}

fn under_ci() -> bool {
    voxlod_testkit::under_ci()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Runs `cmd`, panicking with its output unless it exits 0.
fn run_ok(cmd: &mut Command) -> Output {
    let o = cmd
        .output()
        .unwrap_or_else(|e| panic!("running {cmd:?}: {e}"));
    assert!(
        o.status.success(),
        "{cmd:?} failed ({}):\n{}\n{}",
        o.status,
        text(&o.stdout),
        text(&o.stderr)
    );
    o
}

/// True if the Slurm cluster answers with a node that takes jobs (`sinfo`, `sbatch` on PATH).
/// Otherwise prints "SKIPPED" and why, or under CI fails.
fn slurm_ready(test: &str) -> bool {
    let why = match Command::new("sinfo")
        .args(["--noheader", "--format=%T"])
        .output()
    {
        Ok(o) if o.status.success() => {
            let states = text(&o.stdout);
            let usable = states.lines().any(|s| {
                ["idle", "mixed", "allocated", "completing"]
                    .iter()
                    .any(|u| s.starts_with(u))
            });
            let sbatch = Command::new("sbatch").arg("--version").output();
            match (usable, sbatch) {
                (true, Ok(b)) if b.status.success() => return true,
                (false, _) => format!("sinfo shows no node that takes jobs: {states:?}"),
                (true, r) => format!("sbatch does not run: {r:?}"),
            }
        }
        Ok(o) => format!("sinfo failed: {}", text(&o.stderr).trim()),
        Err(e) => format!("sinfo is not installed: {e}"),
    };
    if under_ci() {
        panic!("{test}: CI=true needs the Slurm cluster of .ci/slurm-up.sh, but {why}");
    }
    voxlod_testkit::skipped(
        test,
        &format!("no Slurm cluster here ({why}); `.ci/slurm-up.sh` starts one"),
    );
    false
}

/// `scripts/slurm/NAME` with `args`, the test's binary as `VOXLOD`.
fn slurm_script(name: &str, args: &[&str], cwd: &Path) -> Output {
    Command::new(repo().join("scripts/slurm").join(name))
        .args(args)
        .current_dir(cwd)
        .env("VOXLOD", BIN)
        .output()
        .unwrap_or_else(|e| panic!("running scripts/slurm/{name}: {e}"))
}

/// The job id after `label` ("array job: 12 (…)") in submit.sh's or rerun.sh's output.
fn job_id(stdout: &str, label: &str) -> String {
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix(label))
        .unwrap_or_else(|| panic!("no '{label}' line in: {stdout}"));
    let id = line.split_whitespace().next().unwrap_or("");
    assert!(
        !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()),
        "job id {id:?} in {line:?}"
    );
    id.to_string()
}

/// The `FIELD=value` pairs of `scontrol show job -o JOB`, one map per record (array tasks).
fn scontrol_job(job: &str) -> Vec<std::collections::BTreeMap<String, String>> {
    let o = run_ok(Command::new("scontrol").args(["show", "job", "-o", job]));
    text(&o.stdout)
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .filter_map(|kv| kv.split_once('='))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

const SHARDS: usize = 3;
/// Build options given to both the plain build and the plan (so both use the same settings).
const OPTS: [&str; 4] = ["-r", "1024", "--memory", "512MiB"];

#[test]
fn slurm_array_build_equals_single_build_and_a_failed_shard_is_rerun() {
    let test = "slurm_array_build_equals_single_build_and_a_failed_shard_is_rerun";
    if !slurm_ready(test) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = d.join("mesh.ply");
    let m = mesh.to_str().unwrap();
    run_ok(Command::new(BIN).args(["gen", "-q", "-n", "40000", "--seed", "16", "-o", m]));
    let single = d.join("single.voxlod");
    let mut build = vec!["build", "-q", m, "-o", single.to_str().unwrap()];
    build.extend(OPTS);
    run_ok(Command::new(BIN).args(&build));
    let expected = std::fs::read(&single).unwrap();

    // plan → array of 3 shard tasks → dependent merge, all as Slurm jobs.
    let n = SHARDS.to_string();
    let mut args = vec![m, "array.voxlod", &n];
    args.extend(OPTS);
    let sub = slurm_script("submit.sh", &args, d);
    assert!(sub.status.success(), "submit.sh: {}", text(&sub.stderr));
    let out = text(&sub.stdout);
    let maps = job_id(&out, "map job: ");
    let array = job_id(&out, "array job: ");
    job_id(&out, "merge job: ");
    let w = slurm_script("wait.sh", &["array.shards", "120"], d);
    assert!(
        w.status.success(),
        "wait.sh: {}{}",
        text(&w.stdout),
        text(&w.stderr)
    );
    let tasks = scontrol_job(&array);
    assert_eq!(
        tasks.len(),
        SHARDS,
        "one finished task per shard: {tasks:?}"
    );
    for t in &tasks {
        assert_eq!(t["JobState"], "COMPLETED", "{t:?}");
        // --mem follows --memory 512MiB; Slurm states it per node.
        assert_eq!(t["MinMemoryNode"], "512M", "{t:?}");
    }
    let map_tasks = scontrol_job(&maps);
    assert_eq!(
        map_tasks.len(),
        SHARDS,
        "one map task per part: {map_tasks:?}"
    );
    for t in &map_tasks {
        assert_eq!(t["JobState"], "COMPLETED", "{t:?}");
    }
    let merged = std::fs::read(d.join("array.voxlod")).unwrap();
    assert!(
        merged == expected,
        "the merged file differs from a plain build"
    );
    for k in 0..SHARDS {
        let shard = d.join(format!("array.shards/shard-{k:04}.vlshard"));
        assert!(shard.is_file(), "{} is missing", shard.display());
        let part = d.join(format!("array.shards/part-{k:04}.json"));
        assert!(part.is_file(), "{} is missing", part.display());
    }

    failed_shard_stops_the_merge_and_rerun_finishes(d, m, &expected);
    failed_map_task_stops_the_shards_and_rerun_finishes(d, m, &expected);
}

/// Map task 1 cannot rename its bins into place (a folder has the name), so it fails: the
/// shard array and the merge are cancelled without running, wait.sh names map task 1 and the
/// rerun command, and `rerun.sh WORK map 1` once the folder is gone reruns it and the shards
/// (none had written a file), to the plain build's bytes.
fn failed_map_task_stops_the_shards_and_rerun_finishes(d: &Path, mesh: &str, expected: &[u8]) {
    let blocker = d.join("mapfail.shards/part-0001.bins");
    std::fs::create_dir_all(blocker.join("in-the-way")).unwrap();
    let n = SHARDS.to_string();
    let mut args = vec![mesh, "mapfail.voxlod", &n];
    args.extend(OPTS);
    let sub = slurm_script("submit.sh", &args, d);
    assert!(sub.status.success(), "submit.sh: {}", text(&sub.stderr));
    let array = job_id(&text(&sub.stdout), "array job: ");
    let w = slurm_script("wait.sh", &["mapfail.shards", "120"], d);
    let err = text(&w.stderr);
    assert_eq!(w.status.code(), Some(1), "wait.sh should fail: {err}");
    assert!(
        err.contains("map task 1: FAILED"),
        "wait.sh names map task 1: {err}"
    );
    assert!(err.contains("rerun.sh mapfail.shards map 1"), "{err}");
    for t in scontrol_job(&array) {
        assert_ne!(
            t["JobState"], "COMPLETED",
            "a shard ran after a failed map task: {t:?}"
        );
    }
    assert!(!d.join("mapfail.voxlod").exists());
    std::fs::remove_dir_all(&blocker).unwrap();
    let re = slurm_script("rerun.sh", &["mapfail.shards", "map", "1"], d);
    assert!(re.status.success(), "rerun.sh: {}", text(&re.stderr));
    let out = text(&re.stdout);
    let maps = scontrol_job(&job_id(&out, "map job: "));
    assert_eq!(maps.len(), 1, "one map task: {maps:?}");
    assert_eq!(maps[0]["ArrayTaskId"], "1", "{maps:?}");
    job_id(&out, "array job: ");
    let w = slurm_script("wait.sh", &["mapfail.shards", "120"], d);
    assert!(
        w.status.success(),
        "wait.sh after the rerun: {}",
        text(&w.stderr)
    );
    let merged = std::fs::read(d.join("mapfail.voxlod")).unwrap();
    assert!(
        merged == expected,
        "the map rerun's merged file differs from a plain build"
    );
}

/// Shard 1 cannot write its file (a folder has its name), so its task fails: the merge job
/// is cancelled without running, wait.sh names shard 1, and rerunning shard 1 alone once the
/// folder is gone gives the plain build's bytes.
fn failed_shard_stops_the_merge_and_rerun_finishes(d: &Path, mesh: &str, expected: &[u8]) {
    let blocker = d.join("fail.shards/shard-0001.vlshard");
    std::fs::create_dir_all(blocker.join("in-the-way")).unwrap();
    let n = SHARDS.to_string();
    let mut args = vec![mesh, "fail.voxlod", &n];
    args.extend(OPTS);
    let sub = slurm_script("submit.sh", &args, d);
    assert!(sub.status.success(), "submit.sh: {}", text(&sub.stderr));
    let merge = job_id(&text(&sub.stdout), "merge job: ");
    let w = slurm_script("wait.sh", &["fail.shards", "120"], d);
    let err = text(&w.stderr);
    assert_eq!(w.status.code(), Some(1), "wait.sh should fail: {err}");
    assert!(
        err.contains("shard 1: FAILED"),
        "wait.sh names shard 1: {err}"
    );
    assert!(
        !err.contains("shard 0:") && !err.contains("shard 2:"),
        "only shard 1 failed: {err}"
    );
    assert!(err.contains("rerun.sh fail.shards 1"), "{err}");
    // The tail of the shard's log, which wait.sh shows: voxlod's error naming the file.
    assert!(
        err.contains("shard-0001.vlshard is a directory"),
        "wait.sh shows the shard's error: {err}"
    );
    let m = &scontrol_job(&merge)[0];
    assert_eq!(
        m["JobState"], "CANCELLED",
        "the merge job must not run: {m:?}"
    );
    assert!(
        !d.join("fail.voxlod").exists(),
        "no output after a failed shard"
    );
    assert!(
        !std::fs::read_to_string(d.join("fail.shards/logs/merge.out"))
            .unwrap_or_default()
            .contains("voxlod-merge: job"),
        "the merge job ran"
    );

    std::fs::remove_dir_all(&blocker).unwrap();
    let re = slurm_script("rerun.sh", &["fail.shards", "1"], d);
    assert!(re.status.success(), "rerun.sh: {}", text(&re.stderr));
    let array = job_id(&text(&re.stdout), "array job: ");
    let tasks = scontrol_job(&array);
    assert_eq!(tasks.len(), 1, "one task: {tasks:?}");
    assert_eq!(tasks[0]["ArrayTaskId"], "1", "{tasks:?}");
    let w = slurm_script("wait.sh", &["fail.shards", "120"], d);
    assert!(
        w.status.success(),
        "wait.sh after the rerun: {}",
        text(&w.stderr)
    );
    let merged = std::fs::read(d.join("fail.voxlod")).unwrap();
    assert!(
        merged == expected,
        "the rerun's merged file differs from a plain build"
    );
}

/// The manifest `scripts/k8s/NAME` as JSON (PyYAML's safe_load, converted by python3).
fn manifest(name: &str) -> serde_json::Value {
    let path = repo().join("scripts/k8s").join(name);
    let o = run_ok(Command::new("python3").args([
        "-c",
        "import json, sys, yaml; print(json.dumps(yaml.safe_load(open(sys.argv[1]))))",
        path.to_str().unwrap(),
    ]));
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// True if python3 with PyYAML runs; else a skip and why (`voxlod_testkit::skipped`), or under
/// CI a failure.
fn yaml_ready(test: &str) -> bool {
    let o = Command::new("python3").args(["-c", "import yaml"]).output();
    let why = match o {
        Ok(o) if o.status.success() => return true,
        Ok(o) => text(&o.stderr),
        Err(e) => e.to_string(),
    };
    if under_ci() {
        panic!("{test}: CI=true but python3 with PyYAML is not available: {why}");
    }
    voxlod_testkit::skipped(
        test,
        &format!("python3 with PyYAML is not available (pip install pyyaml): {why}"),
    );
    false
}

/// The one container of a Job manifest, after checking what every manifest shares: a batch/v1
/// Job that does not restart pods in place, the `voxlod-data` claim mounted at /data.
fn job_container(name: &str, m: &serde_json::Value) -> serde_json::Value {
    assert_eq!(m["apiVersion"], "batch/v1", "{name}");
    assert_eq!(m["kind"], "Job", "{name}");
    let pod = &m["spec"]["template"]["spec"];
    assert_eq!(pod["restartPolicy"], "Never", "{name}");
    assert_eq!(
        pod["volumes"][0]["persistentVolumeClaim"]["claimName"], "voxlod-data",
        "{name}"
    );
    let c = &pod["containers"][0];
    assert_eq!(c["volumeMounts"][0]["mountPath"], "/data", "{name}");
    assert_eq!(
        c["volumeMounts"][0]["name"], pod["volumes"][0]["name"],
        "{name}"
    );
    assert_eq!(c["image"], "debian:12-slim", "{name}");
    c.clone()
}

/// A container's command with /data moved to `data` and the example's scale (16 shards,
/// 16384³, 8 GiB) brought down to a test's (3 shards, 1024³, 512 MiB).
fn local_command(c: &serde_json::Value, data: &Path) -> Command {
    let args: Vec<String> = c["command"]
        .as_array()
        .expect("command")
        .iter()
        .map(|a| {
            a.as_str()
                .expect("command strings")
                .replace("/data", data.to_str().unwrap())
                .replace("--shards 16", "--shards 3")
                .replace("--parts 16", "--parts 3")
                .replace("-r 16384", "-r 1024")
                .replace("8GiB", "512MiB")
        })
        .collect();
    let mut cmd = Command::new(&args[0]);
    cmd.args(&args[1..]);
    cmd
}

/// The Kubernetes manifests parse, agree with each other (shard count, memory, paths), and
/// their commands, run here with /data a temporary folder and the index in
/// JOB_COMPLETION_INDEX, give the plain build's bytes; the rerun manifest rebuilds a lost
/// shard to the same bytes.
#[test]
fn k8s_indexed_job_runs_the_three_commands() {
    let test = "k8s_indexed_job_runs_the_three_commands";
    if !yaml_ready(test) {
        return;
    }
    let plan = manifest("voxlod-plan.yaml");
    let maps = manifest("voxlod-map.yaml");
    let map_c = job_container("voxlod-map.yaml", &maps);
    let shards = manifest("voxlod-shards.yaml");
    let rerun = manifest("voxlod-shard-rerun.yaml");
    let merge = manifest("voxlod-merge.yaml");
    let plan_c = job_container("voxlod-plan.yaml", &plan);
    let shard_c = job_container("voxlod-shards.yaml", &shards);
    let rerun_c = job_container("voxlod-shard-rerun.yaml", &rerun);
    let merge_c = job_container("voxlod-merge.yaml", &merge);
    let plan_cmd = plan_c["command"].to_string();
    assert_eq!(shards["spec"]["completionMode"], "Indexed");
    let n = shards["spec"]["completions"].as_u64().expect("completions");
    assert_eq!(shards["spec"]["parallelism"], n);
    assert!(plan_cmd.contains(&format!("--shards {n} ")), "{plan_cmd}");
    assert_eq!(maps["spec"]["completionMode"], "Indexed");
    let p = maps["spec"]["completions"].as_u64().expect("completions");
    assert!(plan_cmd.contains(&format!("--parts {p} ")), "{plan_cmd}");
    let map_cmd = map_c["command"].to_string();
    assert!(
        map_cmd.contains(r#"--part \"$JOB_COMPLETION_INDEX\""#),
        "{map_cmd}"
    );
    assert!(
        map_cmd.contains("map /data/scan.shards/plan.json"),
        "{map_cmd}"
    );
    assert!(
        plan_cmd.contains("-o /data/scan.shards/plan.json"),
        "{plan_cmd}"
    );
    for c in [&shard_c, &rerun_c] {
        // voxlod's threads and budget are the pod's CPU request and memory limit.
        let cmd = c["command"].to_string();
        assert!(cmd.contains("-j 4 --memory 8GiB"), "{cmd}");
        assert_eq!(c["resources"]["requests"]["cpu"], "4", "{cmd}");
        assert_eq!(c["resources"]["limits"]["memory"], "8Gi", "{cmd}");
        assert!(cmd.contains("--plan /data/scan.shards/plan.json"), "{cmd}");
    }
    assert!(shard_c["command"]
        .to_string()
        .contains(r#"--shard \"$JOB_COMPLETION_INDEX\""#));
    assert_eq!(rerun_c["env"][0]["name"], "SHARD");
    assert_eq!(
        rerun_c["env"][0]["value"], "SHARD",
        "the value the comment's sed replaces"
    );

    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir_all(data.join("bin")).unwrap();
    std::os::unix::fs::symlink(BIN, data.join("bin/voxlod")).unwrap();
    let scan = data.join("scan.ply");
    let s = scan.to_str().unwrap();
    run_ok(Command::new(BIN).args(["gen", "-q", "-n", "20000", "--seed", "8", "-o", s]));
    let single = dir.path().join("single.voxlod");
    let mut build = vec!["build", "-q", s, "-o", single.to_str().unwrap()];
    build.extend(OPTS);
    run_ok(Command::new(BIN).args(&build));

    run_ok(&mut local_command(&plan_c, &data));
    for i in 0..SHARDS {
        run_ok(local_command(&map_c, &data).env("JOB_COMPLETION_INDEX", i.to_string()));
    }
    for i in 0..SHARDS {
        run_ok(local_command(&shard_c, &data).env("JOB_COMPLETION_INDEX", i.to_string()));
    }
    run_ok(&mut local_command(&merge_c, &data));
    let merged = std::fs::read(data.join("scan.voxlod")).unwrap();
    assert!(
        merged == std::fs::read(&single).unwrap(),
        "merged ≠ plain build"
    );

    let shard1 = data.join("scan.shards/shard-0001.vlshard");
    let before = std::fs::read(&shard1).unwrap();
    std::fs::remove_file(&shard1).unwrap();
    run_ok(local_command(&rerun_c, &data).env("SHARD", "1"));
    assert!(
        std::fs::read(&shard1).unwrap() == before,
        "rerun shard 1 differs"
    );
}
