//! `diff`: chunk-level comparison of two voxlod files for regression tests.
//!
//! Nodes are matched by (level, position). Equal payload bytes mean identical without decoding;
//! otherwise both are decoded and merged by Morton order (both are sorted by it, FORMAT.md
//! 5.1), giving the voxel-set difference and, on common voxels, the largest normal angle,
//! colour channel difference and the number of face-mask differences. Two files on different
//! grids (resolution, origin or voxel size) share no chunk: every node is reported as removed
//! and added, and the report says so.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;
use voxlod_format::voxel::unpack_normal;
use voxlod_format::{FormatError, Reader, Voxel};

/// Node identity: level and position in chunks at that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct NodeId {
    /// Level (0 = leaves).
    pub level: u32,
    /// Position in chunks at that level.
    pub pos: [u32; 3],
}

impl std::fmt::Display for NodeId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "level {} ({}, {}, {})",
            self.level, self.pos[0], self.pos[1], self.pos[2]
        )
    }
}

/// What a diff may accept and still call the files equal. The default accepts nothing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    /// Largest accepted angle between the normals of a common voxel, in degrees. Face masks
    /// follow from normals, so a tolerance above 0 also accepts face-mask differences.
    pub max_normal_deg: f64,
    /// Largest accepted difference of one colour channel (0–255).
    pub max_color: u8,
    /// Smallest accepted intersection-over-union of a changed node's voxel positions.
    pub min_iou: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            max_normal_deg: 0.0,
            max_color: 0,
            min_iou: 1.0,
        }
    }
}

/// A header field that differs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldDiff {
    /// Field name as in FORMAT.md.
    pub field: String,
    /// Value in the first file.
    pub a: String,
    /// Value in the second file.
    pub b: String,
}

/// A node present in both files with different voxels.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChangedNode {
    /// Which node.
    pub node: NodeId,
    /// Voxels in the first file's node.
    pub voxels_a: usize,
    /// Voxels in the second file's node.
    pub voxels_b: usize,
    /// Positions only in the second file.
    pub added: usize,
    /// Positions only in the first file.
    pub removed: usize,
    /// Positions in both.
    pub common: usize,
    /// `common / (common + added + removed)`.
    pub iou: f64,
    /// Largest angle between the normals of a common voxel, degrees (180 when one of them is
    /// the zero normal and the other not).
    pub max_normal_deg: f64,
    /// Largest absolute difference of one RGBA channel on a common voxel.
    pub max_color_diff: u8,
    /// Common voxels whose face masks differ.
    pub mask_diffs: usize,
    /// True if this node's differences are inside the tolerance.
    pub within_tolerance: bool,
}

/// What [`diff`] found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DiffReport {
    /// The two files.
    pub a: String,
    /// See `a`.
    pub b: String,
    /// The tolerance the changes were judged by.
    pub tolerance: Tolerance,
    /// False when resolution, origin or voxel size differ: then no chunk corresponds and every
    /// node is listed as removed and added.
    pub same_grid: bool,
    /// Header fields that describe the octree and differ (resolution, levels, mode, origin,
    /// voxel size). The manifest (timings, paths) is not compared.
    pub header: Vec<FieldDiff>,
    /// Nodes in both files with the same voxels.
    pub identical: usize,
    /// Nodes only in the second file.
    pub added: Vec<NodeId>,
    /// Nodes only in the first file.
    pub removed: Vec<NodeId>,
    /// Nodes in both with different voxels.
    pub changed: Vec<ChangedNode>,
}

impl DiffReport {
    /// True when the files hold the same octree: no header, node or voxel difference.
    pub fn identical(&self) -> bool {
        self.header.is_empty()
            && self.added.is_empty()
            && self.removed.is_empty()
            && self.changed.is_empty()
    }
    /// True when the files are identical or differ only inside the tolerance: same header,
    /// the same nodes, and every changed node within it.
    pub fn within_tolerance(&self) -> bool {
        self.header.is_empty()
            && self.added.is_empty()
            && self.removed.is_empty()
            && self.changed.iter().all(|c| c.within_tolerance)
    }
}

