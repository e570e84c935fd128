//! `voxlod export FILE --level K -o out.ply`: one level as a quad mesh (binary PLY, normals
//! and colours) for MeshLab or Blender, or `-o out.glb` the same quads as glTF 2.0 binary;
//! `--source [--node 0 X Y Z]`: the source triangles stored beside the leaves (FORMAT.md
//! 14.4); `--3d-tiles DIR`: an OGC 3D Tiles 1.1 tileset ([`tiles`]); see `voxlod-render`.
//! Every export is sized before it is written and refused when too
//! big ([`size_guard`]).

mod size_guard;
mod tiles;

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use voxlod_format::Reader;
use voxlod_pipeline::{format_size, parse_size, OutputGuard, OutputKind};

use size_guard::SizeLimit;

#[derive(Args)]
pub struct ExportArgs {
    /// An octree file.
    file: PathBuf,
    /// The level to export (0 = finest).
    #[arg(short, long, default_value_t = 0)]
    level: u32,
    /// Output file: `.ply` writes binary PLY, `.glb` glTF 2.0 binary (with --source: `.ply`);
    /// any other name is refused (the format is chosen by it).
    #[arg(short, long, required_unless_present = "tiles")]
    output: Option<PathBuf>,
    /// Write an OGC 3D Tiles 1.1 tileset into this new folder instead: `tileset.json` and one
    /// `.glb` per node of levels --level and coarser (meshopt-compressed, linear colours; a
    /// node over 4 MB split in octants), the model's up as +z, geometric error 8 voxel edges
    /// (voxels at most 2 px at the consumers' default screen-space error of 16).
    #[arg(long = "3d-tiles", id = "tiles", value_name = "DIR", conflicts_with_all = ["output", "source"])]
    tiles: Option<PathBuf>,
    /// With --3d-tiles: cut by geometric error instead of --level: the finest level written
    /// is the coarsest whose voxel edge is at most E (world units).
    #[arg(long, value_name = "E", requires = "tiles", conflicts_with = "level")]
    error: Option<f64>,
    /// With --3d-tiles: the model's up, x,y,z, turned onto the tileset's up [default: as
    /// `render` takes it: the manifest's `input.up`, else 0,0,1 for a model flat in z, else
    /// 0,1,0]. The output says which was used.
    #[arg(long, value_parser = crate::render::parse_vec3, allow_hyphen_values = true, requires = "tiles")]
    up: Option<[f64; 3]>,
    /// With --3d-tiles: place the model on the globe, its bottom centre at LON,LAT,HEIGHT
    /// (degrees, degrees, metres above the WGS 84 ellipsoid), east-north-up (the root tile's
    /// `transform`); without it the tileset keeps the file's coordinates, turned z-up.
    #[arg(long, value_parser = parse_origin, value_name = "LON,LAT,HEIGHT", allow_hyphen_values = true, requires = "tiles")]
    origin: Option<[f64; 3]>,
    /// With --3d-tiles: the length of one file unit: m, dm, cm, mm, km, in, ft, or metres as a
    /// number (3D Tiles are in metres).
    #[arg(long, value_parser = parse_units, default_value = "m", allow_hyphen_values = true, requires = "tiles")]
    units: f64,
    /// Export the source triangles stored beside the leaves (a file built with
    /// --source-geometry) instead of voxel quads.
    #[arg(long)]
    source: bool,
    /// With --source: only this leaf node (level 0 and its chunk position).
    #[arg(long, num_args = 4, value_names = ["L", "X", "Y", "Z"], requires = "source")]
    node: Option<Vec<u32>>,
    /// Replace an existing output file even if it is not of the kind written; with
    /// --3d-tiles, replace the tileset in DIR.
    #[arg(long)]
    force: bool,
    /// Write an export bigger than 4 GiB, up to SIZE (e.g. 20GiB); an export bigger than the
    /// free space of the output's file system is refused whatever this says.
    #[arg(long, value_parser = parse_size, value_name = "SIZE")]
    max_size: Option<u64>,
}

/// `--origin LON,LAT,HEIGHT`: degrees in range, a finite height.
fn parse_origin(s: &str) -> Result<[f64; 3], String> {
    let [lon, lat, h] = crate::render::parse_vec3(s)
        .map_err(|_| format!("'{s}' is not LON,LAT,HEIGHT (e.g. 7.44,46.95,600)"))?;
    if !(-180.0..=180.0).contains(&lon) || !(-90.0..=90.0).contains(&lat) || !h.is_finite() {
        return Err(format!(
            "'{s}': longitude must be in -180..180, latitude in -90..90 degrees, height in metres"
        ));
    }
    Ok([lon, lat, h])
}

/// `--units`: metres per file unit, by name or as a positive number.
fn parse_units(s: &str) -> Result<f64, String> {
    let named = match s.to_ascii_lowercase().as_str() {
        "m" => Some(1.0),
        "dm" => Some(0.1),
        "cm" => Some(0.01),
        "mm" => Some(0.001),
        "km" => Some(1000.0),
        "in" => Some(0.0254),
        "ft" => Some(0.3048),
        _ => None,
    };
    match named.or_else(|| s.parse::<f64>().ok()) {
        Some(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!(
            "'{s}' is not a unit: m, dm, cm, mm, km, in, ft, or metres per unit as a positive number"
        )),
    }
}

