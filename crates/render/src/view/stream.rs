//! Streaming nodes into a fixed GPU budget, as the renderer of Chajdas, Reitinger &
//! Westermann ("Scalable rendering for very large meshes", WSCG 2014, section 5 and
//! Figure 14): each frame the screen-space error cut ([`crate::cut`]) says which nodes the
//! camera needs; those not resident are requested, coarsest level first; a fixed number of
//! bytes per frame is uploaded (a node larger than that arrives over several frames); the
//! cache holds at most its budget of bytes and evicts the least recently used nodes; a node
//! is drawn only when resident, and where a refined node's children are not all resident yet
//! the parent stays drawn in their place.
//!
//! A resident node is one GPU vertex buffer of its voxels' active faces (the face masks),
//! grouped by face direction, so a frame skips whole directions that face away from the eye
//! (back-face culling per voxel face: a face with outward direction +a can be seen only from
//! `eye[a]` above its plane). The CPU holds only the node being uploaded.

use std::ops::Range;

use glam::DVec3;
use voxlod_format::{Aabb, Reader, Voxel};

use crate::camera::Shot;
use crate::cut;
use crate::draw::{Batch, FaceInstance, Renderer, FACE_BYTES};
use crate::faces::node_faces;
use crate::RenderError;

/// The budgets of a [`Stream`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamConfig {
    /// Most bytes of face buffers resident at once.
    pub cache_bytes: u64,
    /// Most bytes uploaded per frame (a multiple of 4 is used: the copy alignment).
    pub upload_bytes_per_frame: u64,
    /// Refine a node while its voxels project above this many pixels.
    pub max_error_px: f64,
}

/// What one frame did, printed as JSON by `voxlod view`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameStats {
    /// Frame number from 0.
    pub frame: u64,
    /// Nodes of the cut the camera wants ([`cut::select`]).
    pub cut_nodes: usize,
    /// Of them, level-0 (leaf) nodes.
    pub cut_leaf_nodes: usize,
    /// Leaves of the cut whose voxels still project above the threshold (where source
    /// geometry would take over; not stored yet).
    pub cut_over_error: usize,
    /// Nodes drawn (resident nodes of the cut, and parents standing in for missing children).
    pub drawn_nodes: usize,
    /// Of them, level-0 nodes.
    pub drawn_leaf_nodes: usize,
    /// Finest (lowest) level drawn, if anything was.
    pub finest_level_drawn: Option<u32>,
    /// Face instances drawn (after the per-direction culling).
    pub faces_drawn: u64,
    /// Face instances of the drawn nodes before that culling.
    pub faces_resident_in_drawn: u64,
    /// Nodes resident after the frame.
    pub nodes_resident: usize,
    /// Bytes of face buffers resident after the frame (never above the budget).
    pub bytes_resident: u64,
    /// The cache budget, bytes.
    pub cache_budget: u64,
    /// Bytes uploaded this frame (never above the limit).
    pub bytes_uploaded: u64,
    /// The upload limit, bytes per frame.
    pub upload_limit: u64,
    /// Nodes of the cut already resident at the start of the frame.
    pub cache_hits: usize,
    /// Nodes of the cut not resident at the start of the frame (requested).
    pub cache_misses: usize,
    /// Nodes evicted this frame.
    pub evictions: usize,
    /// Nodes that became resident this frame.
    pub nodes_completed: usize,
    /// Requests still waiting after the frame (including a partly uploaded node).
    pub pending: usize,
    /// The cache was full of nodes this frame needs, so a request had to wait.
    pub starved: bool,
    /// Nodes larger than the whole cache budget (never drawable at this budget).
    pub too_big: usize,
}

/// A node's face buffer: instances grouped by direction (`ranges[dir]`).
struct Resident {
    buffer: Option<wgpu::Buffer>,
    ranges: [Range<u32>; 6],
    bytes: u64,
    last_used: u64,
}

/// The node being uploaded: its faces on the CPU and how far the copy has got.
struct Upload {
    node: usize,
    data: Vec<u8>,
    done: u64,
    buffer: wgpu::Buffer,
    ranges: [Range<u32>; 6],
}

/// The node cache and upload queue of the viewer (see the module docs).
pub struct Stream {
    config: StreamConfig,
    /// Every world position on the GPU is relative to this point (f32 precision).
    origin: DVec3,
    resident: Vec<Option<Resident>>,
    upload: Option<Upload>,
    bytes: u64,
    frame: u64,
    /// Reused decode buffer.
    voxels: Vec<Voxel>,
}

