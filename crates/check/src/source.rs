//! `verify` for the source-geometry channel (docs/FORMAT.md 14.4): a leaf's stored triangles
//! decode with every check of the format (checksum, frame, counts, first-use indices), and each
//! triangle touches its chunk's box grown by the quantization error — decided with the
//! separating axis theorem of Akenine-Möller ("Fast 3D triangle-box overlap testing", 2001:
//! the three box axes, the triangle's normal, the nine edge/axis cross products) in f64 on the
//! dequantized coordinates (exact multiples of 1/128; the projections round by a relative
//! 2^-52 at most, far below the quantization error the box is grown by) — and carries
//! material ids the manifest names.

use voxlod_format::triangles::{SourceMesh, MAX_ERROR};
use voxlod_format::{FormatError, Reader, CHUNK};

/// The leaf's source triangles checked: `Ok(triangles)` (0 without a payload), or what is
/// wrong. `materials` is the length of the manifest's `"materials"` list, if it has one.
pub(crate) fn check_leaf(
    reader: &Reader,
    index: usize,
    materials: Option<usize>,
) -> Result<u64, Vec<String>> {
    let mesh = match reader.source_triangles(index) {
        Ok(Some(m)) => m,
        Ok(None) => return Ok(0),
        Err(e) => return Err(vec![what_of(&e)]),
    };
    let mut problems = Vec::new();
    let lo = -MAX_ERROR;
    let hi = CHUNK as f64 + MAX_ERROR;
    let mut outside = mesh
        .triangles
        .iter()
        .enumerate()
        .filter(|(_, t)| !touches_box(&corners(&mesh, t), lo, hi));
    if let Some((k, t)) = outside.next() {
        problems.push(format!(
            "source triangle {k} (vertices {:?}) does not touch the chunk's box within the quantization error; {} more",
            t.map(|i| mesh.position(i)),
            outside.count()
        ));
    }
    if let (Some(ms), Some(n)) = (&mesh.materials, materials) {
        if let Some((k, m)) = ms.iter().enumerate().find(|(_, &m)| m as usize >= n) {
            problems.push(format!(
                "source triangle {k} has material {m}, but the manifest names {n} materials"
            ));
        }
    }
    if problems.is_empty() {
        Ok(mesh.triangles.len() as u64)
    } else {
        Err(problems)
    }
}

fn what_of(e: &FormatError) -> String {
    match e {
        FormatError::Node { what, .. } => what.clone(),
        other => other.to_string(),
    }
}

fn corners(mesh: &SourceMesh, t: &[u32; 3]) -> [[f64; 3]; 3] {
    t.map(|i| mesh.position(i))
}

/// True if the closed triangle `v` and the closed box `[lo, hi]³` share a point (separating
/// axis theorem: no separating axis among the 13 candidates).
pub(crate) fn touches_box(v: &[[f64; 3]; 3], lo: f64, hi: f64) -> bool {
    // centre the box at the origin (exact: the halves of dyadic numbers)
    let c = (lo + hi) / 2.0;
    let h = (hi - lo) / 2.0;
    let p: [[f64; 3]; 3] = v.map(|q| q.map(|x| x - c));
    let e: [[f64; 3]; 3] = std::array::from_fn(|k| sub(p[(k + 1) % 3], p[k]));
    let separated = |axis: [f64; 3]| {
        let d = p.map(|q| dot(q, axis));
        let r = h * (axis[0].abs() + axis[1].abs() + axis[2].abs());
        let (min, max) = (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]));
        min > r || max < -r
    };
    let unit = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if unit.iter().any(|&a| separated(a)) || separated(cross(e[0], e[1])) {
        return false;
    }
    !e.iter()
        .any(|&ek| unit.iter().any(|&u| separated(cross(ek, u))))
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn separating_axes() {
        let t = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| touches_box(&[a, b, c], 0.0, 256.0);
        assert!(t([1.0, 1.0, 1.0], [2.0, 1.0, 1.0], [1.0, 2.0, 1.0]));
        assert!(!t([300.0, 1.0, 1.0], [302.0, 1.0, 1.0], [300.0, 2.0, 1.0]));
        // touching a face at one vertex counts
        assert!(t([256.0, 1.0, 1.0], [300.0, 1.0, 1.0], [300.0, 2.0, 1.0]));
        // bounding box overlaps the box, the triangle passes by the corner: only an edge axis separates
        assert!(!t(
            [250.0, 270.0, 0.0],
            [270.0, 250.0, 0.0],
            [270.0, 270.0, 0.0]
        ));
        // a huge triangle through the box
        assert!(t([-1e4, 5.0, -1e4], [1e4, 5.0, -1e4], [0.0, 5.0, 1e4]));
        // its plane misses the box
        assert!(!t(
            [-1e4, 300.0, -1e4],
            [1e4, 300.0, -1e4],
            [0.0, 300.0, 1e4]
        ));
    }
}
