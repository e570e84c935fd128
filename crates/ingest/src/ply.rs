//! PLY reading: binary files are memory-mapped and their vertices read in place; ASCII and
//! gzip files are read front to back, vertices into a compact array, faces streamed.
//! A face element that comes before the vertex element in a front-to-back input is streamed
//! in a second pass over the file.

use crate::batch::Emitter;
use crate::batch::LocalBatch;
use crate::bounds::parallel_bounds;
use crate::map_guard::MappedFile;
use crate::ply_face_data::FaceRecords;
use crate::ply_faces::{
    plain_item, stream_faces, stream_triangles_parallel, triangle_record, triangle_record_bytes,
};
use crate::ply_header::{parse_header, Element, Encoding, Header, Scalar};
use crate::ply_materials::material_table;
use crate::ply_records::{
    AsciiRecords, Counter, CountingReader, Records, SliceRecords, StreamRecords,
};
use crate::ply_vertices::{CompactVertices, MappedVertices, VertexSource};
use crate::{FacePart, IngestError, Location, MeshInfo};
use flate2::read::MultiGzDecoder;
use std::cell::Cell;
use std::collections::BTreeSet;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use voxlod_geom::{Bounds, Triangle, TRI_HAS_COLORS, TRI_HAS_NORMALS, TRI_HAS_UV};

pub(crate) struct PlySource {
    path: PathBuf,
    header: Header,
    gz: bool,
    file_len: u64,
    /// The whole file, for binary (not gzip) input.
    map: Option<MappedFile>,
    /// Byte offset of each element needed from the map (vertex and face elements).
    offsets: Vec<Option<usize>>,
    /// Passes over the file that front-to-back reading needs (2 if faces precede vertices).
    passes: u64,
    /// Flags from the material table (`TRI_HAS_UV`, the one texture's material).
    table_flags: u32,
    /// Triangles decoded by [`PlySource::triangles_at`] since it last released the map's
    /// pages (shared by the threads that call it).
    since_release: std::sync::atomic::AtomicU64,
}

impl PlySource {
    pub fn open(
        path: &Path,
        gz: bool,
        file_len: u64,
        scope: &crate::refs::Scope,
    ) -> Result<(PlySource, MeshInfo), IngestError> {
        let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
        let header = if gz {
            parse_header(path, &mut BufReader::new(MultiGzDecoder::new(file)))?
        } else {
            parse_header(path, &mut BufReader::new(file))?
        };
        let layout = &header.layout;
        let mut warnings = Vec::new();
        if layout.sources.is_empty() {
            // a point cloud: say so and what to do, rather than "no triangles" after a full read
            return Err(IngestError::malformed(
                path,
                Location::File,
                "a point cloud (vertices only, no face or tristrips element): voxlod voxelizes \
                 triangle meshes; reconstruct a surface first (e.g. screened Poisson or ball \
                 pivoting in MeshLab or Open3D) and build from that mesh",
            ));
        }
        let mut map = None;
        let mut offsets = vec![None; header.elements.len()];
        if !gz && header.encoding != Encoding::Ascii {
            let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
            // a truncation while it is mapped ends the process with a message (map_guard)
            let m = MappedFile::map(path, &file).map_err(|e| IngestError::io(path, e))?;
            offsets = match header.encoding {
                Encoding::BinaryBe => element_offsets::<true>(path, &header, &m)?,
                _ => element_offsets::<false>(path, &header, &m)?,
            };
            map = Some(m);
        }
        // after the exact offsets of the fixed-size elements (whose own message names the
        // element and the bytes missing), the counts of the variable-size ones
        if !gz {
            check_counts_fit(path, &header, file_len)?;
        }
        let passes = if layout.sources.iter().any(|s| s.0 < layout.vertex) {
            2
        } else {
            1
        };
        let mut src = PlySource {
            path: path.to_path_buf(),
            header,
            gz,
            file_len,
            map,
            offsets,
            passes,
            table_flags: 0,
            since_release: Default::default(),
        };
        let mut header = src.header.clone();
        let table = material_table(path, scope, &mut header, &mut |h, ei, pi, ty| {
            src.scan_values(h, ei, pi, ty)
        })?;
        src.header = header;
        src.table_flags = table.flags;
        warnings.extend(table.warnings);
        let header = &src.header;
        let layout = &header.layout;
        let info = MeshInfo {
            path: path.to_path_buf(),
            format: format!(
                "ply {}{}",
                header.encoding.name(),
                if gz { " (gzip)" } else { "" }
            ),
            vertices: header.elements[layout.vertex].count,
            faces: layout
                .sources
                .iter()
                .filter(|s| !s.2)
                .map(|s| header.elements[s.0].count)
                .sum(),
            has_normals: layout.has_normals,
            has_colors: layout.has_colors || table.face_colors,
            has_texcoords: table.flags & TRI_HAS_UV != 0,
            materials: table.materials,
            warnings,
            up: None,
            held: 0,
        };
        Ok((src, info))
    }

