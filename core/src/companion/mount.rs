//! Adopting the estimator's mount calibration: a [`MountCorrection`] arriving with a frame's
//! estimate becomes TD_CAM_ROLL and TD_CAM_PITCH (with TD_CAM_CAL = 2) and a STATUSTEXT.
//!
//! Through the parameters rather than straight into the estimator, because the parameters are
//! the one place the mount lives: set here like a ground station's PARAM_SET would set them,
//! they are announced with PARAM_VALUE (a ground station shows the new values at once), saved
//! to flash by the firmware's usual debounce, and handed to the per-frame path by the usual
//! conversion ([`crate::params::PipelineSettings::from_params`], which the firmware's link task
//! runs after every input and the host glue after every frame). The values set are the
//! calibrator's estimate itself (the mount in force plus the correction), so a correction that
//! reaches the companion after the parameters changed cannot be added twice.
//!
//! The STATUSTEXT fits MAVLink's 50 bytes for every value in range:
//! `touchdown: mount r+1.21 p-1.58 deg +-0.06 applied` (TD_CAM_CAL = 2), `... not set`
//! (TD_CAM_CAL = 1: the user copies the values), `... too big` (an estimate beyond
//! TD_CAM_ROLL/PITCH's range: nothing is set).

use core::fmt::Write;

use super::{Pending, State};
use crate::filter::{MountCalibrationMode, MountCorrection};
use crate::params::ParamId;
use mavlink::dialects::common::MavSeverity;

impl State {
    /// Adopts (or only reports) `c` as TD_CAM_CAL says.
    pub(super) fn on_mount_correction(&mut self, c: &MountCorrection) {
        let mode = match MountCalibrationMode::from_param(self.params.get_int(ParamId::CamCal)) {
            // A moving pad's tilt is a deck's roll, not the mount's: report it, set nothing.
            MountCalibrationMode::Apply if self.pad_moving() => MountCalibrationMode::Report,
            mode => mode,
        };
        let verdict = match mode {
            // The estimator was told to stop after this frame was estimated: nothing to say.
            MountCalibrationMode::Off => return,
            MountCalibrationMode::Report => "not set",
            MountCalibrationMode::Apply => {
                let (roll, pitch) = (ParamId::CamRoll, ParamId::CamPitch);
                let fits = [(roll, c.mount_roll_deg), (pitch, c.mount_pitch_deg)]
                    .iter()
                    .all(|&(id, v)| crate::params::validate(id.def(), v).is_ok());
                if fits {
                    // Both validated: neither set can fail, so the pair changes together.
                    let _ = self.set_param(roll, c.mount_roll_deg);
                    let _ = self.set_param(pitch, c.mount_pitch_deg);
                    self.enqueue(Pending::ParamValue(roll));
                    self.enqueue(Pending::ParamValue(pitch));
                    self.stats.mount_corrections_applied =
                        self.stats.mount_corrections_applied.saturating_add(1);
                    "applied"
                } else {
                    "too big"
                }
            }
        };
        self.stats.mount_corrections = self.stats.mount_corrections.saturating_add(1);
        let mut text = heapless::String::<64>::new();
        // At most 50 bytes (two-digit angles and "too big"); the queue would cut a longer one.
        // Integers only, unpadded (as the lag report): core's float formatting keeps panic
        // paths (see nopanic/).
        let (roll, pitch, sigma) = (
            Hundredths::of(c.mount_roll_deg),
            Hundredths::of(c.mount_pitch_deg),
            Hundredths::of(c.sigma_deg),
        );
        let _ = write!(
            text,
            "touchdown: mount r{}{}.{}{} p{}{}.{}{} deg +-{}.{}{} {}",
            roll.sign,
            roll.units,
            roll.cents / 10,
            roll.cents % 10,
            pitch.sign,
            pitch.units,
            pitch.cents / 10,
            pitch.cents % 10,
            sigma.units,
            sigma.cents / 10,
            sigma.cents % 10,
            verdict
        );
        self.queue_status_text(MavSeverity::MAV_SEVERITY_NOTICE, &text);
    }
}

/// A value rounded to hundredths, as a sign and two integers (`-1.58`: '-', 1, 58).
struct Hundredths {
    sign: char,
    units: u32,
    cents: u32,
}

impl Hundredths {
    /// `v` rounded to hundredths (NaN and values beyond 10^7 saturate: never in a text).
    fn of(v: f32) -> Self {
        let scaled = libm::roundf(v.abs() * 100.0);
        // `as` saturates (NaN gives 0).
        let n = scaled as u32;
        Hundredths {
            sign: if v < 0.0 && n > 0 { '-' } else { '+' },
            units: n / 100,
            cents: n % 100,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Hundredths;

    #[test]
    fn hundredths_round_and_sign() {
        let f = |v: f32| {
            let h = Hundredths::of(v);
            (h.sign, h.units, h.cents)
        };
        assert_eq!(f(1.214), ('+', 1, 21));
        assert_eq!(f(-1.587), ('-', 1, 59));
        assert_eq!(f(-0.004), ('+', 0, 0));
        assert_eq!(f(9.996), ('+', 10, 0));
        assert_eq!(f(-11.5), ('-', 11, 50));
        assert_eq!(f(f32::NAN), ('+', 0, 0));
    }
}
