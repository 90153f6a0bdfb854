//! The least-squares machinery of the fit: one pass of the model over the window's pixels
//! into normal equations, the linear solve of the levels, and the damped Cholesky solve of
//! a step.

// The normal equations are fixed N x N arrays indexed by loop counters below N (and the
// counters index two arrays at once, which iterators made slower on the Cortex-M7).
#![allow(clippy::indexing_slicing, clippy::needless_range_loop)]

use super::model::{blurred, known_cells, with_outside, Axis, Pattern, SIDES};
use super::{
    fitted_corners, Refusal, Window, BAND, BAND_PULL, BLACK, BLUR, BLUR_V, CONTRAST,
    MAX_BAND_CELLS, N, OUTSIDE, OUTSIDE_PULL,
};
use crate::geometry::{Homography, Point};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// Normal equations of one iteration: `J^T J`, `J^T e` and the residual sum of squares.
pub(super) struct Normal {
    pub(super) jtj: [[f32; N]; N],
    pub(super) jte: [f32; N],
    pub(super) cost: f32,
    pub(super) count: usize,
}

/// What one pass over the window computes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Pass {
    /// The cost and the normal equations of every parameter.
    Full,
    /// The cost only.
    Cost,
}

/// The model at every window pixel for `params`, accumulated as `pass` says; each side's
/// outside level is pulled towards the sides' mean with the weight [`OUTSIDE_PULL`] (in the
/// cost and, in a full pass, the normal equations).
///
/// The corners' derivatives are closed-form: for the homography of the unit square onto
/// itself, moving corner k by (dx, dy) moves the point (s, t) by
/// `(N_k dx + sign_k s(1-s) dy, sign_k t(1-t) dx + N_k dy)`, with `N_k` the bilinear weight
/// of the corner and `sign_k` -1 for the top-left and bottom-right corners, +1 for the
/// others (solve the four corner conditions of `I + e A` to first order). The quad's affine
/// part carries image moves into the square and back: exact to first order for a
/// parallelogram, and a far marker is one to within its small perspective. It saves eight
/// homographies per pixel.
pub(super) fn linearise(
    pattern: &Pattern,
    win: &Window,
    params: &[f32; N],
    pass: Pass,
) -> Option<Normal> {
    let corners = fitted_corners(params);
    let map = Homography::from_4_points(&corners, &pattern.corner_points())?;
    let (blur, black, contrast) = (libm::expf(params[BLUR]), params[BLACK], params[CONTRAST]);
    let blur_v = libm::expf(params[BLUR_V]);
    // A band is as wide as its parameter within 0 and `MAX_BAND_CELLS`; outside them the
    // parameter has no derivative, and the pull below brings it back.
    let (mut bands, mut band_free) = ([0.0f32; SIDES], [false; SIDES]);
    for k in 0..SIDES {
        bands[k] = params[BAND + k].clamp(0.0, MAX_BAND_CELLS);
        band_free[k] = bands[k] == params[BAND + k];
    }
    let mut outside = [0.0f32; SIDES];
    for (level, p) in outside.iter_mut().zip(params.iter().skip(OUTSIDE)) {
        *level = *p;
    }
    let (lo, span) = (pattern.quad_lo, pattern.quad_hi - pattern.quad_lo);
    let square_from_image = square_from_image(&corners)?;
    let mut normal = Normal {
        jtj: [[0.0; N]; N],
        jte: [0.0; N],
        cost: 0.0,
        count: 0,
    };
    // The pixel's two axes, rewritten in place for each pixel (see `Axis::set`).
    let (mut au, mut av) = (Axis::EMPTY, Axis::EMPTY);
    for sample in &win.samples {
        let observed = f32::from(sample.value);
        let (x, y) = (sample.x, sample.y);
        let g = map.map(f32::from(x), f32::from(y))?;
        au.set(g.x, blur, pattern.side, [bands[0], bands[1]])?;
        av.set(g.y, blur_v, pattern.side, [bands[2], bands[3]])?;
        let b = blurred(pattern, &au, &av, &outside);
        let e = observed - (black + contrast * b.value);
        normal.cost += e * e;
        normal.count += 1;
        match pass {
            Pass::Cost => continue,
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
        jac[BLUR] = contrast * b.d_width_u * blur;
        jac[BLUR_V] = contrast * b.d_width_v * blur_v;
        jac[BLACK] = 1.0;
        jac[CONTRAST] = b.value;
        for (j, w) in jac.iter_mut().skip(OUTSIDE).zip(b.outside.iter()) {
            *j = contrast * w;
        }
        for k in 0..SIDES {
            jac[BAND + k] = if band_free[k] {
                contrast * b.d_band[k]
            } else {
                0.0
            };
        }
        // The geometry, blur and levels in full; a side's row and column only where the
        // pixel sees that side (most pixels see none or one, and this loop is the fit's
        // cost).
        for r in 0..OUTSIDE {
            normal.jte[r] += jac[r] * e;
            for c in r..OUTSIDE {
                normal.jtj[r][c] += jac[r] * jac[c];
            }
        }
        for side in OUTSIDE..N {
            let w = jac[side];
            if w == 0.0 {
                continue;
            }
            normal.jte[side] += w * e;
            for r in 0..OUTSIDE {
                normal.jtj[r][side] += jac[r] * w;
            }
            for c in side..N {
                normal.jtj[side][c] += w * jac[c];
            }
        }
    }
    // The pull of each side towards the sides' mean: a residual of `OUTSIDE_PULL` pixels
    // wholly beyond each side, reading that mean. The mean itself stays free (the outside
    // is as unknown as before), so the pull never holds the levels to a stale value.
    let mean = outside.iter().sum::<f32>() / SIDES as f32;
    let weight = OUTSIDE_PULL * contrast * contrast;
    for (k, level) in outside.iter().enumerate() {
        let gap = mean - level;
        normal.cost += weight * gap * gap;
        if pass == Pass::Full {
            // The residuals' Jacobian is contrast * (I - 1/SIDES): its square is the
            // same projection, and it maps the residuals to their own gaps.
            normal.jte[OUTSIDE + k] += weight * gap;
            for c in k..SIDES {
                let delta = if c == k { 1.0 } else { 0.0 };
                normal.jtj[OUTSIDE + k][OUTSIDE + c] += weight * (delta - 1.0 / SIDES as f32);
            }
        }
    }
    // The pull of each band's width towards none: a residual of `BAND_PULL` pixels.
    let band_weight = BAND_PULL * contrast * contrast;
    for k in BAND..BAND + SIDES {
        let width = params[k];
        normal.cost += band_weight * width * width;
        if pass == Pass::Full {
            normal.jte[k] -= band_weight * width;
            normal.jtj[k][k] += band_weight;
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
pub(super) fn square_from_image(c: &[Point; 4]) -> Option<[[f32; 2]; 2]> {
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

/// The least-squares system of the levels alone, which enter the model linearly: with one
/// outside level for all sides, the pixel is `black + contrast * cells + (contrast *
/// outside) * beyond`, so the system is in (black, contrast, contrast * outside).
#[derive(Clone, Copy, Default)]
pub(super) struct LevelSystem {
    ata: [[f32; 3]; 3],
    aty: [f32; 3],
    /// The pixels' sum of squares: with the solution's products, the least-squares cost
    /// without another pass.
    yy: f32,
}

/// The levels' systems (into `systems`, one per width) for the geometry and blur of
/// `params` with bands of each width in `widths` on every side, from one pass over the
/// window: the known cells' part of each pixel is the same for all of them, and only the
/// bands' ends are computed again.
pub(super) fn level_systems(
    pattern: &Pattern,
    win: &Window,
    params: &[f32; N],
    widths: &[f32],
    systems: &mut [LevelSystem],
) -> Option<()> {
    let corners = fitted_corners(params);
    let map = Homography::from_4_points(&corners, &pattern.corner_points())?;
    let (blur, blur_v) = (libm::expf(params[BLUR]), libm::expf(params[BLUR_V]));
    let (mut au, mut av) = (Axis::EMPTY, Axis::EMPTY);
    let mut yy = 0.0f32;
    for sample in &win.samples {
        let observed = f32::from(sample.value);
        yy += observed * observed;
        let g = map.map(f32::from(sample.x), f32::from(sample.y))?;
        au.set_known(g.x, blur, pattern.side)?;
        av.set_known(g.y, blur_v, pattern.side)?;
        let known = known_cells(pattern, &au, &av);
        for (system, &width) in systems.iter_mut().zip(widths.iter()) {
            au.set_bands(g.x, blur, pattern.side, [width; 2]);
            av.set_bands(g.y, blur_v, pattern.side, [width; 2]);
            // At outside levels of 0 the model is its cells and bands alone; the outside
            // weights are each level's coefficient.
            let b = with_outside(&known, &au, &av, &[0.0; SIDES]);
            let regressors = [1.0, b.value, b.outside.iter().sum()];
            for (r, &x) in regressors.iter().enumerate() {
                system.aty[r] += x * observed;
                for (c, &y) in regressors.iter().enumerate() {
                    system.ata[r][c] += x * y;
                }
            }
        }
    }
    for system in systems.iter_mut() {
        system.yy = yy;
    }
    Some(())
}

/// Sets the levels of `params` to the least-squares solution of `system` (see
/// [`level_systems`]): the levels enter the model linearly, so the nonlinear steps start with
/// only the geometry, the blur and the bands to move. The decoder's contrast is a mean over
/// blurred cells, often half the real one on a small marker. One outside level for all
/// sides here (every side is set to it): the steps then tell the sides apart. Returns the
/// pixels' sum of squared residuals at the solved levels.
pub(super) fn solve_levels(system: &LevelSystem, params: &mut [f32; N]) -> Result<f32, Refusal> {
    let (a, b) = (&system.ata, &system.aty);
    let m = Matrix3::from_fn(|r, c| a[r][c]);
    let rhs = Vector3::new(b[0], b[1], b[2]);
    // A marker in a wide printed margin has almost no pixel beyond the known area: keep the
    // outside level then (its column is nearly zero) and solve the other two.
    let scale = m[(0, 0)] * m[(1, 1)] * m[(2, 2)];
    let x = if m.determinant().abs() > 1e-6 * scale.abs() {
        m.try_inverse().map(|inv| inv * rhs)
    } else {
        let o = params[OUTSIDE];
        Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)])
            .try_inverse()
            .map(|inv| inv * Vector2::new(b[0], b[1]))
            .map(|x| Vector3::new(x[0], x[1], o * x[1]))
    };
    let x = x.ok_or(Refusal::Singular)?;
    if !(x[1] > 0.0) || !x.iter().all(|v| v.is_finite()) {
        return Err(Refusal::Levels);
    }
    // |y - A x|^2 = y.y - 2 x.(A^T y) + x.(A^T A x), with A^T y and A^T A at hand.
    let residual = system.yy - 2.0 * x.dot(&rhs) + x.dot(&(m * x));
    params[BLACK] = x[0];
    params[CONTRAST] = x[1];
    let outside = x[2] / x[1];
    for level in params.iter_mut().skip(OUTSIDE).take(SIDES) {
        *level = outside;
    }
    Ok(residual)
}

/// Solves `(A + lambda diag A) x = b` by Cholesky; `None` when not positive definite.
pub(super) fn solve_damped(a: &[[f32; N]; N], b: &[f32; N], lambda: f32) -> Option<[f32; N]> {
    let mut l = [[0.0f32; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = a[i][j];
            if i == j {
                sum += lambda * a[i][i];
            }
            for (lik, ljk) in l[i].iter().zip(l[j].iter()).take(j) {
                sum -= lik * ljk;
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
