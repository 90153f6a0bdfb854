//! The pad's bearing (TD_PAD_YAW): the vision estimate's frame held to the pad rather than to
//! the autopilot's heading.
//!
//! The board levels the pad with the autopilot's attitude, so the position it sends turns about
//! the pad with the autopilot's heading error (a compass's: degrees, and more after GPS is
//! lost, when nothing else holds the heading) and with the camera's yaw on its mount. The
//! markers show the pad's bearing in that turned frame on every frame; against the bearing the
//! user configured, the difference is the frame's turn, which the position, the velocity and
//! the yaw sent then leave out. An autopilot that takes its heading from the vision estimate
//! (ArduPilot's EK3_SRCn_YAW 6) then holds the pad's frame with no compass at all.
//!
//! - **Smoothed** over [`TURN_SMOOTHING_US`]: one frame's rotation of a small, far pad is
//!   noisy, while the heading error it measures changes slowly. The mean is of unit vectors,
//!   so a turn near ±180 degrees does not average to zero.
//! - **Restarted** when the stream resumes after a gap ([`super::vision::RESUME_GAP_US`]),
//!   with the vision estimate's reset counter: the new track takes its first frame's turn.
//! - **Checked**: a turn over [`TURN_WARN_DEG`] means the configured bearing or the
//!   autopilot's heading is wrong, and an autopilot still steering on its compass would fly a
//!   frame turned from the one it is told its position in; the board says so once per track
//!   (`touchdown: pad 23 deg off heading: TD_PAD_YAW?`).

use core::fmt::Write;

use super::vision::{report_due, resumes_after_gap};
use super::State;
use crate::filter::FrameEstimate;
use crate::params::ParamId;
use mavlink::dialects::common::MavSeverity;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// The smoothing's time constant, µs: many frames at any frame rate the board runs, short
/// beside the time a heading error takes to grow.
pub const TURN_SMOOTHING_US: u64 = 2_000_000;

/// A turn larger than this, degrees, is reported: beyond a compass's error on any vehicle that
/// flies on it.
pub const TURN_WARN_DEG: f32 = 10.0;

/// NAMED_VALUE_FLOAT's name for the pad's bearing as the board sees it.
pub const PAD_BEARING_NAME: &str = "TD_PAD_BRG";

/// The pad's top edge (its +y axis) as seen in NED through the rotation `q_ned` (pad frame to
/// NED, `[w, x, y, z]`): its bearing, radians clockwise from north; `None` for an unusable
/// rotation or a pad seen edge-on (its top edge nearly vertical).
pub fn pad_bearing_in_ned(q_ned: [f32; 4]) -> Option<f32> {
    let [w, x, y, z] = q_ned;
    let q = Quaternion::new(w, x, y, z);
    let n = q.norm();
    if !(n > 0.0) || !n.is_finite() {
        return None;
    }
    let top = UnitQuaternion::from_quaternion(q) * Vector3::y();
    // Under half its length in the horizontal plane: tilted over 60 degrees, no pad the
    // camera can read.
    if libm::hypotf(top.x, top.y) < 0.5 {
        return None;
    }
    Some(libm::atan2f(top.y, top.x))
}

/// The pad's bearing as the markers show it in the autopilot's frame, smoothed, and the turn
/// to the configured one.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct PadBearing {
    /// The mean bearing's cosine and sine (not normalised: a mean of unit vectors).
    mean: Option<(f32, f32)>,
    /// The exposure of the last frame taken, our clock, µs.
    last_us: Option<u64>,
    /// The turn over [`TURN_WARN_DEG`] has been reported in this track.
    warned: bool,
    /// The exposure after which the next report of the bearing is due, our clock, µs.
    next_report_us: u64,
}

/// The turn a frame's vision estimate takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Turn {
    /// The turn, radians about the down axis (positive clockwise seen from above): added to a
    /// bearing in the autopilot's frame it gives the pad-held one.
    pub radians: f32,
    /// The turn has just passed [`TURN_WARN_DEG`] for the first time in this track.
    pub newly_large: bool,
}

