//! Software auto-exposure with hard limits.
//!
//! A sensor's own AEC (the OV7725's included) lets the exposure grow to the whole frame
//! period. Under a moving drone that means motion blur: at 30 deg/s of body rotation a
//! 30 ms exposure smears a QVGA image (focal length ~230 px) by ~3.6 px, enough to lose a
//! small marker, while 4 ms keeps it under half a pixel. In bright sun the AEC picks short
//! exposures anyway; in shade or dusk it does not. [`AutoExposure`] is a small closed loop the
//! firmware runs instead: it measures the frame's mean brightness ([`mean_brightness`]) and
//! sets exposure and gain manually, exposure first up to `max_exposure_us`, then gain up to
//! `max_gain` (noise), and nothing beyond either limit: a frame that is too dark at both
//! limits stays dark rather than blurred.
//!
//! The loop multiplies exposure x gain by `target / mean`, limited to a factor of 2 per step
//! (the sensor applies new values one or two frames late; bigger steps would oscillate), and
//! does nothing while the mean is within [`AutoExposureLimits::deadband`] of the target.

use super::GainX16;
use crate::image::GrayImage;

/// Limits and target of [`AutoExposure`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AutoExposureLimits {
    /// Mean grey level the loop aims for.
    pub target: u8,
    /// No adjustment while `|mean - target| <= deadband`.
    pub deadband: u8,
    /// Longest exposure, µs (motion blur).
    pub max_exposure_us: u32,
    /// Highest analog gain (noise).
    pub max_gain: GainX16,
}

impl Default for AutoExposureLimits {
    /// Mid-grey target, 4 ms and 8x at most.
    fn default() -> Self {
        AutoExposureLimits {
            target: 110,
            deadband: 12,
            max_exposure_us: 4_000,
            max_gain: GainX16(16 * 8),
        }
    }
}

/// Exposure (line periods) and gain to apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ExposureSetting {
    /// Exposure in line periods (at least 1).
    pub lines: u16,
    /// Analog gain.
    pub gain: GainX16,
}

/// The loop's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AutoExposure {
    limits: AutoExposureLimits,
    max_lines: u16,
    setting: ExposureSetting,
}

impl AutoExposure {
    /// A loop for a sensor whose line period is `line_ns` and whose frame has `frame_lines`
    /// lines (the exposure can never exceed the frame). Starts at half the longest exposure
    /// and unity gain.
    pub fn new(limits: AutoExposureLimits, line_ns: u32, frame_lines: u32) -> Self {
        let by_time = u64::from(limits.max_exposure_us) * 1000 / u64::from(line_ns.max(1));
        let max_lines = by_time
            .min(u64::from(frame_lines))
            .clamp(1, u64::from(u16::MAX)) as u16;
        AutoExposure {
            limits,
            max_lines,
            setting: ExposureSetting {
                lines: (max_lines / 2).max(1),
                gain: GainX16::ONE,
            },
        }
    }

    /// Replaces the limits while running (a user changed them): the current setting is pulled
    /// inside the new limits at once and the loop continues from there, so a lowered ceiling
    /// takes effect on the next frame rather than after the loop has walked down to it.
    /// `line_ns` and `frame_lines` are the sensor timing, as for [`AutoExposure::new`].
    /// Returns the new setting when it changed (to be written to the sensor).
    pub fn set_limits(
        &mut self,
        limits: AutoExposureLimits,
        line_ns: u32,
        frame_lines: u32,
    ) -> Option<ExposureSetting> {
        let fresh = AutoExposure::new(limits, line_ns, frame_lines);
        self.limits = limits;
        self.max_lines = fresh.max_lines;
        // min/max rather than `clamp`, which has a panic path for crossed bounds.
        let next = ExposureSetting {
            lines: self.setting.lines.min(self.max_lines).max(1),
            gain: GainX16(
                self.setting
                    .gain
                    .0
                    .min(limits.max_gain.0)
                    .max(GainX16::ONE.0),
            ),
        };
        if next == self.setting {
            return None;
        }
        self.setting = next;
        Some(next)
    }

    /// The longest exposure the limits allow, line periods.
    pub fn max_lines(&self) -> u16 {
        self.max_lines
    }

    /// The setting currently asked of the sensor.
    pub fn setting(&self) -> ExposureSetting {
        self.setting
    }

    /// Feeds the mean grey level of the latest frame; returns the new setting when it changed.
    pub fn update(&mut self, mean: u8) -> Option<ExposureSetting> {
        let target = u64::from(self.limits.target.max(1));
        let mean = u64::from(mean);
        if mean.abs_diff(target) <= u64::from(self.limits.deadband) {
            return None;
        }
        // Brightness is proportional to exposure x gain; work in (lines x gain/16), in u64
        // (65,535 lines at 4,096x gain times a target of 255 would overflow u32).
        let current = u64::from(self.setting.lines) * u64::from(self.setting.gain.0);
        let wanted = current * target / mean.max(1);
        // min/max rather than `clamp`, whose panic on crossed bounds the optimiser cannot rule
        // out (the no-panic check, nopanic/, covers this loop).
        let wanted = wanted
            .min(current.saturating_mul(2))
            .max(current / 2)
            .max(16);
        let max_gain = u64::from(self.limits.max_gain.0.max(16));
        let lines = (wanted / 16).min(u64::from(self.max_lines)).max(1);
        let gain = (wanted / lines).min(max_gain).max(16);
        let next = ExposureSetting {
            lines: lines as u16,
            gain: GainX16(gain as u16),
        };
        if next == self.setting {
            return None;
        }
        self.setting = next;
        Some(next)
    }
}

