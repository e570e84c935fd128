//! Fault tests: what voxlod promises when outputs collide, inputs are damaged, files
//! change under a reader, or the output's disk is full or read-only. Each test made its
//! defect happen before the fix; inputs are made here, not stored. docs/RELIABILITY.md lists
//! the promises and names these tests.
//!
//! The full-disk and read-only cases mount small tmpfs file systems, which needs root; without
//! it they say they were skipped (the read-only folder then uses permissions instead).

use std::io::Write;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use voxlod_format::Reader;

use super::{ok, sample, voxlod, BIN};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Fails with a message containing every one of `parts`, no panic, no Rust debug formatting.
fn fails_with(o: &Output, parts: &[&str]) -> String {
    let e = stderr(o);
    assert!(!o.status.success(), "should have failed; stderr: {e}");
    assert_eq!(o.status.code(), Some(1), "exit status {:?}: {e}", o.status);
    assert!(!e.contains("panicked"), "panic: {e}");
    for p in parts {
        assert!(e.contains(p), "the message should contain {p:?}: {e}");
    }
    e
}

/// Folders in `dir` whose name starts with `.voxlod-work`.
fn work_folders(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(".voxlod-work")
        })
        .collect()
}

/// Every node of `path` decodes (the checks `verify` also makes) and `voxlod verify` passes.
fn assert_valid(path: &Path) {
    let r = Reader::open(path).expect("open");
    for i in 0..r.nodes().len() {
        r.read_node(i).expect("read node");
    }
    ok(&voxlod(&["verify", s(path)], path.parent().unwrap()));
}

/// A small mesh of its own (two triangles), different from the sample.
fn small_ply(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n",
    )
    .unwrap();
    p
}

/// A tmpfs of `size` mounted at `dir` (removed on drop), or None without the privilege.
struct Mount(PathBuf);

impl Mount {
    fn new(dir: &Path, opts: &str) -> Option<Mount> {
        std::fs::create_dir_all(dir).unwrap();
        let o = Command::new("mount")
            .args(["-t", "tmpfs", "-o", opts, "tmpfs", s(dir)])
            .stderr(Stdio::null())
            .status()
            .ok()?;
        o.success().then(|| Mount(dir.to_path_buf()))
    }
}

impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Item 1: Two builds with the same `-o` at once: the second is refused at once, naming the first
/// one's pid, whether its input differs or its arguments are identical; two builds that would
/// share a work folder (same input and settings, outputs of the same name in different
/// folders, one `--tmp`) likewise. The first build's file is complete and valid.
#[test]
fn same_output_at_once_is_refused_naming_the_other_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tmp = d.join("tmp");
    let other = d.join("other");
    std::fs::create_dir_all(&tmp).unwrap();
    std::fs::create_dir_all(&other).unwrap();
    let out = d.join("out.voxlod");
    let bunny = sample();
    let args = |input: &Path, o: &Path| -> Vec<String> {
        [
            "build",
            "-q",
            s(input),
            "-o",
            s(o),
            "-r",
            "1024",
            "-j",
            "1",
            "--tmp",
            s(&tmp),
        ]
        .iter()
        .map(|x| x.to_string())
        .collect()
    };
    let mut first = Command::new(BIN)
        .args(args(&bunny, &out))
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = first.id();
    // the first build holds the output's lock once its lock file has its pid
    let lock = d.join(".voxlod-lock-out.voxlod");
    let t = Instant::now();
    while std::fs::read_to_string(&lock).map_or(true, |p| p.trim() != pid.to_string()) {
        assert!(t.elapsed() < Duration::from_secs(20), "no lock file");
        assert!(first.try_wait().unwrap().is_none(), "the first build ended");
        std::thread::sleep(Duration::from_millis(5));
    }
    let small = small_ply(d, "small.ply");
    let other_input = voxlod(
        &args(&small, &out)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        d,
    );
    let same_args = voxlod(
        &args(&bunny, &out)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        d,
    );
    let shared_work = voxlod(
        &args(&bunny, &other.join("out.voxlod"))
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        d,
    );
    let still_running = first.try_wait().unwrap().is_none();
    let r = first.wait_with_output().unwrap();
    assert!(r.status.success(), "first build: {}", stderr(&r));
    assert!(
        still_running,
        "the first build ended before the others were checked: make it slower"
    );
    let pid_text = format!("pid {pid}");
    fails_with(
        &other_input,
        &["out.voxlod", "another voxlod process", &pid_text],
    );
    fails_with(
        &same_args,
        &["out.voxlod", "another voxlod process", &pid_text],
    );
    fails_with(&shared_work, &["work folder", "in use", &pid_text]);
    assert!(!other.join("out.voxlod").exists());
    assert_valid(&out);
    // nothing of either left beside the output: no lock, no temporary file
    let names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(names.is_empty(), "left behind: {names:?}");
    assert!(work_folders(&tmp).is_empty());
}

