//! The voxlod on-disk octree format. Renderers depend on this crate alone.
//!
//! (Crate documentation with an example is being written together with the container.)

pub mod voxel;

pub use voxel::Voxel;
