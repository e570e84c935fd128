//! `voxlod build` on textured meshes (docs/TEXTURES.md): a made-up textured OBJ whose voxel
//! colours are known, a missing texture (a warning naming it, `Kd` used), the GPU backend
//! handing a textured mesh to the CPU, and the shared YCB banana and Sponza (built, coloured,
//! the same bytes on one and two threads).

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use voxlod_format::Reader;

use super::{shared_meshes, BIN};

/// `voxlod build INPUT -o OUT -q --json EXTRA…`; the parsed summary.
fn build(input: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let o: Output = Command::new(BIN)
        .arg("build")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["-q", "--json"])
        .args(extra)
        .env("NO_COLOR", "1")
        .output()
        .expect("running voxlod");
    assert!(
        o.status.success(),
        "voxlod failed: {}\n{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    serde_json::from_slice(&o.stdout).expect("--json output")
}

/// Every level-0 voxel's colour.
fn level0_colors(path: &Path) -> Vec<[u8; 4]> {
    let r = Reader::open(path).unwrap();
    let mut out = Vec::new();
    for (i, n) in r.nodes().iter().enumerate() {
        if n.level == 0 {
            out.extend(r.read_node(i).unwrap().iter().map(|v| v.rgba()));
        }
    }
    out
}

fn warnings(summary: &serde_json::Value) -> Vec<String> {
    summary["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

/// A 256-unit quad in z = 0.5 (the grid is fitted to it: 256³ voxels of edge 1) textured with
/// a one-texel black and white checkerboard of 1024² texels (4 texels per voxel edge), and
/// `map_Kd` written in another letter case than the file.
fn checker_obj(dir: &Path, map_kd: &str) -> PathBuf {
    let n = 1024u32;
    let img = image::RgbImage::from_fn(n, n, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgb([0, 0, 0])
        } else {
            image::Rgb([255, 255, 255])
        }
    });
    img.save(dir.join("Checker.png")).unwrap();
    std::fs::write(
        dir.join("quad.mtl"),
        format!("newmtl checker\nKd 1 1 1\nmap_Kd {map_kd}\n"),
    )
    .unwrap();
    let obj = dir.join("quad.obj");
    std::fs::write(
        &obj,
        "mtllib quad.mtl\nv 0 0 0.5\nv 256 0 0.5\nv 256 256 0.5\nv 0 256 0.5\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl checker\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    obj
}

#[test]
fn checkerboard_quad_is_linear_grey_and_gpu_hands_it_to_the_cpu() {
    let d = tempfile::tempdir().unwrap();
    let obj = checker_obj(d.path(), "checker.PNG");
    for backend in ["cpu", "gpu"] {
        let out = d.path().join(format!("{backend}.voxlod"));
        let s = build(&obj, &out, &["-r", "256", "--backend", backend]);
        assert!(warnings(&s).is_empty(), "{:?}", warnings(&s));
        let desc = s["backend"]["description"].as_str().unwrap();
        assert!(desc.contains("colours from textures"), "{desc}");
        if backend == "gpu" {
            assert!(desc.contains("ran on the CPU"), "{desc}");
        }
        assert_eq!(
            s["record_bytes"], 76,
            "positions, flags and texture coordinates"
        );
        let colors = level0_colors(&out);
        assert!(colors.len() >= 256 * 256, "{}", colors.len());
        // every voxel averages 4×4 texels, half black, half white: 50 % light, sRGB 188
        // (the quad's border voxels too: the zero-area neighbours outside do not count)
        for c in &colors {
            assert!(
                (187..=189).contains(&c[0]) && c[0] == c[1] && c[1] == c[2] && c[3] == 255,
                "{c:?}"
            );
        }
    }
}

#[test]
fn missing_texture_warns_and_uses_kd() {
    let d = tempfile::tempdir().unwrap();
    let obj = checker_obj(d.path(), "nowhere/gone.png");
    std::fs::write(
        d.path().join("quad.mtl"),
        "newmtl checker\nKd 1 0.5 0\nmap_Kd nowhere/gone.png\n",
    )
    .unwrap();
    let out = d.path().join("q.voxlod");
    let s = build(&obj, &out, &["-r", "256"]);
    let w = warnings(&s);
    assert!(
        w.len() == 1 && w[0].contains("gone.png") && w[0].contains("Kd is used"),
        "{w:?}"
    );
    assert!(level0_colors(&out).iter().all(|c| *c == [255, 128, 0, 255]));
    // an unreadable texture: a warning from the texture stage, Kd used
    std::fs::write(d.path().join("bad.png"), b"not a png").unwrap();
    std::fs::write(
        d.path().join("quad.mtl"),
        "newmtl checker\nKd 1 0.5 0\nmap_Kd bad.png\n",
    )
    .unwrap();
    let s = build(&obj, &out, &["-r", "256", "--force"]);
    let w = warnings(&s);
    assert!(w.len() == 1 && w[0].contains("bad.png"), "{w:?}");
    assert!(level0_colors(&out).iter().all(|c| *c == [255, 128, 0, 255]));
}

/// The YCB banana (one 4096² texture) and Sponza (a case mismatch in its MTL): they build,
/// without warnings about textures, their colours are not one flat `Kd`, and one and two
/// threads give the same voxels.
#[test]
fn shared_textured_meshes() {
    let Some(dir) = shared_meshes("shared_textured_meshes") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    for (mesh, res) in [
        ("ycb-banana-textured/textured_simple_reoriented.obj", "256"),
        ("mcguire-sponza-dabrovic/sponza.obj", "512"),
    ] {
        let input = dir.join(mesh);
        let a = d.path().join("a.voxlod");
        let b = d.path().join("b.voxlod");
        let s = build(&input, &a, &["-r", res, "-j", "1", "--force"]);
        let w = warnings(&s);
        eprintln!("{mesh}: warnings {w:?}");
        assert!(!w.iter().any(|w| w.contains("texture")), "{w:?}");
        let desc = s["backend"]["description"].as_str().unwrap();
        assert!(desc.contains("colours from textures"), "{desc}");
        build(&input, &b, &["-r", res, "-j", "2", "--force"]);
        let ca = level0_colors(&a);
        assert_eq!(ca, level0_colors(&b), "{mesh}: 1 and 2 threads differ");
        let distinct: HashSet<[u8; 4]> = ca.iter().copied().collect();
        assert!(distinct.len() > 1000, "{mesh}: {} colours", distinct.len());
        let grey = ca.iter().filter(|c| c[0] == c[1] && c[1] == c[2]).count();
        assert!(
            grey * 2 < ca.len(),
            "{mesh}: {grey} of {} voxels grey",
            ca.len()
        );
    }
}

/// Every level-0 voxel as (node position, voxel position, colour), in file order.
fn level0_voxels(path: &Path) -> Vec<([u32; 3], [u8; 3], [u8; 4])> {
    let r = Reader::open(path).unwrap();
    let mut out = Vec::new();
    for i in r.level_nodes(0).collect::<Vec<_>>() {
        let e = r.nodes()[i];
        let p = e.pos();
        out.extend(
            r.read_node(i)
                .unwrap()
                .iter()
                .map(|v| ([p[0], p[1], p[2]], v.pos(), v.rgba())),
        );
    }
    out
}

/// A 64² texture whose colour tells u from v and each from its mirror image (red grows with
/// the column, green with the row from the top, blue with both), so that a swapped or flipped
/// coordinate would change the voxels.
fn gradient_png(path: &Path) {
    image::RgbImage::from_fn(64, 64, |x, y| {
        image::Rgb([(4 * x) as u8, (4 * y) as u8, (2 * x + y) as u8])
    })
    .save(path)
    .unwrap();
}

/// The textured quad of `checker_obj` with a gradient texture, as OBJ and as PLY in both
/// texture coordinate conventions (vertex `s t`, face `texcoord` lists; converted by the test
/// kit): the same voxels with the same colours, byte for byte.
#[test]
fn textured_quad_as_ply_equals_obj() {
    use voxlod_testkit::textured::{obj_to_textured_ply, Convention};
    let d = tempfile::tempdir().unwrap();
    let obj = checker_obj(d.path(), "grad.png");
    gradient_png(&d.path().join("grad.png"));
    let want = {
        let out = d.path().join("obj.voxlod");
        assert!(warnings(&build(&obj, &out, &["-r", "256"])).is_empty());
        level0_voxels(&out)
    };
    let colours: HashSet<[u8; 4]> = want.iter().map(|v| v.2).collect();
    assert!(colours.len() > 1000, "{} colours", colours.len());
    for conv in [Convention::VertexST, Convention::FaceTexcoord] {
        let ply = d.path().join(format!("{conv:?}.ply"));
        // Kd 1 1 1: white vertices; the texture named in another letter case
        obj_to_textured_ply(&obj, &ply, "GRAD.png", conv, [255; 4]);
        let out = d.path().join(format!("{conv:?}.voxlod"));
        let s = build(&ply, &out, &["-r", "256"]);
        assert!(warnings(&s).is_empty(), "{conv:?}: {:?}", warnings(&s));
        let desc = s["backend"]["description"].as_str().unwrap();
        assert!(desc.contains("colours from textures"), "{desc}");
        assert!(
            level0_voxels(&out) == want,
            "{conv:?}: voxels differ from the OBJ build"
        );
    }
}

/// The YCB banana converted to PLY (face texcoord lists, as MeshLab writes it): the voxels and
/// colours of the OBJ build.
#[test]
fn banana_as_ply_equals_obj() {
    use voxlod_testkit::textured::{obj_to_textured_ply, Convention};
    let Some(dir) = shared_meshes("banana_as_ply_equals_obj") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let obj = dir.join("ycb-banana-textured/textured_simple_reoriented.obj");
    // the shared folder is read-only: the PLY names the texture by its path from the temporary
    // folder
    let ply = d.path().join("banana.ply");
    let tex = dir.join("ycb-banana-textured/texture_map.png");
    // Kd 0.639216 (= 163/255), d 1
    let tex = tex.canonicalize().unwrap();
    let tex = tex.to_str().unwrap();
    obj_to_textured_ply(
        &obj,
        &ply,
        tex,
        Convention::FaceTexcoord,
        [163, 163, 163, 255],
    );
    let (a, b) = (d.path().join("obj.voxlod"), d.path().join("ply.voxlod"));
    build(&obj, &a, &["-r", "256"]);
    // the texture lies outside the PLY's folder: allowed explicitly
    let allow = dir.join("ycb-banana-textured");
    let s = build(
        &ply,
        &b,
        &["-r", "256", "--allow-path", allow.to_str().unwrap()],
    );
    assert!(warnings(&s).is_empty(), "{:?}", warnings(&s));
    let (va, vb) = (level0_voxels(&a), level0_voxels(&b));
    assert!(va.len() > 10_000, "{}", va.len());
    assert!(
        va == vb,
        "the PLY build's voxels differ from the OBJ build's"
    );
}

/// The shared Munich city (`uchar material` per face, names in header comments): the build has
/// the material channel with the five names, every leaf voxel one of them.
#[test]
fn munich_gets_the_material_channel() {
    let Some(dir) = shared_meshes("munich_gets_the_material_channel") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("m.voxlod");
    let s = build(
        &dir.join("sionna-rt-munich/munich_merged.ply"),
        &out,
        &["-r", "512"],
    );
    assert!(warnings(&s).is_empty(), "{:?}", warnings(&s));
    let r = Reader::open(&out).unwrap();
    assert!(r.has_materials());
    assert_eq!(
        r.manifest().unwrap()["materials"],
        serde_json::json!(["", "marble", "metal", "brick", "wood", "concrete"])
    );
    let mut seen = HashSet::new();
    for i in r.level_nodes(0).collect::<Vec<_>>() {
        seen.extend(r.read_materials(i).unwrap().unwrap());
    }
    let mut seen: Vec<u32> = seen.into_iter().collect();
    seen.sort();
    assert_eq!(seen, [1, 2, 3, 4, 5]);
}

/// The gradient-textured quad as GLB (an embedded image in a buffer view) and as `.gltf` (the
/// PNG beside it): the OBJ build's voxels and colours, byte for byte; the manifest says +Y up.
#[test]
fn textured_quad_as_gltf_equals_obj() {
    use voxlod_testkit::gltf::{write, Image, Mat, Node, Prim};
    let d = tempfile::tempdir().unwrap();
    let obj = checker_obj(d.path(), "grad.png");
    gradient_png(&d.path().join("grad.png"));
    let want = {
        let out = d.path().join("obj.voxlod");
        build(&obj, &out, &["-r", "256"]);
        level0_voxels(&out)
    };
    let quad = Prim::textured_quad();
    let png = std::fs::read(d.path().join("grad.png")).unwrap();
    for (name, img) in [
        ("q.glb", Image::View(png)),
        ("q.gltf", Image::Uri("grad.png".into())),
    ] {
        let mat = Mat {
            name: "checker".into(),
            base_color: [1.0; 4],
            texture: Some(img),
            wrap: [10497; 2],
        };
        let p = d.path().join(name);
        let node = Node {
            mesh: Some(0),
            ..Node::default()
        };
        write(&p, &[vec![quad.clone()]], &[node], &[0], &[mat]);
        let out = d.path().join(format!("{name}.voxlod"));
        let s = build(&p, &out, &["-r", "256"]);
        assert!(warnings(&s).is_empty(), "{name}: {:?}", warnings(&s));
        assert!(
            level0_voxels(&out) == want,
            "{name}: voxels differ from the OBJ build"
        );
        let r = Reader::open(&out).unwrap();
        assert_eq!(
            r.manifest().unwrap()["input"]["up"],
            serde_json::json!([0.0, 1.0, 0.0])
        );
    }
}

/// The shared bunny written as GLB by the test kit: the same voxels as the PLY build (colours
/// and normals aside: the same positions and triangles).
#[test]
fn bunny_glb_has_the_voxels_of_the_ply() {
    use voxlod_testkit::gltf::{write, Node, Prim};
    let Some(dir) = shared_meshes("bunny_glb_has_the_voxels_of_the_ply") else {
        return;
    };
    let ply = dir.join("stanford-bunny/bun_zipper.ply");
    let (v, f) = voxlod_testkit::mesh::read_ply(&ply);
    let d = tempfile::tempdir().unwrap();
    let glb = d.path().join("bunny.glb");
    let prim = Prim {
        positions: v.iter().map(|p| p.map(|x| x as f32)).collect(),
        indices: Some(f.iter().flatten().copied().collect()),
        mode: 4,
        ..Prim::default()
    };
    write(
        &glb,
        &[vec![prim]],
        &[Node {
            mesh: Some(0),
            ..Node::default()
        }],
        &[0],
        &[],
    );
    let (a, b) = (d.path().join("ply.voxlod"), d.path().join("glb.voxlod"));
    build(&ply, &a, &["-r", "512"]);
    build(&glb, &b, &["-r", "512"]);
    let pos = |p: &Path| {
        level0_voxels(p)
            .into_iter()
            .map(|v| (v.0, v.1))
            .collect::<Vec<_>>()
    };
    let (pa, pb) = (pos(&a), pos(&b));
    assert!(pa.len() > 100_000, "{}", pa.len());
    assert!(
        pa == pb,
        "the GLB build's voxel set differs from the PLY build's"
    );
}

/// A 512² plane of 64×64 quads of 8×8 voxels in z = 0.5 (the grid fitted to it: 4 leaf
/// chunks at `-r 512`), each quad mapped to an 8×8-texel patch at a pseudo-random place of one
/// of four 2048² textures (one texel per voxel: every lookup reads level 0 or 1, all over the
/// textures), so a cache smaller than the textures keeps evicting and reading tiles.
fn patchwork_obj(dir: &Path) -> PathBuf {
    let n = 2048u32;
    let mut mtl = String::new();
    for t in 0..4u32 {
        let name = format!("tex{t}.png");
        // smooth gradients with a fine pattern: distinct texels, mips that differ, quick PNGs
        let px = move |x: u32, y: u32| {
            [
                ((x * (t + 1)) >> 3) as u8 ^ ((x ^ y) & 7) as u8,
                ((y * (3 - t + 1)) >> 3) as u8,
                ((x + y + 64 * t) >> 4) as u8 ^ (((x * y) >> 5) & 15) as u8,
                255 - ((x ^ y) >> 6) as u8 * t as u8,
            ]
        };
        if t == 2 {
            image::RgbaImage::from_fn(n, n, |x, y| image::Rgba(px(x, y)))
                .save(dir.join(&name))
                .unwrap();
        } else {
            image::RgbImage::from_fn(n, n, |x, y| {
                let p = px(x, y);
                image::Rgb([p[0], p[1], p[2]])
            })
            .save(dir.join(&name))
            .unwrap();
        }
        mtl += &format!("newmtl m{t}\nKd 1 1 1\nmap_Kd {name}\n");
    }
    std::fs::write(dir.join("patch.mtl"), mtl).unwrap();
    let mut obj = String::from("mtllib patch.mtl\n");
    let mut s = 12345u64;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 33) as u32
    };
    let mut faces = [String::new(), String::new(), String::new(), String::new()];
    let mut k = 1;
    for j in 0..64u32 {
        for i in 0..64u32 {
            let (x, y) = (8 * i, 8 * j);
            let (u, v) = ((next() % (n - 8)) as f32, (next() % (n - 8)) as f32);
            let f = n as f32;
            for (dx, dy) in [(0, 0), (8, 0), (8, 8), (0, 8)] {
                obj += &format!("v {} {} 0.5\n", x + dx, y + dy);
                obj += &format!("vt {} {}\n", (u + dx as f32) / f, (v + dy as f32) / f);
            }
            faces[((i + j) % 4) as usize] += &format!(
                "f {k}/{k} {}/{} {}/{} {}/{}\n",
                k + 1,
                k + 1,
                k + 2,
                k + 2,
                k + 3,
                k + 3
            );
            k += 4;
        }
    }
    for (t, f) in faces.iter().enumerate() {
        obj += &format!("usemtl m{t}\n{f}");
    }
    let path = dir.join("patch.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

/// Decoded textures of 85 MiB, over five times the 16 MiB the plan leaves them under
/// `--memory 464MiB` with two voxelizers: read by tile through a cache whose peak stays within
/// its share, and the same file, byte for byte, as a build holding them whole; an interrupted
/// build's tile file is reused on resume.
#[test]
fn textures_over_their_memory_share_give_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    let obj = patchwork_obj(d.path());
    let whole = d.path().join("whole.voxlod");
    let s = build(&obj, &whole, &["-r", "512", "-j", "2", "--memory", "2GiB"]);
    assert!(warnings(&s).is_empty(), "{:?}", warnings(&s));
    assert!(s["texture_cache"].is_null(), "{}", s["texture_cache"]);
    let decoded = s["memory_plan"]["textures"].as_u64().unwrap();
    assert_eq!(decoded, 4 * 22_369_620, "four 2048² pyramids");

    let out = d.path().join("tiled.voxlod");
    let small = ["-r", "512", "-j", "2", "--memory", "464MiB"];
    let check = |s: &serde_json::Value, reused: bool| {
        assert!(warnings(s).is_empty(), "{:?}", warnings(s));
        let share = s["memory_plan"]["textures"].as_u64().unwrap();
        assert_eq!(share, 16 << 20, "{}", s["memory_plan"]);
        assert_eq!(s["memory_plan"]["voxelizers"], 2);
        let c = &s["texture_cache"];
        assert_eq!(c["decoded_bytes"].as_u64().unwrap(), decoded);
        assert!(decoded >= 4 * share);
        assert_eq!(c["capacity"].as_u64().unwrap(), share);
        let peak = c["peak_resident"].as_u64().unwrap();
        assert!(peak > 0 && peak <= share, "{c}");
        // more tiles read than the cache holds: it evicted and read again
        assert!(c["tile_reads"].as_u64().unwrap() * 16384 > share, "{c}");
        assert_eq!(c["reused"], reused, "{c}");
        assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&whole).unwrap());
    };
    check(&build(&obj, &out, &small), false);

    // interrupted after one of the four chunks: the tile file stays in the work folder, and
    // the resumed build reuses it
    let o = Command::new(BIN)
        .arg("build")
        .arg(&obj)
        .arg("-o")
        .arg(&out)
        .args(["-q", "--force", "--debug-interrupt-after-chunks", "1"])
        .args(small)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("interrupted"), "{err}");
    let work = voxlod_pipeline::find_work_folders(d.path()).unwrap();
    assert_eq!(work.len(), 1, "one work folder kept");
    let tiles = work[0].path.join("textures.tiles");
    assert!(tiles.is_file(), "{}", tiles.display());
    check(
        &build(&obj, &out, &[&small[..], &["--force"]].concat()),
        true,
    );
    // (a corrupt or truncated tile file is rebuilt: crates/texture/tests/tile_cache.rs)
}

