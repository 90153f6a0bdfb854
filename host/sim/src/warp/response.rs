//! The warp renderer's sensor: from radiance to 8-bit grey levels the way a sensor's signal
//! chain does it, with its own noise generator and a DSP's response.
//!
//! 1. Exposure, flare and the full well as the scenario's [`Sensor`] says (its exposure mode,
//!    sensitivity, gain): the photometry is the scenario's, so both renderers put paper and
//!    grass at about the same levels.
//! 2. Noise: shot and read noise in one Gaussian of variance `electrons + read^2`, drawn
//!    from a SplitMix64 stream seeded per row (so threads cannot change the bytes) as the
//!    sum of four 16-bit uniforms (Irwin-Hall, scaled to unit variance; tails cut at 3.5
//!    sigma): a few integer operations per pixel, no logarithm or sine.
//! 3. Gain and black level to grey levels, then the DSP: a gamma curve (through a table)
//!    and a 3x3 sharpening kernel (`(1 + s)` times the pixel less `s` times its 3x3 mean),
//!    then rounding and clipping to 0..255.
//! 4. Optionally, block compression as a sensor module that streams JPEG loses detail: each
//!    8x8 block's cosine transform rounded to steps growing with the frequency.

use crate::sensor::Sensor;

/// The DSP's response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Response {
    /// Gamma: output = black + (255 - black) x (linear / (255 - black))^(1 / gamma) (1 is
    /// linear).
    pub gamma: f64,
    /// Sharpening strength `s` of the 3x3 kernel (0 none).
    pub sharpen: f64,
    /// Shot and read noise on (off: the exact mean signal, for tests).
    pub noise: bool,
    /// Block compression like a JPEG encoder's at this quality (1..100; `None` none): each
    /// whole 8x8 block's cosine transform rounded to steps growing with the frequency.
    pub block_quality: Option<u8>,
}

impl Response {
    /// Linear, unsharpened, noiseless.
    pub fn linear() -> Self {
        Response {
            gamma: 1.0,
            sharpen: 0.0,
            noise: false,
            block_quality: None,
        }
    }

    /// A small camera module's DSP: linear, mild sharpening, noise.
    pub fn board_camera() -> Self {
        Response {
            gamma: 1.0,
            sharpen: 0.3,
            noise: true,
            block_quality: None,
        }
    }
}

/// Entries of the gamma table over 0..255 - black (linear between them).
const GAMMA_STEPS: usize = 1024;

/// A SplitMix64 stream.
struct SplitMix(u64);

impl SplitMix {
    #[inline]
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// About a standard normal deviate: four 16-bit uniforms summed, centred and scaled to
    /// unit variance.
    #[inline]
    fn normal(&mut self) -> f32 {
        let r = self.next();
        let sum = (r & 0xffff) + ((r >> 16) & 0xffff) + ((r >> 32) & 0xffff) + (r >> 48);
        // Each uniform has variance 65536^2 / 12 (to 1e-9), four of them 65536^2 / 3.
        const SCALE: f32 = 1.732_050_8 / 65536.0;
        (sum as f32 - 131_070.0) * SCALE
    }
}

