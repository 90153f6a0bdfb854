//! A lens's point-spread functions, applied to the radiance image by either renderer
//! ([`crate::warp::WarpOptics::psfs`], [`crate::Simulator::with_lens_psfs`]): a Gaussian
//! (the lens's own spread), a defocus disc (the geometric blur circle itself, not a
//! Gaussian stand-in), a straight motion line (camera shake at a fixed length and angle),
//! and a field-dependent blur that grows from nothing at the centre to a Gaussian at the
//! corners (the softer corners of a cheap lens).
//!
//! Borders repeat the edge pixel. The disc and the line are small 2-D kernels whose weights
//! are the kernel's area (or length) inside each pixel, so their widths are right below a
//! pixel too; the Gaussian is separable.

/// One point-spread function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Psf {
    /// A Gaussian of this standard deviation, pixels.
    Gaussian {
        /// Standard deviation, pixels.
        sigma_px: f64,
    },
    /// A uniform disc of this diameter, pixels (defocus).
    Disc {
        /// Diameter, pixels.
        diameter_px: f64,
    },
    /// A uniform line of this length, pixels, at this angle (degrees, counter-clockwise from
    /// the image's +x as seen with y down, i.e. clockwise on screen).
    MotionLine {
        /// Length, pixels.
        length_px: f64,
        /// Direction, degrees from image +x toward image +y.
        angle_deg: f64,
    },
    /// No blur at the image centre growing to a Gaussian of this standard deviation at the
    /// corners, the variance in proportion to the squared distance from the centre (up to
    /// 0.7 px a three-tap kernel per axis; wider, the image blended with its blurred copy by
    /// that proportion).
    Field {
        /// Standard deviation at the corners, pixels.
        corner_sigma_px: f64,
    },
}

/// Kernels wider than this many pixels either side are cut (a PSF that large is a mistake,
/// not an optic; the cut keeps a bad parameter from stalling a frame).
const MAX_RADIUS: usize = 32;
/// Sub-samples per pixel side when a kernel's coverage of a pixel is measured.
const COVERAGE_STEPS: usize = 16;

impl Psf {
    /// Blurs `image` (`width x height`, row-major) in place. Parameters that are not finite
    /// or not positive blur nothing.
    pub fn apply(&self, image: &mut [f32], width: usize, height: usize) {
        if width == 0 || height == 0 || image.len() < width * height {
            return;
        }
        match *self {
            Psf::Gaussian { sigma_px } => gaussian(image, width, height, sigma_px),
            Psf::Disc { diameter_px } => {
                if let Some(kernel) = disc_kernel(diameter_px) {
                    convolve(image, width, height, &kernel);
                }
            }
            Psf::MotionLine {
                length_px,
                angle_deg,
            } => {
                if let Some(kernel) = line_kernel(length_px, angle_deg) {
                    convolve(image, width, height, &kernel);
                }
            }
            Psf::Field { corner_sigma_px } => field(image, width, height, corner_sigma_px),
        }
    }
}

/// A square kernel of odd side `2 radius + 1`, weights summing to 1.
struct Kernel {
    radius: usize,
    weights: Vec<f32>,
}

fn gaussian(image: &mut [f32], width: usize, height: usize, sigma: f64) {
    if !sigma.is_finite() || sigma < 0.05 {
        return;
    }
    let radius = ((3.0 * sigma).ceil() as usize).clamp(1, MAX_RADIUS);
    let mut taps: Vec<f32> = (0..=2 * radius)
        .map(|k| {
            let d = k as f64 - radius as f64;
            (-0.5 * d * d / (sigma * sigma)).exp() as f32
        })
        .collect();
    let sum: f32 = taps.iter().sum();
    taps.iter_mut().for_each(|t| *t /= sum);
    separable(image, width, height, &taps);
}

