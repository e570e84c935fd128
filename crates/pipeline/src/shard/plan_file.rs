//! `voxlod plan`: cuts one build into shards for a cluster (Entwine's `build --subset` /
//! `merge` scheme applied to the octree of Chajdas et al.).
//!
//! The octree file is written in post-order, so the nodes of a whole subtree form one
//! contiguous run of it, and a node's payload depends only on its subtree. A plan picks a
//! *split level* S and gives each shard Morton ranges of the level-S nodes (together they cover
//! every code once): the shard bins, voxelizes and builds the LOD of those subtrees only
//! (`build --plan --shard`), and `merge` copies their payloads in Morton order and builds the
//! levels above S. The plan holds everything
//! the merge needs to write the one-machine build's bytes (settings, grid, manifest fields).
//!
//! The split level and the ranges are chosen in `split.rs`.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use voxlod_geom::{morton3, Grid};

use crate::settings::BuildSettings;

/// The plan file's `format` value.
pub const PLAN_FORMAT: &str = "voxlod-plan";
/// Version of the plan file. 2: the input's content checksum (`input.content_xxh3`), the
/// ingest pass's findings (`ingest`) and the per-chunk counts (`chunks`), so that a shard reads
/// the input once. 3: `parts` (the map tasks' face records), with which the plan reads no
/// faces (no `ingest`, no `content_xxh3`; `chunks` estimated from a sample). 4: a shard holds a
/// list of Morton `ranges` (the split's LPT assignment), not one range. 5: with parts, the
/// XXH3-64 of each part's face records (`parts[].faces_xxh3`) and of the pages before the
/// faces (`input.pages`), which the map tasks check the bytes they read against; the plan's
/// own `checksum`.
pub const PLAN_VERSION: u32 = 5;
/// Bytes hashed at each end of the input for its fingerprint.
const FINGERPRINT_SPAN: u64 = 1 << 20;

/// An input file's identity: size, modification time and SHA-256 of its first and last MiB
/// (the whole file when it is at most 2 MiB). Cheap on a file of any size; a change inside the
/// middle that keeps size and time is not seen.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fingerprint {
    /// Bytes.
    pub size: u64,
    /// Modification time, nanoseconds since the Unix epoch.
    pub mtime_ns: u128,
    /// Hex SHA-256 of the first MiB followed by the last MiB (or of the whole file).
    pub head_tail_sha256: String,
}

impl Fingerprint {
    /// The fingerprint of the file at `path`.
    pub fn of(path: &Path) -> Result<Fingerprint> {
        let mut f = voxlod_io::open_regular(path)
            .with_context(|| format!("{}: cannot open the input", path.display()))?;
        let meta = f
            .metadata()
            .with_context(|| format!("{}: cannot read its metadata", path.display()))?;
        let size = meta.len();
        let mtime_ns = voxlod_io::mtime_ns(&meta);
        let mut h = Sha256::new();
        let mut buf = Vec::new();
        let read = |f: &mut std::fs::File, at: u64, len: u64, buf: &mut Vec<u8>| {
            buf.clear();
            f.seek(SeekFrom::Start(at))?;
            f.take(len).read_to_end(buf)
        };
        let head = size.min(FINGERPRINT_SPAN);
        read(&mut f, 0, head, &mut buf)
            .with_context(|| format!("{}: reading its first MiB", path.display()))?;
        h.update(&buf);
        let tail_start = size.saturating_sub(FINGERPRINT_SPAN).max(head);
        read(&mut f, tail_start, size - tail_start, &mut buf)
            .with_context(|| format!("{}: reading its last MiB", path.display()))?;
        h.update(&buf);
        Ok(Fingerprint {
            size,
            mtime_ns,
            head_tail_sha256: voxlod_io::hex(&h.finalize()),
        })
    }
}

/// The checksum as the plan stores it: 16 lower-case hex digits.
pub(crate) fn hex64(v: u64) -> String {
    voxlod_io::hex(&v.to_be_bytes())
}

