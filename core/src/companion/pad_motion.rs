//! Whether the pad moves (TD_PAD_MOTION): set by the user, or decided from the pad's velocity
//! over the ground.
//!
//! # Why the board cares
//! The LANDING_TARGET itself does not change on a moving pad: every autopilot gets the pad
//! against the vehicle at the frame's exposure, and tracking a target that moves is the
//! autopilot's part (ArduPilot's PLND_OPTIONS bit 0 flies the velocity of its target estimator
//! as a feed-forward; docs/setup-ardupilot.md, "A moving pad"). What does change is what the
//! board derives from the pad *as a fixed point of the world*:
//!
//! - the vehicle's velocity over the ground (TD_VPE_EN 2) is the opposite of the pad's
//!   velocity against the vehicle only while the pad stands still: on a pad driving at 1 m/s
//!   it is 1 m/s wrong, and the autopilot fuses it beside GPS;
//! - the vision position (TD_VPE_EN 1) puts the vehicle in a frame fixed to the pad, which
//!   an autopilot that also has GPS sees drift away from its own;
//! - the in-flight mount calibration reads the pad's tilt as the mount's, and a deck rolls.
//!
//! So while the pad moves the board sends neither vision message and adopts no mount
//! correction (it still reports one), and says so once by STATUSTEXT.
//!
//! # Deciding (TD_PAD_MOTION 2, auto)
//! The pad's place on the ground in each frame is the vehicle's position from its
//! LOCAL_POSITION_NED at the exposure (the companion asks for that stream under auto) plus the
//! level estimate of the pad against the vehicle; its velocity is how far that place moved over
//! the last [`PadMotionWatch::SPAN_US`]. Positions, not velocities: the tracker's velocity lags
//! the vehicle's manoeuvres by a fraction of a second, and a vehicle swinging over a pad at rest
//! (PX4 SIH holding its position) made the sum of the two velocities read a moving pad; the
//! positions agree to centimetres at every frame whatever the vehicle does, and over seconds
//! that is centimetres per second. Judged with hysteresis: moving once the velocity stays above
//! [`PadMotionWatch::MOVING_MPS`] for [`PadMotionWatch::MOVING_AFTER_US`], at rest again once
//! it stays below [`PadMotionWatch::AT_REST_MPS`] for [`PadMotionWatch::AT_REST_AFTER_US`].
//! Where the autopilot navigates on the board's own vision position, its position is measured
//! against the pad, and a moving pad cannot be told from one at rest: that is the case
//! TD_PAD_MOTION 1 is for.

use heapless::Deque;
use nalgebra::Vector2;

/// TD_PAD_MOTION.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PadMotionSetting {
    /// 0: the pad stands still.
    AtRest,
    /// 1: the pad moves (a deck, a roof, a dock).
    Moving,
    /// 2: decided from the pad's velocity over the ground.
    Auto,
}

impl PadMotionSetting {
    /// The setting of TD_PAD_MOTION's value (anything unknown is auto).
    pub fn from_param(value: i32) -> Self {
        match value {
            0 => PadMotionSetting::AtRest,
            1 => PadMotionSetting::Moving,
            _ => PadMotionSetting::Auto,
        }
    }
}

/// A change of the auto decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum PadMotionChange {
    /// The pad moves, at this speed over the ground, m/s.
    Moving(f32),
    /// The pad stands still again.
    AtRest,
}

/// The auto decision, from the pad's place on the ground frame by frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub(super) struct PadMotionWatch {
    /// The pad's place (north, east, metres, in the autopilot's local frame), one every
    /// [`Self::ANCHOR_US`] over the last [`Self::SPAN_US`].
    anchors: Deque<(u64, Vector2<f32>), { PadMotionWatch::ANCHORS }>,
    /// The last velocity worked out, north and east, m/s.
    velocity: Option<Vector2<f32>>,
    /// Since when the speed has been on the other side of the decision's threshold.
    crossing_since_us: Option<u64>,
    /// The last sample's time.
    last_us: Option<u64>,
    moving: bool,
}

