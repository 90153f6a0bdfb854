//! Step 7: corners of small markers from a fit of the decoded pattern to the pixels.
//!
//! ## Why
//! Far from the pad a marker spans 10-20 pixels, a cell 1-2 pixels, and the blur is about
//! as wide as a cell. The edge search of [`super::refine`] then reads a gradient lobe whose
//! tails run into the neighbouring edges (the white ring's outer edge outside, the first data
//! cells inside): the centroid moves by a few hundredths of a pixel per edge, in a direction
//! set by the blur and by what lies around the marker. That is a scale error: on a 1 m marker
//! at 50 m (11 pixels across) the altitude read 1.4 % high on our renderer and 1.4 % low on
//! another, the largest error of the pose above 25 m once the tilt comes from the attitude.
//!
//! Once the marker is decoded, the whole pattern is known: every cell's colour, the white
//! ring outside the border (the family's quiet ring, or the printed margin every family needs
//! for its outline to be found). So the image of the marker is predicted, not searched:
//! the known cells mapped through the corner homography, blurred by a Gaussian of unknown
//! width, with unknown black and white levels and an unknown (uniform) level beyond the known
//! area. A Gauss-Newton fit of the 4 corners, the blur, the two levels and the outside level
//! to every pixel over the marker moves the corners to where the whole pattern agrees: each
//! edge is placed with its neighbours modelled instead of trimmed, so the scale is unbiased
//! whatever the blur.
//!
//! ## The model
//! A pixel at image point `x` (pixel centres at integers) reads `a + c * B(u)`, where `u` is
//! `x` in grid coordinates (cells; the detected corners sit at the border's outer corners,
//! see [`Family::quad_offset`]) and `B` is the blurred pattern (1 white, 0 black). The blur
//! is a Gaussian (the optics and the pixel's own area together) of one width in grid cells
//! along both grid axes: exact for a marker seen square on, as every far marker is, and the
//! corners' moves then leave it alone, which keeps the derivatives simple. A Gaussian over a grid of squares is separable, so `B` and its
//! derivatives are sums of products of normal-distribution differences along the two axes.
//!
//! ## Cost and bounds
//! Only markers whose longest side is at most [`MAX_SIDE_PX`] are fitted; above it the edge
//! search is already within a tenth of a percent. At most [`MAX_PIXELS`] pixels (a regular
//! subsample on the larger markers) and [`ITERATIONS`] iterations, so the time per marker is
//! bounded whatever the image. A fit is kept only when it converged to a sane blur and
//! moved no corner more than [`MAX_CORNER_SHIFT_PX`]; otherwise the edge corners stand.

// The normal equations are fixed 12x12 arrays indexed by loop counters below 12, and the
// normal tables by an index clamped to their length: never by data.
#![allow(clippy::indexing_slicing)]

use super::contour::Tracer;
use super::Detection;
use crate::family::Family;
use crate::geometry::{Homography, Point};
use crate::image::GrayImage;