impl PadBearing {
    /// Takes the frame exposed at `exposure_us`, which shows the pad's top edge at `measured`
    /// (radians, [`pad_bearing_in_ned`]; `None`: not usable). A gap over
    /// [`super::vision::RESUME_GAP_US`] since the last frame starts a new track.
    pub fn observe(&mut self, exposure_us: u64, measured: Option<f32>) {
        if resumes_after_gap(self.last_us, exposure_us) {
            *self = PadBearing {
                next_report_us: self.next_report_us,
                ..PadBearing::default()
            };
        }
        let Some(m) = measured.filter(|m| m.is_finite()) else {
            return;
        };
        let sample = (libm::cosf(m), libm::sinf(m));
        let dt = self
            .last_us
            .map_or(0, |last| exposure_us.saturating_sub(last));
        self.mean = Some(match self.mean {
            None => sample,
            Some((c, s)) => {
                // An exponential mean's weight for `dt`, to first order (capped: a gap longer
                // than the time constant takes the sample alone).
                let k = (dt as f32 / TURN_SMOOTHING_US as f32).min(1.0);
                (c + k * (sample.0 - c), s + k * (sample.1 - s))
            }
        });
        self.last_us = Some(exposure_us);
    }

    /// The smoothed bearing, radians; `None` before a frame has shown one in this track.
    pub fn bearing(&self) -> Option<f32> {
        let (c, s) = self.mean?;
        (libm::hypotf(c, s) > 0.0).then(|| libm::atan2f(s, c))
    }

    /// The turn from the autopilot's frame to the pad `configured` (radians) bearing; `None`
    /// before a frame has shown the bearing in this track.
    pub fn turn(&mut self, configured: f32) -> Option<Turn> {
        let d = configured - self.bearing()?;
        let radians = libm::atan2f(libm::sinf(d), libm::cosf(d));
        let large = libm::fabsf(radians) > TURN_WARN_DEG.to_radians();
        let newly_large = large && !self.warned;
        self.warned |= large;
        Some(Turn {
            radians,
            newly_large,
        })
    }

    /// The bearing in degrees, 0-360, if known and a report is due at `exposure_us`
    /// ([`report_due`]).
    fn due_report_deg(&mut self, exposure_us: u64) -> Option<f32> {
        let bearing = self.bearing()?;
        if !report_due(&mut self.next_report_us, exposure_us) {
            return None;
        }
        let degrees = libm::fmodf(bearing.to_degrees(), 360.0);
        Some(if degrees < 0.0 {
            degrees + 360.0
        } else {
            degrees
        })
    }
}

impl State {
    /// Takes `frame`'s pad bearing (a frame with a fix), and queues its report when due.
    pub(super) fn observe_pad_bearing(&mut self, frame: &FrameEstimate, now_us: u64) {
        let measured = frame
            .estimate
            .as_ref()
            .and_then(|e| e.orientation_ned)
            .and_then(pad_bearing_in_ned);
        self.pad_bearing.observe(frame.exposure_us, measured);
        if let Some(degrees) = self.pad_bearing.due_report_deg(frame.exposure_us) {
            self.queue_named_value(PAD_BEARING_NAME, degrees, now_us);
        }
    }

    /// The turn from the autopilot's frame to the pad-held one, radians: 0 without
    /// TD_PAD_YAW; with it, `None` until a frame has shown the pad's bearing.
    pub(super) fn pad_turn(&mut self) -> Option<f32> {
        let configured = self.params.get(ParamId::PadYaw);
        if !(configured >= 0.0) {
            return Some(0.0);
        }
        let turn = self.pad_bearing.turn(configured.to_radians())?;
        if turn.newly_large {
            let mut text = heapless::String::<64>::new();
            // Integers only (core's float formatting keeps panic paths, see nopanic/).
            let deg = libm::roundf(libm::fabsf(turn.radians.to_degrees())) as u32;
            let _ = write!(text, "touchdown: pad {deg} deg off heading: TD_PAD_YAW?");
            self.queue_status_text(MavSeverity::MAV_SEVERITY_WARNING, &text);
        }
        Some(turn.radians)
    }
}

