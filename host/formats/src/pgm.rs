//! The frames of a recording: 8-bit binary PGM (P5), one image per file, maxval 255, as the
//! contract fixes them (`docs/interfaces.md`).
//!
//! The reader is strict (one image, exactly `width x height` pixel bytes, nothing after), so
//! a truncated or damaged frame is reported instead of decoded as something else; the writer
//! writes exactly what the reader accepts.

use std::path::Path;

use crate::image_io::GrayFrame;

/// Writes a frame as binary PGM (P5).
pub fn save_pgm(path: &Path, frame: &GrayFrame) -> std::io::Result<()> {
    let mut out = format!("P5\n{} {}\n255\n", frame.width, frame.height).into_bytes();
    out.extend_from_slice(&frame.pixels);
    std::fs::write(path, out)
}

/// Parses an 8-bit binary PGM (P5) strictly: one image, maxval 255, exactly `width x
/// height` pixel bytes, and the size `expected` when given; the error is the reason alone.
pub fn parse_pgm(bytes: &[u8], expected: Option<(usize, usize)>) -> Result<GrayFrame, String> {
    if bytes.get(..2) != Some(b"P5") {
        return Err("not a binary PGM file (it must start with `P5`)".into());
    }
    let mut pos = 2;
    let mut numbers = [0usize; 3];
    for (k, name) in ["width", "height", "maxval"].iter().enumerate() {
        // Whitespace and `#` comments separate the header fields.
        loop {
            match bytes.get(pos) {
                Some(b) if b.is_ascii_whitespace() => pos += 1,
                Some(b'#') => {
                    while bytes.get(pos).is_some_and(|&b| b != b'\n') {
                        pos += 1;
                    }
                }
                _ => break,
            }
        }
        let start = pos;
        while bytes.get(pos).is_some_and(u8::is_ascii_digit) {
            pos += 1;
        }
        if start == pos {
            return Err(match bytes.get(pos) {
                None => format!("truncated header: no {name}"),
                Some(_) => format!("bad header: {name} is not a number"),
            });
        }
        let text = std::str::from_utf8(bytes.get(start..pos).unwrap_or(&[])).unwrap_or("");
        numbers[k] = text
            .parse()
            .map_err(|_| format!("bad header: {name} `{text}` is too large"))?;
    }
    let [width, height, maxval] = numbers;
    if maxval != 255 {
        return Err(format!(
            "maxval {maxval}: only 8-bit frames (maxval 255) are supported"
        ));
    }
    if width == 0
        || height == 0
        || width > touchdown_core::image::MAX_DIMENSION
        || height > touchdown_core::image::MAX_DIMENSION
    {
        return Err(format!("unsupported size {width}x{height}"));
    }
    match bytes.get(pos) {
        Some(b) if b.is_ascii_whitespace() => pos += 1,
        Some(_) => return Err("bad header: no whitespace after maxval".into()),
        None => return Err("truncated: no pixel data".into()),
    }
    let needed = width * height;
    let data = bytes.get(pos..).unwrap_or(&[]);
    if data.len() < needed {
        return Err(format!(
            "truncated: a {width}x{height} frame needs {needed} pixel bytes, the file has {}",
            data.len()
        ));
    }
    if data.len() > needed {
        return Err(format!(
            "{} unexpected bytes after the {width}x{height} frame",
            data.len() - needed
        ));
    }
    if let Some((w, h)) = expected {
        if (w, h) != (width, height) {
            return Err(format!(
                "frame is {width}x{height} but camera.toml says {w}x{h}"
            ));
        }
    }
    Ok(GrayFrame {
        width,
        height,
        pixels: data.to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pgm_header_with_comment() {
        let mut bytes = b"P5\n# hello\n2 1\n255\n".to_vec();
        bytes.extend_from_slice(&[7, 9]);
        let f = parse_pgm(&bytes, Some((2, 1))).unwrap();
        assert_eq!(f.pixels, vec![7, 9]);
        assert!(parse_pgm(&bytes[..bytes.len() - 1], None)
            .unwrap_err()
            .starts_with("truncated"));
        assert!(parse_pgm(b"P5\n2 1\n65535\n\0\0\0\0", None)
            .unwrap_err()
            .contains("maxval"));
        assert!(parse_pgm(&bytes, Some((3, 1)))
            .unwrap_err()
            .contains("camera.toml"));
        assert!(parse_pgm(b"P2\n", None).is_err());
        assert!(parse_pgm(b"P5\n2", None).unwrap_err().contains("truncated"));
    }
}
