//! The numerical part of `touchdown calibrate-lens`: a camera's intrinsics and Brown-Conrady
//! distortion from views of a known plane (the printed pad, z = 0).
//!
//! Why this shape: a closed-form start (one homography per view, then Zhang's constraints that
//! the homography's first two columns are orthonormal directions seen through K) lands close
//! enough for a local least-squares fit, and the least-squares fit over everything at once
//! (intrinsics, distortion, every view's pose) is what makes the answer the maximum-likelihood
//! one for pixel noise. The fit is staged (pinhole first, then the radial terms, then the rest)
//! because a strong barrel lens makes the pinhole start a few per cent off, and freeing every
//! distortion term from there lets k1 and k2 wander into each other before the focal length
//! has settled.
//!
//! Host-only, `f64`. The normal equations are dense and solved by Cholesky: with at most a few
//! hundred unknowns (9 for the camera, 6 per view) that is milliseconds, and it keeps the fit
//! free of a sparse solver. Jacobians are central differences: every residual depends on 15
//! numbers at most, so they cost 30 projections a point per iteration, which is nothing next
//! to the detection.

use nalgebra::{Matrix3, Rotation3, SMatrix, SymmetricEigen, Vector3};

/// Levenberg-Marquardt iterations allowed per stage.
pub const MAX_ITERATIONS: usize = 200;
/// A stage has converged when an accepted step lowers the cost by less than this fraction.
pub const CONVERGED_DECREASE: f64 = 1e-10;
/// Largest damping before a stage gives up (no step lowers the cost).
const MAX_DAMPING: f64 = 1e12;

/// Points of one view: pad-plane coordinates (metres, z = 0) and their pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct View {
    /// Pad-frame points (x, y), metres.
    pub object: Vec<[f64; 2]>,
    /// Where the image shows them, pixels ((0, 0) = centre of the top-left pixel).
    pub image: Vec<[f64; 2]>,
}

/// Pinhole intrinsics and OpenCV's five distortion coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// `[k1, k2, p1, p2, k3]`.
    pub k: [f64; 5],
}

impl Intrinsics {
    /// The parameter vector `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`.
    fn to_params(self) -> [f64; 9] {
        let [k1, k2, p1, p2, k3] = self.k;
        [self.fx, self.fy, self.cx, self.cy, k1, k2, p1, p2, k3]
    }

    fn from_params(p: &[f64]) -> Self {
        let g = |i: usize| p.get(i).copied().unwrap_or(0.0);
        Intrinsics {
            fx: g(0),
            fy: g(1),
            cx: g(2),
            cy: g(3),
            k: [g(4), g(5), g(6), g(7), g(8)],
        }
    }

    /// The pixel of a camera-frame point; `None` at or behind the camera plane.
    pub fn project(&self, p: &Vector3<f64>) -> Option<[f64; 2]> {
        if p.z <= 1e-9 {
            return None;
        }
        let (x, y) = (p.x / p.z, p.y / p.z);
        let [k1, k2, p1, p2, k3] = self.k;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        Some([self.fx * xd + self.cx, self.fy * yd + self.cy])
    }

    /// Whether the radial part of the lens is monotonic (no fold-over) from the axis out to the
    /// image corner furthest from the principal point of a `width` x `height` image: every
    /// pixel then has exactly one ray.
    pub fn monotonic_over(&self, width: f64, height: f64) -> bool {
        let [k1, k2, _, _, k3] = self.k;
        let corner = [(-0.5, -0.5), (width - 0.5, -0.5), (-0.5, height - 0.5)]
            .into_iter()
            .chain([(width - 0.5, height - 0.5)])
            .map(|(u, v)| {
                let (x, y) = ((u - self.cx) / self.fx, (v - self.cy) / self.fy);
                (x * x + y * y).sqrt()
            })
            .fold(0.0, f64::max);
        // Walk out along the undistorted radius until the distorted one passes the corner's;
        // a turn before that is a fold inside the image.
        let mut r = 0.0;
        while r < 20.0 {
            let r2 = r * r;
            let slope = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + 7.0 * k3 * r2));
            if slope.is_nan() || slope <= 0.0 {
                return false;
            }
            if r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) > corner {
                return true;
            }
            r += 0.002;
        }
        false
    }
}

/// A view's pose: pad frame to camera frame, `X_cam = R X_pad + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// `R` as an axis-angle vector, radians.
    pub rotation: Vector3<f64>,
    /// `t`, metres.
    pub translation: Vector3<f64>,
}