/// Item 2: An output that is an input (the same file by device and inode, so also a hard link) is
/// refused by `build`, `export`, `render` and `gen`, and the input is unchanged; an existing
/// file of another kind is replaced only with `--force`.
#[test]
fn output_that_is_an_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    std::fs::copy(sample(), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    let link = d.join("link.ply");
    std::fs::hard_link(&input, &link).unwrap();
    for o in [&input, &link] {
        let r = voxlod(&["build", "-q", s(&input), "-o", s(o), "--force"], d);
        fails_with(&r, &["is the input", "in.ply"]);
    }
    assert_eq!(std::fs::read(&input).unwrap(), before, "the input changed");

    let f = d.join("f.voxlod");
    ok(&voxlod(
        &["build", "-q", s(&input), "-o", s(&f), "-r", "256"],
        d,
    ));
    let octree = std::fs::read(&f).unwrap();
    let r = voxlod(&["export", s(&f), "-o", s(&f)], d);
    fails_with(&r, &["f.voxlod is the input"]);
    let r = voxlod(&["render", s(&f), "-o", s(&f), "--force"], d);
    fails_with(&r, &["f.voxlod is the input"]);
    assert_eq!(std::fs::read(&f).unwrap(), octree, "the octree changed");
    let r = voxlod(
        &["gen", "--base", s(&input), "-o", s(&input), "-n", "10"],
        d,
    );
    fails_with(&r, &["is the input"]);
    assert_eq!(
        std::fs::read(&input).unwrap(),
        before,
        "the base mesh changed"
    );

    // files of another kind: refused without --force, whatever the command
    let notes = d.join("notes.txt");
    std::fs::write(&notes, "my notes\n").unwrap();
    let r = voxlod(&["build", "-q", s(&input), "-o", s(&notes), "-r", "256"], d);
    fails_with(&r, &["notes.txt exists and is a text file", "--force"]);
    assert_eq!(std::fs::read(&notes).unwrap(), b"my notes\n");
    let r = voxlod(&["export", s(&f), "-o", s(&input)], d);
    // a PLY is what export writes: replacing the mesh copy is allowed, it is not the input
    ok(&r);
    std::fs::write(&input, &before).unwrap();
    let r = voxlod(&["export", s(&f), "-o", s(&notes)], d);
    fails_with(&r, &["notes.txt exists and is a text file, not a PLY mesh"]);
    let g = d.join("g.voxlod");
    std::fs::copy(&f, &g).unwrap();
    let r = voxlod(&["render", s(&f), "-o", s(&g)], d);
    fails_with(
        &r,
        &["g.voxlod exists and is a voxlod octree, not a PNG image"],
    );
    let r = voxlod(&["build", "-q", s(&input), "-o", s(&input), "--force"], d);
    fails_with(&r, &["is the input"]);
    // --force replaces a file of another kind
    ok(&voxlod(
        &[
            "build",
            "-q",
            s(&input),
            "-o",
            s(&notes),
            "-r",
            "256",
            "--force",
        ],
        d,
    ));
    assert_eq!(std::fs::read(&notes).unwrap(), octree);
    // an octree is replaced without --force (a rebuild)
    ok(&voxlod(
        &["build", "-q", s(&input), "-o", s(&g), "-r", "256"],
        d,
    ));
    assert_eq!(std::fs::read(&g).unwrap(), octree);
}

/// Item 3: A file truncated or overwritten while a reader has it open: reads fail with errors
/// naming the node, the process does not die (before: SIGBUS through the memory map).
#[test]
fn file_changed_while_read_gives_errors_not_a_crash() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let f = d.join("f.voxlod");
    ok(&voxlod(
        &["build", "-q", s(&sample()), "-o", s(&f), "-r", "1024"],
        d,
    ));
    let pristine = std::fs::read(&f).unwrap();

    // truncated to half under an open reader
    let r = Reader::open(&f).unwrap();
    let n = r.nodes().len();
    assert!(n > 3);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&f)
        .unwrap()
        .set_len(pristine.len() as u64 / 2)
        .unwrap();
    let mut errors = 0;
    for i in 0..n {
        if let Err(e) = r.read_node(i) {
            let m = e.to_string();
            assert!(m.contains("f.voxlod") && m.contains("node"), "{m}");
            errors += 1;
        }
    }
    assert!(errors > 0, "no read failed after the truncation");
    let last = r.read_node(n - 1).unwrap_err().to_string();
    assert!(last.contains("truncated after it was opened"), "{last}");
    drop(r);

    // rewritten in place (zeros over the payloads) under an open reader
    std::fs::write(&f, &pristine).unwrap();
    let r = Reader::open(&f).unwrap();
    let mut w = std::fs::OpenOptions::new().write(true).open(&f).unwrap();
    use std::io::Seek;
    w.seek(std::io::SeekFrom::Start(128)).unwrap();
    w.write_all(&vec![0u8; pristine.len() / 2 - 128]).unwrap();
    drop(w);
    let e = r.read_node(0).unwrap_err().to_string();
    assert!(e.contains("checksum mismatch"), "{e}");

    // the tools on a truncated file: an error, not a signal
    std::fs::write(&f, &pristine[..pristine.len() / 2]).unwrap();
    for cmd in ["verify", "export", "inspect"] {
        let out = d.join("x.ply");
        let o = if cmd == "export" {
            voxlod(&[cmd, s(&f), "-o", s(&out)], d)
        } else {
            voxlod(&[cmd, s(&f)], d)
        };
        assert!(o.status.code().is_some(), "{cmd}: killed by a signal");
        assert!(!o.status.success(), "{cmd} accepted a truncated file");
    }
}