/// Why a diff could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiffError {
    /// A file did not open or a node did not decode (the message names the file and node).
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// Compares files `a` and `b` chunk by chunk, judging changed nodes by `tol`.
pub fn diff(a: &Path, b: &Path, tol: &Tolerance) -> Result<DiffReport, DiffError> {
    let ra = Reader::open(a)?;
    let rb = Reader::open(b)?;
    let (ha, hb) = (ra.header(), rb.header());
    let mut header = Vec::new();
    let mut field = |name: &str, x: String, y: String| {
        if x != y {
            header.push(FieldDiff {
                field: name.into(),
                a: x,
                b: y,
            });
        }
    };
    field(
        "resolution",
        ha.resolution.to_string(),
        hb.resolution.to_string(),
    );
    field("levels", ha.levels.to_string(), hb.levels.to_string());
    let mode = |m: u32| match m {
        0 => "conservative".to_string(),
        1 => "thin".to_string(),
        m => m.to_string(),
    };
    field("mode", mode(ha.mode), mode(hb.mode));
    // exact comparison of the bits: a regression test wants to know about any change
    field(
        "origin",
        format!("{:?}", ha.origin),
        format!("{:?}", hb.origin),
    );
    field(
        "voxel_size",
        format!("{:?}", ha.voxel_size),
        format!("{:?}", hb.voxel_size),
    );
    let same_grid = ha.resolution == hb.resolution
        && ha.origin.map(f64::to_bits) == hb.origin.map(f64::to_bits)
        && ha.voxel_size.to_bits() == hb.voxel_size.to_bits();

    let ids = |r: &Reader| -> BTreeMap<NodeId, usize> {
        r.nodes()
            .iter()
            .enumerate()
            .map(|(i, e)| {
                (
                    NodeId {
                        level: e.level,
                        pos: e.pos(),
                    },
                    i,
                )
            })
            .collect()
    };
    let (na, nb) = (ids(&ra), ids(&rb));
    let mut report = DiffReport {
        a: a.display().to_string(),
        b: b.display().to_string(),
        tolerance: *tol,
        same_grid,
        header,
        identical: 0,
        added: Vec::new(),
        removed: Vec::new(),
        changed: Vec::new(),
    };
    if !same_grid {
        report.removed = na.keys().copied().collect();
        report.added = nb.keys().copied().collect();
        return Ok(report);
    }
    report.removed = na.keys().filter(|k| !nb.contains_key(k)).copied().collect();
    report.added = nb.keys().filter(|k| !na.contains_key(k)).copied().collect();
    let (mut va, mut vb) = (Vec::new(), Vec::new());
    let (mut pa, mut pb) = (Vec::new(), Vec::new());
    for (id, &ia) in &na {
        let Some(&ib) = nb.get(id) else { continue };
        ra.read_payload_into(ia, &mut pa)?;
        rb.read_payload_into(ib, &mut pb)?;
        if pa == pb {
            // same bytes, same checksums: still decode, so a corrupt payload is not "identical"
            ra.read_node_into(ia, &mut va)?;
            rb.read_node_into(ib, &mut vb)?;
            report.identical += 1;
            continue;
        }
        ra.read_node_into(ia, &mut va)?;
        rb.read_node_into(ib, &mut vb)?;
        match compare_voxels(*id, &va, &vb, tol) {
            None => report.identical += 1,
            Some(c) => report.changed.push(c),
        }
    }
    Ok(report)
}

