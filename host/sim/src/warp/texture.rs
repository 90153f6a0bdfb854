//! The warp renderer's pre-rasterised world: the printed pad as summed-area tables of its
//! cells, and the ground's albedo as a mirrored texture pyramid.
//!
//! The pad is piecewise constant on its cells, so a summed-area table at cell resolution is
//! exact: the integral of the albedo from the grid's corner is bilinear inside each cell,
//! and a box of any size and position is averaged with four interpolated reads. Edges stay
//! as sharp as the box, at 40 m and at 0.3 m alike, with a table of a few hundred entries
//! per marker. Each marker's table covers its paper square (grid and white margin) in its
//! own frame; the sheet around the markers is an axis-aligned rectangle, averaged in closed
//! form.
//!
//! The ground is sampled from [`GroundTexture::albedo`] once, at [`GROUND_TEXEL_M`], over a
//! square of [`GROUND_TEXELS`] texels, and read with mirrored repeat: the ground beyond the
//! square is its mirror image, which has no seams (clutter around the pad, not a place to
//! recognise). Coarser levels average 2x2 texels; a read is trilinear between the two levels
//! around the footprint's size.

use crate::pad::{PrintedPad, Rect};
use crate::texture::{GroundKind, GroundTexture};
use crate::world::{INK_ALBEDO, PAPER_ALBEDO};

/// Ground texel at the finest level, metres: the grass's finest octave (8 mm) still shows.
pub const GROUND_TEXEL_M: f64 = 0.004;
/// Texels per side of the ground sampled at the finest level (a power of two): 4.1 m, then
/// mirrored.
pub const GROUND_TEXELS: usize = 1024;

/// Smallest box side, in cells or metres, so that a box never has zero area.
const MIN_WIDTH: f64 = 1e-4;

/// Where in an octave of footprint sizes the blend toward the coarser level starts, and over
/// how much of it the blend runs (trilinear filtering is 0 and 1).
const BLEND_START: f64 = 0.35;
const BLEND_WIDTH: f64 = 0.3;

/// Fraction bits of the fixed-point texel coordinates.
const FRACTION_BITS: u32 = 16;

/// One level of the ground pyramid: `2^shift` texels per side, row-major, the mirror image
/// stored whole so that a read wraps with a mask.
#[derive(Clone)]
struct Level {
    shift: u32,
    texels: Vec<f32>,
}

fn to_texel(albedo: f32) -> f32 {
    albedo.clamp(0.0, 1.0)
}

/// The ground's albedo, pre-rasterised.
#[derive(Clone)]
pub(crate) struct GroundPyramid {
    levels: Vec<Level>,
    /// Pad-frame point of texel (0, 0)'s corner: the pad sits mid-square, far from a mirror
    /// line.
    origin: [f64; 2],
}

