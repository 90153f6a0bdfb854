//! Step 5: reading the cells and looking the code up.
//!
//! The quad's corners give the homography from the family's cell grid (grid units, the
//! detected square at [`Family::quad_offset`]) to the image (through a distorting lens, to
//! the ideal-lens image, and from there through the lens: [`GridMap`]). Each cell is read at its
//! centre (bilinear; for cells of 4 pixels or more, the mean of 3x3 points around it so a
//! single noisy pixel cannot flip it).
//!
//! The black/white decision is learnt from the marker itself, not from the frame: the border
//! ring is known black, and the ring next to it on the detected side (the margin outside a
//! normal marker, the white ring inside a reversed one) is known white. A plane
//! `a + b*u + c*v` fitted to each gives the black and the white level anywhere on the marker,
//! so a shadow edge or a brightness gradient across the marker moves the threshold with it.
//! A candidate whose border is not black or whose margin is not white is dropped before any
//! look-up, which is what keeps random quads from ever reaching the code table.

use super::{lens, DetectorConfig};
use crate::camera::CameraModel;
use crate::family::{Decoded, Family, MAX_GRID};
use crate::geometry::cyclic;
use crate::geometry::{Homography, Point};
use crate::image::GrayImage;

/// Border cells allowed to read white, as a fraction of the ring (glare, a speck of dirt).
pub(super) const BORDER_ERROR_FRACTION: f32 = 0.125;
/// Margin cells allowed to read dark (a tight print margin, a neighbouring object).
pub(super) const MARGIN_ERROR_FRACTION: f32 = 0.25;
/// Cells at least this many pixels wide are read as the mean of five points (the centre and
/// four a quarter cell off it); smaller ones at their centre. One bilinear sample already
/// averages four pixels, and a cell of fewer than eight pixels is read well enough by it
/// (its contrast dwarfs sensor noise); above that the extra points keep a speck or a glint
/// from deciding a cell. Five reads cost four times one: on a landing frame with several
/// large markers that was a third of the detection time.
const MULTI_SAMPLE_CELL_PX: f32 = 8.0;
/// Weight of the Laplacian that sharpens the sampled cell grid before thresholding.
const DECODE_SHARPENING: f32 = 0.25;
/// A data cell whose reading lies closer to the threshold than this fraction of half the
/// contrast is uncertain: it counts as an erasure in the look-up (see [`lookup`]).
pub(super) const UNCERTAIN_CELL_MARGIN: f32 = 0.2;
/// Families whose minimum distance exceeds their correction by at most this many bits get
/// the registration check of [`read_robust`]: for them, that many confidently misread cells
/// make another code.
pub(super) const REGISTRATION_CHECK_SLACK: u8 = 5;
/// How far the registration check moves the sampling grid, cells.
const REGISTRATION_SHIFT: f32 = 0.25;
/// The registration check's moves of the sampling grid (cells): a quarter cell each way.
pub(super) const REGISTRATION_SHIFTS: [(f32, f32); 4] = [
    (REGISTRATION_SHIFT, 0.0),
    (-REGISTRATION_SHIFT, 0.0),
    (0.0, REGISTRATION_SHIFT),
    (0.0, -REGISTRATION_SHIFT),
];
/// Image samples' worth of work of undistorting a read's four corners through the lens
/// ([`GridMap::new`]): a Newton inversion is about as much as four bilinear samples. (The
/// lens's own cost per mapped point, a polynomial, is within the per-cell figure's slack.)
pub(super) const LENS_CORNERS_COST: u32 = 16;

/// A decoded marker before de-duplication.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Read {
    pub decoded: Decoded,
    pub corners: [Point; 4],
    pub center: Point,
    pub margin: f32,
    pub contrast: f32,
}

/// Least-squares plane `a + b*u + c*v` through samples; falls back to the mean.
#[derive(Default)]
pub(super) struct PlaneFit {
    n: f32,
    su: f32,
    sv: f32,
    suu: f32,
    suv: f32,
    svv: f32,
    sz: f32,
    suz: f32,
    svz: f32,
}

impl PlaneFit {
    pub(super) fn add(&mut self, u: f32, v: f32, z: f32) {
        self.n += 1.0;
        self.su += u;
        self.sv += v;
        self.suu += u * u;
        self.suv += u * v;
        self.svv += v * v;
        self.sz += z;
        self.suz += u * z;
        self.svz += v * z;
    }

    pub(super) fn mean(&self) -> f32 {
        if self.n > 0.0 {
            self.sz / self.n
        } else {
            0.0
        }
    }