impl std::fmt::Debug for Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Stream")
            .field("config", &self.config)
            .field("bytes", &self.bytes)
            .field("frame", &self.frame)
            .finish_non_exhaustive()
    }
}

/// A node to draw this frame.
pub(crate) struct Drawn {
    pub index: usize,
}

/// One walk of the cut ([`Stream::visit`]): what stays the same through it (the file, the
/// camera, the frame's tick, whether resident stand-ins are marked used) and what it collects
/// (the nodes to draw, the uncovered nodes to request first).
struct CutWalk<'a> {
    reader: &'a Reader,
    shot: &'a Shot,
    tick: u64,
    mark: bool,
    out: Vec<Drawn>,
    stand_ins: Vec<usize>,
}

impl<'a> CutWalk<'a> {
    fn new(reader: &'a Reader, shot: &'a Shot, tick: u64, mark: bool) -> Self {
        CutWalk {
            reader,
            shot,
            tick,
            mark,
            out: Vec::new(),
            stand_ins: Vec::new(),
        }
    }
}

impl Stream {
    /// An empty cache for `reader`'s nodes; GPU coordinates relative to `origin`.
    pub fn new(
        reader: &Reader,
        origin: DVec3,
        config: StreamConfig,
    ) -> Result<Stream, RenderError> {
        if config.cache_bytes == 0 {
            return Err(RenderError::Option(
                "the cache budget must be above 0".into(),
            ));
        }
        if config.upload_bytes_per_frame < 4 {
            return Err(RenderError::Option(
                "the upload limit must be at least 4 bytes per frame".into(),
            ));
        }
        if !(config.max_error_px.is_finite() && config.max_error_px > 0.0) {
            return Err(RenderError::Option(format!(
                "screen-space error {} must be a positive number of pixels",
                config.max_error_px
            )));
        }
        Ok(Stream {
            config,
            origin,
            resident: (0..reader.nodes().len()).map(|_| None).collect(),
            upload: None,
            bytes: 0,
            frame: 0,
            voxels: Vec::new(),
        })
    }

    /// Changes the pixel error of the cut (positive and finite, else ignored).
    pub fn set_max_error(&mut self, px: f64) {
        if px.is_finite() && px > 0.0 {
            self.config.max_error_px = px;
        }
    }

    /// The point GPU coordinates are relative to.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// True if node `i` is resident.
    pub fn is_resident(&self, i: usize) -> bool {
        self.resident[i].is_some()
    }

    /// Indices of the resident nodes, ascending.
    pub fn resident_nodes(&self) -> Vec<usize> {
        (0..self.resident.len())
            .filter(|&i| self.resident[i].is_some())
            .collect()
    }

    /// One frame for `shot`: find the cut, count hits and misses, upload within the limit
    /// (evicting least recently used nodes), and choose the nodes to draw.
    pub(crate) fn frame(
        &mut self,
        reader: &Reader,
        renderer: &Renderer,
        shot: &Shot,
    ) -> Result<(FrameStats, Vec<Drawn>), RenderError> {
        let tick = self.frame + 1;
        let px = self.config.max_error_px;
        let mut stats = FrameStats {
            frame: self.frame,
            cache_budget: self.config.cache_bytes,
            upload_limit: self.upload_limit(),
            ..Default::default()
        };
        let want = cut::select(reader, shot, px);
        stats.cut_nodes = want.len();
        stats.cut_over_error = want.iter().filter(|c| c.over).count();
        stats.cut_leaf_nodes = want
            .iter()
            .filter(|c| reader.nodes()[c.index].level == 0)
            .count();
        // requests: the cut's missing nodes, coarsest level first, then the largest error
        let mut requests = Vec::new();
        for c in &want {
            match &mut self.resident[c.index] {
                Some(r) => {
                    r.last_used = tick;
                    stats.cache_hits += 1;
                }
                None => {
                    stats.cache_misses += 1;
                    requests.push(*c);
                }
            }
        }
        requests.sort_by(|a, b| {
            let (la, lb) = (reader.nodes()[a.index].level, reader.nodes()[b.index].level);
            lb.cmp(&la)
                .then(b.error.total_cmp(&a.error))
                .then(a.index.cmp(&b.index))
        });
        // parents standing in for missing children are in use too; where nothing covers a
        // missing part, its coarsest uncovered ancestor is requested before everything else
        let mut drawn = Vec::new();
        if let Some(root) = reader.root() {
            let mut walk = CutWalk::new(reader, shot, tick, true);
            self.visit(&mut walk, root, false);
            let mut first: Vec<cut::CutNode> = walk
                .stand_ins
                .into_iter()
                .map(|index| cut::CutNode {
                    index,
                    error: cut::node_error(reader, index, shot),
                    over: false,
                })
                .collect();
            first.sort_by_key(|c| (std::cmp::Reverse(reader.nodes()[c.index].level), c.index));
            first.extend(requests);
            requests = first;
        }
        self.upload(reader, renderer, &requests, tick, &mut stats)?;
        if let Some(root) = reader.root() {
            let mut walk = CutWalk::new(reader, shot, tick, false);
            self.visit(&mut walk, root, false);
            drawn = walk.out;
        }
        stats.drawn_nodes = drawn.len();
        for d in &drawn {
            let level = reader.nodes()[d.index].level;
            if level == 0 {
                stats.drawn_leaf_nodes += 1;
            }
            stats.finest_level_drawn =
                Some(stats.finest_level_drawn.map_or(level, |l| l.min(level)));
        }
        stats.nodes_resident = self.resident.iter().flatten().count();
        stats.bytes_resident = self.bytes;
        stats.pending = requests
            .iter()
            .filter(|c| self.resident[c.index].is_none())
            .count();
        assert!(
            self.bytes <= self.config.cache_bytes,
            "the cache exceeds its budget"
        );
        assert!(
            stats.bytes_uploaded <= stats.upload_limit,
            "the upload limit was exceeded"
        );
        self.frame += 1;
        Ok((stats, drawn))
    }

