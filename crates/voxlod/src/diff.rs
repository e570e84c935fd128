//! `voxlod diff A B`: chunk-level comparison for regression tests (see `voxlod-check`); exit
//! code 0 when the files hold the same octree (or differ only within the tolerances).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use voxlod_check::Tolerance;

#[derive(Args)]
pub struct DiffArgs {
    /// The reference file.
    a: PathBuf,
    /// The file compared with it.
    b: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Accept normals of common voxels differing by up to this angle (degrees); also accepts
    /// face-mask differences, which follow from normals.
    #[arg(long, default_value_t = 0.0, value_parser = parse_degrees)]
    max_normal_deg: f64,
    /// Accept colour channels differing by up to this much (0–255).
    #[arg(long, default_value_t = 0)]
    max_color: u8,
    /// Accept changed nodes whose voxel positions have at least this intersection-over-union.
    #[arg(long, default_value_t = 1.0, value_parser = parse_fraction)]
    min_iou: f64,
    /// Nodes listed per category in the text report (all are in --json).
    #[arg(long, default_value_t = 20)]
    limit: usize,
}

/// A number in 0..=1 (NaN, which every comparison fails, is refused).
fn parse_fraction(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("'{s}' is not a number from 0 to 1")),
    }
}

/// An angle in 0..=180 degrees (NaN refused).
fn parse_degrees(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=180.0).contains(&v) => Ok(v),
        _ => Err(format!("'{s}' is not an angle from 0 to 180 degrees")),
    }
}

pub fn run(a: DiffArgs) -> Result<()> {
    let tol = Tolerance {
        max_normal_deg: a.max_normal_deg,
        max_color: a.max_color,
        min_iou: a.min_iou,
    };
    let d = voxlod_check::diff(&a.a, &a.b, &tol)?;
    if a.json {
        crate::json::print(&d)?;
    } else {
        println!("a: {}\nb: {}", d.a, d.b);
        for f in &d.header {
            println!("  header       {}: {} → {}", f.field, f.a, f.b);
        }
        if !d.same_grid {
            println!("  different grids (resolution, origin or voxel size): no chunk corresponds, every node differs");
        }
        println!(
            "  nodes        {} identical, {} changed, {} added, {} removed",
            d.identical,
            d.changed.len(),
            d.added.len(),
            d.removed.len()
        );
        for c in d.changed.iter().take(a.limit) {
            println!(
                "  changed      {}: {} → {} voxels, +{} −{} IoU {:.4}, normal ≤ {:.2}°, colour ≤ {}, {} mask diffs{}",
                c.node,
                c.voxels_a,
                c.voxels_b,
                c.added,
                c.removed,
                c.iou,
                c.max_normal_deg,
                c.max_color_diff,
                c.mask_diffs,
                if c.within_tolerance { " (within tolerance)" } else { "" }
            );
        }
        for n in d.added.iter().take(a.limit) {
            println!("  added        {n}");
        }
        for n in d.removed.iter().take(a.limit) {
            println!("  removed      {n}");
        }
        if d.identical() {
            println!("  identical");
        } else if d.within_tolerance() {
            println!("  within tolerance");
        }
    }
    if !d.within_tolerance() {
        bail!("the files differ");
    }
    Ok(())
}