impl PadMotionWatch {
    /// One anchor kept every this long, µs.
    pub const ANCHOR_US: u64 = 250_000;
    /// The velocity is the move over this span, µs (the oldest anchor within it).
    pub const SPAN_US: u64 = 2_000_000;
    /// No velocity over a shorter span than this, µs.
    pub const MIN_SPAN_US: u64 = 1_500_000;
    /// A pad faster than this over the ground moves, m/s: far above what the positions'
    /// errors move it by over the span, and half the slowest deck worth landing on as a
    /// moving one (a rover's dock creeping at 0.5 m/s is one).
    pub const MOVING_MPS: f32 = 0.5;
    /// Slower than this, it stands still again, m/s.
    pub const AT_REST_MPS: f32 = 0.25;
    /// Above [`Self::MOVING_MPS`] this long: moving, µs.
    pub const MOVING_AFTER_US: u64 = 1_000_000;
    /// Below [`Self::AT_REST_MPS`] this long: at rest, µs.
    pub const AT_REST_AFTER_US: u64 = 3_000_000;
    /// A gap longer than this between samples starts again, µs.
    pub const MAX_GAP_US: u64 = 1_000_000;
    /// A place farther than this from the last anchor starts again, metres: a pad does not
    /// drive 3 m in a quarter of a second (12 m/s), another track or a reset of the
    /// autopilot's position does jump.
    pub const MAX_STEP_M: f32 = 3.0;
    /// Anchors kept: the span's, and one more.
    const ANCHORS: usize = (Self::SPAN_US / Self::ANCHOR_US) as usize + 2;

    /// Whether the pad moves, as decided so far.
    pub(super) fn moving(&self) -> bool {
        self.moving
    }

    /// The pad's velocity over the ground (north, east, m/s), once there is one.
    pub(super) fn velocity_ne(&self) -> Option<Vector2<f32>> {
        self.velocity
    }

