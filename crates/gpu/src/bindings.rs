//! Bind-group slots of the shaders' storage buffers: every pass uses bind group 0, and each
//! buffer's slot here must equal the `@binding(n)` of the WGSL global of the same name in
//! `shaders/classify.wgsl` and `shaders/raster.wgsl` (checked against the parsed shaders by
//! `tests/shaders.rs`, with naga's reflection).

/// `params`: the chunk's `Params` (origin, mode, cutoff, phase, …), read-only.
pub const PARAMS: u32 = 0;
/// `tris`: the batch's triangles, read-only.
pub const TRIS: u32 = 1;
/// `occ`: the chunk's 256³ occupancy bitset.
pub const OCC: u32 = 2;
/// `deferred`: the large triangles deferred to the fragment pass (read-only there).
pub const DEFERRED: u32 = 3;
/// `draw_args`: the fragment pass's indirect draw arguments (compute passes only).
pub const DRAW_ARGS: u32 = 4;
/// `base`: the compaction's slot base of each bitset word (read-only in the fragment pass).
pub const BASE: u32 = 5;
/// `accum`: the attribute accumulators of the current window.
pub const ACCUM: u32 = 6;
/// `counter`: counters and the list of triangles decided on the host.
pub const COUNTER: u32 = 7;

/// Every slot with the name of its WGSL global, in slot order.
pub const SLOTS: [(&str, u32); 8] = [
    ("params", PARAMS),
    ("tris", TRIS),
    ("occ", OCC),
    ("deferred", DEFERRED),
    ("draw_args", DRAW_ARGS),
    ("base", BASE),
    ("accum", ACCUM),
    ("counter", COUNTER),
];