    /// Coefficients (a, b, c).
    pub(super) fn solve(&self) -> (f32, f32, f32) {
        let m = [
            [self.n, self.su, self.sv],
            [self.su, self.suu, self.suv],
            [self.sv, self.suv, self.svv],
        ];
        let r = [self.sz, self.suz, self.svz];
        let det = |m: &[[f32; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let d = det(&m);
        if !(d.abs() > 1e-6 * (1.0 + self.n * self.n * self.n)) {
            return (self.mean(), 0.0, 0.0);
        }
        let mut out = [0.0f32; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let mut mk = m;
            for (row, &rv) in mk.iter_mut().zip(r.iter()) {
                if let Some(cell) = row.get_mut(k) {
                    *cell = rv;
                }
            }
            *o = det(&mk) / d;
        }
        if out.iter().all(|c| c.is_finite()) {
            (out[0], out[1], out[2])
        } else {
            (self.mean(), 0.0, 0.0)
        }
    }
}

/// Most cells of one ring of a grid (ring -1, just outside the largest grid, has the most).
const MAX_RING_CELLS: usize = 4 * MAX_GRID + 4;

/// One ring's readings and the grid points they were read at, in the order read.
pub(super) struct RingSamples {
    points: [(f32, f32, f32); MAX_RING_CELLS],
    count: usize,
}

impl Default for RingSamples {
    fn default() -> Self {
        RingSamples {
            points: [(0.0, 0.0, 0.0); MAX_RING_CELLS],
            count: 0,
        }
    }
}

impl RingSamples {
    pub(super) fn push(&mut self, u: f32, v: f32, z: f32) {
        if let Some(slot) = self.points.get_mut(self.count) {
            *slot = (u, v, z);
            self.count += 1;
        }
    }

    /// The `k`-th reading (0 past the last).
    pub(super) fn reading(&self, k: usize) -> f32 {
        self.points
            .get(k)
            .filter(|_| k < self.count)
            .map_or(0.0, |p| p.2)
    }

    fn readings(&self) -> impl Iterator<Item = f32> + '_ {
        self.points.iter().take(self.count).map(|p| p.2)
    }

    /// The median reading (the upper of the middle two of an even count), 0 when empty.
    fn median(&self) -> f32 {
        let mut sorted = [0.0f32; MAX_RING_CELLS];
        let count = self.count.min(MAX_RING_CELLS);
        for (slot, z) in sorted.iter_mut().zip(self.readings()) {
            *slot = z;
        }
        median_of(sorted.get_mut(..count).unwrap_or(&mut []))
    }
}

/// The median of `items` (the upper of the middle two of an even count), sorting them; the
/// default when empty. An insertion sort: a ring's few dozen cells, and only on a ring that
/// a shadow splits ([`majority_fits`]).
fn median_of<T: Copy + PartialOrd + Default>(items: &mut [T]) -> T {
    for i in 1..items.len() {
        let mut j = i;
        while j > 0 {
            // By pairs taken checked: `swap` has a panic path the no-panic check finds.
            let Some([before, item]) = items.get_mut(j - 1..=j) else {
                break;
            };
            if !(*item < *before) {
                break;
            }
            core::mem::swap(before, item);
            j -= 1;
        }
    }
    items.get(items.len() / 2).copied().unwrap_or_default()
}

/// The black and the white level's planes (`fits`, through every cell of the border ring and
/// of the reference ring, whose readings are `samples`), fitted again to each ring's
/// majority where a hard shadow's edge crosses a ring.
///
/// A shadow scales the light under it, so a ring it crosses reads at two levels, the cells in
/// the sun several times those in the shadow (a marker deep in a shadow, its paper 25 grey
/// levels and its ink 3, with the paper's corner in the sun at 200): one plane through both
/// fits neither, and the threshold halfway between the black and the white plane rises over
/// the shadowed paper, which then reads dark (the margin test fails, or data cells flip). A
/// gradient across the marker (vignetting, a soft shadow) keeps each ring's readings within
/// the contrast of each other; a ring that spreads wider than the contrast between the two
/// rings' means holds a step. Then each level is fitted again to the cells within half the
/// contrast between the rings' medians of their own ring's median: the larger part of each
/// ring, on one side of the edge. The other cells are judged against those planes as before
/// (the margin and border tests allow a share of them to read wrong).
fn majority_fits(fits: [PlaneFit; 2], samples: [&RingSamples; 2]) -> [PlaneFit; 2] {
    let contrast = fits[1].mean() - fits[0].mean();
    let spread = |ring: &RingSamples| {
        let (lo, hi) = ring
            .readings()
            .fold((f32::MAX, f32::MIN), |(lo, hi), z| (lo.min(z), hi.max(z)));
        hi - lo
    };
    if !samples.iter().any(|ring| spread(ring) > contrast) {
        return fits;
    }
    let medians = samples.map(RingSamples::median);
    let reach = 0.5 * (medians[1] - medians[0]);
    if !(reach > 0.0) {
        return fits;
    }
    let mut majority = [PlaneFit::default(), PlaneFit::default()];
    for ((fit, ring), median) in majority.iter_mut().zip(samples).zip(medians) {
        for &(u, v, z) in ring.points.iter().take(ring.count) {
            if (z - median).abs() <= reach {
                fit.add(u, v, z);
            }
        }
    }
    majority
}

/// Where the family's cell grid lies in the frame: a homography from the grid onto the
/// marker's plane as the frame shows it or, through a distorting lens, as an ideal lens would
/// (its ideal-lens pixels, `lens`), each mapped point then taken through the lens into the
/// frame. A wide-angle lens bows a large marker's edges by a good part of a cell: a grid laid
/// through its true corners by a homography alone reads the cells along its edges off their
/// centres.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GridMap {
    h: Homography,
    lens: Option<CameraModel>,
}

impl GridMap {
    /// The map of `family`'s grid for a clockwise quad (frame pixels) whose first corner is
    /// taken as the grid's top-left, through `lens` when given; `None` when a corner cannot
    /// be undistorted or the quad is degenerate.
    pub(crate) fn new(
        family: &Family<'_>,
        quad: &[Point; 4],
        lens: Option<&CameraModel>,
    ) -> Option<Self> {
        let Some(camera) = lens else {
            return Some(GridMap {
                h: grid_homography(family, quad)?,
                lens: None,
            });
        };
        let mut ideal = *quad;
        for corner in ideal.iter_mut() {
            *corner = lens::ideal_pixel(camera, *corner)?;
        }
        Some(GridMap {
            h: grid_homography(family, &ideal)?,
            lens: Some(*camera),
        })
    }

    /// The map by a homography alone (no lens).
    pub(crate) fn homography(h: Homography) -> Self {
        GridMap { h, lens: None }
    }
}

/// A map from grid points to frame pixels: the reads are generic over it, so that without a
/// lens they map by the bare homography, as fast as before there was a lens to ask about.
pub(super) trait CellMap {
    /// The frame pixel of grid point (u, v).
    fn map(&self, u: f32, v: f32) -> Option<Point>;
}

impl CellMap for Homography {
    #[inline]
    fn map(&self, u: f32, v: f32) -> Option<Point> {
        Homography::map(self, u, v)
    }
}

impl CellMap for GridMap {
    #[inline]
    fn map(&self, u: f32, v: f32) -> Option<Point> {
        let p = self.h.map(u, v)?;
        match &self.lens {
            None => Some(p),
            Some(camera) => lens::frame_pixel(camera, p),
        }
    }
}