/// Longest marker side (pixels) that is fitted. At 40 pixels a cell of an 8-cell border
/// square is 5 pixels, wider than any blur, and the edge search is unbiased there.
pub const MAX_SIDE_PX: f32 = 40.0;
/// Most pixels one fit reads. Larger markers are subsampled on a lattice, which leaves a
/// little of the model's mismatch (the pixel's square area against the Gaussian) in the
/// scale: within 0.15 % at 11 pixels across, 0.05 % from 18 pixels up (the tests). Each
/// pixel costs about 1,700 Cortex-M7 instructions per pass with derivatives.
pub const MAX_PIXELS: usize = 192;
/// Levenberg-Marquardt steps. The edge corners start within a few tenths of a pixel and the
/// model is smooth there: three steps converge to about a hundredth of a pixel (the last
/// one's cost is evaluated without derivatives, only to keep or refuse it).
pub const ITERATIONS: usize = 3;
/// Range of the fitted contrast, as a multiple of the decoder's measure of it (a mean over
/// blurred cells: lower than the real contrast on a small marker, never far above it).
const CONTRAST_RANGE: (f32, f32) = (0.5, 4.0);
/// Largest residual RMS a fit may leave, as a fraction of the fitted contrast.
const MAX_RESIDUAL_OF_CONTRAST: f32 = 0.25;
/// Starting Levenberg-Marquardt damping of the normal equations' diagonal: keeps a step
/// finite when a parameter is barely observed (the outside level of a marker in a wide
/// margin).
const DAMPING: f32 = 1e-3;
/// A fit that moves a corner further than this (pixels) is not the small correction it is
/// for (a wrong decode, an occluded marker, another marker in the margin): refused.
pub const MAX_CORNER_SHIFT_PX: f32 = 0.75;
/// Most markers fitted in one frame: the largest. When every marker is small, the largest
/// sets the pad fix's scale (its corners are the farthest apart); the bound keeps a frame
/// of many small look-alikes from paying for many fits.
pub const MAX_FITS_PER_FRAME: usize = 1;
/// Work units of one fit (see `DetectorConfig::work_budget_per_pixel`; one unit is 75 to
/// 100 Cortex-M7 instructions). Measured on the Cortex-M7 benchmark (`bench/m7`,
/// qvga-far-1: one tag36h11 of 14 pixels): 1.62 million instructions for its 192 pixels and five
/// passes. A fit is charged before it starts and skipped when the frame's budget cannot pay
/// for it, so it never breaks the bound on the time per frame.
pub const WORK_PATTERN_FIT: u32 = 20_000;
/// Most cells per side of a family grid the fit models (with its assumed margin ring).
const MAX_GRID: usize = 16;
/// Blur range (pixels) a fit may end in: below, the pixel's own area; above, the marker is
/// not resolved.
const BLUR_RANGE_PX: (f32, f32) = (0.25, 3.0);
/// The Gaussian is summed over this many of its widths on either side of a point.
const WINDOW_SIGMAS: f32 = 3.0;
/// Most cells one axis of the window may cover: a blur of up to 1.1 cells (a marker of 8
/// cells blurred by 1.2 pixels is 9 pixels across, the smallest the detector finds).
const MAX_WINDOW: usize = 8;
/// Blur the fit starts from (pixels): typical of a small lens at focus.
const INITIAL_BLUR_PX: f32 = 0.8;
/// Parameters: 4 corners (x, y), blur (the logarithm of its width in grid cells: always
/// positive, and a step of a given size means the same at any blur), black level, contrast,
/// outside level.
const N: usize = 12;
const BLUR: usize = 8;
const BLACK: usize = 9;
const CONTRAST: usize = 10;
const OUTSIDE: usize = 11;

/// The known pattern of one decoded marker: which cells are white, in the canonical grid
/// with one ring added around it when the family has no quiet ring of its own (the printed
/// margin), and the grid coordinates of the detected corners.
struct Pattern {
    /// Row bitmaps (bit = column), white = 1, of the extended grid.
    white: [u32; MAX_GRID],
    /// Cells per side of the extended grid.
    side: usize,
    /// Grid coordinate (in the extended grid) of the detected corners' square: its sides.
    quad_lo: f32,
    quad_hi: f32,
}

impl Pattern {
    fn new(family: &Family<'_>, id: u16) -> Option<Pattern> {
        let n = family.grid as usize;
        // The detected square is the border's outer edge; outside it must lie white cells
        // for the outline to be found: the family's quiet ring or the printed margin.
        let margin = usize::from(family.quiet_rings == 0 && !family.reversed());
        let cells = n + 2 * margin;
        if cells > MAX_GRID || n == 0 || family.reversed() {
            // Reversed families (data outside the border) are found by their inner edge;
            // their layout is not modelled here.
            return None;
        }
        let mut white = [0u32; MAX_GRID];
        for (row, bits) in white.iter_mut().enumerate().take(cells) {
            for col in 0..cells {
                let inside = |k: usize| k.checked_sub(margin).filter(|&k| k < n);
                let is_white = match (inside(row), inside(col)) {
                    (Some(r), Some(c)) => family.cell_is_white(usize::from(id), r, c)?,
                    _ => true,
                };
                if is_white {
                    *bits |= 1 << col;
                }
            }
        }
        let b = (family.border_ring as usize + margin) as f32;
        Some(Pattern {
            white,
            side: cells,
            quad_lo: b,
            quad_hi: cells as f32 - b,
        })
    }

    /// Row `row`'s white bits from column `first` on (bit 0 = column `first`).
    fn row_from(&self, row: usize, first: usize) -> u32 {
        let bits = self.white.get(row).copied().unwrap_or(0);
        bits.checked_shr(first as u32).unwrap_or(0)
    }

    /// Grid points of the detected corners, in detection order (clockwise from top-left).
    fn corner_points(&self) -> [Point; 4] {
        let (lo, hi) = (self.quad_lo, self.quad_hi);
        [
            Point::new(lo, lo),
            Point::new(hi, lo),
            Point::new(hi, hi),
            Point::new(lo, hi),
        ]
    }
}

