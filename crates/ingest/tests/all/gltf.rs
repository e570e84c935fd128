//! glTF 2.0 input (docs/INGEST.md "glTF"), on files written by the test kit's own writer
//! (`voxlod_testkit::gltf`): a textured quad against the same quad as OBJ (the same triangles,
//! texture coordinates, colours and material table), nested node transforms against positions
//! transformed by the test (TRS and matrix, a mirroring one flipping the winding back), strips
//! and fans, `COLOR_0` times `baseColorFactor`, embedded images, the shared bunny as GLB against
//! its PLY, and truncated or damaged files giving errors that name the file.

use crate::common;
use common::{read, TempDir};
use voxlod_geom::{Triangle, Wrap, TRI_HAS_UV};
use voxlod_ingest::MeshSource;
use voxlod_testkit::gltf::{write, Image, Mat, Node, Prim};

fn quad() -> Prim {
    Prim::textured_quad()
}

fn mat(texture: Option<Image>) -> Mat {
    Mat {
        name: "checker".into(),
        base_color: [1.0; 4],
        texture,
        wrap: [33071, 33648],
    }
}

fn one_node() -> Vec<Node> {
    vec![Node {
        mesh: Some(0),
        ..Node::default()
    }]
}

#[test]
fn textured_quad_equals_the_obj_quad() {
    let d = TempDir::new("gltfquad");
    std::fs::write(d.path("Checker.png"), b"not decoded by ingest").unwrap();
    std::fs::write(
        d.path("q.mtl"),
        "newmtl checker\nKd 1 1 1\nmap_Kd Checker.png\n",
    )
    .unwrap();
    let obj = d.write(
        "q.obj",
        "mtllib q.mtl\nv 0 0 0.5\nv 256 0 0.5\nv 256 256 0.5\nv 0 256 0.5\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl checker\nf 1/1 2/2 3/3 4/4\n",
    );
    let (want, _) = read(&obj).unwrap();
    for name in ["q.gltf", "q.glb"] {
        let p = d.path(name);
        write(
            &p,
            &[vec![quad()]],
            &one_node(),
            &[0],
            &[mat(Some(Image::Uri("Checker.png".into())))],
        );
        let src = MeshSource::open(&p).unwrap();
        let info = src.info();
        assert_eq!(
            info.format,
            if name.ends_with("glb") { "glb" } else { "gltf" }
        );
        assert!(info.warnings.is_empty(), "{:?}", info.warnings);
        assert_eq!(info.up, Some([0.0, 1.0, 0.0]));
        assert!(info.has_texcoords);
        assert_eq!(info.materials.len(), 2);
        assert_eq!(info.materials[1].name, "checker");
        assert_eq!(info.materials[1].texture, Some(d.path("Checker.png")));
        assert_eq!(info.materials[1].wrap, [Wrap::Clamp, Wrap::Mirror]);
        let (got, st) = read(&p).unwrap();
        assert_eq!(st.triangles, 2);
        // the OBJ reader's triangles, but for the flags (glTF has no normals here either)
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(
                (g.v, g.uv, g.c, g.material()),
                (w.v, w.uv, w.c, w.material()),
                "{name}"
            );
            assert!(g.flags & TRI_HAS_UV != 0);
        }
    }
}

/// Column-major 4×4 product and the matrix of a TRS (unit quaternion x, y, z, w), in f64.
fn mul(a: &[f64; 16], b: &[f64; 16]) -> [f64; 16] {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[4 * c + r] = (0..4).map(|k| a[4 * k + r] * b[4 * c + k]).sum();
        }
    }
    m
}