/// The input as the plan saw it.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanInput {
    /// Absolute path of the input (shards read it from a shared filesystem).
    pub path: PathBuf,
    /// Its identity when planned: a shard refuses, before any work, an input whose
    /// fingerprint differs.
    pub fingerprint: Fingerprint,
    /// XXH3-64 of every byte of the input, 16 hex digits (`content_hash.rs`): a shard takes it
    /// again during its pass and refuses an input whose content differs. None for a plan with
    /// parts, which reads only the input's vertex list and a sample of its faces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub content_xxh3: Option<String>,
    /// With parts: the XXH3-64 of every page of the bytes before the face records (the
    /// header, the vertex list); each map task checks the pages it reads against them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pages: Option<PlanPages>,
}

/// The bytes before the face records of a plan with parts, page by page: `[k·page_bytes,
/// (k+1)·page_bytes)` for every `k`, the last page ending at the first face record.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanPages {
    /// Bytes of a page: a power of two, at least 1 MiB, so that there are at most
    /// [`MAX_PAGES`] pages (or the bytes fit 1 MiB pages).
    pub page_bytes: u64,
    /// XXH3-64 of each page, 16 hex digits.
    pub xxh3: Vec<String>,
}

/// The most pages a plan lists for the bytes before the faces (above 4 GiB of them, pages
/// grow beyond 1 MiB).
pub const MAX_PAGES: u64 = 4096;

impl PlanPages {
    /// The page size for `bytes` before the face records: the smallest power of two of at
    /// least 1 MiB that cuts them into at most [`MAX_PAGES`] pages.
    pub fn page_bytes_for(bytes: u64) -> u64 {
        bytes.div_ceil(MAX_PAGES).next_power_of_two().max(1 << 20)
    }
}

/// A u64 as 16 lower-case hex digits in JSON (XXH3-64 values: a JSON number would lose
/// digits in readers that hold numbers as doubles).
pub(crate) mod hex_u64 {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&super::hex64(*v))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
        let t = String::deserialize(d)?;
        if t.len() != 16 || !t.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(serde::de::Error::custom(format!(
                "{t:?} is not 16 hex digits"
            )));
        }
        u64::from_str_radix(&t, 16).map_err(serde::de::Error::custom)
    }
}

impl PlanInput {
    /// `input` by its absolute path, with its fingerprint and content checksum.
    pub(crate) fn of(
        input: &Path,
        fingerprint: Fingerprint,
        xxh3: Option<u64>,
    ) -> Result<PlanInput> {
        let path = input
            .canonicalize()
            .with_context(|| format!("{}: cannot resolve the path", input.display()))?;
        Ok(PlanInput {
            path,
            fingerprint,
            content_xxh3: xxh3.map(hex64),
            pages: None,
        })
    }
}

/// What the plan's pass over the input found (the ingest stage's findings), which a shard
/// takes instead of reading the input for them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanIngest {
    /// Triangles the pass yielded (degenerate ones are skipped): those binned, and what the
    /// shard's pass must yield again.
    pub triangles: u64,
    /// Zero-area triangles skipped.
    pub degenerate_skipped: u64,
    /// The triangles' bounds (world coordinates), minimum corner.
    pub min: [f64; 3],
    /// 〃 maximum corner.
    pub max: [f64; 3],
    /// The ingest pass's warnings (degenerate triangles skipped).
    pub warnings: Vec<String>,
}

/// One part of the input for a map task: consecutive face records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanPart {
    /// 0-based part index.
    pub index: u32,
    /// First face record and the record after the last.
    pub records: [u64; 2],
    /// Their byte range in the input.
    pub bytes: [u64; 2],
    /// XXH3-64 of those bytes when planned (16 hex digits in the file).
    #[serde(with = "hex_u64")]
    pub faces_xxh3: u64,
}

