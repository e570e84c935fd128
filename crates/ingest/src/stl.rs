//! STL reading, binary (memory-mapped, 50-byte facets) and ASCII (line by line). STL facet
//! normals are ignored: the triangles use their face normal. Binary STL starts with an
//! 80-byte header that some writers fill with "solid ...", so the file is taken as ASCII only
//! if it starts with "solid" and either its size is not 84 + 50·n or its next keyword is
//! "facet"/"endsolid".

use crate::batch::Emitter;
use crate::bounds::parallel_bounds;
use crate::map_guard::MappedFile;
use crate::ply_records::{Counter, CountingReader};
use crate::{IngestError, Location, MeshInfo};
use std::cell::Cell;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use voxlod_geom::{Bounds, Triangle};

/// The three corners of binary facet `i` (its record at byte `84 + 50 i`; bytes 0..12 hold the
/// facet normal, ignored).
#[inline]
fn facet_corners(data: &[u8], i: usize) -> [[f32; 3]; 3] {
    let rec = &data[84 + 50 * i..][..50];
    let f = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
    [0, 1, 2].map(|k| [f(12 + 12 * k), f(16 + 12 * k), f(20 + 12 * k)])
}

pub(crate) struct StlSource {
    path: PathBuf,
    /// The mapped file and its facet count, for binary STL.
    binary: Option<(MappedFile, u64)>,
}

/// True if `head` (the first bytes of a file of `len` bytes) is an ASCII STL.
pub(crate) fn is_ascii_stl(head: &[u8], len: u64) -> bool {
    let h = head.trim_ascii_start();
    if !h.starts_with(b"solid") {
        return false;
    }
    if len < 84 || head.len() < 84 {
        return true;
    }
    let n = u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64;
    if 84 + 50 * n != len {
        return true;
    }
    // size fits binary too: ASCII only if the second line starts with a keyword
    match h.iter().position(|&b| b == b'\n') {
        Some(nl) => {
            let rest = h[nl + 1..].trim_ascii_start();
            rest.starts_with(b"facet") || rest.starts_with(b"endsolid")
        }
        None => false,
    }
}

impl StlSource {
    pub fn open(path: &Path, head: &[u8], len: u64) -> Result<(StlSource, MeshInfo), IngestError> {
        let mut warnings = Vec::new();
        let mut info = MeshInfo {
            path: path.to_path_buf(),
            format: "stl ascii".into(),
            vertices: 0,
            faces: 0,
            has_normals: false,
            has_colors: false,
            has_texcoords: false,
            materials: Vec::new(),
            warnings: Vec::new(),
            up: None,
            held: 0,
        };
        if is_ascii_stl(head, len) {
            return Ok((
                StlSource {
                    path: path.to_path_buf(),
                    binary: None,
                },
                info,
            ));
        }
        if len < 84 {
            return Err(IngestError::Truncated {
                path: path.to_path_buf(),
                at: Location::Byte(0),
                what: "the binary STL header and triangle count".into(),
                expected: 84,
                got: len,
            });
        }
        let n = u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64;
        let need = 84 + 50 * n;
        if len < need {
            return Err(IngestError::Truncated {
                path: path.to_path_buf(),
                at: Location::Byte(84),
                what: format!("{n} binary STL facets of 50 bytes"),
                expected: 50 * n,
                got: len - 84,
            });
        }
        if len > need {
            warnings.push(format!(
                "{} bytes after the last of the {n} facets ignored",
                len - need
            ));
        }
        let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
        // a truncation while it is mapped ends the process with a message (map_guard)
        let map = MappedFile::map(path, &file).map_err(|e| IngestError::io(path, e))?;
        if (map.len() as u64) < need {
            return Err(IngestError::malformed(
                path,
                Location::File,
                "the file shrank while being opened",
            ));
        }
        info.format = "stl binary".into();
        info.vertices = 3 * n;
        info.faces = n;
        info.warnings = warnings;
        Ok((
            StlSource {
                path: path.to_path_buf(),
                binary: Some((map, n)),
            },
            info,
        ))
    }

    /// Drops this process's resident pages of the memory-mapped input (they stay in the page
    /// cache, so touching them again is a minor fault, not a read): the mapping's share of
    /// resident memory stays bounded by what a few thousand triangles touch.
    /// True for binary STL, read through the memory map.
    pub fn is_mapped(&self) -> bool {
        self.binary.is_some()
    }

    pub fn release_pages(&self) {
        if let Some((m, _)) = &self.binary {
            // SAFETY: the map is a read-only shared file mapping; after MADV_DONTNEED its pages
            // are read back from the file on the next access, with the same contents.
            let _ = unsafe {
                m.mmap()
                    .unchecked_advise(memmap2::UncheckedAdvice::DontNeed)
            };
        }
    }

    pub fn stream(&self, em: &mut Emitter) -> Result<(), IngestError> {
        match &self.binary {
            Some((map, n)) => self.stream_binary(map, *n, em),
            None => self.stream_ascii(em),
        }
    }

    /// The bounds of every facet corner of a binary STL, `None` for ASCII or if one is not
    /// finite (read in parallel from the map, in rounds of 32 MiB of facets).
    pub fn vertex_bounds(&self) -> Option<Bounds> {
        let (map, n) = self.binary.as_ref()?;
        let data: &[u8] = map;
        parallel_bounds(*n, (32 << 20) / 50, &|| self.release_pages(), &|r, b| {
            for i in r {
                for p in facet_corners(data, i as usize) {
                    b.add(p);
                }
            }
        })
    }

