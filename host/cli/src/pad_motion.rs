//! The moving-pad flags `touchdown simulate`, `touchdown replay --scenario` and `touchdown sitl`
//! share: one definition, so that the three take the same flags with the same ranges and
//! messages ([`touchdown_sim::pad_motion`] says what they mean).

use clap::Args;
use touchdown_sim::pad_motion::PadMotion;

use crate::CliError;

/// `--pad-velocity`, `--pad-turn-rate`, `--deck-heave`, `--deck-roll`.
#[derive(Debug, Clone, Default, Args)]
pub struct PadMotionArgs {
    /// The pad drives at N,E m/s over the ground (north, east), from the start of the flight
    /// (of the LAND against a running SITL) [default: at rest]
    #[arg(
        long,
        value_name = "N,E",
        allow_hyphen_values = true,
        value_parser = pair,
        help_heading = "Moving pad"
    )]
    pub pad_velocity: Option<[f64; 2]>,

    /// The pad's heading, and its velocity with it, turns at DEG_S degrees per second
    /// (clockwise seen from above) [default: 0]
    #[arg(
        long,
        value_name = "DEG_S",
        allow_negative_numbers = true,
        value_parser = finite,
        help_heading = "Moving pad"
    )]
    pub pad_turn_rate: Option<f64>,

    /// A boat's deck heaves up and down by M metres (amplitude) with a period of S seconds
    #[arg(long, value_name = "M@S", value_parser = wave, help_heading = "Moving pad")]
    pub deck_heave: Option<(f64, f64)>,

    /// A boat's deck rolls by DEG degrees (amplitude) about its keel (the way it drives) with
    /// a period of S seconds
    #[arg(long, value_name = "DEG@S", value_parser = wave, help_heading = "Moving pad")]
    pub deck_roll: Option<(f64, f64)>,
}

impl PadMotionArgs {
    /// The motion asked for (at rest with no flag), starting at `start_s`.
    pub fn motion(&self, start_s: f64) -> Result<PadMotion, CliError> {
        let (heave_m, heave_period_s) = self.deck_heave.unwrap_or((0.0, 0.0));
        let (roll_deg, roll_period_s) = self.deck_roll.unwrap_or((0.0, 0.0));
        let motion = PadMotion {
            velocity_ne_mps: self.pad_velocity.unwrap_or([0.0, 0.0]),
            turn_rate_deg_s: self.pad_turn_rate.unwrap_or(0.0),
            heave_m,
            heave_period_s,
            roll_deg,
            roll_period_s,
            start_s,
            stop_s: f64::INFINITY,
        };
        motion.validate().map_err(CliError)?;
        if self.pad_turn_rate.is_some_and(|r| r != 0.0) && self.pad_velocity.is_none() {
            return Err(CliError(
                "--pad-turn-rate turns the pad's velocity: give --pad-velocity too".into(),
            ));
        }
        Ok(motion)
    }

    /// Whether any of the flags was given.
    pub fn any_given(&self) -> bool {
        self.pad_velocity.is_some()
            || self.pad_turn_rate.is_some()
            || self.deck_heave.is_some()
            || self.deck_roll.is_some()
    }
}

/// `N,E`: two finite numbers.
fn pair(text: &str) -> Result<[f64; 2], String> {
    let parts: Vec<_> = text.split(',').map(str::trim).collect();
    match parts.as_slice() {
        [n, e] => match (n.parse::<f64>(), e.parse::<f64>()) {
            (Ok(n), Ok(e)) if n.is_finite() && e.is_finite() => Ok([n, e]),
            _ => Err(format!("`{text}` is not two numbers N,E (m/s)")),
        },
        _ => Err(format!("`{text}` is not two numbers N,E (m/s)")),
    }
}

/// A finite number.
fn finite(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{text}` is not a number")),
    }
}

/// `A@P`: an amplitude >= 0 and a period > 0.
fn wave(text: &str) -> Result<(f64, f64), String> {
    let bad = || format!("`{text}` is not AMPLITUDE@PERIOD (a number >= 0, @, seconds > 0)");
    let (a, p) = text.split_once('@').ok_or_else(bad)?;
    match (a.trim().parse::<f64>(), p.trim().parse::<f64>()) {
        (Ok(a), Ok(p)) if a.is_finite() && a >= 0.0 && p.is_finite() && p > 0.0 => Ok((a, p)),
        _ => Err(bad()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flags_parse_and_refuse_what_they_cannot_mean() {
        assert_eq!(pair("1,-0.5"), Ok([1.0, -0.5]));
        assert_eq!(pair(" 2 , 0 "), Ok([2.0, 0.0]));
        assert!(pair("1").is_err() && pair("1,2,3").is_err() && pair("a,1").is_err());
        assert!(pair("inf,0").is_err());
        assert_eq!(wave("0.5@8"), Ok((0.5, 8.0)));
        assert!(wave("0.5").is_err() && wave("0.5@0").is_err() && wave("-1@3").is_err());
        let turn_alone = PadMotionArgs {
            pad_turn_rate: Some(3.0),
            ..Default::default()
        };
        assert!(turn_alone.motion(0.0).is_err());
        let capsize = PadMotionArgs {
            deck_roll: Some((50.0, 4.0)),
            ..Default::default()
        };
        assert!(capsize.motion(0.0).is_err());
        let none = PadMotionArgs::default();
        assert!(none.motion(0.0).unwrap().is_at_rest() && !none.any_given());
    }
}
