//! Files a mesh refers to (OBJ `mtllib` and `map_Kd`, PLY `comment TextureFile`, glTF buffer
//! and image URIs) are read only inside the mesh's folder, or inside folders the caller allows
//! ([`crate::ReadOptions::allow`]), each compared after resolving symlinks: a service that
//! voxelizes uploaded files must not let a file name `../`, an absolute path, a symlink or a
//! percent-encoded `%2E%2E` read what lies elsewhere. Only regular files are read (a FIFO would
//! block, `/dev/zero` never ends), with a bound; no message quotes the content of such a file.

use std::io::Read;
use std::path::{Path, PathBuf};

/// The folders a mesh's referenced files may lie in, resolved.
#[derive(Clone, Debug)]
pub(crate) struct Scope {
    /// The mesh's folder first, then the allowed folders; each canonical (symlinks resolved).
    roots: Vec<PathBuf>,
}

impl Scope {
    /// The scope of the mesh `mesh`: its folder and the folders in `allow`. A folder that does
    /// not exist allows nothing.
    pub fn new(mesh: &Path, allow: &[PathBuf]) -> Scope {
        let dir = mesh
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let roots = std::iter::once(dir)
            .chain(allow.iter().map(PathBuf::as_path))
            .filter_map(|d| d.canonicalize().ok())
            .collect();
        Scope { roots }
    }

    /// `Ok` if `file` (resolved) lies inside one of the scope's folders.
    pub fn check(&self, file: &Path) -> Result<(), String> {
        let real = file
            .canonicalize()
            .map_err(|e| format!("{}: {e}", file.display()))?;
        if self.roots.iter().any(|r| real.starts_with(r)) {
            return Ok(());
        }
        let home = self
            .roots
            .first()
            .map_or("?".into(), |r| r.display().to_string());
        Err(format!(
            "{} lies outside the mesh's folder {home}{}; files a mesh refers to are read only there unless their folder is allowed (voxlod --allow-path DIR)",
            file.display(),
            if self.roots.len() > 1 {
                " and the allowed folders"
            } else {
                ""
            }
        ))
    }

    /// The first `len` bytes of `file` (fewer if it is shorter), if it is a regular file inside
    /// the scope.
    pub fn read_prefix(&self, file: &Path, len: u64) -> Result<Vec<u8>, String> {
        self.check(file)?;
        let f = voxlod_io::open_regular(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let mut out = Vec::with_capacity(len.min(1 << 30) as usize);
        f.take(len)
            .read_to_end(&mut out)
            .map_err(|e| format!("{}: {e}", file.display()))?;
        Ok(out)
    }

    /// The whole of `file`, if it is a regular file inside the scope of at most `limit` bytes.
    pub fn read_whole(&self, file: &Path, limit: u64) -> Result<Vec<u8>, String> {
        self.check(file)?;
        voxlod_io::read_bounded(file, limit).map_err(|e| format!("{}: {e}", file.display()))
    }

    /// An MTL library (at most [`MTL_LIMIT`] bytes) parsed by `tobj`, read through the scope.
    /// `Err` says why the file was not read (tobj's own error type carries no text).
    pub fn load_mtl(&self, file: &Path) -> Result<tobj::MTLLoadResult, String> {
        let bytes = self.read_whole(file, MTL_LIMIT)?;
        Ok(tobj::load_mtl_buf(&mut std::io::Cursor::new(bytes)))
    }
}

/// The largest MTL file read: material libraries are text of a few kilobytes; this bound only
/// stops a file that would fill memory.
pub(crate) const MTL_LIMIT: u64 = 256 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_inside_the_folder_after_symlinks() {
        let d = tempfile::tempdir().unwrap();
        let mesh_dir = d.path().join("m");
        let other = d.path().join("o");
        std::fs::create_dir_all(&mesh_dir).unwrap();
        std::fs::create_dir_all(&other).unwrap();
        std::fs::write(mesh_dir.join("t.png"), b"x").unwrap();
        std::fs::write(other.join("secret"), b"s").unwrap();
        std::os::unix::fs::symlink(other.join("secret"), mesh_dir.join("link")).unwrap();
        let s = Scope::new(&mesh_dir.join("a.obj"), &[]);
        s.check(&mesh_dir.join("t.png")).unwrap();
        let e = s.check(&mesh_dir.join("../o/secret")).unwrap_err();
        assert!(e.contains("outside the mesh's folder"), "{e}");
        assert!(s.check(&mesh_dir.join("link")).is_err());
        let allowed = Scope::new(&mesh_dir.join("a.obj"), std::slice::from_ref(&other));
        allowed.check(&mesh_dir.join("link")).unwrap();
        assert_eq!(
            allowed.read_prefix(&mesh_dir.join("link"), 9).unwrap(),
            b"s"
        );
    }
}
