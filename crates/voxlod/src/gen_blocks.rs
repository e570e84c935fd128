//! `voxlod gen --kind blocks`: a Minecraft-like block world with one texture per block face
//! material (`voxlod-blocks`), the scene of Chajdas et al. Figure 3, for builds with textures
//! and the per-voxel material channel.

use std::path::Path;

use anyhow::Result;
use voxlod_pipeline::format_size;

/// Generates the `size × size` world of `seed` and writes it to `obj` (with its MTL and
/// textures beside it), then prints what was written.
pub fn run(obj: &Path, size: u32, seed: u64, force: bool) -> Result<()> {
    let world = voxlod_blocks::World::generate(size, seed)?;
    let w = voxlod_blocks::write_world(&world, obj, force)?;
    println!(
        "wrote {}: a {size}x{size} block world (seed {seed}, {} blocks high, {} trees), \
         {} faces, {} triangles, {} vertices; with {} and {} textures, {} in all",
        obj.display(),
        world.top(),
        world.trees(),
        w.faces,
        w.triangles,
        w.vertices,
        w.files[1].display(),
        w.files.len() - 2,
        format_size(w.bytes)
    );
    Ok(())
}
