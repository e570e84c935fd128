//! `voxlod export FILE --level K -o out.ply`: one level as a quad mesh (binary PLY, normals
//! and colours) for MeshLab or Blender; see `voxlod-render`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use voxlod_format::Reader;
use voxlod_pipeline::format_size;

#[derive(Args)]
pub struct ExportArgs {
    /// An octree file.
    file: PathBuf,
    /// The level to export (0 = finest).
    #[arg(short, long, default_value_t = 0)]
    level: u32,
    /// Output PLY file.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: ExportArgs) -> Result<()> {
    let r = Reader::open(&a.file).with_context(|| format!("opening {}", a.file.display()))?;
    let s = voxlod_render::export_ply(&r, a.level, &a.output)?;
    println!(
        "wrote {}: level {}, {} voxels, {} quads, {} vertices, {}",
        a.output.display(),
        a.level,
        s.voxels,
        s.quads,
        s.vertices,
        format_size(s.bytes)
    );
    Ok(())
}
