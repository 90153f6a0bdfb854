//! Step 5 again, for a small marker whose cells the blur has run together: the cells read
//! with the blur taken out.
//!
//! ## Why
//! Far from the pad a cell is one or two pixels and the lens's blur, a defocus, the motion
//! over the exposure or a camera's tone curve spread each cell into its neighbours: a lone
//! white data cell between black ones reads darker than the threshold halfway between the
//! border's black and the margin's white, and the code comes out a few bits wrong. The first
//! read's fixed sharpening ([`super::decode`]) undoes a mild blur only; a stronger fixed one
//! would amplify the noise of every sharp marker.
//!
//! ## How
//! The blur is taken to spill a fraction `k` of each cell into each neighbour along either
//! grid axis (a Gaussian a good part of a cell wide, sampled at the cell centres, is close to
//! that), so the cells sampled at their centres are the true cells through a three-tap
//! kernel along the rows and again along the columns. Given `k` that is undone exactly by a
//! tridiagonal solve along every row and every column of the sampled grid (with one ring
//! beyond the marker's own as the boundary). `k` is not known: of the few tried, the one that
//! leaves the known cells most uniform (the border ring all black, the ring beside it all
//! white) is kept: too little leaves the blur's shading on them, too much rings. The cells
//! are then decided as the first read decides them, uncertain cells and the registration
//! check included, so the look-up's guard against misread codes is the same.
//!
//! ## When
//! Once a frame, at its end, for the largest candidate whose first read found no code, with
//! cells at most [`DEBLUR_MAX_CELL_PX`] across, and only for families read outside in (a
//! normal border): the second read costs a few times the first, only small markers need it,
//! and a far frame has one marker that small (a sheet of small look-alikes must not pay for
//! one each).

// The grids are fixed arrays indexed by loop counters bounded by their side (`m` is at most
// `SIDE`), never by data.
#![allow(clippy::indexing_slicing, clippy::needless_range_loop)]

use super::decode::{
    for_ring, ring_reads_as, shorter_first_side_squared, CellMap, Decided, GridMap, GridRead,
    PlaneFit, BORDER_ERROR_FRACTION, LENS_CORNERS_COST, MARGIN_ERROR_FRACTION,
    REGISTRATION_CHECK_SLACK, REGISTRATION_SHIFTS,
};
use super::DetectorConfig;
use crate::camera::CameraModel;
use crate::family::{Family, MAX_GRID};
use crate::geometry::Point;
use crate::image::GrayImage;

/// Widest cell (pixels along the quad's shorter first side) that gets the deblurred read.
/// Wider cells have their centres more than a pixel and a half from their edges, where a
/// lens's blur of a pixel or less hardly reaches: the first read reads them.
pub(crate) const DEBLUR_MAX_CELL_PX: f32 = 3.0;
/// The spills tried, per neighbour and axis. Below a quarter: at a quarter the kernel's
/// response to a grid of alternating cells is zero and the solve would divide by it.
const SPILLS: [f32; 4] = [0.05, 0.1, 0.15, 0.2];
/// Side of the sampled grid: the family's grid and one ring beyond it.
const SIDE: usize = MAX_GRID + 2;

/// A sampled grid, row-major; cell (r, c) of the family's grid is `[r + 1][c + 1]`.
type Grid = [[f32; SIDE]; SIDE];