/// One axis of the blurred grid at a point: the Gaussian's mass in each window cell and the
/// mass's derivatives with respect to the point and to the width, and the same for the whole
/// known area.
struct Axis {
    first: usize,
    len: usize,
    /// Per window cell: the mass, its derivative by the point and by the width.
    cells: [Cell; MAX_WINDOW],
    known: f32,
    known_d_pos: f32,
    known_d_width: f32,
}

/// Half-width of the normal tables, standard deviations: beyond it the distribution is 0 or
/// 1 and the density 0 to within 2e-4 (the window's own truncation).
const TABLE_REACH: f32 = 4.0;
/// Intervals of the normal tables over `±TABLE_REACH`.
const TABLE_STEPS: usize = 256;
/// Table entries per standard deviation.
const TABLE_SCALE: f32 = TABLE_STEPS as f32 / (2.0 * TABLE_REACH);

/// The standard normal distribution at `TABLE_STEPS + 1` points over `±TABLE_REACH`,
/// computed at compile time (series in f64). A table read and a linear interpolation cost a
/// tenth of `erff` on the Cortex-M7, and the fit reads two dozen values per pixel.
static CDF: [f32; TABLE_STEPS + 1] = normal_table(true);
/// The standard normal density at the same points.
static PDF: [f32; TABLE_STEPS + 1] = normal_table(false);

const fn normal_table(cdf: bool) -> [f32; TABLE_STEPS + 1] {
    let mut out = [0.0f32; TABLE_STEPS + 1];
    let mut i = 0;
    while i <= TABLE_STEPS {
        let z = -(TABLE_REACH as f64) + i as f64 / TABLE_SCALE as f64;
        out[i] = if cdf {
            (0.5 + 0.5 * erf_series(z * core::f64::consts::FRAC_1_SQRT_2)) as f32
        } else {
            (0.398_942_280_401_432_7 * exp_series(-0.5 * z * z)) as f32
        };
        i += 1;
    }
    out
}

/// `erf(x)` by its Taylor series, for |x| <= 3 (enough terms for f64 there).
const fn erf_series(x: f64) -> f64 {
    let mut sum = 0.0;
    let mut term = x; // x^(2n+1) (-1)^n / n!
    let mut n = 0;
    while n < 80 {
        sum += term / (2 * n + 1) as f64;
        n += 1;
        term = -term * x * x / n as f64;
    }
    sum * 1.128_379_167_095_512_6
}

/// `exp(x)` for -8 <= x <= 0: the series of exp(x / 16), squared four times.
const fn exp_series(x: f64) -> f64 {
    let y = x / 16.0;
    let mut sum = 1.0;
    let mut term = 1.0;
    let mut n = 1;
    while n < 30 {
        term = term * y / n as f64;
        sum += term;
        n += 1;
    }
    let mut k = 0;
    while k < 4 {
        sum *= sum;
        k += 1;
    }
    sum
}

/// The Gaussian's mass in one cell of an axis, and its derivatives.
#[derive(Clone, Copy, Default)]
struct Cell {
    mass: f32,
    d_pos: f32,
    d_width: f32,
}

/// Standard normal distribution and density at `z`. The density is interpolated linearly
/// in its table and the distribution is its exact integral from the table point below, so
/// that the density is exactly the distribution's derivative: the fit's derivatives are
/// those of its model, and its steps go where the model's cost falls.
#[inline]
fn normal(z: f32) -> (f32, f32) {
    const STEP: f32 = 1.0 / TABLE_SCALE;
    let t = ((z + TABLE_REACH) * TABLE_SCALE).clamp(0.0, TABLE_STEPS as f32);
    // `t` is finite or NaN here; NaN casts to 0 and reads the table's end.
    let i = (t as usize).min(TABLE_STEPS - 1);
    let f = t - i as f32;
    // In bounds: `i` is at most `TABLE_STEPS - 1` and the tables hold `TABLE_STEPS + 1`.
    let (c0, p0, p1) = (CDF[i], PDF[i], PDF[i + 1]);
    let pdf = p0 + f * (p1 - p0);
    let cdf = c0 + STEP * f * (p0 + 0.5 * f * (p1 - p0));
    (cdf, pdf)
}