/// Item 4: `-j 10000` is capped at the number of cores with a warning (before: 10,000 threads).
#[test]
fn thread_count_is_capped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("j.voxlod");
    let o = voxlod(
        &[
            "build",
            "-q",
            "--json",
            s(&sample()),
            "-o",
            s(&out),
            "-r",
            "256",
            "-j",
            "10000",
        ],
        d,
    );
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let cores = std::thread::available_parallelism().unwrap().get() as u64;
    assert_eq!(summary["threads"].as_u64(), Some(cores));
    let warnings = summary["warnings"].to_string();
    assert!(warnings.contains("-j 10000: capped at"), "{warnings}");
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// Item 5: A `.ply.gz` with a bad CRC or without its trailer is an error naming the file (before:
/// exit 0 and other voxels), ASCII and binary alike; the intact file builds.
#[test]
fn damaged_gzip_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ascii = std::fs::read(small_ply(d, "small.ply")).unwrap();
    let binary = std::fs::read(sample()).unwrap();
    for (kind, plain) in [("ascii", ascii), ("binary", binary)] {
        let good = gzip(&plain);
        let n = good.len();
        let mut bad_crc = good.clone();
        bad_crc[n - 8] ^= 0x5a;
        let mut bad_len = good.clone();
        bad_len[n - 2] ^= 0x01;
        let cases = [
            ("good", good.clone(), None),
            ("crc", bad_crc, Some("checksum")),
            ("len", bad_len, Some("checksum")),
            ("notrailer", good[..n - 8].to_vec(), Some("truncated")),
        ];
        for (name, bytes, expect) in cases {
            let input = d.join(format!("{kind}-{name}.ply.gz"));
            std::fs::write(&input, &bytes).unwrap();
            let out = d.join("out.voxlod");
            let o = voxlod(&["build", "-q", s(&input), "-o", s(&out), "-r", "256"], d);
            match expect {
                None => {
                    ok(&o);
                }
                Some(what) => {
                    let file = format!("{kind}-{name}.ply.gz");
                    fails_with(&o, &[&file, what]);
                    assert!(!out.exists());
                }
            }
            let _ = std::fs::remove_file(&out);
        }
    }
}

/// Item 8: OBJ polylines (`l 1 2 3`) are ignored, as docs/INGEST.md says (before: voxelized as a
/// triangle).
#[test]
fn obj_polylines_are_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let with = d.join("with.obj");
    std::fs::write(
        &with,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 1 2 3\nl 4 5 6\n  l 4 5\nl 6 4 5 6\n",
    )
    .unwrap();
    let src = voxlod_ingest::MeshSource::open(&with).unwrap();
    let mut tris = Vec::new();
    src.stream(
        &mut |b| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(tris.len(), 1, "the polylines became triangles");
    assert_eq!(
        tris[0].v,
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    );
    let o = voxlod(&["build", "-q", "--json", s(&with), "-r", "256"], d);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["triangles"], 1);
}

/// Item 9a: An output path that is a directory fails at once, before any work, without a work
/// folder and without the OS error twice.
#[test]
fn output_that_is_a_directory_fails_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("outdir");
    std::fs::create_dir(&out).unwrap();
    let t = Instant::now();
    let o = voxlod(&["build", "-q", s(&sample()), "-o", s(&out)], d);
    let e = fails_with(&o, &["outdir is a directory"]);
    assert_eq!(e.matches("outdir").count(), 2, "{e}"); // the path, and the example name
    assert!(t.elapsed() < Duration::from_secs(5));
    assert!(work_folders(d).is_empty() && work_folders(&out).is_empty());
    let o = voxlod(
        &[
            "build",
            "-q",
            s(&sample()),
            "-o",
            &format!("{}/", s(&d.join("x"))),
        ],
        d,
    );
    fails_with(&o, &["is a directory"]);
}