    /// The distinct values of integer property `pi` (type `ty`) of element `ei`, read in one
    /// pass over the element (from the map, or front to back), for the material table.
    fn scan_values(
        &self,
        h: &Header,
        ei: usize,
        pi: usize,
        ty: Scalar,
    ) -> Result<BTreeSet<i64>, IngestError> {
        // skips the elements `before`, then reads the values from element `el`
        fn values<R: Records>(
            src: &mut R,
            before: &[Element],
            el: &Element,
            pi: usize,
            ty: Scalar,
        ) -> Result<BTreeSet<i64>, IngestError> {
            for b in before {
                skip_element(src, b)?;
            }
            let mut set = BTreeSet::new();
            src.element(&el.name, el.count);
            for r in 0..el.count {
                src.begin(r)?;
                for (k, p) in el.props.iter().enumerate() {
                    if k == pi {
                        set.insert(src.int(ty)?);
                    } else {
                        src.skip(p.kind)?;
                    }
                }
                src.end()?;
            }
            Ok(set)
        }
        let el = &h.elements[ei];
        if let (Some(m), Some(off)) = (&self.map, self.offsets[ei]) {
            // from the element's own offset: the elements before it are not walked
            return match h.encoding {
                Encoding::BinaryBe => values(
                    &mut SliceRecords::<true>::new(&self.path, m, off),
                    &[],
                    el,
                    pi,
                    ty,
                ),
                _ => values(
                    &mut SliceRecords::<false>::new(&self.path, m, off),
                    &[],
                    el,
                    pi,
                    ty,
                ),
            };
        }
        let (r, counter) = self.open_body(0)?;
        let before = &h.elements[..ei];
        match h.encoding {
            Encoding::Ascii => {
                let mut src = AsciiRecords::new(&self.path, r, counter, h.lines);
                values(&mut src, before, el, pi, ty)
            }
            Encoding::BinaryLe => {
                let mut src = StreamRecords::<_, false>::new(&self.path, r, counter, h.bytes);
                values(&mut src, before, el, pi, ty)
            }
            Encoding::BinaryBe => {
                let mut src = StreamRecords::<_, true>::new(&self.path, r, counter, h.bytes);
                values(&mut src, before, el, pi, ty)
            }
        }
    }

    /// True for binary (not gzip) input, read through the memory map.
    pub fn is_mapped(&self) -> bool {
        self.map.is_some()
    }

    /// Input bytes the progress reports count up to.
    pub fn progress_total(&self) -> u64 {
        if self.map.is_some() {
            self.file_len
        } else {
            self.file_len * self.passes
        }
    }

    fn flags(&self) -> u32 {
        let l = &self.header.layout;
        (if l.has_normals { TRI_HAS_NORMALS } else { 0 })
            | (if l.has_colors { TRI_HAS_COLORS } else { 0 })
            | self.table_flags
    }

