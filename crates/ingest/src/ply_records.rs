//! Decoding of PLY element records, one value at a time, from the three encodings:
//! binary from a memory map ([`SliceRecords`]), binary from a (possibly gzip) stream
//! ([`StreamRecords`]) and ASCII lines ([`AsciiRecords`]). The readers above are generic
//! over [`Records`], so each encoding is decoded by monomorphised code without per-value
//! dispatch on the encoding.

use crate::ply_header::{Element, Kind, Scalar};
use crate::{IngestError, Location};
use std::cell::Cell;
use std::io::{BufRead, Read};
use std::path::Path;
use std::rc::Rc;

/// Input bytes consumed so far (compressed bytes for gzip), for progress reports.
pub(crate) type Counter = Rc<Cell<u64>>;

/// A reader that counts the bytes passing through it.
pub(crate) struct CountingReader<R> {
    pub inner: R,
    pub count: Counter,
}

impl<R: Read> Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.set(self.count.get() + n as u64);
        Ok(n)
    }
}

pub(crate) trait Records {
    /// Names the element whose records follow (for error messages).
    fn element(&mut self, name: &str, count: u64);
    /// Starts record `index` of the current element.
    fn begin(&mut self, index: u64) -> Result<(), IngestError>;
    /// Ends the current record (ASCII: nothing may be left on the line).
    fn end(&mut self) -> Result<(), IngestError>;
    /// A value of scalar type `ty`, rounded to f32 (ASCII floats are parsed straight to f32).
    fn f32(&mut self, ty: Scalar) -> Result<f32, IngestError>;
    /// A value of scalar type `ty` as f64 (exact for every PLY type).
    fn f64(&mut self, ty: Scalar) -> Result<f64, IngestError>;
    /// A value of integer type `ty`.
    fn int(&mut self, ty: Scalar) -> Result<i64, IngestError>;
    /// The count of a list whose items have type `item`; refuses negative or impossible counts.
    fn list_count(&mut self, count: Scalar, item: Scalar) -> Result<u64, IngestError>;
    /// Where the next value is.
    fn location(&self) -> Location;
    /// Input bytes consumed (for progress).
    fn bytes_done(&self) -> u64;

    /// Skips one property value (scalar or whole list).
    fn skip(&mut self, kind: Kind) -> Result<(), IngestError> {
        match kind {
            Kind::Scalar(s) => self.f64(s).map(drop),
            Kind::List { count, item } => {
                let k = self.list_count(count, item)?;
                for _ in 0..k {
                    self.f64(item)?;
                }
                Ok(())
            }
        }
    }
    /// Skips one whole record of `el`.
    fn skip_record(&mut self, el: &Element, index: u64) -> Result<(), IngestError> {
        self.begin(index)?;
        for p in &el.props {
            self.skip(p.kind)?;
        }
        self.end()
    }
}

#[inline]
fn arr<const N: usize>(b: &[u8]) -> [u8; N] {
    let mut a = [0u8; N];
    a.copy_from_slice(&b[..N]);
    a
}

/// Decodes one binary value of type `ty` from the front of `b` (`b.len() >= ty.size()`).
#[inline]
fn decode<const BE: bool>(b: &[u8], ty: Scalar) -> f64 {
    debug_assert!(b.len() >= ty.size());
    macro_rules! num {
        ($t:ty, $n:literal) => {
            if BE {
                <$t>::from_be_bytes(arr::<$n>(b)) as f64
            } else {
                <$t>::from_le_bytes(arr::<$n>(b)) as f64
            }
        };
    }
    match ty {
        Scalar::I8 => b[0] as i8 as f64,
        Scalar::U8 => b[0] as f64,
        Scalar::I16 => num!(i16, 2),
        Scalar::U16 => num!(u16, 2),
        Scalar::I32 => num!(i32, 4),
        Scalar::U32 => num!(u32, 4),
        Scalar::F32 => num!(f32, 4),
        Scalar::F64 => num!(f64, 8),
    }
}