/// Reads a cell centred at grid point (u, v).
#[inline]
fn read_cell<M: CellMap>(image: &GrayImage<'_>, h: &M, u: f32, v: f32, multi: bool) -> Option<f32> {
    if !multi {
        let p = h.map(u, v)?;
        return Some(image.sample(p.x, p.y));
    }
    // Five samples: the centre and four points a quarter cell off it diagonally (each
    // bilinear sample already averages four pixels, so at four or more pixels per cell these
    // cover the cell's middle half). Across a quarter cell the map (homography and lens) is
    // affine to a tiny fraction of a pixel, so the offsets are mapped once (two extra points)
    // rather than each sample through the projective division.
    const OFFSET: f32 = 0.25;
    let centre = h.map(u, v)?;
    let along_u = h.map(u + OFFSET, v)?;
    let along_v = h.map(u, v + OFFSET)?;
    let (ux, uy) = (along_u.x - centre.x, along_u.y - centre.y);
    let (vx, vy) = (along_v.x - centre.x, along_v.y - centre.y);
    let mut acc = image.sample(centre.x, centre.y);
    for (i, j) in [(-1.0f32, -1.0f32), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        acc += image.sample(centre.x + i * ux + j * vx, centre.y + i * uy + j * vy);
    }
    Some(acc / 5.0)
}

/// The homography from the family grid to the image for a clockwise quad whose first corner
/// is taken as the grid's top-left.
pub(crate) fn grid_homography(family: &Family<'_>, quad: &[Point; 4]) -> Option<Homography> {
    let o = family.quad_offset() as f32;
    let q = family.quad_cells() as f32;
    let plane = [
        Point::new(o, o),
        Point::new(o + q, o),
        Point::new(o + q, o + q),
        Point::new(o, o + q),
    ];
    Homography::from_4_points(&plane, quad)
}

/// Corners, centre and the rotation applied: `out[j] = outer_border_corner[(j + k) % 4]`.
fn oriented_corners(family: &Family<'_>, h: &GridMap, rotation: u8) -> Option<([Point; 4], Point)> {
    let n = family.grid as f32;
    let b = family.border_ring as f32;
    let outer = [
        h.map(b, b)?,
        h.map(n - b, b)?,
        h.map(n - b, n - b)?,
        h.map(b, n - b)?,
    ];
    let k = rotation as usize;
    let corners = [
        cyclic(&outer, k),
        cyclic(&outer, k + 1),
        cyclic(&outer, k + 2),
        cyclic(&outer, k + 3),
    ];
    Some((corners, h.map(0.5 * n, 0.5 * n)?))
}

/// What a candidate's cells read as under one cell layout, before any code look-up: families
/// that share a layout (tag36h11 and aruco_6x6_250, say) share this work.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GridRead {
    h: GridMap,
    readings: [u64; 4],
    margin: f32,
    contrast: f32,
    /// Data cells read too close to the threshold to trust.
    uncertain: u8,
}

impl GridRead {
    /// A read without a notion of certainty (the paper's, [`super::paper`]): every cell
    /// counts as clear, the decision margin is 1.
    pub(crate) fn certain(h: Homography, readings: [u64; 4], contrast: f32) -> Self {
        GridRead {
            h: GridMap::homography(h),
            readings,
            margin: 1.0,
            contrast,
            uncertain: 0,
        }
    }
}

/// Looks a read grid up in `family` (which must have the layout it was read with).
///
/// Errors and erasures: a code at distance `h` from the reading is the only possible one,
/// even if every uncertain cell was misread, when `2h + uncertain < d` (the family's minimum
/// distance). A read that fails this is dropped. The bound on `h` alone protects the
/// families with a large distance; this protects the small ones (aruco_4x4_1000 has d = 2,
/// so two misread cells can turn one code into another) against blurred, steep markers whose
/// cells are sampled across their edges, where a wrong id with a clean-looking average
/// margin was seen. A family without a distance guarantee (d < 2) needs a reading without
/// uncertain cells.
pub(crate) fn lookup(family: &Family<'_>, grid: &GridRead, max_hamming: u8) -> Option<Read> {
    let decoded = family.decode(&grid.readings, max_hamming)?;
    let ambiguity = 2 * u32::from(decoded.hamming) + u32::from(grid.uncertain);
    if ambiguity > 0 && ambiguity >= u32::from(family.min_hamming).max(1) {
        return None;
    }
    let (corners, center) = oriented_corners(family, &grid.h, decoded.rotation)?;
    Some(Read {
        decoded,
        corners,
        center,
        margin: grid.margin,
        contrast: grid.contrast,
    })
}

/// Reads a candidate's cells with touchdown's method, using `family`'s layout, through
/// `lens` when given ([`GridMap`]).
///
/// Adds the cells it read, weighted by their cost in image samples and mapped points, to
/// `samples` (the detector's work accounting).
pub(crate) fn read_robust(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    quad: &[Point; 4],
    lens: Option<&CameraModel>,
    config: &DetectorConfig,
    samples: &mut u32,
) -> Option<GridRead> {
    let cost = core::cell::Cell::new(0u32);
    if lens.is_some() {
        // The corners' undistortion (Newton, about as much as four samples each).
        cost.set(LENS_CORNERS_COST);
    }
    let grid = match lens {
        None => {
            let h = grid_homography(family, quad)?;
            read_robust_counted(
                image,
                family,
                quad,
                &h,
                GridMap::homography(h),
                config,
                &cost,
            )
        }
        Some(_) => {
            let map = GridMap::new(family, quad, lens)?;
            read_robust_counted(image, family, quad, &map, map, config, &cost)
        }
    };
    *samples = samples.saturating_add(cost.get());
    grid
}

