//! Pixels of a scene: the ground painted, each marker composited over it by area sampling,
//! the optics' blur, and the rounding to 8 bits (the steps of the [`super`] docs).
//!
//! Split from the scene description so that the sampling code, the part that decides how
//! exact an edge is, reads on its own.

use touchdown_core::geometry::Point;

use super::{Background, FrameOptions, MarkerTruth, PinholeCamera, SceneMarker};
use crate::math::{apply_homography, invert, mul, Mat3};
use crate::noise::ValueNoise;

/// Grid coordinates (col, row in cells from the grid's top-left corner) to pixels.
pub(super) fn grid_to_image(marker: &SceneMarker, camera: &PinholeCamera) -> Mat3 {
    let n = marker.pattern.grid as f64;
    let cell = marker.size / marker.pattern.edge_cells() as f64;
    let half = 0.5 * n * cell;
    // Plane x grows with the column, plane y (up) shrinks with the row.
    let grid_to_plane = [[cell, 0.0, -half], [0.0, -cell, half], [0.0, 0.0, 1.0]];
    mul(&marker.pose.homography(camera), &grid_to_plane)
}

pub(super) fn truth_of(g: &Mat3, marker: &SceneMarker) -> MarkerTruth {
    let n = marker.pattern.grid as f64;
    let b = marker.pattern.border_ring as f64;
    let at = |col: f64, row: f64| {
        apply_homography(g, col, row)
            .map(|(x, y)| Point::new(x as f32, y as f32))
            .unwrap_or(Point::new(f32::NAN, f32::NAN))
    };
    MarkerTruth {
        corners: [at(b, b), at(n - b, b), at(n - b, n - b), at(b, n - b)],
        center: at(0.5 * n, 0.5 * n),
        grid_to_image: *g,
    }
}

pub(super) fn paint_background(
    buffer: &mut [f32],
    w: usize,
    h: usize,
    background: &Background,
    seed: u64,
) {
    match *background {
        Background::Flat(level) => buffer.fill(level),
        Background::Texture {
            mean,
            amplitude,
            scale_px,
        } => {
            let texture = ValueNoise::new(seed, scale_px);
            for y in 0..h {
                for x in 0..w {
                    let v = mean + amplitude * texture.at(x as f64, y as f64) as f32;
                    if let Some(p) = buffer.get_mut(y * w + x) {
                        *p = v;
                    }
                }
            }
        }
    }
}

/// Draws one marker over `buffer` with area sampling (see the module docs).
pub(super) fn composite_marker(
    buffer: &mut [f32],
    w: usize,
    h: usize,
    marker: &SceneMarker,
    g: &Mat3,
    options: &FrameOptions,
) {
    let Some(inverse) = invert(g) else {
        return;
    };
    let pattern = &marker.pattern;
    let n = pattern.grid as f64;
    let lo = -marker.margin_cells.max(0.0);
    let hi = n - lo;
    let level = |white: bool| if white { options.white } else { options.black };
    // Level of a grid point, or None off the paper.
    let sample = |col: f64, row: f64| -> Option<f32> {
        if !(col >= lo && col < hi && row >= lo && row < hi) {
            return None;
        }
        if col >= 0.0 && row >= 0.0 && col < n && row < n {
            Some(level(pattern.is_white(row as usize, col as usize)))
        } else {
            Some(options.white)
        }
    };
    // A whole integer cell is uniform when it lies entirely on or entirely off the paper.
    let uniform_cell = |i: f64, j: f64| -> Option<Option<f32>> {
        let off = i + 1.0 <= lo || i >= hi || j + 1.0 <= lo || j >= hi;
        let on = i >= lo && i + 1.0 <= hi && j >= lo && j + 1.0 <= hi;
        if off {
            Some(None)
        } else if on {
            Some(sample(i + 0.5, j + 0.5))
        } else {
            None
        }
    };

    let Some((x0, x1, y0, y1)) = paper_bbox(g, lo, hi, w, h) else {
        return;
    };
    let s = options.supersampling.max(1);
    // Sub-sample (i, j) sits in stratum (i, j) of an s x s grid, shifted inside it so that all
    // s^2 samples have distinct x and distinct y ("n-rooks"): an axis-aligned edge then sees
    // s^2 coverage levels instead of s, so its rendered position is off by at most 1/(2 s^2)
    // pixel (1/128 for s = 8) rather than 1/(2 s).
    let fine = 1.0 / (s * s) as f64;
    let mut top: Vec<Option<(f64, f64)>> = Vec::with_capacity(x1 - x0 + 2);
    let mut bottom: Vec<Option<(f64, f64)>> = Vec::with_capacity(x1 - x0 + 2);
    let map_row = |out: &mut Vec<Option<(f64, f64)>>, y: f64| {
        out.clear();
        for x in x0..=x1 + 1 {
            out.push(apply_homography(&inverse, x as f64 - 0.5, y));
        }
    };
    map_row(&mut top, y0 as f64 - 0.5);
    for y in y0..=y1 {
        map_row(&mut bottom, y as f64 + 0.5);
        for x in x0..=x1 {
            let k = x - x0;
            let corners = [top[k], top[k + 1], bottom[k], bottom[k + 1]];
            let Some(pixel) = buffer.get_mut(y * w + x) else {
                continue;
            };
            // Fast path: the footprint's image is the convex hull of its mapped corners (all
            // in front of the camera), so four corners in one uniform cell mean a uniform pixel.
            if let [Some(a), Some(b), Some(c), Some(d)] = corners {
                let (i, j) = (a.0.floor(), a.1.floor());
                if [b, c, d]
                    .iter()
                    .all(|p| p.0.floor() == i && p.1.floor() == j)
                {
                    if let Some(value) = uniform_cell(i, j) {
                        if let Some(v) = value {
                            *pixel = v;
                        }
                        continue;
                    }
                }
            }
            let mut sum = 0.0f64;
            let mut covered = 0usize;
            for sy in 0..s {
                for sx in 0..s {
                    let px = x as f64 - 0.5 + ((sx * s + sy) as f64 + 0.5) * fine;
                    let py = y as f64 - 0.5 + ((sy * s + sx) as f64 + 0.5) * fine;
                    if let Some(v) =
                        apply_homography(&inverse, px, py).and_then(|(c, r)| sample(c, r))
                    {
                        sum += v as f64;
                        covered += 1;
                    }
                }
            }
            let total = (s * s) as f64;
            let alpha = covered as f64 / total;
            *pixel = (sum / total + (1.0 - alpha) * *pixel as f64) as f32;
        }
        std::mem::swap(&mut top, &mut bottom);
    }
}

