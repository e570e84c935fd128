//! `voxlod export FILE --3d-tiles DIR [--level K | --error E]`: the octree as an OGC 3D Tiles
//! 1.1 tileset (`voxlod_render::export_tileset_with`). The folder is written whole or not at
//! all: the tiles go into a staging folder beside `DIR`, renamed to `DIR` at the end (an
//! earlier tileset there is replaced only with `--force`); tiles are written as they are
//! compressed, up to the size limit (`size_guard`): past it the rest are only sized, the
//! export is refused with the exact size and the staging folder removed.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use voxlod_format::Reader;
use voxlod_pipeline::{format_size, OutputGuard};

use super::size_guard::{level_voxels, SizeLimit};

/// The finest level of a cut by geometric error `error` (world units): the coarsest level
/// whose voxel edge is at most `error`, or level 0 when every edge is larger.
pub fn level_for_error(reader: &Reader, error: f64) -> u32 {
    let spec = reader.spec();
    (0..spec.levels)
        .rev()
        .find(|&l| spec.voxel_size_at(l) <= error)
        .unwrap_or(0)
}

/// Checks that `dir` may receive a tileset: absent, an empty folder, or (with `force`) a
/// folder holding an earlier `tileset.json`.
fn check_target(dir: &Path, force: bool) -> Result<()> {
    let shown = dir.display();
    let Ok(m) = std::fs::symlink_metadata(dir) else {
        return Ok(());
    };
    if !m.is_dir() {
        bail!("{shown}: exists and is not a folder; --3d-tiles writes a folder");
    }
    let mut entries = std::fs::read_dir(dir).with_context(|| format!("{shown}: cannot list"))?;
    if entries.next().is_none() {
        return Ok(());
    }
    if !dir.join("tileset.json").is_file() {
        bail!("{shown}: the folder is not empty and holds no tileset; name a new or empty folder");
    }
    if !force {
        bail!("{shown}: holds a tileset already; --force replaces it");
    }
    // the whole folder is exchanged for the new tileset: with --force too, only a folder
    // holding nothing but a tileset's own files is replaced
    if let Some(other) = foreign_entry(dir)? {
        bail!(
            "{shown}: holds {}, which is not part of a tileset voxlod writes; even with --force only a folder holding nothing but tileset.json and its level folders is replaced: move it out or name another folder",
            other.display()
        );
    }
    Ok(())
}

/// Where the tileset is put: `--up`, `--origin`, `--units`.
pub struct Placement {
    /// The model's up, if given (else as `render` picks it).
    pub up: Option<[f64; 3]>,
    /// Longitude, latitude (degrees) and height (metres) of the model's bottom centre.
    pub origin: Option<[f64; 3]>,
    /// Metres per file unit.
    pub scale: f64,
}

/// True if `name` is a decimal number (a level folder).
fn is_number(name: &str) -> bool {
    !name.is_empty() && name.bytes().all(|b| b.is_ascii_digit())
}

/// True if `name` is a tile of a level folder: `X-Y-Z.glb`, or a part of a node split for size
/// `X-Y-Z-o1-….glb` (up to eight octant digits 0..=7).
fn is_tile(name: &str) -> bool {
    name.strip_suffix(".glb").is_some_and(|n| {
        let parts: Vec<&str> = n.split('-').collect();
        (3..=11).contains(&parts.len())
            && parts.iter().all(|p| is_number(p))
            && parts[3..]
                .iter()
                .all(|p| p.len() == 1 && p.as_bytes()[0] <= b'7')
    })
}

