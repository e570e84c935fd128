//! Shared by the viewer's tests: what a node costs in the cache and where it sits in the tree,
//! recomputed from the file.

use voxlod_format::Reader;

/// Bytes of node `i`'s voxel buffer, from the file: 12 bytes (the record's three words) per
/// voxel with a face.
pub fn voxel_bytes(r: &Reader, i: usize) -> u64 {
    r.read_node(i)
        .unwrap()
        .iter()
        .filter(|v| v.mask() != 0)
        .count() as u64
        * 12
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