    /// One frame's place of the pad on the ground (north, east, metres) at exposure `t_us`;
    /// the decision's change, if it changed.
    pub(super) fn update(&mut self, t_us: u64, place_ne: Vector2<f32>) -> Option<PadMotionChange> {
        if !(place_ne.x.is_finite() && place_ne.y.is_finite()) {
            return None;
        }
        if let Some(&(anchor_us, anchor)) = self.anchors.back() {
            // A time that went backwards (a reboot of either clock), a gap, or a jump (another
            // track, a reset of the autopilot's position): start again, keeping the decision.
            let gap = self
                .last_us
                .is_none_or(|last| t_us < last || t_us - last > Self::MAX_GAP_US);
            if t_us < anchor_us || gap || (place_ne - anchor).norm() > Self::MAX_STEP_M {
                self.anchors.clear();
                self.velocity = None;
                self.crossing_since_us = None;
            }
        }
        self.last_us = Some(t_us);
        if self
            .anchors
            .back()
            .is_none_or(|&(last, _)| t_us.saturating_sub(last) >= Self::ANCHOR_US)
        {
            while self
                .anchors
                .front()
                .is_some_and(|&(t, _)| t_us.saturating_sub(t) > Self::SPAN_US)
                || self.anchors.is_full()
            {
                self.anchors.pop_front();
            }
            // Cannot fail: a slot was freed above.
            let _ = self.anchors.push_back((t_us, place_ne));
        }
        let &(first, origin) = self.anchors.front()?;
        let span_us = t_us.saturating_sub(first);
        if span_us < Self::MIN_SPAN_US {
            return None;
        }
        let v = (place_ne - origin) / (span_us as f32 * 1e-6);
        self.velocity = Some(v);
        let speed = v.norm();
        let (crossing, hold) = if self.moving {
            (speed < Self::AT_REST_MPS, Self::AT_REST_AFTER_US)
        } else {
            (speed > Self::MOVING_MPS, Self::MOVING_AFTER_US)
        };
        if !crossing {
            self.crossing_since_us = None;
            return None;
        }
        let since = *self.crossing_since_us.get_or_insert(t_us);
        if t_us.saturating_sub(since) < hold {
            return None;
        }
        self.crossing_since_us = None;
        self.moving = !self.moving;
        Some(if self.moving {
            PadMotionChange::Moving(speed)
        } else {
            PadMotionChange::AtRest
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds a pad whose place moves at `v` (m/s) from `place` at 15 frames per second from
    /// `t0` for `seconds`, plus `wobble(k)` (metres) at frame `k`; the last time and place and
    /// the changes.
    fn feed(
        w: &mut PadMotionWatch,
        t0: u64,
        place: Vector2<f32>,
        seconds: f32,
        v: Vector2<f32>,
        wobble: &dyn Fn(u64) -> Vector2<f32>,
    ) -> (u64, Vector2<f32>, heapless::Vec<PadMotionChange, 8>) {
        let mut changes = heapless::Vec::new();
        let frames = (seconds * 15.0) as u64;
        let (mut t, mut p) = (t0, place);
        for k in 0..frames {
            t = t0 + k * 66_667;
            p = place + v * (k as f32 * 0.066_667);
            if let Some(c) = w.update(t, p + wobble(k)) {
                let _ = changes.push(c);
            }
        }
        (t, p, changes)
    }

    #[test]
    fn a_pad_driving_one_metre_a_second_is_moving_after_the_hold_and_at_rest_after_it_stops() {
        let mut w = PadMotionWatch::default();
        let still = |_| Vector2::zeros();
        let (t, p, changes) = feed(&mut w, 0, Vector2::zeros(), 10.0, Vector2::zeros(), &still);
        assert!(changes.is_empty() && !w.moving());
        let east = Vector2::new(0.0, 1.0);
        let (t, p, changes) = feed(&mut w, t + 66_667, p, 1.5, east, &still);
        assert!(
            changes.is_empty(),
            "not before the span and the hold: {changes:?}"
        );
        let (t, p, changes) = feed(&mut w, t + 66_667, p, 3.0, east, &still);
        assert!(matches!(changes.as_slice(), [PadMotionChange::Moving(s)] if *s > 0.5));
        assert!(w.moving());
        assert!((w.velocity_ne().unwrap() - east).norm() < 0.05);
        let (t, p, changes) = feed(&mut w, t + 66_667, p, 3.0, Vector2::zeros(), &still);
        assert!(changes.is_empty(), "at rest only after the longer hold");
        let (_, _, changes) = feed(&mut w, t + 66_667, p, 4.0, Vector2::zeros(), &still);
        assert_eq!(changes.as_slice(), [PadMotionChange::AtRest]);
        assert!(!w.moving());
    }

    #[test]
    fn a_pad_at_rest_under_a_swinging_vehicle_and_noise_does_not_move() {
        let mut w = PadMotionWatch::default();
        // The place's errors: 10 cm swings at 0.5 Hz (an attitude error through 10 m of
        // height while the vehicle swings) and 3 cm frame-to-frame noise, for a minute.
        let wobble = |k: u64| {
            let s = (k as f32 * 0.066_667 * core::f32::consts::TAU * 0.5).sin();
            let n = if k.is_multiple_of(2) { 0.03 } else { -0.03 };
            Vector2::new(0.1 * s + n, -0.1 * s)
        };
        let (t, _, changes) = feed(
            &mut w,
            0,
            Vector2::new(3.0, -2.0),
            60.0,
            Vector2::zeros(),
            &wobble,
        );
        assert!(changes.is_empty() && !w.moving(), "{changes:?}");
        // Not a number: ignored.
        assert_eq!(w.update(t + 66_667, Vector2::new(f32::NAN, 0.0)), None);
    }

    #[test]
    fn a_gap_a_jump_or_a_clock_going_back_starts_again() {
        let mut w = PadMotionWatch::default();
        let still = |_| Vector2::zeros();
        let east = Vector2::new(0.0, 1.0);
        let (t, p, _) = feed(&mut w, 0, Vector2::zeros(), 1.8, east, &still);
        assert!(w.velocity_ne().is_some());
        // 1.2 s without a frame: no velocity across it, until a new span.
        let (t, p, changes) = feed(&mut w, t + 1_200_000, p, 1.4, Vector2::zeros(), &still);
        assert!(changes.is_empty() && w.velocity_ne().is_none());
        let (t, p, _) = feed(&mut w, t + 66_667, p, 1.0, Vector2::zeros(), &still);
        assert!(w.velocity_ne().is_some_and(|v| v.norm() < 0.01));
        // A jump of 20 m (another track, a reset of the autopilot's position): the same.
        let jumped = p + Vector2::new(20.0, 0.0);
        let (t, _, changes) = feed(&mut w, t + 66_667, jumped, 1.0, Vector2::zeros(), &still);
        assert!(changes.is_empty() && w.velocity_ne().is_none());
        // The clock going back.
        assert_eq!(w.update(t - 500_000, jumped), None);
        assert_eq!(w.velocity_ne(), None);
    }

    #[test]
    fn settings_read_from_the_parameter() {
        assert_eq!(PadMotionSetting::from_param(0), PadMotionSetting::AtRest);
        assert_eq!(PadMotionSetting::from_param(1), PadMotionSetting::Moving);
        assert_eq!(PadMotionSetting::from_param(2), PadMotionSetting::Auto);
    }
}
