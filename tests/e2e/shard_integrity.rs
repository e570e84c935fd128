//! The map phase of a sharded build checked by content: a bit flipped in a part's bins, an
//! edited map marker or plan, an input edited between two map tasks with its size, time and
//! both ends kept, and the files a killed map task leaves. Each is refused with an error naming
//! the file (or removed, for the leftovers), and whatever is accepted merges to the one-machine
//! build byte for byte; a seeded fuzz of parts, markers and plans holds to the same rule.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use super::{ok, voxlod, BIN};

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// The error text of a refusal: exit status 1 (not a panic's 101), no panic message.
fn refused(o: &Output) -> String {
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "not a refusal: {e}");
    assert!(!e.contains("panicked"), "{e}");
    e
}

/// A `voxlod gen` scan of `n` triangles in `dir`.
fn gen(dir: &Path, n: &str) -> PathBuf {
    let p = dir.join(format!("gen{n}.ply"));
    ok(&voxlod(&["gen", "-q", "-n", n, "-o", &s(&p)], dir));
    p
}

const SET: [&str; 4] = ["-r", "512", "--backend", "cpu"];

/// The one-machine build's bytes.
fn single(input: &Path, dir: &Path) -> Vec<u8> {
    let out = dir.join("single.voxlod");
    let mut a = vec![
        "build",
        "-q",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    a.extend(SET);
    ok(&voxlod(&a, dir));
    std::fs::read(out).unwrap()
}

/// `plan --shards shards --parts parts` into `dir/plan.json`.
fn plan(input: &Path, dir: &Path, shards: u32, parts: u32) -> (PathBuf, serde_json::Value) {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join("plan.json");
    let (sh, pa) = (shards.to_string(), parts.to_string());
    let mut a = vec![
        "plan",
        "-q",
        input.to_str().unwrap(),
        "-o",
        p.to_str().unwrap(),
    ];
    a.extend(["--shards", &sh, "--parts", &pa]);
    a.extend(SET);
    ok(&voxlod(&a, dir));
    let v = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    (p, v)
}

fn map(plan: &Path, i: u32) -> Output {
    let i = i.to_string();
    voxlod(
        &["map", "-q", &s(plan), "--part", &i, "-j", "2"],
        plan.parent().unwrap(),
    )
}

fn shard(plan: &Path, i: u32) -> Output {
    let i = i.to_string();
    voxlod(
        &["build", "-q", "--plan", &s(plan), "--shard", &i, "-j", "2"],
        plan.parent().unwrap(),
    )
}

fn merge(plan: &Path) -> Output {
    let out = plan.with_file_name("merged.voxlod");
    voxlod(
        &["merge", "-q", &s(plan), "-o", &s(&out), "-j", "2"],
        plan.parent().unwrap(),
    )
}

/// Every shard then the merge: the merged bytes, or the first refusal's text.
fn shards_and_merge(plan: &Path, shards: u32) -> Result<Vec<u8>, String> {
    for i in 0..shards {
        let o = shard(plan, i);
        if !o.status.success() {
            return Err(refused(&o));
        }
    }
    let o = merge(plan);
    if !o.status.success() {
        return Err(refused(&o));
    }
    Ok(std::fs::read(plan.with_file_name("merged.voxlod")).unwrap())
}

/// Writes `bytes` at `at` in `path` in place and puts its modification time back (as `cp -p`
/// or `rsync -t` of an edited copy would leave it).
fn edit_keeping_time(path: &Path, at: u64, bytes: &[u8]) {
    use std::os::unix::fs::FileExt;
    let t = std::fs::metadata(path).unwrap().modified().unwrap();
    let f = std::fs::File::options().write(true).open(path).unwrap();
    f.write_all_at(bytes, at).unwrap();
    f.set_times(std::fs::FileTimes::new().set_modified(t))
        .unwrap();
    drop(f);
    assert_eq!(std::fs::metadata(path).unwrap().modified().unwrap(), t);
}

/// One bit flipped inside a part's bins (same length) is refused by every shard that reads
/// that piece, naming the bins file and its checksum, and by a re-run of that map task (which
/// then makes the part again); a marker whose `triangles` was edited is refused by the shards
/// and the merge, naming the marker; restored, the merge is the one-machine build.
#[test]
fn changed_map_outputs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = gen(d, "200000");
    let want = single(&input, d);
    let (p, _) = plan(&input, &d.join("p"), 4, 4);
    for i in 0..4 {
        ok(&map(&p, i));
    }
    let pd = p.parent().unwrap();
    let bins = pd.join("part-0001.bins");
    let good = std::fs::read(&bins).unwrap();
    let marker: serde_json::Value =
        serde_json::from_slice(&std::fs::read(pd.join("part-0001.json")).unwrap()).unwrap();
    // a bit in the middle of a piece of the part's largest chunk (so that a shard reads it)
    let pieces = marker["pieces"].as_array().unwrap();
    let big = pieces
        .iter()
        .flat_map(|ps| ps.as_array().unwrap())
        .max_by_key(|p| p[1].as_u64().unwrap())
        .unwrap();
    let at = big[0].as_u64().unwrap() + big[1].as_u64().unwrap() / 2;
    let mut bad = good.clone();
    bad[at as usize] ^= 0x04;
    std::fs::write(&bins, &bad).unwrap();
    let mut refusals = 0;
    for i in 0..4 {
        let o = shard(&p, i);
        if !o.status.success() {
            let e = refused(&o);
            assert!(
                e.contains(&s(&bins)) && e.contains("CRC-32") && e.contains("changed or damaged"),
                "{e}"
            );
            assert!(!pd.join(format!("shard-{i:04}.vlshard")).exists());
            refusals += 1;
        }
    }
    assert!(refusals >= 1, "no shard read the changed piece");
    // the map task finds its bins damaged and makes them again
    let o = voxlod(&["map", &s(&p), "--part", "1", "--json"], pd);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["already_done"], false, "{j}");
    assert!(std::fs::read(&bins).unwrap() == good);
    // a marker's triangle count edited: the shards and the merge refuse it, naming it
    let mp = pd.join("part-0002.json");
    let text = std::fs::read_to_string(&mp).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let n = v["triangles"].as_u64().unwrap();
    let edited = text.replace(
        &format!("\"triangles\":{n},"),
        &format!("\"triangles\":{},", n + 1),
    );
    assert_ne!(edited, text);
    std::fs::write(&mp, &edited).unwrap();
    let e = refused(&shard(&p, 0));
    assert!(
        e.contains("part 2:") && e.contains(&s(&mp)) && e.contains("checksum does not match"),
        "{e}"
    );
    std::fs::write(&mp, &text).unwrap();
    let merged = shards_and_merge(&p, 4).unwrap();
    std::fs::write(&mp, &edited).unwrap();
    let e = refused(&merge(&p));
    assert!(e.contains(&s(&mp)), "{e}");
    std::fs::write(&mp, &text).unwrap();
    assert!(
        merged == want,
        "the merge differs from the one-machine build"
    );
}

