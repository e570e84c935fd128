//! Export never fills a disk by surprise: the size of an export is known before
//! its first byte is written (PLY and GLB count their faces first, a 3D Tiles tileset sums its
//! tiles), and an export larger than the free space of the output's file system, or than
//! 4 GiB unless `--max-size` allows more, is refused with the size, the limit, and the
//! coarsest level that fits (the first level, going coarser, whose estimate is under the
//! limit), so that nothing is written at all.

use std::path::Path;

use anyhow::{bail, Result};
use voxlod_format::Reader;
use voxlod_pipeline::format_size;

/// The largest export written without `--max-size`.
pub const DEFAULT_MAX_SIZE: u64 = 4 << 30;

/// The limits an export's size is checked against.
#[derive(Clone, Copy, Debug)]
pub struct SizeLimit {
    /// `--max-size`, if given.
    pub max_size: Option<u64>,
    /// Free bytes on the output's file system, if known.
    pub free: Option<u64>,
    /// The most the output's format can hold, and how to name it (a GLB: 4 GiB).
    pub format_cap: Option<(u64, &'static str)>,
}

impl SizeLimit {
    /// The limits for an output written inside folder `dir`.
    pub fn for_dir(max_size: Option<u64>, dir: &Path) -> SizeLimit {
        SizeLimit {
            max_size,
            free: voxlod_pipeline::free_disk(dir),
            format_cap: None,
        }
    }

    /// The limits with the output format's own cap (`bytes`, named `named`).
    pub fn with_format_cap(mut self, bytes: u64, named: &'static str) -> SizeLimit {
        self.format_cap = Some((bytes, named));
        self
    }

    /// The smaller limit and how to name it.
    pub fn limit(&self) -> (u64, String) {
        let cap = match self.max_size {
            Some(m) => (m, format!("--max-size {}", format_size(m))),
            None => (
                DEFAULT_MAX_SIZE,
                format!(
                    "the {} an export may write without --max-size",
                    format_size(DEFAULT_MAX_SIZE)
                ),
            ),
        };
        let cap = match self.format_cap {
            Some((b, named)) if b < cap.0 => (b, named.to_string()),
            _ => cap,
        };
        match self.free {
            Some(f) if f < cap.0 => (
                f,
                format!("the {} free on the output's file system", format_size(f)),
            ),
            _ => cap,
        }
    }

    /// Refuses `bytes` (the export of `level`) when over the limit. `estimate(l)` is the
    /// size of the same export at level `l`, for naming the coarsest level that fits.
    pub fn check(
        &self,
        what: &str,
        bytes: u64,
        level: u32,
        levels: u32,
        estimate: &dyn Fn(u32) -> u64,
    ) -> Result<()> {
        let (limit, named) = self.limit();
        if bytes <= limit {
            return Ok(());
        }
        let fits = (level + 1..levels)
            .map(|l| (l, estimate(l)))
            .find(|&(_, b)| b <= limit);
        let hint = match fits {
            Some((l, b)) => format!(
                "Level {l} is the coarsest that fits (about {}): --level {l}",
                format_size(b)
            ),
            None => "No coarser level fits either".into(),
        };
        let more = if self.free.is_some_and(|f| f <= limit) {
            "free space on that file system"
        } else if self.format_cap.is_some_and(|(b, _)| b == limit) {
            "write a PLY instead (-o NAME.ply), which has no such cap"
        } else {
            "allow more with --max-size SIZE"
        };
        bail!(
            "{what}: the export of level {level} would write {}, more than {named}; nothing was written. {hint}; or {more}.",
            format_size(bytes)
        );
    }
}

/// Voxels of each level, from the node index (no payload is read).
pub fn level_voxels(reader: &Reader) -> Vec<u64> {
    let mut v = vec![0u64; reader.spec().levels as usize];
    for e in reader.nodes() {
        v[e.level as usize] += e.voxel_count as u64;
    }
    v
}

/// An estimate for other levels from one level's exact size: bytes in proportion to voxels
/// (faces per voxel vary little from level to level of a surface).
pub fn proportional(reader: &Reader, level: u32, bytes: u64) -> impl Fn(u32) -> u64 {
    let voxels = level_voxels(reader);
    let per_voxel = bytes as f64 / voxels[level as usize].max(1) as f64;
    move |l| (voxels[l as usize] as f64 * per_voxel).ceil() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_over_the_limit_and_names_the_level_that_fits() {
        let l = SizeLimit {
            max_size: Some(1000),
            free: None,
            format_cap: None,
        };
        assert!(l.check("x", 1000, 0, 4, &|_| 0).is_ok());
        let e = l
            .check("out.ply", 5000, 0, 4, &|l| 5000 >> (2 * l))
            .unwrap_err()
            .to_string();
        // 5000, 1250, 312: level 2 is the first under 1000
        assert!(
            e.contains("Level 2 is the coarsest that fits (about 312 B): --level 2"),
            "{e}"
        );
        assert!(e.contains("more than --max-size 1000 B"), "{e}");
        assert!(e.contains("would write 4.88 KiB"), "{e}");
        assert!(e.contains("out.ply"), "{e}");
        // no --max-size: 4 GiB; a smaller free space wins and is named
        let l = SizeLimit {
            max_size: None,
            free: Some(100),
            format_cap: None,
        };
        let e = l.check("o", 101, 1, 2, &|_| 0).unwrap_err().to_string();
        assert!(e.contains("free on the output's file system"), "{e}");
        assert!(e.contains("No coarser level fits"), "{e}");
        let l = SizeLimit {
            max_size: None,
            free: None,
            format_cap: None,
        };
        assert!(l.check("o", DEFAULT_MAX_SIZE, 0, 1, &|_| 0).is_ok());
        assert!(l.check("o", DEFAULT_MAX_SIZE + 1, 0, 1, &|_| 0).is_err());
        // a GLB's 4 GiB cap, even with a larger --max-size: named, with the level that fits
        let glb = SizeLimit {
            max_size: Some(20 << 30),
            free: None,
            format_cap: None,
        }
        .with_format_cap(u32::MAX as u64, "the 4 GiB a GLB can hold");
        let e = glb
            .check("o.glb", 6 << 30, 0, 3, &|l| (6u64 << 30) >> (2 * l))
            .unwrap_err()
            .to_string();
        assert!(e.contains("more than the 4 GiB a GLB can hold"), "{e}");
        assert!(e.contains("Level 1 is the coarsest that fits"), "{e}");
        assert!(e.contains("write a PLY instead"), "{e}");
        assert!(glb.check("o.glb", 4 << 30, 0, 3, &|_| 0).is_err());
        assert!(glb.check("o.glb", (4 << 30) - 1, 0, 3, &|_| 0).is_ok());
    }
}