/// The shorter of a quad's first two sides, squared: the size tests compare squared lengths
/// (no square root: they run on every candidate).
pub(super) fn shorter_first_side_squared(quad: &[Point; 4]) -> f32 {
    quad[0]
        .distance_squared(quad[1])
        .min(quad[1].distance_squared(quad[2]))
}

/// [`read_robust`], reading the cells through `h` (`grid`, kept in the result for the
/// corners, maps the same), counting its reads in `cost`.
fn read_robust_counted<M: CellMap>(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    quad: &[Point; 4],
    h: &M,
    grid: GridMap,
    config: &DetectorConfig,
    cost: &core::cell::Cell<u32>,
) -> Option<GridRead> {
    let n = family.grid as usize;
    let b = family.border_ring as isize;
    let reversed = family.reversed();
    // Cells of at least MULTI_SAMPLE_CELL_PX along the first two sides.
    let side2 = shorter_first_side_squared(quad);
    let multi_side = MULTI_SAMPLE_CELL_PX * family.quad_cells() as f32;
    let multi = side2 >= multi_side * multi_side;
    // A single read: one mapped point, one sample; a multi-sampled one: three and five.
    let cost_per_cell: u32 = if multi { 8 } else { 2 };
    let read_cell = |image: &GrayImage<'_>, h: &M, u: f32, v: f32, multi: bool| {
        cost.set(cost.get().saturating_add(cost_per_cell));
        read_cell(image, h, u, v, multi)
    };

    // Learn the black level from the border ring and the white level from the reference ring
    // (outside the border for normal families, even beyond the drawn grid; inside otherwise).
    let white_ring = if reversed { b + 1 } else { b - 1 };
    let mut black = PlaneFit::default();
    let mut white = PlaneFit::default();
    let mut values = [0.0f32; MAX_GRID * MAX_GRID];
    // Each ring's readings in `for_ring`'s order too, with the grid points they were read
    // at, for the fits of their majorities (`majority_fits`).
    let mut black_samples = RingSamples::default();
    for_ring(n, b, |r, c| {
        let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
        if let Some(z) = read_cell(image, h, u, v, multi) {
            black.add(u, v, z);
            black_samples.push(u, v, z);
            if let Some(slot) = values.get_mut(r as usize * n + c as usize) {
                *slot = z;
            }
        }
    });
    let mut white_samples = RingSamples::default();
    for_ring(n, white_ring, |r, c| {
        let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
        if let Some(z) = read_cell(image, h, u, v, multi) {
            white.add(u, v, z);
            white_samples.push(u, v, z);
        }
    });
    let [black, white] = majority_fits([black, white], [&black_samples, &white_samples]);
    let (ba, bb, bc) = black.solve();
    let (wa, wb, wc) = white.solve();
    let threshold = |u: f32, v: f32| 0.5 * ((ba + bb * u + bc * v) + (wa + wb * u + wc * v));
    let contrast = white.mean() - black.mean();
    if !(contrast >= config.min_contrast as f32 * 0.5) {
        return None;
    }

    // The border must read black and the reference ring white.
    let border_black = ring_reads_as(n, b, BORDER_ERROR_FRACTION, |r, c| {
        let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
        values
            .get(r as usize * n + c as usize)
            .copied()
            .unwrap_or(0.0)
            > threshold(u, v)
    });
    let mut k = 0usize;
    let margin_white = ring_reads_as(n, white_ring, MARGIN_ERROR_FRACTION, |r, c| {
        let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
        let dark = white_samples.reading(k) < threshold(u, v);
        k += 1;
        dark
    });
    if !(border_black && margin_white) {
        return None;
    }

    // Quiet cells are not read: they count as the white ring's mean (the white ring next to
    // the border is read, as samples). Stored once in `values`, where nothing else reads them,
    // so the sharpening below looks its neighbours up without asking each one's role.
    let white_mean = white.mean();
    for ring in (0..family.quiet_rings as isize).filter(|&ring| ring != b) {
        for_ring(n, ring, |r, c| {
            if let Some(slot) = values.get_mut(r as usize * n + c as usize) {
                *slot = white_mean;
            }
        });
    }

    // Data cells, sharpened against their neighbours: at one or two pixels per cell the
    // optics and the sampling spread each cell into the next, and a small Laplacian term
    // undoes part of that (AprilTag 3's decode_sharpening does the same). `shift` moves
    // every sample point by that many cells (see the registration check below).
    // The data cells, asked of the family once: the passes below (the read, the decisions,
    // the registration check, the codes) each asked every cell's role.
    let data = family.data_cells()?;
    let read_data = |shift: (f32, f32), values: &mut [f32; MAX_GRID * MAX_GRID]| {
        for &(r, c) in &data {
            let (r, c) = (r as usize, c as usize);
            let (u, v) = (c as f32 + 0.5 + shift.0, r as f32 + 0.5 + shift.1);
            let z = read_cell(image, h, u, v, multi)?;
            if let Some(slot) = values.get_mut(r * n + c) {
                *slot = z;
            }
        }
        Some(())
    };
    // The sharpened reading of data cell (r, c) minus its threshold.
    let decide = |values: &[f32; MAX_GRID * MAX_GRID], r: usize, c: usize| -> f32 {
        // A neighbour outside the grid counts as the cell itself (r and c are below n).
        let k = r * n + c;
        let own = values.get(k).copied().unwrap_or(0.0);
        let value_at = |inside: bool, k: usize| -> f32 {
            if inside {
                values.get(k).copied().unwrap_or(own)
            } else {
                own
            }
        };
        let neighbours = value_at(r > 0, k.wrapping_sub(n))
            + value_at(r + 1 < n, k + n)
            + value_at(c > 0, k.wrapping_sub(1))
            + value_at(c + 1 < n, k + 1);
        let z = own + DECODE_SHARPENING * (4.0 * own - neighbours);
        z - threshold(c as f32 + 0.5, r as f32 + 0.5)
    };
    read_data((0.0, 0.0), &mut values)?;
    // Cells too close to their threshold, or (below) unstable under a shifted grid.
    let mut decided = Decided::of(&data, n, contrast, |r, c| decide(&values, r, c));
    // Registration check for families where a few misread cells make another code: a grid
    // laid half a cell off (a blurred, steep marker whose short edges are a pixel off) reads
    // whole cells of its neighbours with full confidence. Read again with every sample
    // moved a quarter cell each way; a cell whose bit changes is uncertain. On a well-placed
    // grid a quarter cell stays inside each cell.
    if family.min_hamming.saturating_sub(family.max_correction) <= REGISTRATION_CHECK_SLACK {
        let mut shifted = values;
        for shift in REGISTRATION_SHIFTS {
            read_data(shift, &mut shifted)?;
            decided.flag_changed(&data, n, |r, c| decide(&shifted, r, c) > 0.0);
        }
    }
    decided.read(grid, family, &data, contrast, config)
}