fn trs(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> [f64; 16] {
    let [x, y, z, w] = q;
    let r = [
        [
            1. - 2. * (y * y + z * z),
            2. * (x * y + z * w),
            2. * (x * z - y * w),
        ],
        [
            2. * (x * y - z * w),
            1. - 2. * (x * x + z * z),
            2. * (y * z + x * w),
        ],
        [
            2. * (x * z + y * w),
            2. * (y * z - x * w),
            1. - 2. * (x * x + y * y),
        ],
    ];
    let mut m = [0.0; 16];
    for c in 0..3 {
        for k in 0..3 {
            m[4 * c + k] = r[c][k] * s[c];
        }
    }
    m[12..15].copy_from_slice(&t);
    m[15] = 1.0;
    m
}

#[test]
fn nested_transforms_strips_fans_and_colours() {
    let d = TempDir::new("gltfnodes");
    let tri = vec![[0.0f32, 0., 0.], [1., 0., 0.], [0., 2., 0.]];
    let h = 0.5f32.sqrt();
    let (t, q, s) = ([1.0f32, 2., 3.], [0.0f32, 0., h, h], [2.0f32, 2., 2.]);
    // the child: translate by (10, 0, 0) and mirror x (determinant < 0)
    let child: [f32; 16] = [
        -1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 10., 0., 0., 1.,
    ];
    let meshes = vec![
        vec![Prim {
            positions: tri.clone(),
            colors: Some(vec![[0.5, 1.0, 0.0, 1.0]; 3]),
            mode: 4,
            material: Some(0),
            ..Prim::default()
        }],
        // a strip of 4 and a fan of 4 vertices: two triangles each
        vec![
            Prim {
                positions: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]],
                mode: 5,
                ..Prim::default()
            },
            Prim {
                positions: vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
                mode: 6,
                ..Prim::default()
            },
            Prim {
                positions: vec![[0., 0., 0.]],
                mode: 0,
                ..Prim::default()
            },
        ],
    ];
    let nodes = vec![
        Node {
            mesh: Some(0),
            translation: Some(t),
            rotation: Some(q),
            scale: Some(s),
            children: vec![1],
            ..Node::default()
        },
        Node {
            mesh: Some(0),
            matrix: Some(child),
            ..Node::default()
        },
        Node {
            mesh: Some(1),
            ..Node::default()
        },
    ];
    let mats = [Mat {
        name: "tinted".into(),
        base_color: [1.0, 0.5, 1.0, 0.5],
        texture: None,
        wrap: [10497; 2],
    }];
    let p = d.path("n.glb");
    write(&p, &meshes, &nodes, &[0, 2], &mats);
    let src = MeshSource::open(&p).unwrap();
    let w = &src.info().warnings;
    assert!(
        // the build prefixes the input's name; the warning itself does not repeat it
        w.len() == 1 && w[0].contains("points or lines") && !w[0].contains("n.glb"),
        "{w:?}"
    );
    let (got, _) = read(&p).unwrap();
    assert_eq!(got.len(), 6);
    let f64s = |a: [f32; 4]| a.map(f64::from);
    let parent = trs(t.map(f64::from), f64s(q), s.map(f64::from));
    let world = [parent, mul(&parent, &child.map(f64::from))];
    for (k, m) in world.iter().enumerate() {
        let want: Vec<[f64; 3]> = tri
            .iter()
            .map(|v| {
                [0, 1, 2]
                    .map(|r| (0..3).map(|c| m[4 * c + r] * v[c] as f64).sum::<f64>() + m[12 + r])
            })
            .collect();
        // the mirrored node's triangle has corners 1 and 2 swapped (winding kept outward)
        let order = if k == 1 { [0, 2, 1] } else { [0, 1, 2] };
        for (j, &o) in order.iter().enumerate() {
            for a in 0..3 {
                assert!(
                    (got[k].v[j][a] as f64 - want[o][a]).abs() < 1e-5,
                    "node {k} corner {j}: {:?} {:?}",
                    got[k].v,
                    want
                );
            }
        }
        // COLOR_0 (0.5, 1, 0, 1) × factor (1, 0.5, 1, 0.5), linear, stored sRGB: 0.5 → 188
        assert_eq!(got[k].c[0], [188, 188, 0, 128]);
    }
    let v = |t: &Triangle| t.v.map(|p| [p[0], p[1]]);
    // strip (0 1 2), (1 3 2) in glTF order (2 1 3)→ corners v1, v3, v2; fan (1 2 0), (2 3 0)
    assert_eq!(v(&got[2]), [[0., 0.], [1., 0.], [0., 1.]]);
    assert_eq!(v(&got[3]), [[1., 0.], [1., 1.], [0., 1.]]);
    assert_eq!(v(&got[4]), [[1., 0.], [1., 1.], [0., 0.]]);
    assert_eq!(v(&got[5]), [[1., 1.], [0., 1.], [0., 0.]]);
}

