//! The block world: a grid of unit blocks, `size × size` columns, generated from a seed like a
//! Minecraft level. Heightmap terrain from fractal value noise (`noise.rs`): stone, three
//! blocks of dirt under a grass top, sand on beaches and lake floors, water up to the sea
//! level, and oak-like trees (a log trunk under a crown of leaves) on a jittered lattice of
//! grass columns. Blocks are looked up by position ([`World::block`]); only the heightmap and
//! the tree blocks are stored.

use std::collections::HashMap;

use crate::noise::{fbm, hash};

/// Blocks of the world (not their faces: a grass block has three textures, `Material`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Block {
    /// Empty space (also everything outside the world).
    Air,
    /// Stone, under the dirt.
    Stone,
    /// Dirt, under the grass.
    Dirt,
    /// Grass: the top block of a column above the beach.
    Grass,
    /// Sand: beaches and lake floors.
    Sand,
    /// Water, from the ground up to the sea level.
    Water,
    /// A tree trunk.
    Log,
    /// A tree crown.
    Leaves,
}

/// The water surface: columns lower than this are flooded up to it.
pub const SEA_LEVEL: u32 = 11;
/// The middle of the ground heights: a little above the sea, so that most of it is land.
const GROUND: f64 = 15.0;
/// Ground height varies by up to this many blocks around [`GROUND`].
const RELIEF: f64 = 14.0;
/// Trees stand on a jittered lattice of this many blocks.
const TREE_CELL: u32 = 8;
/// Smallest and largest world (columns per side): the smallest holds the tallest terrain and
/// trees inside its bounding cube; the largest keeps the face list under a few hundred MiB.
pub const MIN_SIZE: u32 = 32;
/// See [`MIN_SIZE`].
pub const MAX_SIZE: u32 = 2048;

/// A generated block world.
pub struct World {
    size: u32,
    seed: u64,
    /// Solid blocks per column (`y < height` is ground), row-major `z * size + x`.
    height: Vec<u16>,
    /// Logs and leaves above the ground.
    trees: HashMap<[u32; 3], Block>,
    /// Number of trees.
    tree_count: u32,
    /// One above the highest non-air block.
    top: u32,
}

impl World {
    /// Generates the world of `size × size` columns from `seed`.
    pub fn generate(size: u32, seed: u64) -> Result<World, crate::Error> {
        if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
            return Err(crate::Error::Size(size));
        }
        let mut height = Vec::with_capacity((size * size) as usize);
        for z in 0..size {
            for x in 0..size {
                let h = GROUND + (fbm(seed, x, z) - 0.5) * 2.0 * RELIEF;
                height.push(h.round().clamp(1.0, GROUND + RELIEF) as u16);
            }
        }
        let mut w = World {
            size,
            seed,
            height,
            trees: HashMap::new(),
            tree_count: 0,
            top: 0,
        };
        w.plant_trees();
        let ground = w.height.iter().map(|&h| h as u32).max().unwrap_or(0);
        let crowns = w.trees.keys().map(|p| p[1] + 1).max().unwrap_or(0);
        w.top = ground.max(SEA_LEVEL).max(crowns);
        debug_assert!(w.top <= size, "the world fits its bounding cube");
        Ok(w)
    }

    /// Columns per side.
    pub fn size(&self) -> u32 {
        self.size
    }

    /// The seed it was generated from.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// One above the highest non-air block (every block at `y >= top()` is air).
    pub fn top(&self) -> u32 {
        self.top
    }

    /// Number of trees.
    pub fn trees(&self) -> u32 {
        self.tree_count
    }

    /// Ground height of column `(x, z)`: its blocks `0..h` are solid.
    pub fn ground(&self, x: u32, z: u32) -> u32 {
        self.height[(z * self.size + x) as usize] as u32
    }

    /// The block at `(x, y, z)`; air outside the world.
    pub fn block(&self, x: i64, y: i64, z: i64) -> Block {
        let n = self.size as i64;
        if !(0..n).contains(&x) || !(0..n).contains(&z) || y < 0 || y >= self.top as i64 {
            return Block::Air;
        }
        let (x, y, z) = (x as u32, y as u32, z as u32);
        let h = self.ground(x, z);
        if y < h {
            let beach = h <= SEA_LEVEL + 1;
            return match h - 1 - y {
                0 if !beach => Block::Grass,
                0..=2 if beach => Block::Sand,
                0..=3 => Block::Dirt,
                _ => Block::Stone,
            };
        }
        if y < SEA_LEVEL {
            return Block::Water;
        }
        self.trees.get(&[x, y, z]).copied().unwrap_or(Block::Air)
    }

    /// Plants a tree (or a stump) in some cells of the tree lattice, where the cell's chosen column is
    /// grass and the whole tree fits inside the world. A trunk block wins over a leaf of a
    /// neighbouring crown whatever the order (so the world does not depend on it).
    fn plant_trees(&mut self) {
        let cells = self.size.div_ceil(TREE_CELL);
        for cz in 0..cells {
            for cx in 0..cells {
                let r = hash(self.seed, cx as i64, cz as i64, 0x7ee5);
                // 55 % of the cells get a tree, 10 % a felled one: a stump of one or two logs
                // (whose top shows the rings)
                let stump = match r % 100 {
                    0..55 => false,
                    55..65 => true,
                    _ => continue,
                };
                let x = cx * TREE_CELL + 2 + (r >> 8) as u32 % 4;
                let z = cz * TREE_CELL + 2 + (r >> 16) as u32 % 4;
                let trunk = if stump { 1 } else { 4 } + (r >> 24) as u32 % 2;
                if x + 2 >= self.size || z + 2 >= self.size {
                    continue;
                }
                let h = self.ground(x, z);
                if h <= SEA_LEVEL + 1 || h + trunk + 2 > self.size {
                    continue;
                }
                if stump {
                    (h..h + trunk).for_each(|y| {
                        self.trees.insert([x, y, z], Block::Log);
                    });
                } else {
                    self.plant(x, h, z, trunk);
                }
            }
        }
    }

    /// An oak: `trunk` logs from `(x, y, z)` up, two layers of 5×5 leaves without corners
    /// around the trunk's top two blocks, a 3×3 layer above and a plus on top.
    fn plant(&mut self, x: u32, y: u32, z: u32, trunk: u32) {
        self.tree_count += 1;
        let t = y + trunk; // first block above the trunk
        for (ly, r, shape) in [(t - 2, 2i32, 0), (t - 1, 2, 0), (t, 1, 1), (t + 1, 1, 2)] {
            for dz in -r..=r {
                for dx in -r..=r {
                    let keep = match shape {
                        0 => !(dx.abs() == 2 && dz.abs() == 2),
                        1 => true,
                        _ => dx.abs() + dz.abs() <= 1,
                    };
                    if keep {
                        let p = [(x as i32 + dx) as u32, ly, (z as i32 + dz) as u32];
                        self.trees.entry(p).or_insert(Block::Leaves);
                    }
                }
            }
        }
        for ly in y..t {
            self.trees.insert([x, ly, z], Block::Log);
        }
    }
}
