//! The exposed faces of a block world, as a renderer of block worlds draws them: a face of a
//! block is emitted where the neighbouring block across it is air, or water seen from a block
//! that is not water (so lake floors and shores are there under the water surface, but no
//! faces between two water blocks or from water into the ground). Each face gets the material
//! of its side of its block (a grass block: grass on top, grass side on the sides, dirt below;
//! a log: rings on top and bottom, bark on the sides) and four corners with texture
//! coordinates (0,0) (1,0) (1,1) (0,1), counter-clockwise seen from outside, with the
//! texture's up (`v`) pointing up (+y) on the side faces.

use crate::world::{Block, World};

/// The materials of block faces, one texture each, in the order of the MTL file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Material {
    /// Top of a grass block.
    GrassTop,
    /// Sides of a grass block: dirt with a fringe of grass at the top.
    GrassSide,
    /// Dirt, and the bottom of a grass block.
    Dirt,
    /// Stone.
    Stone,
    /// Sand.
    Sand,
    /// Water.
    Water,
    /// Top and bottom of a log: growth rings.
    LogTop,
    /// Sides of a log: bark.
    LogSide,
    /// Leaves.
    Leaves,
}

impl Material {
    /// Every material, in MTL order.
    pub const ALL: [Material; 9] = [
        Material::GrassTop,
        Material::GrassSide,
        Material::Dirt,
        Material::Stone,
        Material::Sand,
        Material::Water,
        Material::LogTop,
        Material::LogSide,
        Material::Leaves,
    ];

    /// The material's name in the MTL file (and the texture's file name).
    pub fn name(self) -> &'static str {
        match self {
            Material::GrassTop => "grass_top",
            Material::GrassSide => "grass_side",
            Material::Dirt => "dirt",
            Material::Stone => "stone",
            Material::Sand => "sand",
            Material::Water => "water",
            Material::LogTop => "log_top",
            Material::LogSide => "log_side",
            Material::Leaves => "leaves",
        }
    }
}

/// The six face directions (outward normals), in the order −x, +x, −y, +y, −z, +z.
pub const DIRS: [[i64; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

/// The material of the side of `block` whose outward normal is `DIRS[dir]`; `None` for air.
pub fn face_material(block: Block, dir: usize) -> Option<Material> {
    let (top, bottom) = (dir == 3, dir == 2);
    Some(match block {
        Block::Air => return None,
        Block::Grass if top => Material::GrassTop,
        Block::Grass if bottom => Material::Dirt,
        Block::Grass => Material::GrassSide,
        Block::Dirt => Material::Dirt,
        Block::Stone => Material::Stone,
        Block::Sand => Material::Sand,
        Block::Water => Material::Water,
        Block::Log if top || bottom => Material::LogTop,
        Block::Log => Material::LogSide,
        Block::Leaves => Material::Leaves,
    })
}

/// Whether a face of `block` towards `neighbour` is exposed (drawn).
pub fn exposed(block: Block, neighbour: Block) -> bool {
    block != Block::Air
        && (neighbour == Block::Air || (neighbour == Block::Water && block != Block::Water))
}

/// One exposed face: the block's position, the direction (index into [`DIRS`]) and material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Face {
    /// Position of the block the face belongs to.
    pub block: [u32; 3],
    /// Index of the outward normal in [`DIRS`].
    pub dir: u8,
    /// The material of this side of the block.
    pub material: Material,
}

impl Face {
    /// The four corners (integer world positions) counter-clockwise seen from outside, for
    /// the texture coordinates (0,0) (1,0) (1,1) (0,1). The texture's axes `U`, `V` satisfy
    /// `U × V = n` (the outward normal): on side faces `V = +y` and `U = V × n`; on the top
    /// and bottom `U = +x` and `V = n × U`.
    pub fn corners(&self) -> [[u32; 3]; 4] {
        let n = DIRS[self.dir as usize];
        let (u, v) = if n[1] == 0 {
            let v = [0, 1, 0];
            (cross(v, n), v)
        } else {
            let u = [1, 0, 0];
            (u, cross(n, u))
        };
        // the corner at texture (0,0): the block's corner on the face's side of the normal
        // axis, and at the low end of each of U and V (their high end where they point down)
        let b = self.block.map(|c| c as i64);
        let o: [i64; 3] = std::array::from_fn(|a| b[a] + (n[a] > 0 || u[a] < 0 || v[a] < 0) as i64);
        let at = |s: i64, t: i64| -> [u32; 3] {
            std::array::from_fn(|a| (o[a] + s * u[a] + t * v[a]) as u32)
        };
        [at(0, 0), at(1, 0), at(1, 1), at(0, 1)]
    }
}

/// The cross product `a × b`.
fn cross(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Every exposed face of `world`, sorted by material, then by block (z, y, x) and direction:
/// the order of the OBJ file.
pub fn exposed_faces(world: &World) -> Vec<Face> {
    let n = world.size();
    let mut faces = Vec::new();
    for z in 0..n {
        for y in 0..world.top() {
            for x in 0..n {
                let p = [x as i64, y as i64, z as i64];
                let b = world.block(p[0], p[1], p[2]);
                if b == Block::Air {
                    continue;
                }
                for (dir, d) in DIRS.iter().enumerate() {
                    let nb = world.block(p[0] + d[0], p[1] + d[1], p[2] + d[2]);
                    if exposed(b, nb) {
                        let material = face_material(b, dir).expect("not air");
                        faces.push(Face {
                            block: [x, y, z],
                            dir: dir as u8,
                            material,
                        });
                    }
                }
            }
        }
    }
    faces.sort_by_key(|f| f.material); // stable: block order kept within a material
    faces
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corners of each face lie on the face's plane of the unit block, span it, and wind
    /// counter-clockwise seen from outside (the normal of corners 0, 1, 2 is the outward one).
    #[test]
    fn corners_span_the_face_outward() {
        for dir in 0..6u8 {
            let f = Face {
                block: [5, 6, 7],
                dir,
                material: Material::Stone,
            };
            let c = f.corners().map(|p| p.map(|v| v as i64));
            let n = DIRS[dir as usize];
            let a = (0..3).find(|&a| n[a] != 0).unwrap();
            let plane = [5, 6, 7][a] + (n[a] > 0) as i64;
            for p in &c {
                assert_eq!(p[a], plane, "dir {dir}");
                for k in 0..3 {
                    assert!(p[k] - [5, 6, 7][k] == 0 || p[k] - [5, 6, 7][k] == 1);
                }
            }
            let e1: [i64; 3] = std::array::from_fn(|k| c[1][k] - c[0][k]);
            let e2: [i64; 3] = std::array::from_fn(|k| c[2][k] - c[0][k]);
            assert_eq!(cross(e1, e2), n, "dir {dir}");
            // the opposite corners are distinct: a unit square, not a degenerate one
            assert_ne!(c[0], c[2]);
            assert_ne!(c[1], c[3]);
            if n[1] == 0 {
                // texture up is +y on the sides
                assert_eq!(c[3][1] - c[0][1], 1, "dir {dir}");
            }
        }
    }
}