/// A read's decided data cells: each cell's bit, whether it is uncertain, and the decision
/// margin (the mean over the data cells). The first and the deblurred read decide alike.
pub(super) struct Decided {
    cells: [bool; MAX_GRID * MAX_GRID],
    uncertain_cells: [bool; MAX_GRID * MAX_GRID],
    margin: f32,
}

impl Decided {
    /// Decides the `data` cells (grid of `n`) from `relative(row, column)`, a cell's reading
    /// less its threshold, against the black-to-white `contrast`: a cell is white above its
    /// threshold, and uncertain within [`UNCERTAIN_CELL_MARGIN`] of half the contrast of it.
    #[inline]
    pub(super) fn of(
        data: &[(u8, u8)],
        n: usize,
        contrast: f32,
        relative: impl Fn(usize, usize) -> f32,
    ) -> Decided {
        let mut decided = Decided {
            cells: [false; MAX_GRID * MAX_GRID],
            uncertain_cells: [false; MAX_GRID * MAX_GRID],
            margin: 0.0,
        };
        let mut margin_sum = 0.0f32;
        for &(r, c) in data {
            let (r, c) = (r as usize, c as usize);
            let d = relative(r, c);
            let cell_margin = (d.abs() / (0.5 * contrast)).min(1.0);
            let k = r * n + c;
            if let (Some(cell), Some(flag)) =
                (decided.cells.get_mut(k), decided.uncertain_cells.get_mut(k))
            {
                *cell = d > 0.0;
                *flag = cell_margin < UNCERTAIN_CELL_MARGIN;
            }
            margin_sum += cell_margin;
        }
        decided.margin = margin_sum / data.len().max(1) as f32;
        decided
    }

    /// The registration check's step: flags as uncertain each of the `data` cells (grid of
    /// `n`) whose bit under a shifted read, `bit(row, column)`, differs from its decided one.
    #[inline]
    pub(super) fn flag_changed(
        &mut self,
        data: &[(u8, u8)],
        n: usize,
        bit: impl Fn(usize, usize) -> bool,
    ) {
        for &(r, c) in data {
            let (r, c) = (r as usize, c as usize);
            let k = r * n + c;
            if self.cells.get(k).copied() != Some(bit(r, c)) {
                if let Some(flag) = self.uncertain_cells.get_mut(k) {
                    *flag = true;
                }
            }
        }
    }

    /// The grid read through `h` of `family`'s `data` cells with black-to-white `contrast`;
    /// `None` when its decision margin is below the configured one.
    pub(super) fn read(
        &self,
        h: GridMap,
        family: &Family<'_>,
        data: &[(u8, u8)],
        contrast: f32,
        config: &DetectorConfig,
    ) -> Option<GridRead> {
        if self.margin < config.min_decision_margin {
            return None;
        }
        let n = family.grid as usize;
        // Only data cells are ever flagged: counted over them, not the whole array.
        let uncertain = data
            .iter()
            .filter(|&&(r, c)| self.uncertain_cells.get(r as usize * n + c as usize) == Some(&true))
            .count();
        Some(GridRead {
            h,
            readings: family.codes_of_data_cells(self.cells.get(..n * n)?, data),
            margin: self.margin,
            contrast,
            uncertain: u8::try_from(uncertain).unwrap_or(u8::MAX),
        })
    }
}

/// Whether ring `ring` of a grid of `n` cells reads as it should: at most `fraction` of its
/// cells `wrong(row, column)` (a border cell read light, a margin cell read dark).
#[inline]
pub(super) fn ring_reads_as(
    n: usize,
    ring: isize,
    fraction: f32,
    mut wrong: impl FnMut(isize, isize) -> bool,
) -> bool {
    let (mut errors, mut cells) = (0usize, 0usize);
    for_ring(n, ring, |r, c| {
        cells += 1;
        errors += usize::from(wrong(r, c));
    });
    errors as f32 <= fraction * cells.max(1) as f32
}

/// Largest spread of a candidate's data cells, as a fraction of its black-to-white contrast,
/// for [`precheck`] to call the interior flat. A marker's data cells span the whole contrast
/// (some are black, some white); a dark square, a tile or a window spans a few grey levels.
const FLAT_INTERIOR_SPREAD: f32 = 0.2;
/// Samples across the data area, per side, of the flat-interior test.
const FLAT_SAMPLES: usize = 4;
/// Most samples per side of the border ring and of the margin in [`precheck`] (one per cell
/// up to this).
const PRECHECK_RING_SAMPLES: usize = 4;
/// Smallest cell, pixels, for [`precheck`] to judge the border ring at the rough corners:
/// those are within about a pixel of the edges, which must stay well inside one cell.
const PRECHECK_BORDER_CELL_PX: f32 = 2.5;
/// Fraction of the border (or margin) samples allowed on the wrong side of the mid level at
/// the rough corners: twice the full read's allowance ([`BORDER_ERROR_FRACTION`],
/// [`MARGIN_ERROR_FRACTION`]), as rough corners blur the ring's first and last cells.
const PRECHECK_ERROR_SLACK: f32 = 2.0;