#[test]
fn embedded_images() {
    let d = TempDir::new("gltfimg");
    for (name, img) in [
        ("data.gltf", Image::DataUri(b"\x89PNG fake".to_vec())),
        ("view.glb", Image::View(b"\x89PNG fake".to_vec())),
    ] {
        let p = d.path(name);
        write(&p, &[vec![quad()]], &one_node(), &[0], &[mat(Some(img))]);
        let src = MeshSource::open(&p).unwrap();
        let m = &src.info().materials[1];
        assert_eq!(
            m.embedded.as_ref().map(|e| e.0.to_vec()),
            Some(b"\x89PNG fake".to_vec()),
            "{name}"
        );
        assert_eq!(
            m.texture,
            Some(std::path::PathBuf::from(format!("{}#image 0", p.display())))
        );
    }
    // a missing image file: a warning naming it, the factor used
    let p = d.path("missing.gltf");
    write(
        &p,
        &[vec![quad()]],
        &one_node(),
        &[0],
        &[mat(Some(Image::Uri("gone.png".into())))],
    );
    let src = MeshSource::open(&p).unwrap();
    let w = &src.info().warnings;
    assert!(
        w.len() == 1 && w[0].contains("gone.png") && !w[0].contains("missing.gltf"),
        "{w:?}"
    );
    assert!(!src.info().has_texcoords);
    // a textured material on a primitive without TEXCOORD_0: a warning, the factor used
    let mut q = quad();
    q.uv = None;
    let p = d.path("nouv.glb");
    std::fs::write(d.path("t.png"), b"x").unwrap();
    write(
        &p,
        &[vec![q]],
        &one_node(),
        &[0],
        &[mat(Some(Image::Uri("t.png".into())))],
    );
    let src = MeshSource::open(&p).unwrap();
    let w = &src.info().warnings;
    assert!(
        w.len() == 1 && w[0].contains("texture coordinate set") && !w[0].contains("nouv.glb"),
        "{w:?}"
    );
    assert!(!src.info().has_texcoords && src.info().materials.is_empty());
}

#[test]
fn bunny_glb_equals_its_ply() {
    let Some(ply) = voxlod_testkit::shared_mesh(module_path!(), "stanford-bunny/bun_zipper.ply")
    else {
        return;
    };
    let (v, f) = voxlod_testkit::mesh::read_ply(&ply);
    let d = TempDir::new("gltfbunny");
    let p = d.path("bunny.glb");
    let prim = Prim {
        positions: v.iter().map(|p| p.map(|x| x as f32)).collect(),
        indices: Some(f.iter().flatten().copied().collect()),
        mode: 4,
        ..Prim::default()
    };
    write(&p, &[vec![prim]], &one_node(), &[0], &[]);
    let (want, _) = read(&ply).unwrap();
    let (got, st) = read(&p).unwrap();
    assert_eq!(st.polygons, f.len() as u64);
    let pos = |t: &[Triangle]| t.iter().map(|t| t.v).collect::<Vec<_>>();
    assert!(pos(&got) == pos(&want), "positions differ");
}

#[test]
fn damaged_files_are_errors_naming_the_file() {
    let d = TempDir::new("gltfbad");
    let p = d.path("q.glb");
    write(&p, &[vec![quad()]], &one_node(), &[0], &[mat(None)]);
    let good = std::fs::read(&p).unwrap();
    // truncated anywhere: an error (never a panic), naming the file
    for cut in (0..good.len()).step_by(7) {
        let b = d.write("cut.glb", &good[..cut]);
        match read(&b) {
            Ok(_) => panic!("cut at {cut} read fine"),
            Err(e) => assert!(e.to_string().contains("cut.glb"), "{e}"),
        }
    }
    // bytes changed: an error naming the file, or triangles, but no panic
    let mut s = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..300 {
        let mut b = good.clone();
        for _ in 0..3 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let i = (s % b.len() as u64) as usize;
            b[i] = (s >> 32) as u8;
        }
        let f = d.write("fuzz.glb", &b);
        if let Err(e) = read(&f) {
            assert!(e.to_string().contains("fuzz.glb"), "{e}");
        }
    }
    // an index past the vertices
    let mut q = quad();
    q.indices = Some(vec![0, 1, 9]);
    let p = d.path("ix.gltf");
    write(&p, &[vec![q]], &one_node(), &[0], &[mat(None)]);
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("ix.gltf") && e.contains("index 9"), "{e}");
}

