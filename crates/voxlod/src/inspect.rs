//! `voxlod inspect`: what an octree file holds, as text or JSON.

use std::path::Path;

use anyhow::Result;
use serde::Serialize;
use voxlod_format::{Reader, CHANNEL_MATERIAL, CHANNEL_TRIANGLES};
use voxlod_pipeline::format_size;

#[derive(Serialize)]
struct LevelInfo {
    level: u32,
    nodes: u64,
    voxels: u64,
    payload_bytes: u64,
}

#[derive(Serialize)]
struct ChannelInfo {
    id: u32,
    name: &'static str,
    payload_bytes: u64,
    /// Source triangles stored (the triangle channel's entry counts summed; 0 for others).
    triangles: u64,
}

/// The name of an optional channel (FORMAT.md 14); ids this version does not read are listed
/// as "unknown".
fn channel_name(id: u32) -> &'static str {
    match id {
        CHANNEL_MATERIAL => "materials",
        CHANNEL_TRIANGLES => "source triangles",
        _ => "unknown",
    }
}

#[derive(Serialize)]
struct FileInfo {
    file: String,
    format_version: u32,
    resolution: u32,
    levels: u32,
    mode: String,
    origin: [f64; 3],
    voxel_size: f64,
    nodes: u64,
    voxels: u64,
    bytes: u64,
    bytes_per_voxel: f64,
    per_level: Vec<LevelInfo>,
    channels: Vec<ChannelInfo>,
    manifest: serde_json::Value,
}

fn gather(path: &Path) -> Result<FileInfo> {
    // the reader's errors name the file
    let r = Reader::open(path)?;
    let h = r.header();
    let mut per_level: Vec<LevelInfo> = (0..h.levels)
        .map(|level| LevelInfo {
            level,
            nodes: 0,
            voxels: 0,
            payload_bytes: 0,
        })
        .collect();
    for n in r.nodes() {
        let l = &mut per_level[n.level as usize];
        l.nodes += 1;
        l.voxels += n.voxel_count as u64;
        l.payload_bytes += n.payload_size;
    }
    let voxels: u64 = per_level.iter().map(|l| l.voxels).sum();
    let bytes = r.file_size();
    let mode = match h.mode {
        0 => "conservative".to_string(),
        1 => "thin".to_string(),
        m => format!("unknown ({m})"),
    };
    Ok(FileInfo {
        file: path.display().to_string(),
        format_version: h.version,
        resolution: h.resolution,
        levels: h.levels,
        mode,
        origin: h.origin,
        voxel_size: h.voxel_size,
        nodes: r.nodes().len() as u64,
        voxels,
        bytes,
        bytes_per_voxel: if voxels > 0 {
            bytes as f64 / voxels as f64
        } else {
            0.0
        },
        per_level,
        channels: r
            .channel_ids()
            .into_iter()
            .map(|id| ChannelInfo {
                id,
                name: channel_name(id),
                payload_bytes: r.channel_payload_bytes(id),
                triangles: if id == CHANNEL_TRIANGLES {
                    r.source_triangle_count()
                } else {
                    0
                },
            })
            .collect(),
        manifest: r.manifest()?,
    })
}

/// The material legend of a file's manifest (FORMAT.md 14.3: `"materials"` names the ids):
/// one line per material id, `id  #rrggbb  name`, the colour being the one `render --color
/// material` paints that id with ([`voxlod_render::material_color`]); id 0 is "no material".
/// Empty without a `"materials"` list.
pub fn material_legend(manifest: &serde_json::Value) -> Vec<String> {
    let Some(names) = manifest.get("materials").and_then(|m| m.as_array()) else {
        return Vec::new();
    };
    names
        .iter()
        .enumerate()
        .map(|(id, name)| {
            let [r, g, b, _] = voxlod_render::material_color(id as u32);
            let name = match name.as_str() {
                Some("") if id == 0 => "(no material)".to_owned(),
                Some(n) => n.to_owned(),
                None => name.to_string(),
            };
            format!("{id:>5}  #{r:02x}{g:02x}{b:02x}  {name}")
        })
        .collect()
}

pub fn run(path: &Path, json: bool) -> Result<()> {
    let info = gather(path)?;
    if json {
        crate::json::print(&info)?;
        return Ok(());
    }
    println!("{}", info.file);
    println!("  format       voxlod v{}", info.format_version);
    println!(
        "  grid         {}³ voxels, {} levels, {} mode",
        info.resolution, info.levels, info.mode
    );
    println!(
        "  world        origin {:?}, voxel size {}",
        info.origin, info.voxel_size
    );
    println!("  level  nodes      voxels     payload");
    for l in &info.per_level {
        println!(
            "  {:>5}  {:>5}  {:>10}  {:>10}",
            l.level,
            l.nodes,
            l.voxels,
            format_size(l.payload_bytes)
        );
    }
    println!("  nodes        {}", info.nodes);
    println!("  voxels       {} in all levels", info.voxels);
    println!(
        "  size         {} ({:.2} bytes per voxel)",
        format_size(info.bytes),
        info.bytes_per_voxel
    );
    for c in &info.channels {
        let extra = match (c.id, info.manifest.get("materials")) {
            (CHANNEL_MATERIAL, Some(serde_json::Value::Array(names))) => {
                format!(", {} materials", names.len())
            }
            (CHANNEL_TRIANGLES, _) => format!(", {} triangles", c.triangles),
            _ => String::new(),
        };
        println!(
            "  channel {:<4} {} ({}{extra})",
            c.id,
            c.name,
            format_size(c.payload_bytes)
        );
    }
    if info.channels.iter().any(|c| c.id == CHANNEL_MATERIAL) {
        println!("  materials    id, colour in render --color material, name:");
        for line in material_legend(&info.manifest) {
            println!("  {line}");
        }
    }
    if let Some(s) = info.manifest.get("settings") {
        println!("  built with   {s}");
    }
    if let Some(i) = info.manifest.get("input") {
        println!("  input        {i}");
    }
    Ok(())
}
