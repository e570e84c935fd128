//! `verify`: every checksum and invariant of a voxlod file (docs/FORMAT.md sections 4–8),
//! with the LOD rule recomputed independently of the writer: each parent must equal the
//! sort-and-compact merge of its stored children (Chajdas, Reitinger & Westermann 2014,
//! section 4), computed here by `voxlod_lod::MergeScratch`; in a file with the material
//! channel (FORMAT.md 14.3) every node's materials are decoded with their checks and each
//! parent's compared with `voxlod_lod::merge_materials` of its children's; in a file with
//! source geometry (FORMAT.md 14.4) every leaf's triangles are checked by `source.rs`.
//!
//! Nodes are visited in index order, which is a post-order, so a parent comes after all its
//! children; decoded children wait in a map until their parent is checked, which bounds
//! memory by the octree's frontier rather than the file.

use std::collections::HashMap;
use std::path::Path;

use serde::Serialize;
use voxlod_format::voxel::{border_caps, face_mask};
use voxlod_format::{FormatError, Reader, Voxel};
use voxlod_lod::{merge_materials, MergeScratch};

/// One failed check. `level`/`pos`/`index` name the node when the failure is in one.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Problem {
    /// Index of the node in the node index, if the problem is in a node.
    pub index: Option<usize>,
    /// The node's level.
    pub level: Option<u32>,
    /// The node's position in chunks at its level.
    pub pos: Option<[u32; 3]>,
    /// What is wrong.
    pub what: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.index, self.level, self.pos) {
            (Some(i), Some(l), Some(p)) => {
                write!(f, "node {i} (level {l}, position {p:?}): {}", self.what)
            }
            _ => write!(f, "{}", self.what),
        }
    }
}

/// What [`verify`] found.
#[derive(Clone, Debug, Default, Serialize)]
pub struct VerifyReport {
    /// True if the container opened (header, index, manifest and tree structure are valid);
    /// when false, no node was checked and `problems` says why.
    pub opened: bool,
    /// Nodes in the index.
    pub nodes: usize,
    /// Nodes whose payload decoded with all checksums right.
    pub nodes_decoded: usize,
    /// Voxels over all levels (the header's count).
    pub voxels: u64,
    /// Parents compared against the merge of their children.
    pub parents_checked: usize,
    /// Level-0 voxels whose face mask was checked.
    pub leaf_voxels_checked: u64,
    /// Parents whose materials were compared with the material LOD rule (0 without the
    /// material channel).
    pub materials_checked: usize,
    /// Source triangles checked (FORMAT.md 14.4: decoded, each touching its chunk's box; 0
    /// without the source-geometry channel).
    pub source_triangles_checked: u64,
    /// Every failed check.
    pub problems: Vec<Problem>,
}

impl VerifyReport {
    /// True when every check passed.
    pub fn ok(&self) -> bool {
        self.opened && self.problems.is_empty()
    }
}

