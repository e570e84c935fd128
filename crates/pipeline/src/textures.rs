//! The build's textures: decoded once from the material table ingest found
//! ([`voxlod_ingest::MeshInfo::materials`]) and handed to the CPU chunk voxelizers
//! (docs/TEXTURES.md). A texture that cannot be read is a warning naming the file.

use std::path::Path;
use std::sync::Arc;
use voxlod_ingest::MeshInfo;
use voxlod_texture::TextureSet;

/// The textures of `info`'s materials, `None` if the mesh has no texture coordinates or no
/// usable texture; what could not be used goes to `warnings`.
pub(crate) fn load(
    info: &MeshInfo,
    input: &Path,
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
    (!set.is_empty()).then(|| Arc::new(set))
}