/// What [`precheck`] makes of a candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Precheck {
    /// Worth refining and reading.
    Candidate,
    /// The interior is one flat tone (only said for families without a uniform code).
    Flat,
    /// No dark border ring inside a light margin, or too little contrast.
    NoBorder,
}

/// A quick look at a candidate at its rough corners, before the costly refinement: is there
/// a dark border ring in a light margin, and (when `flat_rejects`, i.e. no family searched
/// decodes a uniform grid, see [`uniform_grid_decodes`]) is the interior more than one flat
/// tone? A frame tiled with dark squares, or the dark blobs inside a marker's own data
/// cells, would otherwise each spend the refinement (about 55,000 Cortex-M7 instructions for
/// a 24-pixel marker, several times that for a large one) only to be turned down by the read.
///
/// Cheap on purpose, as it runs on every candidate (a few percent of a refinement, with its
/// rough quad, [`super::refine::rough_half_pixel_adjusted`], when it reads all 48 points, as
/// on the benchmark's frame of small dark squares):
/// nearest pixels at positions blended bilinearly from the corners (no homography:
/// perspective moves the samples along the ring or across the data area by a fraction of a
/// cell, which changes neither test), up to four points along the middle half of each side
/// of the border ring and of the margin outside it, and a 4x4 lattice over the data cells. For dark-on-light families only. The border test is skipped
/// below [`PRECHECK_BORDER_CELL_PX`] per cell, where the rough corners are too rough.
///
/// `cells` is the number of cells across the detected square; with several families, the
/// largest: the thinnest border, whose middle lies inside every family's border and whose
/// margin inside every family's margin (a family with fewer, larger cells only puts more of
/// its border under the data lattice, which makes the interior look less flat).
pub(crate) fn precheck(
    image: &GrayImage<'_>,
    cells: usize,
    quad: &[Point; 4],
    min_contrast: u8,
    flat_rejects: bool,
) -> Precheck {
    // One sample per cell of a side up to PRECHECK_RING_SAMPLES: the count a constant, so
    // each side's reads unroll (cells < 3 has no border to judge; 3 is the one count below).
    if cells >= PRECHECK_RING_SAMPLES {
        precheck_sides::<PRECHECK_RING_SAMPLES>(image, cells, quad, min_contrast, flat_rejects)
    } else if cells == 3 {
        precheck_sides::<3>(image, cells, quad, min_contrast, flat_rejects)
    } else {
        Precheck::Candidate
    }
}

/// [`precheck`] with `N` samples along each side of the border ring and of the margin.
#[inline(always)]
fn precheck_sides<const N: usize>(
    image: &GrayImage<'_>,
    cells: usize,
    quad: &[Point; 4],
    min_contrast: u8,
    flat_rejects: bool,
) -> Precheck {
    let q = cells as f32;
    let [p0, p1, p2, p3] = *quad;
    // (s, t) in 0..1 across the detected square (the border's outer edge), s along p0 -> p1.
    let at = |s: f32, t: f32| {
        let top = (p0.x + (p1.x - p0.x) * s, p0.y + (p1.y - p0.y) * s);
        let bottom = (p3.x + (p2.x - p3.x) * s, p3.y + (p2.y - p3.y) * s);
        Point::new(
            top.0 + (bottom.0 - top.0) * t,
            top.1 + (bottom.1 - top.1) * t,
        )
    };
    let read = NearestReads::new(image, quad, 0.5 / q);
    // The ring at depth `d` inside the edge (negative: outside), along the middle half of
    // each side (clear of the corners, where rough corners are roughest), into `ring`: the
    // mean.
    let read_ring = |d: f32, ring: &mut [[u8; N]; 4]| {
        let (lo, hi) = (0.25, 0.75);
        let sides = [
            (at(lo, d), at(hi, d)),
            (at(1.0 - d, lo), at(1.0 - d, hi)),
            (at(lo, 1.0 - d), at(hi, 1.0 - d)),
            (at(d, lo), at(d, hi)),
        ];
        let mut sum = 0u32;
        for (side, (a, b)) in ring.iter_mut().zip(sides) {
            sum += read.along(a, b, side);
        }
        sum as f32 / (4 * N) as f32
    };
    // The border ring, then the margin: one call site, so the reads are inlined.
    let mut rings = [[[0u8; N]; 4]; 2];
    let mut means = [0.0f32; 2];
    for ((ring, mean), d) in rings
        .iter_mut()
        .zip(means.iter_mut())
        .zip([0.5 / q, -0.5 / q])
    {
        *mean = read_ring(d, ring);
    }
    let ([border, margin], [black, white]) = (rings, means);
    // Cells of at least PRECHECK_BORDER_CELL_PX along the first two sides.
    let side2 = shorter_first_side_squared(quad);
    let min_side = PRECHECK_BORDER_CELL_PX * q;
    let judge_border = side2 >= min_side * min_side;
    // A dark border ring in a light margin, judged against the levels `black` and `white`.
    let bordered = |black: f32, white: f32| {
        if !(white - black >= f32::from(min_contrast) * 0.5) {
            return false;
        }
        if !judge_border {
            return true;
        }
        let mid = 0.5 * (black + white);
        let light = border
            .iter()
            .flatten()
            .filter(|&&z| f32::from(z) > mid)
            .count();
        let dark = margin
            .iter()
            .flatten()
            .filter(|&&z| f32::from(z) < mid)
            .count();
        let samples = (4 * N) as f32;
        light as f32 <= PRECHECK_ERROR_SLACK * BORDER_ERROR_FRACTION * samples
            && dark as f32 <= PRECHECK_ERROR_SLACK * MARGIN_ERROR_FRACTION * samples
    };
    // Where a hard shadow's edge crosses a ring, its sunlit part pulls the ring's mean far
    // from its shadowed part (`majority_fits` of the full read): judged again at the rings'
    // medians, when a ring spreads wider than the contrast of the means. Only for a quad the
    // means turned down, so the candidates that pass pay nothing.
    let mut contrast = white - black;
    if !bordered(black, white) {
        let spread = |ring: &[[u8; N]; 4]| {
            let (lo, hi) = ring
                .iter()
                .flatten()
                .fold((u8::MAX, 0u8), |(lo, hi), &z| (lo.min(z), hi.max(z)));
            f32::from(hi.saturating_sub(lo))
        };
        if !(spread(&border) > contrast || spread(&margin) > contrast) {
            return Precheck::NoBorder;
        }
        let median = |ring: &[[u8; N]; 4]| {
            let mut all = *ring;
            f32::from(median_of(all.as_flattened_mut()))
        };
        let (black, white) = (median(&border), median(&margin));
        if !bordered(black, white) {
            return Precheck::NoBorder;
        }
        contrast = white - black;
    }
    if flat_rejects {
        // A lattice over the data cells, which span 1..q-1 cells of the square.
        let (lo, hi) = (1.0 / q, 1.0 - 1.0 / q);
        let mut lattice = [0u8; FLAT_SAMPLES];
        let (mut min, mut max) = (u32::from(u8::MAX), 0u32);
        for j in 0..FLAT_SAMPLES {
            let t = lo + (hi - lo) * (j as f32 + 0.5) / FLAT_SAMPLES as f32;
            read.along(at(lo, t), at(hi, t), &mut lattice);
            for &z in lattice.iter() {
                min = min.min(u32::from(z));
                max = max.max(u32::from(z));
            }
        }
        if (max.saturating_sub(min) as f32) < FLAT_INTERIOR_SPREAD * contrast {
            return Precheck::Flat;
        }
    }
    Precheck::Candidate
}

