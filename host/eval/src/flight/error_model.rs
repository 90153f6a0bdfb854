//! The error sources between the truth and what the autopilot knows and does, each a number
//! with 0 = off: [`ErrorModel`], and one seeded realisation of it, [`Realisation`].
//!
//! Where each default of [`ErrorModel::typical`] comes from (a small multicopter: an
//! STM32F7/H7 flight controller running ArduPilot's EKF3 or PX4's EKF2, the camera board on a
//! UART):
//!
//! - **attitude white noise, 0.02 deg per sample**: the EKF's attitude output is the gyro
//!   integral corrected slowly by the accelerometers and the compass, so two samples 20 ms
//!   apart differ by the gyro noise integrated over 20 ms (MEMS gyros: ~0.005 deg/s/sqrt(Hz)
//!   noise density; 0.01-0.02 deg with the vibration), not by the filter's absolute error.
//! - **roll/pitch bias, 0.3 deg RMS**: the absolute tilt error of an EKF in hover comes from
//!   accelerometer bias and misalignment of the IMU on the frame (0.1-0.5 deg is what
//!   ArduPilot's and PX4's logs show against a reference); it wanders as the EKF re-estimates
//!   the biases, over tens of seconds: a constant part plus two slow sines (periods 20-40 s
//!   and 40-80 s), each seeded.
//! - **heading bias, 0.5 deg**: compass heading after calibration is good to a degree or
//!   two; 0.5 deg is an EKF with GPS yaw aiding or a well calibrated compass. Constant, sign
//!   seeded.
//! - **sample latency, 5 ms, jitter 2 ms**: from the time stamp of an ATTITUDE_QUATERNION
//!   (the EKF output's time) to its transmission: the MAVLink stream scheduler runs at the
//!   main loop's rate and sends in its own slot (ArduPilot's 400 Hz loop: a few ms).
//! - **link delay, 1 ms + the bytes at 921600 baud**: the UART's DMA and the receiving task's
//!   polling add about a millisecond; 921600 is TD_BAUD's default (10 bits per byte).
//! - **autopilot clock**: booted 12.3 s before the board (it powers the board) and 30 ppm fast
//!   (two crystals differ by tens of ppm).
//! - **processing, 20 ms, jitter 5 ms**: the board's exposure-to-send time (readout, detection,
//!   pose, filter; the board reports its own in the companion's STATUSTEXT, and
//!   `docs/performance.md` has the per-frame path's cost on the Cortex-M7), uniform in
//!   15-25 ms.
//! - **PLND_LAG, 0.02 s**: ArduPilot's default; the autopilot assigns a LANDING_TARGET to its
//!   receipt time minus this.
//! - **local position drift, 0.3 m RMS** (PX4's LOCAL_POSITION_NED): GPS and baro wander over
//!   tens of seconds; sines with periods of 30-120 s per axis.
//!
//! Jitters are uniform in `[-jitter, +jitter]` around their mean (never negative): a
//! scheduler's slot, not a heavy tail. [`ErrorModel::none`] is an autopilot that knows the
//! truth exactly and instantly (the replay before this model) over a link without delay; the
//! board still takes 20 ms to process a frame. With it (and no flight effects,
//! `touchdown replay --scenario paper --ideal`) the in-flight replay differs from the truth
//! itself only by the interpolation of the 50 Hz attitude stream and the board's processing
//! time.
//!
//! A [`Realisation`] turns the model into functions of time, deterministic in its seed: the
//! same seed gives the same errors for every method of a replay, so their columns differ only
//! in what they send.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// The error sources (see the module docs). Angles in degrees, times in milliseconds unless
/// the name says otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    /// White noise on each attitude sample, per axis, degrees (1 sigma).
    pub attitude_noise_deg: f64,
    /// Slowly varying roll/pitch bias, RMS per axis, degrees.
    pub tilt_bias_deg: f64,
    /// Heading bias, degrees.
    pub heading_bias_deg: f64,
    /// From an autopilot sample's time stamp to its transmission, ms.
    pub sample_latency_ms: f64,
    /// Jitter of that latency (uniform, +-), ms.
    pub sample_jitter_ms: f64,
    /// Fixed part of the link delay per message, each direction, ms.
    pub link_delay_ms: f64,
    /// The link's speed, bits per second (10 bits per byte); 0 = bytes take no time.
    pub baud: f64,
    /// The autopilot's clock at our boot, seconds (it booted this long before us).
    pub clock_offset_s: f64,
    /// The autopilot's clock rate error, ppm (positive: it runs fast).
    pub clock_drift_ppm: f64,
    /// The board's exposure-to-send time, ms.
    pub processing_ms: f64,
    /// Its jitter (uniform, +-), ms.
    pub processing_jitter_ms: f64,
    /// ArduPilot's PLND_LAG, seconds.
    pub plnd_lag_s: f64,
    /// PX4's local position drift, RMS per axis, metres.
    pub position_drift_m: f64,
}

