//! A simulated precision-landing descent for the filters: the truth, the noisy pose
//! measurements a real detector would give, and the figures it is judged by (RMS per axis,
//! lag). `tests/filter_descent.rs` holds the filters to it (and prints the comparison);
//! `tests/filter_covariance.rs` draws its Gaussian noise from it ([`gauss`]).
//!
//! Geometry. The pad is at the origin of the local NED frame. The vehicle flies a straight
//! approach: 1 m/s down from 30 m to 1 m above the pad while drifting 0.5 m/s horizontally
//! toward it, so the horizontal offset is `0.5 * (altitude - 1)` m (14.5 m at 30 m: 26° off
//! the optical axis, inside a 60° field of view all the way down). Relative to the vehicle the
//! pad therefore moves at a constant velocity. The camera looks straight down, image top toward
//! the nose ([`CameraMount::downward`]); the vehicle holds a constant heading and may wobble in
//! roll and pitch (`wobble_deg`), as a hovering multicopter does.
//!
//! Pose error. A square marker of edge `s` seen at range `d` by a camera of focal length `f`
//! (pixels) spans `f s / d` pixels. Its range comes from that apparent size, so an error of `k`
//! pixels on the size gives a range error `sigma_r = k d² / (f s)` along the line of sight; its
//! direction comes from its centre, so `k_c` pixels on the centre give `sigma_l = k_c d / f`
//! across it. Defaults: `f = 554.3` px (640x480, 60° horizontal field of view), `s = 1.0` m,
//! `k = 0.5` px (edge-length noise of a sub-pixel corner refinement on a blurred, noisy frame),
//! `k_c = 0.3` px: at 30 m, `sigma_r` ≈ 1 m and `sigma_l` ≈ 2 cm; at 2 m, 4 mm and 1 mm. The
//! measurement reports the covariance a pose module would: the same formula evaluated at the
//! *measured* range, oriented along the measured line of sight.
//!
//! Frames are dropped at random (`drop_probability`) and in one burst (`burst`), and a few
//! measurements are gross outliers (`outlier_probability`, 3-8 m off, a wrong pose that still
//! reports its normal covariance).
// Each test binary that declares this module uses part of it.
#![allow(dead_code)]

use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::filter::{
    camera_to_ned_matrix, level_measurement, ned_to_camera, Attitude, CameraMount, Measurement,
    PaperKalman, Tracker, TrackerConfig, UpdateOutcome,
};

/// The scenario.
#[derive(Debug, Clone)]
pub struct SimConfig {
    pub rate_hz: f64,
    pub start_altitude: f64,
    pub end_altitude: f64,
    pub descent_speed: f64,
    pub drift_speed: f64,
    /// Direction the pad lies in, from north toward east, radians (the vehicle drifts toward it).
    pub drift_direction: f64,
    /// Vehicle heading, radians.
    pub yaw: f64,
    /// Roll/pitch wobble amplitude, degrees, and frequency, Hz.
    pub wobble_deg: f64,
    pub wobble_hz: f64,
    pub focal_px: f64,
    pub marker_size_m: f64,
    /// Edge-length noise, pixels (range error).
    pub k_range_px: f64,
    /// Centre noise, pixels (cross-range error).
    pub k_centre_px: f64,
    pub drop_probability: f64,
    /// A burst of dropped frames: (first frame, count).
    pub burst: (usize, usize),
    pub outlier_probability: f64,
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            rate_hz: 30.0,
            start_altitude: 30.0,
            end_altitude: 1.0,
            descent_speed: 1.0,
            drift_speed: 0.5,
            drift_direction: 0.6,
            yaw: 0.4,
            wobble_deg: 0.0,
            wobble_hz: 0.5,
            focal_px: 554.3,
            marker_size_m: 1.0,
            k_range_px: 0.5,
            k_centre_px: 0.3,
            drop_probability: 0.1,
            burst: (400, 8),
            outlier_probability: 0.01,
            seed: 3,
        }
    }
}

