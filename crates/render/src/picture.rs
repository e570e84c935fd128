//! A rendered picture: RGBA pixels (alpha = coverage by the model), the camera it was taken
//! with, and PNG output with the `png` crate or JPEG output with the `image` crate.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use crate::camera::Shot;
use crate::RenderError;

/// Pixels of a rendered image, rows top to bottom, 4 bytes per pixel. The colour is already
/// composited over the background; alpha is 255 where the model covers the pixel (fractions
/// at multisampled edges), 0 on the background.
#[derive(Clone, Debug)]
pub struct Picture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8 pixels.
    pub rgba: Vec<u8>,
    /// The camera.
    pub shot: Shot,
    /// The nodes drawn.
    pub nodes: Vec<usize>,
    /// Voxels drawn as cubes (those of the nodes not drawn from source triangles).
    pub voxels: u64,
    /// Faces sent to the GPU (active faces turned towards the eye).
    pub faces_drawn: u64,
    /// Leaves drawn from their source triangles instead of their voxels (`--source-geometry`
    /// files).
    pub source_leaves: u64,
    /// Source triangles drawn.
    pub source_triangles: u64,
}

impl Picture {
    /// True for each pixel the model covers (alpha of at least one half).
    pub fn coverage(&self) -> Vec<bool> {
        self.rgba.chunks_exact(4).map(|p| p[3] >= 128).collect()
    }

    /// Writes the picture as an 8-bit RGB PNG (alpha dropped: the background is opaque).
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        let file = File::create(path).map_err(RenderError::io("creating", path))?;
        let png_err = |e: png::EncodingError| RenderError::Png {
            path: path.to_owned(),
            reason: e.to_string(),
        };
        let mut enc = png::Encoder::new(BufWriter::new(file), self.width, self.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::High);
        let mut w = enc.write_header().map_err(png_err)?;
        let rgb: Vec<u8> = self
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        w.write_image_data(&rgb).map_err(png_err)?;
        w.finish().map_err(png_err)
    }

    /// Writes the picture as an RGB JPEG of quality 90 (alpha dropped, as in the PNG).
    pub fn write_jpeg(&self, path: &Path) -> Result<(), RenderError> {
        use std::io::Write;
        let file = File::create(path).map_err(RenderError::io("creating", path))?;
        let jpeg_err = |reason: String| RenderError::Jpeg {
            path: path.to_owned(),
            reason,
        };
        let rgb: Vec<u8> = self
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let mut out = BufWriter::new(file);
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode(
                &rgb,
                self.width,
                self.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| jpeg_err(e.to_string()))?;
        out.flush().map_err(|e| jpeg_err(e.to_string()))
    }
}