    /// The per-frame upload limit actually used: the configured one rounded down to 4 bytes.
    fn upload_limit(&self) -> u64 {
        self.config.upload_bytes_per_frame / 4 * 4
    }

    /// Walks the cut below node `i`; returns true when the subtree can be drawn completely
    /// from resident nodes, pushing them to `walk.out`. A refined node whose subtree is
    /// incomplete is drawn itself if resident (its children's drawn nodes are dropped, so
    /// nothing is drawn twice) and, with `walk.mark`, marked used, so eviction keeps it while
    /// it stands in; if neither it nor an ancestor is resident (`covered` false) it goes to
    /// `walk.stand_ins`, so a coarse node is requested to fill the gap quickly (the first
    /// frames, a sudden turn).
    fn visit(&mut self, walk: &mut CutWalk, i: usize, covered: bool) -> bool {
        let (reader, shot) = (walk.reader, walk.shot);
        let b = reader.node_bounds(i).expect("a node of the file");
        if !cut::in_frustum(shot, b) {
            return true;
        }
        if !cut::refines(reader, i, shot, self.config.max_error_px) {
            let here = self.resident[i].is_some();
            if here {
                walk.out.push(Drawn { index: i });
            }
            return here;
        }
        let start = walk.out.len();
        let first_stand_in = walk.stand_ins.len();
        let mut complete = true;
        let here = self.resident[i].is_some();
        for c in reader.children(i).into_iter().flatten() {
            complete &= self.visit(walk, c, covered || here);
        }
        if complete {
            return true;
        }
        if !here && !covered {
            // the coarsest uncovered node only: drop those found below it
            walk.stand_ins.truncate(first_stand_in);
            walk.stand_ins.push(i);
        }
        match &mut self.resident[i] {
            Some(r) => {
                if walk.mark {
                    r.last_used = walk.tick;
                }
                walk.out.truncate(start);
                walk.out.push(Drawn { index: i });
                true
            }
            None => false,
        }
    }

