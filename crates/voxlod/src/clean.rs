//! `voxlod clean [DIR]`: lists and removes stale work folders (`.voxlod-work-*`) in DIR, the
//! ones no running build holds: a build killed and then not run again with the same
//! arguments (another resolution, a changed input) leaves its folder forever otherwise.
//! Folders of running builds are listed and kept. Also the files a run killed while writing
//! an output leaves beside it (`.voxlod-lock-NAME`, `.voxlod-part-NAME-…`), removed while
//! holding that output's lock; those of a running command are listed and kept.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use voxlod_pipeline::{
    find_output_leftovers, find_work_folders, format_size, remove_output_leftovers,
    remove_stale_work_folder,
};

#[derive(Args)]
pub struct CleanArgs {
    /// Folder to look in: where the outputs are, or the `--tmp` of the builds [default: .].
    dir: Option<PathBuf>,
    /// Only list what would be removed.
    #[arg(short = 'n', long)]
    dry_run: bool,
}

pub fn run(a: CleanArgs) -> Result<()> {
    let dir = a.dir.unwrap_or_else(|| PathBuf::from("."));
    let folders = find_work_folders(&dir)?;
    let leftovers = find_output_leftovers(&dir)?;
    if folders.is_empty() && leftovers.is_empty() {
        println!("no voxlod work folders in {}", dir.display());
        return Ok(());
    }
    let (mut removed, mut freed, mut failed) = (0usize, 0u64, 0usize);
    for f in &folders {
        let age = format_age(f.age_seconds);
        let size = format_size(f.bytes);
        if let Some(pid) = f.in_use_by {
            let who = pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"));
            println!(
                "  in use   {size:>10}  {age:>9}  {} (running build, {who})",
                f.path.display()
            );
        } else if a.dry_run {
            println!(
                "  stale    {size:>10}  {age:>9}  {} (would be removed)",
                f.path.display()
            );
            removed += 1;
            freed += f.bytes;
        } else {
            match remove_stale_work_folder(&f.path) {
                Ok(()) => {
                    println!("  removed  {size:>10}  {age:>9}  {}", f.path.display());
                    removed += 1;
                    freed += f.bytes;
                }
                Err(e) => {
                    eprintln!("error: {e:#}");
                    failed += 1;
                }
            }
        }
    }
    let verb = if a.dry_run { "would remove" } else { "removed" };
    if !folders.is_empty() {
        println!(
            "{verb} {removed} stale work folder{} ({}); {} in use",
            if removed == 1 { "" } else { "s" },
            format_size(freed),
            folders.iter().filter(|f| !f.is_stale()).count()
        );
    }
    // the lock and staged files of outputs whose writer was killed
    let (mut outputs, mut out_bytes) = (0usize, 0u64);
    for l in &leftovers {
        let size = format_size(l.bytes);
        let what = format!(
            "{} ({} file{}: {})",
            dir.join(&l.name).display(),
            l.files.len(),
            if l.files.len() == 1 { "" } else { "s" },
            l.files
                .iter()
                .filter_map(|f| f.file_name())
                .map(|f| f.to_string_lossy())
                .collect::<Vec<_>>()
                .join(", ")
        );
        if let Some(pid) = l.in_use_by {
            let who = pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"));
            println!("  in use   {size:>10}  being written: {what}, {who}");
        } else if a.dry_run {
            println!("  stale    {size:>10}  left by a killed run: {what} (would be removed)");
            outputs += 1;
            out_bytes += l.bytes;
        } else {
            match remove_output_leftovers(&dir, &l.name) {
                Ok(bytes) => {
                    println!("  removed  {size:>10}  left by a killed run: {what}");
                    outputs += 1;
                    out_bytes += bytes;
                }
                Err(e) => {
                    eprintln!("error: {e:#}");
                    failed += 1;
                }
            }
        }
    }
    if !leftovers.is_empty() {
        println!(
            "{verb} the leftovers of {outputs} killed output{} ({}); {} being written",
            if outputs == 1 { "" } else { "s" },
            format_size(out_bytes),
            leftovers.iter().filter(|l| l.in_use_by.is_some()).count()
        );
    }
    if failed > 0 {
        bail!(
            "{failed} stale work folder(s) or output leftovers in {} could not be removed",
            dir.display()
        );
    }
    Ok(())
}

fn format_age(s: u64) -> String {
    match s {
        0..=119 => format!("{s} s old"),
        120..=7199 => format!("{} min old", s / 60),
        7200..=172_799 => format!("{} h old", s / 3600),
        _ => format!("{} days old", s / 86_400),
    }
}