/// One camera frame of the simulation.
#[derive(Debug, Clone)]
pub struct Frame {
    pub t_us: u64,
    /// Pad relative to the vehicle, NED axes (truth).
    pub truth_ned: Vector3<f64>,
    /// Pad in the camera frame (truth).
    pub truth_cam: Vector3<f64>,
    pub attitude: Attitude,
    /// The pose measurement in the camera frame, if the frame was not dropped.
    pub measurement: Option<Measurement>,
    pub outlier: bool,
}

impl SimConfig {
    pub fn duration_s(&self) -> f64 {
        (self.start_altitude - self.end_altitude) / self.descent_speed
    }

    /// Pad relative to the vehicle in NED axes at time `t` seconds (analytic: used for lag).
    pub fn truth_ned(&self, t: f64) -> Vector3<f64> {
        let altitude = self.start_altitude - self.descent_speed * t;
        let offset = self.drift_speed * (altitude - self.end_altitude) / self.descent_speed;
        Vector3::new(
            offset * self.drift_direction.cos(),
            offset * self.drift_direction.sin(),
            altitude,
        )
    }

    pub fn attitude(&self, t: f64) -> Attitude {
        let a = self.wobble_deg.to_radians();
        let w = 2.0 * std::f64::consts::PI * self.wobble_hz * t;
        Attitude::from_euler(
            (a * w.sin()) as f32,
            (a * (0.7 * w).cos()) as f32,
            self.yaw as f32,
        )
        .unwrap_or_default()
    }

    pub fn frames(&self) -> Vec<Frame> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mount = CameraMount::downward();
        let n = (self.duration_s() * self.rate_hz).round() as usize + 1;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 / self.rate_hz;
            let attitude = self.attitude(t);
            let truth_ned = self.truth_ned(t);
            let r_nc = camera_to_ned_matrix(&attitude, &mount).cast::<f64>();
            let truth_cam = r_nc.transpose() * truth_ned;
            let dropped = rng.random_bool(self.drop_probability)
                || (i >= self.burst.0 && i < self.burst.0 + self.burst.1);
            let mut outlier = false;
            let measurement = if dropped {
                None
            } else {
                let (sr, sl) = self.sigmas(truth_cam.norm());
                let u = truth_cam.normalize();
                let (e1, e2) = perpendiculars(&u);
                let mut p = truth_cam
                    + u * (sr * gauss(&mut rng))
                    + e1 * (sl * gauss(&mut rng))
                    + e2 * (sl * gauss(&mut rng));
                if rng.random_bool(self.outlier_probability) {
                    outlier = true;
                    let dir =
                        Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)).normalize();
                    p += dir * rng.random_range(3.0..8.0);
                }
                Some(Measurement {
                    t_us: (t * 1e6).round() as u64,
                    position: p.cast::<f32>(),
                    covariance: self.covariance(&p).cast::<f32>(),
                })
            };
            out.push(Frame {
                t_us: (t * 1e6).round() as u64,
                truth_ned,
                truth_cam,
                attitude,
                measurement,
                outlier,
            });
        }
        out
    }

    /// (range sigma, cross-range sigma) at range `d`.
    pub fn sigmas(&self, d: f64) -> (f64, f64) {
        (
            self.k_range_px * d * d / (self.focal_px * self.marker_size_m),
            self.k_centre_px * d / self.focal_px,
        )
    }

    /// The covariance a pose would report for measured position `p` (camera frame).
    pub fn covariance(&self, p: &Vector3<f64>) -> Matrix3<f64> {
        let d = p.norm().max(1e-3);
        let (sr, sl) = self.sigmas(d);
        let u = p / d;
        let uu = u * u.transpose();
        uu * (sr * sr) + (Matrix3::identity() - uu) * (sl * sl)
    }
}

fn perpendiculars(u: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let a = if u.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = u.cross(&a).normalize();
    let e2 = u.cross(&e1);
    (e1, e2)
}

