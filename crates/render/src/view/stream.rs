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
//!
//! **Source triangles** (section 4 of the paper). In a file that stores them, a leaf
//! of the cut whose voxels still project above the threshold ([`cut::CutNode::over`], the rule
//! `render` draws by) is wanted as a second kind of entry: its source triangles
//! (`source.rs`), requested after the voxel nodes, counted in the same byte budget, evicted by
//! the same least-recently-used rule and uploaded under the same per-frame limit. Until its
//! triangles are resident the leaf's voxels stay drawn and kept (or, where those are not
//! resident either, an ancestor stands in as for any missing node), so no hole opens.
//! [`StreamConfig::source`] off (`--no-source`) draws voxels everywhere; a leaf whose
//! triangles exceed the whole budget is drawn as voxels from then on.

use std::ops::Range;

use glam::DVec3;
use voxlod_format::{Aabb, Reader, Voxel};

use super::source::{leaf_entry, TriangleLayout};
use crate::camera::Shot;
use crate::cut;
use crate::draw::{Batch, FaceInstance, Renderer, SourceBatch, FACE_BYTES};
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
    /// Draw the cut's leaves whose voxels are still coarser than `max_error_px` from their
    /// source triangles, where the file stores them (false: voxels everywhere, `--no-source`).
    pub source: bool,
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
    /// geometry takes over).
    pub cut_over_error: usize,
    /// Of them, the leaves wanted as source triangles (they store triangles, the stream draws
    /// them, and they fit the budget; 0 with `--no-source` or a file without the channel).
    pub source_leaves_wanted: usize,
    /// Nodes drawn (resident nodes of the cut, and parents standing in for missing children),
    /// as voxels or as source triangles.
    pub drawn_nodes: usize,
    /// Of them, level-0 nodes.
    pub drawn_leaf_nodes: usize,
    /// Of those, leaves drawn from their source triangles.
    pub source_leaves_drawn: usize,
    /// Triangles of those leaves.
    pub source_triangles_drawn: u64,
    /// Bytes of those leaves' resident triangle buffers.
    pub source_bytes_drawn: u64,
    /// Finest (lowest) level drawn, if anything was.
    pub finest_level_drawn: Option<u32>,
    /// Face instances drawn (after the per-direction culling).
    pub faces_drawn: u64,
    /// Face instances of the drawn nodes before that culling.
    pub faces_resident_in_drawn: u64,
    /// Nodes whose voxel faces are resident after the frame.
    pub nodes_resident: usize,
    /// Leaves whose source triangles are resident after the frame.
    pub source_resident: usize,
    /// Bytes resident after the frame, face and triangle buffers together (never above the
    /// budget).
    pub bytes_resident: u64,
    /// Of them, bytes of triangle buffers.
    pub source_bytes_resident: u64,
    /// The cache budget, bytes.
    pub cache_budget: u64,
    /// Bytes uploaded this frame, faces and triangles (never above the limit).
    pub bytes_uploaded: u64,
    /// Of them, bytes of triangle buffers.
    pub source_bytes_uploaded: u64,
    /// The upload limit, bytes per frame.
    pub upload_limit: u64,
    /// Nodes of the cut (those wanted as voxels) already resident at the start of the frame.
    pub cache_hits: usize,
    /// Nodes of the cut (those wanted as voxels) not resident at the start of the frame
    /// (requested).
    pub cache_misses: usize,
    /// Leaves wanted as source triangles whose triangles were resident at the start of the
    /// frame.
    pub source_hits: usize,
    /// Leaves wanted as source triangles whose triangles were not (requested).
    pub source_misses: usize,
    /// Entries (voxel nodes and leaf triangles) evicted this frame.
    pub evictions: usize,
    /// Nodes whose voxel faces became resident this frame.
    pub nodes_completed: usize,
    /// Leaves whose triangles became resident this frame.
    pub source_completed: usize,
    /// Requests (of both kinds) still waiting after the frame (including a partly uploaded
    /// entry).
    pub pending: usize,
    /// The cache was full of entries this frame needs, so a request had to wait (leaf
    /// triangles after it are still tried).
    pub starved: bool,
    /// Entries larger than the whole cache budget (never drawable at this budget; a leaf's
    /// triangles that large leave it drawn as voxels).
    pub too_big: usize,
    /// Stream passes made for this frame: 1 for a real-time frame (the window, `--fly
    /// --real-time`); for a complete frame (`Viewer::complete_frame`, the `--fly` default) the
    /// passes until nothing the frame wants was pending, or a pass made no progress.
    pub passes: u32,
}

/// The two kinds of cache entry: a node's voxel faces, a leaf's source triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Faces,
    Triangles,
}

