//! `voxlod export FILE --level K -o out.ply`: one level as a quad mesh (binary PLY, normals
//! and colours) for MeshLab or Blender; see `voxlod-render`.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use voxlod_format::Reader;
use voxlod_pipeline::{format_size, OutputGuard, OutputKind};

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
    /// Replace an existing output file even if it is not a PLY mesh.
    #[arg(long)]
    force: bool,
}

pub fn run(a: ExportArgs) -> Result<()> {
    // the output is checked (not the input, not another kind of file) and locked first, and
    // written under a temporary name: an interrupted export leaves no partial file
    let guard = OutputGuard::acquire(&a.output, &[&a.file], OutputKind::Ply, a.force)?;
    let r = Reader::open(&a.file)?;
    let s = voxlod_render::export_ply(&r, a.level, guard.staged())?;
    guard.commit()?;
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
