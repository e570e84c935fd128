//! End-to-end tests of the `voxlod` binary: on the bundled sample and on real meshes from
//! `../shared/data/meshes`, checked against independent recomputations.
//!
//! All of the `voxlod` crate's integration tests are this one test binary (one link; the tests
//! of every module run in parallel threads of one process), split by subject into modules:
//! the helpers here (running the binary: `voxlod`, `ok`, `text`; the sample, the shared
//! meshes, the LOD reference) are the one copy every module uses, beside a module's own
//! helpers for its subject. A new test file goes into this folder with a `mod` line here
//! (`every_file_is_a_module` fails otherwise); run one module with
//! `cargo test -p voxlod --test e2e MODULE::`.

mod cli;
mod cluster;
mod export_gltf;
mod faults;
mod gen;
mod gen_blocks;
mod gltf_budget;
mod gltf_round_trip;
mod gpu;
mod hostile;
mod index_bins;
mod json_schema;
mod licence;
mod materials;
mod octree;
mod python_package;
mod python_reader;
mod resume;
mod shard;
mod shard_integrity;
mod textures;
mod tiles;
mod tools;
mod validation;
mod view;
mod web;

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

/// The shared test meshes (`voxlod_testkit::shared_meshes`: skipped with a note without
/// `../shared`, a failure under CI).
fn shared_meshes(test: &str) -> Option<PathBuf> {
    voxlod_testkit::shared_meshes(test)
}

/// Runs the binary with `args` in `cwd` (`NO_COLOR` set, so messages carry no escapes).
fn voxlod<S: AsRef<std::ffi::OsStr>>(args: &[S], cwd: impl AsRef<Path>) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .env("NO_COLOR", "1")
        .output()
        .expect("running voxlod")
}

/// A run's stdout followed by its stderr, as text.
fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
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

/// Runs `voxlod build -q INPUT -o OUT EXTRA…` in `cwd` and asserts that it succeeded.
fn build_ok(input: &Path, out: &Path, extra: &[&str], cwd: &Path) -> Output {
    let args = build_args(input, out, extra);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = voxlod(&args, cwd);
    ok(&o);
    o
}

/// Asserts that a run succeeded (its stderr and stdout in the message otherwise); its
/// [`text`].
fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "voxlod failed: {}\n{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    text(o)
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
    let mut t = voxlod_io::PlyHeader::ascii()
        .element("vertex", (tris.len() * 3) as u64)
        .properties("float", &["x", "y", "z"])
        .element("face", tris.len() as u64)
        .list("uchar", "int", "vertex_indices")
        .end();
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

/// The sample's triangles as a binary PLY (three vertices per triangle, in order), followed by
/// `extra` vertices that no face uses.
fn binary_copy_of_sample(dir: &Path, name: &str, extra: &[[f32; 3]]) -> PathBuf {
    let tris = sample_triangles();
    let mut out = voxlod_io::PlyHeader::binary_le()
        .element("vertex", (tris.len() * 3 + extra.len()) as u64)
        .properties("float", &["x", "y", "z"])
        .element("face", tris.len() as u64)
        .list("uchar", "int", "vertex_indices")
        .end()
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

/// Every file of this folder is compiled as a module of this binary, and no test file is left
/// in `tests/` itself (no test target would compile it).
#[test]
fn every_file_is_a_module() {
    let dir = Path::new(REPO).join("tests/e2e");
    voxlod_testkit::suite::assert_every_file_is_a_module(&dir, include_str!("main.rs"));
    let stray = voxlod_testkit::suite::module_files(&Path::new(REPO).join("tests"));
    assert!(stray.is_empty(), "tests/{stray:?}.rs: move into tests/e2e/");
}