impl PlanPart {
    /// The part as the reader takes it.
    pub(crate) fn face_part(&self) -> voxlod_ingest::FacePart {
        voxlod_ingest::FacePart {
            records: self.records,
            bytes: self.bytes,
        }
    }
}

/// One shard: ranges of level-`split_level` Morton codes.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardRange {
    /// 0-based shard index.
    pub index: u32,
    /// `[start, end)` ranges of Morton codes (level-`split_level` chunk coordinates), in
    /// increasing order, non-empty, not touching; none for an empty shard.
    pub ranges: Vec<[u64; 2]>,
    /// Non-empty subtrees in its ranges.
    pub subtrees: u64,
    /// Binned triangles of its leaf chunks (a triangle counts once per chunk).
    pub triangles: u64,
}

/// How even the shards are.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Balance {
    /// Mean binned triangles per shard.
    pub mean: f64,
    /// The largest shard's binned triangles.
    pub max: u64,
    /// `max / mean` (0 without triangles).
    pub ratio: f64,
    /// True if no shard is above 1.5× the mean.
    pub balanced: bool,
    /// Non-empty subtrees at the split level.
    pub subtrees: u64,
}

/// A plan file (JSON). docs/FORMAT.md, "Sharded builds", describes every field.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardPlan {
    /// [`PLAN_FORMAT`].
    pub format: String,
    /// [`PLAN_VERSION`].
    pub version: u32,
    /// Tool version that wrote it; shards and merge refuse another.
    pub tool_version: String,
    /// The input and its fingerprint.
    pub input: PlanInput,
    /// The build settings (threads, memory and the temporary folder may be overridden per
    /// shard; nothing else changes the bytes).
    pub settings: BuildSettings,
    /// The grid of the input's bounds (`Grid::fit` of `ingest`'s bounds).
    pub grid: PlanGrid,
    /// What the pass over the input found (none for a plan with `parts`: the map tasks find it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ingest: Option<PlanIngest>,
    /// Every non-empty leaf chunk, in Morton order: `[Morton code, binned triangles]` (the
    /// tile stage's counts, which size a shard's bins exactly; with `parts`, estimated from a
    /// sample of the faces, for the split only).
    pub chunks: Vec<[u64; 2]>,
    /// The map tasks' parts of the input (`voxlod map --part I`), in file order; empty if the
    /// input cannot be cut (then every shard reads the whole input).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<PlanPart>,
    /// The octree's levels.
    pub levels: u32,
    /// The output's manifest without its `levels` (they are summed by the merge).
    pub manifest: serde_json::Value,
    /// The octree's optional channels (ids, FORMAT.md 14).
    pub channels: Vec<u32>,
    /// Level of the shards' subtree roots.
    pub split_level: u32,
    /// The shards, in Morton order, together covering every level-`split_level` code.
    pub shards: Vec<ShardRange>,
    /// How even they are.
    pub balance: Balance,
    /// Hex SHA-256 of the plan's JSON as `plan` writes it (pretty-printed, keys in this order)
    /// with this field empty: an edited plan is refused, so every shard and map task builds
    /// what was planned.
    pub checksum: String,
}

impl ShardPlan {
    /// The SHA-256 of the plan with `checksum` empty, serialized as it is written.
    fn own_sha256(&self) -> String {
        let mut p = self.clone();
        p.checksum.clear();
        let text = serde_json::to_vec_pretty(&p).expect("a plan serializes");
        voxlod_io::hex(&Sha256::digest(&text))
    }

    /// The plan's file bytes: its JSON, pretty-printed, with `checksum` set.
    pub fn sealed_json(&mut self) -> Vec<u8> {
        self.checksum = self.own_sha256();
        serde_json::to_vec_pretty(self).expect("a plan serializes")
    }
}

