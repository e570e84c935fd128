//! The grid a file covers ([`FileSpec`]): resolution, levels, voxelization mode and the
//! placement in world space, with the arithmetic that maps a node and a voxel to world
//! coordinates (`docs/FORMAT.md`, "Coordinates").

/// Voxels per chunk along one axis (chunks are 256³; positions inside are 8 bits).
pub const CHUNK: u32 = 256;
/// Largest number of voxels in one node (a full chunk).
pub const MAX_NODE_VOXELS: u32 = CHUNK * CHUNK * CHUNK;
/// `mode`: conservative (26-separating) voxelization.
pub const MODE_CONSERVATIVE: u32 = 0;
/// `mode`: thin (6-separating) voxelization.
pub const MODE_THIN: u32 = 1;

/// What a file covers; stored in the header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FileSpec {
    /// Leaf voxels per axis, `R = 256·2^k`, at most 2^31.
    pub resolution: u32,
    /// `k + 1` (see [`levels_for_resolution`]).
    pub levels: u32,
    /// [`MODE_CONSERVATIVE`] or [`MODE_THIN`].
    pub mode: u32,
    /// World coordinates of the grid's minimum corner.
    pub origin: [f64; 3],
    /// World units per leaf voxel (finite, > 0).
    pub voxel_size: f64,
}

/// Number of levels of a grid of `resolution` leaf voxels per axis (`k + 1` for
/// `R = 256·2^k`), or `None` if `resolution` is not of that form or exceeds 2^31.
pub fn levels_for_resolution(resolution: u32) -> Option<u32> {
    (resolution >= CHUNK && resolution.is_power_of_two())
        .then(|| resolution.trailing_zeros() - 8 + 1)
}

impl FileSpec {
    /// A spec whose `levels` follows from `resolution`.
    pub fn new(resolution: u32, mode: u32, origin: [f64; 3], voxel_size: f64) -> FileSpec {
        let levels = levels_for_resolution(resolution).unwrap_or(0);
        FileSpec {
            resolution,
            levels,
            mode,
            origin,
            voxel_size,
        }
    }

    /// Checks every rule above; the error says which one fails.
    pub fn validate(&self) -> Result<(), String> {
        let Some(levels) = levels_for_resolution(self.resolution) else {
            return Err(format!(
                "resolution {} is not 256·2^k (k ≥ 0, at most 2^31)",
                self.resolution
            ));
        };
        if self.levels != levels {
            return Err(format!(
                "levels is {} but resolution {} needs {levels}",
                self.levels, self.resolution
            ));
        }
        if self.mode > MODE_THIN {
            return Err(format!(
                "mode {} is neither 0 (conservative) nor 1 (thin)",
                self.mode
            ));
        }
        if !self.origin.iter().all(|c| c.is_finite()) {
            return Err(format!("origin {:?} is not finite", self.origin));
        }
        if !(self.voxel_size.is_finite() && self.voxel_size > 0.0) {
            return Err(format!(
                "voxel size {} is not finite and positive",
                self.voxel_size
            ));
        }
        Ok(())
    }

    /// Chunks per axis at `level`: `(R/256) >> level` (1 at the root level).
    pub fn chunks_per_axis(&self, level: u32) -> u32 {
        (self.resolution / CHUNK).checked_shr(level).unwrap_or(0)
    }

    /// True if `level < levels` and `pos` lies inside that level's grid.
    pub fn contains_node(&self, level: u32, pos: [u32; 3]) -> bool {
        level < self.levels && pos.iter().all(|&p| p < self.chunks_per_axis(level))
    }

    /// Edge length in world units of one voxel at `level`: `voxel_size · 2^level`.
    pub fn voxel_size_at(&self, level: u32) -> f64 {
        self.voxel_size * (level as f64).exp2()
    }

    /// World coordinates of the minimum corner of voxel `voxel_pos` in node `node_pos` at
    /// `level`: `origin + voxel_size · 2^level · (node_pos·256 + voxel_pos)`. The voxel is the
    /// cube from there with edge [`voxel_size_at`](Self::voxel_size_at)`(level)`.
    pub fn voxel_min_corner(&self, level: u32, node_pos: [u32; 3], voxel_pos: [u8; 3]) -> [f64; 3] {
        let s = self.voxel_size_at(level);
        std::array::from_fn(|a| {
            self.origin[a] + s * (node_pos[a] as f64 * CHUNK as f64 + voxel_pos[a] as f64)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_and_grid() {
        assert_eq!(levels_for_resolution(256), Some(1));
        assert_eq!(levels_for_resolution(16384), Some(7));
        assert_eq!(levels_for_resolution(1 << 31), Some(24));
        assert_eq!(levels_for_resolution(128), None);
        assert_eq!(levels_for_resolution(768), None);
        let s = FileSpec::new(1024, MODE_THIN, [1.0, 2.0, 3.0], 0.5);
        assert_eq!(s.levels, 3);
        assert!(s.validate().is_ok());
        assert_eq!(
            (
                s.chunks_per_axis(0),
                s.chunks_per_axis(1),
                s.chunks_per_axis(2)
            ),
            (4, 2, 1)
        );
        assert!(
            s.contains_node(1, [1, 1, 0])
                && !s.contains_node(1, [2, 0, 0])
                && !s.contains_node(3, [0; 3])
        );
        // level 1 node (1,0,0), voxel (3,0,0): 0.5·2·(256+3) + 1
        assert_eq!(
            s.voxel_min_corner(1, [1, 0, 0], [3, 0, 0]),
            [260.0, 2.0, 3.0]
        );
        let mut bad = s;
        bad.levels = 4;
        assert!(bad.validate().unwrap_err().contains("needs 3"));
        bad = s;
        bad.voxel_size = 0.0;
        assert!(bad.validate().is_err());
        bad = s;
        bad.origin[1] = f64::NAN;
        assert!(bad.validate().is_err());
    }
}