    /// Drops this process's resident pages of the memory-mapped input (they stay in the page
    /// cache, so touching them again is a minor fault, not a read): the mapping's share of
    /// resident memory stays bounded by what a few thousand triangles touch.
    pub fn release_pages(&self) {
        if let Some(m) = &self.map {
            // SAFETY: the map is a read-only shared file mapping; after MADV_DONTNEED its pages
            // are read back from the file on the next access, with the same contents.
            let _ = unsafe {
                m.mmap()
                    .unchecked_advise(memmap2::UncheckedAdvice::DontNeed)
            };
        }
    }

    /// Tells the kernel how the mapped file will be read: `true` at random (no readahead: a
    /// sample of scattered face records reads only their pages, not the 8 MiB around each),
    /// `false` in order again (the default readahead).
    pub fn advise_random(&self, random: bool) {
        if let Some(m) = &self.map {
            let advice = if random {
                memmap2::Advice::Random
            } else {
                memmap2::Advice::Normal
            };
            let _ = m.mmap().advise(advice);
        }
    }

    pub fn stream(&self, em: &mut Emitter) -> Result<(), IngestError> {
        match (&self.map, self.header.encoding) {
            (Some(m), Encoding::BinaryBe) => self.stream_mapped::<true>(m, None, false, em),
            (Some(m), _) => self.stream_mapped::<false>(m, None, false, em),
            (None, _) => self.stream_sequential(em),
        }
    }

    /// Streams every triangle with its face record ([`PlySource::fixed_faces`] must hold).
    pub fn stream_indexed(&self, em: &mut Emitter) -> Result<(), IngestError> {
        assert!(self.fixed_faces().is_some(), "faces of fixed-size records");
        match (&self.map, self.header.encoding) {
            (Some(m), Encoding::BinaryBe) => self.stream_mapped::<true>(m, None, true, em),
            (Some(m), _) => self.stream_mapped::<false>(m, None, true, em),
            (None, _) => unreachable!("fixed faces are mapped"),
        }
    }

    /// The face element as fixed-size triangle records that can be found by index, if it is
    /// one (the conditions of [`PlySource::face_parts`]): its element, index list property,
    /// record bytes and byte offset.
    fn fixed_faces(&self) -> Option<(usize, usize, usize, usize)> {
        let data: &[u8] = self.map.as_ref()?;
        let l = &self.header.layout;
        self.header.elements[l.vertex].fixed_size()?;
        let &[(ei, list, false)] = l.sources.as_slice() else {
            return None;
        };
        let el = &self.header.elements[ei];
        let size = triangle_record_bytes(el, list)?;
        let off = self.offsets[ei]?;
        let fills = ei + 1 == self.header.elements.len()
            && el
                .count
                .checked_mul(size as u64)
                .and_then(|b| b.checked_add(off as u64))
                == Some(data.len() as u64);
        fills.then_some((ei, list, size, off))
    }

    /// Face records, if they are fixed-size triangle records that can be found by index.
    pub fn fixed_face_count(&self) -> Option<u64> {
        self.fixed_faces()
            .map(|(ei, ..)| self.header.elements[ei].count)
    }