/// A glTF whose geometry is compressed (Draco, meshopt) as those tools write it: the error
/// names the extension and suggests decompressing, before any rule the compressed layout
/// breaks on purpose (accessors without data, a fallback buffer without bytes). Before this
/// check the Draco file said "accessors[0].bufferView: Missing data; …" and the meshopt file
/// "buffer 1 has no uri, but it is not the first buffer of a GLB".
#[test]
fn compressed_geometry_names_the_extension_first() {
    let d = TempDir::new("gltfcompressed");
    let data = "data:application/octet-stream;base64,".to_owned() + &"A".repeat(88);
    let head = |ext: &str, required: bool| {
        let req = if required {
            format!(r#""extensionsRequired":["{ext}"],"#)
        } else {
            String::new()
        };
        format!(
            r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["{ext}"],{req}
            "nodes":[{{"mesh":0}}],"scenes":[{{"nodes":[0]}}],"scene":0,"#
        )
    };
    // Draco: the accessors have no bufferView; the primitive's extension holds the data
    let draco = |required| {
        head("KHR_draco_mesh_compression", required)
            + &format!(
                r#""buffers":[{{"byteLength":64,"uri":"{data}"}}],
            "bufferViews":[{{"buffer":0,"byteLength":64}}],
            "accessors":[{{"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}},
                         {{"componentType":5125,"count":3,"type":"SCALAR"}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,
              "extensions":{{"KHR_draco_mesh_compression":{{"bufferView":0,"attributes":{{"POSITION":0}}}}}}}}]}}]}}"#
            )
    };
    // meshopt: views read a fallback buffer that has no bytes, the real data is compressed
    let meshopt = |required| {
        head("EXT_meshopt_compression", required)
            + &format!(
                r#""buffers":[{{"byteLength":64,"uri":"{data}"}},
                {{"byteLength":36,"extensions":{{"EXT_meshopt_compression":{{"fallback":true}}}}}}],
            "bufferViews":[{{"buffer":1,"byteLength":36,"byteStride":12,"extensions":{{"EXT_meshopt_compression":
              {{"buffer":0,"byteLength":64,"byteStride":12,"count":3,"mode":"ATTRIBUTES"}}}}}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}]}}"#
            )
    };
    let p = d.write("draco.gltf", draco(true));
    let e = read(&p).unwrap_err().to_string();
    let at = |s: &str| e.find(s).unwrap_or_else(|| panic!("{s:?} not in: {e}"));
    let ext = "KHR_draco_mesh_compression";
    assert!(
        at("draco.gltf") < at(ext) && at(ext) < at("decompress"),
        "{e}"
    );
    assert!(e.contains("gltf-transform"), "{e}");
    for noise in ["Missing data", "no uri", "accessor", "bufferView"] {
        assert!(!e.contains(noise), "{noise:?} in: {e}");
    }
    // meshopt is decoded (gltf_compressed.rs), required or only used: here its data is
    // zeros, which meshoptimizer's decoder refuses, and the error names the view
    for (name, required) in [("meshopt.gltf", true), ("meshopt-optional.gltf", false)] {
        let p = d.write(name, meshopt(required));
        let e = read(&p).unwrap_err().to_string();
        assert!(
            e.contains(name)
                && e.contains("bufferView 0 (EXT_meshopt_compression)")
                && e.contains("corrupt or truncated"),
            "{e}"
        );
    }
}

