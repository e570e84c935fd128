//! The bound the crate docs (section "Attributes") and docs/FORMAT.md section 6 state for the
//! attributes against the input's own numbers: a triangle's corners in grid coordinates are
//! rounded to f32 once (`Grid::to_grid`), each coordinate by at most ε ≤ 2⁻²⁴·R voxel, so its
//! face normal turns by at most `√3·ε·(|e1|+|e2|)/A` radians to first order (exactly:
//! `sin θ ≤ (2√3·ε·(|e1|+|e2|) + 12·ε²)/(2A)`). Checked on random triangles of every shape,
//! slivers among them, against the corners computed in f64 from the same f32 world positions.

use voxlod_geom::Grid;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn len(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

#[test]
fn face_normals_on_the_f32_grid_turn_within_the_stated_bound() {
    let r = 512u32;
    // an origin and voxel size that are not powers of two, as fitted grids have
    let grid = Grid::new([-13.37, 2.25, -0.618], 374.73, r).unwrap();
    let eps = (r as f64) * 2f64.powi(-24);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut checked, mut worst) = (0, 0.0f64);
    for i in 0..20_000 {
        // triangles of 1e-3 to 30 voxels, some of them slivers (a corner near an edge)
        let size = 10f64.powf(-3.0 + 4.5 * rnd());
        let c = [
            rnd() * 500.0 + 5.0,
            rnd() * 500.0 + 5.0,
            rnd() * 500.0 + 5.0,
        ];
        let mut g = [[0.0; 3]; 3];
        for v in &mut g {
            *v = [0, 1, 2].map(|k| c[k] + (rnd() - 0.5) * size);
        }
        if i % 3 == 0 {
            let t = rnd();
            let squash = 10f64.powf(-4.0 * rnd());
            g[2] = [0, 1, 2].map(|k| {
                let on_edge = g[0][k] + t * (g[1][k] - g[0][k]);
                on_edge + squash * (g[2][k] - on_edge)
            });
        }
        // the input's own numbers: f32 world positions; their grid coordinates in f64
        let world: Vec<[f32; 3]> = g
            .iter()
            .map(|p| [0, 1, 2].map(|k| (grid.origin[k] + p[k] * grid.voxel_size) as f32))
            .collect();
        let exact: Vec<[f64; 3]> = world
            .iter()
            .map(|p| [0, 1, 2].map(|k| (p[k] as f64 - grid.origin[k]) / grid.voxel_size))
            .collect();
        let rounded: Vec<[f64; 3]> = world
            .iter()
            .map(|&p| grid.to_grid(p).map(f64::from))
            .collect();
        for (a, b) in exact.iter().zip(&rounded) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= eps, "{a:?} {b:?}");
            }
        }
        let (e1, e2) = (sub(exact[1], exact[0]), sub(exact[2], exact[0]));
        let n = cross(e1, e2);
        let m = cross(sub(rounded[1], rounded[0]), sub(rounded[2], rounded[0]));
        let area = len(n) / 2.0;
        if area == 0.0 || len(m) == 0.0 {
            continue;
        }
        let first_order = 3f64.sqrt() * eps * (len(e1) + len(e2)) / area;
        let sin_bound =
            (2.0 * 3f64.sqrt() * eps * (len(e1) + len(e2)) + 12.0 * eps * eps) / (2.0 * area);
        let cos = (n[0] * m[0] + n[1] * m[1] + n[2] * m[2]) / (len(n) * len(m));
        let theta = cos.clamp(-1.0, 1.0).acos();
        if sin_bound < 0.5 {
            // f64 evaluation of the angle itself adds about 1e-8 rad
            assert!(
                theta.sin() <= sin_bound * 1.000_001 + 1e-8,
                "triangle {i}: turned {theta} rad, bound {sin_bound} (first order {first_order})"
            );
            checked += 1;
            worst = worst.max(theta / first_order.max(1e-300));
        }
    }
    assert!(checked > 10_000, "{checked}");
    // the first-order bound is reached to within a small factor, not vacuous
    assert!(worst > 0.05 && worst <= 1.01, "{worst}");
}