/// An input edited between two map tasks, its size and modification time kept and the edit
/// outside its first and last MiB (what the fingerprint sees): a face record of part 2, then a
/// vertex that part 3's faces use. The map task that reads the edit refuses it, naming the
/// part, the input, the bytes and the plan, and writes no output; restored, every part maps
/// and the merge is the one-machine build.
#[test]
fn an_input_edited_between_map_tasks_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = gen(d, "300000");
    let len = std::fs::metadata(&input).unwrap().len();
    assert!(len > 4 << 20, "{len} bytes");
    let want = single(&input, d);
    let (p, v) = plan(&input, &d.join("p"), 4, 4);
    let pd = p.parent().unwrap();
    let parts = v["parts"].as_array().unwrap();
    let range = |i: usize| {
        let b = parts[i]["bytes"].as_array().unwrap();
        (b[0].as_u64().unwrap(), b[1].as_u64().unwrap())
    };
    for i in 0..2 {
        ok(&map(&p, i));
    }
    let bytes = std::fs::read(&input).unwrap();
    let canonical = s(&input.canonicalize().unwrap());
    // a face record in the middle of part 2: its first index's low byte (another vertex)
    let (a2, b2) = range(2);
    let rec = 13; // uchar 3, three int indices
    let at = a2 + (b2 - a2) / rec / 2 * rec + 1;
    assert!(at > 1 << 20 && at < len - (1 << 20));
    edit_keeping_time(&input, at, &[bytes[at as usize] ^ 1]);
    let e = refused(&map(&p, 2));
    assert!(
        e.contains("part 2:")
            && e.contains(&canonical)
            && e.contains("its face records")
            && e.contains(&s(&p))
            && e.contains("changed since"),
        "{e}"
    );
    assert!(!pd.join("part-0002.json").exists() && !pd.join("part-0002.bins").exists());
    edit_keeping_time(&input, at, &[bytes[at as usize]]);
    // a vertex of the middle face of part 3, outside the first and last MiB
    let (a3, b3) = range(3);
    let text_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..text_end]).unwrap();
    let nv: u64 = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    let stride = (a2.min(range(0).0) - text_end as u64) / nv;
    let face = a3 + (b3 - a3) / rec / 2 * rec;
    let f = face as usize;
    let index = u32::from_le_bytes(bytes[f + 1..f + 5].try_into().unwrap()) as u64;
    let vat = text_end as u64 + index * stride;
    assert!(vat > 1 << 20, "vertex {index} lies in the first MiB");
    edit_keeping_time(&input, vat, &[bytes[vat as usize] ^ 1]);
    let e = refused(&map(&p, 3));
    assert!(
        e.contains("part 3:") && e.contains("a page of the header or vertex list"),
        "{e}"
    );
    edit_keeping_time(&input, vat, &[bytes[vat as usize]]);
    for i in 2..4 {
        ok(&map(&p, i));
    }
    let merged = shards_and_merge(&p, 4).unwrap();
    assert!(
        merged == want,
        "the merge differs from the one-machine build"
    );
}