/// Item 9b: An output folder that cannot be written (with a writable `--tmp`) fails up front, not
/// after the build, and leaves no work folder.
#[test]
fn unwritable_output_folder_fails_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ro = d.join("ro");
    let tmp = d.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    // root ignores permissions: a read-only tmpfs then; otherwise a folder without write bits
    let _mount = Mount::new(&ro, "ro,size=1m");
    if _mount.is_none() {
        std::fs::create_dir_all(&ro).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        if std::fs::write(ro.join("probe"), b"").is_ok() {
            voxlod_testkit::skipped(
                "unwritable_output_folder_fails_up_front",
                "cannot make a read-only folder",
            );
            return;
        }
    }
    let out = ro.join("x.voxlod");
    let o = voxlod(
        &["build", "-q", s(&sample()), "-o", s(&out), "--tmp", s(&tmp)],
        d,
    );
    let e = fails_with(&o, &["x.voxlod", "is not writable"]);
    assert!(!e.contains("os error"), "{e}");
    assert!(work_folders(&tmp).is_empty(), "a work folder was left");
}

/// Fills the file system of `dir` until no byte more fits, leaving `keep` bytes free.
fn fill(dir: &Path, keep: u64) {
    let free = |p: &Path| -> u64 {
        let o = Command::new("df")
            .args(["-B1", "--output=avail", s(p)])
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .nth(1)
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    };
    let f = free(dir);
    let mut w = std::fs::File::create(dir.join("filler")).unwrap();
    let _ = w.write_all(&vec![7u8; f.saturating_sub(keep) as usize]);
    let _ = w.sync_all();
}

/// Item 9c: A full output disk fails up front; 9d. a write that fails for lack of space keeps the
/// voxelized chunks, and once there is space the same command writes only the file (the
/// earlier stages are taken from the work folder) with the bytes of a fresh build.
#[test]
fn full_output_disk_fails_early_and_keeps_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mnt = d.join("mnt");
    let tmp = d.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let fresh = d.join("fresh.voxlod");
    let args = |o: &Path| {
        vec![
            "build".to_string(),
            "-q".into(),
            "--json".into(),
            s(&sample()).into(),
            "-o".into(),
            s(o).into(),
            "-r".into(),
            "512".into(),
            "--tmp".into(),
            s(&tmp).into(),
        ]
    };
    let run = |o: &Path| {
        let a = args(o);
        voxlod(&a.iter().map(String::as_str).collect::<Vec<_>>(), d)
    };
    ok(&run(&fresh));
    let bytes = std::fs::read(&fresh).unwrap();
    let r = Reader::open(&fresh).unwrap();
    let leaves: u64 = r
        .nodes()
        .iter()
        .filter(|n| n.level == 0)
        .map(|n| n.payload_size)
        .sum();
    drop(r);
    assert!(
        bytes.len() as u64 > leaves + 64 * 1024,
        "too small a file to test with"
    );
    // room for the file, the lock file and a little more
    let size = format!("size={}k", bytes.len() / 1024 + 512);
    let Some(_mount) = Mount::new(&mnt, &size) else {
        voxlod_testkit::skipped(
            "full_output_disk_fails_early_and_keeps_the_work",
            "mounting a tmpfs needs root",
        );
        return;
    };

    // 9c: a full disk
    fill(&mnt, 0);
    let out = mnt.join("x.voxlod");
    let t = Instant::now();
    let o = run(&out);
    let e = fails_with(&o, &["x.voxlod", "full"]);
    assert!(!e.contains("os error"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(5));
    assert!(work_folders(&tmp).is_empty());
    std::fs::remove_file(mnt.join("filler")).unwrap();

    // 9d: room for the leaf chunks but not for the whole file: the write fails, the work stays
    fill(&mnt, (leaves + bytes.len() as u64) / 2);
    let o = run(&out);
    fails_with(&o, &["x.voxlod", "kept in", "run the same command again"]);
    assert!(!out.exists());
    assert_eq!(work_folders(&tmp).len(), 1, "the work folder was not kept");
    let left: Vec<_> = std::fs::read_dir(&mnt)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("filler")]);
    std::fs::remove_file(mnt.join("filler")).unwrap();
    let o = run(&out);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for st in summary["stages"].as_array().unwrap() {
        let resumed = st["resumed"].as_bool().unwrap();
        assert_eq!(resumed, st["stage"] != "lod+write", "{st}");
    }
    // the manifest holds the input's name only, so the bytes are those of the fresh build
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
    assert!(work_folders(&tmp).is_empty());
}