/// The folder an output is written in (`.` for a bare file name).
fn output_dir(output: &Path) -> PathBuf {
    match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// What `-o` asks for, from its extension (any case): `.ply` binary PLY, `.glb` glTF binary
/// (not with `--source`); any other name is refused rather than written in a format it does
/// not name.
fn output_kind(output: &Path, source: bool) -> Result<OutputKind> {
    let ext = output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("ply") => Ok(OutputKind::Ply),
        Some("glb") if !source => Ok(OutputKind::Glb),
        Some("gltf") if !source => anyhow::bail!(
            "{}: write glTF as one binary file: name it .glb (a .gltf with a separate .bin is not written)",
            output.display()
        ),
        _ if source => anyhow::bail!(
            "{}: --source writes binary PLY: the output's name must end in .ply",
            output.display()
        ),
        _ => anyhow::bail!(
            "{}: the output's name must end in .ply (binary PLY) or .glb (glTF 2.0 binary): the format is chosen by it",
            output.display()
        ),
    }
}

/// `--source`: the stored source triangles of one leaf or of all of them.
fn run_source(
    a: &ExportArgs,
    output: &Path,
    r: &Reader,
    guard: &OutputGuard,
    limit: &SizeLimit,
) -> Result<()> {
    let nodes = match &a.node {
        Some(n) => {
            let (level, pos) = (n[0], [n[1], n[2], n[3]]);
            anyhow::ensure!(
                level == 0,
                "--node {level} …: source triangles are stored for leaf chunks (level 0) only"
            );
            let i = r.find(level, pos).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: no node at level {level}, position {pos:?}",
                    a.file.display()
                )
            })?;
            anyhow::ensure!(
                r.source_triangles(i)?.is_some(),
                "{}: leaf {pos:?} has no source triangles",
                a.file.display()
            );
            Some(vec![i])
        }
        None => None,
    };
    let s = voxlod_render::export_source_ply(r, nodes.as_deref(), guard.staged(), &mut |s| {
        // source triangles exist at level 0 only: no coarser level to suggest
        limit
            .check(&output.display().to_string(), s.bytes, 0, 1, &|_| 0)
            .map_err(|e| voxlod_render::RenderError::Option(e.to_string()))?;
        eprintln!(
            "writing the source triangles of {} leaves of {}: {} triangles, {} to {}",
            s.leaves,
            a.file.display(),
            s.triangles,
            format_size(s.bytes),
            output.display()
        );
        Ok(())
    })?;
    guard.commit()?;
    println!(
        "wrote {}: source triangles of {} leaves, {} triangles, {} vertices, {}",
        output.display(),
        s.leaves,
        s.triangles,
        s.vertices,
        format_size(s.bytes)
    );
    Ok(())
}

pub fn run(a: ExportArgs) -> Result<()> {
    if let Some(dir) = &a.tiles {
        let place = tiles::Placement {
            up: a.up,
            origin: a.origin,
            scale: a.units,
        };
        return tiles::run(&a.file, dir, a.level, a.error, a.max_size, a.force, &place);
    }
    let output = a.output.clone().expect("clap: -o or --3d-tiles");
    // the output is checked (not the input, not another kind of file) and locked first, and
    // written under a temporary name: an interrupted export leaves no partial file
    let kind = match output_kind(&output, a.source) {
        Ok(k) => k,
        Err(e) => {
            // a name that is the input itself is the graver mistake: the guard says so first
            drop(OutputGuard::acquire(
                &output,
                &[&a.file],
                OutputKind::Ply,
                false,
            )?);
            return Err(e);
        }
    };
    let guard = OutputGuard::acquire(&output, &[&a.file], kind, a.force)?;
    let r = Reader::open(&a.file)?;
    let mut limit = SizeLimit::for_dir(a.max_size, &output_dir(&output));
    if kind == OutputKind::Glb {
        // a GLB's lengths are 32-bit: past that, refused by the guard naming the level that fits
        limit = limit.with_format_cap(u32::MAX as u64, "the 4 GiB a GLB can hold");
    }
    if a.source {
        return run_source(&a, &output, &r, &guard, &limit);
    }
    // the size is known before anything is written: refused when too big, else
    // said first (a fine level of a big model is gigabytes), without a prompt, as
    // command-line tools that write files do
    let mut before = |s: &voxlod_render::ExportSummary| {
        let estimate = size_guard::proportional(&r, a.level, s.bytes);
        limit
            .check(
                &output.display().to_string(),
                s.bytes,
                a.level,
                r.spec().levels,
                &estimate,
            )
            .map_err(|e| voxlod_render::RenderError::Option(e.to_string()))?;
        eprintln!(
            "writing level {} of {}: {} quads, {} to {}",
            a.level,
            a.file.display(),
            s.quads,
            format_size(s.bytes),
            output.display()
        );
        Ok(())
    };
    let s = if kind == OutputKind::Glb {
        voxlod_render::export_glb_with(&r, a.level, guard.staged(), &mut before)?
    } else {
        voxlod_render::export_ply_with(&r, a.level, guard.staged(), &mut before)?
    };
    guard.commit()?;
    println!(
        "wrote {}: level {}, {} voxels, {} quads, {} vertices, {}",
        output.display(),
        a.level,
        s.voxels,
        s.quads,
        s.vertices,
        format_size(s.bytes)
    );
    Ok(())
}
