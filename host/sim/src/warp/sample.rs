//! The warp renderer's pixels: one ground point per pixel through its row's homography, the
//! footprint from the homography's derivative, motion blur as the footprint's sweep, and the
//! pre-rasterised world box-filtered over it.
//!
//! Per pixel: the ray of its centre (undistorted once, with the ray's derivative along the
//! pixel axes) meets the ground through the homography of its row's pose (the middle of the
//! row's exposure, so a rolling shutter is a homography per row). The footprint is the
//! parallelogram the pixel's axes map to, `J = d ground / d pixel`; the motion during the
//! exposure sweeps it along the path the image travels, which adds the path's spread
//! (its covariance, in pixels) to the pixel's own box and moves its centre by the path's
//! mean: `W = J (I + 12 Cov) J^T`. The path is measured at a sparse grid of knots (every
//! [`KNOT_ROWS`] rows, three columns) from poses spread over each knot row's exposure, and
//! interpolated in between. The world is then averaged over the box with the footprint's
//! widths along the pad's and each marker's axes (`super::texture`), the light over the
//! footprint's width across the shadow edge and the occluder's rim.
//!
//! A pixel whose centre ray misses the ground sees the sky whole (no partial horizon).

use std::collections::HashMap;

use super::texture::{Footprint, GroundPyramid, PadTables};
use crate::camera::{CameraPose, RayMap};
use crate::math::{apply_homography, Mat3};
use crate::world::{World, SKY_RADIANCE};
use crate::Simulator;

/// Rows between motion knots.
pub const KNOT_ROWS: usize = 8;
/// Pixels along a row that share one interpolation of the motion knots (the motion changes
/// by hundredths of a pixel over them).
const MOTION_RUN: usize = 16;
/// Most pieces of an exposure's image path (with vibration: one per
/// [`crate::VIBRATION_MOTION_STEP_S`] of a grid shared by the rows, longer for long
/// exposures).
const MAX_PIECES: usize = 16;

/// Per pixel: the centre's normalised ray `(x, y)` and its derivatives along the pixel's
/// axes `(dx/du, dy/du, dx/dv, dy/dv)`; `x` NaN where the lens has no inverse.
pub(crate) fn pixel_rays(rays: &RayMap, width: usize, height: usize) -> Vec<[f32; 6]> {
    let mut out = Vec::with_capacity(width * height);
    for j in 0..height {
        for i in 0..width {
            let (c00, c10, c01, c11) = (
                rays.corner(i, j),
                rays.corner(i + 1, j),
                rays.corner(i, j + 1),
                rays.corner(i + 1, j + 1),
            );
            let centre = [
                0.25 * (c00[0] + c10[0] + c01[0] + c11[0]),
                0.25 * (c00[1] + c10[1] + c01[1] + c11[1]),
            ];
            let du = [
                0.5 * (c10[0] - c00[0] + c11[0] - c01[0]),
                0.5 * (c10[1] - c00[1] + c11[1] - c01[1]),
            ];
            let dv = [
                0.5 * (c01[0] - c00[0] + c11[0] - c10[0]),
                0.5 * (c01[1] - c00[1] + c11[1] - c10[1]),
            ];
            let v = [centre[0], centre[1], du[0], du[1], dv[0], dv[1]];
            out.push(if v.iter().all(|x| x.is_finite()) {
                v.map(|x| x as f32)
            } else {
                [f32::NAN; 6]
            });
        }
    }
    out
}

/// The light and the occluder in closed form.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Light {
    sky: f64,
    direct: f64,
    /// Point, unit normal into the shadow, penumbra width.
    shadow: Option<([f64; 2], [f64; 2], f64)>,
    occluder: Option<Blob>,
}

/// The occluder as the light's closed forms need it.
#[derive(Debug, Clone, Copy)]
struct Blob {
    centre: [f64; 2],
    /// Pad frame to the unit circle's.
    to_unit: [[f64; 2]; 2],
    albedo: f64,
    /// Bounding radius, metres.
    reach: f64,
}