/// Reads `family`'s cells through `quad` (detection order, through `lens` when given) with
/// the blur taken out, as the module docs describe; `None` when the marker is not small,
/// the family is reversed, or the read finds no black border in a white ring or no clear
/// cells. Adds the image reads to `samples` as [`super::decode::read_robust`] does.
pub(crate) fn read_deblurred(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    quad: &[Point; 4],
    lens: Option<&CameraModel>,
    config: &DetectorConfig,
    samples: &mut u32,
) -> Option<GridRead> {
    let n = family.grid as usize;
    let b = family.border_ring as isize;
    if family.reversed() || !(3..=MAX_GRID).contains(&n) || !is_small(quad, family.quad_cells()) {
        return None;
    }
    let m = n + 2;
    let map = GridMap::new(family, quad, lens)?;
    // One mapped point and one sample a cell, and the corners' undistortion through a lens,
    // as the first read counts them.
    let grid_cost = 2 * (m * m) as u32;
    let lens_cost = if lens.is_some() { LENS_CORNERS_COST } else { 0 };
    let mut sampled: Grid = [[0.0; SIDE]; SIDE];
    *samples = samples.saturating_add(grid_cost + lens_cost);
    sample(image, &map, m, (0.0, 0.0), &mut sampled)?;

    // The spill that leaves the known rings most uniform, its grid and levels kept.
    let mut work: Grid = sampled;
    let mut best: Option<(f32, f32, Levels, Grid)> = None;
    for k in SPILLS {
        work = sampled;
        unspill(&mut work, m, k);
        let Some(levels) = Levels::of(&work, n, b) else {
            continue;
        };
        let spread = levels.spread(&work, n, b);
        if best.as_ref().is_none_or(|(_, s, ..)| spread < *s) {
            best = Some((k, spread, levels, work));
        }
    }
    let (k, _, levels, grid) = best?;
    if !(levels.contrast >= config.min_contrast as f32 * 0.5) {
        return None;
    }

    // The border must read black and the ring beside it white, as in the first read.
    let border_black = ring_reads_as(n, b, BORDER_ERROR_FRACTION, |r, c| {
        levels.relative(&grid, r, c) > 0.0
    });
    let margin_white = ring_reads_as(n, b - 1, MARGIN_ERROR_FRACTION, |r, c| {
        levels.relative(&grid, r, c) < 0.0
    });
    if !(border_black && margin_white) {
        return None;
    }

    let data = family.data_cells()?;
    let mut decided = Decided::of(&data, n, levels.contrast, |r, c| {
        levels.relative(&grid, r as isize, c as isize)
    });
    // The first read's registration check, on the deblurred grid: read again with every
    // sample a quarter cell off each way; a cell whose bit changes is uncertain.
    if family.min_hamming.saturating_sub(family.max_correction) <= REGISTRATION_CHECK_SLACK {
        for shift in REGISTRATION_SHIFTS {
            *samples = samples.saturating_add(grid_cost);
            sample(image, &map, m, shift, &mut work)?;
            unspill(&mut work, m, k);
            decided.flag_changed(&data, n, |r, c| {
                levels.relative(&work, r as isize, c as isize) > 0.0
            });
        }
    }
    decided.read(map, family, &data, levels.contrast, config)
}

/// Whether a quad of `cells` cells across has cells of at most [`DEBLUR_MAX_CELL_PX`] (along
/// its shorter first side).
pub(crate) fn is_small(quad: &[Point; 4], cells: usize) -> bool {
    libm::sqrtf(shorter_first_side_squared(quad)) <= DEBLUR_MAX_CELL_PX * cells as f32
}

/// Samples the grid's cell centres and the ring beyond it, every point moved by `shift`
/// cells, into `grid`.
fn sample<M: CellMap>(
    image: &GrayImage<'_>,
    map: &M,
    m: usize,
    shift: (f32, f32),
    grid: &mut Grid,
) -> Option<()> {
    for (r, row) in grid.iter_mut().enumerate().take(m) {
        for (c, value) in row.iter_mut().enumerate().take(m) {
            // Cell (r - 1, c - 1) of the family's grid: its centre.
            let p = map.map(c as f32 - 0.5 + shift.0, r as f32 - 0.5 + shift.1)?;
            *value = image.sample(p.x, p.y);
        }
    }
    Some(())
}