/// Item 11: The peak memory a build reports is its own, not that of the process that launched it
/// (before: a 1.5 GB launcher made a small build report 1.5 GB).
#[test]
fn peak_memory_is_the_builds_own() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let big: Vec<u8> = vec![1u8; 1536 << 20]; // touched: resident in this process
    let o = voxlod(
        &[
            "build",
            "-q",
            "--json",
            s(&sample()),
            "-o",
            s(&d.join("m.voxlod")),
            "-r",
            "256",
            "-j",
            "1",
        ],
        d,
    );
    assert_eq!(big[big.len() - 1], 1);
    drop(big);
    ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let peak = summary["peak_rss"].as_u64().unwrap();
    assert!(peak > 0 && peak < 1024 << 20, "peak_rss {peak}");
    for st in summary["stages"].as_array().unwrap() {
        assert!(st["peak_rss"].as_u64().unwrap() <= peak);
    }
}

/// Messages: each names the problem once, in words, without Rust's debug formatting.
#[test]
fn messages_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let no_debug = |e: &str| {
        for leak in [
            "\\u{",
            "os error",
            "(Loop)",
            "[56,",
            "Some(",
            "No such device",
        ] {
            assert!(!e.contains(leak), "{leak:?} leaked into: {e}");
        }
    };
    // inspect on a directory, and on a file that is not an octree: the path once, the magic
    // bytes in hex
    let o = voxlod(&["inspect", s(d)], d);
    no_debug(&fails_with(&o, &["is a directory"]));
    let garbage = d.join("garbage.bin");
    std::fs::write(&garbage, vec![b'V'; 300]).unwrap();
    let o = voxlod(&["inspect", s(&garbage)], d);
    let e = fails_with(&o, &["magic bytes are 56 56 56", "not a voxlod file"]);
    no_debug(&e);
    assert_eq!(e.matches("garbage.bin").count(), 1, "{e}");
    // a FIFO or a device as input: said so, at once (before: "is empty", or a read that
    // never ends)
    let fifo = d.join("pipe.ply");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    for (input, what) in [
        (fifo.as_path(), "a FIFO"),
        (Path::new("/dev/zero"), "a device"),
    ] {
        let o = voxlod(&["build", "-q", s(input), "-o", s(&d.join("o.voxlod"))], d);
        no_debug(&fails_with(&o, &[s(input), what, "regular file"]));
    }
    // ASCII STL: the keyword and what was expected, in words
    let stl = d.join("bad.stl");
    std::fs::write(
        &stl,
        "solid x\nfacet normal 0 0 1\nouter loop\nvertx 0 0 0\nendloop\nendfacet\nendsolid x\n",
    )
    .unwrap();
    let o = voxlod(&["build", "-q", s(&stl)], d);
    no_debug(&fails_with(
        &o,
        &[
            "bad.stl",
            "line 4",
            "\"vertx\" where \"vertex\" or \"endloop\" was expected",
        ],
    ));
    // PLY header: control bytes shown as \xNN
    let ply = d.join("ctl.ply");
    std::fs::write(
        &ply,
        b"ply\nformat ascii 1.0\nelement vertex 1\nprope\x01\0\0\0float x\nend_header\n0\n",
    )
    .unwrap();
    let o = voxlod(&["build", "-q", s(&ply)], d);
    no_debug(&fails_with(
        &o,
        &["ctl.ply", "\"prope\\x01\\x00\\x00\\x00float\""],
    ));
    // a header claiming far more faces than the file can hold: said so, not "disk space"
    let huge = d.join("huge.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 4000000000\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    bytes.extend(std::iter::repeat_n(0u8, 36 + 13 * 1000));
    std::fs::write(&huge, &bytes).unwrap();
    let o = voxlod(&["build", "-q", s(&huge)], d);
    let e = fails_with(&o, &["huge.ply", "inconsistent with the file size"]);
    assert!(!e.contains("disk space"), "{e}");
    // a value from a settings file is blamed on the file, a flag's on the flag
    let cfg = d.join("c.toml");
    std::fs::write(&cfg, "resolution = 300\n").unwrap();
    let o = voxlod(&["build", "-q", s(&sample()), "--config", s(&cfg)], d);
    let e = fails_with(&o, &["settings file", "c.toml", "resolution = 300"]);
    assert!(!e.contains("--resolution"), "{e}");
    let o = voxlod(
        &[
            "build",
            "-q",
            s(&sample()),
            "-r",
            "300",
            "--config",
            s(&cfg),
        ],
        d,
    );
    fails_with(&o, &["--resolution 300"]);
    // a file that is no settings file (`/proc/self/environ`, a key file) is not echoed: the
    // error says where and what, not the line
    let secret = d.join("environ");
    std::fs::write(&secret, "HOME=/root\0API_TOKEN=hunter2-secret\0").unwrap();
    let o = voxlod(&["build", "-q", s(&sample()), "--config", s(&secret)], d);
    let e = fails_with(&o, &["settings file", "environ", "line 1, column"]);
    assert!(!e.contains("hunter2") && !e.contains("HOME=/root"), "{e}");
    let o = voxlod(
        &[
            "build",
            "-q",
            s(&sample()),
            "--config",
            "/proc/self/environ",
        ],
        d,
    );
    let e = fails_with(&o, &["settings file /proc/self/environ"]);
    assert!(!e.contains("PATH="), "{e}");
    // NaN tolerances are refused (clap's usage error: exit status 2)
    let f = d.join("f.voxlod");
    ok(&voxlod(
        &["build", "-q", s(&sample()), "-o", s(&f), "-r", "256"],
        d,
    ));
    let o = voxlod(&["diff", s(&f), s(&f), "--min-iou", "nan"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("not a number from 0 to 1"),
        "{}",
        stderr(&o)
    );
    ok(&voxlod(&["diff", s(&f), s(&f), "--min-iou", "0.5"], d));
}

/// Item 10: a killed build followed by a build with other settings leaves a stale work folder;
/// the build summary says so, `voxlod clean --dry-run` lists it with its size and keeps it,
/// `voxlod clean` removes it, and a folder held by a running build is listed as in use and
/// kept.
#[test]
fn stale_work_folders_are_reported_and_cleaned() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("bunny.voxlod");
    let o = voxlod(
        &[
            "build",
            "-q",
            s(&sample()),
            "-o",
            s(&out),
            "-r",
            "512",
            "--debug-interrupt-after-chunks",
            "1",
        ],
        d,
    );
    assert!(!o.status.success(), "the interrupted build must fail");
    let stale = work_folders(d);
    assert_eq!(
        stale.len(),
        1,
        "the interrupted build keeps its work folder"
    );
    // another resolution: a new work folder; the old one is reported in the summary
    let o = voxlod(
        &["build", "-q", s(&sample()), "-o", s(&out), "-r", "256"],
        d,
    );
    ok(&o);
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("1 stale work folder") && summary.contains("voxlod clean"),
        "{summary}"
    );
    assert_eq!(work_folders(d), stale);
    // a folder in use: a running build's lock, held here by flock(1)
    let busy = d.join(".voxlod-work-other.voxlod-0123456789abcdef");
    std::fs::create_dir(&busy).unwrap();
    std::fs::write(busy.join("data"), vec![1u8; 5000]).unwrap();
    let mut holder = Command::new("flock")
        .arg(busy.join("lock"))
        .args(["sleep", "60"])
        .process_group(0) // with the sleep that inherits the locked descriptor
        .spawn()
        .unwrap();
    let t = Instant::now();
    while !busy.join("lock").exists() && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));

    let o = voxlod(&["clean", "--dry-run", s(d)], d);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("stale") && text.contains("would be removed") && text.contains("in use"),
        "{text}"
    );
    assert!(text.contains(&*stale[0].to_string_lossy()), "{text}");
    assert!(
        text.contains("KiB") || text.contains("MiB"),
        "sizes: {text}"
    );
    assert_eq!(work_folders(d).len(), 2, "--dry-run removes nothing");

    let o = voxlod(&["clean", s(d)], d);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("removed 1 stale work folder"), "{text}");
    assert_eq!(work_folders(d), vec![busy.clone()], "{text}");
    let _ = Command::new("kill")
        .args(["-TERM", "--", &format!("-{}", holder.id())])
        .status();
    let _ = holder.wait();
    // The sleep that inherited the locked descriptor dies after flock(1) has been reaped: wait
    // until the lock is free (under load the next clean could otherwise still see it in use).
    let t = Instant::now();
    while !Command::new("flock")
        .arg("--nonblock")
        .arg(busy.join("lock"))
        .arg("true")
        .status()
        .unwrap()
        .success()
    {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the lock is still held"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // no longer held: now it goes too, and a build beside it reports nothing
    ok(&voxlod(&["clean", s(d)], d));
    assert!(work_folders(d).is_empty());
    let o = voxlod(
        &["build", "-q", s(&sample()), "-o", s(&out), "-r", "256"],
        d,
    );
    ok(&o);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("stale"));
    assert!(String::from_utf8_lossy(&voxlod(&["clean", s(d)], d).stdout)
        .contains("no voxlod work folders"));
}