impl Axis {
    /// The axis at grid coordinate `t` with Gaussian width `width` (cells), over a known
    /// area of `cells` cells. The known area's mass is taken from the window's own end edges
    /// where the window reaches the area's ends, and is whole otherwise: the mass a window
    /// leaves out is [`WINDOW_SIGMAS`] widths away, and it counts as outside level instead of
    /// its cells', an error below 0.3 % of the difference.
    fn new(t: f32, width: f32, cells: usize) -> Option<Axis> {
        let inverse = 1.0 / width;
        let reach = WINDOW_SIGMAS * width;
        let (lo, hi) = (libm::floorf(t - reach), libm::ceilf(t + reach));
        let (first, last) = (lo.max(0.0), hi.min(cells as f32));
        if !(first.is_finite() && last.is_finite() && inverse.is_finite()) {
            return None;
        }
        let mut axis = Axis {
            first: 0,
            len: 0,
            cells: [Cell::default(); MAX_WINDOW],
            known: 1.0,
            known_d_pos: 0.0,
            known_d_width: 0.0,
        };
        if last <= first {
            // Farther than the window from the known area: only the outside level.
            axis.known = 0.0;
            return Some(axis);
        }
        let (first, len) = (first as usize, (last - first) as usize);
        if len > MAX_WINDOW {
            return None;
        }
        axis.first = first;
        axis.len = len;
        let edge = |k: usize| {
            let z = ((first + k) as f32 - t) * inverse;
            let (cdf, pdf) = normal(z);
            (cdf, pdf, z)
        };
        let start = edge(0);
        let mut lower = start;
        for (k, cell) in axis.cells.iter_mut().enumerate().take(len) {
            let upper = edge(k + 1);
            *cell = Cell {
                mass: upper.0 - lower.0,
                d_pos: -(upper.1 - lower.1) * inverse,
                d_width: -(upper.1 * upper.2 - lower.1 * lower.2) * inverse,
            };
            lower = upper;
        }
        // The known area's ends inside the window are its first and last edges; an end
        // beyond the window counts as at infinity.
        let below = if lo < 0.0 { start } else { (0.0, 0.0, 0.0) };
        let above = if hi > cells as f32 {
            lower
        } else {
            (1.0, 0.0, 0.0)
        };
        axis.known = above.0 - below.0;
        axis.known_d_pos = -(above.1 - below.1) * inverse;
        axis.known_d_width = -(above.1 * above.2 - below.1 * below.2) * inverse;
        Some(axis)
    }
}

/// The blurred pattern at one point and its derivatives.
struct Blurred {
    value: f32,
    d_u: f32,
    d_v: f32,
    d_width_u: f32,
    d_width_v: f32,
    /// Weight of the outside level: the Gaussian's mass beyond the known area.
    outside: f32,
}

fn blurred(pattern: &Pattern, u: &Axis, v: &Axis, outside_level: f32) -> Blurred {
    let (mut value, mut d_u, mut d_v, mut d_wu, mut d_wv) = (0.0f32, 0.0, 0.0, 0.0, 0.0);
    for (r, across) in v.cells.iter().enumerate().take(v.len) {
        let (mut row, mut row_d, mut row_w) = (0.0f32, 0.0f32, 0.0f32);
        // Only the white cells of the window's row count (black is 0): visit their bits.
        let in_window = 1u32.checked_shl(u.len as u32).map_or(u32::MAX, |b| b - 1);
        let mut white = pattern.row_from(v.first + r, u.first) & in_window;
        while white != 0 {
            let k = white.trailing_zeros() as usize;
            white &= white - 1;
            if let Some(along) = u.cells.get(k) {
                row += along.mass;
                row_d += along.d_pos;
                row_w += along.d_width;
            }
        }
        value += across.mass * row;
        d_u += across.mass * row_d;
        d_wu += across.mass * row_w;
        d_v += across.d_pos * row;
        d_wv += across.d_width * row;
    }
    let inside = u.known * v.known;
    let o = outside_level;
    Blurred {
        value: value + o * (1.0 - inside),
        d_u: d_u - o * u.known_d_pos * v.known,
        d_v: d_v - o * u.known * v.known_d_pos,
        d_width_u: d_wu - o * u.known_d_width * v.known,
        d_width_v: d_wv - o * u.known * v.known_d_width,
        outside: 1.0 - inside,
    }
}

/// The pixels a fit reads: the box around the known area's image, thinned to a lattice
/// of every `step`-th pixel (a checkerboard for 2) when the box holds more than
/// [`MAX_PIXELS`].
struct Window {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
    step: usize,
}

impl Window {
    /// Whether pixel (x, y) is on the lattice: rows shifted by half a step, so that every
    /// column and every row is read.
    fn reads(&self, x: usize, y: usize) -> bool {
        (x + y * (self.step / 2).max(1)) % self.step == 0
    }
}

