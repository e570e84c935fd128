//! Streaming nodes into a fixed GPU budget, as the renderer of Chajdas, Reitinger &
//! Westermann ("Scalable rendering for very large meshes", WSCG 2014, section 5 and
//! Figure 14): each frame the screen-space error cut ([`crate::cut`]) says which nodes the
//! camera needs; those not resident are requested, coarsest level first; a fixed number of
//! bytes per frame is uploaded (a node larger than that arrives over several frames); the
//! cache holds at most its budget of bytes and evicts the least recently used nodes; a node
//! is drawn only when resident, and where a refined node's children are not all resident yet
//! the parent stays drawn in their place.
//!
//! A resident node is one GPU vertex buffer of its voxels as the file decodes them (the three
//! words of each record, [`VOXEL_BYTES`] per voxel, nothing per face: "we never store the
//! geometric representation but rather generate it on-the-fly from the voxel buffers",
//! section 4); the vertex shader makes each voxel's at most three faces towards the eye. The
//! CPU holds only the node being uploaded.
//!
//! **Occlusion culling** (section 4). With [`StreamConfig::occlusion`], every voxel node drawn
//! is drawn inside an occlusion query, nearest first; the results of a draw
//! ([`Stream::occlusion_results`]) mark the nodes none of whose samples passed the depth test
//! as hidden, and a refined node all of whose drawn parts were hidden as hidden too. In the
//! next frame the cut is not refined below a hidden node (its children are neither requested
//! nor drawn: `occluded_nodes`); the node itself is drawn as a probe (depth tested, no colour
//! or depth written) inside a query, and refined again once a sample of it passes.
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

use glam::DVec3;
use voxlod_format::{Aabb, Reader, Voxel};

use super::source::{leaf_entry, TriangleLayout};
use crate::camera::Shot;
use crate::cut;
use crate::draw::{Batch, NodeConstants, Renderer, SourceBatch, VOXEL_BYTES};
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
    /// Occlusion culling: nodes found hidden behind nearer ones by the last draw's occlusion
    /// queries are not refined (false: `--no-occlusion`).
    pub occlusion: bool,
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
    /// Faces drawn: of the nodes drawn (probes included), per voxel the faces of the axes on
    /// which the eye is outside the node's box that the face mask allows, and on the other
    /// axes each voxel's faces of the axis (an upper bound there: the vertex shader draws
    /// one face per axis at most, none where the eye is inside the voxel's slab).
    pub faces_drawn: u64,
    /// Active faces (face-mask bits) of the voxels of the drawn nodes.
    pub faces_resident_in_drawn: u64,
    /// Voxels of the drawn nodes (one instance each).
    pub voxels_drawn: u64,
    /// Nodes the cut did not refine because the last draw found them hidden behind nearer
    /// ones (occlusion culling; 0 with `--no-occlusion`).
    pub occluded_nodes: usize,
    /// Nodes drawn as occlusion probes (hidden in the last draw: depth tested, nothing
    /// written); they count in `drawn_nodes` and `faces_drawn`.
    pub probe_nodes: usize,
    /// Of the probes, those a sample of which passed (refined again from the next frame).
    pub probes_passed: usize,
    /// Draws made for this frame: 1, or for a complete frame with occlusion culling more when
    /// probes passed (each time the frame is streamed and drawn again, refined where they did).
    pub draws: u32,
    /// Wall milliseconds of the frame's GPU draws (encoding, submitting and waiting for them,
    /// with the picture's read-back); the measure of the draw on a hardware GPU.
    pub draw_ms: f64,
    /// Nodes whose voxels are resident after the frame.
    pub nodes_resident: usize,
    /// Voxels of those nodes (their buffers hold [`VOXEL_BYTES`] per voxel).
    pub voxels_resident: u64,
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

/// The two kinds of cache entry: a node's voxels, a leaf's source triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Voxels,
    Triangles,
}

/// What a node's voxel buffer holds: its voxels with a face (instances), and how many of them
/// have each face-mask bit and each axis (either bit).
#[derive(Clone, Copy, Debug, Default)]
struct VoxelCounts {
    voxels: u32,
    dirs: [u32; 6],
    axes: [u32; 3],
}

/// What an entry's buffer holds.
enum Layout {
    /// Voxel records.
    Voxels(VoxelCounts),
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
    /// Per node, the number of the draw that found it hidden (occlusion culling); a node is
    /// hidden for the next draw only.
    hidden_at: Vec<u64>,
    /// Draws whose occlusion results were taken.
    draws: u64,
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
    /// Drawn as an occlusion probe (hidden in the last draw).
    pub probe: bool,
}

