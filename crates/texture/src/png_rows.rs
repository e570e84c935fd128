//! A PNG decoded one row at a time into RGBA8, for textures too big to decode whole within the
//! memory budget (a 16384² texture is 1 GiB of RGBA8; a zlib bomb makes one from a small file).
//! Rows come out as `image`'s whole-image decode and `into_rgba8` make them — the `png` crate
//! with `EXPAND` (palettes and bit depths below 8 expanded), 16-bit samples to 8 bits as
//! `(c + 128) / 257`, grey to `(g, g, g)`, a missing alpha 255 — so both paths give the same
//! texels (tested against `image` below). Interlaced (Adam7) images arrive in passes, not rows,
//! and are not read this way.

use std::io::{BufRead, Seek};

/// The rows of one non-interlaced PNG.
pub(crate) struct PngRows<R: BufRead + Seek> {
    reader: png::Reader<R>,
    color: png::ColorType,
    sixteen: bool,
    width: u32,
    height: u32,
}

/// True if `head` starts with the PNG signature.
pub(crate) fn is_png(head: &[u8]) -> bool {
    head.starts_with(b"\x89PNG\r\n\x1a\n")
}

impl<R: BufRead + Seek> PngRows<R> {
    /// Reads the header; `None` (not an error) for an interlaced image, which the caller
    /// decodes whole. The decoder's own allocations are bounded by `max_alloc` bytes.
    pub(crate) fn open(r: R, max_alloc: usize) -> Result<Option<PngRows<R>>, String> {
        let mut d = png::Decoder::new_with_limits(r, png::Limits { bytes: max_alloc });
        d.set_transformations(png::Transformations::EXPAND);
        let reader = d.read_info().map_err(|e| e.to_string())?;
        let info = reader.info();
        if info.interlaced {
            return Ok(None);
        }
        let (width, height) = (info.width, info.height);
        let (color, bits) = reader.output_color_type();
        let sixteen = match bits {
            png::BitDepth::Eight => false,
            png::BitDepth::Sixteen => true,
            b => return Err(format!("unsupported PNG bit depth {b:?} after expansion")),
        };
        if color == png::ColorType::Indexed {
            return Err("an indexed PNG that the decoder did not expand".into());
        }
        Ok(Some(PngRows {
            reader,
            color,
            sixteen,
            width,
            height,
        }))
    }

    pub(crate) fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Decodes the next row into `out` (`width` texels).
    pub(crate) fn next(&mut self, out: &mut [[u8; 4]]) -> Result<(), String> {
        assert_eq!(out.len(), self.width as usize);
        let (color, sixteen) = (self.color, self.sixteen);
        let row = self
            .reader
            .next_row()
            .map_err(|e| e.to_string())?
            .ok_or("the image data ends before its last row")?;
        let data = row.data();
        let channels = match color {
            png::ColorType::Grayscale => 1,
            png::ColorType::GrayscaleAlpha => 2,
            png::ColorType::Rgb => 3,
            _ => 4,
        };
        let bytes = if sixteen { 2 } else { 1 };
        if data.len() < out.len() * channels * bytes {
            return Err("a row shorter than the image's width".into());
        }
        // sample c of texel x, as 8 bits
        let at = |x: usize, c: usize| -> u8 {
            let i = (x * channels + c) * bytes;
            if sixteen {
                let v = u16::from_be_bytes([data[i], data[i + 1]]) as u32;
                ((v + 128) / 257) as u8
            } else {
                data[i]
            }
        };
        for (x, t) in out.iter_mut().enumerate() {
            *t = match channels {
                1 => {
                    let g = at(x, 0);
                    [g, g, g, 255]
                }
                2 => {
                    let g = at(x, 0);
                    [g, g, g, at(x, 1)]
                }
                3 => [at(x, 0), at(x, 1), at(x, 2), 255],
                _ => [at(x, 0), at(x, 1), at(x, 2), at(x, 3)],
            };
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(s: &mut u64) -> u8 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 33) as u8
    }

    /// Every colour type and bit depth PNG has, including palettes with and without
    /// transparency and bit depths below 8: the rows equal `image`'s decode + `into_rgba8`.
    #[test]
    fn rows_equal_image_decode_for_every_color_type() {
        use png::{BitDepth as B, ColorType as C};
        let cases = [
            (C::Grayscale, B::One),
            (C::Grayscale, B::Four),
            (C::Grayscale, B::Eight),
            (C::Grayscale, B::Sixteen),
            (C::GrayscaleAlpha, B::Eight),
            (C::GrayscaleAlpha, B::Sixteen),
            (C::Rgb, B::Eight),
            (C::Rgb, B::Sixteen),
            (C::Rgba, B::Eight),
            (C::Rgba, B::Sixteen),
            (C::Indexed, B::Two),
            (C::Indexed, B::Eight),
        ];
        let mut seed = 7u64;
        for (i, &(color, depth)) in cases.iter().enumerate() {
            for trns in [false, true] {
                if trns && color != C::Indexed && color != C::Rgb {
                    continue;
                }
                let (w, h) = (37 + i as u32, 23);
                let samples = match color {
                    C::Grayscale | C::Indexed => 1,
                    C::GrayscaleAlpha => 2,
                    C::Rgb => 3,
                    C::Rgba => 4,
                };
                let row_bytes = (w as usize * samples * depth as usize).div_ceil(8);
                let data: Vec<u8> = (0..row_bytes * h as usize)
                    .map(|_| lcg(&mut seed))
                    .collect();
                let mut png_bytes = Vec::new();
                {
                    let mut e = png::Encoder::new(&mut png_bytes, w, h);
                    e.set_color(color);
                    e.set_depth(depth);
                    if color == C::Indexed {
                        let n = 1usize << (depth as u8);
                        e.set_palette((0..n * 3).map(|_| lcg(&mut seed)).collect::<Vec<_>>());
                        if trns {
                            e.set_trns((0..n / 2).map(|_| lcg(&mut seed)).collect::<Vec<_>>());
                        }
                    } else if trns {
                        e.set_trns(vec![0, data[0], 0, data[1], 0, data[2]]);
                    }
                    let mut wr = e.write_header().unwrap();
                    wr.write_image_data(&data).unwrap();
                }
                let want = image::load_from_memory(&png_bytes)
                    .unwrap()
                    .into_rgba8()
                    .into_raw();
                let mut rows = PngRows::open(std::io::Cursor::new(&png_bytes), 1 << 20)
                    .unwrap()
                    .unwrap();
                assert_eq!(rows.size(), (w, h));
                let mut got: Vec<u8> = Vec::new();
                let mut row = vec![[0u8; 4]; w as usize];
                for _ in 0..h {
                    rows.next(&mut row).unwrap();
                    got.extend_from_slice(bytemuck::cast_slice(&row));
                }
                assert_eq!(got, want, "{color:?} {depth:?} tRNS {trns}");
                assert!(rows.next(&mut row).is_err(), "a row past the last");
            }
        }
    }
}
