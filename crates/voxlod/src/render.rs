//! `voxlod render FILE -o image.png` (or `.jpg`): a headless picture of the octree (each voxel
//! a cube of its active faces, shaded by normal and colour), see `voxlod-render`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use voxlod_format::Reader;
use voxlod_pipeline::{OutputGuard, OutputKind};
use voxlod_render::{ColorBy, Lod, Renderer, View};

#[derive(Args)]
pub struct RenderArgs {
    /// An octree file.
    file: PathBuf,
    /// Output picture: PNG for a name ending in .png, JPEG for .jpg or .jpeg.
    #[arg(short, long)]
    output: PathBuf,
    /// Draw every node of this level (0 = finest).
    #[arg(long, conflicts_with = "error")]
    level: Option<u32>,
    /// Draw the screen-space error cut: refine while voxels project to more than this many
    /// pixels [default: 1].
    #[arg(long)]
    error: Option<f64>,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x768", value_parser = parse_image_size)]
    size: (u32, u32),
    /// Direction from the model towards the camera, x,y,z.
    #[arg(long, default_value = "0.55,0.35,1", value_parser = parse_vec3, allow_hyphen_values = true)]
    view: [f64; 3],
    /// World up vector, x,y,z [default: from the file's manifest if it names one (`input.up`),
    /// else 0,0,1 for a model flat in z (a Z-up city or terrain), else 0,1,0]. The output
    /// says which was used.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<[f64; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 35.0)]
    fov: f64,
    /// Move closer: 1 frames the whole model, 2 is twice as close.
    #[arg(long, default_value_t = 1.0)]
    zoom: f64,
    /// The point looked at, x,y,z in world coordinates (a close-up of one part with --zoom)
    /// [default: the centre of the model].
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// Replace an existing output file even if it is not a picture of that format.
    #[arg(long)]
    force: bool,
    /// What the faces' colour shows: `voxel` (the voxels' colours) or `material` (one colour
    /// per material id of the file's material channel; grey for no material).
    #[arg(long, default_value = "voxel", value_parser = parse_color)]
    color: ColorBy,
    /// Draw voxels everywhere. By default, in a file built with --source-geometry, the leaves
    /// of the error cut whose voxels are still coarser than --error pixels are drawn from
    /// their source triangles.
    #[arg(long)]
    no_source: bool,
    /// Draw open surfaces (scans, photogrammetry, single walls) from behind too: per axis, a
    /// voxel with either face of the axis in its mask shows the one towards the eye, lit as
    /// the front would be from that side. Closed surfaces seen from outside look the same;
    /// from inside a closed shell its inner side shows. Default: only the faces of the masks.
    #[arg(long)]
    two_sided: bool,
}

fn parse_color(s: &str) -> Result<ColorBy, String> {
    match s {
        "voxel" => Ok(ColorBy::Voxel),
        "material" => Ok(ColorBy::Material),
        _ => Err(format!("'{s}' is neither voxel nor material")),
    }
}

/// An image size `WIDTHxHEIGHT` (`x` or `X`), for `--size` of `render` and `view`.
pub(crate) fn parse_image_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("'{s}' is not WIDTHxHEIGHT (e.g. 1024x768)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let p = |v: &str| v.trim().parse::<u32>().map_err(|_| bad());
    Ok((p(w)?, p(h)?))
}

pub(crate) fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}' is not x,y,z (e.g. 0.5,0.3,1)"))?;
    match v[..] {
        [x, y, z] => Ok([x, y, z]),
        _ => Err(format!("'{s}' is not x,y,z (three numbers)")),
    }
}

/// The image format `-o` asks for by its extension: PNG for `.png`, JPEG for `.jpg`/`.jpeg`
/// (any case); any other name is refused rather than written in a format it does not name.
fn image_kind(path: &Path) -> Result<OutputKind> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => Ok(OutputKind::Png),
        Some("jpg" | "jpeg") => Ok(OutputKind::Jpeg),
        _ => bail!(
            "{}: the picture's name must end in .png, .jpg or .jpeg (the format is chosen by it)",
            path.display()
        ),
    }
}