#[inline]
fn decode_int<const BE: bool>(b: &[u8], ty: Scalar) -> i64 {
    debug_assert!(!ty.is_float() && b.len() >= ty.size());
    macro_rules! int {
        ($t:ty, $n:literal) => {
            if BE {
                <$t>::from_be_bytes(arr::<$n>(b)) as i64
            } else {
                <$t>::from_le_bytes(arr::<$n>(b)) as i64
            }
        };
    }
    match ty {
        Scalar::I8 => b[0] as i8 as i64,
        Scalar::U8 => b[0] as i64,
        Scalar::I16 => int!(i16, 2),
        Scalar::U16 => int!(u16, 2),
        Scalar::I32 => int!(i32, 4),
        Scalar::U32 => int!(u32, 4),
        // header parsing refuses float counts and indices
        Scalar::F32 | Scalar::F64 => decode::<BE>(b, ty) as i64,
    }
}

pub(crate) fn decode_f32<const BE: bool>(b: &[u8], ty: Scalar) -> f32 {
    if ty == Scalar::F32 {
        let a = arr::<4>(b);
        if BE {
            f32::from_be_bytes(a)
        } else {
            f32::from_le_bytes(a)
        }
    } else {
        decode::<BE>(b, ty) as f32
    }
}

pub(crate) fn decode_f64<const BE: bool>(b: &[u8], ty: Scalar) -> f64 {
    decode::<BE>(b, ty)
}

/// A read error inside the body (for gzip: a corrupt or cut compressed stream).
fn read_failed(path: &Path, at: Location, e: std::io::Error) -> IngestError {
    IngestError::malformed(path, at, format!("read failed: {e}"))
}

fn negative_count(path: &Path, at: Location, k: i64) -> IngestError {
    IngestError::malformed(path, at, format!("negative list count {k}"))
}

// ------------------------------------------------------------------------------------------

/// Binary records read straight from a memory-mapped file.
pub(crate) struct SliceRecords<'a, const BE: bool> {
    path: &'a Path,
    data: &'a [u8],
    pub pos: usize,
    el: String,
    index: u64,
}

impl<'a, const BE: bool> SliceRecords<'a, BE> {
    /// Records starting at byte `pos` of `data` (the whole file).
    pub fn new(path: &'a Path, data: &'a [u8], pos: usize) -> Self {
        SliceRecords {
            path,
            data,
            pos,
            el: String::new(),
            index: 0,
        }
    }