/// `clean`: a run killed while writing its output (here `gen`, SIGKILL while it
/// writes) leaves `.voxlod-lock-NAME` and `.voxlod-part-NAME-…` beside it; `clean --dry-run`
/// lists them and keeps them, `clean` removes them (and nothing else), and those of an output
/// whose lock a running process holds are listed as being written and kept.
#[test]
fn leftovers_of_killed_writers_are_cleaned() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("big.ply");
    let mut child = Command::new(BIN)
        .args(["gen", "-q", "-n", "3e7", "-o", s(&out)])
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let part = |d: &Path| {
        std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".voxlod-part-big.ply-"))
            .collect::<Vec<_>>()
    };
    let t = Instant::now();
    while part(d).is_empty() || std::fs::metadata(d.join(part(d)[0].clone())).unwrap().len() == 0 {
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "gen wrote no part file"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "gen ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!out.exists(), "a killed gen left its output");
    assert!(d.join(".voxlod-lock-big.ply").exists());
    assert_eq!(part(d).len(), 1);
    // an output being written by a live process: its lock held by flock(1)
    let busy_lock = d.join(".voxlod-lock-busy.png");
    std::fs::write(d.join(".voxlod-part-busy.png-123-abc"), b"partial").unwrap();
    let mut holder = Command::new("flock")
        .arg(&busy_lock)
        .args(["sleep", "60"])
        .process_group(0)
        .spawn()
        .unwrap();
    let t = Instant::now();
    while !busy_lock.exists() && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));

    let o = voxlod(&["clean", "--dry-run", s(d)], d);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        text.contains("left by a killed run")
            && text.contains("big.ply")
            && text.contains("would be removed")
            && text.contains("being written")
            && text.contains("busy.png"),
        "{text}"
    );
    assert_eq!(part(d).len(), 1, "--dry-run removed something: {text}");

    let o = voxlod(&["clean", s(d)], d);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        text.contains("removed the leftovers of 1 killed output"),
        "{text}"
    );
    assert!(
        part(d).is_empty() && !d.join(".voxlod-lock-big.ply").exists(),
        "{text}"
    );
    assert!(busy_lock.exists() && d.join(".voxlod-part-busy.png-123-abc").exists());
    let _ = Command::new("kill")
        .args(["-TERM", "--", &format!("-{}", holder.id())])
        .status();
    let _ = holder.wait();
}

