//! A deterministic Minecraft-like block world for voxlod (`voxlod gen --kind blocks`): the
//! kind of scene Chajdas, Reitinger & Westermann ("Scalable rendering for very large meshes",
//! WSCG 2014, section 3.1 and Figure 3) render with per-face data, a material per block face
//! and a texture per material. No shared mesh is a block world, so this makes one: seeded
//! heightmap terrain with grass, dirt, stone, sand, water and trees (`world.rs`, `noise.rs`),
//! its exposed faces only (`faces.rs`), written as OBJ + MTL with one small procedural PNG
//! texture per face material (`textures.rs`, `obj.rs`). The same size and seed give the same
//! bytes on every machine.
//!
//! On a grid of `k` voxels per block (a power-of-two world size `n` built at resolution
//! `k·n`) every block face covers `k × k` voxels exactly, which is what the tests use to check
//! each voxel's material and colour against the block it lies on.

mod faces;
mod noise;
mod obj;
mod textures;
mod world;

use std::path::PathBuf;

pub use faces::{exposed, exposed_faces, face_material, Face, Material, DIRS};
pub use obj::{write_world, Written};
pub use textures::{png_bytes, texels, TEXTURE_SIZE};
pub use world::{Block, World, MAX_SIZE, MIN_SIZE, SEA_LEVEL};

/// What can go wrong generating or writing a block world.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The world size is out of range.
    #[error("world size {0} is out of range: give {MIN_SIZE} to {MAX_SIZE} columns per side")]
    Size(u32),
    /// The output is not named `*.obj`.
    #[error("{0}: a block world is written as OBJ: name the output NAME.obj")]
    NotObj(PathBuf),
    /// The output's name has white space, which `mtllib` and `map_Kd` cannot name.
    #[error(
        "{0}: the name has white space, which the OBJ's mtllib and the MTL's map_Kd cannot name"
    )]
    WhiteSpace(PathBuf),
    /// The output's folder does not exist.
    #[error("{0}: no such folder (the output's folder must exist)")]
    Folder(PathBuf),
    /// A file to write exists already.
    #[error("{0} exists (--force replaces it)")]
    Exists(PathBuf),
    /// Writing a file failed.
    #[error("writing {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Encoding a texture failed.
    #[error("encoding {path}: {message}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The encoder's message.
        message: String,
    },
}