    fn stream_binary(&self, data: &[u8], n: u64, em: &mut Emitter) -> Result<(), IngestError> {
        for i in 0..n as usize {
            let off = 84 + 50 * i;
            let v = facet_corners(data, i);
            for (k, vk) in v.iter().enumerate() {
                if !vk.iter().all(|x| x.is_finite()) {
                    return Err(IngestError::NonFinite {
                        path: self.path.clone(),
                        at: Location::Record {
                            element: "facet".into(),
                            index: i as u64,
                            offset: (off + 12 + 12 * k) as u64,
                        },
                        vertex: 3 * i as u64 + k as u64,
                        coords: vk.map(|x| x as f64),
                    });
                }
            }
            em.stats.polygons += 1;
            em.bytes_done = (off + 50) as u64;
            em.push(Triangle::new(v))?;
        }
        Ok(())
    }

    fn stream_ascii(&self, em: &mut Emitter) -> Result<(), IngestError> {
        // The ASCII STL grammar as one state machine.
        let path = &self.path;
        let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
        let counter: Counter = Rc::new(Cell::new(0));
        let mut r = BufReader::with_capacity(
            1 << 18,
            CountingReader {
                inner: file,
                count: counter.clone(),
            },
        );
        let mut buf = Vec::new();
        let mut line_no = 0u64;
        let mut loop_verts: Vec<[f32; 3]> = Vec::new();
        // where we are: outside any solid, inside a solid, a facet, or a loop
        #[derive(PartialEq, Clone, Copy, Debug)]
        enum At {
            Outside,
            Solid,
            Facet,
            Loop,
        }
        let mut state = At::Outside;
        let mut solids = 0u64;
        let mut vertices = 0u64;
        loop {
            buf.clear();
            if r.read_until(b'\n', &mut buf)
                .map_err(|e| IngestError::io(path, e))?
                == 0
            {
                break;
            }
            line_no += 1;
            let at = Location::Line(line_no);
            let line = String::from_utf8_lossy(&buf);
            let mut t = line.split_ascii_whitespace();
            let Some(kw) = t.next() else { continue };
            let unexpected = |state: At| {
                let expected = match state {
                    At::Outside => "\"solid\"",
                    At::Solid => "\"facet\" or \"endsolid\"",
                    At::Facet => "\"outer loop\" or \"endfacet\"",
                    At::Loop => "\"vertex\" or \"endloop\"",
                };
                IngestError::malformed(
                    path,
                    at.clone(),
                    format!("{} where {expected} was expected", crate::error::quoted(kw)),
                )
            };
            state = match (kw, state) {
                ("solid", At::Outside) => {
                    solids += 1;
                    At::Solid
                }
                ("endsolid", At::Solid) => At::Outside,
                ("facet", At::Solid) => At::Facet,
                ("outer", At::Facet) => {
                    loop_verts.clear();
                    At::Loop
                }
                ("vertex", At::Loop) => {
                    let mut p = [0f32; 3];
                    for pk in p.iter_mut() {
                        let s = t.next().ok_or_else(|| {
                            IngestError::malformed(path, at.clone(), "vertex needs 3 coordinates")
                        })?;
                        *pk = s.parse().map_err(|_| {
                            IngestError::malformed(
                                path,
                                at.clone(),
                                format!("{} is not a number", crate::error::quoted(s)),
                            )
                        })?;
                    }
                    if !p.iter().all(|x| x.is_finite()) {
                        return Err(IngestError::NonFinite {
                            path: path.clone(),
                            at,
                            vertex: vertices,
                            coords: p.map(|x| x as f64),
                        });
                    }
                    vertices += 1;
                    loop_verts.push(p);
                    At::Loop
                }
                ("endloop", At::Loop) => {
                    if loop_verts.len() < 3 {
                        return Err(IngestError::malformed(
                            path,
                            at,
                            format!("a facet loop with {} vertices", loop_verts.len()),
                        ));
                    }
                    em.stats.polygons += 1;
                    em.bytes_done = counter.get();
                    for k in 1..loop_verts.len() - 1 {
                        em.push(Triangle::new([
                            loop_verts[0],
                            loop_verts[k],
                            loop_verts[k + 1],
                        ]))?;
                    }
                    At::Facet
                }
                ("endfacet", At::Facet) => At::Solid,
                (_, s) => return Err(unexpected(s)),
            };
        }
        if state != At::Outside || solids == 0 {
            return Err(IngestError::malformed(
                path,
                Location::Line(line_no),
                "the ASCII STL ends without \"endsolid\" (truncated?)",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::is_ascii_stl;

    fn binary_head(text: &[u8], n: u32) -> Vec<u8> {
        let mut h = vec![b' '; 80];
        h[..text.len()].copy_from_slice(text);
        h.extend_from_slice(&n.to_le_bytes());
        h
    }

    #[test]
    fn ascii_or_binary() {
        let ascii = b"solid cube\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n      vertex 1 0 0\n      vertex 0 1 0\n    endloop\n  endfacet\nendsolid\n";
        assert!(is_ascii_stl(ascii, ascii.len() as u64));
        // binary whose header says "solid": its size is 84 + 50·n and no keyword follows
        let h = binary_head(b"solid by some exporter", 2);
        assert!(!is_ascii_stl(&h, 84 + 100));
        // same header but the size does not fit binary: ASCII
        assert!(is_ascii_stl(&h, 84 + 99));
        assert!(!is_ascii_stl(&binary_head(b"exported", 2), 184));
    }
}
