//! `voxlod verify FILE`: every checksum and invariant (see `voxlod-check`); exit code 0 only
//! if all hold, otherwise a list of what failed, node by node.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct VerifyArgs {
    /// An octree file.
    file: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

pub fn run(a: VerifyArgs) -> Result<()> {
    let r = voxlod_check::verify(&a.file);
    if a.json {
        crate::json::print(&r)?;
    } else {
        println!("{}", a.file.display());
        if r.opened {
            println!(
                "  checked      {} nodes ({} decoded), {} voxels, {} parents against the merge of their children, {} leaf face masks",
                r.nodes, r.nodes_decoded, r.voxels, r.parents_checked, r.leaf_voxels_checked
            );
            if r.materials_checked > 0 {
                println!(
                    "  materials    {} parents against the material LOD rule",
                    r.materials_checked
                );
            }
            if r.source_triangles_checked > 0 {
                println!(
                    "  source       {} triangles decoded, each touching its chunk's box",
                    r.source_triangles_checked
                );
            }
        }
        for p in &r.problems {
            println!("  FAILED       {p}");
        }
        if r.ok() {
            println!("  ok           every checksum and invariant holds");
        }
    }
    if !r.ok() {
        bail!(
            "{}: {} check(s) failed",
            a.file.display(),
            r.problems.len().max(1)
        );
    }
    Ok(())
}