/// The grid (`voxlod_geom::Grid`) as the plan stores it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanGrid {
    /// World position of the grid's minimum corner.
    pub origin: [f64; 3],
    /// Edge of one leaf voxel.
    pub voxel_size: f64,
    /// Voxels per axis.
    pub resolution: u32,
}

impl From<Grid> for PlanGrid {
    fn from(g: Grid) -> Self {
        PlanGrid {
            origin: g.origin,
            voxel_size: g.voxel_size,
            resolution: g.resolution,
        }
    }
}

impl From<PlanGrid> for Grid {
    fn from(g: PlanGrid) -> Self {
        Grid {
            origin: g.origin,
            voxel_size: g.voxel_size,
            resolution: g.resolution,
        }
    }
}

/// A plan as read from its file, with the SHA-256 of the file's bytes (which every shard
/// file records).
#[derive(Clone, Debug)]
pub struct LoadedPlan {
    /// The plan.
    pub plan: ShardPlan,
    /// SHA-256 of the plan file.
    pub sha256: [u8; 32],
    /// The plan file's path.
    pub path: PathBuf,
    /// Every shard range as `(start, end, shard)` in Morton order ([`range_owners`]).
    pub owners: Vec<(u64, u64, u32)>,
}

/// The largest plan file read (a plan is a few kilobytes of JSON).
const PLAN_LIMIT: u64 = 64 << 20;

impl LoadedPlan {
    /// Reads and checks a plan file.
    pub fn load(path: &Path) -> Result<LoadedPlan> {
        let bytes = voxlod_io::read_bounded(path, PLAN_LIMIT)
            .with_context(|| format!("{}: cannot read the plan", path.display()))?;
        let plan: ShardPlan = serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not a voxlod plan", path.display()))?;
        if plan.format != PLAN_FORMAT || plan.version != PLAN_VERSION {
            bail!(
                "{}: a plan of format {:?} version {}, this tool reads {PLAN_FORMAT:?} version {PLAN_VERSION}",
                path.display(),
                plan.format,
                plan.version
            );
        }
        if plan.checksum != plan.own_sha256() {
            bail!(
                "{}: its checksum does not match its content (edited or damaged since it was planned): plan again",
                path.display()
            );
        }
        if plan.tool_version != env!("CARGO_PKG_VERSION") {
            bail!(
                "{}: planned by voxlod {}, this is {}: plan again with this version (the bytes may differ)",
                path.display(),
                plan.tool_version,
                env!("CARGO_PKG_VERSION")
            );
        }
        let max_levels = voxlod_geom::Grid::MAX_RESOLUTION.trailing_zeros() - 7;
        if plan.levels == 0 || plan.levels > max_levels || plan.split_level >= plan.levels {
            bail!(
                "{}: {} levels with split level {} (edited by hand?)",
                path.display(),
                plan.levels,
                plan.split_level
            );
        }
        let indexed = plan
            .shards
            .iter()
            .enumerate()
            .all(|(i, s)| s.index == i as u32);
        let owners = range_owners(&plan.shards, plan.levels - 1 - plan.split_level);
        let (true, Some(owners)) = (indexed, owners) else {
            bail!(
                "{}: the shards' ranges do not cover the level-{} chunks once each, in order within each shard (edited by hand?)",
                path.display(),
                plan.split_level
            );
        };
        check_chunks(&plan, &owners)
            .with_context(|| format!("{}: edited by hand?", path.display()))?;
        let parts_ok = plan.parts.iter().enumerate().all(|(i, p)| {
            p.index == i as u32 && p.records[0] <= p.records[1] && p.bytes[0] <= p.bytes[1]
        }) && plan
            .parts
            .windows(2)
            .all(|w| w[0].records[1] == w[1].records[0] && w[0].bytes[1] == w[1].bytes[0]);
        let pages_ok = match (&plan.input.pages, plan.parts.first()) {
            (None, None) => true,
            (Some(pg), Some(first)) => {
                pg.page_bytes == PlanPages::page_bytes_for(first.bytes[0])
                    && pg.xxh3.len() as u64 == first.bytes[0].div_ceil(pg.page_bytes)
                    && pg
                        .xxh3
                        .iter()
                        .all(|h| h.len() == 16 && h.bytes().all(|b| b.is_ascii_hexdigit()))
            }
            _ => false,
        };
        if !parts_ok || !pages_ok || plan.parts.is_empty() == plan.ingest.is_none() {
            bail!(
                "{}: its parts are not consecutive face records in order, its pages before the faces do not match them, or it has both or neither of parts and the ingest pass's findings (edited by hand?)",
                path.display()
            );
        }
        Ok(LoadedPlan {
            sha256: Sha256::digest(&bytes).into(),
            plan,
            path: path.to_path_buf(),
            owners,
        })
    }

