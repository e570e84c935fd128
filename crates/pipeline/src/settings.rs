//! What a user sets for a build ([`BuildSettings`], from the command line or a settings
//! file) and the checks of those values.

use std::path::PathBuf;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use voxlod_geom::Grid;
use voxlod_voxelize::{Method, Mode};

use crate::size;

/// Everything a build depends on. Only `resolution`, `mode` and `zstd_level` affect the output
/// bytes (and `voxelizer` when it is the approximate `scanline-ilv`, `source_geometry` when it
/// adds the source-triangle channel); `threads`, `memory`,
/// `tmp_dir` and `progress` do not.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildSettings {
    /// Voxels per axis of the whole grid, 256·2^k.
    pub resolution: u32,
    /// Conservative (26-separating) or thin (6-separating).
    pub mode: Mode,
    /// CPU voxelizer method: sat (overlap tests) or scanline (Zhang et al.), the same voxels;
    /// scanline-ilv (integer-only, approximate, conservative only).
    pub voxelizer: Method,
    /// Worker threads; 0 = one per core.
    pub threads: usize,
    /// Memory budget in bytes for the whole process.
    #[serde(with = "size::serde_size")]
    pub memory: u64,
    /// zstd level of the node payloads.
    pub zstd_level: i32,
    /// Folder for temporary files (default: the output's folder).
    pub tmp_dir: Option<PathBuf>,
    /// Voxelizer: auto (a hardware GPU if found, else the CPU), cpu or gpu.
    pub backend: Backend,
    /// GPU method: hybrid, triangle or fragment.
    pub gpu_method: GpuMethod,
    /// GPU hybrid cutoff in voxels², or auto.
    pub cutoff: Cutoff,
    /// Store each leaf chunk's source triangles beside its voxels (FORMAT.md 14.4).
    pub source_geometry: bool,
    /// Folders besides the input's own that files the mesh refers to (MTL, textures, glTF
    /// buffers and images) may be read from (`--allow-path`; docs/INGEST.md).
    #[serde(skip)]
    pub allow_paths: Vec<PathBuf>,
    /// Show progress bars on stderr.
    #[serde(skip)]
    pub progress: bool,
    /// Replace an existing output file that is not a voxlod octree.
    #[serde(skip)]
    pub force: bool,
}

impl BuildSettings {
    /// How the input's referenced files are read: inside its folder and `allow_paths`.
    pub fn read_options(&self) -> voxlod_ingest::ReadOptions {
        voxlod_ingest::ReadOptions {
            allow: self.allow_paths.clone(),
            memory: None,
        }
    }
}

impl Default for BuildSettings {
    fn default() -> Self {
        BuildSettings {
            resolution: 1024,
            mode: Mode::Conservative,
            voxelizer: Method::default(),
            threads: 0,
            memory: 2 << 30,
            zstd_level: voxlod_format::DEFAULT_ZSTD_LEVEL,
            tmp_dir: None,
            backend: Backend::Auto,
            gpu_method: GpuMethod::default(),
            cutoff: Cutoff::default(),
            source_geometry: false,
            allow_paths: Vec::new(),
            progress: false,
            force: false,
        }
    }
}

/// A setting that is wrong on its own, named as in a settings file (`resolution`,
/// `zstd_level`), so that the command line can say where the value came from.
#[derive(Debug)]
pub struct SettingError {
    /// The setting's name in a settings file.
    pub field: &'static str,
    /// The value, as given.
    pub value: String,
    /// What is wrong with it.
    pub message: String,
}

impl std::fmt::Display for SettingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {}: {}", self.field, self.value, self.message)
    }
}

impl std::error::Error for SettingError {}

impl BuildSettings {
    /// Checks the settings that can be wrong on their own (the memory budget is checked by
    /// [`crate::MemoryPlan::new`], which knows the thread count).
    pub fn validate(&self) -> std::result::Result<(), SettingError> {
        if let Err(e) = Grid::new([0.0; 3], 1.0, self.resolution) {
            return Err(SettingError {
                field: "resolution",
                value: self.resolution.to_string(),
                message: e.to_string(),
            });
        }
        if !(-7..=22).contains(&self.zstd_level) {
            return Err(SettingError {
                field: "zstd_level",
                value: self.zstd_level.to_string(),
                message: "outside -7..=22".into(),
            });
        }
        Ok(())
    }
}

/// The settings checks every entry makes before any work.
pub(crate) fn check_settings(s: &BuildSettings) -> Result<()> {
    s.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    if !s.voxelizer.supports(s.mode) {
        bail!(
            "--voxelizer {} approximates the conservative set only; use --voxelizer scanline (or sat) with {} mode",
            s.voxelizer,
            s.mode
        );
    }
    Ok(())
}

/// `--backend`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// A hardware GPU when one is found, else the CPU (a software rasterizer such as lavapipe
    /// is slower than the CPU backend, so `auto` does not pick it).
    #[default]
    Auto,
    /// The CPU chunk voxelizer on every core.
    Cpu,
    /// Any adapter, software ones included; an error when there is none.
    Gpu,
}