pub fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = 1.0 - rng.random::<f64>();
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A time series of positions to score against the truth (camera frame, metres).
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// (time s, position, truth at that time)
    pub points: Vec<(f64, Vector3<f64>, Vector3<f64>)>,
}

/// The figures of one series.
#[derive(Debug, Clone, Copy)]
pub struct Score {
    pub rms: [f64; 3],
    pub rms_total: f64,
    /// Time shift, frames, that best aligns the series with the truth (positive: behind).
    pub lag_frames: f64,
    pub count: usize,
}

impl Series {
    /// RMS error per axis and overall (the norm), and the lag: the shift `tau` (searched from
    /// -10 to +30 frames in steps of 0.01 frame) minimising the weighted sum over the series of
    /// `w(t) |position(t) - truth(t - tau)|²`, where `truth(t - tau)` is the analytic truth in
    /// the frame the series is scored in (`truth_at`) and `w(t)` the inverse of the pose's
    /// range variance at that time (`weight_at`): the maximum-likelihood shift. Unweighted, the
    /// metre-level noise at 30 m would swamp a lag of a few centimetres.
    pub fn score(
        &self,
        rate_hz: f64,
        truth_at: &dyn Fn(f64) -> Vector3<f64>,
        weight_at: &dyn Fn(f64) -> f64,
    ) -> Score {
        let n = self.points.len().max(1) as f64;
        let mut sq = [0.0f64; 3];
        for (_, p, truth) in &self.points {
            let e = p - truth;
            for (s, v) in sq.iter_mut().zip(e.iter()) {
                *s += v * v;
            }
        }
        let rms = sq.map(|s| (s / n).sqrt());
        let rms_total = (sq.iter().sum::<f64>() / n).sqrt();
        let weights: Vec<f64> = self.points.iter().map(|(t, _, _)| weight_at(*t)).collect();
        let mut best = (f64::INFINITY, 0.0);
        for step in -1000..=3000 {
            let tau = step as f64 * 0.01;
            let shift = tau / rate_hz;
            let cost: f64 = self
                .points
                .iter()
                .zip(&weights)
                .map(|((t, p, _), w)| w * (p - truth_at(t - shift)).norm_squared())
                .sum();
            if cost < best.0 {
                best = (cost, tau);
            }
        }
        Score {
            rms,
            rms_total,
            lag_frames: best.1,
            count: self.points.len(),
        }
    }
}

/// Everything the comparison needs.
pub struct Comparison {
    pub raw: Score,
    pub raw_inliers: Score,
    pub paper: Score,
    pub ours: Score,
    pub ours_camera_frame: Score,
    pub gated: usize,
    /// Injected outliers that ours fused (accepted) anyway.
    pub outliers_fused: usize,
    /// Good measurements that ours gated.
    pub inliers_gated: usize,
    pub outliers: usize,
    pub frames: usize,
    pub measured: usize,
    pub repairs: u32,
}

