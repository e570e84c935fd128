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
    // the size is known before anything is written: say it first (a fine level of a big
    // model is gigabytes), without a prompt, as command-line tools that write files do
    let s = voxlod_render::export_ply_with(&r, a.level, guard.staged(), &mut |s| {
        eprintln!(
            "writing level {} of {}: {} quads, {} to {}",
            a.level,
            a.file.display(),
            s.quads,
            format_size(s.bytes),
            a.output.display()
        );
        Ok(())
    })?;
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