impl Light {
    pub(crate) fn new(world: &World) -> Self {
        let l = &world.lighting;
        let occluder = world
            .occluder
            .filter(|o| o.radii[0] > 0.0 && o.radii[1] > 0.0)
            .map(|o| {
                let (s, c) = o.angle_deg.to_radians().sin_cos();
                let a = [
                    [c / o.radii[0], s / o.radii[0]],
                    [-s / o.radii[1], c / o.radii[1]],
                ];
                Blob {
                    centre: o.center,
                    to_unit: a,
                    albedo: f64::from(o.albedo),
                    reach: o.radii[0].max(o.radii[1]),
                }
            });
        Light {
            sky: l.sky,
            direct: l.direct,
            shadow: l.shadow.map(|s| (s.point, s.normal, s.penumbra_m.max(0.0))),
            occluder,
        }
    }

    /// Mean illumination over the footprint.
    #[inline]
    fn illumination(&self, f: &Footprint) -> f64 {
        let Some((p, n, penumbra)) = self.shadow else {
            return self.sky + self.direct;
        };
        let depth = (f.x - p[0]) * n[0] + (f.y - p[1]) * n[1];
        let w = f.width2(n[0], n[1]).max(0.0).sqrt();
        // The sun's fraction (1 lit, falling linearly across the penumbra to 0) averaged over
        // the footprint's width across the edge, through its integral.
        let integral = |d: f64| -> f64 {
            if penumbra <= 0.0 {
                return d.min(0.0);
            }
            let h = 0.5 * penumbra;
            if d <= -h {
                d
            } else if d >= h {
                0.0
            } else {
                -h + 0.5 * d - d * d / (2.0 * penumbra) + 0.75 * h
            }
        };
        let sun = if w < 1e-9 {
            if penumbra <= 0.0 {
                if depth > 0.0 {
                    0.0
                } else {
                    1.0
                }
            } else {
                (0.5 - depth / penumbra).clamp(0.0, 1.0)
            }
        } else {
            ((integral(depth + 0.5 * w) - integral(depth - 0.5 * w)) / w).clamp(0.0, 1.0)
        };
        self.sky + self.direct * sun
    }

    /// The occluder's albedo and the fraction of the footprint it covers (its rim a straight
    /// edge at the footprint's scale).
    #[inline]
    fn occluder(&self, f: &Footprint) -> Option<(f64, f64)> {
        let Blob {
            centre: c,
            to_unit: a,
            albedo,
            reach,
        } = self.occluder?;
        let (dx, dy) = (f.x - c[0], f.y - c[1]);
        let wide = f.wxx.max(f.wyy).max(0.0).sqrt();
        if dx.abs() > reach + wide || dy.abs() > reach + wide {
            return None;
        }
        let u = a[0][0] * dx + a[0][1] * dy;
        let v = a[1][0] * dx + a[1][1] * dy;
        let rho = (u * u + v * v).sqrt();
        // The footprint's width along the radius, in the unit circle's measure.
        let (nu, nv) = if rho > 1e-12 {
            (u / rho, v / rho)
        } else {
            (1.0, 0.0)
        };
        let (ex, ey) = (nu * a[0][0] + nv * a[1][0], nu * a[0][1] + nv * a[1][1]);
        let w = f.width2(ex, ey).max(0.0).sqrt();
        let cover = if w < 1e-9 {
            if rho <= 1.0 {
                1.0
            } else {
                0.0
            }
        } else {
            (0.5 - (rho - 1.0) / w).clamp(0.0, 1.0)
        };
        (cover > 0.0).then_some((albedo, cover))
    }
}

/// The path of the image during a knot's exposure: `M = I + 12 Cov` (pixels squared, the
/// pixel's own box plus the sweep) and the mean displacement to add to the ground point
/// (pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Motion {
    m: [f64; 3],
    mu: [f64; 2],
}