    /// Appends the triangle of each face record of `faces` to `out`: the triangle the stream
    /// gave for that record (bit for bit: the same decode), which must still be one (else
    /// [`IngestError::FaceChanged`]). Releases the map's pages every
    /// [`crate::batch::RELEASE_EVERY`] triangles, as the stream does.
    pub fn triangles_at(&self, faces: &[u64], out: &mut Vec<Triangle>) -> Result<(), IngestError> {
        let (Some(m), Some((ei, list, size, off))) = (&self.map, self.fixed_faces()) else {
            panic!("triangles by face record from fixed-size triangle records only");
        };
        match self.header.encoding {
            Encoding::BinaryBe => self.triangles_at_in::<true>(m, ei, list, size, off, faces, out),
            _ => self.triangles_at_in::<false>(m, ei, list, size, off, faces, out),
        }?;
        use std::sync::atomic::Ordering;
        let n = faces.len() as u64;
        let before = self.since_release.fetch_add(n, Ordering::Relaxed);
        if before + n >= crate::batch::RELEASE_EVERY as u64 {
            self.since_release.store(0, Ordering::Relaxed);
            self.release_pages();
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn triangles_at_in<const BE: bool>(
        &self,
        data: &[u8],
        ei: usize,
        list: usize,
        size: usize,
        off: usize,
        faces: &[u64],
        out: &mut Vec<Triangle>,
    ) -> Result<(), IngestError> {
        let l = &self.header.layout;
        let vel = &self.header.elements[l.vertex];
        let stride = vel.fixed_size().expect("fixed faces have fixed vertices");
        let voff = self.offsets[l.vertex].expect("mapped vertices");
        let verts =
            MappedVertices::<BE>::new(&data[voff..voff + vel.count as usize * stride], vel, l);
        let el = &self.header.elements[ei];
        let records = FaceRecords {
            path: &self.path,
            el,
            list,
            verts: &verts,
            flags: self.flags(),
        };
        let plain = plain_item(el, list);
        let mut lb = LocalBatch {
            tris: std::mem::take(out),
            ..Default::default()
        };
        let mut r = Ok(());
        for &f in faces {
            let had = lb.tris.len();
            let changed = || IngestError::FaceChanged {
                path: self.path.clone(),
                face: f,
            };
            if f >= el.count {
                r = Err(changed());
                break;
            }
            match triangle_record::<BE, _>(&records, data, off, size, plain, f, &mut lb) {
                Ok(true) if lb.tris.len() == had + 1 => {}
                Ok(_) => {
                    r = Err(changed());
                    break;
                }
                Err(e) => {
                    r = Err(e);
                    break;
                }
            }
        }
        *out = lb.tris;
        r
    }

    /// The face records cut into `n` parts of consecutive records (fewer if there are fewer
    /// records), if a part can be found and read without reading the others: a memory-mapped
    /// file with fixed-size vertex records and one face element (no strips), the last element,
    /// whose records are triangles of one size that fill the file to its end exactly (so no
    /// record is a polygon of another size). `None` otherwise.
    pub fn face_parts(&self, n: u64) -> Option<Vec<FacePart>> {
        let (ei, _, size, off) = self.fixed_faces()?;
        let el = &self.header.elements[ei];
        let (size, off) = (size as u64, off as u64);
        let n = n.clamp(1, el.count.max(1));
        Some(
            (0..n)
                .map(|i| {
                    let (a, b) = (el.count * i / n, el.count * (i + 1) / n);
                    FacePart {
                        records: [a, b],
                        bytes: [off + a * size, off + b * size],
                    }
                })
                .collect(),
        )
    }

    /// What part `part` of [`PlySource::face_parts`] reads besides its face records: the
    /// indices of the pages of `page` bytes (a power of two) (counted from byte 0 of the file, up to the first
    /// face record) that hold the header and the elements before the vertex list, or a vertex
    /// record one of the part's face records names. `faces` is handed the part's face record
    /// bytes, in order. `None` if the file cannot be cut into parts.
    pub fn part_footprint(
        &self,
        part: &FacePart,
        page: u64,
        faces: &mut dyn FnMut(&[u8]),
    ) -> Option<Vec<u64>> {
        use crate::ply_header::Kind;
        assert!(page.is_power_of_two(), "pages of a power of two bytes");
        let (ei, list, size, off) = self.fixed_faces()?;
        let data: &[u8] = self.map.as_ref()?;
        let el = &self.header.elements[ei];
        let l = &self.header.layout;
        let vel = &self.header.elements[l.vertex];
        let stride = vel.fixed_size()? as u64;
        let voff = self.offsets[l.vertex]? as u64;
        let Kind::List { count, item } = el.props[list].kind else {
            return None;
        };
        // where the three vertex indices of a record start
        let first: usize = el.props[..list]
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { .. } => 0,
            })
            .sum::<usize>()
            + count.size();
        let be = self.header.encoding == Encoding::BinaryBe;
        let pages = (off as u64).div_ceil(page) as usize;
        let shift = page.trailing_zeros();
        let mut used = vec![0u64; pages.div_ceil(64)];
        let mut set = |k: u64| used[k as usize / 64] |= 1 << (k % 64);
        // the header and the elements before the vertex list
        if voff > 0 {
            for k in 0..=((voff - 1) >> shift) {
                set(k);
            }
        }
        let (nv, isz) = (vel.count, item.size());
        let value = |b: &[u8]| -> Option<u64> {
            let mut w = [0u8; 8];
            if be {
                w[8 - isz..].copy_from_slice(b);
                w.reverse();
            } else {
                w[..isz].copy_from_slice(b);
            }
            let raw = u64::from_le_bytes(w);
            let v = match item {
                Scalar::I8 => raw as u8 as i8 as i64,
                Scalar::I16 => raw as u16 as i16 as i64,
                Scalar::I32 => raw as u32 as i32 as i64,
                Scalar::U8 | Scalar::U16 | Scalar::U32 => raw as i64,
                Scalar::F32 => f32::from_bits(raw as u32) as i64,
                Scalar::F64 => f64::from_bits(raw) as i64,
            };
            // an index out of range is the decoder's error to report, not a page to check
            u64::try_from(v).ok().filter(|&v| v < nv)
        };
        // the pages of vertex `v`'s record (one, or two when it straddles a border); a run of
        // faces mostly names vertices of the page named last
        let mut last = u64::MAX;
        let mut mark = |v: u64| {
            let a = voff + v * stride;
            let (p, q) = (a >> shift, (a + stride - 1) >> shift);
            if p != last {
                set(p);
                last = p;
            }
            if q != p {
                set(q);
            }
        };
        // plain little-endian 32-bit indices (what scanners write) without the general decode
        let plain_le = !be && matches!(item, Scalar::I32 | Scalar::U32);
        // in blocks of whole records, the map's pages released after each
        let block = ((16u64 << 20) / size as u64).max(1) as usize * size;
        let (start, end) = (part.bytes[0] as usize, part.bytes[1] as usize);
        debug_assert_eq!((start - off) % size, 0, "a part starts at a record");
        let mut at = start;
        while at < end {
            let to = (at + block).min(end);
            let bytes = &data[at..to];
            faces(bytes);
            for r in bytes.chunks_exact(size) {
                for k in 0..3 {
                    let i = first + k * isz;
                    let v = if plain_le {
                        let v = u32::from_le_bytes([r[i], r[i + 1], r[i + 2], r[i + 3]]) as u64;
                        let negative = item == Scalar::I32 && v > i32::MAX as u64;
                        (!negative && v < nv).then_some(v)
                    } else {
                        value(&r[i..i + isz])
                    };
                    if let Some(v) = v {
                        mark(v);
                    }
                }
            }
            self.release_pages();
            at = to;
        }
        Some(
            (0..pages as u64)
                .filter(|&k| used[k as usize / 64] & (1 << (k % 64)) != 0)
                .collect(),
        )
    }