    /// The level-`split_level` Morton code of leaf chunk code `m`.
    fn subtree_of(&self, m: u64) -> u64 {
        m >> (3 * self.plan.split_level)
    }

    /// The folder of the map outputs: beside the plan.
    pub fn parts_dir(&self) -> &Path {
        crate::files::output::output_dir(&self.path)
    }

    /// The name of shard `index`'s file: `shard-IIII.vlshard`.
    pub fn shard_file_name(index: u32) -> String {
        format!("shard-{index:04}.vlshard")
    }

    /// Where shard `index` is written or read: in `dir`, else beside the plan.
    pub fn shard_path(&self, index: u32, dir: Option<&Path>) -> PathBuf {
        let dir = dir.unwrap_or_else(|| crate::files::output::output_dir(&self.path));
        dir.join(Self::shard_file_name(index))
    }

    /// The scope of shard `index`, or an error if the plan has no such shard.
    pub fn scope(&self, index: u32) -> Result<ShardScope> {
        let n = self.plan.shards.len();
        let Some(r) = self.plan.shards.get(index as usize) else {
            bail!(
                "--shard {index}: {} has {n} shards, 0 to {}",
                self.path.display(),
                n - 1
            );
        };
        let chunks = self
            .plan
            .chunks
            .iter()
            .filter(|c| in_ranges(&r.ranges, self.subtree_of(c[0])))
            .copied()
            .collect();
        Ok(ShardScope {
            index,
            count: n as u32,
            split_level: self.plan.split_level,
            levels: self.plan.levels,
            ranges: r.ranges.clone(),
            plan_sha256: self.sha256,
            grid: self.plan.grid.into(),
            channels: self.plan.channels.clone(),
            plan_path: self.path.clone(),
            content_xxh3: self.plan.input.content_xxh3.clone(),
            parts: self.plan.parts.clone(),
            plan_sha256_hex: voxlod_io::hex(&self.sha256),
            ingest: self.plan.ingest.clone(),
            chunks,
        })
    }
}

/// True if `code` lies in one of `ranges` (sorted, disjoint).
fn in_ranges(ranges: &[[u64; 2]], code: u64) -> bool {
    let i = ranges.partition_point(|r| r[1] <= code);
    ranges.get(i).is_some_and(|r| r[0] <= code)
}

/// Every range of `shards` as `(start, end, shard)` in Morton order, if each shard's ranges
/// are non-empty and increasing and all of them tile the codes of a level `up` levels below
/// the root, `0..8^up`, without gap or overlap; `None` otherwise.
pub(crate) fn range_owners(shards: &[ShardRange], up: u32) -> Option<Vec<(u64, u64, u32)>> {
    let full = 1u64.checked_shl(3 * up)?;
    let mut all = Vec::new();
    for s in shards {
        if !s.ranges.windows(2).all(|w| w[0][1] < w[1][0]) {
            return None;
        }
        all.extend(s.ranges.iter().map(|r| (r[0], r[1], s.index)));
    }
    all.sort_unstable();
    let mut at = 0;
    for &(a, b, _) in &all {
        if a != at || b <= a {
            return None;
        }
        at = b;
    }
    (at == full).then_some(all)
}