impl Motion {
    const STILL: Motion = Motion {
        m: [1.0, 0.0, 1.0],
        mu: [0.0, 0.0],
    };

    fn lerp(a: &Motion, b: &Motion, t: f64) -> Motion {
        let l = |p: f64, q: f64| p + t * (q - p);
        Motion {
            m: [l(a.m[0], b.m[0]), l(a.m[1], b.m[1]), l(a.m[2], b.m[2])],
            mu: [l(a.mu[0], b.mu[0]), l(a.mu[1], b.mu[1])],
        }
    }

    /// From the image positions of one ground point at instants `times` of the exposure,
    /// relative to its position at the row's time: each piece between two instants travelled
    /// at constant speed, weighed by its duration.
    fn of_path(path: &[[f64; 2]], times: &[f64]) -> Motion {
        let total = match (times.first(), times.last()) {
            (Some(a), Some(b)) if b > a && path.len() == times.len() => b - a,
            _ => return Motion::STILL,
        };
        let (mut ex, mut ey, mut exx, mut exy, mut eyy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (w, t) in path.windows(2).zip(times.windows(2)) {
            let (p, q) = (w[0], w[1]);
            let k = (t[1] - t[0]) / total;
            ex += k * 0.5 * (p[0] + q[0]);
            ey += k * 0.5 * (p[1] + q[1]);
            exx += k * ((p[0] * p[0] + q[0] * q[0]) / 3.0 + p[0] * q[0] / 3.0);
            eyy += k * ((p[1] * p[1] + q[1] * q[1]) / 3.0 + p[1] * q[1] / 3.0);
            exy += k * ((p[0] * p[1] + q[0] * q[1]) / 3.0 + (p[0] * q[1] + q[0] * p[1]) / 6.0);
        }
        let (cxx, cxy, cyy) = (exx - ex * ex, exy - ex * ey, eyy - ey * ey);
        // The pixel sees, at each instant, the ground point the image moved onto it: the
        // opposite of the displacement.
        Motion {
            m: [
                1.0 + 12.0 * cxx.max(0.0),
                12.0 * cxy,
                1.0 + 12.0 * cyy.max(0.0),
            ],
            mu: [-ex, -ey],
        }
    }
}

/// The motion knots of a frame: `rows` knot rows of three columns each.
pub(crate) struct Knots {
    rows: Vec<usize>,
    motion: Vec<[Motion; 3]>,
}

impl Knots {
    /// The knots of the frame at `t` exposed for `exposure_s`; `None` when nothing moves.
    pub(crate) fn new(
        sim: &Simulator,
        rays: &[[f32; 6]],
        t: f64,
        exposure_s: f64,
    ) -> Option<Knots> {
        let cam = &sim.scenario.camera;
        let (w, h) = (cam.width(), cam.height());
        if exposure_s <= 0.0 || w == 0 || h == 0 {
            return None;
        }
        let mut rows: Vec<usize> = (0..h).step_by(KNOT_ROWS).collect();
        if rows.last() != Some(&(h - 1)) {
            rows.push(h - 1);
        }
        let columns = [0.0, 0.5 * (w as f64 - 1.0), w as f64 - 1.0];
        let vibrating = !sim.scenario.vibration.is_none();
        let mut moved = false;
        let mut motion = Vec::with_capacity(rows.len());
        let mut path = Vec::with_capacity(MAX_PIECES + 2);
        let mut times = Vec::with_capacity(MAX_PIECES + 2);
        // Poses by their time's bits: the knot rows' exposures overlap, and their inner
        // instants lie on one grid, so most poses serve several rows.
        let mut cache: HashMap<u64, CameraPose> = HashMap::new();
        let mut pose_at = |time: f64| {
            *cache
                .entry(time.to_bits())
                .or_insert_with(|| sim.camera_pose(time))
        };
        for &y in &rows {
            let (open, close) = sim.row_exposure_window(t, y as f64, exposure_s);
            let span = close - open;
            if span <= 0.0 {
                motion.push([Motion::STILL; 3]);
                continue;
            }
            times.clear();
            times.push(open);
            if vibrating {
                // The grid's instants inside the exposure, at most MAX_PIECES pieces.
                let step = crate::VIBRATION_MOTION_STEP_S;
                let stride = (span / (step * MAX_PIECES as f64)).ceil().max(1.0) * step;
                let mut k = (open / stride).floor() + 1.0;
                while k * stride < close - 1e-9 && times.len() < MAX_PIECES + 1 {
                    times.push(k * stride);
                    k += 1.0;
                }
            } else {
                times.push(open + 0.5 * span);
            }
            times.push(close);
            let middle = pose_at(sim.row_time(t, y as f64));
            let poses: Vec<CameraPose> = times.iter().map(|&time| pose_at(time)).collect();
            let hm = middle.ground_homography();
            let mut row = [Motion::STILL; 3];
            for (slot, &cx) in row.iter_mut().zip(&columns) {
                let x = (cx + 0.5) as usize;
                let Some(r) = rays.get(y * w + x.min(w - 1)) else {
                    continue;
                };
                let Some(g) = apply_homography(&hm, f64::from(r[0]), f64::from(r[1])) else {
                    continue;
                };
                let ground = [g.0, g.1, 0.0];
                let Some(at) = cam.project(middle.to_camera(ground)) else {
                    continue;
                };
                path.clear();
                for pose in &poses {
                    match cam.project(pose.to_camera(ground)) {
                        Some(p) => path.push([p[0] - at[0], p[1] - at[1]]),
                        None => break,
                    }
                }
                if path.len() == poses.len() {
                    *slot = Motion::of_path(&path, &times);
                    moved |= *slot != Motion::STILL;
                }
            }
            motion.push(row);
        }
        moved.then_some(Knots { rows, motion })
    }