impl GroundPyramid {
    /// Rasterises `ground` (on `threads` threads; the texels do not depend on it).
    pub(crate) fn new(ground: &GroundTexture, threads: usize) -> Self {
        if let GroundKind::Flat(a) = ground.kind {
            return GroundPyramid {
                levels: vec![Level {
                    shift: 0,
                    texels: vec![to_texel(a)],
                }],
                origin: [0.0; 2],
            };
        }
        let n = GROUND_TEXELS;
        let half = 0.5 * n as f64 * GROUND_TEXEL_M;
        let origin = [-half, -half];
        let mut base = vec![0.0f32; n * n];
        let threads = threads.clamp(1, n);
        let rows_per_band = n.div_ceil(threads);
        std::thread::scope(|scope| {
            for (band, chunk) in base.chunks_mut(rows_per_band * n).enumerate() {
                let mut job = move || {
                    let mut points = Vec::with_capacity(n);
                    for (r, row) in chunk.chunks_mut(n).enumerate() {
                        let j = band * rows_per_band + r;
                        let y = origin[1] + (j as f64 + 0.5) * GROUND_TEXEL_M;
                        points.clear();
                        points.extend((0..n).map(|i| {
                            [
                                origin[0] + (i as f64 + 0.5) * GROUND_TEXEL_M,
                                y,
                                GROUND_TEXEL_M,
                            ]
                        }));
                        ground.albedo_batch(&points, row);
                    }
                };
                if threads == 1 {
                    job();
                } else {
                    scope.spawn(job);
                }
            }
        });
        // The mirror images stored whole: texel k and 2n - 1 - k are the same, so a read
        // wraps with a mask at the period 2n.
        let side = 2 * n;
        let mut mirrored = vec![0.0f32; side * side];
        for (j, row) in mirrored.chunks_mut(side).enumerate() {
            let sj = j.min(side - 1 - j);
            for (i, t) in row.iter_mut().enumerate() {
                *t = base[sj * n + i.min(side - 1 - i)];
            }
        }
        let base = mirrored;
        let mut levels = vec![Level {
            shift: side.trailing_zeros(),
            texels: base.iter().map(|&a| to_texel(a)).collect(),
        }];
        let mut finer = base;
        while let Some(last) = levels.last() {
            if last.shift == 0 {
                break;
            }
            let (size, shift) = (1usize << (last.shift - 1), last.shift - 1);
            let from = 1usize << last.shift;
            // Averaged in f32 from the finer level's f32 values, then stored.
            let mut coarser = Vec::with_capacity(size * size);
            for j in 0..size {
                for i in 0..size {
                    let at = |di: usize, dj: usize| finer[(2 * j + dj) * from + 2 * i + di];
                    coarser.push(0.25 * (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)));
                }
            }
            levels.push(Level {
                shift,
                texels: coarser.iter().map(|&a| to_texel(a)).collect(),
            });
            finer = coarser;
        }
        GroundPyramid { levels, origin }
    }

    /// Mean albedo over a footprint about `sqrt(footprint2_m2)` metres across around
    /// `(x, y)`: bilinear in the level whose texels match the footprint, blended with the next
    /// coarser one in the middle of the octave.
    #[inline(always)]
    pub(crate) fn sample(&self, x: f64, y: f64, footprint2_m2: f64) -> f64 {
        let Some(first) = self.levels.first() else {
            return 0.0;
        };
        if first.shift == 0 {
            return f64::from(first.texels.first().copied().unwrap_or(0.0));
        }
        const INV_TEXEL: f64 = 1.0 / GROUND_TEXEL_M;
        let top = (self.levels.len() - 1) as f64;
        // log2 of the footprint's size from its square: no square root.
        let lod = (0.5 * fast_log2(footprint2_m2 * (INV_TEXEL * INV_TEXEL))).clamp(0.0, top);
        let l0 = lod as i64;
        // Blended across the middle of each octave only: most samples read one level (half
        // the cost), and the blur still changes continuously with the footprint.
        let t = (((lod - l0 as f64) - BLEND_START) * (1.0 / BLEND_WIDTH)).clamp(0.0, 1.0) as f32;
        let l0 = l0 as usize;
        // Fixed-point texel coordinates of the finest level, with the texel centres at
        // integers (`- 0.5`); a coarser level's are these halved, shifted by the same half.
        const ONE: f64 = (1u64 << FRACTION_BITS) as f64;
        let u = ((x - self.origin[0]) * (INV_TEXEL * ONE)) as i64;
        let v = ((y - self.origin[1]) * (INV_TEXEL * ONE)) as i64;
        let a = self.bilinear(l0, u, v);
        if t <= 0.0 || l0 + 1 >= self.levels.len() {
            return f64::from(a);
        }
        if t >= 1.0 {
            return f64::from(self.bilinear(l0 + 1, u, v));
        }
        f64::from(a + t * (self.bilinear(l0 + 1, u, v) - a))
    }

    /// Level `level` at the finest level's fixed-point texel corner coordinates `(u, v)`.
    #[inline(always)]
    fn bilinear(&self, level: usize, u: i64, v: i64) -> f32 {
        let Some(l) = self.levels.get(level) else {
            return 0.0;
        };
        const HALF: i64 = 1 << (FRACTION_BITS - 1);
        const FRACTION: i64 = (1 << FRACTION_BITS) - 1;
        const SCALE: f32 = 1.0 / (1u32 << FRACTION_BITS) as f32;
        // Arithmetic shifts floor negative coordinates too.
        let (u, v) = ((u >> level) - HALF, (v >> level) - HALF);
        let (fu, fv) = ((u & FRACTION) as f32 * SCALE, (v & FRACTION) as f32 * SCALE);
        let mask = (1i64 << l.shift) - 1;
        let (i0, j0) = (u >> FRACTION_BITS, v >> FRACTION_BITS);
        let (i0, i1) = ((i0 & mask) as usize, ((i0 + 1) & mask) as usize);
        let (j0, j1) = (
            ((j0 & mask) as usize) << l.shift,
            (((j0 + 1) & mask) as usize) << l.shift,
        );
        let texels = &l.texels;
        let at = |k: usize| texels.get(k).copied().unwrap_or(0.0);
        let (a, b, c, d) = (at(j0 | i0), at(j0 | i1), at(j1 | i0), at(j1 | i1));
        let top = a + fu * (b - a);
        let bottom = c + fu * (d - c);
        top + fv * (bottom - top)
    }
}

