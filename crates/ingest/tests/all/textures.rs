//! OBJ + MTL textures (docs/TEXTURES.md): the material table, texture coordinates and material
//! indices of the triangles, path resolution (relative to the MTL, case-insensitive fallback,
//! `\` separators, options), and the warnings for what cannot be used; on made-up files and
//! on the textured meshes of `../shared/data/meshes`.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use voxlod_geom::{Triangle, TRI_HAS_UV};
use voxlod_ingest::MeshSource;

fn read(path: &Path) -> (MeshSource, Vec<Triangle>) {
    let src = MeshSource::open(path).unwrap();
    let mut tris = Vec::new();
    src.stream(
        &mut |b| {
            tris.extend_from_slice(b);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    (src, tris)
}

/// Two quads: the first with material `a` (textured), the second with `b`; the third face has
/// material `a` but no `vt` indices.
const OBJ: &str = "mtllib sub/mats.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl a
f 1/1 2/2 3/3 4/4
usemtl b
f 2/1 5/2 6/3 3/4
";

#[test]
fn obj_material_table_uv_and_case_insensitive_paths() {
    let d = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(d.path().join("sub/Tex")).unwrap();
    std::fs::write(d.path().join("sub/Tex/Brick.PNG"), b"not decoded by ingest").unwrap();
    std::fs::write(d.path().join("sub/other.jpg"), b"x").unwrap();
    std::fs::write(
        d.path().join("sub/mats.mtl"),
        "newmtl a\nKd 0.5 0.25 1\nd 0.5\nmap_Kd -s 1 1 1 -clamp on tex\\brick.png\n\
         newmtl b\nKd 1 1 1\nmap_Kd other.jpg\nnewmtl unused\nmap_Kd missing.png\n",
    )
    .unwrap();
    let obj = d.path().join("m.obj");
    std::fs::write(&obj, OBJ).unwrap();
    let (src, tris) = read(&obj);
    let info = src.info();
    assert!(info.has_texcoords && info.has_colors);
    assert!(info.warnings.is_empty(), "{:?}", info.warnings);
    let m = &info.materials;
    assert_eq!(m.len(), 3, "{m:?}");
    assert_eq!(m[0].texture, None);
    assert_eq!(m[1].name, "a");
    assert_eq!(m[1].texture, Some(d.path().join("sub/Tex/Brick.PNG")));
    assert_eq!(m[1].wrap, [voxlod_geom::Wrap::Clamp; 2]);
    assert_eq!(m[2].texture, Some(d.path().join("sub/other.jpg")));
    assert_eq!(m[2].wrap, [voxlod_geom::Wrap::Repeat; 2]);
    assert_eq!(tris.len(), 4);
    for t in &tris[..2] {
        assert_eq!(t.material(), 1);
        assert!(t.flags & TRI_HAS_UV != 0);
        assert_eq!(t.c[0], [128, 64, 255, 128]); // Kd, alpha from d
    }
    assert_eq!(tris[0].uv, [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]);
    assert_eq!(tris[1].uv, [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
    assert_eq!(tris[2].material(), 2);
}

#[test]
fn missing_texture_is_a_warning_and_kd_is_used() {
    let d = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(d.path().join("sub")).unwrap();
    std::fs::write(
        d.path().join("sub/mats.mtl"),
        "newmtl a\nKd 1 0 0\nmap_Kd gone.png\nnewmtl b\nKd 0 1 0\n",
    )
    .unwrap();
    let obj = d.path().join("m.obj");
    std::fs::write(&obj, OBJ).unwrap();
    let (src, tris) = read(&obj);
    let info = src.info();
    assert_eq!(info.warnings.len(), 1, "{:?}", info.warnings);
    assert!(info.warnings[0].contains("gone.png"), "{:?}", info.warnings);
    // no texture left, but two materials: the table stays for the material channel
    assert!(!info.has_texcoords);
    assert!(info.materials.iter().all(|m| m.texture.is_none()));
    assert!(tris.iter().all(|t| t.flags & TRI_HAS_UV == 0));
    assert_eq!(tris[0].c[0], [255, 0, 0, 255]);
    assert_eq!(tris[3].c[0], [0, 255, 0, 255]);
}

#[test]
fn textured_faces_without_vt_are_a_warning() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("t.png"), b"x").unwrap();
    std::fs::write(d.path().join("m.mtl"), "newmtl a\nmap_Kd t.png\n").unwrap();
    let obj = d.path().join("m.obj");
    std::fs::write(
        &obj,
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\nf 1 3 2\n",
    )
    .unwrap();
    let (src, tris) = read(&obj);
    let w = &src.info().warnings;
    assert!(
        w.len() == 1
            && w[0].contains(
                "\"a\" has a texture (map_Kd) but some of its faces have no texture coordinate"
            ),
        "{w:?}"
    );
    // the material's faces are not all textured: none is (tobj would fill the missing
    // coordinates with the previous ones)
    assert!(tris.iter().all(|t| t.flags & TRI_HAS_UV == 0));
}

/// The shared textured meshes, or None (with a note) when this clone has no `../shared`.
/// Under CI (`CI=true`) a missing `../shared` is a failure, never a silent skip.
fn shared(test: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/meshes");
    if p.is_dir() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: ../shared/data/meshes is missing, and CI=true requires it");
    }
    voxlod_testkit::skipped(test, "../shared/data/meshes is not beside this clone");
    None
}

/// Sponza (its MTL names `SP_LUK.JPG` for `sp_luk.JPG`: resolved case-insensitively) and the
/// YCB banana: every textured material found, most triangles textured, with coordinates.
#[test]
fn shared_textured_objs() {
    let Some(dir) = shared("shared_textured_objs") else {
        return;
    };
    let (src, tris) = read(&dir.join("ycb-banana-textured/textured_simple_reoriented.obj"));
    let info = src.info();
    assert!(info.warnings.is_empty(), "{:?}", info.warnings);
    assert_eq!(info.materials.len(), 2);
    assert!(tris
        .iter()
        .all(|t| t.flags & TRI_HAS_UV != 0 && t.material() == 1));

    let (src, tris) = read(&dir.join("mcguire-sponza-dabrovic/sponza.obj"));
    let info = src.info();
    eprintln!("sponza warnings: {:?}", info.warnings);
    assert!(info.has_texcoords);
    let files: HashSet<_> = info
        .materials
        .iter()
        .filter_map(|m| m.texture.as_ref())
        .map(|p| p.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert!(files.contains("sp_luk.JPG"), "{files:?}");
    assert!(files.len() >= 10, "{files:?}");
    // every used material has an entry (the material channel's ids); the textured ones exist
    for m in info.materials[1..].iter().filter(|m| m.texture.is_some()) {
        assert!(m.texture.as_ref().unwrap().is_file(), "{m:?}");
    }
    assert!(info.materials.len() > files.len());
    let textured = tris.iter().filter(|t| t.flags & TRI_HAS_UV != 0).count();
    assert!(textured * 2 > tris.len(), "{textured} of {}", tris.len());
    assert!(tris
        .iter()
        .all(|t| (t.material() as usize) < info.materials.len()));
}