/// Pixel bounds (inclusive) that may see the paper, or `None` when it is off the frame.
fn paper_bbox(
    g: &Mat3,
    lo: f64,
    hi: f64,
    w: usize,
    h: usize,
) -> Option<(usize, usize, usize, usize)> {
    if w == 0 || h == 0 {
        return None;
    }
    let mut bounds = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for (c, r) in [(lo, lo), (hi, lo), (hi, hi), (lo, hi)] {
        match apply_homography(g, c, r) {
            Some((x, y)) => {
                bounds = [
                    bounds[0].min(x),
                    bounds[1].max(x),
                    bounds[2].min(y),
                    bounds[3].max(y),
                ];
            }
            // Part of the paper is behind the camera: search the whole frame, the per-sample
            // test sorts it out.
            None => return Some((0, w - 1, 0, h - 1)),
        }
    }
    let clamp = |v: f64, max: usize| v.max(0.0).min(max as f64) as usize;
    let (xmin, xmax) = ((bounds[0] - 1.0).floor(), (bounds[1] + 1.0).ceil());
    let (ymin, ymax) = ((bounds[2] - 1.0).floor(), (bounds[3] + 1.0).ceil());
    if xmax < 0.0 || ymax < 0.0 || xmin > (w - 1) as f64 || ymin > (h - 1) as f64 {
        return None;
    }
    Some((
        clamp(xmin, w - 1),
        clamp(xmax, w - 1),
        clamp(ymin, h - 1),
        clamp(ymax, h - 1),
    ))
}

/// Separable Gaussian blur, edges replicated.
///
/// A kernel that reaches past the image (the defocus of a pad a few millimetres from the
/// lens: a sigma of thousands of pixels) takes [`wide_blur_pass`], whose cost is bounded
/// by the image's size; the usual small kernel keeps the direct sum, so the images it gives
/// are unchanged to the bit.
pub(crate) fn gaussian_blur(buffer: &mut [f32], w: usize, h: usize, sigma: f64) {
    let radius = (4.0 * sigma).ceil().max(1.0);
    if radius >= w.max(h) as f64 {
        let kernel = WideKernel::new(sigma, radius, w.max(h));
        let mut line = Vec::new();
        for y in 0..h {
            if let Some(row) = buffer.get_mut(y * w..(y + 1) * w) {
                wide_blur_pass(row, 1, &kernel, &mut line);
            }
        }
        for x in 0..w {
            if let Some(column) = buffer.get_mut(x..) {
                wide_blur_pass(column, w, &kernel, &mut line);
            }
        }
        return;
    }
    let radius = radius as isize;
    let mut kernel: Vec<f32> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    let mut scratch = vec![0.0f32; w * h];
    let clamp = |v: isize, len: usize| v.clamp(0, len as isize - 1) as usize;
    let r = radius as usize;
    for y in 0..h {
        let (Some(row), Some(out_row)) = (
            buffer.get(y * w..(y + 1) * w),
            scratch.get_mut(y * w..(y + 1) * w),
        ) else {
            continue;
        };
        for (x, out) in out_row.iter_mut().enumerate() {
            // Away from the edges the taps are the window itself: no clamping (the same sum,
            // in the same order, as the clamped one).
            let window = if x >= r {
                row.get(x - r..x + r + 1)
            } else {
                None
            };
            let mut acc = 0.0;
            match window {
                Some(window) => {
                    for (weight, v) in kernel.iter().zip(window) {
                        acc += weight * v;
                    }
                }
                None => {
                    for (k, weight) in kernel.iter().enumerate() {
                        let sx = clamp(x as isize + k as isize - radius, w);
                        acc += weight * row.get(sx).copied().unwrap_or(0.0);
                    }
                }
            }
            *out = acc;
        }
    }
    // Columns a row at a time: every output row is the kernel's weighted sum of whole input
    // rows, added tap by tap in the kernel's order, as the per-pixel sum does.
    let mut acc = vec![0.0f32; w];
    for y in 0..h {
        acc.fill(0.0);
        for (k, weight) in kernel.iter().enumerate() {
            let sy = clamp(y as isize + k as isize - radius, h);
            if let Some(src) = scratch.get(sy * w..(sy + 1) * w) {
                for (a, v) in acc.iter_mut().zip(src) {
                    *a += weight * v;
                }
            }
        }
        if let Some(out) = buffer.get_mut(y * w..(y + 1) * w) {
            out.copy_from_slice(&acc);
        }
    }
}