    /// The file's bytes, for a memory-mapped input.
    pub fn mapped_bytes(&self) -> Option<&[u8]> {
        self.map.as_deref()
    }

    /// Streams the triangles of one part of [`PlySource::face_parts`] only.
    pub fn stream_part(&self, part: &FacePart, em: &mut Emitter) -> Result<(), IngestError> {
        let range = part.records[0]..part.records[1];
        match (&self.map, self.header.encoding) {
            (Some(m), Encoding::BinaryBe) => self.stream_mapped::<true>(m, Some(range), false, em),
            (Some(m), _) => self.stream_mapped::<false>(m, Some(range), false, em),
            (None, _) => panic!("a part of a PLY that is not memory-mapped"),
        }
    }

    /// Streams the faces from the map: all of them, or the face records `part` only.
    fn stream_mapped<const BE: bool>(
        &self,
        data: &[u8],
        part: Option<std::ops::Range<u64>>,
        indexed: bool,
        em: &mut Emitter,
    ) -> Result<(), IngestError> {
        let l = &self.header.layout;
        let vel = &self.header.elements[l.vertex];
        let voff = self.offsets[l.vertex].unwrap_or(data.len());
        match vel.fixed_size() {
            Some(stride) => {
                // element_offsets checked that the vertex records lie inside the file
                let end = voff + vel.count as usize * stride;
                let verts = MappedVertices::<BE>::new(&data[voff..end], vel, l);
                self.faces_from_map::<BE, _>(data, &verts, part, indexed, em)
            }
            None => {
                assert!(
                    part.is_none() && !indexed,
                    "parts and indices need fixed-size vertex records"
                );
                let mut src = SliceRecords::<BE>::new(&self.path, data, voff);
                let verts =
                    CompactVertices::load(&self.path, &mut src, vel, l, &mut |b| em.report(b))?;
                self.faces_from_map::<BE, _>(data, &verts, None, false, em)
            }
        }
    }