/// Convolves with `taps` along x, then along y.
fn separable(image: &mut [f32], width: usize, height: usize, taps: &[f32]) {
    let radius = taps.len() / 2;
    let mut padded = vec![0.0f32; width + 2 * radius];
    for row in image.chunks_mut(width).take(height) {
        let first = row.first().copied().unwrap_or(0.0);
        let last = row.last().copied().unwrap_or(0.0);
        padded[..radius].fill(first);
        padded[radius..radius + width].copy_from_slice(row);
        padded[radius + width..].fill(last);
        for (x, o) in row.iter_mut().enumerate() {
            let window = &padded[x..x + taps.len()];
            *o = window.iter().zip(taps).map(|(v, t)| v * t).sum();
        }
    }
    // Along y a row at a time: the inner loop runs over x and vectorises.
    let source = image.to_vec();
    for (y, row) in image.chunks_mut(width).take(height).enumerate() {
        row.fill(0.0);
        for (k, &t) in taps.iter().enumerate() {
            let sy = (y + k).saturating_sub(radius).min(height - 1);
            let src = &source[sy * width..(sy + 1) * width];
            for (o, s) in row.iter_mut().zip(src) {
                *o += t * s;
            }
        }
    }
}

/// The disc's area in each pixel of its kernel.
fn disc_kernel(diameter: f64) -> Option<Kernel> {
    if !diameter.is_finite() || diameter <= 0.1 {
        return None;
    }
    let r = 0.5 * diameter;
    coverage_kernel(r, |x, y| x * x + y * y <= r * r)
}

/// The line's length in each pixel of its kernel, measured as the coverage of a line one
/// sub-sample thick.
fn line_kernel(length: f64, angle_deg: f64) -> Option<Kernel> {
    if !length.is_finite() || length <= 0.1 || !angle_deg.is_finite() {
        return None;
    }
    let (s, c) = angle_deg.to_radians().sin_cos();
    let half = 0.5 * length;
    let thickness = 0.5 / COVERAGE_STEPS as f64;
    coverage_kernel(half, |x, y| {
        let along = x * c + y * s;
        let across = -x * s + y * c;
        along.abs() <= half && across.abs() <= thickness
    })
}

/// A kernel reaching `reach` pixels from its centre whose weights are the fraction of each
/// pixel's sub-samples `inside` accepts; `None` if it accepts none.
fn coverage_kernel(reach: f64, inside: impl Fn(f64, f64) -> bool) -> Option<Kernel> {
    let radius = ((reach + 0.5).ceil() as usize).clamp(1, MAX_RADIUS);
    let side = 2 * radius + 1;
    let step = 1.0 / COVERAGE_STEPS as f64;
    let mut weights = vec![0.0f32; side * side];
    for (k, w) in weights.iter_mut().enumerate() {
        let (px, py) = (
            (k % side) as f64 - radius as f64,
            (k / side) as f64 - radius as f64,
        );
        let mut hits = 0u32;
        for sy in 0..COVERAGE_STEPS {
            for sx in 0..COVERAGE_STEPS {
                let x = px - 0.5 + (sx as f64 + 0.5) * step;
                let y = py - 0.5 + (sy as f64 + 0.5) * step;
                if inside(x, y) {
                    hits += 1;
                }
            }
        }
        *w = hits as f32;
    }
    let sum: f32 = weights.iter().sum();
    if sum <= 0.0 {
        return None;
    }
    weights.iter_mut().for_each(|w| *w /= sum);
    Some(Kernel { radius, weights })
}

