//! `voxlod export -o x.glb` and the export size guard.
//!
//! The GLB is checked three ways: the Khronos glTF validator (npm `gltf-validator`, run by node
//! from `tests/node`, installed by `.ci/run`) reports no error and no warning; the `gltf`
//! crate reads the document back; and its triangles, placed by the node transforms and with
//! their normals, colours and material names, are exactly the triangles of the PLY export of
//! the same level (each PLY quad split the same way), on the shared bunny and on a made-up
//! world with three materials.
//!
//! The guard: an export over `--max-size` is refused before anything is written (no output,
//! no staged file), the refusal names the size (the size the export then writes) and the
//! coarsest level that fits, and that level is then written.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use super::{build_ok, ok, shared_meshes, text, voxlod};

/// One triangle's three vertices: position in 1/64 of the smallest voxel edge, RGBA,
/// material name; rotated so that the smallest vertex comes first (the winding is kept). No
/// two faces of a level share all of these (one face per voxel side), so sorting pairs them.
type Key = [([i64; 3], [u8; 4], String); 3];
/// A triangle: its key and its vertices' normals.
type Tri = (Key, [[f32; 3]; 3]);

fn canonical(t: [([i64; 3], [f32; 3], [u8; 4], String); 3]) -> Tri {
    let k = (0..3).min_by_key(|&i| (t[i].0, t[i].2)).unwrap();
    let mut t = t.to_vec();
    t.rotate_left(k);
    (
        std::array::from_fn(|i| (t[i].0, t[i].2, t[i].3.clone())),
        std::array::from_fn(|i| t[i].1),
    )
}

fn grid(p: [f64; 3], unit: f64) -> [i64; 3] {
    p.map(|c| (c / unit * 64.0).round() as i64)
}

/// The triangles of a PLY export (binary little-endian, as `export_ply` writes it).
fn ply_triangles(path: &Path, unit: f64, names: &[String]) -> Vec<Tri> {
    let b = std::fs::read(path).unwrap();
    let end = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = String::from_utf8_lossy(&b[..end]).to_string();
    let count = |el: &str| -> usize {
        let l = header
            .lines()
            .find(|l| l.starts_with(&format!("element {el} ")))
            .unwrap();
        l.rsplit(' ').next().unwrap().parse().unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let materials = header.contains("property uint material");
    let vb = if materials { 32 } else { 28 };
    let f = |r: &[u8], i: usize| f32::from_le_bytes(r[4 * i..4 * i + 4].try_into().unwrap());
    let verts: Vec<_> = b[end..end + nv * vb]
        .chunks_exact(vb)
        .map(|r| {
            let m = if materials {
                u32::from_le_bytes(r[28..32].try_into().unwrap())
            } else {
                0
            };
            let name = names
                .get(m as usize)
                .filter(|n| !n.is_empty())
                .cloned()
                .unwrap_or_else(|| "voxel".into());
            (
                grid([f(r, 0) as f64, f(r, 1) as f64, f(r, 2) as f64], unit),
                [f(r, 3), f(r, 4), f(r, 5)],
                [r[24], r[25], r[26], r[27]],
                name,
            )
        })
        .collect();
    let faces = &b[end + nv * vb..];
    assert_eq!(faces.len(), 17 * nf);
    let mut tris = Vec::new();
    for rec in faces.chunks_exact(17) {
        assert_eq!(rec[0], 4);
        let q: Vec<usize> = (0..4)
            .map(|k| u32::from_le_bytes(rec[1 + 4 * k..5 + 4 * k].try_into().unwrap()) as usize)
            .collect();
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            tris.push(canonical(t.map(|i| verts[i].clone())));
        }
    }
    tris
}

/// Reads `n` components of type `ct` at `at` of `blob` as f64 (normalized as glTF says).
fn component(blob: &[u8], at: usize, ct: gltf::accessor::DataType, normalized: bool) -> f64 {
    use gltf::accessor::DataType as D;
    let (v, max) = match ct {
        D::U8 => (blob[at] as f64, 255.0),
        D::I16 => (i16::from_le_bytes([blob[at], blob[at + 1]]) as f64, 32767.0),
        D::U16 => (u16::from_le_bytes([blob[at], blob[at + 1]]) as f64, 65535.0),
        D::U32 => (
            u32::from_le_bytes(blob[at..at + 4].try_into().unwrap()) as f64,
            1.0,
        ),
        D::F32 => (
            f32::from_le_bytes(blob[at..at + 4].try_into().unwrap()) as f64,
            1.0,
        ),
        D::I8 => (blob[at] as i8 as f64, 127.0),
    };
    if normalized {
        (v / max).max(-1.0)
    } else {
        v
    }
}