impl ErrorModel {
    /// A typical small multicopter (see the module docs for each figure).
    pub fn typical() -> Self {
        ErrorModel {
            attitude_noise_deg: 0.02,
            tilt_bias_deg: 0.3,
            heading_bias_deg: 0.5,
            sample_latency_ms: 5.0,
            sample_jitter_ms: 2.0,
            link_delay_ms: 1.0,
            baud: 921_600.0,
            clock_offset_s: 12.3,
            clock_drift_ppm: 30.0,
            processing_ms: 20.0,
            processing_jitter_ms: 5.0,
            plnd_lag_s: 0.02,
            position_drift_m: 0.3,
        }
    }

    /// Nothing: the autopilot knows the truth exactly and at once, the link takes no time,
    /// and the autopilot assigns each target to its exposure (PLND_LAG 0, which ArduPilot
    /// itself does not allow: the ideal autopilot). The board still takes its 20 ms to
    /// process a frame (without jitter): that is not an error, and it is what lets the
    /// attitude samples either side of an exposure arrive before the frame is estimated, as
    /// in flight.
    pub fn none() -> Self {
        ErrorModel {
            attitude_noise_deg: 0.0,
            tilt_bias_deg: 0.0,
            heading_bias_deg: 0.0,
            sample_latency_ms: 0.0,
            sample_jitter_ms: 0.0,
            link_delay_ms: 0.0,
            baud: 0.0,
            clock_offset_s: 0.0,
            clock_drift_ppm: 0.0,
            processing_ms: 20.0,
            processing_jitter_ms: 0.0,
            plnd_lag_s: 0.0,
            position_drift_m: 0.0,
        }
    }

    /// Every term as (name, value, unit), in declaration order: for the JSON and the header.
    pub fn terms(&self) -> [(&'static str, f64, &'static str); 13] {
        [
            ("attitude_noise", self.attitude_noise_deg, "deg"),
            ("tilt_bias", self.tilt_bias_deg, "deg"),
            ("heading_bias", self.heading_bias_deg, "deg"),
            ("sample_latency", self.sample_latency_ms, "ms"),
            ("sample_jitter", self.sample_jitter_ms, "ms"),
            ("link_delay", self.link_delay_ms, "ms"),
            ("baud", self.baud, "bit/s"),
            ("clock_offset", self.clock_offset_s, "s"),
            ("clock_drift", self.clock_drift_ppm, "ppm"),
            ("processing", self.processing_ms, "ms"),
            ("processing_jitter", self.processing_jitter_ms, "ms"),
            ("plnd_lag", self.plnd_lag_s, "s"),
            ("position_drift", self.position_drift_m, "m"),
        ]
    }
}

impl Default for ErrorModel {
    fn default() -> Self {
        ErrorModel::typical()
    }
}

/// The EKF's output rate, Hz: attitude noise is drawn once per output sample, and
/// ArduPilot's inertial history holds one entry per main-loop tick at this rate.
pub const EKF_RATE_HZ: f64 = 400.0;

