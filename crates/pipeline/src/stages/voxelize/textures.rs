//! The build's textures: decoded once from the material table ingest found
//! ([`voxlod_ingest::MeshInfo::materials`]) and handed to the CPU chunk voxelizers
//! (docs/TEXTURES.md), inside the memory plan: whole in memory when the decoded pyramids fit
//! the plan's texture share ([`crate::memory::MemoryPlan::texture_share`]), otherwise tiled to the work
//! folder's `textures.tiles` and read through a tile cache of that share
//! ([`TextureSet::load_within`]). A texture that cannot be read is a warning naming the file.

use std::sync::Arc;

use serde::Serialize;
use voxlod_ingest::MeshInfo;
use voxlod_texture::TextureSet;

use crate::context::BuildContext;
use crate::error::StageError;
use crate::files::work::WorkFile;
use crate::size::format_size;

/// The tile cache of a build whose decoded textures exceed their share of the plan
/// (`--json` `texture_cache`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct TextureCacheSummary {
    /// Bytes of the decoded pyramids (what holding them whole would take).
    pub decoded_bytes: u64,
    /// The cache's capacity: the plan's texture share, bytes.
    pub capacity: u64,
    /// The most bytes of tiles the cache held at once.
    pub peak_resident: u64,
    /// Tiles (64×64 RGBA8, 16 KiB) read from the tile file.
    pub tile_reads: u64,
    /// Size of the tile file in the work folder, bytes.
    pub file_bytes: u64,
    /// True if the tile file of the interrupted build was reused (complete, CRC checked).
    pub reused: bool,
}

/// The textures of the mesh, `None` if it has no texture coordinates or no usable texture;
/// what could not be used goes to the warnings. Sets the plan's texture part
/// ([`crate::memory::MemoryPlan::with_textures`]). An error is a failure to write the tile file.
pub(crate) fn load(ctx: &mut BuildContext) -> Result<Option<Arc<TextureSet>>, StageError> {
    let info = ctx.source.info();
    if !info.has_texcoords {
        return Ok(None);
    }
    let share = ctx.memory.texture_share();
    let file = ctx.work.file(WorkFile::TextureTiles);
    let set = TextureSet::load_within(&info.materials, share, &file)
        .map_err(|e| StageError::Other(anyhow::anyhow!(e)))?;
    let input = ctx.input.display();
    ctx.warnings
        .extend(set.warnings.iter().map(|w| format!("{input}: {w}")));
    if set.is_empty() {
        return Ok(None);
    }
    ctx.memory = ctx.memory.with_textures(set.bytes() as u64);
    if let Some(t) = set.tiles() {
        if ctx.progress {
            eprintln!(
                "textures: {} decoded, more than their {} share: read by 64×64 tile through a {} cache from {} ({}, {})",
                format_size(t.decoded_bytes),
                format_size(share),
                format_size(share),
                t.file.display(),
                if t.reused { "reused" } else { "written" },
                format_size(t.file_bytes)
            );
        }
    }
    Ok(Some(Arc::new(set)))
}

/// True if the build writes the per-voxel material channel (docs/FORMAT.md 14.3): the mesh's
/// material table names at least two materials besides entry 0. A mesh with at most one
/// material accumulates no material weights and its file is version 1, as before.
pub(crate) fn has_material_channel(info: &MeshInfo) -> bool {
    info.materials.len() > 2
}
