//! Level-of-detail by sort-and-compact (Chajdas, Reitinger & Westermann, "Scalable rendering
//! for very large meshes", WSCG 2014, section 4).
//!
//! A level k+1 chunk covers the 2×2×2 block of its eight level k children. Each child voxel
//! maps to the parent voxel `(octant·256 + pos) >> 1` per axis; voxels that map to the same
//! parent voxel form a *run*. Sort by parent position, find run starts with a prefix scan,
//! and *compact* each run into one voxel: face mask = OR of the run's masks (so the parent
//! covers its children, which culling relies on) plus the parent chunk's border caps,
//! normal and colour = the run's mean.
//!
//! ```
//! use voxlod_format::voxel::{pack_normal, pack_color, Voxel, FACE_POS_X, FACE_NEG_X, FACE_POS_Y};
//! use voxlod_lod::merge_children;
//! let n = pack_normal([1.0, 0.0, 0.0]);
//! let a = Voxel::new([10, 20, 30], FACE_POS_X, n, pack_color([255, 0, 0, 255]));
//! let b = Voxel::new([11, 20, 30], FACE_POS_Y, n, pack_color([0, 0, 255, 255]));
//! let octant0 = vec![a, b];
//! let mut children: [&[Voxel]; 8] = [&[]; 8];
//! children[0] = &octant0;
//! let parent = merge_children(&children);
//! assert_eq!(parent.len(), 1); // both map to parent voxel (5, 10, 15)
//! assert_eq!(parent[0].pos(), [5, 10, 15]);
//! assert_eq!(parent[0].mask(), FACE_POS_X | FACE_POS_Y);
//! assert_eq!(parent[0].rgba(), [128, 0, 128, 255]);
//! ```

mod material;
mod sort_compact;

pub use material::{halve_materials, merge_materials};
pub use sort_compact::{merge_children, parent_key, MergeScratch};