/// The textured quad with the base colour texture's `KHR_texture_transform` set to `t` (JSON).
fn transformed_quad(d: &TempDir, name: &str, t: &str) -> std::path::PathBuf {
    let p = d.path(name);
    write(
        &p,
        &[vec![quad()]],
        &one_node(),
        &[0],
        &[mat(Some(Image::DataUri(b"not decoded".to_vec())))],
    );
    let json = std::fs::read_to_string(&p).unwrap();
    let with = json
        .replace(
            r#""baseColorTexture":{"index":0}"#,
            &format!(
                r#""baseColorTexture":{{"index":0,"extensions":{{"KHR_texture_transform":{t}}}}}"#
            ),
        )
        .replacen('{', r#"{"extensionsUsed":["KHR_texture_transform"],"#, 1);
    assert_ne!(with, json);
    std::fs::write(&p, with).unwrap();
    p
}

/// `KHR_texture_transform`'s rotation turns as three.js's GLTFLoader turns it (and as the
/// extension's prose says: counter-clockwise in texture space, whose v runs down the image):
/// `u' = cos·u + sin·v`, `v' = −sin·u + cos·v`, not as the extension's GLSL listing read with
/// GLSL's column-major `mat3` would (docs/INGEST.md says why). Pinned by hand at a quarter
/// turn, then compared with three.js itself (`tests/node/uv-transform.mjs`) at an angle with
/// offset and scale.
#[test]
fn khr_texture_transform_turns_as_three_js() {
    let d = TempDir::new("gltfuvrot");
    // a quarter turn: (u, v) ↦ (v, −u), then v stored as 1 − v
    let p = transformed_quad(&d, "quarter.gltf", r#"{"rotation":1.5707963267948966}"#);
    let (got, _) = read(&p).unwrap();
    let want = |pos: [f32; 3]| -> [f32; 2] {
        // the quad's texture coordinates by corner: (0,1) (1,1) (1,0) (0,0)
        let uv = match (pos[0] > 0.0, pos[1] > 0.0) {
            (false, false) => [0.0, 1.0],
            (true, false) => [1.0, 1.0],
            (true, true) => [1.0, 0.0],
            (false, true) => [0.0, 0.0],
        };
        let turned = [uv[1], -uv[0]];
        [turned[0], 1.0 - turned[1]]
    };
    for t in &got {
        for k in 0..3 {
            let w = want(t.v[k]);
            assert!(
                (t.uv[k][0] - w[0]).abs() < 1e-6 && (t.uv[k][1] - w[1]).abs() < 1e-6,
                "corner {:?}: {:?}, want {w:?}",
                t.v[k],
                t.uv[k]
            );
        }
    }
    // three.js's loader on the same kind of file, at an angle, with offset and scale
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/node");
    let installed = script.join("node_modules/three").is_dir()
        && std::process::Command::new("node")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if !installed {
        assert!(
            !voxlod_testkit::under_ci(),
            "three.js is not installed (node and `npm ci` in tests/node: .ci/run does both)"
        );
        eprintln!("khr_texture_transform_turns_as_three_js: three.js skipped: not installed (run `npm ci` in tests/node)");
        return;
    }
    let p = transformed_quad(
        &d,
        "all.gltf",
        r#"{"rotation":0.3,"offset":[0.25,-0.5],"scale":[2,0.75]}"#,
    );
    let o = std::process::Command::new("node")
        .arg(script.join("uv-transform.mjs"))
        .arg(&p)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let three: Vec<serde_json::Value> = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(three.len(), 4);
    let (got, _) = read(&p).unwrap();
    assert_eq!(got.len(), 2);
    for t in &got {
        for k in 0..3 {
            let v = three
                .iter()
                .find(|x| (0..3).all(|c| x["position"][c].as_f64() == Some(t.v[k][c] as f64)))
                .expect("three.js has the corner");
            let (u, w) = (
                v["uv"][0].as_f64().unwrap(),
                1.0 - v["uv"][1].as_f64().unwrap(),
            );
            assert!(
                (t.uv[k][0] as f64 - u).abs() < 1e-5 && (t.uv[k][1] as f64 - w).abs() < 1e-5,
                "corner {:?}: voxlod {:?}, three.js ({u}, {w})",
                t.v[k],
                t.uv[k]
            );
        }
    }
}