    #[inline]
    fn take(&mut self, n: usize, what: impl FnOnce() -> String) -> Result<&'a [u8], IngestError> {
        let left = self.data.len() - self.pos;
        if left < n {
            return Err(IngestError::Truncated {
                path: self.path.to_path_buf(),
                at: self.location(),
                what: what(),
                expected: n as u64,
                got: left as u64,
            });
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
}

impl<const BE: bool> Records for SliceRecords<'_, BE> {
    fn element(&mut self, name: &str, _count: u64) {
        self.el.clear();
        self.el.push_str(name);
    }
    #[inline]
    fn begin(&mut self, index: u64) -> Result<(), IngestError> {
        self.index = index;
        Ok(())
    }
    #[inline]
    fn end(&mut self) -> Result<(), IngestError> {
        Ok(())
    }
    #[inline]
    fn f32(&mut self, ty: Scalar) -> Result<f32, IngestError> {
        let b = self.take(ty.size(), || format!("one {} value", ty.name()))?;
        Ok(decode_f32::<BE>(b, ty))
    }
    #[inline]
    fn f64(&mut self, ty: Scalar) -> Result<f64, IngestError> {
        let b = self.take(ty.size(), || format!("one {} value", ty.name()))?;
        Ok(decode::<BE>(b, ty))
    }
    #[inline]
    fn int(&mut self, ty: Scalar) -> Result<i64, IngestError> {
        let b = self.take(ty.size(), || format!("one {} value", ty.name()))?;
        Ok(decode_int::<BE>(b, ty))
    }
    #[inline]
    fn list_count(&mut self, count: Scalar, item: Scalar) -> Result<u64, IngestError> {
        let at = self.pos;
        let k = self.int(count)?;
        if k < 0 {
            self.pos = at;
            return Err(negative_count(self.path, self.location(), k));
        }
        let need = k as u64 * item.size() as u64;
        let left = (self.data.len() - self.pos) as u64;
        if need > left {
            return Err(IngestError::Truncated {
                path: self.path.to_path_buf(),
                at: self.location(),
                what: format!(
                    "a list of {k} {} values (absurd count or truncated file)",
                    item.name()
                ),
                expected: need,
                got: left,
            });
        }
        Ok(k as u64)
    }
    fn skip(&mut self, kind: Kind) -> Result<(), IngestError> {
        match kind {
            Kind::Scalar(s) => self
                .take(s.size(), || format!("one {} value", s.name()))
                .map(drop),
            Kind::List { count, item } => {
                let k = self.list_count(count, item)?;
                self.pos += k as usize * item.size(); // list_count checked it fits
                Ok(())
            }
        }
    }
    fn skip_record(&mut self, el: &Element, index: u64) -> Result<(), IngestError> {
        self.index = index;
        match el.fixed_size() {
            Some(n) => self
                .take(n, || format!("a {}-byte {} record", n, el.name))
                .map(drop),
            None => {
                for p in &el.props {
                    self.skip(p.kind)?;
                }
                Ok(())
            }
        }
    }
    fn location(&self) -> Location {
        Location::Record {
            element: self.el.clone(),
            index: self.index,
            offset: self.pos as u64,
        }
    }
    #[inline]
    fn bytes_done(&self) -> u64 {
        self.pos as u64
    }
}

// ------------------------------------------------------------------------------------------

/// Binary records read from a stream (gzip-compressed binary PLY).
pub(crate) struct StreamRecords<'a, R, const BE: bool> {
    path: &'a Path,
    r: R,
    counter: Counter,
    /// Decompressed byte offset of the next value.
    pos: u64,
    el: String,
    index: u64,
    buf: [u8; 8],
}

impl<'a, R: BufRead, const BE: bool> StreamRecords<'a, R, BE> {
    fn location_at(&self, offset: u64) -> Location {
        Location::Record {
            element: self.el.clone(),
            index: self.index,
            offset,
        }
    }

    /// The stream, positioned after the last value read.
    pub fn into_inner(self) -> R {
        self.r
    }

    /// `r` positioned at decompressed byte `pos`.
    pub fn new(path: &'a Path, r: R, counter: Counter, pos: u64) -> Self {
        StreamRecords {
            path,
            r,
            counter,
            pos,
            el: String::new(),
            index: 0,
            buf: [0; 8],
        }
    }

    #[inline]
    fn fill(&mut self, ty: Scalar) -> Result<(), IngestError> {
        let n = ty.size();
        let at = self.pos;
        let avail = match self.r.fill_buf() {
            Ok(a) => a,
            Err(e) => return Err(read_failed(self.path, self.location_at(at), e)),
        };
        if avail.len() >= n {
            self.buf[..n].copy_from_slice(&avail[..n]);
            self.r.consume(n);
        } else {
            let mut got = 0;
            while got < n {
                let k = match self.r.read(&mut self.buf[got..n]) {
                    Ok(k) => k,
                    Err(e) => return Err(read_failed(self.path, self.location(), e)),
                };
                if k == 0 {
                    return Err(IngestError::Truncated {
                        path: self.path.to_path_buf(),
                        at: self.location(),
                        what: format!("one {} value", ty.name()),
                        expected: n as u64,
                        got: got as u64,
                    });
                }
                got += k;
            }
        }
        self.pos += n as u64;
        Ok(())
    }
}

