//! `touchdown detect --draw`: the markers found, outlined on the image, written as an RGB PNG.
//!
//! The picture is for a person checking a detection (and for the documentation's figures):
//! the grey image, each marker's four edges in green and its first corner (top-left of the
//! marker's canonical image) as a red dot, so that the corner order shows as well as the
//! outline. Lines are drawn at whole pixels, two pixels wide so that they stay visible when
//! the picture is shown smaller; the corners' sub-pixel values are in the text and JSON output.
//! A shrink factor (`--draw-scale`) averages blocks of pixels first: a noisy camera frame
//! compresses badly as PNG, and a picture for a web page need not be full size.

use std::path::Path;

use touchdown_formats::image_io::GrayFrame;

const EDGE: [u8; 3] = [0, 220, 0];
const FIRST_CORNER: [u8; 3] = [230, 0, 0];

/// An RGB copy of a grey frame to draw on.
struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn from_gray(frame: &GrayFrame) -> Self {
        let rgb = frame.pixels.iter().flat_map(|&g| [g, g, g]).collect();
        Canvas {
            width: frame.width,
            height: frame.height,
            rgb,
        }
    }

    /// Paints the 2x2 pixel block whose top-left pixel is nearest (x, y); outside the image,
    /// nothing.
    fn dab(&mut self, x: f32, y: f32, colour: [u8; 3]) {
        let (x0, y0) = ((x - 0.5).round(), (y - 0.5).round());
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            self.set(x0 + dx, y0 + dy, colour);
        }
    }

    fn set(&mut self, x: f32, y: f32, colour: [u8; 3]) {
        if !(x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32) {
            return;
        }
        let at = 3 * (y as usize * self.width + x as usize);
        if let Some(pixel) = self.rgb.get_mut(at..at + 3) {
            pixel.copy_from_slice(&colour);
        }
    }

    fn line(&mut self, from: [f32; 2], to: [f32; 2], colour: [u8; 3]) {
        let length = (to[0] - from[0]).hypot(to[1] - from[1]);
        if !length.is_finite() {
            return;
        }
        // Two samples per pixel of length: no gaps at any slope.
        let steps = (2.0 * length).ceil().clamp(1.0, 1e5) as usize;
        for k in 0..=steps {
            let t = k as f32 / steps as f32;
            let x = from[0] + t * (to[0] - from[0]);
            let y = from[1] + t * (to[1] - from[1]);
            self.dab(x, y, colour);
        }
    }

    fn dot(&mut self, centre: [f32; 2], radius: f32, colour: [u8; 3]) {
        let r = radius.ceil() as i32;
        for dy in -r..=r {
            for dx in -r..=r {
                let (fx, fy) = (dx as f32, dy as f32);
                if fx * fx + fy * fy <= radius * radius {
                    self.set((centre[0] + fx).round(), (centre[1] + fy).round(), colour);
                }
            }
        }
    }
}

/// The frame shrunk `factor` times in each direction, each pixel the mean of its block (the
/// last partial row and column of blocks dropped).
fn shrink(frame: &GrayFrame, factor: usize) -> GrayFrame {
    let factor = factor.max(1);
    let (width, height) = (frame.width / factor, frame.height / factor);
    let mut pixels = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let mut sum = 0u32;
            for row in frame
                .pixels
                .chunks(frame.width)
                .skip(y * factor)
                .take(factor)
            {
                let block = row.iter().skip(x * factor).take(factor);
                sum += block.map(|&g| u32::from(g)).sum::<u32>();
            }
            let count = (factor * factor) as u32;
            pixels.push(((sum + count / 2) / count) as u8);
        }
    }
    GrayFrame {
        width,
        height,
        pixels,
    }
}

/// A point of the full frame in the pixels of the frame shrunk `factor` times (pixel centres
/// at whole numbers in both: block k's centre is full-frame k * factor + (factor - 1) / 2).
fn shrunk_point(p: [f32; 2], factor: usize) -> [f32; 2] {
    let f = factor.max(1) as f32;
    let offset = (f - 1.0) / 2.0;
    [(p[0] - offset) / f, (p[1] - offset) / f]
}

