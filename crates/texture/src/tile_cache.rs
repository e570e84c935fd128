//! The tile cache: texture tiles read from the tile file ([`crate::tile_file`]) on demand and
//! kept in a least-recently-used cache of bounded bytes, shared by every voxelize worker.
//!
//! **Lock-striped, shared** (not per worker): the cache is split into up to 16 stripes by a
//! hash of the tile's index, each an exact LRU (a hash map into a doubly linked list kept in a
//! slab) under its own mutex with an equal part of the capacity. Shared, because the workers
//! voxelize neighbouring chunks in Morton order and so read the same tiles: one copy serves
//! them all, where per-worker caches would each hold it in a smaller part of the budget. And the
//! samplers keep their `&self` signature ([`crate::Texture::sample`]), so the voxelizer does not
//! change. A worker holds a stripe's lock only for a lookup, or a lookup and one 16 KiB read
//! on a miss; two workers meet on the same stripe rarely (1 in 16 lookups at random).
//!
//! Accounting: [`TileCache::stats`] gives the bytes of the tiles held and their peak, which
//! never exceed the capacity (a tile is evicted before its replacement is counted); a sampler
//! also holds, for the length of one bilinear lookup, the tile it is reading.

use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Texels per tile edge.
pub const TILE: u32 = 64;
/// Bytes of one tile (64×64 RGBA8).
pub const TILE_BYTES: u64 = (TILE * TILE * 4) as u64;
/// The least capacity a cache accepts: one bilinear lookup touches up to four tiles.
pub const MIN_CAPACITY: u64 = 8 * TILE_BYTES;

/// One tile's texels, row by row (64×64; a level's edge tiles padded with zeros).
pub type Tile = Arc<[[u8; 4]]>;

const NIL: usize = usize::MAX;

struct Slot {
    id: u64,
    tile: Tile,
    prev: usize,
    next: usize,
}

/// An exact LRU of at most `max` tiles: `head` the most recently used.
struct Lru {
    map: HashMap<u64, usize>,
    slots: Vec<Slot>,
    head: usize,
    tail: usize,
    max: usize,
}

impl Lru {
    fn new(max: usize) -> Lru {
        assert!(max > 0);
        Lru {
            map: HashMap::new(),
            slots: Vec::new(),
            head: NIL,
            tail: NIL,
            max,
        }
    }

    fn unlink(&mut self, i: usize) {
        let (p, n) = (self.slots[i].prev, self.slots[i].next);
        match p {
            NIL => self.head = n,
            p => self.slots[p].next = n,
        }
        match n {
            NIL => self.tail = p,
            n => self.slots[n].prev = p,
        }
    }

    fn push_front(&mut self, i: usize) {
        self.slots[i].prev = NIL;
        self.slots[i].next = self.head;
        if self.head != NIL {
            self.slots[self.head].prev = i;
        }
        self.head = i;
        if self.tail == NIL {
            self.tail = i;
        }
    }

    fn get(&mut self, id: u64) -> Option<Tile> {
        let i = *self.map.get(&id)?;
        if self.head != i {
            self.unlink(i);
            self.push_front(i);
        }
        Some(self.slots[i].tile.clone())
    }

    /// Inserts a tile that is not held; true if the least recently used one was evicted.
    fn insert(&mut self, id: u64, tile: Tile) -> bool {
        if self.slots.len() < self.max {
            self.slots.push(Slot {
                id,
                tile,
                prev: NIL,
                next: NIL,
            });
            let i = self.slots.len() - 1;
            self.map.insert(id, i);
            self.push_front(i);
            return false;
        }
        // full: the tail's slot takes the new tile (its old tile is dropped here)
        let i = self.tail;
        self.unlink(i);
        self.map.remove(&self.slots[i].id);
        self.slots[i].id = id;
        self.slots[i].tile = tile;
        self.map.insert(id, i);
        self.push_front(i);
        true
    }
}

/// What the cache did (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// The cache's capacity, bytes (its share of the memory plan).
    pub capacity: u64,
    /// Bytes of the tiles held now.
    pub resident: u64,
    /// The most bytes of tiles held at once.
    pub peak_resident: u64,
    /// Tiles read from the tile file (cache misses).
    pub tile_reads: u64,
}