/// Faces of a frame's drawn voxel nodes (see [`FrameStats`]).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FaceCounts {
    /// Face-mask bits.
    pub resident: u64,
    /// Faces drawn (a bound; `faces_drawn`).
    pub drawn: u64,
    /// Voxels.
    pub voxels: u64,
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
            hidden_at: vec![0; n],
            draws: 0,
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

    /// True if the last draw found node `i` hidden (with occlusion culling on).
    fn is_hidden(&self, i: usize) -> bool {
        self.config.occlusion && self.draws > 0 && self.hidden_at[i] == self.draws
    }

    /// Turns occlusion culling on or off (off: every node is refined as the cut says).
    pub fn set_occlusion(&mut self, on: bool) {
        self.config.occlusion = on;
    }

    /// True if the entry of `kind` of node `i` is resident.
    fn has(&self, kind: Kind, i: usize) -> bool {
        match kind {
            Kind::Voxels => self.resident[i].is_some(),
            Kind::Triangles => self.triangles[i].is_some(),
        }
    }

    fn entries(&mut self, kind: Kind) -> &mut Vec<Option<Resident>> {
        match kind {
            Kind::Voxels => &mut self.resident,
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
        let (want, occluded) = cut::select_unless(reader, shot, px, &|i| self.is_hidden(i));
        stats.occluded_nodes = occluded;
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
                    (Kind::Voxels, c)
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
        stats.voxels_resident = self
            .resident
            .iter()
            .flatten()
            .map(|r| match r.layout {
                Layout::Voxels(c) => c.voxels as u64,
                Layout::Triangles(_) => 0,
            })
            .sum();
        stats.probe_nodes = drawn.iter().filter(|d| d.probe).count();
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
                    faces.push((Kind::Voxels, *c));
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
        let hidden = self.is_hidden(i);
        if hidden || !cut::refines(reader, i, shot, self.config.max_error_px) {
            if self.wanted[i] == walk.tick && self.triangles[i].is_some() {
                walk.out.push(Drawn {
                    index: i,
                    triangles: true,
                    probe: false,
                });
                return true;
            }
            let here = self.resident[i].is_some();
            if here {
                walk.out.push(Drawn {
                    index: i,
                    triangles: false,
                    probe: hidden,
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
                    probe: false,
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
                Kind::Voxels => stats.nodes_completed += 1,
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
            let skip = |k: Kind| stats.starved && k == Kind::Voxels;
            let Some(&(kind, c)) = next.find(|(k, c)| !skip(*k) && !self.has(*k, c.index)) else {
                return Ok(false);
            };
            let (data, layout) = match kind {
                Kind::Voxels => {
                    let (data, counts) = self.node_voxels(reader, c.index)?;
                    (data, Layout::Voxels(counts))
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
                Kind::Voxels => wgpu::BufferUsages::VERTEX,
                Kind::Triangles => wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::INDEX,
            };
            let buffer = renderer.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(match kind {
                    Kind::Voxels => "node voxels",
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
            let victim = lru(Kind::Voxels, &self.resident)
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

    /// The voxels of node `i` that have a face (their records as decoded, as bytes) and
    /// their counts.
    fn node_voxels(
        &mut self,
        reader: &Reader,
        i: usize,
    ) -> Result<(Vec<u8>, VoxelCounts), RenderError> {
        reader.read_node_into(i, &mut self.voxels)?;
        self.voxels.retain(|v| v.mask() != 0);
        let mut counts = VoxelCounts {
            voxels: self.voxels.len() as u32,
            ..Default::default()
        };
        for v in &self.voxels {
            let m = v.mask();
            for d in 0..6 {
                counts.dirs[d] += (m >> d & 1) as u32;
            }
            for a in 0..3 {
                counts.axes[a] += (m >> (2 * a) & 3 != 0) as u32;
            }
        }
        let data = bytemuck::cast_slice(&self.voxels).to_vec();
        debug_assert_eq!(data.len() as u64, counts.voxels as u64 * VOXEL_BYTES);
        Ok((data, counts))
    }

    /// The voxel batches to draw for `drawn`, as occlusion culling wants them: the nodes
    /// drawn normally nearest first (by the nearest view depth of their boxes), then the
    /// probes, nearest first; each inside an occlusion query with occlusion culling on. Also
    /// returns, per batch, its entry of `drawn`, and the counts of [`FaceCounts`].
    pub(crate) fn batches<'a>(
        &'a self,
        reader: &Reader,
        shot: &Shot,
        drawn: &[Drawn],
        two_sided: bool,
    ) -> (Vec<Batch<'a>>, Vec<usize>, FaceCounts) {
        let mut order: Vec<(bool, f64, usize, usize)> = drawn
            .iter()
            .enumerate()
            .filter(|(_, d)| !d.triangles)
            .map(|(k, d)| {
                let b = reader.node_bounds(d.index).expect("a node of the file");
                (d.probe, cut::nearest_depth(shot, b), d.index, k)
            })
            .collect();
        order.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut out = Vec::new();
        let mut which = Vec::new();
        let mut counts = FaceCounts::default();
        for (probe, _, index, k) in order {
            let r = self.resident[index]
                .as_ref()
                .expect("drawn nodes are resident");
            let Layout::Voxels(c) = &r.layout else {
                unreachable!("a voxel entry")
            };
            counts.resident += c.dirs.iter().map(|&n| n as u64).sum::<u64>();
            counts.voxels += c.voxels as u64;
            let b: Aabb = reader.node_bounds(index).expect("a node of the file");
            for a in 0..3 {
                counts.drawn += if shot.eye[a] > b.max[a] {
                    if two_sided {
                        c.axes[a]
                    } else {
                        c.dirs[2 * a]
                    }
                } else if shot.eye[a] < b.min[a] {
                    if two_sided {
                        c.axes[a]
                    } else {
                        c.dirs[2 * a + 1]
                    }
                } else if two_sided {
                    c.axes[a]
                } else {
                    c.dirs[2 * a] + c.dirs[2 * a + 1]
                } as u64;
            }
            let Some(buffer) = &r.buffer else { continue };
            out.push(Batch {
                buffer,
                voxels: 0..c.voxels,
                node: NodeConstants::of(reader, index, self.origin),
                probe,
                query: self.config.occlusion,
            });
            which.push(k);
        }
        (out, which, counts)
    }

    /// Takes the occlusion results of a draw of `drawn` for `shot`: `passed[k]` for entry `k`
    /// (none where no query was made). A node drawn whose query passed no sample is hidden in
    /// the next draw; so is a node refined in this one all of whose children in the frustum
    /// had something drawn, all of it hidden. Returns the number of probes that passed (their
    /// nodes are refined again).
    pub(crate) fn occlusion_results(
        &mut self,
        reader: &Reader,
        shot: &Shot,
        drawn: &[Drawn],
        passed: &[Option<bool>],
    ) -> usize {
        self.draws += 1;
        if !self.config.occlusion {
            return 0;
        }
        let mut result = std::collections::HashMap::new();
        let mut revealed = 0;
        for (d, p) in drawn.iter().zip(passed) {
            result.insert(d.index, *p);
            revealed += (d.probe && *p == Some(true)) as usize;
        }
        // the ancestors of drawn nodes are the nodes refined in this draw
        let mut refined = std::collections::HashSet::new();
        for d in drawn {
            let mut i = d.index;
            while let Some(p) = parent(reader, i) {
                if !refined.insert(p) {
                    break;
                }
                i = p;
            }
        }
        if let Some(root) = reader.root() {
            self.pull_up(reader, shot, root, &result, &refined);
        }
        revealed
    }

    /// Whether the subtree of node `i` was hidden in the draw (`Some(true)`), seen
    /// (`Some(false)`), or not known (`None`: nothing drawn, out of the frustum); marks the
    /// hidden nodes.
    fn pull_up(
        &mut self,
        reader: &Reader,
        shot: &Shot,
        i: usize,
        result: &std::collections::HashMap<usize, Option<bool>>,
        refined: &std::collections::HashSet<usize>,
    ) -> Option<bool> {
        let hidden = if let Some(p) = result.get(&i) {
            p.map(|passed| !passed)
        } else if refined.contains(&i) {
            let b = reader.node_bounds(i).expect("a node of the file");
            if !cut::in_frustum(shot, b) {
                return None;
            }
            let mut any_hidden = false;
            let mut all_hidden = true;
            for c in reader.children(i).into_iter().flatten() {
                match self.pull_up(reader, shot, c, result, refined) {
                    Some(true) => any_hidden = true,
                    Some(false) => all_hidden = false,
                    None => {
                        // outside the frustum it hides nothing; inside, with nothing drawn,
                        // it is not known to be hidden
                        let cb = reader.node_bounds(c).expect("a node of the file");
                        if cut::in_frustum(shot, cb) {
                            all_hidden = false;
                        }
                    }
                }
            }
            Some(any_hidden && all_hidden)
        } else {
            None
        };
        if hidden == Some(true) {
            self.hidden_at[i] = self.draws;
        }
        hidden
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

/// The parent of node `i`, none for the root.
fn parent(reader: &Reader, i: usize) -> Option<usize> {
    let e = reader.nodes()[i];
    if e.level + 1 >= reader.spec().levels {
        return None;
    }
    reader.find(e.level + 1, e.pos().map(|p| p / 2))
}
