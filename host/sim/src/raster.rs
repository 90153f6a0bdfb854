//! Area-sampled rendering of the world's radiance through the camera, with motion blur.
//!
//! Per camera pose, every pixel corner's ray ([`RayMap`]) is sent to the ground through one
//! homography (normalised image coordinates to pad-plane points). A pixel whose footprint is
//! uniform (`World::footprint`) costs one texture look-up at its centre, with the texture
//! filtered to the footprint's size; any other pixel (marker edges, the sheet's edge, the
//! shadow boundary, the occluder, the horizon) averages `s x s` sub-samples placed as in the
//! test renderer ("n-rooks" within an s x s stratification, so an edge lands within
//! 1/(2 s^2) pixel). Sub-samples on bare ground share the pixel's filtered texture value:
//! the texture has no detail finer than the footprint left.
//!
//! Motion blur averages the renders of several poses spread over the exposure; how many is
//! decided by the caller from how far the image moves ([`super::Simulator`]). With a rolling
//! shutter every row has its own poses ([`RowPoses`]), each row's pixel corners mapped by
//! its own homographies: a homography per row and sub-frame is cheap next to the pixels.
//! Rows are split between threads; every pixel is computed independently, so the result
//! does not depend on the thread count.

use super::camera::{CameraPose, RayMap};
use super::world::{Footprint, World, SKY_RADIANCE};
use crate::math::apply_homography;

/// The sub-frame poses each row of a frame is averaged over.
///
/// A global shutter exposes every row over the same poses ([`RowPoses::global`]); a rolling
/// shutter exposes each row at its own time, so each row has its own list, all of one length
/// ([`RowPoses::per_row`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RowPoses {
    poses: Vec<CameraPose>,
    /// Poses per row when every row has its own; `None` when all rows share `poses`.
    per_row: Option<usize>,
}

impl RowPoses {
    /// Every row over the same `poses`.
    pub fn global(poses: Vec<CameraPose>) -> Self {
        RowPoses {
            poses,
            per_row: None,
        }
    }

    /// Row `y` over `poses[y * per_row .. (y + 1) * per_row]`.
    pub fn per_row(per_row: usize, poses: Vec<CameraPose>) -> Self {
        RowPoses {
            poses,
            per_row: Some(per_row.max(1)),
        }
    }

    /// The poses of row `y` (empty past the last row given).
    pub fn row(&self, y: usize) -> &[CameraPose] {
        match self.per_row {
            None => &self.poses,
            Some(n) => self.poses.get(y * n..(y + 1) * n).unwrap_or(&[]),
        }
    }

    /// Sub-frames averaged per row (the first row's count; all rows have the same).
    pub fn subframes(&self) -> usize {
        self.row(0).len()
    }
}

/// Which pixels are sub-sampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampling {
    /// Only the pixels whose footprint is not uniform (`World::footprint`); the renderer's.
    Adaptive,
    /// Every pixel, uniform or not: the reference the adaptive sampling is tested against
    /// (a uniform footprint's sub-samples all see the same albedo and light, so the two
    /// differ only where a mixed footprint was taken for a uniform one).
    Exhaustive,
}

/// Renders the mean radiance of each row over its poses into a `width x height` buffer.
pub fn render_radiance(
    world: &World,
    rays: &RayMap,
    width: usize,
    height: usize,
    poses: &RowPoses,
    supersampling: usize,
    threads: usize,
) -> Vec<f32> {
    render_radiance_sampled(
        world,
        rays,
        width,
        height,
        poses,
        supersampling,
        threads,
        Sampling::Adaptive,
    )
}

/// [`render_radiance`] with the pixels to sub-sample chosen by `sampling`.
#[allow(clippy::too_many_arguments)]
pub fn render_radiance_sampled(
    world: &World,
    rays: &RayMap,
    width: usize,
    height: usize,
    poses: &RowPoses,
    supersampling: usize,
    threads: usize,
    sampling: Sampling,
) -> Vec<f32> {
    let mut out = vec![0.0f32; width * height];
    if width == 0 || height == 0 || poses.row(0).is_empty() {
        return out;
    }
    let threads = threads.clamp(1, height);
    let rows_per_band = height.div_ceil(threads);
    std::thread::scope(|scope| {
        for (band, chunk) in out.chunks_mut(rows_per_band * width).enumerate() {
            let y0 = band * rows_per_band;
            let mut job = move || {
                let rows = chunk.len() / width;
                match poses.per_row {
                    None => render_band_global(
                        world,
                        rays,
                        width,
                        y0,
                        rows,
                        &poses.poses,
                        supersampling,
                        sampling,
                        chunk,
                    ),
                    Some(_) => render_band_rolling(
                        world,
                        rays,
                        width,
                        y0,
                        poses,
                        supersampling,
                        sampling,
                        chunk,
                    ),
                }
            };
            if threads == 1 {
                job();
            } else {
                scope.spawn(job);
            }
        }
    });
    out
}