pub fn run(a: RenderArgs) -> Result<()> {
    let t = Instant::now();
    // the output is checked (not the input, not another kind of file) and locked first
    let kind = match image_kind(&a.output) {
        Ok(k) => k,
        Err(e) => {
            // a name that is the input itself is the graver mistake: the guard says so first
            drop(OutputGuard::acquire(
                &a.output,
                &[&a.file],
                OutputKind::Png,
                false,
            )?);
            return Err(e);
        }
    };
    let guard = OutputGuard::acquire(&a.output, &[&a.file], kind, a.force)?;
    let r = Reader::open(&a.file)?;
    if a.color == ColorBy::Material && !r.has_materials() {
        bail!(
            "{}: --color material: the file has no material channel (built from a mesh with fewer than two materials)",
            a.file.display()
        );
    }
    let lod = match (a.level, a.error) {
        (Some(l), _) => Lod::Level(l),
        (None, Some(e)) => Lod::Error(e),
        (None, None) => Lod::Error(1.0),
    };
    let (up, up_from) = pick_up(&r, a.up)?;
    let view = View {
        width: a.size.0,
        height: a.size.1,
        direction: a.view,
        up,
        fov_y_deg: a.fov,
        zoom: a.zoom,
        target: a.target,
    };
    let (shot, nodes) = voxlod_render::frame(&r, &view, lod)?;
    let mut renderer = Renderer::new()?;
    renderer.set_two_sided(a.two_sided);
    let source = if a.no_source {
        Vec::new()
    } else {
        voxlod_render::over_leaves(&r, &shot, lod)
    };
    let pic = renderer.render_with_source(&r, &nodes, &source, &shot, a.color)?;
    if pic.coverage().iter().all(|&c| !c) {
        bail!("nothing of the model is in the picture (check --view, --up and --zoom)");
    }
    match kind {
        OutputKind::Jpeg => pic.write_jpeg(guard.staged())?,
        _ => pic.write_png(guard.staged())?,
    }
    guard.commit()?;
    let mut levels: Vec<u32> = nodes.iter().map(|&i| r.nodes()[i].level).collect();
    levels.sort_unstable();
    levels.dedup();
    println!(
        "wrote {}: {}x{}, up {},{},{} ({up_from}), {} nodes (levels {:?}), {} voxels, {} faces drawn, {} leaves as {} source triangles on {} in {:.2}s",
        a.output.display(),
        pic.width,
        pic.height,
        up[0],
        up[1],
        up[2],
        nodes.len(),
        levels,
        pic.voxels,
        pic.faces_drawn,
        pic.source_leaves,
        pic.source_triangles,
        renderer.adapter(),
        t.elapsed().as_secs_f64()
    );
    if a.color == ColorBy::Material {
        println!("legend (material id, colour, name):");
        for line in crate::inspect::material_legend(&r.manifest()?) {
            println!("{line}");
        }
    }
    Ok(())
}

/// The up vector and where it came from: `--up`, the manifest's `input.up` (three numbers),
/// the model's shape ([`voxlod_render::up_from_shape`] on its robust bounds), or the default +Y.
pub(crate) fn pick_up(r: &Reader, given: Option<[f64; 3]>) -> Result<([f64; 3], &'static str)> {
    if let Some(u) = given {
        return Ok((u, "--up"));
    }
    let manifest = r.manifest()?;
    if let Some(u) = manifest["input"]["up"].as_array() {
        let v: Vec<f64> = u.iter().filter_map(|x| x.as_f64()).collect();
        if let [x, y, z] = v[..] {
            return Ok(([x, y, z], "from the file"));
        }
    }
    if let Some(b) = voxlod_render::robust_bounds(r)? {
        if let Some(u) = voxlod_render::up_from_shape(b) {
            return Ok((u, "the model is flat in z; --up to change"));
        }
    }
    Ok(([0.0, 1.0, 0.0], "default; --up to change"))
}