/// Every element of an accessor as f64 components.
fn read_accessor(a: &gltf::Accessor, blob: &[u8]) -> Vec<Vec<f64>> {
    let view = a.view().unwrap();
    let size = a.data_type().size();
    let stride = view.stride().unwrap_or(a.size());
    let base = view.offset() + a.offset();
    (0..a.count())
        .map(|i| {
            (0..a.dimensions().multiplicity())
                .map(|c| {
                    component(
                        blob,
                        base + i * stride + c * size,
                        a.data_type(),
                        a.normalized(),
                    )
                })
                .collect()
        })
        .collect()
}

/// The triangles of a GLB export, placed by the node transforms (translation, scale; no
/// rotation in `-o x.glb`), read with the `gltf` crate. Also: the file's extensions.
fn glb_triangles(path: &Path, unit: f64) -> (Vec<Tri>, Vec<String>) {
    let bytes = std::fs::read(path).unwrap();
    // without validation: the crate does not list KHR_mesh_quantization as supported
    let g = gltf::Gltf::from_slice_without_validation(&bytes).unwrap();
    let blob = g.blob.as_deref().unwrap();
    let doc = &g.document;
    let mut tris = Vec::new();
    let scene = doc.default_scene().unwrap();
    let mut stack: Vec<gltf::Node> = scene.nodes().collect();
    while let Some(node) = stack.pop() {
        stack.extend(node.children());
        let Some(mesh) = node.mesh() else { continue };
        let (t, r, s) = node.transform().decomposed();
        assert_eq!(r, [0.0, 0.0, 0.0, 1.0], "no rotation in a plain GLB export");
        for p in mesh.primitives() {
            assert_eq!(p.mode(), gltf::mesh::Mode::Triangles);
            let name = p.material().name().unwrap().to_string();
            let pos = read_accessor(&p.get(&gltf::Semantic::Positions).unwrap(), blob);
            let nrm = read_accessor(&p.get(&gltf::Semantic::Normals).unwrap(), blob);
            let col = read_accessor(&p.get(&gltf::Semantic::Colors(0)).unwrap(), blob);
            let idx = read_accessor(&p.indices().unwrap(), blob);
            let vert = |i: usize| {
                let w: [f64; 3] = std::array::from_fn(|a| t[a] as f64 + s[a] as f64 * pos[i][a]);
                let n: [f32; 3] = std::array::from_fn(|a| nrm[i][a] as f32);
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-3, "normal {n:?} not unit");
                // COLOR_0 is linear (glTF): back to the stored sRGB byte, by IEC 61966-2-1
                let c: [u8; 4] = std::array::from_fn(|a| {
                    let l = col[i][a];
                    let s = if a == 3 || l <= 0.0031308 {
                        if a == 3 {
                            l
                        } else {
                            l * 12.92
                        }
                    } else {
                        1.055 * l.powf(1.0 / 2.4) - 0.055
                    };
                    (s * 255.0).round() as u8
                });
                (grid(w, unit), n, c, name.clone())
            };
            for t in idx.chunks_exact(3) {
                tris.push(canonical([0, 1, 2].map(|k| vert(t[k][0] as usize))));
            }
        }
    }
    (
        tris,
        g.document.extensions_required().map(String::from).collect(),
    )
}

/// The Khronos validator's report on `glb`, or None (skipped; a failure under CI) when node
/// or the validator is not installed.
fn khronos_report(glb: &Path) -> Option<serde_json::Value> {
    let node = Path::new(super::REPO).join("tests/node");
    let installed = node.join("node_modules/gltf-validator").is_dir()
        && Command::new("node")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if !installed {
        assert!(
            !voxlod_testkit::under_ci(),
            "the Khronos glTF validator is not installed (node and `npm ci` in tests/node: .ci/run does both)"
        );
        voxlod_testkit::skipped(
            "export_gltf (the Khronos glTF validator)",
            "not installed (run `npm ci` in tests/node)",
        );
        return None;
    }
    let o = Command::new("node")
        .arg(node.join("validate-gltf.js"))
        .arg(glb)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    Some(serde_json::from_slice(&o.stdout).unwrap())
}