fn window(image: &GrayImage<'_>, pattern: &Pattern, corners: &[Point; 4]) -> Option<Window> {
    let to_image = Homography::from_4_points(&pattern.corner_points(), corners)?;
    let c = pattern.side as f32;
    let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    for (u, v) in [(0.0, 0.0), (c, 0.0), (c, c), (0.0, c)] {
        let p = to_image.map(u, v)?;
        lo_x = lo_x.min(p.x);
        lo_y = lo_y.min(p.y);
        hi_x = hi_x.max(p.x);
        hi_y = hi_y.max(p.y);
    }
    // The blur reaches a little beyond the known area: read it, the outside level models it.
    let pad = 1.5;
    let x0 = libm::floorf(lo_x - pad).max(0.0);
    let y0 = libm::floorf(lo_y - pad).max(0.0);
    let x1 = libm::ceilf(hi_x + pad).min(image.width() as f32 - 1.0);
    let y1 = libm::ceilf(hi_y + pad).min(image.height() as f32 - 1.0);
    if !(x1 > x0 && y1 > y0) {
        return None;
    }
    let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize, y1 as usize);
    let area = (x1 - x0 + 1) * (y1 - y0 + 1);
    Some(Window {
        x0,
        y0,
        x1,
        y1,
        step: area.div_ceil(MAX_PIXELS).max(1),
    })
}

/// Normal equations of one iteration: `J^T J`, `J^T e` and the residual sum of squares.
struct Normal {
    jtj: [[f32; N]; N],
    jte: [f32; N],
    cost: f32,
    count: usize,
}

/// What one pass over the window computes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    /// The cost and the normal equations of every parameter.
    Full,
    /// The cost only.
    Cost,
    /// The least-squares normal equations of the levels alone, which enter the model
    /// linearly: the pixel is `black + contrast * cells + (contrast * outside) * beyond`, so
    /// the first three rows and columns hold the system in (black, contrast, contrast *
    /// outside) against the pixels themselves.
    Levels,
}

