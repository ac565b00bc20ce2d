//! The film: a width × height buffer of linear radiance, and (cargo feature `image`) its
//! atomic output as PNG (8-bit sRGB, clamped as CS184 does) or OpenEXR (linear 32-bit float)
//! through [`crate::fs::output`].

use crate::math::Vec3;
use std::path::{Path, PathBuf};

/// A linear RGB image; row 0 is the top row.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels in row-major order, top row first.
    pub pixels: Vec<Vec3>,
}

/// How to turn film values into 8-bit display values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// Linear radiance: clamp to `[0, 1]`, then the sRGB transfer curve.
    Srgb,
    /// Values are already display values in `[0, 1]` (normal maps, false colour).
    Display,
}

/// Why an image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// Creating, writing or renaming the file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The output path.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The encoder failed.
    #[error("cannot encode {path}: {message}")]
    Encode {
        /// The output path.
        path: PathBuf,
        /// What the encoder said.
        message: String,
    },
}

impl Film {
    /// A black film.
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, pixels: vec![Vec3::ZERO; width * height] }
    }

    /// The pixel at column `x`, row `y` (row 0 at the top).
    pub fn get(&self, x: usize, y: usize) -> Vec3 {
        self.pixels[y * self.width + x]
    }

    /// Mean of all pixels.
    pub fn mean(&self) -> Vec3 {
        self.pixels.iter().copied().sum::<Vec3>() / self.pixels.len().max(1) as f32
    }

    /// 8-bit RGB bytes, row-major, top row first.
    pub fn to_rgb8(&self, encoding: Encoding) -> Vec<u8> {
        let enc = |v: f32| -> u8 {
            let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
            let v = match encoding {
                Encoding::Srgb if v <= 0.003_130_8 => 12.92 * v,
                Encoding::Srgb => 1.055 * v.powf(1.0 / 2.4) - 0.055,
                Encoding::Display => v,
            };
            (v * 255.0 + 0.5) as u8
        };
        self.pixels.iter().flat_map(|p| [enc(p.x), enc(p.y), enc(p.z)]).collect()
    }

    /// Writes the film to `path`: OpenEXR (linear) when it ends in `.exr`, PNG otherwise.
    /// The file appears whole or not at all, and only a regular file (or nothing) at `path`
    /// is replaced ([`crate::fs::output`]).
    #[cfg(feature = "image")]
    pub fn write(&self, path: &Path, encoding: Encoding) -> Result<(), ImageError> {
        let bytes = self
            .encode(ImageFormat::of(path), encoding)
            .map_err(|message| ImageError::Encode { path: path.to_path_buf(), message })?;
        crate::fs::output::write_file(path, &bytes).map_err(ImageError::from)
    }

    /// The film as the bytes of a `format` file (PNG encoded with `encoding`; EXR linear).
    #[cfg(feature = "image")]
    pub fn encode(&self, format: ImageFormat, encoding: Encoding) -> Result<Vec<u8>, String> {
        match format {
            ImageFormat::Png => encode_png(self.width, self.height, &self.to_rgb8(encoding)),
            ImageFormat::Exr => {
                let img = exr::prelude::Image::from_channels(
                    (self.width, self.height),
                    exr::prelude::SpecificChannels::rgb(|p: exr::prelude::Vec2<usize>| {
                        let c = self.pixels[p.1 * self.width + p.0];
                        (c.x, c.y, c.z)
                    }),
                );
                use exr::prelude::WritableImage;
                let mut buf = std::io::Cursor::new(Vec::new());
                img.write().to_buffered(&mut buf).map_err(|e| e.to_string())?;
                Ok(buf.into_inner())
            }
        }
    }
}

/// The file formats a film is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// Linear 32-bit float OpenEXR.
    Exr,
}

impl ImageFormat {
    /// The file extensions raypack writes images in, with what each holds.
    pub const EXTENSIONS: [(&'static str, &'static str); 2] =
        [("png", "8-bit sRGB"), ("exr", "linear 32-bit float radiance")];

    /// EXR when `path` ends in `.exr` (any case), PNG otherwise.
    pub fn of(path: &Path) -> Self {
        if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) { Self::Exr } else { Self::Png }
    }

    /// The format `path`'s extension names, or `None` for a path without one or an extension
    /// raypack cannot write (`.jpg`): [`ImageFormat::of`] would write PNG bytes there.
    pub fn for_path(path: &Path) -> Option<Self> {
        match path.extension() {
            None => None,
            Some(e) if e.eq_ignore_ascii_case("png") => Some(Self::Png),
            Some(e) if e.eq_ignore_ascii_case("exr") => Some(Self::Exr),
            Some(_) => None,
        }
    }
}

impl From<crate::fs::output::OutputError> for ImageError {
    fn from(e: crate::fs::output::OutputError) -> Self {
        ImageError::Io { path: e.path, source: e.source }
    }
}

/// 8-bit RGB `rgb` (row-major, top row first) as the bytes of a PNG file.
#[cfg(feature = "image")]
pub fn encode_png(width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, width as u32, height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut w = enc.write_header().map_err(|e| e.to_string())?;
    w.write_image_data(rgb).map_err(|e| e.to_string())?;
    w.finish().map_err(|e| e.to_string())?;
    Ok(out)
}

/// Writes 8-bit RGB `rgb` (row-major, top row first) as a PNG, atomically.
#[cfg(feature = "image")]
pub fn write_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<(), ImageError> {
    let bytes =
        encode_png(width, height, rgb).map_err(|message| ImageError::Encode { path: path.to_path_buf(), message })?;
    crate::fs::output::write_file(path, &bytes).map_err(ImageError::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_clamps_and_curves() {
        let mut f = Film::new(3, 1);
        f.pixels = vec![Vec3::splat(-1.0), Vec3::splat(0.5), Vec3::splat(7.0)];
        let b = f.to_rgb8(Encoding::Srgb);
        assert_eq!((b[0], b[3], b[6]), (0, 188, 255));
        assert_eq!(f.to_rgb8(Encoding::Display)[3], 128);
    }

    #[test]
    #[cfg(feature = "image")]
    fn unwritable_path_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("raypack-film-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = dir.join("no/such/dir/out.png");
        assert!(Film::new(2, 2).write(&missing, Encoding::Srgb).is_err());
        let ok = dir.join("out.png");
        Film::new(2, 2).write(&ok, Encoding::Srgb).unwrap();
        Film::new(2, 2).write(&dir.join("out.exr"), Encoding::Srgb).unwrap();
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "no temporary files left: {names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