fn check_glb_against_ply(file: &Path, level: u32, dir: &Path) {
    let r = voxlod_format::Reader::open(file).unwrap();
    let names: Vec<String> = r.manifest().unwrap()["materials"]
        .as_array()
        .map(|a| a.iter().map(|n| n.as_str().unwrap().to_string()).collect())
        .unwrap_or_default();
    let unit = r.spec().voxel_size;
    let (ply, glb) = (dir.join("l.ply"), dir.join("l.glb"));
    let f = file.to_str().unwrap();
    let lv = level.to_string();
    ok(&voxlod(
        &["export", f, "--level", &lv, "-o", ply.to_str().unwrap()],
        dir,
    ));
    let said = ok(&voxlod(
        &["export", f, "--level", &lv, "-o", glb.to_str().unwrap()],
        dir,
    ));
    let bytes = std::fs::metadata(&glb).unwrap().len();
    assert!(
        said.contains(&voxlod_pipeline::format_size(bytes)),
        "{said}"
    );

    let mut want = ply_triangles(&ply, unit, &names);
    let (mut got, required) = glb_triangles(&glb, unit);
    assert_eq!(required, ["KHR_mesh_quantization"]);
    assert!(!want.is_empty());
    assert_eq!(got.len(), want.len(), "triangles of {f} level {level}");
    want.sort_by(|a, b| a.0.cmp(&b.0));
    got.sort_by(|a, b| a.0.cmp(&b.0));
    let differ = want.iter().zip(&got).filter(|(a, b)| a.0 != b.0).count();
    let first = want.iter().zip(&got).find(|(a, b)| a.0 != b.0);
    assert_eq!(
        differ,
        0,
        "{differ} of {} triangles differ, e.g. {first:?}",
        want.len()
    );
    // normals: the PLY's f32, the GLB's normalized i16 (within its quantization step)
    for (a, b) in want.iter().zip(&got) {
        for (na, nb) in a.1.iter().zip(&b.1) {
            assert!(
                na.iter().zip(nb).all(|(x, y)| (x - y).abs() < 1e-4),
                "{na:?} vs {nb:?}"
            );
        }
    }
    if names.len() > 1 {
        let used: std::collections::BTreeSet<_> = got.iter().map(|t| t.0[0].2.clone()).collect();
        assert!(used.len() > 1, "materials {used:?}");
        assert!(
            used.iter().all(|u| names.contains(u)),
            "{used:?} not in {names:?}"
        );
    }

    if let Some(report) = khronos_report(&glb) {
        let issues = &report["issues"];
        assert_eq!(issues["numErrors"], 0, "{issues}");
        assert_eq!(issues["numWarnings"], 0, "{issues}");
        assert_eq!(
            report["info"]["extensionsRequired"],
            serde_json::json!(["KHR_mesh_quantization"])
        );
    }
}

#[test]
fn glb_export_is_the_ply_export_and_valid_gltf() {
    let Some(m) = shared_meshes("glb_export_is_the_ply_export_and_valid_gltf") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // a real scan, two levels
    let bunny = d.join("bunny.voxlod");
    build_ok(&m.join("npm-bunny/bunny.ply"), &bunny, &["-r", "512"], d);
    check_glb_against_ply(&bunny, 1, d);
    // a real model with materials (per-face materials become glTF materials by name)
    let sib = d.join("sibenik.voxlod");
    build_ok(
        &m.join("mcguire-sibenik/sibenik.obj"),
        &sib,
        &["-r", "256"],
        d,
    );
    check_glb_against_ply(&sib, 0, d);

    // .gltf is refused with what to write instead; an existing PLY is not replaced by a GLB
    let o = voxlod(&["export", "bunny.voxlod", "-o", "x.gltf"], d);
    assert!(!o.status.success());
    assert!(text(&o).contains("name it .glb"), "{}", text(&o));
    // a name of a format export does not write is refused, nothing is left under it
    for (args, says) in [
        (
            &["-o", "x.obj"][..],
            "must end in .ply (binary PLY) or .glb",
        ),
        (
            &["-o", "x.OBJ"][..],
            "must end in .ply (binary PLY) or .glb",
        ),
        (&["-o", "x"][..], "must end in .ply (binary PLY) or .glb"),
        (
            &["--source", "-o", "x.glb"][..],
            "--source writes binary PLY",
        ),
    ] {
        let o = voxlod(&[&["export", "bunny.voxlod"][..], args].concat(), d);
        assert!(!o.status.success(), "{args:?}");
        let out = text(&o);
        assert!(
            out.contains(says) && out.contains(args[args.len() - 1]),
            "{out}"
        );
        assert!(!d.join(args[args.len() - 1]).exists(), "{args:?}");
    }
    let o = voxlod(
        &["export", "bunny.voxlod", "--level", "1", "-o", "l.glb"],
        d,
    );
    ok(&o);
    std::fs::copy(d.join("l.ply"), d.join("p.glb")).unwrap();
    let o = voxlod(
        &["export", "bunny.voxlod", "--level", "1", "-o", "p.glb"],
        d,
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("a PLY mesh"), "{}", text(&o));
}