    /// Uploads requests in order until this frame's byte limit is used up.
    fn upload(
        &mut self,
        reader: &Reader,
        renderer: &Renderer,
        requests: &[cut::CutNode],
        tick: u64,
        stats: &mut FrameStats,
    ) -> Result<(), RenderError> {
        let limit = self.upload_limit();
        // a partly uploaded node no longer wanted is dropped (its bytes freed)
        if let Some(u) = &self.upload {
            if !requests.iter().any(|c| c.index == u.node) {
                let u = self.upload.take().expect("checked");
                self.bytes -= u.data.len() as u64;
                u.buffer.destroy();
            }
        }
        let mut next = requests.iter();
        loop {
            if self.upload.is_none() {
                // start the next request that is not resident
                let Some(c) = next.find(|c| self.resident[c.index].is_none()) else {
                    break;
                };
                let (data, ranges) = self.node_instances(reader, c.index)?;
                let size = data.len() as u64;
                if size == 0 {
                    self.resident[c.index] = Some(Resident {
                        buffer: None,
                        ranges,
                        bytes: 0,
                        last_used: tick,
                    });
                    stats.nodes_completed += 1;
                    continue;
                }
                if size > self.config.cache_bytes {
                    stats.too_big += 1;
                    continue;
                }
                if !self.make_room(size, tick, stats) {
                    stats.starved = true;
                    break;
                }
                let buffer = renderer.device().create_buffer(&wgpu::BufferDescriptor {
                    label: Some("node faces"),
                    size,
                    usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                self.bytes += size;
                self.upload = Some(Upload {
                    node: c.index,
                    data,
                    done: 0,
                    buffer,
                    ranges,
                });
            }
            let u = self.upload.as_mut().expect("set above");
            let room = limit - stats.bytes_uploaded;
            let n = (u.data.len() as u64 - u.done).min(room);
            if n > 0 {
                let from = u.done as usize;
                renderer
                    .queue()
                    .write_buffer(&u.buffer, u.done, &u.data[from..from + n as usize]);
                u.done += n;
                stats.bytes_uploaded += n;
            }
            if u.done < u.data.len() as u64 {
                break; // the limit is reached; the rest next frame
            }
            let u = self.upload.take().expect("set above");
            self.resident[u.node] = Some(Resident {
                buffer: Some(u.buffer),
                ranges: u.ranges,
                bytes: u.data.len() as u64,
                last_used: tick,
            });
            stats.nodes_completed += 1;
        }
        Ok(())
    }

    /// Evicts least recently used nodes not used this frame until `size` more bytes fit;
    /// false if the nodes in use leave no room.
    fn make_room(&mut self, size: u64, tick: u64, stats: &mut FrameStats) -> bool {
        while self.bytes + size > self.config.cache_bytes {
            let victim = (0..self.resident.len())
                .filter_map(|i| {
                    let r = self.resident[i].as_ref()?;
                    (r.last_used < tick).then_some((r.last_used, i))
                })
                .min();
            let Some((_, i)) = victim else {
                return false;
            };
            let r = self.resident[i].take().expect("resident");
            self.bytes -= r.bytes;
            if let Some(b) = r.buffer {
                b.destroy();
            }
            stats.evictions += 1;
        }
        true
    }

    /// The face instances of node `i`, grouped by direction, as bytes, and each direction's
    /// instance range.
    fn node_instances(
        &mut self,
        reader: &Reader,
        i: usize,
    ) -> Result<(Vec<u8>, [Range<u32>; 6]), RenderError> {
        let mut by_dir: [Vec<FaceInstance>; 6] = Default::default();
        let origin = self.origin;
        node_faces(reader, i, &mut self.voxels, &mut |f| {
            by_dir[f.dir as usize].push(FaceInstance::of(&f, origin));
        })?;
        let mut data = Vec::new();
        let mut at = 0u32;
        let ranges = std::array::from_fn(|d| {
            let r = at..at + by_dir[d].len() as u32;
            at = r.end;
            data.extend_from_slice(bytemuck::cast_slice(&by_dir[d]));
            r
        });
        debug_assert_eq!(data.len() as u64, at as u64 * FACE_BYTES);
        Ok((data, ranges))
    }

    /// The batches to draw for `drawn`: per node, only the face directions that can face
    /// the eye (direction +a when the eye is above the box's low side on axis a, −a when below
    /// its high side). Returns the batches and the instances before and after culling.
    pub(crate) fn batches<'a>(
        &'a self,
        reader: &Reader,
        shot: &Shot,
        drawn: &[Drawn],
    ) -> (Vec<Batch<'a>>, u64, u64) {
        let mut out = Vec::new();
        let (mut all, mut kept) = (0u64, 0u64);
        for d in drawn {
            let r = self.resident[d.index]
                .as_ref()
                .expect("drawn nodes are resident");
            let Some(buffer) = &r.buffer else { continue };
            let b: Aabb = reader.node_bounds(d.index).expect("a node of the file");
            for dir in 0..6usize {
                let range = r.ranges[dir].clone();
                all += range.len() as u64;
                let a = dir >> 1;
                let seen = if dir & 1 == 0 {
                    shot.eye[a] > b.min[a]
                } else {
                    shot.eye[a] < b.max[a]
                };
                if seen && !range.is_empty() {
                    kept += range.len() as u64;
                    out.push((buffer, range));
                }
            }
        }
        (out, all, kept)
    }
}