    /// The bounds of every vertex position, for a memory-mapped file with fixed-size vertex
    /// records (read straight from the map); `None` otherwise or if a position is not finite.
    pub fn vertex_bounds(&self) -> Option<Bounds> {
        match self.header.encoding {
            Encoding::BinaryBe => self.vertex_bounds_mapped::<true>(),
            _ => self.vertex_bounds_mapped::<false>(),
        }
    }

    fn vertex_bounds_mapped<const BE: bool>(&self) -> Option<Bounds> {
        let data: &[u8] = self.map.as_ref()?;
        let l = &self.header.layout;
        let vel = &self.header.elements[l.vertex];
        let stride = vel.fixed_size()?;
        let voff = self.offsets[l.vertex]?;
        // element_offsets checked that the vertex records lie inside the file
        let end = voff + vel.count as usize * stride;
        let verts = MappedVertices::<BE>::new(&data[voff..end], vel, l);
        // in rounds of 32 MiB of records, the pages read released after each
        let round = (32u64 << 20) / stride as u64;
        parallel_bounds(vel.count, round, &|| self.release_pages(), &|r, b| {
            verts.add_positions(r, b)
        })
    }

    fn faces_from_map<const BE: bool, V: VertexSource + Sync>(
        &self,
        data: &[u8],
        verts: &V,
        part: Option<std::ops::Range<u64>>,
        indexed: bool,
        em: &mut Emitter,
    ) -> Result<(), IngestError> {
        debug_assert!(part.is_none() || self.header.layout.sources.len() == 1);
        debug_assert!(!indexed || self.header.layout.sources.len() == 1);
        for &(ei, list, strips) in &self.header.layout.sources {
            let off = self.offsets[ei].unwrap_or(data.len());
            let el = &self.header.elements[ei];
            let faces = FaceRecords {
                path: &self.path,
                el,
                list,
                verts,
                flags: self.flags(),
            };
            if strips {
                let mut src = SliceRecords::<BE>::new(&self.path, data, off);
                stream_faces(&faces, strips, &mut src, em, 0..el.count, false)?;
            } else {
                let records = part.clone().unwrap_or(0..el.count);
                stream_triangles_parallel::<BE, V>(&faces, data, off, records, indexed, em)?;
            }
        }
        Ok(())
    }

    /// Opens the file positioned at the first body byte. The counter starts at `start`.
    fn open_body(&self, start: u64) -> Result<(BufReader<Box<dyn Read>>, Counter), IngestError> {
        let path = &self.path;
        let file = File::open(path).map_err(|e| IngestError::io(path, e))?;
        let counter: Counter = Rc::new(Cell::new(start));
        let counting = CountingReader {
            inner: file,
            count: counter.clone(),
        };
        let inner: Box<dyn Read> = if self.gz {
            Box::new(MultiGzDecoder::new(counting))
        } else {
            Box::new(counting)
        };
        let mut r = BufReader::with_capacity(1 << 18, inner);
        let want = self.header.bytes;
        let skipped = std::io::copy(&mut (&mut r).take(want), &mut std::io::sink())
            .map_err(|e| IngestError::io(path, e))?;
        if skipped != want {
            return Err(IngestError::malformed(
                path,
                Location::File,
                "the file changed since its header was read",
            ));
        }
        Ok((r, counter))
    }