/// The files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A size as `format_size` prints it ("78.20 MiB") back in bytes, approximately.
fn bytes_of(s: &str) -> f64 {
    let (n, u) = s.split_once(' ').unwrap();
    let k = ["B", "KiB", "MiB", "GiB", "TiB"]
        .iter()
        .position(|x| *x == u)
        .unwrap();
    n.parse::<f64>().unwrap() * 1024f64.powi(k as i32)
}

#[test]
fn export_over_the_size_limit_is_refused_before_writing() {
    let Some(m) = shared_meshes("export_over_the_size_limit_is_refused_before_writing") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bunny = d.join("bunny.voxlod");
    build_ok(&m.join("npm-bunny/bunny.ply"), &bunny, &["-r", "512"], d);
    let before = listing(d);
    let mut sizes = BTreeMap::new();
    for out in ["big.ply", "big.glb"] {
        let o = voxlod(
            &["export", "bunny.voxlod", "-o", out, "--max-size", "100MiB"],
            d,
        );
        let t = text(&o);
        assert!(!o.status.success(), "{t}");
        assert!(
            t.contains(&format!("{out}: the export of level 0 would write ")),
            "{t}"
        );
        assert!(
            t.contains("more than --max-size 100.00 MiB; nothing was written"),
            "{t}"
        );
        // the bunny at 512³ has levels 0 and 1; level 1 is about a quarter of level 0
        let hint = t
            .split("Level ")
            .nth(1)
            .unwrap_or_else(|| panic!("no level named: {t}"));
        assert!(
            hint.starts_with("1 is the coarsest that fits (about "),
            "{t}"
        );
        assert!(
            t.contains("--level 1; or allow more with --max-size SIZE."),
            "{t}"
        );
        assert_eq!(listing(d), before, "nothing written, nothing staged");
        let size_of = |after: &str| {
            let s = t.split(after).nth(1).unwrap();
            s[..s.find([',', ')']).unwrap()].to_string()
        };
        sizes.insert(out, (size_of("would write "), size_of("(about ")));
    }
    // the level named fits and is written; its size is near the estimate the refusal gave
    for out in ["big.ply", "big.glb"] {
        let o = voxlod(
            &[
                "export",
                "bunny.voxlod",
                "--level",
                "1",
                "-o",
                out,
                "--max-size",
                "100MiB",
            ],
            d,
        );
        ok(&o);
        let real = std::fs::metadata(d.join(out)).unwrap().len() as f64;
        let est = bytes_of(&sizes[out].1);
        assert!(
            (est / real - 1.0).abs() < 0.15,
            "{out}: estimate {est} vs {real}"
        );
        assert!(real <= 100.0 * 1024.0 * 1024.0);
    }
    // the size refused is the size written: level 1 under a smaller limit, no coarser level
    for out in ["big.ply", "big.glb"] {
        let real = std::fs::metadata(d.join(out)).unwrap().len();
        let o = voxlod(
            &[
                "export",
                "bunny.voxlod",
                "--level",
                "1",
                "-o",
                out,
                "--max-size",
                "1MiB",
            ],
            d,
        );
        let t = text(&o);
        assert!(!o.status.success(), "{t}");
        let want = format!(
            "{out}: the export of level 1 would write {}, more than --max-size 1.00 MiB; nothing was written. No coarser level fits either",
            voxlod_pipeline::format_size(real)
        );
        assert!(t.contains(&want), "{t}");
        assert_eq!(
            std::fs::metadata(d.join(out)).unwrap().len(),
            real,
            "the old file stays"
        );
    }
    // sizes parse as elsewhere in the CLI
    let o = voxlod(
        &[
            "export",
            "bunny.voxlod",
            "-o",
            "x.ply",
            "--max-size",
            "lots",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("--max-size"), "{}", text(&o));
}