/// `log2(v)` to within 0.09, monotonic, exact at powers of two (the exponent plus the
/// mantissa read as a line): enough to pick and blend mip levels. 0 for `v <= 0`.
#[inline]
fn fast_log2(v: f64) -> f64 {
    if v.is_nan() || v <= 0.0 {
        return 0.0;
    }
    let bits = v.to_bits();
    let exponent = ((bits >> 52) & 0x7ff) as i64 - 1023;
    // Through i64: a u64 to f64 conversion is a branchy sequence on x86-64.
    let mantissa = (bits & ((1u64 << 52) - 1)) as i64 as f64 * (1.0 / (1u64 << 52) as f64);
    exponent as f64 + mantissa
}

/// A pixel's footprint on the ground for box filtering: its centre and its "width squared"
/// matrix `W` (pad frame, metres squared: for a parallelogram spanned by `a` and `b`,
/// `a a^T + b b^T`, plus the motion's spread), whose `e^T W e` is the square of the width
/// of the box with the footprint's variance along the unit direction `e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Footprint {
    /// Centre, pad frame, metres.
    pub x: f64,
    /// Centre, pad frame, metres.
    pub y: f64,
    /// `W_xx`.
    pub wxx: f64,
    /// `W_xy`.
    pub wxy: f64,
    /// `W_yy`.
    pub wyy: f64,
}

impl Footprint {
    /// The squared width along `(ex, ey)` (any length: the width scales with it).
    #[inline]
    pub(crate) fn width2(&self, ex: f64, ey: f64) -> f64 {
        ex * ex * self.wxx + 2.0 * ex * ey * self.wxy + ey * ey * self.wyy
    }

    /// The square of the longest width, to within a factor of two: the larger eigenvalue of
    /// `W` bounded from above by its larger diagonal element plus the off-diagonal one
    /// (Gershgorin; exact for a footprint stretched along an axis or a diagonal).
    #[inline]
    pub(crate) fn longest2(&self) -> f64 {
        self.wxx.max(self.wyy) + self.wxy.abs()
    }
}

/// Fraction of the interval of width `w` centred on `c` that lies in `[lo, hi]`.
#[inline]
fn overlap(c: f64, w: f64, lo: f64, hi: f64) -> f64 {
    let h = 0.5 * w;
    ((c + h).min(hi) - (c - h).max(lo)).clamp(0.0, w) / w
}