/// A 2-D convolution, a kernel row at a time over whole image rows.
fn convolve(image: &mut [f32], width: usize, height: usize, kernel: &Kernel) {
    let r = kernel.radius;
    let side = 2 * r + 1;
    let padded_width = width + 2 * r;
    // The image with `r` repeated pixels on every side.
    let mut padded = vec![0.0f32; padded_width * (height + 2 * r)];
    for py in 0..height + 2 * r {
        let sy = py.saturating_sub(r).min(height - 1);
        let src = &image[sy * width..(sy + 1) * width];
        let dst = &mut padded[py * padded_width..(py + 1) * padded_width];
        dst[..r].fill(src[0]);
        dst[r..r + width].copy_from_slice(src);
        dst[r + width..].fill(src[width - 1]);
    }
    for (y, row) in image.chunks_mut(width).take(height).enumerate() {
        row.fill(0.0);
        for ky in 0..side {
            let src = &padded[(y + ky) * padded_width..(y + ky + 1) * padded_width];
            for kx in 0..side {
                let w = kernel.weights[ky * side + kx];
                if w == 0.0 {
                    continue;
                }
                for (o, s) in row.iter_mut().zip(&src[kx..kx + width]) {
                    *o += w * s;
                }
            }
        }
    }
}

/// Corner blurs up to this standard deviation are a three-tap kernel per axis whose weights
/// follow the pixel's distance from the centre (one cheap pass); wider ones blend the image
/// with a blurred copy.
const FIELD_TAPS_MAX_SIGMA: f64 = 0.7;

fn field(image: &mut [f32], width: usize, height: usize, corner_sigma: f64) {
    if !corner_sigma.is_finite() || corner_sigma < 0.05 {
        return;
    }
    let (cx, cy) = (0.5 * (width as f64 - 1.0), 0.5 * (height as f64 - 1.0));
    let corner2 = (cx * cx + cy * cy).max(1e-9);
    // The share of the corner's blur at each pixel: the squared distance from the centre over
    // the corner's.
    let share =
        |x: usize, y: usize| (((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)) / corner2) as f32;
    if corner_sigma <= FIELD_TAPS_MAX_SIGMA {
        // [w, 1 - 2w, w] along x, then along y, has the variance 2w per axis: w = sigma^2 / 2
        // with sigma^2 the corner's times the share. The share is a sum of a column's part
        // and a row's.
        let k = (0.5 * corner_sigma * corner_sigma / corner2) as f32;
        let columns: Vec<f32> = (0..width)
            .map(|x| k * (x as f64 - cx).powi(2) as f32)
            .collect();
        let mut row_in = vec![0.0f32; width];
        for (y, row) in image.chunks_mut(width).take(height).enumerate() {
            let dy = k * (y as f64 - cy).powi(2) as f32;
            row_in.copy_from_slice(row);
            for (x, o) in row.iter_mut().enumerate() {
                let w = columns[x] + dy;
                let (l, r) = (row_in[x.saturating_sub(1)], row_in[(x + 1).min(width - 1)]);
                *o = row_in[x] + w * (l + r - 2.0 * row_in[x]);
            }
        }
        // Along y a row at a time: the rows above and here kept unfiltered, the one below
        // not filtered yet.
        let mut above = image.get(..width).map(<[f32]>::to_vec).unwrap_or_default();
        let mut here = above.clone();
        for y in 0..height {
            let dy = k * (y as f64 - cy).powi(2) as f32;
            let (head, tail) = image.split_at_mut((y + 1) * width);
            let row = &mut head[y * width..];
            let below: &[f32] = if y + 1 < height {
                &tail[..width]
            } else {
                &here
            };
            for (x, o) in row.iter_mut().enumerate() {
                let w = columns[x] + dy;
                *o = here[x] + w * (above[x] + below[x] - 2.0 * here[x]);
            }
            std::mem::swap(&mut above, &mut here);
            if let Some(next) = tail.get(..width) {
                here.copy_from_slice(next);
            }
        }
        return;
    }
    let mut blurred = image.to_vec();
    gaussian(&mut blurred, width, height, corner_sigma);
    for (y, (row, blurred_row)) in image
        .chunks_mut(width)
        .zip(blurred.chunks(width))
        .take(height)
        .enumerate()
    {
        for (x, (o, b)) in row.iter_mut().zip(blurred_row).enumerate() {
            let t = share(x, y);
            *o += t * (b - *o);
        }
    }
}