/// [`precheck`]'s nearest-pixel reads along lines of a candidate.
#[derive(Clone, Copy)]
struct NearestReads<'a, 'i> {
    image: &'a GrayImage<'i>,
    /// Every read lies inside the image: none needs clamping.
    inside: bool,
}

impl<'a, 'i> NearestReads<'a, 'i> {
    /// Reads around `quad` reaching `reach` (a fraction of its sides) beyond it.
    ///
    /// The reads lie in the square widened by `reach` on every side, which the bilinear
    /// blend of the corners maps within `2 * reach * (1 + reach)` times the extent of the
    /// corners' bounding box beyond it, in each coordinate (below `3 * reach` for a reach up to
    /// a half; [`precheck`]'s is at most 1/6): when that stays inside the image
    /// (every candidate but those at the frame's edge), no read needs clamping, which was a
    /// third of the cost of a read.
    #[inline(always)]
    fn new(image: &'a GrayImage<'i>, quad: &[Point; 4], reach: f32) -> Self {
        let [a, b, c, d] = *quad;
        let (x0, x1) = (
            a.x.min(b.x).min(c.x.min(d.x)),
            a.x.max(b.x).max(c.x.max(d.x)),
        );
        let (y0, y1) = (
            a.y.min(b.y).min(c.y.min(d.y)),
            a.y.max(b.y).max(c.y.max(d.y)),
        );
        let (mx, my) = (3.0 * reach * (x1 - x0), 3.0 * reach * (y1 - y0));
        // Up to the last pixel's centre: (x + 0.5) truncates to it.
        let (w, h) = (
            image.width().saturating_sub(1) as f32,
            image.height().saturating_sub(1) as f32,
        );
        let inside = x0 - mx >= 0.0 && y0 - my >= 0.0 && x1 + mx <= w && y1 + my <= h;
        NearestReads { image, inside }
    }

    /// `out.len()` evenly spaced samples between a and b (the middle of `out.len()` equal
    /// parts: a line of the square, which the bilinear blend keeps straight along s or t),
    /// nearest pixels ((x + 0.5) truncated: below -0.5 it clamps to the edge anyway), into
    /// `out`; returns their sum. Kept as grey levels: arrays of bytes are zeroed in a few
    /// stores, where float ones took a memset call per quick look.
    #[inline(always)]
    fn along(self, a: Point, b: Point, out: &mut [u8]) -> u32 {
        let count = out.len() as f32;
        let step = ((b.x - a.x) / count, (b.y - a.y) / count);
        let start = Point::new(a.x + 0.5 * step.0, a.y + 0.5 * step.1);
        let image = self.image;
        if self.inside {
            read_line(start, step, out, |p| image.nearest_inside(p.x, p.y))
        } else {
            read_line(start, step, out, |p| {
                image.pixel_clamped((p.x + 0.5) as isize, (p.y + 0.5) as isize)
            })
        }
    }
}

/// The pixels `pixel` gives at `start`, `start + step`, ... into `out`, and their sum.
#[inline(always)]
fn read_line(start: Point, step: (f32, f32), out: &mut [u8], pixel: impl Fn(Point) -> u8) -> u32 {
    let mut p = start;
    let mut sum = 0u32;
    for slot in out.iter_mut() {
        let z = pixel(p);
        sum += u32::from(z);
        *slot = z;
        p = Point::new(p.x + step.0, p.y + step.1);
    }
    sum
}

/// Whether `family` decodes an all-black or an all-white grid (within its correction
/// radius, in any rotation): then [`precheck`] must not call a flat interior a reject.
pub(crate) fn uniform_grid_decodes(family: &Family<'_>) -> bool {
    let ones = if family.bits >= 64 {
        u64::MAX
    } else {
        (1u64 << family.bits) - 1
    };
    [0u64, ones]
        .iter()
        .any(|&code| family.decode(&[code; 4], family.max_correction).is_some())
}

