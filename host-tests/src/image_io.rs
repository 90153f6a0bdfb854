//! Reading and writing grey frames (PNG, PGM, JPEG; colour is converted to grey).

use std::fmt;
use std::path::{Path, PathBuf};

use touchdown_core::image::GrayImage;

/// An owned 8-bit grey frame, rows packed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GrayFrame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` bytes, row-major.
    pub pixels: Vec<u8>,
}

impl GrayFrame {
    /// A frame filled with one grey level.
    pub fn filled(width: usize, height: usize, level: u8) -> Self {
        GrayFrame {
            width,
            height,
            pixels: vec![level; width * height],
        }
    }

    /// The core's view of the frame.
    pub fn view(&self) -> GrayImage<'_> {
        GrayImage::new(&self.pixels, self.width, self.height)
            .expect("GrayFrame invariant: pixels.len() == width * height, dimensions in range")
    }
}

/// An image file could not be read.
#[derive(Debug)]
pub struct ImageLoadError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong, one line.
    pub reason: String,
}

impl fmt::Display for ImageLoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.reason)
    }
}

impl std::error::Error for ImageLoadError {}

/// Reads a PNG, PGM/PPM or JPEG file as grey (ITU-R 601 luma for colour images).
pub fn load_gray(path: &Path) -> Result<GrayFrame, ImageLoadError> {
    let fail = |reason: String| ImageLoadError {
        path: path.to_path_buf(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    let decoded = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| fail(e.to_string()))?
        .decode()
        .map_err(|e| fail(format!("not a readable PNG, PGM or JPEG image ({e})")))?;
    let luma = decoded.to_luma8();
    let (width, height) = (luma.width() as usize, luma.height() as usize);
    if width == 0
        || height == 0
        || width > touchdown_core::image::MAX_DIMENSION
        || height > touchdown_core::image::MAX_DIMENSION
    {
        return Err(fail(format!("unsupported size {width}x{height}")));
    }
    Ok(GrayFrame {
        width,
        height,
        pixels: luma.into_raw(),
    })
}

/// Writes a frame as binary PGM (P5).
pub fn save_pgm(path: &Path, frame: &GrayFrame) -> std::io::Result<()> {
    let mut out = format!("P5\n{} {}\n255\n", frame.width, frame.height).into_bytes();
    out.extend_from_slice(&frame.pixels);
    std::fs::write(path, out)
}

/// Writes a frame as PNG.
pub fn save_png(path: &Path, frame: &GrayFrame) -> Result<(), ImageLoadError> {
    image::save_buffer(
        path,
        &frame.pixels,
        frame.width as u32,
        frame.height as u32,
        image::ExtendedColorType::L8,
    )
    .map_err(|e| ImageLoadError {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}