/// Mean grey level over every `step`-th pixel of every `step`-th row (0 for an empty image).
/// A step of 8 reads 1/64 of a frame: 1,200 pixels at QVGA, a few microseconds.
pub fn mean_brightness(image: &GrayImage<'_>, step: usize) -> u8 {
    let step = step.max(1);
    let mut sum = 0u64;
    let mut count = 0u64;
    for y in (0..image.height()).step_by(step) {
        for &p in image.row(y).iter().step_by(step) {
            sum += u64::from(p);
            count += 1;
        }
    }
    sum.checked_div(count).unwrap_or(0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// QVGA at 30 fps on the OV7725: 120 µs lines, 278 lines.
    fn qvga() -> AutoExposure {
        AutoExposure::new(AutoExposureLimits::default(), 120_000, 278)
    }

    /// A scene whose mean is proportional to exposure x gain, saturating at 255.
    fn scene(s: ExposureSetting, radiance: u32) -> u8 {
        (u32::from(s.lines) * u32::from(s.gain.0) * radiance / 1000).min(255) as u8
    }

    #[test]
    fn exposure_is_capped_then_gain_rises_to_its_limit() {
        let mut ae = qvga();
        // 4 ms / 120 µs = 33 lines.
        assert_eq!(ae.max_lines(), 33);
        // A dark scene: the loop runs into both limits and stays there.
        for _ in 0..20 {
            let mean = scene(ae.setting(), 10);
            ae.update(mean);
        }
        assert_eq!(ae.setting().lines, 33);
        assert_eq!(ae.setting().gain, GainX16(128));
    }

    #[test]
    fn bright_sun_converges_to_a_short_exposure_near_unity_gain() {
        let mut ae = qvga();
        for _ in 0..20 {
            let mean = scene(ae.setting(), 2_000);
            ae.update(mean);
        }
        let s = ae.setting();
        let mean = scene(s, 2_000);
        assert!(mean.abs_diff(110) <= 12, "mean {mean}, {s:?}");
        // A few lines' exposure; the gain only trims the last exposure quantum.
        assert!(s.lines < 8, "{s:?}");
        assert!(s.gain < GainX16(32), "{s:?}");
    }

    #[test]
    fn within_the_deadband_nothing_changes_and_steps_are_bounded() {
        let mut ae = qvga();
        assert_eq!(ae.update(110), None);
        assert_eq!(ae.update(120), None);
        let before = ae.setting();
        let after = ae.update(255).unwrap();
        // At most halved per step.
        let p0 = u32::from(before.lines) * u32::from(before.gain.0);
        let p1 = u32::from(after.lines) * u32::from(after.gain.0);
        assert!(p1 * 2 >= p0 - 16 && p1 < p0, "{before:?} -> {after:?}");
    }

    #[test]
    fn new_limits_apply_at_once_and_the_loop_follows_them() {
        let mut ae = qvga();
        // A dark scene drives exposure and gain to 4 ms (33 lines) and 8x.
        for _ in 0..20 {
            let mean = scene(ae.setting(), 10);
            ae.update(mean);
        }
        assert_eq!(ae.setting().lines, 33);
        assert_eq!(ae.setting().gain, GainX16(128));
        // Bright sun: the user lowers the ceiling to 1 ms and 2x; the setting is clipped now.
        let tight = AutoExposureLimits {
            max_exposure_us: 1_000,
            max_gain: GainX16(32),
            ..AutoExposureLimits::default()
        };
        let clipped = ae.set_limits(tight, 120_000, 278).unwrap();
        assert_eq!(ae.max_lines(), 8);
        assert_eq!(
            clipped,
            ExposureSetting {
                lines: 8,
                gain: GainX16(32)
            }
        );
        assert_eq!(ae.setting(), clipped);
        // Still dark: the loop stays at the new ceiling.
        for _ in 0..20 {
            let mean = scene(ae.setting(), 10);
            ae.update(mean);
        }
        assert_eq!(ae.setting(), clipped);
        // The same limits again change nothing.
        assert_eq!(ae.set_limits(tight, 120_000, 278), None);
        // Raised limits free the loop again without a jump; it then climbs to them.
        assert_eq!(
            ae.set_limits(AutoExposureLimits::default(), 120_000, 278),
            None
        );
        assert_eq!(ae.max_lines(), 33);
        for _ in 0..20 {
            let mean = scene(ae.setting(), 10);
            ae.update(mean);
        }
        assert_eq!(ae.setting().lines, 33);
        assert_eq!(ae.setting().gain, GainX16(128));
        // A new target moves the operating point.
        let mut ae = qvga();
        let darker = AutoExposureLimits {
            target: 60,
            ..AutoExposureLimits::default()
        };
        assert_eq!(ae.set_limits(darker, 120_000, 278), None);
        for _ in 0..20 {
            let mean = scene(ae.setting(), 200);
            ae.update(mean);
        }
        let mean = scene(ae.setting(), 200);
        assert!(mean.abs_diff(60) <= 12, "mean {mean}, {:?}", ae.setting());
    }

    #[test]
    fn mean_brightness_samples_the_frame() {
        let mut data = [0u8; 16 * 8];
        for (i, p) in data.iter_mut().enumerate() {
            *p = if i % 16 < 8 { 200 } else { 100 };
        }
        let image = GrayImage::new(&data, 16, 8).unwrap();
        assert_eq!(mean_brightness(&image, 1), 150);
        assert_eq!(mean_brightness(&image, 4), 150);
        assert_eq!(mean_brightness(&image, 0), 150);
    }
}