impl Pose {
    fn to_params(self) -> [f64; 6] {
        let (r, t) = (self.rotation, self.translation);
        [r.x, r.y, r.z, t.x, t.y, t.z]
    }

    fn from_params(p: &[f64]) -> Self {
        let g = |i: usize| p.get(i).copied().unwrap_or(0.0);
        Pose {
            rotation: Vector3::new(g(0), g(1), g(2)),
            translation: Vector3::new(g(3), g(4), g(5)),
        }
    }

    /// The rotation matrix.
    pub fn matrix(&self) -> Matrix3<f64> {
        Rotation3::from_scaled_axis(self.rotation).into_inner()
    }

    /// Angle between the camera's optical axis and the pad's normal, degrees.
    pub fn tilt_deg(&self) -> f64 {
        self.normal().z.abs().min(1.0).acos().to_degrees()
    }

    /// The pad's normal (+z) in the camera frame.
    pub fn normal(&self) -> Vector3<f64> {
        self.matrix().column(2).into_owned()
    }
}

/// Which distortion terms a fit may change (the others stay as they are).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FreeTerms {
    /// k1 and k2.
    pub radial: bool,
    /// p1 and p2.
    pub tangential: bool,
    /// k3.
    pub k3: bool,
}

impl FreeTerms {
    /// Which of the 9 camera parameters move.
    fn mask(self) -> [bool; 9] {
        let (r, t) = (self.radial, self.tangential);
        [true, true, true, true, r, r, t, t, self.k3]
    }
}

/// Why a fit failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitError {
    /// A view's points are degenerate (fewer than four, or all on a line).
    Degenerate {
        /// The view's index.
        view: usize,
    },
    /// Zhang's constraints give no positive focal length (views nearly parallel to each
    /// other: too little tilt).
    NoInitialFocalLength,
    /// A number went non-finite, or the iteration cap was reached.
    NotConverged,
}

/// The result of [`fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    /// The camera.
    pub intrinsics: Intrinsics,
    /// One pose per view.
    pub poses: Vec<Pose>,
    /// Residual (projected minus observed) per view and point, pixels.
    pub residuals: Vec<Vec<[f64; 2]>>,
    /// RMS reprojection error over every point, pixels.
    pub rms_px: f64,
    /// One-sigma uncertainty of `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` from the fit's
    /// covariance (0 for a term held fixed).
    pub sigma: [f64; 9],
    /// Iterations over all stages.
    pub iterations: usize,
}

/// The homography taking pad-plane points to pixels (normalised DLT: both point sets moved
/// to their centroid and scaled to a mean distance of sqrt 2 first, which is what makes the
/// linear solution well conditioned). `None` for fewer than 4 points or a degenerate set.
pub fn homography(object: &[[f64; 2]], image: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    if object.len() < 4 || object.len() != image.len() {
        return None;
    }
    let t_obj = normalising_transform(object)?;
    let t_img = normalising_transform(image)?;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (o, i) in object.iter().zip(image) {
        let p = t_obj * Vector3::new(o[0], o[1], 1.0);
        let q = t_img * Vector3::new(i[0], i[1], 1.0);
        let rows = [
            [-p.x, -p.y, -1.0, 0.0, 0.0, 0.0, q.x * p.x, q.x * p.y, q.x],
            [0.0, 0.0, 0.0, -p.x, -p.y, -1.0, q.y * p.x, q.y * p.y, q.y],
        ];
        for row in rows {
            for a in 0..9 {
                for b in 0..9 {
                    ata[(a, b)] += row[a] * row[b];
                }
            }
        }
    }
    let eigen = SymmetricEigen::new(ata);
    let (smallest, _) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    // A second near-zero eigenvalue: the points do not pin the plane down (collinear).
    let mut sorted: Vec<f64> = eigen.eigenvalues.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    if sorted[1] <= 1e-9 * sorted[8].max(1e-300) {
        return None;
    }
    let h = eigen.eigenvectors.column(smallest);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let h = t_img.try_inverse()? * hn * t_obj;
    let scale = h[(2, 2)];
    let h = if scale.abs() > 1e-12 { h / scale } else { h };
    h.iter().all(|v| v.is_finite()).then_some(h)
}