/// A band of rows that all share `poses`: one pose at a time over the whole band, each
/// mapped row of pixel corners used as the bottom of one row and the top of the next.
#[allow(clippy::too_many_arguments)]
fn render_band_global(
    world: &World,
    rays: &RayMap,
    width: usize,
    y0: usize,
    rows: usize,
    poses: &[CameraPose],
    supersampling: usize,
    sampling: Sampling,
    chunk: &mut [f32],
) {
    let weight = 1.0 / poses.len() as f32;
    let mut scratch = vec![0.0f32; chunk.len()];
    let mut row_scratch = RowScratch::default();
    let mut top: Vec<Option<(f64, f64)>> = Vec::with_capacity(width + 1);
    let mut bottom: Vec<Option<(f64, f64)>> = Vec::with_capacity(width + 1);
    for pose in poses {
        let h = pose.ground_homography();
        map_corner_row(&mut top, rays, &h, width, y0);
        for r in 0..rows {
            let y = y0 + r;
            map_corner_row(&mut bottom, rays, &h, width, y + 1);
            let row_out = scratch
                .get_mut(r * width..(r + 1) * width)
                .unwrap_or(&mut []);
            shade_row(
                world,
                rays,
                &h,
                width,
                y,
                &top,
                &bottom,
                supersampling,
                sampling,
                row_out,
                &mut row_scratch,
            );
            std::mem::swap(&mut top, &mut bottom);
        }
        for (o, s) in chunk.iter_mut().zip(&scratch) {
            *o += weight * s;
        }
    }
}

/// A band of rows each exposed over its own poses (a rolling shutter): row by row, each
/// pose's homography mapping the row's top and bottom pixel corners.
#[allow(clippy::too_many_arguments)]
fn render_band_rolling(
    world: &World,
    rays: &RayMap,
    width: usize,
    y0: usize,
    poses: &RowPoses,
    supersampling: usize,
    sampling: Sampling,
    chunk: &mut [f32],
) {
    let mut scratch = vec![0.0f32; width];
    let mut row_scratch = RowScratch::default();
    let mut top: Vec<Option<(f64, f64)>> = Vec::with_capacity(width + 1);
    let mut bottom: Vec<Option<(f64, f64)>> = Vec::with_capacity(width + 1);
    for (r, row_out) in chunk.chunks_mut(width).enumerate() {
        let y = y0 + r;
        let row_poses = poses.row(y);
        let weight = 1.0 / row_poses.len().max(1) as f32;
        for pose in row_poses {
            let h = pose.ground_homography();
            map_corner_row(&mut top, rays, &h, width, y);
            map_corner_row(&mut bottom, rays, &h, width, y + 1);
            shade_row(
                world,
                rays,
                &h,
                width,
                y,
                &top,
                &bottom,
                supersampling,
                sampling,
                &mut scratch,
                &mut row_scratch,
            );
            for (o, s) in row_out.iter_mut().zip(&scratch) {
                *o += weight * s;
            }
        }
    }
}

/// The ground points of pixel-corner row `j` through `h`.
fn map_corner_row(
    out: &mut Vec<Option<(f64, f64)>>,
    rays: &RayMap,
    h: &[[f64; 3]; 3],
    width: usize,
    j: usize,
) {
    out.clear();
    out.extend((0..=width).map(|i| ground(h, rays.corner(i, j))));
}

/// Ground point of a normalised ray, `None` for rays that miss the ground or failed to
/// undistort.
#[inline]
fn ground(h: &[[f64; 3]; 3], ray: [f64; 2]) -> Option<(f64, f64)> {
    if ray[0].is_nan() {
        return None;
    }
    apply_homography(h, ray[0], ray[1])
}

/// What a pixel of a row still needs once its footprint is known: the ground's texture at
/// [`RowScratch::points`], then either only the light or its sub-samples.
#[derive(Debug, Clone, Copy)]
enum Pending {
    /// Uniform bare ground under this illumination.
    Ground(f64),
    /// Mixed: sub-sampled with the texture as every sub-sample's bare-ground albedo.
    Mixed,
}

/// Buffers reused from row to row: the pixels of a row that wait for the ground's texture,
/// which is looked up for all of them at once ([`crate::texture::GroundTexture::albedo_batch`]).
#[derive(Debug, Default)]
pub(crate) struct RowScratch {
    /// Pixel and what it needs.
    pending: Vec<(usize, Pending)>,
    /// Where the texture is wanted: `[x, y, footprint_m]`.
    points: Vec<[f64; 3]>,
    /// The texture there.
    albedo: Vec<f32>,
}