/// Compares two Morton-sorted voxel lists; `None` if equal.
fn compare_voxels(node: NodeId, a: &[Voxel], b: &[Voxel], tol: &Tolerance) -> Option<ChangedNode> {
    if a == b {
        return None;
    }
    let (mut i, mut j) = (0, 0);
    let (mut added, mut removed, mut common, mut mask_diffs) = (0, 0, 0, 0);
    let mut max_deg = 0f64;
    let mut max_col = 0u8;
    while i < a.len() || j < b.len() {
        let ka = a.get(i).map(Voxel::morton);
        let kb = b.get(j).map(Voxel::morton);
        match (ka, kb) {
            (Some(x), Some(y)) if x == y => {
                let (u, v) = (&a[i], &b[j]);
                common += 1;
                mask_diffs += (u.mask() != v.mask()) as usize;
                max_deg = max_deg.max(normal_angle_deg(u.normal, v.normal));
                for (p, q) in u.rgba().iter().zip(v.rgba().iter()) {
                    max_col = max_col.max(p.abs_diff(*q));
                }
                i += 1;
                j += 1;
            }
            (Some(x), Some(y)) if x < y => {
                removed += 1;
                i += 1;
            }
            (Some(_), None) => {
                removed += 1;
                i += 1;
            }
            _ => {
                added += 1;
                j += 1;
            }
        }
    }
    let union = common + added + removed;
    let iou = if union == 0 {
        1.0
    } else {
        common as f64 / union as f64
    };
    let within = iou >= tol.min_iou
        && max_deg <= tol.max_normal_deg
        && max_col <= tol.max_color
        && (mask_diffs == 0 || tol.max_normal_deg > 0.0);
    Some(ChangedNode {
        node,
        voxels_a: a.len(),
        voxels_b: b.len(),
        added,
        removed,
        common,
        iou,
        max_normal_deg: max_deg,
        max_color_diff: max_col,
        mask_diffs,
        within_tolerance: within,
    })
}

/// Angle in degrees between two packed normals; 0 for two zero normals, 180 for a zero and a
/// non-zero one.
fn normal_angle_deg(a: u32, b: u32) -> f64 {
    if a == b {
        return 0.0;
    }
    let (p, q) = (unpack_normal(a), unpack_normal(b));
    let dot: f64 = (0..3).map(|k| p[k] as f64 * q[k] as f64).sum();
    let len = |v: [i32; 3]| v.iter().map(|&c| (c as f64).powi(2)).sum::<f64>().sqrt();
    let (lp, lq) = (len(p), len(q));
    if lp == 0.0 && lq == 0.0 {
        return 0.0;
    }
    if lp == 0.0 || lq == 0.0 {
        return 180.0;
    }
    (dot / (lp * lq)).clamp(-1.0, 1.0).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_format::voxel::{pack_color, pack_normal};

    #[test]
    fn voxel_comparison() {
        let n = pack_normal([1.0, 0.0, 0.0]);
        let m = pack_normal([0.0, 1.0, 0.0]);
        let v = |p: [u8; 3], n: u32, r: u8| Voxel::new(p, 1, n, pack_color([r, 0, 0, 255]));
        let a = vec![
            v([1, 0, 0], n, 10),
            v([0, 1, 0], n, 10),
            v([1, 1, 0], n, 10),
        ];
        let b = vec![v([1, 0, 0], m, 13), v([1, 1, 0], n, 10), v([0, 0, 1], n, 0)];
        let id = NodeId {
            level: 0,
            pos: [0; 3],
        };
        let c = compare_voxels(id, &a, &b, &Tolerance::default()).unwrap();
        assert_eq!((c.added, c.removed, c.common), (1, 1, 2));
        assert!((c.iou - 0.5).abs() < 1e-12);
        assert!((c.max_normal_deg - 90.0).abs() < 1e-9);
        assert_eq!(c.max_color_diff, 3);
        assert!(!c.within_tolerance);
        let loose = Tolerance {
            max_normal_deg: 90.0,
            max_color: 3,
            min_iou: 0.5,
        };
        assert!(compare_voxels(id, &a, &b, &loose).unwrap().within_tolerance);
        assert!(compare_voxels(id, &a, &a, &loose).is_none());
        assert_eq!(normal_angle_deg(0, n), 180.0);
        assert_eq!(normal_angle_deg(0, 0), 0.0);
    }
}