    fn stream_sequential(&self, em: &mut Emitter) -> Result<(), IngestError> {
        let mut verts = None;
        let mut done = vec![false; self.header.layout.sources.len()];
        for pass in 0..self.passes {
            let (r, counter) = self.open_body(pass * self.file_len)?;
            let rest = match self.header.encoding {
                Encoding::Ascii => {
                    let mut src = AsciiRecords::new(&self.path, r, counter, self.header.lines);
                    self.pass(&mut src, &mut verts, &mut done, em)?;
                    src.into_inner()
                }
                Encoding::BinaryLe => {
                    let mut src =
                        StreamRecords::<_, false>::new(&self.path, r, counter, self.header.bytes);
                    self.pass(&mut src, &mut verts, &mut done, em)?;
                    src.into_inner()
                }
                Encoding::BinaryBe => {
                    let mut src =
                        StreamRecords::<_, true>::new(&self.path, r, counter, self.header.bytes);
                    self.pass(&mut src, &mut verts, &mut done, em)?;
                    src.into_inner()
                }
            };
            if self.gz && pass + 1 == self.passes {
                check_gzip_trailer(&self.path, rest)?;
            }
        }
        debug_assert!(done.iter().all(|&d| d));
        Ok(())
    }

    /// One front-to-back pass: loads the vertices if not yet loaded, streams every face
    /// element not yet done whose vertices are known, skips everything else, and stops after
    /// the last element it needs.
    fn pass<R: Records>(
        &self,
        src: &mut R,
        verts: &mut Option<CompactVertices>,
        done: &mut [bool],
        em: &mut Emitter,
    ) -> Result<(), IngestError> {
        let l = &self.header.layout;
        let mut last = if verts.is_none() { l.vertex } else { 0 };
        for (s, d) in l.sources.iter().zip(done.iter()) {
            if !d {
                last = last.max(s.0);
            }
        }
        for (i, el) in self.header.elements.iter().enumerate().take(last + 1) {
            if i == l.vertex && verts.is_none() {
                *verts = Some(CompactVertices::load(&self.path, src, el, l, &mut |b| {
                    em.report(b)
                })?);
                continue;
            }
            if let Some(si) = l.sources.iter().position(|s| s.0 == i) {
                if let (false, Some(v)) = (done[si], verts.as_ref()) {
                    let (_, list, strips) = l.sources[si];
                    let faces = FaceRecords {
                        path: &self.path,
                        el,
                        list,
                        verts: v,
                        flags: self.flags(),
                    };
                    stream_faces(&faces, strips, src, em, 0..el.count, false)?;
                    done[si] = true;
                    continue;
                }
            }
            skip_element(src, el)?;
        }
        Ok(())
    }
}

/// An ASCII body may fall short of the fewest bytes its counts need by this much before the
/// header is refused up front; a smaller shortfall is left to the parser, whose message names
/// the line where the data stops or goes wrong (more useful for a truncated or mistyped file).
const ASCII_SHORTFALL: u64 = 64 << 20;