/// Turns radiance (vignetting and PSFs applied) into grey levels.
pub(crate) fn develop(
    radiance: &[f32],
    width: usize,
    height: usize,
    sensor: &Sensor,
    response: &Response,
    seed: u64,
) -> Vec<u8> {
    let n = width * height;
    let radiance = radiance.get(..n).unwrap_or(radiance);
    let scale = sensor.electrons_per_radiance(radiance) as f32;
    let lift = if sensor.flare > 0.0 {
        let mean = radiance.iter().map(|&v| f64::from(v)).sum::<f64>() / n.max(1) as f64;
        (sensor.flare * mean * f64::from(scale)) as f32
    } else {
        0.0
    };
    let full = sensor.full_well_e as f32;
    let read2 = (sensor.read_noise_e * sensor.read_noise_e) as f32;
    let noisy = response.noise && (sensor.read_noise_e > 0.0 || sensor.full_well_e.is_finite());
    let grey_per_electron = sensor.grey_per_electron() as f32;
    let black = sensor.black_level as f32;
    let mut grey = vec![0.0f32; n];
    for (y, (out, row)) in grey
        .chunks_mut(width.max(1))
        .zip(radiance.chunks(width.max(1)))
        .enumerate()
    {
        let mut rng = SplitMix(crate::mix(seed, y as u64 + 1));
        for (o, &v) in out.iter_mut().zip(row) {
            let mut e = (v * scale + lift).clamp(0.0, full);
            if noisy {
                e += (e + read2).sqrt() * rng.normal();
            }
            *o = black + e * grey_per_electron;
        }
    }
    if response.gamma.is_finite() && response.gamma > 0.0 && response.gamma != 1.0 {
        apply_gamma(&mut grey, black, response.gamma);
    }
    let mut pixels = if response.sharpen.is_finite() && response.sharpen != 0.0 {
        sharpen(&grey, width, height, response.sharpen as f32)
    } else {
        grey.iter().map(|&v| quantise(v)).collect()
    };
    if let Some(quality) = response.block_quality {
        compress_blocks(&mut pixels, width, height, quality);
    }
    pixels
}

/// Side of a compression block, pixels.
const BLOCK: usize = 8;

/// Compresses an 8-bit image in place the way a JPEG encoder loses detail (a sensor module
/// that streams JPEG): each whole 8x8 block's cosine transform (DCT-II, orthonormal) is
/// rounded to steps that grow with the frequency, `step(u, v) = s (1 + (u + v) / 2)`, with
/// `s` from 0.5 at quality 100 to 50 at quality 1, and transformed back. The block's mean
/// keeps a step of `s` / 8 grey levels; a partial block at the right or bottom edge is kept
/// as it is. No entropy coding: only what the rounding loses.
pub(crate) fn compress_blocks(pixels: &mut [u8], width: usize, height: usize, quality: u8) {
    if width < BLOCK || height < BLOCK || pixels.len() < width * height {
        return;
    }
    let q = f32::from(quality.clamp(1, 100));
    let step = 0.5 + 49.5 * (100.0 - q) / 99.0;
    // basis[u][x] = c(u) cos((2x + 1) u pi / 16), orthonormal.
    let mut basis = [[0.0f32; BLOCK]; BLOCK];
    for (u, row) in basis.iter_mut().enumerate() {
        let c = if u == 0 { (1.0f32 / 8.0).sqrt() } else { 0.5 };
        for (x, b) in row.iter_mut().enumerate() {
            let angle = (2 * x + 1) as f32 * u as f32 * std::f32::consts::PI / 16.0;
            *b = c * angle.cos();
        }
    }
    let mut block = [[0.0f32; BLOCK]; BLOCK];
    let mut tmp = [[0.0f32; BLOCK]; BLOCK];
    for by in 0..height / BLOCK {
        for bx in 0..width / BLOCK {
            for (y, row) in block.iter_mut().enumerate() {
                let start = (by * BLOCK + y) * width + bx * BLOCK;
                for (x, v) in row.iter_mut().enumerate() {
                    *v = f32::from(pixels[start + x]) - 128.0;
                }
            }
            // Rows, then columns: F = B X B^T.
            transform(&block, &mut tmp, &basis, false);
            transform_columns(&tmp, &mut block, &basis, false);
            for (u, row) in block.iter_mut().enumerate() {
                for (v, c) in row.iter_mut().enumerate() {
                    let s = step * (1.0 + 0.5 * (u + v) as f32);
                    *c = (*c / s).round() * s;
                }
            }
            transform_columns(&block, &mut tmp, &basis, true);
            transform(&tmp, &mut block, &basis, true);
            for (y, row) in block.iter().enumerate() {
                let start = (by * BLOCK + y) * width + bx * BLOCK;
                for (x, &v) in row.iter().enumerate() {
                    pixels[start + x] = quantise(v + 128.0);
                }
            }
        }
    }
}