/// A 3D Tiles export stages its folder as `.voxlod-part-NAME-PID-TIME` under the output's lock
/// (`.voxlod-lock-NAME`), like a file output: what a killed export left (here made by hand: a
/// staged folder with a tile in it and the lock file nobody holds) is listed and removed by
/// `clean`, and also by the next export to the same folder; a finished export (a new one and
/// one replacing a tileset with `--force`) leaves nothing beside its folder.
#[test]
fn a_killed_tiles_exports_staging_folder_is_cleaned() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&voxlod(
        &["build", "-q", s(&sample()), "-o", "s.voxlod", "-r", "256"],
        d,
    ));
    let hidden = |d: &Path| {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".voxlod-"))
            .collect();
        v.sort();
        v
    };
    let leave = |d: &Path| {
        let staged = d.join(".voxlod-part-tiles-4242-17f3a9");
        std::fs::create_dir_all(staged.join("tiles")).unwrap();
        std::fs::write(staged.join("tiles/0.glb"), vec![1u8; 5000]).unwrap();
        std::fs::write(d.join(".voxlod-lock-tiles"), b"4242").unwrap();
    };
    leave(d);
    let o = voxlod(&["clean", "--dry-run", s(d)], d);
    ok(&o);
    let t = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        t.contains("left by a killed run")
            && t.contains(".voxlod-part-tiles-4242-17f3a9")
            && t.contains("would be removed"),
        "{t}"
    );
    let o = voxlod(&["clean", s(d)], d);
    ok(&o);
    let t = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        t.contains("removed the leftovers of 1 killed output"),
        "{t}"
    );
    assert!(hidden(d).is_empty(), "{:?}", hidden(d));

    // the next export to the same folder removes them too, and leaves nothing itself
    leave(d);
    ok(&voxlod(&["export", "s.voxlod", "--3d-tiles", "tiles"], d));
    assert!(d.join("tiles/tileset.json").is_file());
    assert!(hidden(d).is_empty(), "{:?}", hidden(d));
    ok(&voxlod(
        &["export", "s.voxlod", "--3d-tiles", "tiles", "--force"],
        d,
    ));
    assert!(d.join("tiles/tileset.json").is_file());
    assert!(hidden(d).is_empty(), "{:?}", hidden(d));
}