/// Checks the file at `path` completely; never panics, whatever the bytes. See the crate docs
/// for the list of checks. A file that does not open reports the one reason why.
pub fn verify(path: &Path) -> VerifyReport {
    // The crate docs' list of checks, in that order, each adding to one report.
    let mut report = VerifyReport::default();
    let reader = match Reader::open(path) {
        Ok(r) => r,
        Err(e) => {
            report.problems.push(problem_from(&e));
            return report;
        }
    };
    report.opened = true;
    report.nodes = reader.nodes().len();
    report.voxels = reader.total_voxels();
    let spec = reader.spec();

    // decoded nodes waiting for their parent; `None` marks a node that failed to decode
    let mut pending: HashMap<usize, Option<Vec<Voxel>>> = HashMap::new();
    let mut merge = MergeScratch::new();
    let mut merged = Vec::new();
    // the material channel: decoded materials of nodes waiting for their parent
    let materials = reader.has_materials();
    let mut pending_mats: HashMap<usize, Vec<u32>> = HashMap::new();
    // the source-geometry channel: the manifest's material count bounds the triangles' ids
    let source = reader.has_source_triangles();
    let material_names = reader
        .manifest()
        .ok()
        .and_then(|m| m["materials"].as_array().map(Vec::len));
    for (i, e) in reader.nodes().iter().enumerate() {
        let node_problem = |what: String| Problem {
            index: Some(i),
            level: Some(e.level),
            pos: Some(e.pos()),
            what,
        };
        if source && e.level == 0 {
            match crate::source::check_leaf(&reader, i, material_names) {
                Ok(n) => report.source_triangles_checked += n,
                Err(whats) => report.problems.extend(whats.into_iter().map(&node_problem)),
            }
        }
        let voxels = match reader.read_node(i) {
            Ok(v) => {
                report.nodes_decoded += 1;
                Some(v)
            }
            Err(err) => {
                report.problems.push(node_problem(what_of(&err)));
                None
            }
        };
        let children: Vec<(usize, Option<usize>)> =
            reader.children(i).into_iter().enumerate().collect();
        let kids: Vec<(usize, usize, Option<Vec<Voxel>>)> = children
            .iter()
            .filter_map(|&(o, c)| c.map(|c| (o, c, pending.remove(&c).flatten())))
            .collect();
        let mats = if materials {
            match reader.read_materials(i) {
                Ok(m) => m,
                Err(err) => {
                    report.problems.push(node_problem(what_of(&err)));
                    None
                }
            }
        } else {
            None
        };
        let kid_mats: Vec<Option<Vec<u32>>> = kids
            .iter()
            .map(|&(_, c, _)| pending_mats.remove(&c))
            .collect();
        let Some(voxels) = voxels else {
            continue;
        };
        if let Some(m) = &mats {
            if e.level > 0
                && kids.iter().all(|k| k.2.is_some())
                && kid_mats.iter().all(Option::is_some)
            {
                let mut slices: [&[Voxel]; 8] = [&[]; 8];
                let mut mslices: [&[u32]; 8] = [&[]; 8];
                for ((o, _, v), km) in kids.iter().zip(&kid_mats) {
                    slices[*o] = v.as_deref().unwrap_or(&[]);
                    mslices[*o] = km.as_deref().unwrap_or(&[]);
                }
                report.materials_checked += 1;
                let want = merge_materials(&slices, &mslices);
                if let Some(j) = (0..m.len().max(want.len())).find(|&j| m.get(j) != want.get(j)) {
                    report.problems.push(node_problem(format!(
                        "materials are not the LOD rule's (the most frequent among the children, ties to the smallest id): first difference at voxel {j}: stored {:?}, rule {:?}",
                        m.get(j),
                        want.get(j)
                    )));
                }
            } else if e.level > 0 {
                report.problems.push(node_problem(
                    "materials not compared with the LOD rule: a child's voxels or materials failed to decode".into(),
                ));
            }
            if e.level + 1 < spec.levels {
                pending_mats.insert(i, m.clone());
            }
        }
        if voxels.len() != e.voxel_count as usize {
            report.problems.push(node_problem(format!(
                "decoded {} voxels, the index says {}",
                voxels.len(),
                e.voxel_count
            )));
        }
        if e.level == 0 {
            check_leaf_masks(&voxels, &mut report.problems, &node_problem);
            report.leaf_voxels_checked += voxels.len() as u64;
        } else if kids.iter().all(|k| k.2.is_some()) {
            let mut slices: [&[Voxel]; 8] = [&[]; 8];
            for (o, _, v) in &kids {
                slices[*o] = v.as_deref().unwrap_or(&[]);
            }
            check_children_inside(&voxels, &slices, &mut report.problems, &node_problem);
            merge.merge(&slices, &mut merged);
            report.parents_checked += 1;
            if let Some(what) = compare_merge(&voxels, &merged) {
                report.problems.push(node_problem(what));
            }
        } else {
            report.problems.push(node_problem(
                "not compared with the merge of its children: a child failed to decode".into(),
            ));
        }
        let is_root = e.level + 1 == spec.levels;
        if !is_root {
            pending.insert(i, Some(voxels));
        }
    }
    report
}