/// An 8×8 PNG of four 4×4 quadrants: red top left, green top right, blue bottom left, white
/// bottom right (top = the image's first row).
fn quadrants_png(path: &Path) {
    image::RgbImage::from_fn(8, 8, |x, y| {
        image::Rgb(match (x < 4, y < 4) {
            (true, true) => [255, 0, 0],
            (false, true) => [0, 255, 0],
            (true, false) => [0, 0, 255],
            (false, false) => [255, 255, 255],
        })
    })
    .save(path)
    .unwrap();
}

/// Every level-0 voxel of `out` is red: the texture's top-left quadrant, nothing else.
fn all_red(out: &Path, what: &str) {
    let c = level0_colors(out);
    assert!(c.len() > 10_000, "{what}: {} voxels", c.len());
    let other: HashSet<[u8; 4]> = c
        .iter()
        .copied()
        .filter(|&c| c != [255, 0, 0, 255])
        .collect();
    assert!(
        other.is_empty(),
        "{what}: the quad addressing the top-left (red) quadrant has voxels of {other:?}"
    );
}

/// Each format's texture coordinate convention, with a texture no flip leaves unchanged: a quad
/// whose coordinates address the inside of the top-left (red) quadrant comes out red. OBJ
/// (`vt`) and PLY (`s t`, as MeshLab writes them from OBJ) put `v = 0` at the image's last
/// row, glTF at its first.
#[test]
fn each_format_reads_its_own_v_convention() {
    use voxlod_testkit::gltf::{write, Image, Mat, Node, Prim};
    use voxlod_testkit::textured::{obj_to_textured_ply, Convention};
    let d = tempfile::tempdir().unwrap();
    quadrants_png(&d.path().join("q.png"));
    std::fs::write(
        d.path().join("q.mtl"),
        "newmtl m\nKd 1 1 1\nmap_Kd -clamp on q.png\n",
    )
    .unwrap();
    // OBJ: u 0.1–0.4, v 0.6–0.9 (v up): inside the top-left quadrant
    let obj = d.path().join("q.obj");
    std::fs::write(
        &obj,
        "mtllib q.mtl\nv 0 0 0.5\nv 256 0 0.5\nv 256 256 0.5\nv 0 256 0.5\n\
         vt 0.1 0.6\nvt 0.4 0.6\nvt 0.4 0.9\nvt 0.1 0.9\nusemtl m\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    let out = d.path().join("obj.voxlod");
    build(&obj, &out, &["-r", "256"]);
    all_red(&out, "OBJ");
    let ply = d.path().join("q.ply");
    obj_to_textured_ply(&obj, &ply, "q.png", Convention::VertexST, [255; 4]);
    let out = d.path().join("ply.voxlod");
    build(&ply, &out, &["-r", "256"]);
    all_red(&out, "PLY");
    // glTF: the same quadrant is v 0.1–0.4 (v down)
    let quad = Prim {
        uv: Some(vec![[0.1, 0.4], [0.4, 0.4], [0.4, 0.1], [0.1, 0.1]]),
        ..Prim::textured_quad()
    };
    let mat = Mat {
        name: "m".into(),
        base_color: [1.0; 4],
        texture: Some(Image::Uri("q.png".into())),
        wrap: [33071; 2],
    };
    let node = Node {
        mesh: Some(0),
        ..Node::default()
    };
    for name in ["q.gltf", "q.glb"] {
        let p = d.path().join(name);
        write(
            &p,
            &[vec![quad.clone()]],
            std::slice::from_ref(&node),
            &[0],
            std::slice::from_ref(&mat),
        );
        let out = d.path().join(format!("{name}.voxlod"));
        let s = build(&p, &out, &["-r", "256"]);
        assert!(warnings(&s).is_empty(), "{name}: {:?}", warnings(&s));
        all_red(&out, name);
    }
}

/// `KHR_texture_transform` (offset, rotation, scale and its `texCoord`) is applied: the quad's
/// coordinates 0–1 mapped by a rotation of π, a scale of 0.3 and an offset of 0.4 land in glTF's
/// 0.1–0.4 square, the red quadrant; the extension's `texCoord` 0 replaces the texture's set 1
/// (which the primitive does not have).
#[test]
fn khr_texture_transform_is_applied() {
    use voxlod_testkit::gltf::{write, Image, Mat, Node, Prim};
    let d = tempfile::tempdir().unwrap();
    quadrants_png(&d.path().join("q.png"));
    let mat = Mat {
        name: "m".into(),
        base_color: [1.0; 4],
        texture: Some(Image::Uri("q.png".into())),
        wrap: [33071; 2],
    };
    let node = Node {
        mesh: Some(0),
        ..Node::default()
    };
    let p = d.path().join("t.gltf");
    write(&p, &[vec![Prim::textured_quad()]], &[node], &[0], &[mat]);
    let json = std::fs::read_to_string(&p).unwrap();
    let with = json
        .replace(
            r#""baseColorTexture":{"index":0}"#,
            r#""baseColorTexture":{"index":0,"texCoord":1,"extensions":{"KHR_texture_transform":{"offset":[0.4,0.4],"rotation":3.141592653589793,"scale":[0.3,0.3],"texCoord":0}}}"#,
        )
        .replacen('{', r#"{"extensionsUsed":["KHR_texture_transform"],"#, 1);
    assert_ne!(with, json);
    std::fs::write(&p, with).unwrap();
    let out = d.path().join("t.voxlod");
    let s = build(&p, &out, &["-r", "256"]);
    assert!(warnings(&s).is_empty(), "{:?}", warnings(&s));
    all_red(&out, "KHR_texture_transform");
}

/// A glTF made from the YCB banana's OBJ by an independent converter (Cesium's
/// `obj2gltf`, installed by `.ci/run` into `tests/converters/`) voxelizes as the OBJ does: the
/// same voxels, colours within 2 units. obj2gltf writes `baseColorFactor` 1 when a material has
/// a texture (it ignores `Kd` then), where an OBJ's texture multiplies `Kd` (0.639 in the
/// banana's MTL), so both are built from a copy whose MTL says `Kd 1 1 1`. A v convention read
/// the wrong way round (glTF's v = 0 is the image's first row, OBJ's its last) moves every
/// colour (the banana's texture is not symmetric).
#[test]
fn gltf_from_an_independent_converter_matches_its_obj() {
    let Some(dir) = shared_meshes("gltf_from_an_independent_converter_matches_its_obj") else {
        return;
    };
    let tool = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/converters/node_modules/obj2gltf/bin/obj2gltf.js");
    if !tool.is_file() {
        let why = format!(
            "{} is missing (npm ci --prefix tests/converters installs it)",
            tool.display()
        );
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{why}; CI=true requires it"
        );
        voxlod_testkit::skipped(
            "textures::gltf_from_an_independent_converter_matches_its_obj",
            &why,
        );
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let src = dir.join("ycb-banana-textured");
    for f in ["textured_simple_reoriented.obj", "texture_map.png"] {
        std::fs::copy(src.join(f), d.path().join(f)).unwrap();
    }
    let mtl = std::fs::read_to_string(src.join("textured_simple_reoriented.mtl")).unwrap();
    assert!(mtl.contains("Kd 0.639216"), "{mtl}");
    let mtl: String = mtl
        .lines()
        .map(|l| {
            if l.starts_with("Kd ") {
                "Kd 1.000000 1.000000 1.000000"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(d.path().join("textured_simple_reoriented.mtl"), mtl).unwrap();
    let obj = d.path().join("textured_simple_reoriented.obj");
    let glb = d.path().join("banana.glb");
    let o = Command::new("node")
        .arg(&tool)
        .arg("-i")
        .arg(&obj)
        .arg("-o")
        .arg(&glb)
        .output()
        .expect("running node");
    assert!(
        o.status.success() && glb.is_file(),
        "obj2gltf failed: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let (a, b) = (d.path().join("obj.voxlod"), d.path().join("glb.voxlod"));
    for r in ["256", "512"] {
        assert!(warnings(&build(&obj, &a, &["-r", r, "--backend", "cpu"])).is_empty());
        assert!(warnings(&build(&glb, &b, &["-r", r, "--backend", "cpu"])).is_empty());
        let (va, vb) = (level0_voxels(&a), level0_voxels(&b));
        assert!(va.len() > 10_000, "{}", va.len());
        assert_eq!(va.len(), vb.len(), "@{r}: voxel counts");
        let mut worst = 0;
        for (x, y) in va.iter().zip(&vb) {
            assert_eq!((x.0, x.1), (y.0, y.1), "@{r}: the voxels differ");
            for c in 0..4 {
                worst = worst.max(x.2[c].abs_diff(y.2[c]));
            }
        }
        assert!(worst <= 2, "@{r}: a colour differs by {worst}");
    }
}
