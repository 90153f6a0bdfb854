//! Benchmark frames: committed PGMs (rendered by the simulator) and generated patterns.

/// Pixels of the largest frame (VGA).
const MAX_PIXELS: usize = 640 * 480;

/// Where a frame's pixels come from.
pub enum Source {
    /// A binary PGM (P5, 8-bit) of exactly the frame's size.
    Pgm(&'static [u8]),
    /// One grey level everywhere.
    Flat(u8),
    /// Uniform random grey levels (xorshift32 from `seed`).
    Noise { seed: u32 },
    /// A checkerboard of `cell`-pixel squares, grey 40 and 215.
    Checker { cell: usize },
    /// Dark `side`-pixel squares (grey 30) every `pitch` pixels on light paper (grey 220).
    Squares { side: usize, pitch: usize },
    /// Marker look-alikes every `pitch` pixels: a `side`-pixel square of 8 x 8 cells, the
    /// outer ring black, the 6 x 6 inside random black and white (xorshift32 from `seed`),
    /// on white paper. Each has a marker's border, margin and busy interior, so the detector
    /// refines and reads every one (the costliest path per candidate) before the code
    /// look-up turns it down (no code of the default families).
    Tags {
        side: usize,
        pitch: usize,
        seed: u32,
    },
}

/// The frame buffer: one VGA frame, aligned like the firmware's (32-byte cache lines).
#[repr(C, align(32))]
pub struct FrameBuffer([u8; MAX_PIXELS]);

impl FrameBuffer {
    /// A zeroed buffer (for a `static`).
    pub const fn new() -> Self {
        FrameBuffer([0; MAX_PIXELS])
    }

    /// Writes a `width` x `height` frame from `source` and returns its pixels.
    pub fn fill(
        &mut self,
        width: usize,
        height: usize,
        source: &Source,
    ) -> Result<&[u8], &'static str> {
        let pixels = self
            .0
            .get_mut(..width * height)
            .ok_or("larger than the frame buffer")?;
        match *source {
            Source::Pgm(file) => pixels.copy_from_slice(pgm_pixels(file, width, height)?),
            Source::Flat(level) => pixels.fill(level),
            Source::Noise { seed } => {
                let mut state = seed.max(1);
                for p in pixels.iter_mut() {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    *p = (state >> 24) as u8;
                }
            }
            Source::Checker { cell } => {
                let cell = cell.max(1);
                for (y, row) in pixels.chunks_exact_mut(width).enumerate() {
                    for (x, p) in row.iter_mut().enumerate() {
                        *p = if (x / cell + y / cell) % 2 == 0 {
                            40
                        } else {
                            215
                        };
                    }
                }
            }
            Source::Squares { side, pitch } => {
                let pitch = pitch.max(1);
                let side = side.clamp(1, pitch);
                // Whole squares only, the grid centred in the frame.
                let span = |len: usize| {
                    let n = len.saturating_sub(side) / pitch + 1;
                    let extent = (n - 1) * pitch + side;
                    (len.saturating_sub(extent) / 2, extent)
                };
                let ((x0, x_extent), (y0, y_extent)) = (span(width), span(height));
                let dark_at = |v: usize, v0: usize, extent: usize| {
                    v >= v0 && v - v0 < extent && (v - v0) % pitch < side
                };
                for (y, row) in pixels.chunks_exact_mut(width).enumerate() {
                    let dark_row = dark_at(y, y0, y_extent);
                    for (x, p) in row.iter_mut().enumerate() {
                        let dark = dark_row && dark_at(x, x0, x_extent);
                        *p = if dark { 30 } else { 220 };
                    }
                }
            }
            Source::Tags { side, pitch, seed } => {
                let pitch = pitch.max(1);
                let cell = (side / 8).max(1);
                let side = cell * 8;
                pixels.fill(235);
                let mut state = seed.max(1);
                let (across, down) = (width / pitch, height / pitch);
                let margin = (pitch.saturating_sub(side)) / 2;
                for ty in 0..down {
                    for tx in 0..across {
                        let (x0, y0) = (tx * pitch + margin, ty * pitch + margin);
                        for cy in 0..8 {
                            for cx in 0..8 {
                                let border = cx == 0 || cy == 0 || cx == 7 || cy == 7;
                                state ^= state << 13;
                                state ^= state >> 17;
                                state ^= state << 5;
                                let black = border || state & 1 == 1;
                                if !black {
                                    continue;
                                }
                                for y in y0 + cy * cell..y0 + (cy + 1) * cell {
                                    if let Some(row) = pixels.get_mut(y * width..(y + 1) * width) {
                                        let (a, b) = (x0 + cx * cell, x0 + (cx + 1) * cell);
                                        if let Some(run) = row.get_mut(a..b.min(width)) {
                                            run.fill(25);
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(pixels)
    }
}

/// The pixels of a binary PGM (`P5 <width> <height> 255`, single whitespace after the
/// maxval), checked against the expected size.
fn pgm_pixels(file: &[u8], width: usize, height: usize) -> Result<&[u8], &'static str> {
    let mut fields = [0usize; 3];
    let rest = file.strip_prefix(b"P5").ok_or("not a binary PGM")?;
    let mut pos = 0;
    for field in fields.iter_mut() {
        while rest.get(pos).is_some_and(|b| b.is_ascii_whitespace()) {
            pos += 1;
        }
        let start = pos;
        while let Some(b) = rest.get(pos).filter(|b| b.is_ascii_digit()) {
            *field = *field * 10 + usize::from(b - b'0');
            pos += 1;
        }
        if pos == start {
            return Err("bad PGM header");
        }
    }
    if fields != [width, height, 255] {
        return Err("PGM of another size or depth");
    }
    // One whitespace byte separates the header from the pixels.
    rest.get(pos + 1..)
        .filter(|pixels| pixels.len() == width * height)
        .ok_or("PGM pixel data of the wrong length")
}