/// Calls `f(row, col)` for every cell of ring `ring` of an `n x n` grid; the ring may lie
/// outside the grid (ring -1 is the row of cells just outside it).
pub(super) fn for_ring(n: usize, ring: isize, mut f: impl FnMut(isize, isize)) {
    let lo = ring;
    let hi = n as isize - 1 - ring;
    if hi < lo {
        return;
    }
    if hi == lo {
        f(lo, lo);
        return;
    }
    for c in lo..=hi {
        f(lo, c);
    }
    for r in lo + 1..=hi {
        f(r, hi);
    }
    for c in (lo..hi).rev() {
        f(hi, c);
    }
    for r in (lo + 1..hi).rev() {
        f(r, lo);
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::family::tables::TAG36H11;

    /// Frame side of [`shadowed_marker`], pixels.
    const SIZE: usize = 120;
    /// Cell side of [`shadowed_marker`], pixels.
    const CELL: f32 = 8.0;
    /// Where [`shadowed_marker`]'s grid starts: its cell edges lie on pixel edges.
    const GRID_AT: f32 = 19.5;

    /// tag36h11 `id`, cells of 8 pixels, on paper that fills the frame, deep in a shadow (ink
    /// 3, paper 25: the camera exposed for the sun) but where `sunlit(x, y)`, which is eight
    /// times as bright (paper 200); and the outer corners of its black border.
    fn shadowed_marker(
        id: u16,
        sunlit: impl Fn(f32, f32) -> bool,
    ) -> (std::vec::Vec<u8>, [Point; 4]) {
        let family = &TAG36H11;
        let n = family.grid as usize;
        const SUB: usize = 4;
        let mut pixels = std::vec![0u8; SIZE * SIZE];
        for y in 0..SIZE {
            for x in 0..SIZE {
                let mut sum = 0.0;
                for sy in 0..SUB {
                    for sx in 0..SUB {
                        let px = x as f32 - 0.5 + (sx as f32 + 0.5) / SUB as f32;
                        let py = y as f32 - 0.5 + (sy as f32 + 0.5) / SUB as f32;
                        let (u, v) = ((px - GRID_AT) / CELL, (py - GRID_AT) / CELL);
                        let inside = u >= 0.0 && v >= 0.0 && u < n as f32 && v < n as f32;
                        let white = !inside
                            || family.cell_is_white(usize::from(id), v as usize, u as usize)
                                == Some(true);
                        let level = if white { 25.0 } else { 3.0 };
                        sum += if sunlit(px, py) { 8.0 * level } else { level };
                    }
                }
                pixels[y * SIZE + x] = (sum / (SUB * SUB) as f32).round() as u8;
            }
        }
        let b = family.quad_offset() as f32;
        let (lo, hi) = (GRID_AT + b * CELL, GRID_AT + (n as f32 - b) * CELL);
        let corners = [
            Point::new(lo, lo),
            Point::new(hi, lo),
            Point::new(hi, hi),
            Point::new(lo, hi),
        ];
        (pixels, corners)
    }

    /// The edge of a hard shadow across the left side of the margin and its corner: the sun
    /// on the paper beside the marker's top-left corner and along most of its left side, the
    /// marker itself in the shadow but for the black border's corner.
    fn sun_along_the_left(x: f32, y: f32) -> bool {
        x + 0.25 * y < 41.0
    }

    /// A marker deep in a shadow whose margin the sun lights along one side: the full read
    /// learns its white level from the shadowed paper, the larger part of the ring beside its
    /// border, and reads the code (the plane through all of that ring, sunlit cells and
    /// shadowed, rose over the shadowed paper, which then read dark).
    #[test]
    fn a_shadowed_marker_with_its_margin_partly_in_the_sun_is_read() {
        let config = DetectorConfig::default();
        for id in [0u16, 7, 301] {
            let (pixels, corners) = shadowed_marker(id, sun_along_the_left);
            let image = GrayImage::new(&pixels, SIZE, SIZE).unwrap();
            let mut samples = 0;
            let read = read_robust(&image, &TAG36H11, &corners, None, &config, &mut samples)
                .unwrap_or_else(|| panic!("id {id}: no marker grid read"));
            let found = lookup(&TAG36H11, &read, u8::MAX).expect("a code");
            assert_eq!(found.decoded.id, id);
            assert_eq!(found.decoded.hamming, 0, "id {id}");
            // The levels are the shadow's: ink 3, paper 25.
            assert!(
                (read.contrast - 22.0).abs() < 2.0,
                "id {id}: {}",
                read.contrast
            );
        }
    }

    /// The quick look at the same marker passes it on: at the rings' means the sunlit paper
    /// put the mid-level above the shadowed paper, at their medians it does not.
    #[test]
    fn the_quick_look_passes_a_shadowed_marker_with_its_margin_partly_in_the_sun() {
        let (pixels, corners) = shadowed_marker(7, sun_along_the_left);
        let image = GrayImage::new(&pixels, SIZE, SIZE).unwrap();
        let cells = TAG36H11.quad_cells();
        assert_eq!(
            precheck(&image, cells, &corners, 20, true),
            Precheck::Candidate
        );
        // Uniform light (the sun everywhere, or nowhere): passed as before; paper with no
        // marker on it: turned down.
        for sunlit in [|_: f32, _: f32| true, |_: f32, _: f32| false] {
            let (pixels, corners) = shadowed_marker(7, sunlit);
            let image = GrayImage::new(&pixels, SIZE, SIZE).unwrap();
            assert_eq!(
                precheck(&image, cells, &corners, 20, true),
                Precheck::Candidate
            );
        }
        let paper: std::vec::Vec<u8> = (0..SIZE * SIZE)
            .map(|k| {
                if sun_along_the_left((k % SIZE) as f32, (k / SIZE) as f32) {
                    200
                } else {
                    25
                }
            })
            .collect();
        let image = GrayImage::new(&paper, SIZE, SIZE).unwrap();
        assert_eq!(
            precheck(&image, cells, &corners, 20, true),
            Precheck::NoBorder
        );
    }

    /// The median of a ring's readings is one of them, the middle one (the upper of two).
    #[test]
    fn the_median_is_the_middle_reading() {
        assert_eq!(median_of(&mut [3u8, 200, 25, 24, 26]), 25);
        assert_eq!(median_of(&mut [4.0f32, 1.0, 3.0, 2.0]), 3.0);
        assert_eq!(median_of::<u8>(&mut []), 0);
    }
}
