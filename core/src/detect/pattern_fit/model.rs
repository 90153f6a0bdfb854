//! The model of a decoded marker's image: its known cells, blurred by a Gaussian, at any
//! point of the grid, with the derivatives the fit needs (see the parent module's docs for
//! the model, and [`Pattern`] for what is known of a marker).
//!
//! Per pixel and pass the window's ends are rounded to whole cells by micromath's floor and
//! ceiling, exact on the clamped values they get ([`Axis::set`]) and a third of libm's cost
//! on the Cortex-M7; the blur's `expf` (once per pass) stays libm's, micromath's `exp` being
//! both less precise and dearer there.

// Cell windows are fixed arrays walked by iterators; the normal tables are indexed by a
// clamped index: never by data.
#![allow(clippy::indexing_slicing)]

use super::{MAX_GRID, MAX_WINDOW, WINDOW_SIGMAS};
use crate::family::Family;
use crate::geometry::Point;
use micromath::F32Ext;

/// The known pattern of one decoded marker: which cells are white, in the family's canonical
/// grid (its quiet rings included), and the grid coordinates of the detected corners. What
/// lies beyond the grid is not known: for a family without a quiet ring (ArUco) the printed
/// margin may be narrower than a cell, or the ground; the fit gives it a level of its own.
pub(super) struct Pattern {
    /// Row bitmaps (bit = column), white = 1, of the extended grid.
    pub(super) white: [u32; MAX_GRID],
    /// Cells per side of the extended grid.
    pub(super) side: usize,
    /// Grid coordinate (in the extended grid) of the detected corners' square: its sides.
    pub(super) quad_lo: f32,
    pub(super) quad_hi: f32,
}

impl Pattern {
    pub(super) fn new(family: &Family<'_>, id: u16) -> Option<Pattern> {
        let n = family.grid as usize;
        if n > MAX_GRID || n == 0 || family.reversed() {
            // Reversed families (data outside the border) are found by their inner edge;
            // their layout is not modelled here.
            return None;
        }
        // Only the family's own cells are known. Assuming a printed margin of one cell around
        // a family without a quiet ring put a wrong edge into the model where the margin is
        // narrower (0.6 px off on 32-pixel ArUco markers drawn with a thin one).
        let mut white = [0u32; MAX_GRID];
        family.white_rows(usize::from(id), &mut white)?;
        let b = family.border_ring as f32;
        Some(Pattern {
            white,
            side: n,
            quad_lo: b,
            quad_hi: n as f32 - b,
        })
    }

    /// Whether the cell at grid point (u, v) is white; `None` beyond the known area.
    pub(super) fn colour_at(&self, u: f32, v: f32) -> Option<bool> {
        let side = self.side as f32;
        if !(u >= 0.0 && v >= 0.0 && u < side && v < side) {
            return None;
        }
        Some(self.row_from(v as usize, u as usize) & 1 == 1)
    }

    /// Row `row`'s white bits from column `first` on (bit 0 = column `first`).
    pub(super) fn row_from(&self, row: usize, first: usize) -> u32 {
        let bits = self.white.get(row).copied().unwrap_or(0);
        bits.checked_shr(first as u32).unwrap_or(0)
    }