/// Files in `dir` other than the plan, the map outputs and the input (what a killed map task
/// may leave).
fn strays(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| {
            let kept = n == "plan.json"
                || (n.starts_with("part-")
                    && (n.ends_with(".json") || n.ends_with(".bins"))
                    && n.len() == "part-0000.bins".len());
            !kept
        })
        .collect();
    v.sort();
    v
}

/// Runs map task `i` and kills it (SIGKILL) once it has written something beside the plan.
fn kill_map_while_writing(plan: &Path, i: u32) {
    let pd = plan.parent().unwrap();
    let mut child = Command::new(BIN)
        .args(["map", "-q", &s(plan), "--part", &i.to_string(), "-j", "1"])
        .current_dir(pd)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    let started = |d: &Path| {
        std::fs::read_dir(d).unwrap().flatten().any(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            let m = e.metadata().map(|m| m.len()).unwrap_or(0);
            m > 0 && (n.contains(".partial") || n.starts_with(".voxlod-part-"))
        })
    };
    while !started(pd) {
        assert!(t.elapsed() < Duration::from_secs(120), "map wrote nothing");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the map task ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

/// A map task killed while it writes leaves files beside the plan; running it again removes
/// them (and commits the part), and `voxlod clean` removes those of another killed task.
#[test]
fn a_killed_map_task_leaves_nothing_after_a_rerun_or_clean() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = gen(d, "1000000");
    let (p, _) = plan(&input, &d.join("p"), 2, 3);
    let pd = p.parent().unwrap();
    kill_map_while_writing(&p, 1);
    assert!(!strays(pd).is_empty(), "the killed task left nothing");
    ok(&map(&p, 1));
    assert_eq!(strays(pd), Vec::<String>::new(), "left after the re-run");
    assert!(pd.join("part-0001.json").is_file());
    kill_map_while_writing(&p, 2);
    let left = strays(pd);
    assert!(!left.is_empty(), "the killed task left nothing");
    let o = voxlod(&["clean", &s(pd)], pd);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(text.contains("part-0002.bins"), "{text}");
    assert_eq!(strays(pd), Vec::<String>::new(), "left after clean: {text}");
}