/// What an entry's buffer holds.
enum Layout {
    /// Face instances grouped by direction (`ranges[dir]`).
    Faces([Range<u32>; 6]),
    /// Vertices, then indices.
    Triangles(TriangleLayout),
}

/// A resident entry: its GPU buffer (none for a node without faces).
struct Resident {
    buffer: Option<wgpu::Buffer>,
    layout: Layout,
    bytes: u64,
    last_used: u64,
}

/// The entry being uploaded: its bytes on the CPU and how far the copy has got.
struct Upload {
    kind: Kind,
    node: usize,
    data: Vec<u8>,
    done: u64,
    buffer: wgpu::Buffer,
    layout: Layout,
}

/// A request: an entry of a node of the cut.
type Request = (Kind, cut::CutNode);

/// The node cache and upload queue of the viewer (see the module docs).
pub struct Stream {
    config: StreamConfig,
    /// Every world position on the GPU is relative to this point (f32 precision).
    origin: DVec3,
    /// Voxel faces per node.
    resident: Vec<Option<Resident>>,
    /// Source triangles per node (leaves only).
    triangles: Vec<Option<Resident>>,
    /// Triangles stored beside each node (the file's index; 0 without the channel).
    stored: Vec<u32>,
    /// Leaves drawn as voxels although over the error: their triangles exceed the budget.
    refused: Vec<bool>,
    /// The frame tick at which each leaf was last wanted as triangles.
    wanted: Vec<u64>,
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
    /// Drawn from its source triangles instead of its voxels.
    pub triangles: bool,
}