/// Runs raw, the paper's filter and ours (level frame with attitude, and camera frame without)
/// over the scenario. All are scored in the camera frame at the frame times where they give an
/// output; ours in the level frame is rotated back with the frame's attitude.
pub fn compare(cfg: &SimConfig) -> Comparison {
    let frames = cfg.frames();
    let mount = CameraMount::downward();
    let mut raw = Series::default();
    let mut raw_inliers = Series::default();
    let mut paper_series = Series::default();
    let mut ours = Series::default();
    let mut ours_cam = Series::default();
    let mut paper = PaperKalman::default();
    let mut level = Tracker::new(TrackerConfig::level()).expect("config");
    let mut camera = Tracker::new(TrackerConfig::camera_frame()).expect("config");
    let mut last_paper_t: Option<u64> = None;
    let mut gated = 0;
    let mut outliers_fused = 0;
    let mut inliers_gated = 0;
    let mut outliers = 0;
    let mut measured = 0;
    for f in &frames {
        let t = f.t_us as f64 * 1e-6;
        if let Some(m) = &f.measurement {
            measured += 1;
            let p = m.position.cast::<f64>();
            raw.points.push((t, p, f.truth_cam));
            if f.outlier {
                outliers += 1;
            } else {
                raw_inliers.points.push((t, p, f.truth_cam));
            }
            let dt = last_paper_t.map_or(0.0, |t0| (f.t_us - t0) as f32 * 1e-6);
            last_paper_t = Some(f.t_us);
            let e = paper.update([m.position.x, m.position.y, m.position.z], dt);
            paper_series.points.push((
                t,
                Vector3::new(e[0] as f64, e[1] as f64, e[2] as f64),
                f.truth_cam,
            ));
            let lm = level_measurement(m, &f.attitude, &mount);
            match level.update(&lm) {
                UpdateOutcome::Gated(_) => {
                    gated += 1;
                    if !f.outlier {
                        inliers_gated += 1;
                    }
                }
                UpdateOutcome::Accepted if f.outlier => outliers_fused += 1,
                _ => {}
            }
            camera.update(m);
        } else {
            level.predict_to(f.t_us);
            camera.predict_to(f.t_us);
        }
        if let Some(e) = level.estimate(f.t_us) {
            let p = ned_to_camera(&e.position, &f.attitude, &mount).cast::<f64>();
            ours.points.push((t, p, f.truth_cam));
        }
        if let Some(e) = camera.estimate(f.t_us) {
            ours_cam
                .points
                .push((t, e.position.cast::<f64>(), f.truth_cam));
        }
    }
    // The truth in the camera frame at an arbitrary time, for the lag search.
    let truth_cam = |t: f64| {
        let r = camera_to_ned_matrix(&cfg.attitude(t), &mount).cast::<f64>();
        r.transpose() * cfg.truth_ned(t)
    };
    let weight = |t: f64| {
        let (sr, _) = cfg.sigmas(cfg.truth_ned(t).norm());
        1.0 / (sr * sr)
    };
    let rate = cfg.rate_hz;
    Comparison {
        raw: raw.score(rate, &truth_cam, &weight),
        raw_inliers: raw_inliers.score(rate, &truth_cam, &weight),
        paper: paper_series.score(rate, &truth_cam, &weight),
        ours: ours.score(rate, &truth_cam, &weight),
        ours_camera_frame: ours_cam.score(rate, &truth_cam, &weight),
        gated,
        outliers_fused,
        inliers_gated,
        outliers,
        frames: frames.len(),
        measured,
        repairs: level.repairs(),
    }
}

impl Comparison {
    /// The comparison table (camera frame axes: x right, y down, z along the optical axis).
    pub fn table(&self) -> String {
        let mut s = String::new();
        s.push_str(
            "| series | n | RMS x (m) | RMS y (m) | RMS z (m) | RMS |e| (m) | lag (frames) |\n",
        );
        s.push_str("|---|---|---|---|---|---|---|\n");
        for (name, sc) in [
            ("raw pose (all)", &self.raw),
            ("raw pose (inliers)", &self.raw_inliers),
            ("paper (eq. 8-14, Table 1)", &self.paper),
            ("ours, level frame (attitude)", &self.ours),
            ("ours, camera frame (no attitude)", &self.ours_camera_frame),
        ] {
            s.push_str(&format!(
                "| {name} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:+.2} |\n",
                sc.count, sc.rms[0], sc.rms[1], sc.rms[2], sc.rms_total, sc.lag_frames
            ));
        }
        s.push_str(&format!(
            "frames {}, measured {}, outliers injected {} (fused by ours {}), gated by ours {} \
             (good ones {}), covariance repairs {}\n",
            self.frames,
            self.measured,
            self.outliers,
            self.outliers_fused,
            self.gated,
            self.inliers_gated,
            self.repairs
        ));
        s
    }
}