/// One marker's paper square: its summed-area table and where it lies.
#[derive(Clone)]
struct MarkerTable {
    centre: [f64; 2],
    /// `cos yaw`, `sin yaw`.
    rotation: (f64, f64),
    inv_cell: f64,
    /// Half the paper square, cells.
    half_cells: f64,
    /// Cells per side of the paper square.
    n: usize,
    /// `(n + 1)^2` sums: entry `(r, c)` is the albedo summed over the cells above row `r` and
    /// left of column `c` (cell areas 1).
    sat: Vec<f64>,
    /// Pad-frame bounds of the paper square.
    bounds: Rect,
    /// The albedo of each cell, row-major `n x n`.
    cells: Vec<f32>,
    /// How its axes lie on the pad's.
    axes: Axes,
}

/// How a marker's axes lie on the pad's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Axes {
    /// Along them (turned by 0 or 180 degrees).
    Same,
    /// Across them (turned by 90 or 270 degrees).
    Swapped,
    /// Turned by another angle.
    Turned,
}

impl MarkerTable {
    /// The integral of the summed area at fractional grid point `(c, r)` (in `[0, n]`).
    #[inline]
    fn integral(&self, c: f64, r: f64) -> f64 {
        let n = self.n;
        let last = n as i64 - 1;
        let (i, j) = ((c as i64).min(last), (r as i64).min(last));
        let (fc, fr) = (c - i as f64, r - j as f64);
        let (i, j) = (i as usize, j as usize);
        let s = n + 1;
        let at = |i: usize, j: usize| self.sat.get(j * s + i).copied().unwrap_or(0.0);
        let top = at(i, j) + fc * (at(i + 1, j) - at(i, j));
        let bottom = at(i, j + 1) + fc * (at(i + 1, j + 1) - at(i, j + 1));
        top + fr * (bottom - top)
    }
}

/// The printed pad, pre-rasterised.
#[derive(Clone)]
pub(crate) struct PadTables {
    sheet: Rect,
    markers: Vec<MarkerTable>,
}

/// What the pad contributes to a footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PadCover {
    /// Albedo times area fraction, summed over the printed paper.
    pub albedo_sum: f64,
    /// Fraction of the footprint on the printed paper.
    pub paper: f64,
}

impl PadTables {
    pub(crate) fn new(pad: &PrintedPad) -> Self {
        let markers = pad
            .markers
            .iter()
            .map(|m| {
                let margin = m.margin_cells.max(0.0).round() as usize;
                let grid = m.grid();
                let n = grid + 2 * margin;
                let s = n + 1;
                let mut sat = vec![0.0f64; s * s];
                let mut cells = Vec::with_capacity(n * n);
                for r in 0..n {
                    let mut row_sum = 0.0;
                    for c in 0..n {
                        let inside = (margin..margin + grid).contains(&r)
                            && (margin..margin + grid).contains(&c);
                        let white = !inside || m.pattern.is_white(r - margin, c - margin);
                        let albedo = if white { PAPER_ALBEDO } else { INK_ALBEDO };
                        cells.push(albedo);
                        row_sum += f64::from(albedo);
                        sat[(r + 1) * s + c + 1] = sat[r * s + c + 1] + row_sum;
                    }
                }
                let yaw = m.yaw_deg.to_radians();
                let half = 0.5 * n as f64 * m.cell;
                let mut bounds = Rect {
                    x0: f64::INFINITY,
                    x1: f64::NEG_INFINITY,
                    y0: f64::INFINITY,
                    y1: f64::NEG_INFINITY,
                };
                for (lx, ly) in [(-half, -half), (half, -half), (half, half), (-half, half)] {
                    let [x, y] = m.to_pad(lx, ly);
                    bounds.x0 = bounds.x0.min(x);
                    bounds.x1 = bounds.x1.max(x);
                    bounds.y0 = bounds.y0.min(y);
                    bounds.y1 = bounds.y1.max(y);
                }
                MarkerTable {
                    centre: [m.x, m.y],
                    rotation: (yaw.cos(), yaw.sin()),
                    inv_cell: 1.0 / m.cell,
                    half_cells: 0.5 * n as f64,
                    n: n.max(1),
                    sat,
                    bounds,
                    cells,
                    axes: if yaw.sin().abs() < 1e-12 {
                        Axes::Same
                    } else if yaw.cos().abs() < 1e-12 {
                        Axes::Swapped
                    } else {
                        Axes::Turned
                    },
                }
            })
            .collect();
        PadTables {
            sheet: pad.sheet,
            markers,
        }
    }

