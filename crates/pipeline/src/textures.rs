//! The build's textures: decoded once from the material table ingest found
//! ([`voxlod_ingest::MeshInfo::materials`]) and handed to the CPU chunk voxelizers
//! (docs/TEXTURES.md). A texture that cannot be read is a warning naming the file.

use std::path::Path;
use std::sync::Arc;
use voxlod_ingest::MeshInfo;
use voxlod_texture::TextureSet;

/// The textures of `info`'s materials, `None` if the mesh has no texture coordinates or no
/// usable texture; what could not be used goes to `warnings`, and so does a set of decoded
/// textures larger than a quarter of the memory `budget` (they are not yet inside the plan).
pub(crate) fn load(
    info: &MeshInfo,
    input: &Path,
    budget: u64,
    warnings: &mut Vec<String>,
) -> Option<Arc<TextureSet>> {
    if !info.has_texcoords {
        return None;
    }
    let set = TextureSet::load(&info.materials);
    warnings.extend(
        set.warnings
            .iter()
            .map(|w| format!("{}: {w}", input.display())),
    );
    let bytes = set.bytes() as u64;
    if bytes > budget / 4 {
        warnings.push(format!(
            "the decoded textures take {:.0} MiB, held in memory outside the --memory plan ({:.0} MiB): peak memory can exceed the budget",
            bytes as f64 / (1u64 << 20) as f64,
            budget as f64 / (1u64 << 20) as f64
        ));
    }
    (!set.is_empty()).then(|| Arc::new(set))
}

/// True if the build writes the per-voxel material channel (docs/FORMAT.md 14.3): the mesh's
/// material table names at least two materials besides entry 0. A mesh with at most one
/// material accumulates no material weights and its file is version 1, as before.
pub(crate) fn has_material_channel(info: &MeshInfo) -> bool {
    info.materials.len() > 2
}