/// splitmix64 of `(seed, stream, index)`: an independent uniform draw for every sample of
/// every stream, so a draw never depends on how many others were made before it.
fn hash(seed: u64, stream: u64, index: u64) -> u64 {
    let mut z = seed
        ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in [0, 1).
fn uniform(seed: u64, stream: u64, index: u64) -> f64 {
    (hash(seed, stream, index) >> 11) as f64 / (1u64 << 53) as f64
}

/// Standard normal (Box-Muller).
fn gauss(seed: u64, stream: u64, index: u64) -> f64 {
    let u1 = uniform(seed, stream, 2 * index).max(1e-300);
    let u2 = uniform(seed, stream, 2 * index + 1);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A slow wander: `rms * (c0 + s1 sin(2 pi t / T1 + p1) + s2 sin(2 pi t / T2 + p2))` with
/// `c0^2 + s1^2 / 2 + s2^2 / 2 = 1`, so its RMS over a long time is `rms`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Wander {
    constant: f64,
    terms: [(f64, f64, f64); 2],
}

impl Wander {
    /// Periods uniform in `periods[0]` and `periods[1]` (seconds), phases and the constant's
    /// sign seeded; `constant` the share of the mean square in the constant part (0..1).
    fn new(seed: u64, stream: u64, periods: [(f64, f64); 2], constant: f64) -> Self {
        let sign = if uniform(seed, stream, 0) < 0.5 {
            -1.0
        } else {
            1.0
        };
        let amplitude = (1.0 - constant).max(0.0).sqrt(); // s1 = s2: 2 * s^2 / 2 = 1 - c
        let term = |k: u64, (lo, hi): (f64, f64)| {
            let period = lo + (hi - lo) * uniform(seed, stream, 1 + 2 * k);
            let phase = std::f64::consts::TAU * uniform(seed, stream, 2 + 2 * k);
            (amplitude, std::f64::consts::TAU / period, phase)
        };
        Wander {
            constant: sign * constant.sqrt(),
            terms: [term(0, periods[0]), term(1, periods[1])],
        }
    }

    fn at(&self, t_s: f64) -> f64 {
        self.constant
            + self
                .terms
                .iter()
                .map(|(a, w, p)| a * (w * t_s + p).sin())
                .sum::<f64>()
    }
}

/// Streams of the realisation's draws.
mod stream {
    pub const NOISE: u64 = 1;
    pub const TILT_N: u64 = 2;
    pub const TILT_E: u64 = 3;
    pub const HEADING: u64 = 4;
    pub const SAMPLE_LATENCY: u64 = 5;
    pub const PROCESSING: u64 = 6;
    pub const DRIFT: u64 = 7;
}

/// One seeded draw of an [`ErrorModel`]: the autopilot's errors as functions of the true
/// time (seconds, the frames' clock), and the random delays by sample or frame index.
#[derive(Debug, Clone, PartialEq)]
pub struct Realisation {
    /// The model drawn from.
    pub model: ErrorModel,
    seed: u64,
    tilt: [Wander; 2],
    heading_sign: f64,
    drift: [Wander; 3],
}

impl Realisation {
    /// The realisation of `model` for `seed`.
    pub fn new(model: ErrorModel, seed: u64) -> Self {
        let seed = hash(seed, 0x7061_6473, 0);
        let slow = [(20.0, 40.0), (40.0, 80.0)];
        let drift = [(30.0, 60.0), (60.0, 120.0)];
        Realisation {
            model,
            seed,
            // Half the tilt bias's mean square is constant (a mounting offset of the IMU),
            // half wanders.
            tilt: [
                Wander::new(seed, stream::TILT_N, slow, 0.5),
                Wander::new(seed, stream::TILT_E, slow, 0.5),
            ],
            heading_sign: if uniform(seed, stream::HEADING, 0) < 0.5 {
                -1.0
            } else {
                1.0
            },
            drift: [0, 1, 2].map(|k| Wander::new(seed, stream::DRIFT + 16 * k, drift, 0.0)),
        }
    }

    /// The autopilot's attitude error at `t_s`: the rotation `E` with
    /// `estimate = E * truth` (both body FRD to NED), i.e. a small rotation in NED axes: tilt
    /// about north and east (bias plus the noise of the EKF output sample `t_s` falls in),
    /// heading about down.
    pub fn attitude_error(&self, t_s: f64) -> Matrix3<f64> {
        let m = &self.model;
        let tick = (t_s * EKF_RATE_HZ).floor().max(0.0) as u64;
        let noise =
            |axis: u64| m.attitude_noise_deg * gauss(self.seed, stream::NOISE + 32 * axis, tick);
        let angles = Vector3::new(
            m.tilt_bias_deg * self.tilt[0].at(t_s) + noise(0),
            m.tilt_bias_deg * self.tilt[1].at(t_s) + noise(1),
            m.heading_bias_deg * self.heading_sign + noise(2),
        )
        .map(f64::to_radians);
        Rotation3::new(angles).into_inner()
    }

    /// The autopilot's estimate of an attitude `truth` (body FRD to NED) at `t_s`.
    pub fn estimated_attitude(&self, truth: &Matrix3<f64>, t_s: f64) -> Matrix3<f64> {
        self.attitude_error(t_s) * truth
    }

    /// The local position estimate's error at `t_s` (NED, metres).
    pub fn position_error(&self, t_s: f64) -> Vector3<f64> {
        let r = self.model.position_drift_m;
        Vector3::new(
            r * self.drift[0].at(t_s),
            r * self.drift[1].at(t_s),
            r * self.drift[2].at(t_s),
        )
    }

    /// How long sample `index` of stream `kind` waits between its time stamp and its
    /// transmission, µs.
    pub fn sample_latency_us(&self, kind: u64, index: u64) -> u64 {
        let m = &self.model;
        jittered_us(
            m.sample_latency_ms,
            m.sample_jitter_ms,
            uniform(self.seed, stream::SAMPLE_LATENCY + 64 * kind, index),
        )
    }

    /// The board's exposure-to-send time of frame `index`, µs.
    pub fn processing_us(&self, index: u64) -> u64 {
        let m = &self.model;
        jittered_us(
            m.processing_ms,
            m.processing_jitter_ms,
            uniform(self.seed, stream::PROCESSING, index),
        )
    }

    /// The time `bytes` take on the link after the fixed delay, µs.
    pub fn transmission_us(&self, bytes: usize) -> u64 {
        if self.model.baud > 0.0 {
            (bytes as f64 * 10.0 / self.model.baud * 1e6).round() as u64
        } else {
            0
        }
    }

    /// The fixed link delay, µs.
    pub fn link_delay_us(&self) -> u64 {
        (self.model.link_delay_ms.max(0.0) * 1000.0).round() as u64
    }

    /// The autopilot's clock (µs) at our clock's `board_us`.
    pub fn autopilot_clock_us(&self, board_us: u64) -> u64 {
        let m = &self.model;
        let t =
            m.clock_offset_s.max(0.0) * 1e6 + board_us as f64 * (1.0 + m.clock_drift_ppm * 1e-6);
        t.max(0.0) as u64
    }

    /// Our clock (µs) at the autopilot's `autopilot_us` (the inverse of
    /// [`Realisation::autopilot_clock_us`]).
    pub fn board_clock_us(&self, autopilot_us: u64) -> u64 {
        let m = &self.model;
        let t = (autopilot_us as f64 - m.clock_offset_s.max(0.0) * 1e6)
            / (1.0 + m.clock_drift_ppm * 1e-6);
        t.max(0.0) as u64
    }
}

/// `mean +- jitter` ms (uniform, `u` in [0, 1)) in µs, never negative.
fn jittered_us(mean_ms: f64, jitter_ms: f64, u: f64) -> u64 {
    let ms = mean_ms + jitter_ms * (2.0 * u - 1.0);
    (ms.max(0.0) * 1000.0).round() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle_deg(m: &Matrix3<f64>) -> f64 {
        Rotation3::from_matrix_unchecked(*m).angle().to_degrees()
    }

    #[test]
    fn none_is_exact_and_instant() {
        let r = Realisation::new(ErrorModel::none(), 7);
        for t in [0.0, 1.3, 47.9] {
            assert!(angle_deg(&r.attitude_error(t)) < 1e-12);
            assert_eq!(r.position_error(t), Vector3::zeros());
        }
        assert_eq!(r.sample_latency_us(0, 5), 0);
        assert_eq!(r.processing_us(3), 20_000);
        assert_eq!(r.transmission_us(60), 0);
        assert_eq!(r.link_delay_us(), 0);
        assert_eq!(r.autopilot_clock_us(1_234_567), 1_234_567);
        assert_eq!(r.board_clock_us(1_234_567), 1_234_567);
    }

    #[test]
    fn each_term_alone_and_zero_is_off() {
        // Heading bias alone: a rotation about down of exactly that size.
        let model = ErrorModel {
            heading_bias_deg: 0.5,
            ..ErrorModel::none()
        };
        let e = Realisation::new(model, 3).attitude_error(10.0);
        assert!((angle_deg(&e) - 0.5).abs() < 1e-9);
        let axis = Rotation3::from_matrix_unchecked(e).axis().unwrap();
        assert!(axis.z.abs() > 0.999_999, "{axis:?}");
        // Tilt bias alone: RMS over a long time near the asked value, about horizontal axes.
        let model = ErrorModel {
            tilt_bias_deg: 0.3,
            ..ErrorModel::none()
        };
        let r = Realisation::new(model, 11);
        let n = 20_000;
        let ms: f64 = (0..n)
            .map(|k| {
                let e = r.attitude_error(k as f64 * 0.05);
                let v = Rotation3::from_matrix_unchecked(e).scaled_axis();
                assert!(v.z.abs() < 1e-12);
                v.x.to_degrees().powi(2)
            })
            .sum::<f64>()
            / n as f64;
        assert!((ms.sqrt() - 0.3).abs() < 0.08, "RMS {}", ms.sqrt());
        // Processing jitter stays within its bounds.
        let model = ErrorModel {
            processing_ms: 20.0,
            processing_jitter_ms: 5.0,
            ..ErrorModel::none()
        };
        let r = Realisation::new(model, 1);
        let delays: Vec<u64> = (0..1000).map(|k| r.processing_us(k)).collect();
        assert!(delays.iter().all(|d| (15_000..=25_000).contains(d)));
        assert!(delays.iter().any(|&d| d < 16_000) && delays.iter().any(|&d| d > 24_000));
    }

    #[test]
    fn realisations_are_deterministic_and_seeded() {
        let a = Realisation::new(ErrorModel::typical(), 5);
        let b = Realisation::new(ErrorModel::typical(), 5);
        let c = Realisation::new(ErrorModel::typical(), 6);
        assert_eq!(a, b);
        assert_eq!(a.attitude_error(3.21), b.attitude_error(3.21));
        assert_eq!(a.processing_us(9), b.processing_us(9));
        assert_ne!(a.attitude_error(3.21), c.attitude_error(3.21));
        // Noise is per EKF sample: constant within one 2.5 ms tick, another in the next.
        let noise = Realisation::new(
            ErrorModel {
                attitude_noise_deg: 0.02,
                ..ErrorModel::none()
            },
            5,
        );
        assert_eq!(noise.attitude_error(1.0001), noise.attitude_error(1.0019));
        assert_ne!(noise.attitude_error(1.0001), noise.attitude_error(1.0026));
    }

    #[test]
    fn clocks_invert() {
        let r = Realisation::new(ErrorModel::typical(), 1);
        let board = 61_000_000;
        let ap = r.autopilot_clock_us(board);
        assert_eq!(ap, 12_300_000 + 61_000_000 + 1830);
        assert!(r.board_clock_us(ap).abs_diff(board) <= 1);
        assert_eq!(r.transmission_us(72), 781);
    }
}