    /// Whether the footprint's box may reach the sheet (compared squared: most pixels are
    /// ground, and need no square root).
    #[inline]
    pub(crate) fn near(&self, f: &Footprint) -> bool {
        let s = &self.sheet;
        let beyond = |gap: f64, w2: f64| gap > 0.0 && 4.0 * gap * gap > w2;
        !(beyond(s.x0 - f.x, f.wxx)
            || beyond(f.x - s.x1, f.wxx)
            || beyond(s.y0 - f.y, f.wyy)
            || beyond(f.y - s.y1, f.wyy))
    }

    /// The pad's share of a footprint, `None` when the footprint's box misses the sheet.
    #[inline]
    pub(crate) fn cover(&self, f: &Footprint, hint: &mut usize) -> Option<PadCover> {
        if !self.near(f) {
            return None;
        }
        let wx = f.wxx.max(0.0).sqrt().max(MIN_WIDTH * 1e-2);
        let wy = f.wyy.max(0.0).sqrt().max(MIN_WIDTH * 1e-2);
        let (hx, hy) = (0.5 * wx, 0.5 * wy);
        let mut albedo_sum = 0.0;
        let mut printed = 0.0;
        // Neighbouring pixels mostly see the same marker: the last one found is tried first.
        let count = self.markers.len();
        let first = (*hint).min(count.saturating_sub(1));
        for k in 0..count {
            let index = if k == 0 {
                first
            } else if k <= first {
                k - 1
            } else {
                k
            };
            let Some(m) = self.markers.get(index) else {
                continue;
            };
            let b = &m.bounds;
            if f.x + hx < b.x0 || f.x - hx > b.x1 || f.y + hy < b.y0 || f.y - hy > b.y1 {
                continue;
            }
            let (c, s) = m.rotation;
            let (dx, dy) = (f.x - m.centre[0], f.y - m.centre[1]);
            // Grid coordinates: columns along the marker's x, rows down its y.
            let col = (c * dx + s * dy) * m.inv_cell + m.half_cells;
            let row = m.half_cells - (-s * dx + c * dy) * m.inv_cell;
            // The widths along the marker's axes: those along the pad's for an unturned
            // marker (no square roots).
            let (wc, wr) = if m.axes == Axes::Same {
                (wx * m.inv_cell, wy * m.inv_cell)
            } else if m.axes == Axes::Swapped {
                (wy * m.inv_cell, wx * m.inv_cell)
            } else {
                (
                    f.width2(c, s).max(0.0).sqrt() * m.inv_cell,
                    f.width2(s, -c).max(0.0).sqrt() * m.inv_cell,
                )
            };
            let (wc, wr) = (wc.max(MIN_WIDTH), wr.max(MIN_WIDTH));
            let n = m.n as f64;
            let (c0, c1) = (col - 0.5 * wc, col + 0.5 * wc);
            let (r0, r1) = (row - 0.5 * wr, row + 0.5 * wr);
            if c0 >= 0.0 && r0 >= 0.0 && c1 <= n && r1 <= n {
                *hint = index;
                // Wholly on this marker's paper (the squares do not overlap): one cell's
                // albedo, or the table's average.
                let (i, j) = (c0 as i64 as usize, r0 as i64 as usize);
                if c1 < (i as i64 + 1) as f64 && r1 < (j as i64 + 1) as f64 {
                    let albedo = m.cells.get(j * m.n + i).copied().unwrap_or(PAPER_ALBEDO);
                    return Some(PadCover {
                        albedo_sum: f64::from(albedo),
                        paper: 1.0,
                    });
                }
                let integral = m.integral(c1, r1) - m.integral(c0, r1) - m.integral(c1, r0)
                    + m.integral(c0, r0);
                return Some(PadCover {
                    albedo_sum: integral / (wc * wr),
                    paper: 1.0,
                });
            }
            let (c0, c1) = (c0.max(0.0), c1.min(n));
            let (r0, r1) = (r0.max(0.0), r1.min(n));
            if c1 <= c0 || r1 <= r0 {
                continue;
            }
            let inv_area = 1.0 / (wc * wr);
            let integral =
                m.integral(c1, r1) - m.integral(c0, r1) - m.integral(c1, r0) + m.integral(c0, r0);
            albedo_sum += integral * inv_area;
            printed += (c1 - c0) * (r1 - r0) * inv_area;
        }
        let s = &self.sheet;
        let sheet = overlap(f.x, wx, s.x0, s.x1) * overlap(f.y, wy, s.y0, s.y1);
        // The sheet's white beyond the markers' squares (the two boxes, in the pad's and the
        // markers' frames, have the same widths along their axes but not the same shape).
        let plain = (sheet - printed).max(0.0);
        Some(PadCover {
            albedo_sum: albedo_sum + plain * f64::from(PAPER_ALBEDO),
            paper: printed + plain,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_log2_brackets_the_log() {
        for v in [0.3, 1.0, 1.5, 2.0, 3.9, 1000.0] {
            let l = fast_log2(v);
            assert!((l - f64::log2(v)).abs() < 0.09, "{v}: {l}");
        }
    }

    #[test]
    fn the_summed_area_table_averages_cells_exactly() {
        let pad = PrintedPad::design("paper-single").expect("shipped design");
        let tables = PadTables::new(&pad);
        let m = &tables.markers[0];
        // The whole paper square's integral is the sum of its cells.
        let n = m.n as f64;
        let total = m.integral(n, n);
        let mut expected = 0.0;
        let margin = 1;
        let grid = pad.markers[0].grid();
        for r in 0..m.n {
            for c in 0..m.n {
                let inside =
                    (margin..margin + grid).contains(&r) && (margin..margin + grid).contains(&c);
                let white = !inside || pad.markers[0].pattern.is_white(r - margin, c - margin);
                expected += f64::from(if white { PAPER_ALBEDO } else { INK_ALBEDO });
            }
        }
        assert!((total - expected).abs() < 1e-9, "{total} {expected}");
    }

    #[test]
    fn a_box_across_a_cell_edge_is_the_area_mix_of_its_cells() {
        let pad = PrintedPad::design("paper-single").expect("shipped design");
        let tables = PadTables::new(&pad);
        let m = &pad.markers[0];
        // The black border's outer edge: column 0 of the grid is black, the margin white.
        let [x0, y0] = m.to_pad(-0.5 * m.size, 0.0);
        let side = 0.25 * m.cell;
        for (shift, black) in [
            (0.0, 0.5),
            (0.25 * side, 0.75),
            (-0.25 * side, 0.25),
            (side, 1.0),
        ] {
            let f = Footprint {
                x: x0 + shift,
                y: y0,
                wxx: side * side,
                wxy: 0.0,
                wyy: side * side,
            };
            let cover = tables.cover(&f, &mut 0).expect("on the pad");
            let expected = black * f64::from(INK_ALBEDO) + (1.0 - black) * f64::from(PAPER_ALBEDO);
            assert!((cover.paper - 1.0).abs() < 1e-9, "{cover:?}");
            assert!(
                (cover.albedo_sum - expected).abs() < 1e-6,
                "{shift}: {cover:?}"
            );
        }
        // Half off the sheet's edge: half paper.
        let f = Footprint {
            x: pad.sheet.x1,
            y: 0.0,
            wxx: side * side,
            wxy: 0.0,
            wyy: side * side,
        };
        let cover = tables.cover(&f, &mut 0).expect("on the sheet's edge");
        assert!((cover.paper - 0.5).abs() < 1e-9, "{cover:?}");
        assert!((cover.albedo_sum - 0.5 * f64::from(PAPER_ALBEDO)).abs() < 1e-6);
    }
}
