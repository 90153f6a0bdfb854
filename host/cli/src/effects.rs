//! The flight-effect flags `touchdown simulate` and `touchdown replay --scenario` share.
//!
//! Both render scenarios with the simulator's [`FlightEffects`]: typical by default, none
//! with their `--ideal`, and each term overridden by its flag. One definition, so that the
//! two commands take the same flags with the same ranges, defaults and messages.

use clap::Args;
use touchdown_sim::effects::FlightEffects;

/// `--readout-ms`, `--vibration-deg`, `--mount-roll-deg`, `--mount-pitch-deg`.
#[derive(Debug, Clone, Default, Args)]
pub struct EffectArgs {
    /// Rolling-shutter readout, first row to last, ms (0 = global shutter) [default: 30.5]
    #[arg(long, value_name = "MS", value_parser = non_negative, help_heading = "Flight effects")]
    pub readout_ms: Option<f64>,

    /// Camera vibration on its mount, degrees RMS per axis, 50-200 Hz [default: 0.03]
    #[arg(long, value_name = "DEG", value_parser = non_negative, help_heading = "Flight effects")]
    pub vibration_deg: Option<f64>,

    /// Mount misalignment about body x, degrees [default: 1.2]
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "DEG",
        value_parser = angle,
        help_heading = "Flight effects"
    )]
    pub mount_roll_deg: Option<f64>,

    /// Mount misalignment about body y, degrees [default: -1.6]
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "DEG",
        value_parser = angle,
        help_heading = "Flight effects"
    )]
    pub mount_pitch_deg: Option<f64>,
}

impl EffectArgs {
    /// The effects asked for: typical (none when `ideal`), each flag overriding its term.
    pub fn effects(&self, ideal: bool) -> FlightEffects {
        let base = if ideal {
            FlightEffects::none()
        } else {
            FlightEffects::typical()
        };
        FlightEffects {
            readout_ms: self.readout_ms.unwrap_or(base.readout_ms),
            vibration_deg: self.vibration_deg.unwrap_or(base.vibration_deg),
            mount_roll_deg: self.mount_roll_deg.unwrap_or(base.mount_roll_deg),
            mount_pitch_deg: self.mount_pitch_deg.unwrap_or(base.mount_pitch_deg),
        }
    }

    /// Whether any of the flags was given.
    pub fn any_given(&self) -> bool {
        self.readout_ms.is_some()
            || self.vibration_deg.is_some()
            || self.mount_roll_deg.is_some()
            || self.mount_pitch_deg.is_some()
    }
}

/// A finite number >= 0 (a readout, an RMS).
fn non_negative(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{text}` is not a number >= 0")),
    }
}

/// A mount angle: finite, within +-45 degrees (beyond that it is not a misalignment).
fn angle(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= 45.0 => Ok(v),
        _ => Err(format!(
            "`{text}` is not an angle in degrees within -45..45"
        )),
    }
}