/// The source triangles to draw in a frame.
pub(crate) struct SourceDraw<'a> {
    pub batches: Vec<SourceBatch<'a>>,
    pub leaves: u64,
    pub triangles: u64,
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
        let n = reader.nodes().len();
        Ok(Stream {
            config,
            origin,
            resident: (0..n).map(|_| None).collect(),
            triangles: (0..n).map(|_| None).collect(),
            stored: (0..n)
                .map(|i| reader.node_source_triangle_count(i))
                .collect(),
            refused: vec![false; n],
            wanted: vec![0; n],
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

    /// Indices of the leaves whose source triangles are resident, ascending.
    pub fn resident_triangle_leaves(&self) -> Vec<usize> {
        (0..self.triangles.len())
            .filter(|&i| self.triangles[i].is_some())
            .collect()
    }

    /// True if the cut node `c` is to be drawn from its source triangles: a leaf over the
    /// error that stores triangles fitting the budget, with source drawing on.
    fn by_triangles(&self, c: &cut::CutNode) -> bool {
        self.config.source && c.over && self.stored[c.index] > 0 && !self.refused[c.index]
    }

    /// True if the entry of `kind` of node `i` is resident.
    fn has(&self, kind: Kind, i: usize) -> bool {
        match kind {
            Kind::Faces => self.resident[i].is_some(),
            Kind::Triangles => self.triangles[i].is_some(),
        }
    }

    fn entries(&mut self, kind: Kind) -> &mut Vec<Option<Resident>> {
        match kind {
            Kind::Faces => &mut self.resident,
            Kind::Triangles => &mut self.triangles,
        }
    }

    /// One frame for `shot`: find the cut, count hits and misses, upload within the limit
    /// (evicting least recently used nodes), and choose the nodes to draw.
    pub(crate) fn frame(
        &mut self,
        reader: &Reader,
        renderer: &Renderer,
        shot: &Shot,
    ) -> Result<(FrameStats, Vec<Drawn>), RenderError> {
        // The per-frame steps in order: cut, requests, upload, draw list.
        let tick = self.frame + 1;
        let px = self.config.max_error_px;
        let mut stats = FrameStats {
            frame: self.frame,
            cache_budget: self.config.cache_bytes,
            upload_limit: self.upload_limit(),
            passes: 1,
            ..Default::default()
        };
        let want = cut::select(reader, shot, px);
        stats.cut_nodes = want.len();
        stats.cut_over_error = want.iter().filter(|c| c.over).count();
        stats.cut_leaf_nodes = want
            .iter()
            .filter(|c| reader.nodes()[c.index].level == 0)
            .count();
        // requests: the cut's missing entries, voxel nodes coarsest level first, then leaf
        // triangles, each by the largest error
        let (mut requests, triangles) = self.want(reader, &want, tick, &mut stats);
        requests.extend(triangles);
        // parents standing in for missing children are in use too; where nothing covers a
        // missing part, its coarsest uncovered ancestor is requested before everything else
        let mut drawn = Vec::new();
        if let Some(root) = reader.root() {
            let mut walk = CutWalk::new(reader, shot, tick, true);
            self.visit(&mut walk, root, false);
            let mut first: Vec<Request> = walk
                .stand_ins
                .into_iter()
                .map(|index| {
                    let c = cut::CutNode {
                        index,
                        error: cut::node_error(reader, index, shot),
                        over: false,
                    };
                    (Kind::Faces, c)
                })
                .collect();
            first.sort_by_key(|(_, c)| (std::cmp::Reverse(reader.nodes()[c.index].level), c.index));
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
            if d.triangles {
                let r = self.triangles[d.index]
                    .as_ref()
                    .expect("drawn, so resident");
                let Layout::Triangles(t) = &r.layout else {
                    unreachable!("a triangle entry")
                };
                stats.source_leaves_drawn += 1;
                stats.source_triangles_drawn += t.triangles();
                stats.source_bytes_drawn += r.bytes;
            }
        }
        stats.nodes_resident = self.resident.iter().flatten().count();
        stats.source_resident = self.triangles.iter().flatten().count();
        stats.bytes_resident = self.bytes;
        stats.source_bytes_resident = self.triangles.iter().flatten().map(|r| r.bytes).sum();
        stats.pending = requests
            .iter()
            .filter(|(k, c)| !self.has(*k, c.index))
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

    /// Hits and misses of the cut `want`: resident entries are marked used; the missing ones
    /// are returned as requests, voxel nodes (coarsest level first, then the largest error)
    /// and leaf triangles (the largest error first). A leaf wanted as triangles is marked for
    /// this frame (`wanted`), and while its triangles are missing its voxels, if resident, are
    /// marked used too: they stay drawn in its place.
    fn want(
        &mut self,
        reader: &Reader,
        want: &[cut::CutNode],
        tick: u64,
        stats: &mut FrameStats,
    ) -> (Vec<Request>, Vec<Request>) {
        let (mut faces, mut triangles) = (Vec::new(), Vec::new());
        for c in want {
            if self.by_triangles(c) {
                self.wanted[c.index] = tick;
                stats.source_leaves_wanted += 1;
                match &mut self.triangles[c.index] {
                    Some(r) => {
                        r.last_used = tick;
                        stats.source_hits += 1;
                    }
                    None => {
                        stats.source_misses += 1;
                        triangles.push((Kind::Triangles, *c));
                        if let Some(r) = &mut self.resident[c.index] {
                            r.last_used = tick;
                        }
                    }
                }
                continue;
            }
            match &mut self.resident[c.index] {
                Some(r) => {
                    r.last_used = tick;
                    stats.cache_hits += 1;
                }
                None => {
                    stats.cache_misses += 1;
                    faces.push((Kind::Faces, *c));
                }
            }
        }
        let by_error = |a: &cut::CutNode, b: &cut::CutNode| {
            b.error.total_cmp(&a.error).then(a.index.cmp(&b.index))
        };
        faces.sort_by(|(_, a), (_, b)| {
            let (la, lb) = (reader.nodes()[a.index].level, reader.nodes()[b.index].level);
            lb.cmp(&la).then(by_error(a, b))
        });
        triangles.sort_by(|(_, a), (_, b)| by_error(a, b));
        (faces, triangles)
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
            if self.wanted[i] == walk.tick && self.triangles[i].is_some() {
                walk.out.push(Drawn {
                    index: i,
                    triangles: true,
                });
                return true;
            }
            let here = self.resident[i].is_some();
            if here {
                walk.out.push(Drawn {
                    index: i,
                    triangles: false,
                });
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
                walk.out.push(Drawn {
                    index: i,
                    triangles: false,
                });
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
        requests: &[Request],
        tick: u64,
        stats: &mut FrameStats,
    ) -> Result<(), RenderError> {
        let limit = self.upload_limit();
        // a partly uploaded entry no longer wanted is dropped (its bytes freed)
        if let Some(u) = &self.upload {
            if !requests
                .iter()
                .any(|(k, c)| (*k, c.index) == (u.kind, u.node))
            {
                let u = self.upload.take().expect("checked");
                self.bytes -= u.data.len() as u64;
                u.buffer.destroy();
            }
        }
        let mut next = requests.iter();
        loop {
            if self.upload.is_none()
                && !self.start_next(reader, renderer, &mut next, tick, stats)?
            {
                break;
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
                if u.kind == Kind::Triangles {
                    stats.source_bytes_uploaded += n;
                }
            }
            if u.done < u.data.len() as u64 {
                break; // the limit is reached; the rest next frame
            }
            let u = self.upload.take().expect("set above");
            match u.kind {
                Kind::Faces => stats.nodes_completed += 1,
                Kind::Triangles => stats.source_completed += 1,
            }
            self.entries(u.kind)[u.node] = Some(Resident {
                buffer: Some(u.buffer),
                layout: u.layout,
                bytes: u.data.len() as u64,
                last_used: tick,
            });
        }
        Ok(())
    }

    /// Starts uploading the next request of `next` that is not resident and fits: reads its
    /// bytes, makes room for them and creates its buffer. A request for which the entries in
    /// use leave no room waits (`starved`), and then only the leaf triangles after it are
    /// tried. False when none is left.
    fn start_next<'r>(
        &mut self,
        reader: &Reader,
        renderer: &Renderer,
        next: &mut impl Iterator<Item = &'r Request>,
        tick: u64,
        stats: &mut FrameStats,
    ) -> Result<bool, RenderError> {
        loop {
            // after a request had to wait, only leaf triangles are tried (without reading the
            // voxel nodes): far smaller than a node's faces, they should not wait behind one
            let skip = |k: Kind| stats.starved && k == Kind::Faces;
            let Some(&(kind, c)) = next.find(|(k, c)| !skip(*k) && !self.has(*k, c.index)) else {
                return Ok(false);
            };
            let (data, layout) = match kind {
                Kind::Faces => {
                    let (data, ranges) = self.node_instances(reader, c.index)?;
                    (data, Layout::Faces(ranges))
                }
                Kind::Triangles => match leaf_entry(reader, c.index, self.origin)? {
                    Some((data, t)) => (data, Layout::Triangles(t)),
                    None => {
                        // nothing to draw after all: the leaf stays voxels
                        self.refused[c.index] = true;
                        continue;
                    }
                },
            };
            let size = data.len() as u64;
            if size == 0 {
                self.entries(kind)[c.index] = Some(Resident {
                    buffer: None,
                    layout,
                    bytes: 0,
                    last_used: tick,
                });
                stats.nodes_completed += 1;
                continue;
            }
            if size > self.config.cache_bytes {
                stats.too_big += 1;
                if kind == Kind::Triangles {
                    self.refused[c.index] = true;
                }
                continue;
            }
            if !self.make_room(size, tick, stats) {
                // it waits; a later, smaller request (a leaf's triangles) may still fit
                stats.starved = true;
                continue;
            }
            let usage = match kind {
                Kind::Faces => wgpu::BufferUsages::VERTEX,
                Kind::Triangles => wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::INDEX,
            };
            let buffer = renderer.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(match kind {
                    Kind::Faces => "node faces",
                    Kind::Triangles => "leaf triangles",
                }),
                size,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.bytes += size;
            self.upload = Some(Upload {
                kind,
                node: c.index,
                data,
                done: 0,
                buffer,
                layout,
            });
            return Ok(true);
        }
    }

    /// Evicts least recently used entries not used this frame until `size` more bytes fit;
    /// false if the entries in use leave no room.
    fn make_room(&mut self, size: u64, tick: u64, stats: &mut FrameStats) -> bool {
        while self.bytes + size > self.config.cache_bytes {
            let lru = |kind: Kind, entries: &[Option<Resident>]| {
                (0..entries.len())
                    .filter_map(|i| {
                        let r = entries[i].as_ref()?;
                        (r.last_used < tick).then_some((r.last_used, kind, i))
                    })
                    .min()
            };
            let victim = lru(Kind::Faces, &self.resident)
                .into_iter()
                .chain(lru(Kind::Triangles, &self.triangles))
                .min();
            let Some((_, kind, i)) = victim else {
                return false;
            };
            let r = self.entries(kind)[i].take().expect("resident");
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
        for d in drawn.iter().filter(|d| !d.triangles) {
            let r = self.resident[d.index]
                .as_ref()
                .expect("drawn nodes are resident");
            let Some(buffer) = &r.buffer else { continue };
            let Layout::Faces(ranges) = &r.layout else {
                unreachable!("a face entry")
            };
            let b: Aabb = reader.node_bounds(d.index).expect("a node of the file");
            for dir in 0..6usize {
                let range = ranges[dir].clone();
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

    /// The source triangles to draw for `drawn` (the leaves drawn as triangles).
    pub(crate) fn source_batches<'a>(&'a self, drawn: &[Drawn]) -> SourceDraw<'a> {
        let mut out = SourceDraw {
            batches: Vec::new(),
            leaves: 0,
            triangles: 0,
        };
        for d in drawn.iter().filter(|d| d.triangles) {
            let r = self.triangles[d.index]
                .as_ref()
                .expect("drawn triangles are resident");
            let (Some(buffer), Layout::Triangles(t)) = (&r.buffer, &r.layout) else {
                unreachable!("a triangle entry has a buffer")
            };
            out.batches.push(t.batch(buffer));
            out.leaves += 1;
            out.triangles += t.triangles();
        }
        out
    }
}