/// The model at every window pixel for `params`, accumulated as `pass` says.
///
/// The corners' derivatives are closed-form: for the homography of the unit square onto
/// itself, moving corner k by (dx, dy) moves the point (s, t) by
/// `(N_k dx + sign_k s(1-s) dy, sign_k t(1-t) dx + N_k dy)`, with `N_k` the bilinear weight
/// of the corner and `sign_k` -1 for the top-left and bottom-right corners, +1 for the
/// others (solve the four corner conditions of `I + e A` to first order). The quad's affine
/// part carries image moves into the square and back: exact to first order for a
/// parallelogram, and a far marker is one to within its small perspective. It saves eight
/// homographies per pixel.
fn linearise(
    image: &GrayImage<'_>,
    pattern: &Pattern,
    win: &Window,
    params: &[f32; N],
    pass: Pass,
) -> Option<Normal> {
    let corners = fitted_corners(params);
    let map = Homography::from_4_points(&corners, &pattern.corner_points())?;
    let (blur, black, contrast, outside) = (
        libm::expf(params[BLUR]),
        params[BLACK],
        params[CONTRAST],
        params[OUTSIDE],
    );
    let (lo, span) = (pattern.quad_lo, pattern.quad_hi - pattern.quad_lo);
    let square_from_image = square_from_image(&corners)?;
    let mut normal = Normal {
        jtj: [[0.0; N]; N],
        jte: [0.0; N],
        cost: 0.0,
        count: 0,
    };
    for y in win.y0..=win.y1 {
        let row = image.row(y);
        for x in win.x0..=win.x1 {
            if !win.reads(x, y) {
                continue;
            }
            let observed = f32::from(row.get(x).copied().unwrap_or(0));
            let g = map.map(x as f32, y as f32)?;
            let (Some(au), Some(av)) = (
                Axis::new(g.x, blur, pattern.side),
                Axis::new(g.y, blur, pattern.side),
            ) else {
                return None;
            };
            let b = blurred(pattern, &au, &av, outside);
            let e = observed - (black + contrast * b.value);
            normal.cost += e * e;
            normal.count += 1;
            match pass {
                Pass::Cost => continue,
                Pass::Levels => {
                    let cells = b.value - outside * b.outside;
                    let regressors = [1.0, cells, b.outside];
                    for (r, &x) in regressors.iter().enumerate() {
                        normal.jte[r] += x * observed;
                        for (c, &y) in regressors.iter().enumerate() {
                            normal.jtj[r][c] += x * y;
                        }
                    }
                    continue;
                }
                Pass::Full => {}
            }
            // The model's gradient over the square (s, t), and the corners' moves of (s, t).
            let (gs, gt) = (contrast * b.d_u * span, contrast * b.d_v * span);
            let (s, t) = ((g.x - lo) / span, (g.y - lo) / span);
            let (ss, tt) = (s * (1.0 - s), t * (1.0 - t));
            let weights = [(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t];
            let mut jac = [0.0f32; N];
            for (k, w) in weights.iter().enumerate() {
                let sign = if k % 2 == 0 { -1.0 } else { 1.0 };
                // The model's change for a unit move of the corner along s and along t.
                let along_s = gs * w + gt * sign * tt;
                let along_t = gs * sign * ss + gt * w;
                let [[a, b_], [c, d]] = square_from_image;
                jac[2 * k] = -(along_s * a + along_t * c);
                jac[2 * k + 1] = -(along_s * b_ + along_t * d);
            }
            jac[BLUR] = contrast * (b.d_width_u + b.d_width_v) * blur;
            jac[BLACK] = 1.0;
            jac[CONTRAST] = b.value;
            jac[OUTSIDE] = contrast * b.outside;
            for r in 0..N {
                normal.jte[r] += jac[r] * e;
                for c in r..N {
                    normal.jtj[r][c] += jac[r] * jac[c];
                }
            }
        }
    }
    for r in 0..N {
        for c in 0..r {
            if pass == Pass::Full {
                normal.jtj[r][c] = normal.jtj[c][r];
            }
        }
    }
    Some(normal)
}

/// The inverse of the quad's affine part (its mean side vectors as the square's axes): how
/// an image move of a corner moves it in the unit square. Row-major `[[ds/dx, ds/dy],
/// [dt/dx, dt/dy]]`.
fn square_from_image(c: &[Point; 4]) -> Option<[[f32; 2]; 2]> {
    let (sx, sy) = (
        0.5 * (c[1].x - c[0].x + c[2].x - c[3].x),
        0.5 * (c[1].y - c[0].y + c[2].y - c[3].y),
    );
    let (tx, ty) = (
        0.5 * (c[3].x - c[0].x + c[2].x - c[1].x),
        0.5 * (c[3].y - c[0].y + c[2].y - c[1].y),
    );
    let det = sx * ty - tx * sy;
    if !(det.abs() > 1e-6) {
        return None;
    }
    Some([[ty / det, -tx / det], [-sy / det, sx / det]])
}

/// Sets the levels of `params` to their least-squares values for its geometry and blur:
/// the levels enter the model linearly, so one pass finds them exactly, and the nonlinear
/// steps start with only the geometry and the blur to move. The decoder's contrast is a
/// mean over blurred cells, often half the real one on a small marker.
fn solve_levels(
    image: &GrayImage<'_>,
    pattern: &Pattern,
    win: &Window,
    params: &mut [f32; N],
) -> Result<(), Refusal> {
    let levels = linearise(image, pattern, win, params, Pass::Levels).ok_or(Refusal::Geometry)?;
    let a = &levels.jtj;
    let b = &levels.jte;
    let det3 = |m: [[f32; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let m = [
        [a[0][0], a[0][1], a[0][2]],
        [a[1][0], a[1][1], a[1][2]],
        [a[2][0], a[2][1], a[2][2]],
    ];
    // A marker in a wide printed margin has almost no pixel beyond the known area: keep the
    // outside level then (its column is nearly zero) and solve the other two.
    let d = det3(m);
    let scale = m[0][0] * m[1][1] * m[2][2];
    let mut x = [0.0f32; 3];
    if d.abs() > 1e-6 * scale.abs() {
        for (k, slot) in x.iter_mut().enumerate() {
            let mut mk = m;
            for (row, rhs) in mk.iter_mut().zip(b.iter()) {
                row[k] = *rhs;
            }
            *slot = det3(mk) / d;
        }
    } else {
        let o = params[OUTSIDE];
        let d2 = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        if !(d2.abs() > 0.0) {
            return Err(Refusal::Singular);
        }
        x[0] = (b[0] * m[1][1] - m[0][1] * b[1]) / d2;
        x[1] = (m[0][0] * b[1] - b[0] * m[1][0]) / d2;
        x[2] = o * x[1];
    }
    if !(x[1] > 0.0) || !x.iter().all(|v| v.is_finite()) {
        return Err(Refusal::Levels);
    }
    params[BLACK] = x[0];
    params[CONTRAST] = x[1];
    params[OUTSIDE] = x[2] / x[1];
    Ok(())
}

/// Solves `(A + lambda diag A) x = b` by Cholesky; `None` when not positive definite.
fn solve_damped(a: &[[f32; N]; N], b: &[f32; N], lambda: f32) -> Option<[f32; N]> {
    let mut l = [[0.0f32; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = a[i][j];
            if i == j {
                sum += lambda * a[i][i];
            }
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(sum > 0.0) {
                    return None;
                }
                l[i][i] = libm::sqrtf(sum);
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    let mut z = [0.0f32; N];
    for i in 0..N {
        let mut sum = b[i];
        for k in 0..i {
            sum -= l[i][k] * z[k];
        }
        z[i] = sum / l[i][i];
    }
    let mut x = [0.0f32; N];
    for i in (0..N).rev() {
        let mut sum = z[i];
        for k in i + 1..N {
            sum -= l[k][i] * x[k];
        }
        x[i] = sum / l[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Where the diagonals of a quad cross: the image of its centre under any homography.
fn diagonals_meet(c: &[Point; 4]) -> Option<Point> {
    let (d1x, d1y) = (c[2].x - c[0].x, c[2].y - c[0].y);
    let (d2x, d2y) = (c[3].x - c[1].x, c[3].y - c[1].y);
    let den = d1x * d2y - d1y * d2x;
    if !(den.abs() > 1e-6) {
        return None;
    }
    let s = ((c[1].x - c[0].x) * d2y - (c[1].y - c[0].y) * d2x) / den;
    let p = Point::new(c[0].x + s * d1x, c[0].y + s * d1y);
    (p.x.is_finite() && p.y.is_finite()).then_some(p)
}

/// The mean side of a quad, pixels.
fn mean_side(c: &[Point; 4]) -> f32 {
    0.25 * (0..4).map(|k| c[k].distance(c[(k + 1) % 4])).sum::<f32>()
}

/// The corners in a parameter vector.
fn fitted_corners(params: &[f32; N]) -> [Point; 4] {
    let mut corners = [Point::default(); 4];
    for (k, c) in corners.iter_mut().enumerate() {
        *c = Point::new(params[2 * k], params[2 * k + 1]);
    }
    corners
}

/// The longest side of a quad, pixels.
pub(crate) fn longest_side(corners: &[Point; 4]) -> f32 {
    (0..4)
        .map(|k| corners[k].distance(corners[(k + 1) % 4]))
        .fold(0.0, f32::max)
}

/// Corners of the decoded marker `id` of `family` at `corners` (detection order), fitted to
/// the pixels as the module docs describe; `None` when the marker is not small, its family's
/// layout is not modelled, or the fit is refused. `contrast` (grey levels) starts the fit.
pub(crate) fn fit_corners(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    id: u16,
    corners: &[Point; 4],
    contrast: f32,
) -> Option<[Point; 4]> {
    fit(image, family, id, corners, contrast).ok()
}

/// Why a fit was not kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The marker is larger than [`MAX_SIDE_PX`].
    Large,
    /// The family's layout is not modelled, or the id is unknown.
    Layout,
    /// The marker's image is degenerate or outside the image.
    Geometry,
    /// The normal equations were singular.
    Singular,
    /// The model does not explain the pixels.
    Residual,
    /// The blur or the contrast ended outside their ranges.
    Levels,
    /// A corner moved more than [`MAX_CORNER_SHIFT_PX`].
    Moved,
}

/// [`fit_corners`], with the reason of a refusal.
pub(crate) fn fit(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    id: u16,
    corners: &[Point; 4],
    contrast: f32,
) -> Result<[Point; 4], Refusal> {
    if longest_side(corners) > MAX_SIDE_PX {
        return Err(Refusal::Large);
    }
    let pattern = Pattern::new(family, id).ok_or(Refusal::Layout)?;
    let win = window(image, &pattern, corners).ok_or(Refusal::Geometry)?;
    let mut params = [0.0f32; N];
    for (k, c) in corners.iter().enumerate() {
        params[2 * k] = c.x;
        params[2 * k + 1] = c.y;
    }
    // Levels: start from the darkest pixels as black and the detector's contrast; the
    // outside as white (a printed margin). The first iteration solves them nearly exactly.
    let cell_px = mean_side(corners) / (pattern.quad_hi - pattern.quad_lo);
    if !(cell_px > 0.0) {
        return Err(Refusal::Geometry);
    }
    params[BLUR] = libm::logf(INITIAL_BLUR_PX / cell_px);
    params[BLACK] = darkest(image, &win);
    let start_contrast = contrast.max(1.0);
    params[CONTRAST] = start_contrast;
    params[OUTSIDE] = 1.0;
    // Levenberg-Marquardt: the start is within a few tenths of a pixel, where the model is
    // nearly linear and the first step usually lands. A step that does not lower the cost
    // is taken back and retried shorter.
    solve_levels(image, &pattern, &win, &mut params)?;
    let mut current =
        linearise(image, &pattern, &win, &params, Pass::Full).ok_or(Refusal::Geometry)?;
    let mut damping = DAMPING;
    for iteration in 0..ITERATIONS {
        let step = solve_damped(&current.jtj, &current.jte, damping).ok_or(Refusal::Singular)?;
        let mut trial = params;
        for (p, d) in trial.iter_mut().zip(step.iter()) {
            *p += d;
        }
        let last = iteration + 1 == ITERATIONS;
        let pass = if last { Pass::Cost } else { Pass::Full };
        match linearise(image, &pattern, &win, &trial, pass) {
            Some(next) if next.cost < current.cost => {
                params = trial;
                current = next;
                damping = (damping * 0.1).max(DAMPING * 1e-3);
            }
            _ => damping *= 10.0,
        }
    }
    // The model must explain the pixels: a residual of a few grey levels (sensor noise and
    // the blur's shape), far below the contrast. A wrong pattern or clutter does not fit.
    let rms = libm::sqrtf(current.cost / current.count.max(1) as f32);
    if !(rms < MAX_RESIDUAL_OF_CONTRAST * params[CONTRAST]) {
        return Err(Refusal::Residual);
    }
    let cells = pattern.quad_hi - pattern.quad_lo;
    let blur = libm::expf(params[BLUR]) * mean_side(&fitted_corners(&params)) / cells;
    // The fitted contrast must be the marker's: a fit that flattened it found something else.
    let contrast_ratio = params[CONTRAST] / start_contrast;
    if !(blur >= BLUR_RANGE_PX.0 && blur <= BLUR_RANGE_PX.1)
        || !(contrast_ratio >= CONTRAST_RANGE.0 && contrast_ratio <= CONTRAST_RANGE.1)
    {
        return Err(Refusal::Levels);
    }
    let mut out = [Point::default(); 4];
    for (k, slot) in out.iter_mut().enumerate() {
        let p = Point::new(params[2 * k], params[2 * k + 1]);
        if !(p.distance(corners[k]) <= MAX_CORNER_SHIFT_PX) {
            return Err(Refusal::Moved);
        }
        *slot = p;
    }
    Ok(out)
}

/// The darkest pixel of the window: the start of the black level (the first step solves the
/// levels, which enter the model linearly, nearly exactly).
fn darkest(image: &GrayImage<'_>, win: &Window) -> f32 {
    let mut lowest = u8::MAX;
    for y in win.y0..=win.y1 {
        let row = image.row(y);
        for &p in row.get(win.x0..=win.x1).unwrap_or(&[]) {
            lowest = lowest.min(p);
        }
    }
    f32::from(lowest)
}

/// Step 7 over a frame's `detections`: fits the largest small markers, at most
/// [`MAX_FITS_PER_FRAME`], when every marker of the frame is small (see the module docs: a
/// larger marker, or the spread of several, sets the pose's scale better than any small
/// marker's own size). Charges [`WORK_PATTERN_FIT`] per fit to `tracer` and stops when the
/// budget is spent. Returns the number of markers whose corners were replaced.
pub(super) fn fit_small_markers(
    image: &GrayImage<'_>,
    families: &[&Family<'_>],
    detections: &mut [Detection],
    tracer: &mut Tracer<'_>,
) -> u32 {
    if detections
        .iter()
        .any(|d| longest_side(&d.corners) > MAX_SIDE_PX)
    {
        return 0;
    }
    // The largest markers first: a single pass keeps the top few, largest first.
    let mut largest: [Option<(usize, f32)>; MAX_FITS_PER_FRAME] = [None; MAX_FITS_PER_FRAME];
    for (k, d) in detections.iter().enumerate() {
        let mut entry = Some((k, longest_side(&d.corners)));
        for slot in largest.iter_mut() {
            match (*slot, entry) {
                (Some((_, kept)), Some((_, side))) if side <= kept => {}
                (_, Some(_)) => core::mem::swap(slot, &mut entry),
                (_, None) => break,
            }
        }
    }
    let mut fitted = 0u32;
    for (k, _) in largest.iter().flatten() {
        let Some(detection) = detections.get_mut(*k) else {
            continue;
        };
        let Some(family) = families.get(usize::from(detection.family)) else {
            continue;
        };
        if !tracer.charge(WORK_PATTERN_FIT) {
            break;
        }
        let fit = fit_corners(
            image,
            family,
            detection.id,
            &detection.corners,
            detection.contrast,
        );
        if let Some(corners) = fit {
            detection.corners = corners;
            detection.center = diagonals_meet(&corners).unwrap_or(detection.center);
            fitted += 1;
        }
    }
    fitted
}

#[cfg(test)]
mod tests;