/// The frame, shrunk `factor` times, with each quad (corners in the contract's order and
/// pixel convention, in the full frame's pixels) outlined.
fn drawn(frame: &GrayFrame, quads: &[[[f32; 2]; 4]], factor: usize) -> Canvas {
    let small;
    let frame = if factor > 1 {
        small = shrink(frame, factor);
        &small
    } else {
        frame
    };
    let quads: Vec<[[f32; 2]; 4]> = quads
        .iter()
        .map(|q| q.map(|p| shrunk_point(p, factor)))
        .collect();
    let mut canvas = Canvas::from_gray(frame);
    for quad in &quads {
        for k in 0..4 {
            canvas.line(quad[k], quad[(k + 1) % 4], EDGE);
        }
    }
    // Dots last, so that no edge covers them.
    let radius = (frame.width.max(frame.height) as f32 / 200.0).max(2.0);
    for quad in &quads {
        canvas.dot(quad[0], radius, FIRST_CORNER);
    }
    canvas
}

/// Writes `frame`, shrunk `factor` times (1: full size), with `quads` outlined to `path` as
/// an RGB PNG.
pub fn write_png(
    path: &Path,
    frame: &GrayFrame,
    quads: &[[[f32; 2]; 4]],
    factor: usize,
) -> Result<(), String> {
    let canvas = drawn(frame, quads, factor);
    image::save_buffer(
        path,
        &canvas.rgb,
        canvas.width as u32,
        canvas.height as u32,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixel(canvas: &Canvas, x: usize, y: usize) -> [u8; 3] {
        let at = 3 * (y * canvas.width + x);
        [canvas.rgb[at], canvas.rgb[at + 1], canvas.rgb[at + 2]]
    }

    #[test]
    fn outlines_the_quad_and_marks_its_first_corner() {
        let frame = GrayFrame::filled(40, 30, 128);
        let quad = [[10.0, 5.0], [30.0, 5.0], [30.0, 25.0], [10.0, 25.0]];
        let canvas = drawn(&frame, &[quad], 1);
        // An edge's middle is green, the first corner red, the inside and outside untouched.
        assert_eq!(pixel(&canvas, 20, 5), EDGE);
        assert_eq!(pixel(&canvas, 30, 15), EDGE);
        assert_eq!(pixel(&canvas, 10, 5), FIRST_CORNER);
        assert_eq!(pixel(&canvas, 30, 25), EDGE);
        assert_eq!(pixel(&canvas, 20, 15), [128; 3]);
        assert_eq!(pixel(&canvas, 2, 2), [128; 3]);
    }

    #[test]
    fn a_quad_partly_outside_the_image_is_clipped() {
        let frame = GrayFrame::filled(20, 20, 0);
        let quad = [[-50.0, -50.0], [50.0, -50.0], [50.0, 10.0], [-50.0, 10.0]];
        let canvas = drawn(&frame, &[quad, [[f32::NAN; 2]; 4]], 1);
        assert_eq!(pixel(&canvas, 10, 10), EDGE);
        assert_eq!(canvas.rgb.len(), 20 * 20 * 3);
    }

    #[test]
    fn shrinking_averages_blocks_and_keeps_the_outline_on_the_marker() {
        // A 2x2 checker of 2-pixel blocks shrinks to single pixels of each block's level.
        let mut frame = GrayFrame::filled(5, 4, 0);
        for (k, g) in frame.pixels.iter_mut().enumerate() {
            let (x, y) = (k % 5, k / 5);
            *g = if (x / 2 + y / 2) % 2 == 0 { 200 } else { 10 };
        }
        let small = shrink(&frame, 2);
        assert_eq!((small.width, small.height), (2, 2));
        assert_eq!(small.pixels, [200, 10, 10, 200]);
        // Full-frame pixel centres 0.5 and 2.5 (between the pixels of the first and second
        // blocks) are the shrunk frame's pixels 0 and 1.
        assert_eq!(shrunk_point([0.5, 2.5], 2), [0.0, 1.0]);
        assert_eq!(shrunk_point([7.0, 4.0], 1), [7.0, 4.0]);
        let frame = GrayFrame::filled(80, 60, 128);
        let quad = [[20.5, 10.5], [60.5, 10.5], [60.5, 50.5], [20.5, 50.5]];
        let canvas = drawn(&frame, &[quad], 2);
        assert_eq!((canvas.width, canvas.height), (40, 30));
        assert_eq!(pixel(&canvas, 20, 5), EDGE);
        assert_eq!(pixel(&canvas, 10, 5), FIRST_CORNER);
        assert_eq!(pixel(&canvas, 20, 15), [128; 3]);
    }
}