/// The shared tile cache of a tile file (see the module docs).
pub struct TileCache {
    file: File,
    path: PathBuf,
    stripes: Vec<Mutex<Lru>>,
    capacity: u64,
    resident: AtomicU64,
    peak: AtomicU64,
    reads: AtomicU64,
    error: Mutex<Option<String>>,
}

impl std::fmt::Debug for TileCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TileCache")
            .field("path", &self.path)
            .field("stats", &self.stats())
            .finish()
    }
}

impl TileCache {
    /// A cache of at most `capacity` bytes (≥ [`MIN_CAPACITY`]) over the tile file `path`.
    pub fn open(path: &Path, capacity: u64) -> std::io::Result<TileCache> {
        assert!(capacity >= MIN_CAPACITY, "a tile cache holds 8 tiles");
        let file = File::open(path)?;
        let tiles = capacity / TILE_BYTES;
        // stripes of at least 8 tiles each, so a lookup's four tiles rarely evict each other
        let n = (tiles / 8).clamp(1, 16);
        let stripes = (0..n)
            .map(|s| {
                // the tiles split as evenly as they go; the total stays ≤ capacity
                let share = tiles / n + u64::from(s < tiles % n);
                Mutex::new(Lru::new(share as usize))
            })
            .collect();
        Ok(TileCache {
            file,
            path: path.to_path_buf(),
            stripes,
            capacity,
            resident: AtomicU64::new(0),
            peak: AtomicU64::new(0),
            reads: AtomicU64::new(0),
            error: Mutex::new(None),
        })
    }

    /// The tile of index `id` in the file (from the cache, or read and cached). After a read
    /// error the tile is all zeros and [`TileCache::error`] names the file and the error.
    pub fn tile(&self, id: u64) -> Tile {
        // Fibonacci hashing: neighbouring tiles land on different stripes
        let s = (id.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize % self.stripes.len();
        // a panic elsewhere cannot leave an LRU half-linked (no user code runs under the lock)
        let mut lru = self.stripes[s].lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = lru.get(id) {
            return t;
        }
        let mut texels = vec![[0u8; 4]; (TILE * TILE) as usize];
        self.reads.fetch_add(1, Ordering::Relaxed);
        let at = id * TILE_BYTES;
        if let Err(e) = self
            .file
            .read_exact_at(bytemuck::cast_slice_mut(&mut texels), at)
        {
            let mut err = self.error.lock().unwrap_or_else(|e| e.into_inner());
            err.get_or_insert_with(|| {
                format!(
                    "{}: reading the texture tile at byte {at}: {e}",
                    self.path.display()
                )
            });
            return Tile::from(texels);
        }
        let tile = Tile::from(texels);
        if lru.insert(id, tile.clone()) {
            self.resident.fetch_sub(TILE_BYTES, Ordering::Relaxed);
        }
        let now = self.resident.fetch_add(TILE_BYTES, Ordering::Relaxed) + TILE_BYTES;
        self.peak.fetch_max(now, Ordering::Relaxed);
        tile
    }

    /// What the cache did so far.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            capacity: self.capacity,
            resident: self.resident.load(Ordering::Relaxed),
            peak_resident: self.peak.load(Ordering::Relaxed),
            tile_reads: self.reads.load(Ordering::Relaxed),
        }
    }

    /// The first read error, naming the file: the colours sampled since are wrong, so the
    /// build must fail.
    pub fn error(&self) -> Option<String> {
        self.error.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slab LRU against a plain recency list on a random sequence of lookups.
    #[test]
    fn lru_evicts_the_least_recently_used() {
        let mut lru = Lru::new(5);
        let mut model: Vec<u64> = Vec::new(); // most recent last
        let mut s = 3u64;
        for _ in 0..5000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            let id = (s >> 33) % 12;
            let hit = lru.get(id).is_some();
            assert_eq!(hit, model.contains(&id), "{id}");
            if hit {
                model.retain(|&x| x != id);
            } else {
                let evicted = lru.insert(id, Tile::from(vec![[id as u8; 4]]));
                assert_eq!(evicted, model.len() == 5);
                if evicted {
                    model.remove(0);
                }
            }
            model.push(id);
            assert_eq!(lru.get(id).unwrap()[0], [id as u8; 4]);
        }
        // walking the list from its head gives the model's order, most recent first
        let mut order = Vec::new();
        let mut i = lru.head;
        while i != NIL {
            order.push(lru.slots[i].id);
            i = lru.slots[i].next;
        }
        model.reverse();
        assert_eq!(order, model);
    }
}