    /// The three column knots of row `y`, interpolated between knot rows.
    fn row(&self, y: usize) -> [Motion; 3] {
        let k = self.rows.partition_point(|&r| r <= y).saturating_sub(1);
        let (Some(&r0), Some(m0)) = (self.rows.get(k), self.motion.get(k)) else {
            return [Motion::STILL; 3];
        };
        let (Some(&r1), Some(m1)) = (self.rows.get(k + 1), self.motion.get(k + 1)) else {
            return *m0;
        };
        let t = (y - r0) as f64 / (r1 - r0).max(1) as f64;
        [0, 1, 2].map(|i| Motion::lerp(&m0[i], &m1[i], t))
    }
}

/// What the pixels are sampled from.
pub(crate) struct Sources<'a> {
    pub pad: &'a PadTables,
    pub ground: &'a GroundPyramid,
    pub light: Light,
    pub rays: &'a [[f32; 6]],
    pub cos_off_axis: &'a [f32],
    pub vignetting: f32,
}

/// Renders radiance (vignetting applied) with row `y` seen through `homographies[y]` (or the
/// one homography of a global shutter), on `threads` threads (the result does not depend on
/// it).
pub(crate) fn render_radiance(
    src: &Sources<'_>,
    width: usize,
    height: usize,
    homographies: &[Mat3],
    knots: Option<&Knots>,
    threads: usize,
) -> Vec<f32> {
    let mut out = vec![0.0f32; width * height];
    if width == 0 || height == 0 || homographies.is_empty() {
        return out;
    }
    let threads = threads.clamp(1, height);
    let rows_per_band = height.div_ceil(threads);
    std::thread::scope(|scope| {
        for (band, chunk) in out.chunks_mut(rows_per_band * width).enumerate() {
            let mut job = move || {
                let mut scratch = RowScratch::default();
                for (r, row) in chunk.chunks_mut(width).enumerate() {
                    let y = band * rows_per_band + r;
                    let h = homographies
                        .get(y)
                        .or(homographies.first())
                        .copied()
                        .unwrap_or([[0.0; 3]; 3]);
                    let motion = knots.map(|k| k.row(y));
                    shade_row(src, &h, motion.as_ref(), y, width, row, &mut scratch);
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

/// A row's footprints and albedos, between the passes of [`shade_row`].
#[derive(Default)]
struct RowScratch {
    footprints: Vec<Footprint>,
    albedo: Vec<f64>,
    near_pad: Vec<usize>,
}

/// One row in passes (footprints, ground, pad, light), each a short loop whose iterations
/// the processor overlaps: one pass per pixel would be one long chain of dependent steps.
fn shade_row(
    src: &Sources<'_>,
    h: &Mat3,
    motion: Option<&[Motion; 3]>,
    y: usize,
    width: usize,
    out: &mut [f32],
    scratch: &mut RowScratch,
) {
    let rays = src.rays.get(y * width..(y + 1) * width).unwrap_or(&[]);
    let cos = src
        .cos_off_axis
        .get(y * width..(y + 1) * width)
        .unwrap_or(&[]);
    // In spans short enough for a span's footprints to stay in the first-level cache
    // between the passes.
    for ((rays, cos), (k, out)) in rays
        .chunks(SPAN)
        .zip(cos.chunks(SPAN))
        .zip(out.chunks_mut(SPAN).enumerate())
    {
        shade_span(src, h, motion, width, k * SPAN, rays, cos, out, scratch);
    }
}

/// Pixels shaded a pass at a time.
const SPAN: usize = 128;

/// Pixels `x0..` of a row (their rays and cosines): [`shade_row`]'s passes.
#[allow(clippy::too_many_arguments)]
fn shade_span(
    src: &Sources<'_>,
    h: &Mat3,
    motion: Option<&[Motion; 3]>,
    width: usize,
    x0: usize,
    rays: &[[f32; 6]],
    cos: &[f32],
    out: &mut [f32],
    scratch: &mut RowScratch,
) {
    let half = 0.5 * (width as f64 - 1.0);
    let inv_half = 1.0 / half.max(1e-9);
    const SKY: Footprint = Footprint {
        x: f64::NAN,
        y: f64::NAN,
        wxx: 0.0,
        wxy: 0.0,
        wyy: 0.0,
    };
    scratch.footprints.clear();
    scratch.footprints.resize(rays.len(), SKY);
    let mut mo = Motion::STILL;
    for (x, (r, slot)) in rays.iter().zip(scratch.footprints.iter_mut()).enumerate() {
        // The knots interpolated at the middle of each run of MOTION_RUN pixels.
        let x = x0 + x;
        if let (Some(knots), 0) = (motion, x % MOTION_RUN) {
            let xf = (x + MOTION_RUN / 2) as i64 as f64;
            mo = if xf <= half {
                Motion::lerp(&knots[0], &knots[1], xf * inv_half)
            } else {
                Motion::lerp(&knots[1], &knots[2], ((xf - half) * inv_half).min(1.0))
            };
        }
        let (rx, ry) = (f64::from(r[0]), f64::from(r[1]));
        let w = h[2][0] * rx + h[2][1] * ry + h[2][2];
        // NaN rays fail this too; the sky is a NaN footprint.
        if w.is_nan() || w <= 1e-12 {
            continue;
        }
        let iw = 1.0 / w;
        let gx = (h[0][0] * rx + h[0][1] * ry + h[0][2]) * iw;
        let gy = (h[1][0] * rx + h[1][1] * ry + h[1][2]) * iw;
        // d ground / d ray, then d ground / d pixel along u (a) and v (b).
        let d00 = (h[0][0] - gx * h[2][0]) * iw;
        let d01 = (h[0][1] - gx * h[2][1]) * iw;
        let d10 = (h[1][0] - gy * h[2][0]) * iw;
        let d11 = (h[1][1] - gy * h[2][1]) * iw;
        let (r2, r3, r4, r5) = (
            f64::from(r[2]),
            f64::from(r[3]),
            f64::from(r[4]),
            f64::from(r[5]),
        );
        let a = [d00 * r2 + d01 * r3, d10 * r2 + d11 * r3];
        let b = [d00 * r4 + d01 * r5, d10 * r4 + d11 * r5];
        *slot = match motion {
            None => Footprint {
                x: gx,
                y: gy,
                wxx: a[0] * a[0] + b[0] * b[0],
                wxy: a[0] * a[1] + b[0] * b[1],
                wyy: a[1] * a[1] + b[1] * b[1],
            },
            Some(_) => {
                let [m0, m1, m2] = mo.m;
                // J M with J = [a b] (columns), then (J M) J^T.
                let jm = [
                    [a[0] * m0 + b[0] * m1, a[0] * m1 + b[0] * m2],
                    [a[1] * m0 + b[1] * m1, a[1] * m1 + b[1] * m2],
                ];
                Footprint {
                    x: gx + a[0] * mo.mu[0] + b[0] * mo.mu[1],
                    y: gy + a[1] * mo.mu[0] + b[1] * mo.mu[1],
                    wxx: jm[0][0] * a[0] + jm[0][1] * b[0],
                    wxy: jm[0][0] * a[1] + jm[0][1] * b[1],
                    wyy: jm[1][0] * a[1] + jm[1][1] * b[1],
                }
            }
        };
    }
    // The ground under every pixel away from the pad; the pad's pixels after.
    scratch.albedo.clear();
    scratch.albedo.resize(scratch.footprints.len(), 0.0);
    scratch.near_pad.clear();
    for (x, (f, albedo)) in scratch
        .footprints
        .iter()
        .zip(scratch.albedo.iter_mut())
        .enumerate()
    {
        if f.x.is_nan() {
            continue;
        }
        if src.pad.near(f) {
            scratch.near_pad.push(x);
        } else {
            *albedo = src.ground.sample(f.x, f.y, f.longest2());
        }
    }
    let mut hint = 0;
    for &x in &scratch.near_pad {
        let (Some(f), Some(albedo)) = (scratch.footprints.get(x), scratch.albedo.get_mut(x)) else {
            continue;
        };
        *albedo = pad_albedo(src, f, &mut hint);
    }
    for (((o, f), &albedo), &c) in out
        .iter_mut()
        .zip(&scratch.footprints)
        .zip(&scratch.albedo)
        .zip(cos)
    {
        let gain = 1.0 - src.vignetting * (1.0 - c * c * c * c);
        *o = if f.x.is_nan() {
            SKY_RADIANCE
        } else {
            lit(src, f, albedo) as f32
        } * gain;
    }
}

/// The albedo of a footprint that may reach the pad: the printed paper's share, the rest
/// ground.
#[inline]
fn pad_albedo(src: &Sources<'_>, f: &Footprint, hint: &mut usize) -> f64 {
    match src.pad.cover(f, hint) {
        None => src.ground.sample(f.x, f.y, f.longest2()),
        Some(c) if c.paper >= 1.0 => c.albedo_sum / c.paper,
        Some(c) => c.albedo_sum + (1.0 - c.paper) * src.ground.sample(f.x, f.y, f.longest2()),
    }
}

/// Radiance of a footprint of this albedo: under the occluder, in the light.
#[inline]
fn lit(src: &Sources<'_>, f: &Footprint, albedo: f64) -> f64 {
    let albedo = match src.light.occluder(f) {
        Some((a, cover)) => albedo + cover * (a - albedo),
        None => albedo,
    };
    albedo * src.light.illumination(f)
}