/// Refuses a header whose element counts cannot fit in the file, even at the fewest bytes a
/// record can take (a 42 KB file claiming 4e9 faces), before any plan is made from them.
fn check_counts_fit(path: &Path, header: &Header, file_len: u64) -> Result<(), IngestError> {
    let ascii = header.encoding == Encoding::Ascii;
    let body = file_len.saturating_sub(header.bytes);
    let allowed = if ascii {
        body.saturating_add(ASCII_SHORTFALL)
    } else {
        body
    };
    let mut need = 0u64;
    for el in &header.elements {
        need = need.saturating_add(el.count.saturating_mul(el.min_record_bytes(ascii)));
        if need > allowed {
            return Err(IngestError::malformed(
                path,
                Location::File,
                format!(
                    "the header declares {} records of element \"{}\" (and the elements before them), which need at least {need} bytes, but the file has {body} bytes after its header: the header is inconsistent with the file size (truncated file?)",
                    el.count, el.name
                ),
            ));
        }
    }
    Ok(())
}

/// Reads a gzip stream to its end, which makes the decoder check each member's trailer (CRC32
/// and length of the data): the parse stops after the last element it needs, before the
/// trailer, so without this a damaged or truncated `.ply.gz` would build without an error.
fn check_gzip_trailer(path: &Path, mut rest: impl Read) -> Result<(), IngestError> {
    match std::io::copy(&mut rest, &mut std::io::sink()) {
        Ok(_) => Ok(()),
        Err(e) => Err(gzip_error(path, e)),
    }
}

/// A gzip decoding error as a message about the file: damaged (checksum), truncated (no
/// trailer) or another read error.
pub(crate) fn gzip_error(path: &Path, e: std::io::Error) -> IngestError {
    let what = match e.kind() {
        std::io::ErrorKind::UnexpectedEof => {
            "the gzip data ends early, without its trailer: the file is truncated"
        }
        std::io::ErrorKind::InvalidInput | std::io::ErrorKind::InvalidData => {
            if e.to_string().contains("checksum") {
                "the gzip checksum (CRC32 and length in the trailer) does not match the data: the file is damaged"
            } else {
                "the gzip data is corrupt: the file is damaged"
            }
        }
        _ => return IngestError::io(path, e),
    };
    IngestError::malformed(path, Location::File, what)
}

fn skip_element<R: Records>(src: &mut R, el: &Element) -> Result<(), IngestError> {
    src.element(&el.name, el.count);
    for r in 0..el.count {
        src.skip_record(el, r)?;
    }
    Ok(())
}

/// Byte offsets of the elements up to the last one the mesh needs. Fixed-size elements are
/// stepped over arithmetically (and must fit in the file); variable-size ones before a needed
/// element are walked record by record.
fn element_offsets<const BE: bool>(
    path: &Path,
    header: &Header,
    data: &[u8],
) -> Result<Vec<Option<usize>>, IngestError> {
    let l = &header.layout;
    let last = l
        .sources
        .iter()
        .map(|s| s.0)
        .chain([l.vertex])
        .max()
        .unwrap_or(l.vertex);
    let mut offsets = vec![None; header.elements.len()];
    let mut off = header.bytes as usize;
    for (i, el) in header.elements.iter().enumerate().take(last + 1) {
        offsets[i] = Some(off);
        match el.fixed_size() {
            Some(size) => {
                let left = (data.len() - off) as u64;
                let need = el.count.saturating_mul(size as u64);
                if need > left {
                    return Err(IngestError::Truncated {
                        path: path.to_path_buf(),
                        at: Location::Record {
                            element: el.name.clone(),
                            index: 0,
                            offset: off as u64,
                        },
                        what: format!(
                            "element {:?} ({} records of {size} bytes)",
                            el.name, el.count
                        ),
                        expected: need,
                        got: left,
                    });
                }
                off += need as usize;
            }
            None if i == last => break,
            None => {
                let mut src = SliceRecords::<BE>::new(path, data, off);
                skip_element(&mut src, el)?;
                off = src.pos;
            }
        }
    }
    Ok(offsets)
}

/// True if the gzip stream in `path` decompresses to something starting with "ply".
pub(crate) fn gz_holds_ply(path: &Path) -> bool {
    let Ok(f) = File::open(path) else {
        return false;
    };
    let mut r = BufReader::new(MultiGzDecoder::new(f));
    matches!(r.fill_buf(), Ok(b) if b.starts_with(b"ply"))
}
