//! Reading and writing grey frames (PNG, PGM, JPEG; colour is converted to grey). The strict
//! PGM of recordings, reader and writer, is [`crate::pgm`].

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
    let bytes = std::fs::read(path).map_err(|e| ImageLoadError {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    decode_gray(&bytes).map_err(|reason| ImageLoadError {
        path: path.to_path_buf(),
        reason,
    })
}

/// Decodes the bytes of a PNG, PGM/PPM or JPEG file as grey; the error is one line.
///
/// The size is read from the header and checked before any pixel is decoded, so a
/// 20000x20000 file is refused at once instead of after allocating gigabytes, and the
/// decoder's own limits stop a header that lies. A JPEG must reach its end-of-image marker:
/// the JPEG decoder fills a cut-off file with grey instead of failing, and a third of a
/// photo that silently reads as "no markers" is worse than an error.
pub fn decode_gray(bytes: &[u8]) -> Result<GrayFrame, String> {
    const MAX: usize = touchdown_core::image::MAX_DIMENSION;
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())
    };
    let unreadable = |e: image::ImageError| format!("not a readable PNG, PGM or JPEG image ({e})");
    let format = reader()?.format();
    let (width, height) = reader()?.into_dimensions().map_err(unreadable)?;
    let (width, height) = (width as usize, height as usize);
    if width == 0 || height == 0 || width > MAX || height > MAX {
        return Err(format!(
            "image is {width}x{height} pixels; touchdown reads images of 1x1 to {MAX}x{MAX}"
        ));
    }
    if format == Some(image::ImageFormat::Jpeg) && !jpeg_is_complete(bytes) {
        return Err(
            "truncated JPEG: the file ends before the image does (no end-of-image marker)".into(),
        );
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX as u32);
    limits.max_image_height = Some(MAX as u32);
    let mut decoder = reader()?;
    decoder.limits(limits);
    let luma = decoder.decode().map_err(unreadable)?.to_luma8();
    Ok(GrayFrame {
        width: luma.width() as usize,
        height: luma.height() as usize,
        pixels: luma.into_raw(),
    })
}

/// Whether a JPEG stream runs from its start-of-image to its end-of-image marker.
///
/// Walks the marker segments by their lengths (so an EXIF thumbnail, a whole JPEG inside an
/// APP1 segment, is skipped with its own end marker) and, after each start-of-scan, the
/// entropy-coded data, where 0xFF is only ever followed by a stuffed 0x00, a restart marker
/// or the next marker.
pub fn jpeg_is_complete(bytes: &[u8]) -> bool {
    const SOI: u8 = 0xD8;
    const EOI: u8 = 0xD9;
    const SOS: u8 = 0xDA;
    if bytes.get(..2) != Some(&[0xFF, SOI]) {
        return false;
    }
    let mut at = 2;
    let mut in_scan = false;
    while let (Some(&byte), Some(&marker)) = (bytes.get(at), bytes.get(at + 1)) {
        if byte != 0xFF {
            if !in_scan {
                return false;
            }
            at += 1;
            continue;
        }
        match marker {
            EOI => return true,
            // A fill byte before a marker.
            0xFF => at += 1,
            // Stuffed 0xFF in scan data, restart markers, TEM: no length follows.
            0x00 | 0xD0..=0xD7 | 0x01 => at += 2,
            _ => {
                let Some(&[high, low]) = bytes.get(at + 2..at + 4) else {
                    return false;
                };
                at += 2 + usize::from(u16::from_be_bytes([high, low]));
                in_scan = marker == SOS;
            }
        }
    }
    false
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

#[cfg(test)]
mod tests {
    use super::*;
    use image::ImageEncoder;

    /// A JPEG of a horizontal ramp, as an encoder writes it.
    fn ramp_jpeg(width: u32, height: u32) -> Vec<u8> {
        let pixels: Vec<u8> = (0..width * height).map(|i| (i % width) as u8).collect();
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
            .encode(&pixels, width, height, image::ExtendedColorType::L8)
            .expect("encode");
        bytes
    }

    #[test]
    fn complete_jpeg_decodes() {
        let frame = decode_gray(&ramp_jpeg(64, 48)).expect("a whole JPEG");
        assert_eq!((frame.width, frame.height), (64, 48));
    }

    #[test]
    fn truncated_jpeg_is_an_error_at_every_cut() {
        let bytes = ramp_jpeg(64, 48);
        for cut in [
            bytes.len() / 3,
            bytes.len() / 2,
            bytes.len() - 2,
            bytes.len() - 1,
        ] {
            let err = decode_gray(&bytes[..cut]).expect_err("a cut-off JPEG");
            assert!(
                err.contains("truncated JPEG") || err.contains("not a readable"),
                "cut at {cut}: {err}"
            );
        }
    }

    #[test]
    fn thumbnail_end_marker_does_not_hide_a_truncated_photo() {
        // SOI, an APP1 segment holding a whole small JPEG (as EXIF thumbnails are), then the
        // photo's own segments cut off in its scan data.
        let thumbnail = ramp_jpeg(8, 8);
        let photo = ramp_jpeg(64, 48);
        let mut bytes = vec![0xFF, 0xD8, 0xFF, 0xE1];
        bytes.extend_from_slice(&u16::try_from(thumbnail.len() + 2).unwrap().to_be_bytes());
        bytes.extend_from_slice(&thumbnail);
        let photo_start = bytes.len();
        bytes.extend_from_slice(&photo[2..]);
        assert!(jpeg_is_complete(&bytes), "the whole file is complete");
        assert!(!jpeg_is_complete(&bytes[..photo_start + photo.len() / 2]));
        assert!(decode_gray(&bytes).is_ok());
    }

    #[test]
    fn oversized_image_is_refused_from_its_header() {
        let width = 20_000u32;
        let mut bytes = Vec::new();
        image::codecs::png::PngEncoder::new(&mut bytes)
            .write_image(
                &vec![0u8; width as usize],
                width,
                1,
                image::ExtendedColorType::L8,
            )
            .expect("encode");
        let err = decode_gray(&bytes).expect_err("wider than MAX_DIMENSION");
        assert_eq!(
            err,
            "image is 20000x1 pixels; touchdown reads images of 1x1 to 8192x8192"
        );
    }

    #[test]
    fn truncated_png_and_pgm_are_errors() {
        let frame = GrayFrame::filled(32, 32, 200);
        let mut png = Vec::new();
        image::codecs::png::PngEncoder::new(&mut png)
            .write_image(&frame.pixels, 32, 32, image::ExtendedColorType::L8)
            .expect("encode");
        assert!(decode_gray(&png[..png.len() / 2]).is_err());
        let mut pgm = b"P5\n32 32\n255\n".to_vec();
        pgm.extend_from_slice(&frame.pixels[..500]);
        assert!(decode_gray(&pgm).is_err());
    }
}