#[cfg(feature = "clap")]
impl clap::ValueEnum for Backend {
    fn value_variants<'a>() -> &'a [Self] {
        &[Backend::Auto, Backend::Cpu, Backend::Gpu]
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// `--gpu-method`: how the GPU voxelizer covers a chunk's triangles.
pub use voxlod_voxelize::GpuMethod;

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Backend::Auto),
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            _ => Err(format!("unknown backend '{s}' (auto, cpu or gpu)")),
        }
    }
}

impl Backend {
    /// The backend's name, as settings and the command line spell it.
    pub const fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `--cutoff`: the projected area (voxels²) from which the GPU hybrid defers a triangle to the
/// fragment pass, or `auto` for a short bracketing search on the build's largest chunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cutoff {
    /// Search a cutoff on the build's largest chunk.
    Auto,
    /// This cutoff, voxels².
    Fixed(f32),
}

impl Default for Cutoff {
    fn default() -> Self {
        Cutoff::Fixed(DEFAULT_CUTOFF)
    }
}

/// The GPU crate's default (a few voxels², as the paper finds best).
pub const DEFAULT_CUTOFF: f32 = 8.0;

impl std::str::FromStr for Cutoff {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Cutoff::Auto);
        }
        match s.parse::<f32>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(Cutoff::Fixed(v)),
            _ => Err(format!(
                "cutoff '{s}' is not 'auto' or a non-negative number of voxels²"
            )),
        }
    }
}

impl std::fmt::Display for Cutoff {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cutoff::Auto => f.write_str("auto"),
            Cutoff::Fixed(v) => write!(f, "{v}"),
        }
    }
}

impl Serialize for Cutoff {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for Cutoff {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum V {
            N(f32),
            S(String),
        }
        match V::deserialize(d)? {
            V::N(n) => format!("{n}").parse().map_err(serde::de::Error::custom),
            V::S(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The presets in configs/ parse, with the enum settings' documented strings.
    #[test]
    fn config_presets_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
        let d: BuildSettings =
            toml::from_str(&std::fs::read_to_string(dir.join("default.toml")).unwrap()).unwrap();
        assert_eq!(d.gpu_method, GpuMethod::Hybrid);
        assert_eq!(
            (d.mode, d.voxelizer),
            (Mode::Conservative, Method::Scanline)
        );
        assert_eq!((d.backend, d.cutoff), (Backend::Auto, Cutoff::Fixed(8.0)));
        for name in ["preview.toml", "scan.toml"] {
            let s: BuildSettings =
                toml::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap();
            assert_eq!(s.mode, Mode::Thin, "{name}");
        }
        let all = "mode = \"thin\"\nvoxelizer = \"scanline-ilv\"\nbackend = \"gpu\"\ngpu_method = \"fragment\"\ncutoff = \"auto\"";
        let s: BuildSettings = toml::from_str(all).unwrap();
        assert_eq!(
            (s.mode, s.voxelizer, s.backend, s.gpu_method, s.cutoff),
            (
                Mode::Thin,
                Method::ScanlineIlv,
                Backend::Gpu,
                GpuMethod::Fragment,
                Cutoff::Auto
            )
        );
    }

    /// A bad value of an enum setting in a settings file is refused when the file is read,
    /// with an error that names the key and the value.
    #[test]
    fn bad_enum_value_in_a_settings_file_names_the_key() {
        for (key, value) in [
            ("mode", "\"thick\""),
            ("voxelizer", "\"raster\""),
            ("backend", "\"tpu\""),
            ("gpu_method", "\"mesh\""),
            ("cutoff", "\"often\""),
            ("cutoff", "-2"),
        ] {
            let text = format!("resolution = 512\n{key} = {value}\n");
            let e = toml::from_str::<BuildSettings>(&text)
                .err()
                .unwrap_or_else(|| panic!("{key} = {value} was accepted"))
                .to_string();
            assert!(
                e.contains(&format!("{key} = {value}")) && e.contains("line 2"),
                "{key} = {value}: {e}"
            );
        }
    }

    #[test]
    fn parse_settings() {
        assert_eq!("gpu".parse::<Backend>(), Ok(Backend::Gpu));
        assert!("tpu".parse::<Backend>().is_err());
        assert_eq!("auto".parse::<Cutoff>(), Ok(Cutoff::Auto));
        assert_eq!("2.5".parse::<Cutoff>(), Ok(Cutoff::Fixed(2.5)));
        assert!("-1".parse::<Cutoff>().is_err());
        #[derive(Deserialize)]
        struct T {
            c: Cutoff,
            b: Backend,
        }
        let t: T = toml::from_str("c = 16\nb = \"cpu\"").unwrap();
        assert_eq!((t.c, t.b), (Cutoff::Fixed(16.0), Backend::Cpu));
        let t: T = toml::from_str("c = \"auto\"\nb = \"auto\"").unwrap();
        assert_eq!((t.c, t.b), (Cutoff::Auto, Backend::Auto));
    }
}