/// The radiance of pixel row `y` through `h`, from the ground points of its top and bottom
/// pixel corners.
#[allow(clippy::too_many_arguments)]
fn shade_row(
    world: &World,
    rays: &RayMap,
    h: &[[f64; 3]; 3],
    width: usize,
    y: usize,
    top: &[Option<(f64, f64)>],
    bottom: &[Option<(f64, f64)>],
    supersampling: usize,
    sampling: Sampling,
    out: &mut [f32],
    scratch: &mut RowScratch,
) {
    let s = supersampling.max(1);
    let fine = 1.0 / (s * s) as f64;
    let corner = |row: &[Option<(f64, f64)>], i: usize| row.get(i).copied().flatten();
    scratch.pending.clear();
    scratch.points.clear();
    for (x, o) in out.iter_mut().enumerate().take(width) {
        let corners = [
            corner(top, x),
            corner(top, x + 1),
            corner(bottom, x + 1),
            corner(bottom, x),
        ];
        match corners {
            [Some(a), Some(b), Some(c), Some(d)] => {
                let quad = [a, b, c, d];
                let uniform = match sampling {
                    Sampling::Adaptive => {
                        (world.footprint(&quad), world.footprint_illumination(&quad))
                    }
                    Sampling::Exhaustive => (Footprint::Mixed, None),
                };
                match uniform {
                    (Footprint::Uniform(Some(albedo)), Some(light)) => {
                        *o = (f64::from(albedo) * light) as f32;
                        continue;
                    }
                    (Footprint::Uniform(None), Some(light)) => {
                        scratch.pending.push((x, Pending::Ground(light)));
                    }
                    _ => scratch.pending.push((x, Pending::Mixed)),
                }
                let centre = (
                    0.25 * (a.0 + b.0 + c.0 + d.0),
                    0.25 * (a.1 + b.1 + c.1 + d.1),
                );
                // The longest of three sides; one square root (it keeps the order).
                let footprint_m = dist2(a, b).max(dist2(a, d)).max(dist2(b, c)).sqrt();
                scratch.points.push([centre.0, centre.1, footprint_m]);
            }
            // Part of the footprint sees the sky (or lies outside the lens model): per
            // sample, with the texture taken where the pixel does see the ground.
            _ => match corners.iter().flatten().next() {
                Some(p) => {
                    scratch.pending.push((x, Pending::Mixed));
                    scratch.points.push([p.0, p.1, 1.0]);
                }
                None => *o = supersample(world, rays, h, x, y, s, fine, 0.0),
            },
        }
    }
    scratch.albedo.resize(scratch.points.len(), 0.0);
    world
        .ground
        .albedo_batch(&scratch.points, &mut scratch.albedo);
    for (&(x, pending), &albedo) in scratch.pending.iter().zip(&scratch.albedo) {
        let Some(o) = out.get_mut(x) else {
            continue;
        };
        *o = match pending {
            Pending::Ground(light) => (f64::from(albedo) * light) as f32,
            Pending::Mixed => supersample(world, rays, h, x, y, s, fine, albedo),
        };
    }
}

/// Squared distance.
#[inline]
fn dist2(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)
}

/// Mean radiance of `s x s` sub-samples of pixel `(x, y)`.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn supersample(
    world: &World,
    rays: &RayMap,
    h: &[[f64; 3]; 3],
    x: usize,
    y: usize,
    s: usize,
    fine: f64,
    ground_albedo: f32,
) -> f32 {
    let r00 = rays.corner(x, y);
    let r10 = rays.corner(x + 1, y);
    let r01 = rays.corner(x, y + 1);
    let r11 = rays.corner(x + 1, y + 1);
    let mut sum = 0.0f64;
    for sy in 0..s {
        for sx in 0..s {
            // Position inside the pixel, [0, 1) on each axis (same pattern as the test
            // renderer).
            let u = ((sx * s + sy) as f64 + 0.5) * fine;
            let v = ((sy * s + sx) as f64 + 0.5) * fine;
            let ray = [
                (1.0 - v) * ((1.0 - u) * r00[0] + u * r10[0])
                    + v * ((1.0 - u) * r01[0] + u * r11[0]),
                (1.0 - v) * ((1.0 - u) * r00[1] + u * r10[1])
                    + v * ((1.0 - u) * r01[1] + u * r11[1]),
            ];
            sum += match ground(h, ray) {
                Some((gx, gy)) => {
                    let albedo = world.object_albedo(gx, gy).unwrap_or(ground_albedo);
                    f64::from(albedo) * world.illumination(gx, gy)
                }
                None => f64::from(SKY_RADIANCE),
            };
        }
    }
    (sum / (s * s) as f64) as f32
}