/// The first entry of `dir` that a tileset does not write (`tileset.json`, level folders `L`
/// of tiles `X-Y-Z.glb`), if any.
fn foreign_entry(dir: &Path) -> Result<Option<PathBuf>> {
    let list = |d: &Path| -> Result<Vec<(String, std::fs::FileType)>> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(d).with_context(|| format!("{}: cannot list", d.display()))? {
            let e = e.with_context(|| format!("{}: cannot list", d.display()))?;
            let t = e
                .file_type()
                .with_context(|| format!("{}: cannot list", d.display()))?;
            out.push((e.file_name().to_string_lossy().into_owned(), t));
        }
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(out)
    };
    for (name, t) in list(dir)? {
        let at = dir.join(&name);
        match name.as_str() {
            "tileset.json" if t.is_file() => {}
            n if is_number(n) && t.is_dir() => {
                if let Some((tile, _)) = list(&at)?
                    .into_iter()
                    .find(|(tile, tt)| !(tt.is_file() && is_tile(tile)))
                {
                    return Ok(Some(at.join(tile)));
                }
            }
            _ => return Ok(Some(at)),
        }
    }
    Ok(None)
}

pub fn run(
    file: &Path,
    dir: &Path,
    level: u32,
    error: Option<f64>,
    max_size: Option<u64>,
    force: bool,
    place: &Placement,
) -> Result<()> {
    check_target(dir, force)?;
    let r = Reader::open(file)?;
    let level = match error {
        Some(e) if !(e.is_finite() && e > 0.0) => {
            bail!("--error {e}: give a positive size in world units")
        }
        Some(e) => level_for_error(&r, e),
        None => level,
    };
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        bail!(
            "{}: the folder {} does not exist",
            dir.display(),
            parent.display()
        );
    }
    // the output's lock and its staged folder `.voxlod-part-NAME-PID-TIME` beside it (removed
    // if this fails; left to `voxlod clean` if the process is killed)
    let guard = OutputGuard::acquire_folder(dir)?;
    let stage_path = guard.staged().to_path_buf();
    let limit = SizeLimit::for_dir(max_size, &parent);
    let voxels = level_voxels(&r);
    let (up, up_from) = crate::render::pick_up(&r, place.up)?;
    let opts = voxlod_render::TilesetOptions {
        min_level: level,
        up,
        origin: place.origin,
        scale: place.scale,
        max_bytes: limit.limit().0,
    };
    // the tiles are written as they are made, at most up to the limit (past it the rest are
    // only sized, for the message), and the staging folder is removed if the export fails
    std::fs::create_dir(&stage_path)
        .with_context(|| format!("{}: cannot create", stage_path.display()))?;
    let s = voxlod_render::export_tileset_with(&r, &opts, &stage_path, &mut |s| {
        // other cuts: bytes in proportion to the voxels of the levels they hold
        let cut_voxels = |l: u32| voxels[l as usize..].iter().sum::<u64>();
        let per_voxel = s.bytes as f64 / cut_voxels(level).max(1) as f64;
        let estimate = |l: u32| (cut_voxels(l) as f64 * per_voxel).ceil() as u64;
        limit
            .check(
                &dir.display().to_string(),
                s.bytes,
                level,
                r.spec().levels,
                &estimate,
            )
            .map_err(|e| voxlod_render::RenderError::Option(e.to_string()))?;
        Ok(())
    })?;
    // into place: exchanged atomically with an earlier tileset, which is then removed
    guard.commit_folder()?;
    println!(
        "wrote {}: 3D Tiles 1.1, levels {level}..={}, {} tiles ({} with content), {} quads, {} ({:.2} bytes a voxel; largest tile {})",
        dir.display(),
        r.spec().levels - 1,
        s.tiles,
        s.contents,
        s.quads,
        format_size(s.bytes),
        s.bytes as f64 / s.voxels.max(1) as f64,
        format_size(s.largest_tile),
    );
    let placed = match place.origin {
        Some([lon, lat, h]) => format!(
            "its bottom centre at longitude {lon}°, latitude {lat}°, height {h} m, east-north-up"
        ),
        None => "at the file's coordinates (--origin places it on the globe)".into(),
    };
    println!(
        "  up: {} ({up_from}) is the tileset's +z; {placed}; {} m per file unit; geometric error {}× the voxel edge (voxels at most 2 px at a maximum screen-space error of 16)",
        up.map(|c| c.to_string()).join(","),
        place.scale,
        voxlod_render::GEOMETRIC_ERROR_PER_EDGE,
    );
    Ok(())
}
