//! File helpers every voxlod crate shares, so each exists once: [`write_atomic`] and
//! [`commit`] (a file replaced whole or not at all, written from memory or streamed),
//! [`open_regular`] and [`read_bounded`] (only regular files, never more bytes than the caller
//! allows: a FIFO, `/dev/zero` or a device is refused before a byte is read), the
//! [`PlyHeader`] writer, and the small text, hash and random helpers ([`hex`], [`fnv1a`],
//! [`mtime_ns`], [`splitmix64`]).
//!
//! It depends on nothing but `std`, so every crate of the workspace can use it.
//!
//! ```
//! let dir = tempfile::tempdir().unwrap();
//! let p = dir.path().join("a.json");
//! voxlod_io::write_atomic(&p, b"{}").unwrap();
//! assert_eq!(voxlod_io::read_bounded(&p, 16).unwrap(), b"{}");
//! assert!(voxlod_io::read_bounded(&p, 1).is_err()); // over the bound: refused
//! assert_eq!(voxlod_io::hex(&[0xab, 0x01]), "ab01");
//! ```

mod atomic;
mod ply;
mod regular;

pub use atomic::{commit, sync_dir, temp_path, write_atomic, write_atomic_via};
pub use ply::PlyHeader;
pub use regular::{open_regular, read_bounded, BoundError};

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// FNV-1a offset basis (64 bit), the `h` to start [`fnv1a`] from.
pub const FNV1A_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a, 64 bit, continuing from `h` ([`FNV1A_OFFSET`] to start): a hash that is stable
/// across Rust releases (std's hasher is not), for names derived from content.
pub fn fnv1a(bytes: &[u8], mut h: u64) -> u64 {
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// SplitMix64 (Steele, Lea & Flood, "Fast splittable pseudorandom number generators",
/// OOPSLA 2014): advances the 64-bit `state` and returns the next 64 random bits. Every seed
/// (including 0) is good and the numbers are the same on every platform, so generated meshes
/// and test data are reproducible.
#[inline]
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A file's modification time in nanoseconds since the Unix epoch; 0 when the file system
/// does not record one (or it is before 1970).
pub fn mtime_ns(meta: &std::fs::Metadata) -> u128 {
    meta.modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_the_published_vectors() {
        // from the FNV reference test suite (http://www.isthe.com/chongo/src/fnv/test_fnv.c)
        assert_eq!(fnv1a(b"", FNV1A_OFFSET), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a", FNV1A_OFFSET), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(b"foobar", FNV1A_OFFSET), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn splitmix64_matches_the_reference() {
        // the first outputs for seed 0 from the reference C implementation (Vigna's splitmix64.c)
        let mut s = 0;
        assert_eq!(splitmix64(&mut s), 0xe220_a839_7b1d_cdaf);
        assert_eq!(splitmix64(&mut s), 0x6e78_9e6a_a1b9_65f4);
    }

    #[test]
    fn hex_is_lower_case_two_digits_a_byte() {
        assert_eq!(hex(&[]), "");
        assert_eq!(hex(&[0, 0x0f, 0xf0, 0xff]), "000ff0ff");
    }
}