impl<R: BufRead, const BE: bool> Records for StreamRecords<'_, R, BE> {
    fn element(&mut self, name: &str, _count: u64) {
        self.el.clear();
        self.el.push_str(name);
    }
    #[inline]
    fn begin(&mut self, index: u64) -> Result<(), IngestError> {
        self.index = index;
        Ok(())
    }
    #[inline]
    fn end(&mut self) -> Result<(), IngestError> {
        Ok(())
    }
    #[inline]
    fn f32(&mut self, ty: Scalar) -> Result<f32, IngestError> {
        self.fill(ty)?;
        Ok(decode_f32::<BE>(&self.buf, ty))
    }
    #[inline]
    fn f64(&mut self, ty: Scalar) -> Result<f64, IngestError> {
        self.fill(ty)?;
        Ok(decode::<BE>(&self.buf, ty))
    }
    #[inline]
    fn int(&mut self, ty: Scalar) -> Result<i64, IngestError> {
        self.fill(ty)?;
        Ok(decode_int::<BE>(&self.buf, ty))
    }
    fn list_count(&mut self, count: Scalar, _item: Scalar) -> Result<u64, IngestError> {
        let k = self.int(count)?;
        if k < 0 {
            return Err(negative_count(self.path, self.location(), k));
        }
        // The stream's length is unknown: an absurd count ends in a truncation error.
        Ok(k as u64)
    }
    fn location(&self) -> Location {
        Location::Record {
            element: self.el.clone(),
            index: self.index,
            offset: self.pos,
        }
    }
    fn bytes_done(&self) -> u64 {
        self.counter.get()
    }
}

// ------------------------------------------------------------------------------------------

/// ASCII records, one per line.
pub(crate) struct AsciiRecords<'a, R> {
    path: &'a Path,
    r: R,
    counter: Counter,
    line: Vec<u8>,
    cur: usize,
    /// 1-based number of the line in `line`.
    line_no: u64,
    el: String,
    count: u64,
}

#[inline]
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0x0b | 0x0c)
}

impl<'a, R: BufRead> AsciiRecords<'a, R> {
    /// The stream, positioned after the last line read.
    pub fn into_inner(self) -> R {
        self.r
    }

    /// `r` positioned just after the header's `lines` lines.
    pub fn new(path: &'a Path, r: R, counter: Counter, lines: u64) -> Self {
        AsciiRecords {
            path,
            r,
            counter,
            line: Vec::with_capacity(256),
            cur: 0,
            line_no: lines,
            el: String::new(),
            count: 0,
        }
    }

    #[inline]
    fn token(&mut self, ty: Scalar) -> Result<&[u8], IngestError> {
        let l = &self.line;
        let mut i = self.cur;
        while i < l.len() && is_space(l[i]) {
            i += 1;
        }
        let s = i;
        while i < l.len() && !is_space(l[i]) {
            i += 1;
        }
        if s == i {
            return Err(IngestError::malformed(
                self.path,
                Location::Line(self.line_no),
                format!(
                    "{} record ends early: expected another {} value",
                    self.el,
                    ty.name()
                ),
            ));
        }
        self.cur = i;
        Ok(&self.line[s..i])
    }

    fn bad_number(&self, tok: &[u8], ty: Scalar) -> IngestError {
        IngestError::malformed(
            self.path,
            Location::Line(self.line_no),
            format!(
                "{} is not a valid {} value",
                crate::error::quoted(&String::from_utf8_lossy(tok)),
                ty.name()
            ),
        )
    }
}

