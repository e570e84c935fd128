//! The stored attributes of source triangles as `render` draws them: a made-up PLY
//! of two triangles with vertex normals that are not their face normal, a distinct vertex
//! colour per triangle and a per-face material, built with `--source-geometry` at 256³ (one
//! leaf, which a close-up puts over the pixel error). Pixels inside each triangle are compared
//! with the colour computed here from the input mesh and the shading rule `source.wgsl`
//! documents (ambient 0.22 plus 0.78 diffuse from the light fixed to the camera): with the
//! vertex colours (`ColorBy::Voxel`) and with the material hues (`ColorBy::Material`). The
//! face normal would give other colours, so the stored normals are what is drawn. No adapter
//! is a FAILURE, not a skip.

use std::path::Path;

use glam::DVec3;
use voxlod_format::Reader;
use voxlod_pipeline::BuildSettings;
use voxlod_render::{frame, material_color, over_leaves, ColorBy, Lod, Renderer, Shot, View};
use voxlod_voxelize::Mode;

/// One triangle of the made-up mesh: corners (in z = 0), vertex normal, colour, material value.
struct Tri {
    corners: [[f32; 3]; 3],
    normal: [f32; 3],
    rgb: [u8; 3],
    material: i32,
    /// A point well inside it.
    inside: [f64; 3],
}

fn mesh() -> [Tri; 2] {
    [
        Tri {
            corners: [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0]],
            normal: [0.5, 0.3, 0.8],
            rgb: [210, 60, 40],
            material: 7,
            inside: [0.25, -0.25, 0.0],
        },
        Tri {
            corners: [[-1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],
            normal: [-0.4, 0.55, 0.75],
            rgb: [50, 190, 90],
            material: 3,
            inside: [-0.25, 0.25, 0.0],
        },
    ]
}

/// Binary PLY: vertices with normals and colours (three per triangle, none shared), faces with
/// an `int material` named in header comments.
fn write_ply(path: &Path, tris: &[Tri]) {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment material 3 = paint\ncomment material 7 = metal\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face {}\nproperty list uchar int vertex_indices\nproperty int material\nend_header\n",
        3 * tris.len(),
        tris.len()
    )
    .into_bytes();
    for t in tris {
        for c in t.corners {
            for x in c.iter().chain(&t.normal) {
                out.extend_from_slice(&x.to_le_bytes());
            }
            out.extend_from_slice(&t.rgb);
        }
    }
    for (k, t) in tris.iter().enumerate() {
        out.push(3);
        for v in 0..3 {
            out.extend_from_slice(&(3 * k as i32 + v).to_le_bytes());
        }
        out.extend_from_slice(&t.material.to_le_bytes());
    }
    std::fs::write(path, out).unwrap();
}

/// The light of a shot: from the upper left behind the eye, fixed to the camera.
fn light(shot: &Shot) -> DVec3 {
    let fwd = (shot.target - shot.eye).normalize();
    let right = fwd.cross(shot.up).normalize();
    (-fwd * 0.8 + shot.up * 0.7 - right * 0.45).normalize()
}

/// `rgb` lit with unit normal `n`.
fn shaded(rgb: [u8; 3], n: DVec3, light: DVec3) -> [f64; 3] {
    let shade = 0.22 + 0.78 * n.dot(light).max(0.0);
    rgb.map(|c| c as f64 * shade)
}

#[test]
fn stored_normals_colours_and_materials_are_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("two.ply");
    let tris = mesh();
    write_ply(&ply, &tris);
    let file = dir.path().join("two.voxlod");
    let s = BuildSettings {
        resolution: 256,
        mode: Mode::Thin,
        source_geometry: true,
        progress: false,
        ..Default::default()
    };
    voxlod_pipeline::build(&ply, &file, &s).unwrap();
    let r = Reader::open(&file).unwrap();
    assert!(r.has_source_triangles() && r.has_materials());
    let leaf = r.root().unwrap();
    let stored = r.source_triangles(leaf).unwrap().unwrap();
    assert!(stored.normals.is_some() && stored.colors.is_some());
    // material ids: 1 + the rank of the face's value among the mesh's values (3, 7)
    let ids = [2u32, 1];
    let got: Vec<u32> = stored
        .materials
        .clone()
        .unwrap()
        .iter()
        .map(|&m| m as u32)
        .collect();
    assert_eq!(got, ids);

    let renderer = match Renderer::new() {
        Ok(x) => x,
        Err(e) => panic!("no GPU adapter: the render test needs one (lavapipe: apt-get install mesa-vulkan-drivers libvulkan1): {e}"),
    };
    let view = View {
        width: 200,
        height: 150,
        direction: [0.2, -0.3, 1.0],
        zoom: 3.0,
        ..View::default()
    };
    let lod = Lod::Error(1.0);
    let (shot, nodes) = frame(&r, &view, lod).unwrap();
    let source = over_leaves(&r, &shot, lod);
    assert_eq!(
        source,
        vec![leaf],
        "the close-up puts the one leaf over the error"
    );
    let l = light(&shot);
    for (color, rgb_of) in [
        (
            ColorBy::Voxel,
            &(|t: &Tri, _| t.rgb) as &dyn Fn(&Tri, u32) -> [u8; 3],
        ),
        (ColorBy::Material, &|_: &Tri, id: u32| {
            let c = material_color(id);
            [c[0], c[1], c[2]]
        }),
    ] {
        let pic = renderer
            .render_with_source(&r, &nodes, &source, &shot, color)
            .unwrap();
        assert_eq!((pic.source_leaves, pic.source_triangles), (1, 2));
        for (t, &id) in tris.iter().zip(&ids) {
            let p = shot.project(t.inside).unwrap();
            let (x, y) = (p[0] as usize, p[1] as usize);
            let at = 4 * (y * pic.width as usize + x);
            let px = &pic.rgba[at..at + 4];
            let n = DVec3::from(t.normal.map(|v| v as f64)).normalize();
            let want = shaded(rgb_of(t, id), n, l);
            let flat = shaded(rgb_of(t, id), DVec3::Z, l);
            eprintln!(
                "{color:?} {:?}: pixel {px:?}, stored normal {want:?}, face normal {flat:?}",
                t.rgb
            );
            assert_eq!(px[3], 255, "pixel ({x}, {y}) not covered");
            for k in 0..3 {
                assert!(
                    (px[k] as f64 - want[k]).abs() <= 2.0,
                    "{color:?}: pixel {px:?} at ({x}, {y}), want {want:?}"
                );
            }
            // the face normal would be told apart
            assert!(
                (0..3).any(|k| (flat[k] - want[k]).abs() > 8.0),
                "{flat:?} {want:?}"
            );
        }
    }
}