fn problem_from(e: &FormatError) -> Problem {
    match e {
        FormatError::Node {
            index, level, pos, ..
        } => Problem {
            index: Some(*index),
            level: Some(*level),
            pos: Some(*pos),
            what: e.to_string(),
        },
        _ => Problem {
            index: None,
            level: None,
            pos: None,
            what: e.to_string(),
        },
    }
}

/// The part of a node error after the node's name (the problem names the node itself).
fn what_of(e: &FormatError) -> String {
    match e {
        FormatError::Node { what, .. } => what.clone(),
        other => other.to_string(),
    }
}

/// Level-0 masks are exactly `face_mask(normal) | border_caps(pos)` (FORMAT.md section 6).
fn check_leaf_masks(voxels: &[Voxel], out: &mut Vec<Problem>, problem: &dyn Fn(String) -> Problem) {
    let mut bad = voxels
        .iter()
        .filter(|v| v.mask() != face_mask(v.normal) | border_caps(v.pos()));
    if let Some(first) = bad.next() {
        let count = 1 + bad.count();
        out.push(problem(format!(
            "{count} leaf voxels have a face mask other than face_mask(normal) | border_caps(pos); first at {:?}: mask {:#08b}, expected {:#08b}",
            first.pos(),
            first.mask(),
            face_mask(first.normal) | border_caps(first.pos())
        )));
    }
}

/// Every child voxel maps to a parent voxel whose mask contains the child's (the OR-merge's
/// covering guarantee that culling relies on). Stated separately from the merge comparison so
/// the report says which guarantee broke.
fn check_children_inside(
    parent: &[Voxel],
    children: &[&[Voxel]; 8],
    out: &mut Vec<Problem>,
    problem: &dyn Fn(String) -> Problem,
) {
    let by_pos: HashMap<[u8; 3], u8> = parent.iter().map(|v| (v.pos(), v.mask())).collect();
    let mut missing = 0usize;
    let mut uncovered = 0usize;
    let mut first = None;
    for (octant, child) in children.iter().enumerate() {
        for v in child.iter() {
            let (p, _) = voxlod_lod::parent_key(octant, v.pos());
            match by_pos.get(&p) {
                None => missing += 1,
                Some(&m) if m & v.mask() != v.mask() => uncovered += 1,
                Some(_) => continue,
            }
            first.get_or_insert((octant, v.pos(), p));
        }
    }
    if let Some((octant, c, p)) = first {
        out.push(problem(format!(
            "children not inside the parent: {missing} child voxels have no parent voxel, {uncovered} have faces the parent voxel lacks; first: child octant {octant} voxel {c:?} → parent voxel {p:?}"
        )));
    }
}

/// `None` if `stored` equals `merged`, else a description of the first difference.
fn compare_merge(stored: &[Voxel], merged: &[Voxel]) -> Option<String> {
    if stored == merged {
        return None;
    }
    let first = stored
        .iter()
        .zip(merged.iter())
        .position(|(a, b)| a != b)
        .unwrap_or(stored.len().min(merged.len()));
    let show = |v: Option<&Voxel>| match v {
        Some(v) => format!(
            "pos {:?} mask {:#08b} normal {:#010x} rgba {:?}",
            v.pos(),
            v.mask(),
            v.normal,
            v.rgba()
        ),
        None => "none".into(),
    };
    Some(format!(
        "voxels are not the OR-merge of its children ({} stored, {} merged); first difference at voxel {first}: stored {}, merged {}",
        stored.len(),
        merged.len(),
        show(stored.get(first)),
        show(merged.get(first))
    ))
}