/// The similarity moving `points` to their centroid with mean distance sqrt 2.
fn normalising_transform(points: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p[0] / n, y + p[1] / n));
    let mean = points
        .iter()
        .map(|p| ((p[0] - mx).powi(2) + (p[1] - my).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    if !(mean.is_finite() && mean > 1e-12) {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean;
    Some(Matrix3::new(
        s,
        0.0,
        -s * mx,
        0.0,
        s,
        -s * my,
        0.0,
        0.0,
        1.0,
    ))
}

/// Zhang's closed-form focal lengths from per-view homographies, with zero skew and the
/// principal point at the image centre (a lens is centred on its sensor to a few per cent, and
/// leaving the principal point to the least-squares fit keeps the start stable with few
/// views). Falls back to square pixels (`fx = fy`) when the two focal lengths are not both
/// determined (views tilted about one axis only). `None` when neither gives a positive focal
/// length.
pub fn initial_intrinsics(
    homographies: &[Matrix3<f64>],
    width: f64,
    height: f64,
) -> Option<Intrinsics> {
    let (cx, cy) = (0.5 * (width - 1.0), 0.5 * (height - 1.0));
    // Pixels moved to the principal point and scaled by the width, so that the unknowns
    // (width / f)^2 are of order one.
    let s = width;
    let t = Matrix3::new(1.0 / s, 0.0, -cx / s, 0.0, 1.0 / s, -cy / s, 0.0, 0.0, 1.0);
    // Rows of [a, b | c] for a (s/fx)^2 + b (s/fy)^2 + c = 0.
    let mut rows: Vec<[f64; 3]> = Vec::new();
    for h in homographies {
        let h = t * h;
        let h = h / h.norm();
        let (h1, h2) = (h.column(0), h.column(1));
        rows.push([h1[0] * h2[0], h1[1] * h2[1], h1[2] * h2[2]]);
        rows.push([
            h1[0] * h1[0] - h2[0] * h2[0],
            h1[1] * h1[1] - h2[1] * h2[1],
            h1[2] * h1[2] - h2[2] * h2[2],
        ]);
    }
    let focal = |a: f64| (a.is_finite() && a > 0.0).then(|| s / a.sqrt());
    // Two unknowns: least squares on the 2x2 normal equations.
    let (mut aa, mut ab, mut bb, mut ac, mut bc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for [a, b, c] in &rows {
        aa += a * a;
        ab += a * b;
        bb += b * b;
        ac += a * c;
        bc += b * c;
    }
    let det = aa * bb - ab * ab;
    if det.abs() > 1e-12 * (aa * bb).max(1e-300) {
        let a = (-ac * bb + bc * ab) / det;
        let b = (-bc * aa + ac * ab) / det;
        if let (Some(fx), Some(fy)) = (focal(a), focal(b)) {
            if (0.5..2.0).contains(&(fx / fy)) {
                return Some(Intrinsics {
                    fx,
                    fy,
                    cx,
                    cy,
                    k: [0.0; 5],
                });
            }
        }
    }
    // Square pixels: one unknown.
    let (mut num, mut den) = (0.0, 0.0);
    for [a, b, c] in &rows {
        num -= (a + b) * c;
        den += (a + b) * (a + b);
    }
    let f = focal(num / den)?;
    Some(Intrinsics {
        fx: f,
        fy: f,
        cx,
        cy,
        k: [0.0; 5],
    })
}

/// A view's pose from its homography and a pinhole camera: the rotation's first two columns
/// and the translation are `K^-1 H`'s columns up to one scale, made a proper rotation by the
/// nearest orthonormal matrix (SVD), with the pad in front of the camera.
pub fn initial_pose(h: &Matrix3<f64>, camera: &Intrinsics) -> Option<Pose> {
    let k_inv = Matrix3::new(
        1.0 / camera.fx,
        0.0,
        -camera.cx / camera.fx,
        0.0,
        1.0 / camera.fy,
        -camera.cy / camera.fy,
        0.0,
        0.0,
        1.0,
    );
    let m = k_inv * h;
    let (m1, m2, m3) = (m.column(0), m.column(1), m.column(2));
    let mut lambda = 2.0 / (m1.norm() + m2.norm());
    if !lambda.is_finite() {
        return None;
    }
    if m3.z * lambda < 0.0 {
        lambda = -lambda;
    }
    let r1 = m1 * lambda;
    let r2 = m2 * lambda;
    let r3 = r1.cross(&r2);
    let approx = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = approx.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        let mut u = u;
        u.column_mut(2).neg_mut();
        r = u * v_t;
    }
    let rotation = Rotation3::from_matrix_unchecked(r).scaled_axis();
    let translation = m3 * lambda;
    (rotation
        .iter()
        .chain(translation.iter())
        .all(|v| v.is_finite()))
    .then_some(Pose {
        rotation,
        translation,
    })
}

/// Residuals (projected minus observed, pixels) of one view; a point behind the camera gets a
/// large residual rather than none, so the cost never jumps by dropping points.
fn view_residuals(camera: &Intrinsics, pose: &Pose, view: &View, out: &mut Vec<f64>) {
    let r = pose.matrix();
    for (o, i) in view.object.iter().zip(&view.image) {
        let p = r * Vector3::new(o[0], o[1], 0.0) + pose.translation;
        match camera.project(&p) {
            Some([u, v]) => {
                out.push(u - i[0]);
                out.push(v - i[1]);
            }
            None => {
                out.push(1e6);
                out.push(1e6);
            }
        }
    }
}

/// Sum of squared residuals over all views.
fn cost(camera: &Intrinsics, poses: &[Pose], views: &[View]) -> f64 {
    let mut buffer = Vec::new();
    let mut total = 0.0;
    for (pose, view) in poses.iter().zip(views) {
        buffer.clear();
        view_residuals(camera, pose, view, &mut buffer);
        total += buffer.iter().map(|r| r * r).sum::<f64>();
    }
    total
}

/// Central-difference steps of the camera parameters and of a pose's.
const CAMERA_STEPS: [f64; 9] = [1e-4, 1e-4, 1e-4, 1e-4, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7];
const POSE_STEPS: [f64; 6] = [1e-7, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7];

/// The normal equations `J^T J` (dense, row-major) and `J^T r` of the free parameters:
/// camera terms first, then 6 per view.
fn normal_equations(
    camera: &Intrinsics,
    poses: &[Pose],
    views: &[View],
    free: &[usize],
) -> (Vec<f64>, Vec<f64>) {
    let nc = free.len();
    let n = nc + 6 * poses.len();
    let mut jtj = vec![0.0; n * n];
    let mut jtr = vec![0.0; n];
    let base = camera.to_params();
    let mut r0 = Vec::new();
    let (mut plus, mut minus) = (Vec::new(), Vec::new());
    for (v, (pose, view)) in poses.iter().zip(views).enumerate() {
        r0.clear();
        view_residuals(camera, pose, view, &mut r0);
        let m = r0.len();
        // Columns: the free camera terms, then this view's six.
        let mut columns: Vec<Vec<f64>> = Vec::with_capacity(nc + 6);
        for &j in free {
            let h = CAMERA_STEPS[j] * base[j].abs().max(1.0);
            let mut p = base;
            p[j] += h;
            plus.clear();
            view_residuals(&Intrinsics::from_params(&p), pose, view, &mut plus);
            p[j] -= 2.0 * h;
            minus.clear();
            view_residuals(&Intrinsics::from_params(&p), pose, view, &mut minus);
            columns.push((0..m).map(|i| (plus[i] - minus[i]) / (2.0 * h)).collect());
        }
        let pose_params = pose.to_params();
        for j in 0..6 {
            let h = POSE_STEPS[j] * pose_params[j].abs().max(1.0);
            let mut p = pose_params;
            p[j] += h;
            plus.clear();
            view_residuals(camera, &Pose::from_params(&p), view, &mut plus);
            p[j] -= 2.0 * h;
            minus.clear();
            view_residuals(camera, &Pose::from_params(&p), view, &mut minus);
            columns.push((0..m).map(|i| (plus[i] - minus[i]) / (2.0 * h)).collect());
        }
        // Global indices of this view's columns.
        let index: Vec<usize> = (0..nc).chain((0..6).map(|j| nc + 6 * v + j)).collect();
        for (a, ca) in columns.iter().enumerate() {
            let ga = index[a];
            jtr[ga] += ca.iter().zip(&r0).map(|(x, y)| x * y).sum::<f64>();
            for (b, cb) in columns.iter().enumerate().skip(a) {
                let gb = index[b];
                let s: f64 = ca.iter().zip(cb).map(|(x, y)| x * y).sum();
                jtj[ga * n + gb] += s;
                if ga != gb {
                    jtj[gb * n + ga] += s;
                }
            }
        }
    }
    (jtj, jtr)
}

/// Solves `A x = b` for a symmetric positive definite `A` (row-major, n x n) by Cholesky;
/// `None` when `A` is not positive definite.
fn cholesky_solve(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let n = b.len();
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let s: f64 = (0..i).map(|k| l[i * n + k] * y[k]).sum();
        y[i] = (b[i] - s) / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| l[k * n + i] * x[k]).sum();
        x[i] = (y[i] - s) / l[i * n + i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// One Levenberg-Marquardt stage over the `free` camera terms and every pose. Returns the
/// iterations used.
fn stage(
    camera: &mut Intrinsics,
    poses: &mut [Pose],
    views: &[View],
    free: &[usize],
) -> Result<usize, FitError> {
    let mut current = cost(camera, poses, views);
    if !current.is_finite() {
        return Err(FitError::NotConverged);
    }
    let mut damping = 1e-3;
    let nc = free.len();
    for iteration in 1..=MAX_ITERATIONS {
        let (jtj, jtr) = normal_equations(camera, poses, views, free);
        let n = jtr.len();
        loop {
            let mut a = jtj.clone();
            for i in 0..n {
                a[i * n + i] += damping * jtj[i * n + i].max(1e-12);
            }
            let neg: Vec<f64> = jtr.iter().map(|g| -g).collect();
            let Some(step) = cholesky_solve(&a, &neg) else {
                damping *= 10.0;
                if damping > MAX_DAMPING {
                    return Err(FitError::NotConverged);
                }
                continue;
            };
            let mut params = camera.to_params();
            for (k, &j) in free.iter().enumerate() {
                params[j] += step[k];
            }
            let trial_camera = Intrinsics::from_params(&params);
            let trial_poses: Vec<Pose> = poses
                .iter()
                .enumerate()
                .map(|(v, pose)| {
                    let mut p = pose.to_params();
                    for (j, value) in p.iter_mut().enumerate() {
                        *value += step[nc + 6 * v + j];
                    }
                    Pose::from_params(&p)
                })
                .collect();
            let trial = cost(&trial_camera, &trial_poses, views);
            if trial.is_finite() && trial < current {
                *camera = trial_camera;
                poses.copy_from_slice(&trial_poses);
                let decrease = (current - trial) / current.max(1e-300);
                current = trial;
                damping = (damping / 3.0).max(1e-12);
                if decrease < CONVERGED_DECREASE || current < 1e-18 {
                    return Ok(iteration);
                }
                break;
            }
            damping *= 4.0;
            if damping > MAX_DAMPING {
                // Not even a tiny step along the gradient lowers the cost: a minimum to the
                // precision of the arithmetic.
                return Ok(iteration);
            }
        }
    }
    Err(FitError::NotConverged)
}

/// Fits the camera and every view's pose to the views, from `camera` and `poses` (one per
/// view), in stages: the pinhole (distortion held), then k1 and k2, then every term
/// `free` allows. k3 stays as given unless `free.k3`.
pub fn fit(
    views: &[View],
    camera: Intrinsics,
    poses: Vec<Pose>,
    free: FreeTerms,
) -> Result<Fit, FitError> {
    if views.len() != poses.len() {
        return Err(FitError::NotConverged);
    }
    let mut camera = camera;
    let mut poses = poses;
    let mut iterations = 0;
    let stages = [
        FreeTerms {
            radial: false,
            tangential: false,
            k3: false,
        },
        FreeTerms {
            radial: free.radial,
            tangential: false,
            k3: false,
        },
        free,
    ];
    let mut last = None;
    for terms in stages {
        if last == Some(terms) {
            continue;
        }
        last = Some(terms);
        let free_idx: Vec<usize> = (0..9).filter(|&j| terms.mask()[j]).collect();
        iterations += stage(&mut camera, &mut poses, views, &free_idx)?;
    }
    let free_idx: Vec<usize> = (0..9).filter(|&j| free.mask()[j]).collect();
    let total = cost(&camera, &poses, views);
    let points: usize = views.iter().map(|v| v.object.len()).sum();
    let unknowns = free_idx.len() + 6 * views.len();
    let dof = (2 * points).saturating_sub(unknowns).max(1);
    let variance = total / dof as f64;
    let (jtj, _) = normal_equations(&camera, &poses, views, &free_idx);
    let mut sigma = [0.0; 9];
    let n = free_idx.len() + 6 * views.len();
    for (k, &j) in free_idx.iter().enumerate() {
        let mut e = vec![0.0; n];
        e[k] = 1.0;
        if let Some(col) = cholesky_solve(&jtj, &e) {
            sigma[j] = (col[k] * variance).max(0.0).sqrt();
        }
    }
    let residuals = poses
        .iter()
        .zip(views)
        .map(|(pose, view)| {
            let mut r = Vec::new();
            view_residuals(&camera, pose, view, &mut r);
            r.chunks_exact(2).map(|c| [c[0], c[1]]).collect()
        })
        .collect();
    let rms_px = (total / points.max(1) as f64).sqrt();
    if !(rms_px.is_finite() && camera.fx > 0.0 && camera.fy > 0.0) {
        return Err(FitError::NotConverged);
    }
    Ok(Fit {
        intrinsics: camera,
        poses,
        residuals,
        rms_px,
        sigma,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth() -> Intrinsics {
        Intrinsics {
            fx: 420.0,
            fy: 418.0,
            cx: 322.0,
            cy: 236.0,
            k: [-0.25, 0.08, 0.001, -0.0005, 0.0],
        }
    }

    /// A 6 x 4 grid of points seen from tilted poses.
    fn synthetic(camera: &Intrinsics) -> (Vec<View>, Vec<Pose>) {
        let grid: Vec<[f64; 2]> = (0..24)
            .map(|i| [(i % 6) as f64 * 0.1 - 0.25, (i / 6) as f64 * 0.1 - 0.15])
            .collect();
        let mut views = Vec::new();
        let mut poses = Vec::new();
        for k in 0..8 {
            let a = k as f64 * 0.8;
            let pose = Pose {
                rotation: Vector3::new(0.5 * a.cos(), 0.5 * a.sin(), 0.3 * a.sin()),
                translation: Vector3::new(0.05 * a.sin(), -0.04 * a.cos(), 0.7),
            };
            let r = pose.matrix();
            let image = grid
                .iter()
                .map(|o| {
                    camera
                        .project(&(r * Vector3::new(o[0], o[1], 0.0) + pose.translation))
                        .unwrap()
                })
                .collect();
            views.push(View {
                object: grid.clone(),
                image,
            });
            poses.push(pose);
        }
        (views, poses)
    }

    #[test]
    fn homography_maps_the_points() {
        let object = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.3]];
        let h = Matrix3::new(300.0, 20.0, 100.0, -10.0, 280.0, 50.0, 0.1, 0.05, 1.0);
        let image: Vec<[f64; 2]> = object
            .iter()
            .map(|o| {
                let p = h * Vector3::new(o[0], o[1], 1.0);
                [p.x / p.z, p.y / p.z]
            })
            .collect();
        let found = homography(&object, &image).unwrap();
        assert!((found - h).norm() < 1e-6 * h.norm(), "{found}");
        assert!(homography(&object[..3], &image[..3]).is_none());
        let line = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]];
        assert!(homography(&line, &line).is_none());
    }

    #[test]
    fn exact_points_give_the_camera_back() {
        let camera = truth();
        let (views, _) = synthetic(&camera);
        let hs: Vec<Matrix3<f64>> = views
            .iter()
            .map(|v| homography(&v.object, &v.image).unwrap())
            .collect();
        let start = initial_intrinsics(&hs, 640.0, 480.0).unwrap();
        // Barrel distortion biases the start; the fit has to do the rest.
        assert!((start.fx / camera.fx - 1.0).abs() < 0.2, "{start:?}");
        let poses = hs
            .iter()
            .map(|h| initial_pose(h, &start).unwrap())
            .collect();
        let free = FreeTerms {
            radial: true,
            tangential: true,
            k3: false,
        };
        let fit = fit(&views, start, poses, free).unwrap();
        let c = fit.intrinsics;
        assert!(fit.rms_px < 1e-6, "rms {}", fit.rms_px);
        assert!(
            (c.fx - camera.fx).abs() < 1e-4 && (c.fy - camera.fy).abs() < 1e-4,
            "{c:?}"
        );
        assert!(
            (c.cx - camera.cx).abs() < 1e-4 && (c.cy - camera.cy).abs() < 1e-4,
            "{c:?}"
        );
        for (a, b) in c.k.iter().zip(camera.k) {
            assert!((a - b).abs() < 1e-6, "{c:?}");
        }
    }

    #[test]
    fn a_folding_lens_is_noticed() {
        let mut camera = truth();
        assert!(camera.monotonic_over(640.0, 480.0));
        camera.k = [-0.5, 0.0, 0.0, 0.0, 0.0];
        camera.fx = 200.0;
        camera.fy = 200.0;
        assert!(!camera.monotonic_over(640.0, 480.0));
    }
}