    /// Grid points of the detected corners, in detection order (clockwise from top-left).
    pub(super) fn corner_points(&self) -> [Point; 4] {
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
pub(super) struct Axis {
    first: usize,
    len: usize,
    /// Per window cell: the mass, its derivative by the point and by the width.
    cells: [Cell; MAX_WINDOW],
    /// The mass beyond the known area's low end (grid coordinate < 0) and beyond its high
    /// end (> cells), with their derivatives: the outside is modelled side by side (see
    /// [`Blurred::outside`]); the known area's mass is the rest ([`Axis::known`]).
    beyond_lo: Cell,
    beyond_hi: Cell,
    /// The mass beyond the printed band beyond each end (see [`Blurred::outside`]), with
    /// its derivatives by the point and the width, and by the band's width in `d_band`.
    far_lo: Far,
    far_hi: Far,
}

/// The Gaussian's mass beyond the band of white paper beyond one end of the known area.
#[derive(Clone, Copy)]
struct Far {
    cell: Cell,
    d_band: f32,
}

impl Far {
    const ZERO: Far = Far {
        cell: Cell::ZERO,
        d_band: 0.0,
    };
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
            (0.5 * core::f64::consts::FRAC_2_SQRT_PI
                * core::f64::consts::FRAC_1_SQRT_2
                * exp_series(-0.5 * z * z)) as f32
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
    sum * core::f64::consts::FRAC_2_SQRT_PI
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
#[derive(Clone, Copy)]
pub(super) struct Cell {
    mass: f32,
    d_pos: f32,
    d_width: f32,
}

impl Cell {
    const ZERO: Cell = Cell {
        mass: 0.0,
        d_pos: 0.0,
        d_width: 0.0,
    };
}

/// Standard normal distribution and density at `z`. The density is interpolated linearly
/// in its table and the distribution is its exact integral from the table point below, so
/// that the density is exactly the distribution's derivative: the fit's derivatives are
/// those of its model, and its steps go where the model's cost falls.
#[inline]
pub(super) fn normal(z: f32) -> (f32, f32) {
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
    #[cfg(test)]
    pub(super) fn new(t: f32, width: f32, cells: usize) -> Option<Axis> {
        let mut axis = Axis::EMPTY;
        axis.set(t, width, cells, [0.0; 2]).map(|()| axis)
    }

    /// An axis of no cells, to be [`Axis::set`].
    pub(super) const EMPTY: Axis = Axis {
        first: 0,
        len: 0,
        cells: [Cell::ZERO; MAX_WINDOW],
        beyond_lo: Cell::ZERO,
        beyond_hi: Cell::ZERO,
        far_lo: Far::ZERO,
        far_hi: Far::ZERO,
    };

    /// Makes this the axis at `t` ([`Axis::new`]) in place: `None` (and the axis unusable)
    /// where there is none. In place because the fit takes two axes per pixel and pass:
    /// built and returned by value, each was cleared and copied (128 bytes, twice), which
    /// was a fifth of the fit's Cortex-M7 instructions. Only the first `len` cells are
    /// written; nothing reads beyond them.
    /// `bands` are the widths (cells) of the printed band beyond the low and the high end.
    pub(super) fn set(&mut self, t: f32, width: f32, cells: usize, bands: [f32; 2]) -> Option<()> {
        self.set_known(t, width, cells)?;
        self.set_bands(t, width, cells, bands);
        Some(())
    }

    /// The bands' part of [`Axis::set`], after [`Axis::set_known`] with the same `t`, `width`
    /// and `cells`: the bands may change without the known area's masses being computed again.
    pub(super) fn set_bands(&mut self, t: f32, width: f32, cells: usize, bands: [f32; 2]) {
        // Beyond the bands: the distribution at their outer ends, `bands` cells beyond the
        // known area's (the same forms as the known area's own ends).
        let inverse = 1.0 / width;
        let far = |z: f32, upper: bool| {
            let (cdf, pdf) = normal(z);
            let sign = if upper { 1.0 } else { -1.0 };
            Far {
                cell: Cell {
                    mass: if upper { 1.0 - cdf } else { cdf },
                    d_pos: sign * pdf * inverse,
                    d_width: sign * pdf * z * inverse,
                },
                d_band: -pdf * inverse,
            }
        };
        // Nothing lies beyond a band where nothing lies beyond the known area (the window
        // does not reach that end): most pixels, and two table reads each saved.
        self.far_lo = if self.beyond_lo.mass > 0.0 {
            far((-bands[0] - t) * inverse, false)
        } else {
            Far::ZERO
        };
        self.far_hi = if self.beyond_hi.mass > 0.0 {
            far((cells as f32 + bands[1] - t) * inverse, true)
        } else {
            Far::ZERO
        };
    }

    /// The known area's part of [`Axis::set`].
    pub(super) fn set_known(&mut self, t: f32, width: f32, cells: usize) -> Option<()> {
        let inverse = 1.0 / width;
        let reach = WINDOW_SIGMAS * width;
        let (lo, hi) = (t - reach, t + reach);
        // The window's first and last cell edges: the floor and ceiling of its ends, within
        // the known area. Clamped before rounding (the same result, `cells` being a whole
        // number; NaN goes to the same end as before), micromath's floor and ceiling (a
        // conversion to an integer and back) are exact: twice per axis and pixel, 6 and 7
        // Cortex-M7 instructions where libm's bit manipulation takes 19 each (see
        // `docs/design/floating-point.md`).
        let cells_f = cells as f32;
        let first = F32Ext::floor(lo.max(0.0).min(cells_f));
        let last = F32Ext::ceil(hi.min(cells_f).max(0.0));
        if lo == f32::INFINITY || hi == f32::NEG_INFINITY || !inverse.is_finite() {
            return None;
        }
        if last <= first {
            // Farther than the window from the known area: only the outside level of the
            // side the point is on.
            let whole = Cell {
                mass: 1.0,
                ..Cell::ZERO
            };
            let (below, above) = if t < 0.0 {
                (whole, Cell::ZERO)
            } else {
                (Cell::ZERO, whole)
            };
            (self.first, self.len, self.beyond_lo, self.beyond_hi) = (0, 0, below, above);
            return Some(());
        }
        let (first, len) = (first as usize, (last - first) as usize);
        if len > MAX_WINDOW {
            return None;
        }
        self.first = first;
        self.len = len;
        let edge = |k: usize| {
            let z = ((first + k) as f32 - t) * inverse;
            let (cdf, pdf) = normal(z);
            (cdf, pdf, z)
        };
        let start = edge(0);
        let mut lower = start;
        for (k, cell) in self.cells.iter_mut().enumerate().take(len) {
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
        let above = if hi > cells_f { lower } else { (1.0, 0.0, 0.0) };
        self.beyond_lo = Cell {
            mass: below.0,
            d_pos: -below.1 * inverse,
            d_width: -below.1 * below.2 * inverse,
        };
        self.beyond_hi = Cell {
            mass: 1.0 - above.0,
            d_pos: above.1 * inverse,
            d_width: above.1 * above.2 * inverse,
        };
        Some(())
    }

    /// The Gaussian's mass in the printed bands beyond both ends, and its derivatives by
    /// the point and the width.
    fn band_mass(&self) -> Cell {
        let (lo, hi) = (&self.beyond_lo, &self.beyond_hi);
        let (far_lo, far_hi) = (&self.far_lo.cell, &self.far_hi.cell);
        Cell {
            mass: lo.mass - far_lo.mass + hi.mass - far_hi.mass,
            d_pos: lo.d_pos - far_lo.d_pos + hi.d_pos - far_hi.d_pos,
            d_width: lo.d_width - far_lo.d_width + hi.d_width - far_hi.d_width,
        }
    }

    /// The Gaussian's mass past the bands, each end's weighted by its level (`low`, `high`)
    /// less white, and its derivatives by the point and the width.
    fn past_mass(&self, low: f32, high: f32) -> Cell {
        let (lo, hi) = (&self.far_lo.cell, &self.far_hi.cell);
        let (a, b) = (low - 1.0, high - 1.0);
        Cell {
            mass: a * lo.mass + b * hi.mass,
            d_pos: a * lo.d_pos + b * hi.d_pos,
            d_width: a * lo.d_width + b * hi.d_width,
        }
    }

    /// The Gaussian's mass over the known area and its derivatives: all that is not
    /// beyond either end.
    fn known(&self) -> Cell {
        let (lo, hi) = (&self.beyond_lo, &self.beyond_hi);
        Cell {
            mass: 1.0 - lo.mass - hi.mass,
            d_pos: -(lo.d_pos + hi.d_pos),
            d_width: -(lo.d_width + hi.d_width),
        }
    }
}

/// The sides of the outside, in grid coordinates: beyond u = 0, beyond u = cells, beyond
/// v = 0 and beyond v = cells (left, right, top, bottom). A corner quadrant lies beyond two
/// sides and reads their mean; each side's Gaussian mass is a product of one-axis masses, so
/// the model stays separable.
pub(super) const SIDES: usize = 4;

/// The blurred pattern at one point and its derivatives.
pub(super) struct Blurred {
    pub(super) value: f32,
    pub(super) d_u: f32,
    pub(super) d_v: f32,
    pub(super) d_width_u: f32,
    pub(super) d_width_v: f32,
    /// By the width of the printed band beyond each side ([`SIDES`]).
    pub(super) d_band: [f32; SIDES],
    /// Weight of each side's outside level ([`SIDES`]): the Gaussian's mass beyond the
    /// known area on that side. One level for all four sides was wrong wherever the ground
    /// differs around the pattern (a pad on grass: dark ground on three sides of the large
    /// marker, the white sheet with the small markers on the fourth), and the fit then
    /// moved the edges next to the mismatch: -0.75 % in width and +0.40 % in height on the
    /// landing's 18-pixel marker at 40 m.
    pub(super) outside: [f32; SIDES],
}

/// The blurred pattern at the point of `u` and `v`, outside levels `outside_levels`.
pub(super) fn blurred(
    pattern: &Pattern,
    u: &Axis,
    v: &Axis,
    outside_levels: &[f32; SIDES],
) -> Blurred {
    with_outside(&known_cells(pattern, u, v), u, v, outside_levels)
}

/// The known cells' part of [`blurred`]: its value and derivatives without the outside.
pub(super) struct Known {
    value: f32,
    d_u: f32,
    d_v: f32,
    d_width_u: f32,
    d_width_v: f32,
}

/// The known cells' part of the blurred pattern: the same whatever the bands and levels
/// beyond them.
pub(super) fn known_cells(pattern: &Pattern, u: &Axis, v: &Axis) -> Known {
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
    Known {
        value,
        d_u,
        d_v,
        d_width_u: d_wu,
        d_width_v: d_wv,
    }
}

/// The blurred pattern from its known cells' part, `u` and `v`'s bands and the outside
/// levels.
pub(super) fn with_outside(
    known: &Known,
    u: &Axis,
    v: &Axis,
    outside_levels: &[f32; SIDES],
) -> Blurred {
    let (value, mut d_u, mut d_v) = (known.value, known.d_u, known.d_v);
    let (mut d_wu, mut d_wv) = (known.d_width_u, known.d_width_v);
    let [left, right, top, bottom] = *outside_levels;
    // Beyond the known u range (left and right) and beyond the known v range (top and
    // bottom), each weighted by its one-axis masses; a corner quadrant (beyond both) reads
    // the mean of its two sides, so no side is favoured there. The weight of the u sides is
    // then their mass times (known v + half the rest), (1 + known v) / 2. Each side is white
    // paper for the band's width and its own level beyond it.
    let lo_u = side(&u.beyond_lo, &u.far_lo, left);
    let hi_u = side(&u.beyond_hi, &u.far_hi, right);
    let lo_v = side(&v.beyond_lo, &v.far_lo, top);
    let hi_v = side(&v.beyond_hi, &v.far_hi, bottom);
    let beyond_u = lo_u.value + hi_u.value;
    let beyond_v = lo_v.value + hi_v.value;
    let (known_u, known_v) = (u.known(), v.known());
    let (along_u, along_v) = (0.5 * (1.0 + known_v.mass), 0.5 * (1.0 + known_u.mass));
    // The outside's part of a derivative along one axis: that axis's two sides through their
    // own derivatives (`sides`), and the other axis's sides through this axis's known mass
    // (`known`, half of it: the corner quadrants).
    let part =
        |weight: f32, sides: f32, known: f32, other: f32| weight * sides + 0.5 * known * other;
    d_u += part(along_u, lo_u.d_pos + hi_u.d_pos, known_u.d_pos, beyond_v);
    d_v += part(along_v, lo_v.d_pos + hi_v.d_pos, known_v.d_pos, beyond_u);
    d_wu += part(
        along_u,
        lo_u.d_width + hi_u.d_width,
        known_u.d_width,
        beyond_v,
    );
    d_wv += part(
        along_v,
        lo_v.d_width + hi_v.d_width,
        known_v.d_width,
        beyond_u,
    );
    // The corner quadrants again: the mean of two sides is right where both are past their
    // bands, or both in them, but where one is in its band and the other past its own, the
    // point is off the sheet (a sheet's corner is square) and reads that other side's
    // level, not the mean with white. Half of each such product is added back: with `W` an
    // axis's mass in its bands and `P` its mass past them weighted by (level - 1), that is
    // (W_v P_u + W_u P_v) / 2.
    let (band_u, past_u) = (u.band_mass(), u.past_mass(left, right));
    let (band_v, past_v) = (v.band_mass(), v.past_mass(top, bottom));
    let corner = 0.5 * (band_v.mass * past_u.mass + band_u.mass * past_v.mass);
    d_u += 0.5 * (band_v.mass * past_u.d_pos + band_u.d_pos * past_v.mass);
    d_v += 0.5 * (band_v.d_pos * past_u.mass + band_u.mass * past_v.d_pos);
    d_wu += 0.5 * (band_v.mass * past_u.d_width + band_u.d_width * past_v.mass);
    d_wv += 0.5 * (band_v.d_width * past_u.mass + band_u.mass * past_v.d_width);
    // A side's band moves its far mass out (`d_band`) and its band mass in by as much.
    let band_term = |far: &Far, level: f32, other_band: f32, other_past: f32| {
        0.5 * far.d_band * (other_band * (level - 1.0) - other_past)
    };
    Blurred {
        value: value + along_u * beyond_u + along_v * beyond_v + corner,
        d_u,
        d_v,
        d_width_u: d_wu,
        d_width_v: d_wv,
        d_band: [
            along_u * lo_u.d_band + band_term(&u.far_lo, left, band_v.mass, past_v.mass),
            along_u * hi_u.d_band + band_term(&u.far_hi, right, band_v.mass, past_v.mass),
            along_v * lo_v.d_band + band_term(&v.far_lo, top, band_u.mass, past_u.mass),
            along_v * hi_v.d_band + band_term(&v.far_hi, bottom, band_u.mass, past_u.mass),
        ],
        outside: [
            (along_u + 0.5 * band_v.mass) * u.far_lo.cell.mass,
            (along_u + 0.5 * band_v.mass) * u.far_hi.cell.mass,
            (along_v + 0.5 * band_u.mass) * v.far_lo.cell.mass,
            (along_v + 0.5 * band_u.mass) * v.far_hi.cell.mass,
        ],
    }
}

/// One side of the outside at a point: its part of the blurred pattern, and that part's
/// derivatives.
struct Side {
    value: f32,
    d_pos: f32,
    d_width: f32,
    d_band: f32,
}

/// The side whose mass beyond the known area is `beyond` and beyond its band `far`: white
/// paper (1) in the band, `level` past it.
fn side(beyond: &Cell, far: &Far, level: f32) -> Side {
    let past = level - 1.0;
    Side {
        value: beyond.mass + past * far.cell.mass,
        d_pos: beyond.d_pos + past * far.cell.d_pos,
        d_width: beyond.d_width + past * far.cell.d_width,
        d_band: past * far.d_band,
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// The window as it was computed with libm's floor and ceiling, before micromath's:
    /// `None` where that returned `None`, else (first, len, beyond_lo mass, beyond_hi mass).
    fn libm_window(t: f32, width: f32, cells: usize) -> Option<(usize, usize, f32, f32)> {
        let inverse = 1.0 / width;
        let reach = WINDOW_SIGMAS * width;
        let (lo, hi) = (libm::floorf(t - reach), libm::ceilf(t + reach));
        let (first, last) = (lo.max(0.0), hi.min(cells as f32));
        if !(first.is_finite() && last.is_finite() && inverse.is_finite()) {
            return None;
        }
        if last <= first {
            return Some(if t < 0.0 {
                (0, 0, 1.0, 0.0)
            } else {
                (0, 0, 0.0, 1.0)
            });
        }
        let (first, len) = (first as usize, (last - first) as usize);
        (len <= MAX_WINDOW).then_some((first, len, f32::NAN, f32::NAN))
    }

    /// The model's derivatives are its own: central differences of the blurred value by the
    /// point, the widths and each band, and the value's change per outside level, at points
    /// inside, beside and beyond the known area, corners included.
    #[test]
    fn the_derivatives_are_the_models() {
        let family = &crate::family::tables::TAG36H11;
        let pattern = Pattern::new(family, 7).unwrap();
        let cells = pattern.side;
        let levels = [0.2f32, 0.45, 0.1, 0.7];
        let bands = [0.8f32, 1.6, 0.4, 1.2];
        let at = |u: f32, v: f32, wu: f32, wv: f32, bands: [f32; 4], levels: &[f32; 4]| {
            let (mut au, mut av) = (Axis::EMPTY, Axis::EMPTY);
            au.set(u, wu, cells, [bands[0], bands[1]]).unwrap();
            av.set(v, wv, cells, [bands[2], bands[3]]).unwrap();
            blurred(&pattern, &au, &av, levels)
        };
        let h = 1e-2f32;
        let mut checked = 0;
        for (u, v) in [
            (4.3f32, 5.1f32),
            (-0.4, 3.3),
            (10.6, 6.2),
            (2.2, -1.3),
            (7.7, 11.1),
            (-1.2, -0.9),
            (11.4, 10.8),
            (-2.3, 10.5),
            (0.3, 9.8),
        ] {
            for (wu, wv) in [(0.5f32, 0.6f32), (0.9, 0.7)] {
                // The known cells' window ends on whole cells 3 widths out, and its cells
                // change where an end crosses one: no derivative there.
                let near_whole = |x: f32| (x - libm::roundf(x)).abs() < 4.0 * h;
                let ends = [u - 3.0 * wu, u + 3.0 * wu, v - 3.0 * wv, v + 3.0 * wv];
                if ends.iter().any(|&e| near_whole(e)) {
                    continue;
                }
                let b = at(u, v, wu, wv, bands, &levels);
                let diff = |f: &dyn Fn(f32) -> f32| (f(h) - f(-h)) / (2.0 * h);
                let mut pairs = std::vec![
                    (
                        "u",
                        b.d_u,
                        diff(&|d| at(u + d, v, wu, wv, bands, &levels).value)
                    ),
                    (
                        "v",
                        b.d_v,
                        diff(&|d| at(u, v + d, wu, wv, bands, &levels).value)
                    ),
                    (
                        "wu",
                        b.d_width_u,
                        diff(&|d| at(u, v, wu + d, wv, bands, &levels).value)
                    ),
                    (
                        "wv",
                        b.d_width_v,
                        diff(&|d| at(u, v, wu, wv + d, bands, &levels).value)
                    ),
                ];
                for k in 0..SIDES {
                    let by_band = diff(&|d| {
                        let mut moved = bands;
                        moved[k] += d;
                        at(u, v, wu, wv, moved, &levels).value
                    });
                    pairs.push(("band", b.d_band[k], by_band));
                    let by_level = diff(&|d| {
                        let mut l = levels;
                        l[k] += d;
                        at(u, v, wu, wv, bands, &l).value
                    });
                    pairs.push(("level", b.outside[k], by_level));
                }
                for (name, got, want) in pairs {
                    assert!(
                        (got - want).abs() < 2e-3 + 0.01 * want.abs(),
                        "({u}, {v}) widths ({wu}, {wv}): d/d{name} {got} against {want}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked >= 120, "{checked}");
    }

    #[test]
    fn window_bounds_are_libms_for_every_input() {
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
            -1e30,
            3e9,
            -3e9,
        ];
        let mut ts: heapless::Vec<f32, 4096> = heapless::Vec::new();
        for k in -1600..=1600 {
            let _ = ts.push(k as f32 * 0.0137);
        }
        for (k, &s) in specials.iter().enumerate() {
            let _ = ts.push(s);
            let _ = ts.push(k as f32 + 0.5);
            let _ = ts.push(k as f32);
            let _ = ts.push(-(k as f32));
        }
        let widths = [
            0.05,
            0.3,
            0.5,
            0.77,
            1.0,
            1.3,
            2.0,
            40.0,
            0.0,
            -0.5,
            f32::NAN,
            f32::INFINITY,
            1e30,
        ];
        let mut compared = 0;
        for cells in [8usize, 10, 16] {
            for &width in &widths {
                for &t in &ts {
                    let want = libm_window(t, width, cells);
                    let got = Axis::new(t, width, cells);
                    assert_eq!(
                        got.is_some(),
                        want.is_some(),
                        "t {t} width {width} cells {cells}"
                    );
                    let (Some(got), Some((first, len, lo_mass, hi_mass))) = (got, want) else {
                        continue;
                    };
                    assert_eq!((got.first, got.len), (first, len), "t {t} width {width}");
                    if len == 0 {
                        assert_eq!(got.beyond_lo.mass, lo_mass, "t {t} width {width}");
                        assert_eq!(got.beyond_hi.mass, hi_mass, "t {t} width {width}");
                    }
                    compared += 1;
                }
            }
        }
        assert!(compared > 50_000, "{compared}");
    }
}
