//! Shared by the viewer's tests: what a node costs in the cache and where it sits in the tree,
//! recomputed from the file.

use voxlod_format::Reader;

/// Bytes of node `i`'s face buffer, from its voxels' face masks (28 bytes per active face).
pub fn face_bytes(r: &Reader, i: usize) -> u64 {
    r.read_node(i)
        .unwrap()
        .iter()
        .map(|v| v.mask().count_ones() as u64 * 28)
        .sum()
}

/// The ancestors of node `i`, parent first, up to the root.
pub fn ancestors(r: &Reader, mut i: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let root = r.root().unwrap();
    while i != root {
        let e = r.nodes()[i];
        i = r.find(e.level + 1, e.pos().map(|p| p / 2)).unwrap();
        out.push(i);
    }
    out
}