/// Takes out a spill of `k` into each neighbour along the rows, then along the columns, of
/// the first `m` rows and columns: each line is solved for the cells that, through the
/// kernel `(k, 1 - 2k, k)`, give the samples. The end cells spill into a neighbour of their
/// own value (the ring beyond is the boundary, not solved for better than that).
fn unspill(grid: &mut Grid, m: usize, k: f32) {
    let m = m.min(SIDE);
    let mut line = [0.0f32; SIDE];
    for row in grid.iter_mut().take(m) {
        line[..m].copy_from_slice(&row[..m]);
        solve_line(&mut line, m, k);
        row[..m].copy_from_slice(&line[..m]);
    }
    for c in 0..m {
        for r in 0..m {
            line[r] = grid[r][c];
        }
        solve_line(&mut line, m, k);
        for r in 0..m {
            grid[r][c] = line[r];
        }
    }
}

/// Solves the tridiagonal system `k x[i-1] + (1 - 2k) x[i] + k x[i+1] = line[i]` (at the
/// ends `(1 - k) x + k x[neighbour]`) in place, by the Thomas algorithm. For `k` below a
/// quarter the matrix is strictly diagonally dominant: no pivot is zero.
fn solve_line(line: &mut [f32; SIDE], m: usize, k: f32) {
    let m = m.min(SIDE);
    if m < 2 {
        return;
    }
    let diagonal = |i: usize| {
        if i == 0 || i + 1 == m {
            1.0 - k
        } else {
            1.0 - 2.0 * k
        }
    };
    let mut upper = [0.0f32; SIDE];
    let mut pivot = diagonal(0);
    upper[0] = k / pivot;
    line[0] /= pivot;
    for i in 1..m {
        pivot = diagonal(i) - k * upper[i - 1];
        upper[i] = k / pivot;
        line[i] = (line[i] - k * line[i - 1]) / pivot;
    }
    for i in (0..m - 1).rev() {
        line[i] -= upper[i] * line[i + 1];
    }
}

/// The black and white levels of a deblurred grid: planes through its border ring and
/// through the ring beside it (outside), as the first read learns them.
struct Levels {
    black: (f32, f32, f32),
    white: (f32, f32, f32),
    contrast: f32,
}

impl Levels {
    /// The levels of `grid` for a family of `n` cells with its border on ring `b`; `None`
    /// without a contrast.
    fn of(grid: &Grid, n: usize, b: isize) -> Option<Levels> {
        let (mut black, mut white) = (PlaneFit::default(), PlaneFit::default());
        for_ring(n, b, |r, c| {
            let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
            black.add(u, v, at(grid, r, c));
        });
        for_ring(n, b - 1, |r, c| {
            let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
            white.add(u, v, at(grid, r, c));
        });
        let contrast = white.mean() - black.mean();
        (contrast > 0.0).then(|| Levels {
            black: black.solve(),
            white: white.solve(),
            contrast,
        })
    }

    /// Cell (r, c) of `grid` less the threshold halfway between the levels there.
    fn relative(&self, grid: &Grid, r: isize, c: isize) -> f32 {
        let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
        let plane = |(a, b, c): (f32, f32, f32)| a + b * u + c * v;
        at(grid, r, c) - 0.5 * (plane(self.black) + plane(self.white))
    }

    /// How far the two rings' cells lie from their planes: the RMS, over the contrast.
    fn spread(&self, grid: &Grid, n: usize, b: isize) -> f32 {
        let (mut sum, mut count) = (0.0f32, 0usize);
        for (ring, (a, bu, bv)) in [(b, self.black), (b - 1, self.white)] {
            for_ring(n, ring, |r, c| {
                let (u, v) = (c as f32 + 0.5, r as f32 + 0.5);
                let e = at(grid, r, c) - (a + bu * u + bv * v);
                sum += e * e;
                count += 1;
            });
        }
        libm::sqrtf(sum / count.max(1) as f32) / self.contrast
    }
}

