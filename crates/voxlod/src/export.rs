//! `voxlod export FILE --level K -o out.ply`: one level as a quad mesh (binary PLY, normals
//! and colours) for MeshLab or Blender; `--source [--node 0 X Y Z]`: the source triangles
//! stored beside the leaves (FORMAT.md 14.4); see `voxlod-render`.

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
    /// Export the source triangles stored beside the leaves (a file built with
    /// --source-geometry) instead of voxel quads.
    #[arg(long)]
    source: bool,
    /// With --source: only this leaf node (level 0 and its chunk position).
    #[arg(long, num_args = 4, value_names = ["L", "X", "Y", "Z"], requires = "source")]
    node: Option<Vec<u32>>,
    /// Replace an existing output file even if it is not a PLY mesh.
    #[arg(long)]
    force: bool,
}

/// `--source`: the stored source triangles of one leaf or of all of them.
fn run_source(a: &ExportArgs, r: &Reader, guard: &OutputGuard) -> Result<()> {
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
        eprintln!(
            "writing the source triangles of {} leaves of {}: {} triangles, {} to {}",
            s.leaves,
            a.file.display(),
            s.triangles,
            format_size(s.bytes),
            a.output.display()
        );
        Ok(())
    })?;
    guard.commit()?;
    println!(
        "wrote {}: source triangles of {} leaves, {} triangles, {} vertices, {}",
        a.output.display(),
        s.leaves,
        s.triangles,
        s.vertices,
        format_size(s.bytes)
    );
    Ok(())
}

pub fn run(a: ExportArgs) -> Result<()> {
    // the output is checked (not the input, not another kind of file) and locked first, and
    // written under a temporary name: an interrupted export leaves no partial file
    let guard = OutputGuard::acquire(&a.output, &[&a.file], OutputKind::Ply, a.force)?;
    let r = Reader::open(&a.file)?;
    if a.source {
        return run_source(&a, &r, &guard);
    }
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
