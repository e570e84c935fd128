//! The renderer-facing reader API on a sphere surface in a 1024³ grid (3 levels): the
//! depth-first walk against a recursive reference, level picking, conservative node boxes
//! against every decoded voxel, and the screen-space error cut against a brute-force check of
//! its defining properties (a cover without overlap, refined exactly where the error is too
//! large, the error recomputed here from the projection formula).

use crate::common;

use std::collections::{BTreeMap, HashMap};

use common::sphere::{sphere_grid, Colour};
use voxlod_format::{encode_node, Camera, FileSpec, Reader, Voxel, Writer, MODE_CONSERVATIVE};

fn sphere_file(dir: &std::path::Path) -> (Reader, Vec<BTreeMap<[u32; 3], Vec<Voxel>>>) {
    let spec = FileSpec::new(1024, MODE_CONSERVATIVE, [-5.0, 1.0, 2.0], 0.01);
    // off-centre, so some chunks are empty and some parents have fewer than 8 children
    let leaves = sphere_grid(1024, [380.0, 420.0, 300.0], 260.0, Colour::Smooth)
        .into_iter()
        .map(|(g, v)| (g, v.mask(), v.normal, v.color));
    let levels = common::build_levels(&spec, leaves);
    let path = dir.join("sphere.voxlod");
    let mut w = Writer::create(&path, spec).unwrap();
    let chunks: Vec<[u32; 3]> = levels[0].keys().copied().collect();
    for (l, p, m) in common::post_order(spec.levels, &chunks) {
        w.write_node(l, p, m, &encode_node(&levels[l as usize][&p], 1).unwrap())
            .unwrap();
    }
    w.finish(&serde_json::json!({})).unwrap();
    (Reader::open(&path).unwrap(), levels)
}

/// Recursive pre-order over the in-memory levels, children in octant order.
fn pre_order(
    levels: &[BTreeMap<[u32; 3], Vec<Voxel>>],
    l: u32,
    p: [u32; 3],
    out: &mut Vec<(u32, [u32; 3])>,
) {
    if !levels[l as usize].contains_key(&p) {
        return;
    }
    out.push((l, p));
    if l > 0 {
        for i in 0..8 {
            let c = [
                2 * p[0] + (i & 1),
                2 * p[1] + (i >> 1 & 1),
                2 * p[2] + (i >> 2 & 1),
            ];
            pre_order(levels, l - 1, c, out);
        }
    }
}

/// Independent screen-space error: edge · H / (2·tan(fov/2)·d), d the distance from the eye
/// to the node's voxel box computed here from the decoded voxels.
fn error_of(cam: &Camera, spec: &FileSpec, level: u32, pos: [u32; 3], voxels: &[Voxel]) -> f64 {
    let edge = spec.voxel_size * 2f64.powi(level as i32);
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for v in voxels {
        for a in 0..3 {
            let c = spec.origin[a] + edge * (256.0 * pos[a] as f64 + v.pos()[a] as f64);
            lo[a] = lo[a].min(c);
            hi[a] = hi[a].max(c + edge);
        }
    }
    let d = (0..3)
        .map(|a| {
            let e = cam.position[a];
            let t = if e < lo[a] {
                lo[a] - e
            } else if e > hi[a] {
                e - hi[a]
            } else {
                0.0
            };
            t * t
        })
        .sum::<f64>()
        .sqrt();
    edge * cam.viewport_height / (2.0 * (cam.fov_y / 2.0).tan() * d)
}