/// Cell (r, c) of the family's grid (ring -1 beyond it) in the sampled grid; 0 outside it.
fn at(grid: &Grid, r: isize, c: isize) -> f32 {
    let (r, c) = (r + 1, c + 1);
    if r < 0 || c < 0 {
        return 0.0;
    }
    grid.get(r as usize)
        .and_then(|row| row.get(c as usize))
        .copied()
        .unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::detect::decode::{lookup, read_robust};
    use crate::detect::pattern_fit::tests::{draw, SIZE};
    use crate::family::tables::TAG36H11;

    /// The solve undoes the kernel it models, on any line and spill tried.
    #[test]
    fn the_line_solve_inverts_the_spill() {
        for m in [3usize, 8, 12, SIDE] {
            for k in SPILLS {
                let truth: [f32; SIDE] =
                    core::array::from_fn(|i| ((i * 37 + m * 11) % 23) as f32 * 9.0 - 40.0);
                let mut line = [0.0f32; SIDE];
                for i in 0..m {
                    let left = truth[i.saturating_sub(1)];
                    let right = truth[(i + 1).min(m - 1)];
                    line[i] = k * left + (1.0 - 2.0 * k) * truth[i] + k * right;
                }
                solve_line(&mut line, m, k);
                for i in 0..m {
                    assert!((line[i] - truth[i]).abs() < 1e-3, "m {m} k {k} i {i}");
                }
            }
        }
    }

    /// Far markers of 11 to 12 pixels (cells of 1.4 pixels) behind a blur of 0.7 to 0.9
    /// pixels: the first read misses some of their codes, the deblurred read none, and
    /// neither reads another id.
    #[test]
    fn a_marker_blurred_across_its_cells_is_read_once_the_blur_is_taken_out() {
        let config = DetectorConfig::default();
        let (mut first, mut second, mut total) = (0, 0, 0);
        for (case, &(side, sigma)) in [(11.0f32, 0.7f32), (11.5, 0.8), (12.0, 0.9)]
            .iter()
            .cycle()
            .take(24)
            .enumerate()
        {
            let id = (case * 19 % 587) as u16;
            let centre = Point::new(31.6 + 0.07 * case as f32, 32.3 - 0.05 * case as f32);
            let (pixels, truth) = draw(id, side, 0.03 * case as f32, centre, sigma);
            let image = GrayImage::new(&pixels, SIZE, SIZE).unwrap();
            let mut samples = 0;
            let [plain, deblurred] = [read_robust, read_deblurred].map(|reader| {
                reader(&image, &TAG36H11, &truth, None, &config, &mut samples)
                    .and_then(|g| lookup(&TAG36H11, &g, 255))
            });
            for found in [plain, deblurred].iter().flatten() {
                assert_eq!(found.decoded.id, id, "case {case}: a wrong id");
            }
            first += usize::from(plain.is_some());
            second += usize::from(deblurred.is_some());
            total += 1;
        }
        std::println!("first read {first} of {total}, deblurred {second}");
        assert!(
            second == total && first < total,
            "{first} {second} of {total}"
        );
    }

    /// A sharp or large marker is not the deblurred read's, and a flat image reads nothing.
    #[test]
    fn large_markers_and_flat_images_get_no_deblurred_read() {
        let config = DetectorConfig::default();
        let mut samples = 0;
        let (pixels, truth) = draw(3, 40.0, 0.1, Point::new(32.0, 32.0), 0.8);
        let image = GrayImage::new(&pixels, SIZE, SIZE).unwrap();
        assert!(read_deblurred(&image, &TAG36H11, &truth, None, &config, &mut samples).is_none());
        assert_eq!(samples, 0);
        let flat = [128u8; SIZE * SIZE];
        let image = GrayImage::new(&flat, SIZE, SIZE).unwrap();
        let small = draw(3, 11.0, 0.0, Point::new(32.0, 32.0), 0.8).1;
        assert!(read_deblurred(&image, &TAG36H11, &small, None, &config, &mut samples).is_none());
    }
}