/// The rotation by `radians` about NED's down axis (clockwise seen from above).
pub(super) fn turn_matrix(radians: f32) -> Matrix3<f32> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), radians).into_inner()
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::vision::RESUME_GAP_US;
    use super::*;

    /// `v` (NED) turned by `radians` about the down axis.
    pub(crate) fn turn_ned(v: &Vector3<f32>, radians: f32) -> Vector3<f32> {
        turn_matrix(radians) * v
    }

    /// Pad frame to NED for a flat pad whose top edge points `bearing` radians east of north
    /// (pad x right, y top, z up; NED z down).
    pub(crate) fn flat_pad(bearing: f32) -> [f32; 4] {
        // Pad to NED for bearing 0: x -> east, y -> north, z -> up (-down).
        let base = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 1.0, 0.0, //
            1.0, 0.0, 0.0, //
            0.0, 0.0, -1.0,
        ));
        let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), bearing);
        let q = UnitQuaternion::from_rotation_matrix(&(turn * base));
        [q.w, q.i, q.j, q.k]
    }

    #[test]
    fn the_bearing_of_a_flat_pad_is_its_top_edges() {
        for deg in [0.0f32, 30.0, 90.0, -120.0, 179.0] {
            let got = pad_bearing_in_ned(flat_pad(deg.to_radians())).unwrap();
            let diff = (got - deg.to_radians() + core::f32::consts::PI)
                .rem_euclid(core::f32::consts::TAU)
                - core::f32::consts::PI;
            assert!(diff.abs() < 1e-5, "{deg}: {}", got.to_degrees());
        }
        assert_eq!(pad_bearing_in_ned([0.0; 4]), None);
        assert_eq!(pad_bearing_in_ned([f32::NAN, 0.0, 0.0, 0.0]), None);
        // Stood on its bottom edge, the top edge straight down in NED: no bearing.
        let q = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::FRAC_PI_2);
        assert_eq!(pad_bearing_in_ned([q.w, q.i, q.j, q.k]), None);
    }

    #[test]
    fn the_turn_takes_a_heading_error_out_of_a_position() {
        // The autopilot's heading is 3 degrees clockwise of the truth: levelled with it, the
        // pad's top edge (truly at 40 degrees) and a vehicle truly 2 m north of the pad are
        // both seen turned 3 degrees clockwise.
        let err = 3f32.to_radians();
        let truth = Vector3::new(2.0f32, 0.0, -10.0);
        let seen = turn_ned(&truth, err);
        let mut b = PadBearing::default();
        b.observe(0, Some(40f32.to_radians() + err));
        let turn = b.turn(40f32.to_radians()).unwrap();
        assert!(!turn.newly_large);
        let held = turn_ned(&seen, turn.radians);
        assert!((held - truth).amax() < 1e-5, "{held}");
    }

    #[test]
    fn the_bearing_is_smoothed_restarted_and_a_large_turn_reported_once() {
        let mut b = PadBearing::default();
        b.observe(0, None);
        assert_eq!(b.turn(0.0), None);
        // Frames at 15 Hz alternating 1 degree either side of 2 degrees average to it.
        for k in 0..150u64 {
            let noise = if k % 2 == 0 { 1.0f32 } else { -1.0 };
            b.observe(k * 66_667, Some((2.0 + noise).to_radians()));
        }
        let mean = b.bearing().unwrap();
        assert!(
            (mean.to_degrees() - 2.0).abs() < 0.1,
            "{}",
            mean.to_degrees()
        );
        assert!((b.turn(0.0).unwrap().radians - -mean).abs() < 1e-6);
        // A frame without a bearing holds it.
        b.observe(150 * 66_667, None);
        assert_eq!(b.bearing(), Some(mean));
        // Around +-180 degrees the mean stays there, not at zero; the turn from 0 is large,
        // reported once.
        let mut b = PadBearing::default();
        for k in 0..30u64 {
            let m = if k % 2 == 0 { 179f32 } else { -179.0 };
            b.observe(k * 66_667, Some(m.to_radians()));
            let t = b.turn(0.0).unwrap();
            assert!(
                t.radians.abs().to_degrees() > 170.0,
                "{}",
                t.radians.to_degrees()
            );
            assert_eq!(t.newly_large, k == 0);
        }
        // A gap starts a new track: the first frame's bearing, and a large turn reported
        // again.
        b.observe(30 * 66_667 + RESUME_GAP_US + 1, Some(20f32.to_radians()));
        let t = b.turn(0.0).unwrap();
        assert!(t.newly_large && (t.radians.to_degrees() + 20.0).abs() < 1e-4);
    }

    #[test]
    fn the_bearing_is_reported_in_degrees_twice_a_second() {
        let mut b = PadBearing::default();
        assert_eq!(b.due_report_deg(0), None);
        b.observe(0, Some(-90f32.to_radians()));
        let first = b.due_report_deg(0).unwrap();
        assert!((first - 270.0).abs() < 1e-3, "{first}");
        assert_eq!(b.due_report_deg(400_000), None);
        assert!(b.due_report_deg(500_000).is_some());
    }
}