#[test]
fn walk_levels_bounds_and_error_cut() {
    let dir = tempfile::tempdir().unwrap();
    let (r, levels) = sphere_file(dir.path());
    let spec = r.spec();
    assert_eq!(spec.levels, 3);
    assert!(
        levels[0].len() > 8 && levels[0].len() < 64,
        "{} leaves",
        levels[0].len()
    );

    // depth-first walk = recursive pre-order
    let mut expect = Vec::new();
    pre_order(&levels, 2, [0, 0, 0], &mut expect);
    let walked: Vec<(u32, [u32; 3])> = r
        .depth_first()
        .map(|i| (r.nodes()[i].level, r.nodes()[i].pos()))
        .collect();
    assert_eq!(walked, expect);
    assert_eq!(walked.len(), r.nodes().len());

    // level picking
    for l in 0..3 {
        let got: Vec<[u32; 3]> = r.level_nodes(l).map(|i| r.nodes()[i].pos()).collect();
        assert_eq!(got.len(), levels[l as usize].len(), "level {l}");
        assert!(got.iter().all(|p| levels[l as usize].contains_key(p)));
    }

    // node boxes: tight around every decoded voxel's cube, parents contain children
    let mut voxels = HashMap::new();
    let mut buf = Vec::new();
    for i in 0..r.nodes().len() {
        r.read_node_into(i, &mut buf).unwrap();
        let e = r.nodes()[i];
        let b = r.node_bounds(i).unwrap();
        let edge = spec.voxel_size_at(e.level);
        for a in 0..3 {
            let at = |v: f64| spec.origin[a] + edge * (256.0 * e.pos()[a] as f64 + v);
            let lo = buf.iter().map(|v| v.pos()[a]).min().unwrap() as f64;
            let hi = buf.iter().map(|v| v.pos()[a]).max().unwrap() as f64;
            assert_eq!(
                (b.min[a], b.max[a]),
                (at(lo), at(hi + 1.0)),
                "node {i} axis {a}"
            );
        }
        assert!(r.chunk_bounds(i).unwrap().contains(&b));
        for c in r.children(i).into_iter().flatten() {
            assert!(b.contains(&r.node_bounds(c).unwrap()), "node {i} child {c}");
        }
        voxels.insert(i, buf.clone());
    }

    // screen-space error cut for cameras near, inside and far, several thresholds
    let fov = 50f64.to_radians();
    let centre = [-5.0 + 3.8, 1.0 + 4.2, 2.0 + 3.0];
    let cams = [
        Camera::new([centre[0], centre[1], centre[2] + 8.0], fov, 720.0),
        Camera::new(
            [centre[0] + 2.0, centre[1] - 1.0, centre[2] + 2.0],
            fov,
            1080.0,
        ),
        Camera::new(centre, fov, 1080.0),
        Camera::new([centre[0], centre[1], centre[2] + 500.0], fov, 1080.0),
    ];
    for (ci, cam) in cams.iter().enumerate() {
        let mut prev_len = 0;
        for &thr in &[64.0, 8.0, 2.0, 1.0, 0.5] {
            let sel = r.select_by_error(cam, thr);
            // each leaf has exactly one selected ancestor-or-self
            for (leaf_i, e) in r.nodes().iter().enumerate().filter(|(_, e)| e.level == 0) {
                let n = sel
                    .iter()
                    .filter(|&&s| {
                        let se = r.nodes()[s];
                        (0..3).all(|a| e.pos()[a] >> se.level == se.pos()[a])
                    })
                    .count();
                assert_eq!(
                    n, 1,
                    "camera {ci} thr {thr}: leaf {leaf_i} covered {n} times"
                );
            }
            for &s in &sel {
                let e = r.nodes()[s];
                let err = error_of(cam, &spec, e.level, e.pos(), &voxels[&s]);
                // refined exactly where the error is too large
                assert!(
                    e.level == 0 || err <= thr,
                    "camera {ci}: node {s} error {err} > {thr}"
                );
                if e.level + 1 < spec.levels {
                    let p = r.find(e.level + 1, [e.x / 2, e.y / 2, e.z / 2]).unwrap();
                    let pe = error_of(cam, &spec, e.level + 1, r.nodes()[p].pos(), &voxels[&p]);
                    assert!(
                        pe > thr,
                        "camera {ci}: parent of {s} has error {pe} ≤ {thr}"
                    );
                }
                let api = r.screen_error(s, cam).unwrap();
                assert!(
                    (api - err).abs() <= 1e-9 * err.max(1.0)
                        || (api.is_infinite() && err.is_infinite())
                );
            }
            assert!(
                sel.len() >= prev_len,
                "smaller thresholds never select fewer nodes"
            );
            prev_len = sel.len();
        }
    }
    // far away the root alone; inside the model every leaf
    assert_eq!(r.select_by_error(&cams[3], 1.0), vec![r.root().unwrap()]);
    let inside = r.select_by_error(&cams[2], 1e-6);
    assert_eq!(inside.len(), levels[0].len());
}
