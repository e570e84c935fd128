//! The per-voxel material of a leaf chunk (Chajdas, Reitinger & Westermann, "Scalable
//! rendering for very large meshes", WSCG 2014, section 3.1: per-face data such as material
//! ids kept beside the voxels; docs/FORMAT.md section 14.3).
//!
//! Beside the colour and normal sums of each voxel, the chunk voxelizer adds each
//! contribution's clipped area `w` to its triangle's material ([`Triangle::material`]); the
//! voxel's material is the one with the largest summed area, or, if every area in the voxel
//! is zero, the one with the most contributions; ties go to the smallest material id.
//!
//! Most voxels see one material, so each voxel has one inline cell and further materials go
//! to a shared overflow list. Meshes with at most one material do not make a
//! [`MaterialSums`] at all, so they pay nothing but the voxelizer's `None` check.
//!
//! [`Triangle::material`]: voxlod_geom::Triangle::material

/// The summed weight of one material in one voxel.
#[derive(Clone, Copy, Debug)]
struct Cell {
    material: u32,
    /// contributions
    k: u32,
    /// summed clipped area (voxel²)
    w: f64,
    /// index + 1 of the next cell of the same voxel in `extra`, 0 = none
    next: u32,
}

/// Per-voxel material weights of the chunk being voxelized, indexed by the voxelizer's
/// accumulator slot (slots are made in order 0, 1, 2, …).
#[derive(Clone, Debug, Default)]
pub struct MaterialSums {
    heads: Vec<Cell>,
    extra: Vec<Cell>,
    /// the material of the triangle being added
    current: u32,
}

impl MaterialSums {
    /// Empty sums.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets every voxel (a new chunk).
    pub fn clear(&mut self) {
        self.heads.clear();
        self.extra.clear();
    }

    /// The material of the triangle whose contributions follow.
    #[inline]
    pub fn set_triangle(&mut self, material: u32) -> &mut Self {
        self.current = material;
        self
    }

    /// Adds a contribution of clipped area `w` of the current triangle to slot `slot`, which is
    /// either an existing slot or the next new one.
    #[inline]
    pub fn add(&mut self, slot: usize, w: f32) {
        let m = self.current;
        let w = w as f64;
        if slot == self.heads.len() {
            self.heads.push(Cell {
                material: m,
                k: 1,
                w,
                next: 0,
            });
            return;
        }
        debug_assert!(slot < self.heads.len(), "slots come in order");
        let head = &mut self.heads[slot];
        if head.material == m {
            head.k += 1;
            head.w += w;
            return;
        }
        let mut link = head.next;
        let mut last: Option<usize> = None;
        while link != 0 {
            let c = &mut self.extra[link as usize - 1];
            if c.material == m {
                c.k += 1;
                c.w += w;
                return;
            }
            last = Some(link as usize - 1);
            link = c.next;
        }
        self.extra.push(Cell {
            material: m,
            k: 1,
            w,
            next: 0,
        });
        let new = self.extra.len() as u32;
        match last {
            Some(l) => self.extra[l].next = new,
            None => self.heads[slot].next = new,
        }
    }

    /// Number of voxels (slots) seen.
    pub fn len(&self) -> usize {
        self.heads.len()
    }

    /// True if no voxel was seen.
    pub fn is_empty(&self) -> bool {
        self.heads.is_empty()
    }

    /// The material of slot `slot`: the largest summed area; if every area is zero, the most
    /// contributions; ties to the smallest material id.
    pub fn winner(&self, slot: usize) -> u32 {
        let head = &self.heads[slot];
        let mut best = (head.w, head.k, head.material);
        let mut link = head.next;
        while link != 0 {
            let c = &self.extra[link as usize - 1];
            if better((c.w, c.k, c.material), best) {
                best = (c.w, c.k, c.material);
            }
            link = c.next;
        }
        best.2
    }
}

/// True if material `a` beats `b` (each as summed area, count, id): a larger area, else (both
/// areas zero) more contributions, else a smaller id.
#[inline]
pub fn better(a: (f64, u32, u32), b: (f64, u32, u32)) -> bool {
    if a.0 != b.0 {
        return a.0 > b.0;
    }
    if a.0 == 0.0 && a.1 != b.1 {
        return a.1 > b.1;
    }
    a.2 < b.2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn largest_area_then_count_then_smallest_id() {
        let mut s = MaterialSums::new();
        // slot 0: 3 (0.25 + 0.25) beats 5 (0.4), 9 (0.1)
        s.set_triangle(5).add(0, 0.4);
        s.set_triangle(3).add(0, 0.25);
        s.set_triangle(9).add(0, 0.1);
        s.set_triangle(3).add(0, 0.25);
        // slot 1: zero areas, 7 twice beats 2 once
        s.set_triangle(2).add(1, 0.0);
        s.set_triangle(7).add(1, 0.0);
        s.set_triangle(7).add(1, 0.0);
        // slot 2: a tie of areas goes to the smaller id
        s.set_triangle(8).add(2, 0.5);
        s.set_triangle(4).add(2, 0.5);
        // slot 3: one material
        s.set_triangle(6).add(3, 0.0);
        assert_eq!(
            (0..4).map(|i| s.winner(i)).collect::<Vec<_>>(),
            [3, 7, 4, 6]
        );
        assert_eq!(s.len(), 4);
        s.clear();
        assert!(s.is_empty());
    }
}
