//! Writes a block world as OBJ + MTL + one PNG per material, beside each other:
//! `NAME.obj` (vertices shared between faces, four `vt` for the texture's corners, the faces of
//! each material after its `usemtl`, two triangles per face), `NAME.mtl` (per material `Kd 1 1 1`
//! and `map_Kd -clamp on NAME-MATERIAL.png`) and the textures. Every file is written under a
//! temporary name in the same folder and renamed when all are complete, the OBJ last, so an
//! interrupted run leaves no OBJ that refers to missing files and no half-written file under a
//! final name.

use std::collections::HashMap;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::faces::{exposed_faces, Face, Material};
use crate::textures::png_bytes;
use crate::world::World;
use crate::Error;

/// What [`write_world`] wrote.
#[derive(Clone, Debug)]
pub struct Written {
    /// Exposed faces (two triangles each).
    pub faces: u64,
    /// Triangles of the OBJ.
    pub triangles: u64,
    /// Distinct vertices of the OBJ.
    pub vertices: u64,
    /// Every file written: the OBJ, the MTL, then the textures.
    pub files: Vec<PathBuf>,
    /// Their total size in bytes.
    pub bytes: u64,
}

/// Writes `world` to `obj` (a name ending in `.obj`, in an existing folder) with its MTL and
/// textures beside it. Existing files of those names are an error unless `force`.
pub fn write_world(world: &World, obj: &Path, force: bool) -> Result<Written, Error> {
    let (dir, stem) = split(obj)?;
    let mtl_name = format!("{stem}.mtl");
    let tex_name = |m: Material| format!("{stem}-{}.png", m.name());
    let mut targets = vec![obj.to_path_buf(), dir.join(&mtl_name)];
    targets.extend(Material::ALL.iter().map(|&m| dir.join(tex_name(m))));
    if !force {
        if let Some(p) = targets.iter().find(|p| p.exists()) {
            return Err(Error::Exists(p.clone()));
        }
    }
    let part = |p: &Path| {
        let name = p.file_name().unwrap_or_default().to_string_lossy();
        dir.join(format!(".{name}.part-{}", std::process::id()))
    };
    let parts: Vec<PathBuf> = targets.iter().map(|p| part(p)).collect();
    remove_stale_parts(&dir, &targets);
    let result = write_parts(world, &parts, &mtl_name, &tex_name);
    let written = match result {
        Ok(w) => w,
        Err(e) => {
            for p in &parts {
                let _ = std::fs::remove_file(p);
            }
            return Err(e);
        }
    };
    // textures and MTL first, the OBJ that refers to them last
    let mut bytes = 0;
    for (p, t) in parts.iter().zip(&targets).rev() {
        bytes += std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
        std::fs::rename(p, t).map_err(|source| Error::Io {
            path: t.clone(),
            source,
        })?;
    }
    Ok(Written {
        files: targets,
        bytes,
        ..written
    })
}

/// Removes the temporary files a killed run left for these targets (`.NAME.part-PID` whose
/// process is gone; on systems without `/proc` none are removed).
fn remove_stale_parts(dir: &Path, targets: &[PathBuf]) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefixes: Vec<String> = targets
        .iter()
        .filter_map(|t| t.file_name())
        .map(|n| format!(".{}.part-", n.to_string_lossy()))
        .collect();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let pid = prefixes.iter().find_map(|p| name.strip_prefix(p.as_str()));
        if let Some(pid) = pid.and_then(|p| p.parse::<u32>().ok()) {
            let gone =
                Path::new("/proc/self").exists() && !Path::new(&format!("/proc/{pid}")).exists();
            if gone {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// The output's folder (which must exist) and file stem (which must have no white space, as
/// the OBJ's `mtllib` and the MTL's `map_Kd` name files by it).
fn split(obj: &Path) -> Result<(PathBuf, String), Error> {
    let is_obj = obj
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let stem = obj.file_stem().map(|s| s.to_string_lossy().into_owned());
    let Some(stem) = stem.filter(|s| is_obj && !s.is_empty()) else {
        return Err(Error::NotObj(obj.to_path_buf()));
    };
    if stem.chars().any(char::is_whitespace) {
        return Err(Error::WhiteSpace(obj.to_path_buf()));
    }
    let dir = match obj.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(Error::Folder(dir));
    }
    Ok((dir, stem))
}

/// Writes the OBJ, MTL and textures to `parts` (in that order); the counts of the OBJ.
fn write_parts(
    world: &World,
    parts: &[PathBuf],
    mtl_name: &str,
    tex_name: &dyn Fn(Material) -> String,
) -> Result<Written, Error> {
    for (m, p) in Material::ALL.iter().zip(&parts[2..]) {
        let png = png_bytes(*m).map_err(|e| Error::Png {
            path: p.clone(),
            message: e.to_string(),
        })?;
        std::fs::write(p, png).map_err(|source| Error::Io {
            path: p.clone(),
            source,
        })?;
    }
    let mut mtl = String::from("# voxlod gen --kind blocks: one texture per block face material\n");
    for m in Material::ALL {
        mtl += &format!(
            "\nnewmtl {}\nKd 1 1 1\nmap_Kd -clamp on {}\n",
            m.name(),
            tex_name(m)
        );
    }
    std::fs::write(&parts[1], mtl).map_err(|source| Error::Io {
        path: parts[1].clone(),
        source,
    })?;
    let faces = exposed_faces(world);
    write_obj(world, &faces, &parts[0], mtl_name).map_err(|source| Error::Io {
        path: parts[0].clone(),
        source,
    })
}

fn write_obj(
    world: &World,
    faces: &[Face],
    path: &Path,
    mtl_name: &str,
) -> std::io::Result<Written> {
    let f = std::fs::File::create(path)?;
    let mut w = BufWriter::with_capacity(1 << 20, f);
    writeln!(
        w,
        "# voxlod gen --kind blocks: a {n}x{n} block world, seed {s}, {t} trees, {f} faces\n\
         mtllib {mtl_name}\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1",
        n = world.size(),
        s = world.seed(),
        t = world.trees(),
        f = faces.len(),
    )?;
    let mut index: HashMap<[u32; 3], u64> = HashMap::new();
    let mut current = None;
    for face in faces {
        if current != Some(face.material) {
            writeln!(w, "usemtl {}", face.material.name())?;
            current = Some(face.material);
        }
        let mut ids = [0u64; 4];
        for (id, c) in ids.iter_mut().zip(face.corners()) {
            let next = index.len() as u64 + 1;
            *id = *index.entry(c).or_insert_with(|| next);
            if *id == next {
                writeln!(w, "v {} {} {}", c[0], c[1], c[2])?;
            }
        }
        let [a, b, c, d] = ids;
        writeln!(w, "f {a}/1 {b}/2 {c}/3\nf {a}/1 {c}/3 {d}/4")?;
    }
    let file = w.into_inner().map_err(|e| e.into_error())?;
    file.sync_all()?;
    Ok(Written {
        faces: faces.len() as u64,
        triangles: 2 * faces.len() as u64,
        vertices: index.len() as u64,
        files: Vec::new(),
        bytes: 0,
    })
}