/// A normalised Gaussian kernel of `radius` taps each side, stored only as far as an image
/// line of up to `len` pixels can tell its taps apart: every tap further out lands on the
/// line's edge pixel (edges replicated), so it enters as a tail sum.
struct WideKernel {
    /// `weights[j]`: the weight of the taps at offset +-j, j < len.
    weights: Vec<f64>,
    /// `tails[m]`: the weights of the offsets m..=radius added up, m in 0..=len.
    tails: Vec<f64>,
}

/// Above this many taps beyond the stored ones the far tail is summed over coarser steps
/// (trapezoids over [`FAR_TAIL_STEPS`] intervals): a Gaussian that wide is flat to far
/// below an f32's resolution over one step, and the sum stays bounded in time however close
/// the scene comes.
const FAR_TAIL_EXACT_TAPS: f64 = 1.0e6;
/// Intervals of the coarse far-tail sum.
const FAR_TAIL_STEPS: usize = 100_000;

impl WideKernel {
    fn new(sigma: f64, radius: f64, len: usize) -> Self {
        let g = |j: f64| (-(j * j) / (2.0 * sigma * sigma)).exp();
        let weights: Vec<f64> = (0..len).map(|j| g(j as f64)).collect();
        // The taps from `len` to `radius`, as far as any line can reach.
        let first = len as f64;
        let far = if radius - first <= FAR_TAIL_EXACT_TAPS {
            let mut sum = 0.0;
            let mut j = first;
            while j <= radius {
                sum += g(j);
                j += 1.0;
            }
            sum
        } else {
            let step = (radius - first) / FAR_TAIL_STEPS as f64;
            let inner: f64 = (1..FAR_TAIL_STEPS)
                .map(|k| g(first + k as f64 * step))
                .sum();
            // The sum of unit-spaced taps is the integral (trapezoids of width `step`) plus
            // half of each end's tap (Euler-Maclaurin; the next term is below 1e-12 here).
            (0.5 * (g(first) + g(radius)) + inner) * step + 0.5 * (g(first) + g(radius))
        };
        let mut tails = vec![0.0; len + 1];
        let mut acc = far;
        if let Some(t) = tails.get_mut(len) {
            *t = acc;
        }
        for m in (0..len).rev() {
            acc += weights.get(m).copied().unwrap_or(0.0);
            if let Some(t) = tails.get_mut(m) {
                *t = acc;
            }
        }
        // Both sides, the centre tap once.
        let total =
            2.0 * tails.first().copied().unwrap_or(1.0) - weights.first().copied().unwrap_or(0.0);
        let norm = if total > 0.0 { 1.0 / total } else { 0.0 };
        WideKernel {
            weights: weights.iter().map(|v| v * norm).collect(),
            tails: tails.iter().map(|v| v * norm).collect(),
        }
    }
}

/// Blurs one line of `data` (every `stride`-th value) with `kernel`, in place.
fn wide_blur_pass(data: &mut [f32], stride: usize, kernel: &WideKernel, line: &mut Vec<f32>) {
    line.clear();
    line.extend(data.iter().step_by(stride).copied());
    let n = line.len();
    let (Some(&first), Some(&last)) = (line.first(), line.last()) else {
        return;
    };
    let tail = |m: usize| kernel.tails.get(m).copied().unwrap_or(0.0);
    for (x, out) in data.iter_mut().step_by(stride).enumerate() {
        // Offsets below -x all land on the first pixel, those past n - 1 - x on the last.
        let mut acc = tail(x + 1) * f64::from(first) + tail(n - x) * f64::from(last);
        for (s, &v) in line.iter().enumerate() {
            let weight = kernel.weights.get(s.abs_diff(x)).copied().unwrap_or(0.0);
            acc += weight * f64::from(v);
        }
        *out = acc as f32;
    }
}

pub(super) fn quantise(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}