/// Seeded mutations of a part's bins (bit flips, bytes set, truncation, growth), a map marker
/// and the plan (a number, a string or a byte of the JSON changed): each run of every shard
/// and the merge either refuses (exit status 1, naming the plan, a part's file or the input)
/// or merges to the one-machine build byte for byte; never another octree. `VOXLOD_FUZZ_ITERS`
/// sets the mutants (default 24).
#[test]
fn fuzzed_parts_markers_and_plans_are_refused_or_merge_to_the_single_build() {
    let iters: u64 = std::env::var("VOXLOD_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = gen(d, "20000");
    let want = single(&input, d);
    let pristine = d.join("pristine");
    let (p, _) = plan(&input, &pristine, 2, 3);
    for i in 0..3 {
        ok(&map(&p, i));
    }
    let files: Vec<String> = [
        "plan.json",
        "part-0000.bins",
        "part-0001.bins",
        "part-0002.bins",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain((0..3).map(|i| format!("part-{i:04}.json")))
    .collect();
    let mut seed = 0x5eed_2026_u64;
    let mut rng = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let (mut accepted, mut rejected) = (0, 0);
    for k in 0..iters {
        let run = d.join(format!("run{k}"));
        std::fs::create_dir_all(&run).unwrap();
        for f in &files {
            std::fs::copy(pristine.join(f), run.join(f)).unwrap();
        }
        let name = &files[(rng() % files.len() as u64) as usize];
        let path = run.join(name);
        let mut b = std::fs::read(&path).unwrap();
        let what = if name.ends_with(".json") && rng() % 3 != 0 {
            // a number or string of the JSON changed, the rest as written
            let mut v: serde_json::Value = serde_json::from_slice(&b).unwrap();
            let mut leaves = Vec::new();
            collect_leaves(&v, String::new(), &mut leaves);
            let ptr = leaves[(rng() % leaves.len() as u64) as usize].clone();
            let leaf = v.pointer_mut(&ptr).unwrap();
            let r = rng();
            *leaf = match leaf.clone() {
                serde_json::Value::Number(n) => match (n.as_u64(), n.as_f64()) {
                    (Some(u), _) => serde_json::json!(match r % 4 {
                        0 => u + 1,
                        1 => u.saturating_sub(1),
                        2 => u ^ (1 << ((r >> 8) % 20)),
                        _ => u * 2,
                    }),
                    (None, Some(f)) => serde_json::json!(f * (1.0 + 1e-9 * (r % 7 + 1) as f64)),
                    _ => serde_json::json!(0),
                },
                serde_json::Value::String(t) => {
                    let mut c: Vec<char> = t.chars().collect();
                    if c.is_empty() {
                        serde_json::json!("x")
                    } else {
                        let i = (r >> 8) as usize % c.len();
                        c[i] = if c[i] == '0' { '1' } else { '0' };
                        serde_json::json!(c.into_iter().collect::<String>())
                    }
                }
                serde_json::Value::Bool(x) => serde_json::json!(!x),
                other => other,
            };
            b = if name == "plan.json" {
                serde_json::to_vec_pretty(&v).unwrap()
            } else {
                serde_json::to_vec(&v).unwrap()
            };
            format!("{name}: {ptr} changed")
        } else {
            let r = rng();
            let i = (rng() % b.len() as u64) as usize;
            match r % 4 {
                0 => b[i] ^= 1 << ((r >> 8) % 8),
                1 => b[i] = (r >> 16) as u8,
                2 => b.truncate(i),
                _ => b.insert(i, (r >> 16) as u8),
            }
            format!("{name}: byte {i} mutated ({})", r % 4)
        };
        std::fs::write(&path, &b).unwrap();
        let plan = run.join("plan.json");
        match shards_and_merge(&plan, 2) {
            Ok(merged) => {
                assert!(merged == want, "{what}: accepted, and the octree differs");
                accepted += 1;
            }
            Err(e) => {
                let named = e.contains("plan.json")
                    || e.contains("part-000")
                    || e.contains(&s(&input.canonicalize().unwrap()));
                assert!(named, "{what}: the error names no file: {e}");
                rejected += 1;
            }
        }
        std::fs::remove_dir_all(&run).unwrap();
    }
    eprintln!("fuzzed sharded path: {accepted} accepted (same bytes), {rejected} refused");
    assert!(rejected > 0);
}

/// The JSON pointers of every number, string and boolean in `v`.
fn collect_leaves(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                collect_leaves(
                    x,
                    format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                    out,
                );
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                collect_leaves(x, format!("{at}/{i}"), out);
            }
        }
        serde_json::Value::Null => {}
        _ => out.push(at),
    }
}