/// More messages (docs/RELIABILITY.md, "Messages"): each names the file and
/// the place, in words.
#[test]
fn more_messages_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // an ASCII list count above its declared uchar type
    let ply = d.join("count.ply");
    std::fs::write(
        &ply,
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n300 {}\n",
            "0 1 2 ".repeat(100)
        ),
    )
    .unwrap();
    let o = voxlod(&["build", "-q", s(&ply)], d);
    fails_with(
        &o,
        &[
            "count.ply",
            "line 13",
            "300 does not fit the declared type uchar",
        ],
    );
    // OBJ: a normal index past the normals, and text that is not UTF-8 (tobj: "face normal
    // index out of bounds", "read error", without a line)
    let obj = d.join("n.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n",
    )
    .unwrap();
    let e = fails_with(
        &voxlod(&["build", "-q", s(&obj)], d),
        &["n.obj", "line 5", "normal"],
    );
    assert!(!e.contains("out of bounds"), "{e}");
    let obj = d.join("u.obj");
    std::fs::write(&obj, b"v 0 0 0\nv 1 0 0\n# caf\xe9\nv 0 1 0\nf 1 2 3\n").unwrap();
    let e = fails_with(
        &voxlod(&["build", "-q", s(&obj)], d),
        &["u.obj", "line 3", "UTF-8"],
    );
    assert!(!e.contains("read error"), "{e}");
    // a gzip PLY declaring 1e19 vertices: no "needs 18446744073709551615 bytes"
    let gz = d.join("big.ply.gz");
    std::fs::write(
        &gz,
        gzip(b"ply\nformat binary_little_endian 1.0\nelement vertex 10000000000000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"),
    )
    .unwrap();
    let e = fails_with(&voxlod(&["build", "-q", s(&gz)], d), &["big.ply.gz"]);
    assert!(!e.contains("18446744073709551615"), "{e}");
    // the memory plan's parts add up to its total
    let o = voxlod(
        &[
            "build",
            s(&sample()),
            "-o",
            s(&d.join("m.voxlod")),
            "-r",
            "256",
            "--memory",
            "1GiB",
            "-j",
            "1",
        ],
        d,
    );
    ok(&o);
    let e = stderr(&o);
    let plan = e
        .lines()
        .find(|l| l.contains("memory plan"))
        .unwrap_or_else(|| panic!("{e}"));
    assert!(
        plan.contains("= base 64.00 MiB + LOD 128.00 MiB + "),
        "{plan}"
    );
}

/// A textured quad (OBJ) whose texture is a `side`² PNG of one colour: a small file whose
/// decoded pyramid is large.
fn big_texture_quad(dir: &Path, side: u32) -> PathBuf {
    image::RgbaImage::from_pixel(side, side, image::Rgba([200, 30, 30, 255]))
        .save(dir.join("big.png"))
        .unwrap();
    std::fs::write(dir.join("q.mtl"), "newmtl m\nKd 1 1 1\nmap_Kd big.png\n").unwrap();
    let p = dir.join("q.obj");
    std::fs::write(
        &p,
        "mtllib q.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl m\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    p
}

/// The temporary-disk estimate counts the texture tiles a build writes when its textures
/// exceed their memory share (their size from the images' headers), and a build whose tiles
/// cannot fit is refused before anything is decoded or written, naming them. A 2048² PNG of
/// one colour (a few KiB) under `--memory 336MiB` (a 16 MiB texture share) writes a 21 MiB
/// tile file.
#[test]
fn texture_tiles_are_in_the_temporary_disk_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = big_texture_quad(d, 2048);
    let build = |tmp: &Path, out: &str| {
        voxlod(
            &[
                "build",
                "--json",
                s(&obj),
                "-o",
                s(&d.join(out)),
                "-r",
                "256",
                "--memory",
                "336MiB",
                "--tmp",
                s(tmp),
            ],
            d,
        )
    };
    // the estimate names the tiles, and they are what the build writes
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let o = build(&tmp, "ok.voxlod");
    let t = ok(&o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let written = summary["texture_cache"]["file_bytes"].as_u64().unwrap();
    assert!(written > 20 << 20, "{}", summary["texture_cache"]);
    let line = t
        .lines()
        .find(|l| l.starts_with("temporary disk: up to about"))
        .unwrap_or_else(|| panic!("no estimate: {t}"));
    let said = format!(
        "and texture tiles {:.2} MiB",
        written as f64 / (1u64 << 20) as f64
    );
    assert!(line.contains(&said), "{line} (wanted {said})");
    // an 8 MiB file system: refused up front, naming the tiles; nothing left behind
    let mnt = d.join("small");
    let Some(_mount) = Mount::new(&mnt, "size=8m") else {
        eprintln!(
            "texture_tiles_are_in_the_temporary_disk_estimate: the full-disk part SKIPPED: mounting a tmpfs needs root"
        );
        return;
    };
    let t0 = Instant::now();
    let o = build(&mnt, "no.voxlod");
    let e = fails_with(&o, &["not enough disk space", "texture tiles", "--tmp"]);
    assert!(!e.contains("writing the texture tiles"), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(20));
    assert!(!d.join("no.voxlod").exists());
    assert_eq!(std::fs::read_dir(&mnt).unwrap().count(), 0);
}