fn parse_int(t: &[u8]) -> Option<i64> {
    let (neg, digits) = match t.first()? {
        b'-' => (true, &t[1..]),
        b'+' => (false, &t[1..]),
        _ => (false, t),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (d - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

impl<R: BufRead> Records for AsciiRecords<'_, R> {
    fn element(&mut self, name: &str, count: u64) {
        self.el.clear();
        self.el.push_str(name);
        self.count = count;
    }
    fn begin(&mut self, index: u64) -> Result<(), IngestError> {
        // Blank lines between records are tolerated.
        loop {
            self.line.clear();
            self.cur = 0;
            let n = match self.r.read_until(b'\n', &mut self.line) {
                Ok(n) => n,
                Err(e) => return Err(read_failed(self.path, Location::Line(self.line_no + 1), e)),
            };
            if n == 0 {
                return Err(IngestError::malformed(
                    self.path,
                    Location::Line(self.line_no + 1),
                    format!(
                        "the file ends after {index} of the {} {} records the header declares",
                        self.count, self.el
                    ),
                ));
            }
            self.line_no += 1;
            if !self.line.iter().all(|&b| is_space(b)) {
                return Ok(());
            }
        }
    }
    fn end(&mut self) -> Result<(), IngestError> {
        let rest = &self.line[self.cur..];
        if rest.iter().all(|&b| is_space(b)) {
            Ok(())
        } else {
            Err(IngestError::malformed(
                self.path,
                Location::Line(self.line_no),
                format!(
                    "extra values after the last property of the {} record: {}",
                    self.el,
                    crate::error::quoted(String::from_utf8_lossy(rest).trim())
                ),
            ))
        }
    }
    #[inline]
    fn f32(&mut self, ty: Scalar) -> Result<f32, IngestError> {
        if ty != Scalar::F32 {
            return self.f64(ty).map(|v| v as f32);
        }
        let t = self.token(ty)?;
        match std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<f32>().ok())
        {
            Some(v) => Ok(v),
            None => {
                let t = t.to_vec();
                Err(self.bad_number(&t, ty))
            }
        }
    }
    #[inline]
    fn f64(&mut self, ty: Scalar) -> Result<f64, IngestError> {
        let t = self.token(ty)?;
        let v = if ty.is_float() {
            std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse::<f64>().ok())
        } else {
            parse_int(t).map(|v| v as f64)
        };
        match v {
            Some(v) => Ok(v),
            None => {
                let t = t.to_vec();
                Err(self.bad_number(&t, ty))
            }
        }
    }
    #[inline]
    fn int(&mut self, ty: Scalar) -> Result<i64, IngestError> {
        let t = self.token(ty)?;
        match parse_int(t) {
            // an ASCII value must fit its declared type, as it would in a binary file (a
            // list count of 300 declared `uchar` is an error, not 300)
            Some(v) if ty.int_range().is_none_or(|r| r.contains(&v)) => Ok(v),
            Some(v) => {
                let r = ty.int_range().expect("an integer type");
                Err(IngestError::malformed(
                    self.path,
                    Location::Line(self.line_no),
                    format!(
                        "{v} does not fit the declared type {} ({}..={})",
                        ty.name(),
                        r.start(),
                        r.end()
                    ),
                ))
            }
            None => {
                let t = t.to_vec();
                Err(self.bad_number(&t, ty))
            }
        }
    }
    fn list_count(&mut self, count: Scalar, item: Scalar) -> Result<u64, IngestError> {
        let k = self.int(count)?;
        if k < 0 {
            return Err(negative_count(self.path, self.location(), k));
        }
        // every value takes at least two bytes (a digit and a separator)
        let room = (self.line.len() - self.cur) as u64;
        if (k as u64).saturating_mul(2) > room + 1 {
            return Err(IngestError::malformed(
                self.path,
                self.location(),
                format!("absurd list count {k}: {room} bytes left on the line cannot hold {k} {} values", item.name()),
            ));
        }
        Ok(k as u64)
    }
    fn skip_record(&mut self, _el: &Element, index: u64) -> Result<(), IngestError> {
        // one record per line: skipping it is reading the line
        self.begin(index)
    }
    fn location(&self) -> Location {
        Location::Line(self.line_no)
    }
    fn bytes_done(&self) -> u64 {
        self.counter.get()
    }
}