/// The plan's chunk list is in strictly increasing Morton order inside the grid, without
/// empty chunks, and each shard's chunks add up to its `triangles`.
fn check_chunks(plan: &ShardPlan, owners: &[(u64, u64, u32)]) -> Result<()> {
    let leaves = 1u64 << (3 * (plan.levels - 1));
    if !plan.chunks.windows(2).all(|w| w[0][0] < w[1][0])
        || plan.chunks.iter().any(|c| c[0] >= leaves || c[1] == 0)
    {
        bail!(
            "the chunk list is not in increasing Morton order of non-empty chunks inside the grid"
        );
    }
    let mut sums = vec![0u64; plan.shards.len()];
    for c in &plan.chunks {
        let code = c[0] >> (3 * plan.split_level);
        let i = owners.partition_point(|r| r.1 <= code);
        if let Some(s) = owners.get(i).and_then(|r| sums.get_mut(r.2 as usize)) {
            *s = s.saturating_add(c[1]);
        }
    }
    for (r, sum) in plan.shards.iter().zip(sums) {
        if r.triangles != sum {
            bail!(
                "shard {} lists {} binned triangles, its chunks add up to {sum}",
                r.index,
                r.triangles
            );
        }
    }
    Ok(())
}

/// What a sharded build restricts itself to (from its plan).
#[derive(Clone, Debug)]
pub struct ShardScope {
    /// 0-based shard index.
    pub index: u32,
    /// Shards in the plan.
    pub count: u32,
    /// Level of the subtree roots.
    pub split_level: u32,
    /// Levels of the octree.
    pub levels: u32,
    /// The shard's level-`split_level` Morton codes: `[start, end)` ranges, sorted, disjoint.
    pub ranges: Vec<[u64; 2]>,
    /// SHA-256 of the plan file.
    pub plan_sha256: [u8; 32],
    /// The grid the plan found.
    pub grid: Grid,
    /// The octree's channels.
    pub channels: Vec<u32>,
    /// The plan file (named by errors).
    pub plan_path: PathBuf,
    /// The plan's XXH3-64 of the input's bytes, hex (none for a plan with parts).
    pub content_xxh3: Option<String>,
    /// What the plan's pass over the input found (none for a plan with parts).
    pub ingest: Option<PlanIngest>,
    /// The map tasks' parts, whose outputs the shard reads instead of the input (if any).
    pub parts: Vec<PlanPart>,
    /// The plan's SHA-256, hex (what the map outputs record).
    pub plan_sha256_hex: String,
    /// The shard's non-empty leaf chunks, `[Morton code, binned triangles]` in Morton order.
    pub chunks: Vec<[u64; 2]>,
}

impl ShardScope {
    /// True if leaf chunk `c` lies in one of the shard's subtrees.
    pub fn contains_chunk(&self, c: [u32; 3]) -> bool {
        in_ranges(
            &self.ranges,
            morton3(c[0], c[1], c[2]) >> (3 * self.split_level),
        )
    }
}

/// What `voxlod plan` did.
#[derive(Clone, Debug, Serialize)]
pub struct PlanSummary {
    /// The plan file written.
    pub plan: PathBuf,
    /// Triangles read (with parts: the face records, none of them read whole).
    pub triangles: u64,
    /// Non-empty leaf chunks (with parts: those the sample touched).
    pub chunks: u64,
    /// Parts for map tasks (0: none; every shard reads the input).
    pub parts: u32,
    /// With parts: the face records the plan decoded for the per-chunk weights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sampled_triangles: Option<u64>,
    /// Level of the subtree roots.
    pub split_level: u32,
    /// The shards.
    pub shards: Vec<ShardRange>,
    /// Their balance.
    pub balance: Balance,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Warnings (unbalanced plan, input warnings).
    pub warnings: Vec<String>,
}
