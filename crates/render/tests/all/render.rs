//! GPU pictures of the Stanford bunny's octree (wgpu; lavapipe in CI) against a CPU
//! projection of the same voxels: every voxel's cube rasterized on the CPU at pixel centres
//! with the same camera. The covered pixels must agree (IoU > 0.9), the picture must not be
//! blank, must frame the model (nothing touches the border), and must be shaded (the voxel
//! normals under the light give many grey levels). No adapter is a FAILURE, not a skip.

use crate::common;

use voxlod_format::Reader;
use voxlod_render::{frame, Lod, Picture, Renderer, Shot, View};
use voxlod_voxelize::Mode;

/// Pixels covered by the cubes of every voxel of `nodes`, rasterized on the CPU: each cube's
/// 12 triangles projected with `shot`, pixel centres inside any of them.
fn cpu_coverage(r: &Reader, nodes: &[usize], shot: &Shot) -> Vec<bool> {
    let (w, h) = (shot.width as usize, shot.height as usize);
    let mut cov = vec![false; w * h];
    let spec = r.spec();
    // the 12 triangles of the unit cube, by corner index (bit 0 x, bit 1 y, bit 2 z)
    const TRIS: [[usize; 3]; 12] = [
        [0, 1, 3],
        [0, 3, 2],
        [4, 5, 7],
        [4, 7, 6],
        [0, 1, 5],
        [0, 5, 4],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 3, 7],
        [1, 7, 5],
    ];
    for &i in nodes {
        let e = r.nodes()[i];
        let edge = spec.voxel_size_at(e.level);
        for v in r.read_node(i).unwrap() {
            let min = spec.voxel_min_corner(e.level, e.pos(), v.pos());
            let corners: Vec<[f64; 3]> = (0..8)
                .map(|k| {
                    let p: [f64; 3] =
                        std::array::from_fn(|a| min[a] + edge * ((k >> a) & 1) as f64);
                    shot.project(p).expect("voxel behind the eye")
                })
                .collect();
            for t in TRIS {
                let [a, b, c] = t.map(|k| corners[k]);
                let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                if area == 0.0 {
                    continue;
                }
                let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
                let x1 = (a[0].max(b[0]).max(c[0]).ceil() as usize).min(w);
                let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
                let y1 = (a[1].max(b[1]).max(c[1]).ceil() as usize).min(h);
                for y in y0..y1 {
                    for x in x0..x1 {
                        let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                        let e = |p: [f64; 3], q: [f64; 3]| {
                            ((q[0] - p[0]) * (py - p[1]) - (q[1] - p[1]) * (px - p[0]))
                                * area.signum()
                        };
                        if e(a, b) >= 0.0 && e(b, c) >= 0.0 && e(c, a) >= 0.0 {
                            cov[y * w + x] = true;
                        }
                    }
                }
            }
        }
    }
    cov
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    inter as f64 / union.max(1) as f64
}

/// Not blank, framed, shaded; returns the covered fraction.
fn check_picture(p: &Picture, what: &str) -> f64 {
    let (w, h) = (p.width as usize, p.height as usize);
    let cov = p.coverage();
    let covered = cov.iter().filter(|&&c| c).count();
    let frac = covered as f64 / (w * h) as f64;
    assert!(frac > 0.05, "{what}: only {frac:.3} of the picture covered");
    for x in 0..w {
        assert!(
            !cov[x] && !cov[(h - 1) * w + x],
            "{what}: model touches the top/bottom border"
        );
    }
    for y in 0..h {
        assert!(
            !cov[y * w] && !cov[y * w + w - 1],
            "{what}: model touches the left/right border"
        );
    }
    // shading: grey levels of covered pixels spread out (the bunny has no colour: white voxels)
    let lum: Vec<f64> = p
        .rgba
        .chunks_exact(4)
        .zip(&cov)
        .filter(|(_, c)| **c)
        .map(|(px, _)| 0.299 * px[0] as f64 + 0.587 * px[1] as f64 + 0.114 * px[2] as f64)
        .collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let sd = (lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64).sqrt();
    let mut levels: Vec<u8> = lum.iter().map(|&l| l as u8).collect();
    levels.sort_unstable();
    levels.dedup();
    assert!(
        sd > 15.0 && levels.len() > 60,
        "{what}: flat shading (sd {sd:.1}, {} levels)",
        levels.len()
    );
    frac
}

#[test]
fn bunny_pictures_match_a_cpu_projection() {
    let Some(m) = common::meshes() else { return };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bunny.voxlod");
    common::build(&m, "stanford-bunny/bun_zipper.ply", &file, 512, Mode::Thin);
    let r = Reader::open(&file).unwrap();
    let renderer = match Renderer::new() {
        Ok(x) => x,
        Err(e) => panic!("no GPU adapter: the render test needs one (lavapipe: apt-get install mesa-vulkan-drivers libvulkan1): {e}"),
    };
    eprintln!("adapter: {}", renderer.adapter());

    let view = View {
        width: 320,
        height: 240,
        ..View::default()
    };
    for lod in [Lod::Level(0), Lod::Level(1), Lod::Error(1.0)] {
        let (shot, nodes) = frame(&r, &view, lod).unwrap();
        let pic = renderer.render(&r, &nodes, &shot).unwrap();
        let what = format!("{lod:?}");
        let frac = check_picture(&pic, &what);
        let cpu = cpu_coverage(&r, &nodes, &shot);
        let score = iou(&pic.coverage(), &cpu);
        eprintln!(
            "{what}: {} nodes, {} faces drawn, {frac:.3} covered, IoU {score:.4}",
            nodes.len(),
            pic.faces_drawn
        );
        assert!(score > 0.9, "{what}: IoU {score} of GPU and CPU coverage");
    }

    // another view direction draws another silhouette (the camera really moves)
    let (s1, n1) = frame(&r, &view, Lod::Level(1)).unwrap();
    let side = View {
        direction: [-1.0, 0.2, 0.0],
        ..view
    };
    let (s2, n2) = frame(&r, &side, Lod::Level(1)).unwrap();
    let a = renderer.render(&r, &n1, &s1).unwrap().coverage();
    let b = renderer.render(&r, &n2, &s2).unwrap().coverage();
    assert!(
        iou(&a, &b) < 0.8,
        "front and side silhouettes should differ"
    );
    assert!(iou(&b, &cpu_coverage(&r, &n2, &s2)) > 0.9);

    // the picture written as PNG decodes to the same pixels
    let (shot, nodes) = frame(&r, &view, Lod::Level(1)).unwrap();
    let pic = renderer.render(&r, &nodes, &shot).unwrap();
    let png_path = dir.path().join("bunny.png");
    pic.write_png(&png_path).unwrap();
    let dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&png_path).unwrap(),
    ));
    let mut rd = dec.read_info().unwrap();
    let mut buf = vec![0; rd.output_buffer_size().unwrap()];
    let info = rd.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (320, 240));
    let rgb: Vec<u8> = pic
        .rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    assert!(buf[..info.buffer_size()] == rgb[..]);
}