/// Along each row of `from`: forward (`out[y][u] = sum_x from[y][x] basis[u][x]`) or
/// inverse (`out[y][x] = sum_u from[y][u] basis[u][x]`).
fn transform(
    from: &[[f32; BLOCK]; BLOCK],
    out: &mut [[f32; BLOCK]; BLOCK],
    basis: &[[f32; BLOCK]; BLOCK],
    inverse: bool,
) {
    for (src, dst) in from.iter().zip(out.iter_mut()) {
        for (k, d) in dst.iter_mut().enumerate() {
            *d = (0..BLOCK)
                .map(|j| {
                    let b = if inverse { basis[j][k] } else { basis[k][j] };
                    src[j] * b
                })
                .sum();
        }
    }
}

/// Along each column of `from`, as [`transform`] along rows.
fn transform_columns(
    from: &[[f32; BLOCK]; BLOCK],
    out: &mut [[f32; BLOCK]; BLOCK],
    basis: &[[f32; BLOCK]; BLOCK],
    inverse: bool,
) {
    for col in 0..BLOCK {
        for k in 0..BLOCK {
            out[k][col] = (0..BLOCK)
                .map(|j| {
                    let b = if inverse { basis[j][k] } else { basis[k][j] };
                    from[j][col] * b
                })
                .sum();
        }
    }
}

/// Rounded and clipped to 0..255 (`as` truncates toward zero, the floor of a non-negative).
#[inline]
fn quantise(v: f32) -> u8 {
    // Through i32: the saturating float-to-u8 conversion is longer.
    (v.clamp(0.0, 255.0) + 0.5) as i32 as u8
}

fn apply_gamma(grey: &mut [f32], black: f32, gamma: f64) {
    let span = (255.0 - black).max(1.0);
    let table: Vec<f32> = (0..=GAMMA_STEPS)
        .map(|k| (k as f64 / GAMMA_STEPS as f64).powf(1.0 / gamma) as f32)
        .collect();
    let steps = GAMMA_STEPS as f32;
    for v in grey.iter_mut() {
        let t = ((*v - black) / span).clamp(0.0, 1.0) * steps;
        let k = (t as usize).min(GAMMA_STEPS - 1);
        let f = t - k as f32;
        let (a, b) = (table[k], table[k + 1]);
        let curved = black + span * (a + f * (b - a));
        // Below the black level the signal stays linear (the curve starts at black).
        if *v > black {
            *v = curved;
        }
    }
}

/// `(1 + s) v - s mean3x3(v)`, edges repeated, quantised.
fn sharpen(grey: &[f32], width: usize, height: usize, s: f32) -> Vec<u8> {
    if width == 0 || height == 0 {
        return Vec::new();
    }
    // Horizontal 3-sums, then vertical ones a row at a time.
    let mut h3 = vec![0.0f32; width * height];
    for (src, dst) in grey.chunks(width).zip(h3.chunks_mut(width)) {
        for x in 0..width {
            let l = src[x.saturating_sub(1)];
            let r = src[(x + 1).min(width - 1)];
            dst[x] = l + src[x] + r;
        }
    }
    let k = s / 9.0;
    let mut out = vec![0u8; width * height];
    for (y, (row, here)) in out.chunks_mut(width).zip(grey.chunks(width)).enumerate() {
        let up = &h3[y.saturating_sub(1) * width..][..width];
        let mid = &h3[y * width..][..width];
        let down = &h3[(y + 1).min(height - 1) * width..][..width];
        for x in 0..width {
            row[x] = quantise((1.0 + s) * here[x] - k * (up[x] + mid[x] + down[x]));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normals_have_unit_variance() {
        let mut rng = SplitMix(7);
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let z = f64::from(rng.normal());
            sum += z;
            sum2 += z * z;
        }
        let mean = sum / n as f64;
        let var = sum2 / n as f64 - mean * mean;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
            "{mean} {var}"
        );
    }
}
