//! The visible geometry of voxels as the Chajdas renderer draws it: each voxel a cube of which
//! only the faces in its face mask are drawn (FORMAT.md section 6: outward faces from the
//! normal plus chunk border caps). Shared by the PLY export and the GPU renderer.

use voxlod_format::{Reader, Voxel};

use crate::RenderError;

/// One active face of a voxel cube.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Face {
    /// World coordinates of the voxel's minimum corner.
    pub min: [f64; 3],
    /// Edge of the voxel (`voxel_size·2^level`).
    pub edge: f64,
    /// Face-mask bit: 0 +x, 1 −x, 2 +y, 3 −y, 4 +z, 5 −z.
    pub dir: u8,
    /// The voxel's packed 10:10:10 normal.
    pub normal: u32,
    /// The voxel's RGBA colour.
    pub rgba: [u8; 4],
}

/// The outward unit vector of face-mask bit `dir`.
pub fn face_direction(dir: u8) -> [f32; 3] {
    debug_assert!(dir < 6);
    let mut d = [0.0; 3];
    d[(dir >> 1) as usize] = if dir & 1 == 0 { 1.0 } else { -1.0 };
    d
}

/// The four corners of face `dir` of the unit cube `[0,1]³`, counter-clockwise seen from
/// outside (so the right-hand normal is the face direction).
pub fn unit_face_corners(dir: u8) -> [[f32; 3]; 4] {
    debug_assert!(dir < 6);
    let a = (dir >> 1) as usize;
    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
    let plane = if dir & 1 == 0 { 1.0 } else { 0.0 };
    let uv: [[f32; 2]; 4] = if dir & 1 == 0 {
        [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    } else {
        [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]
    };
    uv.map(|[s, t]| {
        let mut p = [0.0; 3];
        p[a] = plane;
        p[u] = s;
        p[v] = t;
        p
    })
}

/// What a face's colour shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorBy {
    /// The voxel's RGBA colour.
    #[default]
    Voxel,
    /// The voxel's material (FORMAT.md 14.3) as [`material_color`]: needs the material channel.
    Material,
}

/// A distinct opaque colour for material id `id`: mid grey for 0 (no material), otherwise hues
/// spaced by the golden angle (so neighbouring ids differ clearly), fully saturated, at two
/// alternating brightnesses.
pub fn material_color(id: u32) -> [u8; 4] {
    if id == 0 {
        return [128, 128, 128, 255];
    }
    let h = (id as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let v = if id % 2 == 0 { 1.0 } else { 0.75 };
    let x = 1.0 - ((h % 2.0) - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    let q = |c: f64| (c * v * 255.0).round() as u8;
    [q(r), q(g), q(b), 255]
}

/// Calls `f` with every active face of the voxels of node `index` (decoded into `buf`).
pub fn node_faces(
    reader: &Reader,
    index: usize,
    buf: &mut Vec<Voxel>,
    f: &mut dyn FnMut(Face),
) -> Result<(), RenderError> {
    node_faces_by(reader, index, buf, ColorBy::Voxel, f)
}

/// [`node_faces`] with the faces coloured as `color` says; [`ColorBy::Material`] on a file
/// without the material channel is an error saying so.
pub fn node_faces_by(
    reader: &Reader,
    index: usize,
    buf: &mut Vec<Voxel>,
    color: ColorBy,
    f: &mut dyn FnMut(Face),
) -> Result<(), RenderError> {
    reader.read_node_into(index, buf)?;
    let materials = match color {
        ColorBy::Voxel => None,
        ColorBy::Material => Some(reader.read_materials(index)?.ok_or_else(|| {
            RenderError::Option(
                "the file has no material channel (built from a mesh with fewer than two materials)"
                    .into(),
            )
        })?),
    };
    let e = reader.nodes()[index];
    let spec = reader.spec();
    let edge = spec.voxel_size_at(e.level);
    for (j, v) in buf.iter().enumerate() {
        let mask = v.mask();
        if mask == 0 {
            continue;
        }
        let rgba = materials
            .as_ref()
            .map_or(v.rgba(), |m| material_color(m[j]));
        let min = spec.voxel_min_corner(e.level, e.pos(), v.pos());
        for dir in 0..6u8 {
            if mask >> dir & 1 == 1 {
                f(Face {
                    min,
                    edge,
                    dir,
                    normal: v.normal,
                    rgba,
                });
            }
        }
    }
    Ok(())
}

/// Indices of the nodes at `level`, or an error naming the levels the file has.
pub fn level_nodes(reader: &Reader, level: u32) -> Result<Vec<usize>, RenderError> {
    let levels = reader.spec().levels;
    if level >= levels {
        return Err(RenderError::Option(format!(
            "level {level} is not in the file (it has levels 0..={})",
            levels - 1
        )));
    }
    Ok(reader.level_nodes(level).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn material_colours_are_distinct_and_opaque() {
        let c: Vec<_> = (0..64).map(material_color).collect();
        assert_eq!(c[0], [128, 128, 128, 255]);
        for i in 0..64 {
            assert_eq!(c[i][3], 255);
            for j in 0..i {
                assert_ne!(c[i], c[j], "ids {i} and {j}");
            }
        }
    }

    #[test]
    fn corners_wind_around_the_face_direction() {
        for dir in 0..6u8 {
            let c = unit_face_corners(dir);
            let e1: [f32; 3] = std::array::from_fn(|k| c[1][k] - c[0][k]);
            let e2: [f32; 3] = std::array::from_fn(|k| c[2][k] - c[0][k]);
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            assert_eq!(n, face_direction(dir), "dir {dir}");
            // every corner on the face's plane
            let a = (dir >> 1) as usize;
            let plane = if dir & 1 == 0 { 1.0 } else { 0.0 };
            assert!(c.iter().all(|p| p[a] == plane));
        }
    }
}
