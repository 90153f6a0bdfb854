//! Software auto-exposure with hard limits.
//!
//! A sensor's own AEC (the OV7725's included) lets the exposure grow to the whole frame
//! period. Under a moving drone that means motion blur: at 30 deg/s of body rotation a
//! 30 ms exposure smears a QVGA image (focal length ~230 px) by ~3.6 px, enough to lose a
//! small marker, while 4 ms keeps it under half a pixel. In bright sun the AEC picks short
//! exposures anyway; in shade or dusk it does not. And it meters the frame's mean, so a white
//! pad on dark grass clips. [`AutoExposure`] is a small closed loop the firmware runs instead:
//! it is fed each frame's [`Metering`] (from the per-frame path,
//! [`crate::pipeline::FrameReport::metering`]) and sets exposure and gain manually, exposure
//! first up to `max_exposure_us` (and up to the frame's motion cap), then gain up to
//! `max_gain` (noise), and nothing beyond either limit: a frame that is too dark at both
//! limits stays dark rather than blurred.
//!
//! What it aims for, in order:
//! 1. **Decoded markers** ([`Metering::pad`]): the brightest marker's white cells at
//!    [`PAD_WHITE_TARGET`], below clipping with headroom, whatever the scene's mean; a white
//!    that reads [`PAD_CLIPPED`] or more is clipped (how far is unknown) and the exposure is
//!    halved. For [`PAD_HOLD_FRAMES`] frames after the markers were last seen the setting is
//!    held rather than handed back to the scene's mean, which would clip the pad again and
//!    lose it for longer than the one missed frame.
//! 2. **The scene** otherwise: its mean at `target`, with a highlight guard: the brightest
//!    1/256 of the frame ([`Metering::highlight`]) is kept at or below [`HIGHLIGHT_CEILING`]
//!    (halved while it reads [`HIGHLIGHT_CLIPPED`] or more), so a pad too small to be decoded
//!    yet is not clipped. The guard may lower the mean to a quarter of the target and no
//!    further ([`GUARD_FLOOR_DIVISOR`]): a white roof filling a tenth of the frame must not
//!    black out the ground around it.
//! 3. **Motion** ([`Metering::max_exposure_us`]): the exposure never exceeds what keeps the
//!    image motion of the vehicle's body rate under half a pixel; gain makes up the light.
//!
//! The loop multiplies exposure x gain by `aim / level`, limited to a factor of 2 per step,
//! and does nothing while the level is within the deadband of its aim ([`PAD_DEADBAND`] for
//! the markers' white, [`AutoExposureLimits::deadband`] for the mean) except moving light
//! between exposure and gain when the motion cap changed. [`AutoExposure::update`], the mean
//! alone, is the loop as it was before markers and highlights were metered.
//!
//! # Latency
//!
//! A setting computed from frame `n` is written while frame `n + 1` is being exposed, so `n + 2`
//! is the first frame exposed with it (`n + 3` on a sensor that latches its exposure a frame
//! late). A step is the whole correction, so the frames metered before it reaches the sensor
//! must not be corrected for again: after each change of the brightness the loop lets
//! [`SETTLE_FRAMES`] frames' levels pass (their bookkeeping, the pad's hold, and the motion cap
//! still apply). Without that, a clipped pad is halved on two frames in a row, then found a
//! quarter too dark and doubled twice: a limit cycle of six frames, a third of them clipped,
//! where blooming makes the markers read small (the altitude as much high) and the jumps
//! between those and the good frames become the pad tracker's velocity.
//!
//! # Search
//!
//! The scene's aim is a guess at what the markers need, and in hard light it can be a guess
//! at which they are not found at all: a shadow edge across the pad at 20 m (the `shadow`
//! scenario) decodes only a stop above the scene's aim, where the shadowed half of the sheet
//! is bright enough for the threshold. So while no marker is metered (the metered loop, with
//! the scene's highlight, not the mean alone), after [`SEARCH_PROBE_AFTER_FRAMES`] settled
//! frames the loop takes one step a stop brighter, the next time a stop darker, and so on: a
//! probe costs the frames of one setting (a clipped or dim frame that finds nothing either),
//! and once a marker decodes the markers' metering holds the exposure where they are. The
//! limit cycle above did this by accident.

use super::metering::Metering;
use super::GainX16;
use crate::image::GrayImage;

/// Grey level the loop holds the decoded markers' white at: 55 levels (22 %) of headroom below
/// clipping, for the paper outside the sampled cells (larger white areas read a little brighter
/// through the lens blur) and a brighter marker in the next frame.
pub const PAD_WHITE_TARGET: u8 = 200;
/// No adjustment while the markers' white is within this of [`PAD_WHITE_TARGET`].
pub const PAD_DEADBAND: u8 = 16;
/// A markers' white at or above this is clipped.
pub const PAD_CLIPPED: u8 = 245;
/// Frames the setting is held after the markers were last metered (half a second at 30 fps).
pub const PAD_HOLD_FRAMES: u8 = 15;
/// The scene's highlight is kept at or below this.
pub const HIGHLIGHT_CEILING: u8 = 230;
/// A highlight at or above this is clipped.
pub const HIGHLIGHT_CLIPPED: u8 = 250;
/// The highlight guard lowers the scene's mean to `target / GUARD_FLOOR_DIVISOR` at most.
pub const GUARD_FLOOR_DIVISOR: u64 = 4;
/// Frames whose levels are not acted on after a change of the brightness: they were exposed
/// before the change reached the sensor (see the module docs' latency).
pub const SETTLE_FRAMES: u8 = 2;
/// While no marker is metered, after this many settled frames at the scene's aim the loop
/// probes a stop brighter or darker, alternately (see the module docs' search).
pub const SEARCH_PROBE_AFTER_FRAMES: u8 = 6;

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
    line_ns: u32,
    setting: ExposureSetting,
    /// Frames left during which a lost pad's setting is held.
    pad_hold: u8,
    /// Frames left whose levels predate the last change of the brightness.
    settling: u8,
    /// Settled frames the scene has been metered without markers since the last probe.
    search_frames: u8,
    /// The last probe was the brighter one (they alternate).
    probe_brighter: bool,
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
            line_ns: line_ns.max(1),
            setting: ExposureSetting {
                lines: (max_lines / 2).max(1),
                gain: GainX16::ONE,
            },
            pad_hold: 0,
            settling: 0,
            search_frames: 0,
            probe_brighter: false,
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
        self.line_ns = fresh.line_ns;
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
        // Pulled inside the new limits: a change of the brightness like the loop's own.
        self.settling = SETTLE_FRAMES;
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

    /// Feeds the mean grey level of the latest frame (no markers, no highlight guard, no
    /// motion cap); returns the new setting when it changed.
    pub fn update(&mut self, mean: u8) -> Option<ExposureSetting> {
        self.update_metered(&Metering::mean_only(mean))
    }

    /// Feeds the latest frame's metering (see the module docs); returns the new setting when
    /// it changed.
    pub fn update_metered(&mut self, metering: &Metering) -> Option<ExposureSetting> {
        // Brightness is proportional to exposure x gain; work in (lines x gain/16), in u64
        // (65,535 lines at 4,096x gain times a target of 255 would overflow u32).
        let current = u64::from(self.setting.lines) * u64::from(self.setting.gain.0);
        // The aim is taken on every frame (it keeps the pad's hold), acted on only once the
        // frames exposed before the last change have passed.
        let aim = self.aim(metering);
        let settled = self.settling == 0;
        self.settling = self.settling.saturating_sub(1);
        let wanted = match aim.filter(|_| settled) {
            Some((level, aim)) => {
                let wanted = current * aim / level.max(1);
                // min/max rather than `clamp`, whose panic on crossed bounds the optimiser
                // cannot rule out (the no-panic check, nopanic/, covers this loop).
                wanted
                    .min(current.saturating_mul(2))
                    .max(current / 2)
                    .max(16)
            }
            None => current,
        };
        let max_lines = match metering.max_exposure_us {
            Some(us) => {
                let by_motion = u64::from(us) * 1000 / u64::from(self.line_ns.max(1));
                u64::from(self.max_lines).min(by_motion).max(1)
            }
            None => u64::from(self.max_lines),
        };
        let max_gain = u64::from(self.limits.max_gain.0.max(16));
        let lines = (wanted / 16).min(max_lines).max(1);
        let gain = (wanted / lines).min(max_gain).max(16);
        let next = ExposureSetting {
            lines: lines as u16,
            gain: GainX16(gain as u16),
        };
        if next == self.setting {
            return None;
        }
        // Light moved between exposure and gain alone (the motion cap) changes no level.
        if wanted != current {
            self.settling = SETTLE_FRAMES;
        }
        self.setting = next;
        Some(next)
    }

    /// The level metered and the level wanted, `(level, aim)`, or `None` to hold (within the
    /// deadband, or a lost pad's hold).
    fn aim(&mut self, metering: &Metering) -> Option<(u64, u64)> {
        if let Some(pad) = metering.pad {
            self.pad_hold = PAD_HOLD_FRAMES;
            self.search_frames = 0;
            let white = u64::from(pad.white);
            if pad.white >= PAD_CLIPPED {
                return Some((2, 1));
            }
            let aim = u64::from(PAD_WHITE_TARGET);
            return (white.abs_diff(aim) > u64::from(PAD_DEADBAND)).then_some((white, aim));
        }
        if self.pad_hold > 0 {
            self.pad_hold -= 1;
            return None;
        }
        let target = u64::from(self.limits.target.max(1));
        let mean = u64::from(metering.mean);
        let highlight = u64::from(metering.highlight);
        let mut aim = target;
        if metering.highlight >= HIGHLIGHT_CLIPPED {
            aim = aim.min(mean / 2);
        } else if let Some(limit) = (mean * u64::from(HIGHLIGHT_CEILING)).checked_div(highlight) {
            aim = aim.min(limit);
        }
        let mut aim = aim.max(target / GUARD_FLOOR_DIVISOR);
        // The search's probes (see the module docs), in the metered loop only, once settled.
        if metering.highlight > 0 && self.settling == 0 {
            self.search_frames = self.search_frames.saturating_add(1);
            if self.search_frames > SEARCH_PROBE_AFTER_FRAMES {
                self.search_frames = 0;
                self.probe_brighter = !self.probe_brighter;
                aim = if self.probe_brighter {
                    aim * 2
                } else {
                    aim / 2
                };
                return Some((mean, aim.max(1)));
            }
        }
        (mean.abs_diff(aim) > u64::from(self.limits.deadband)).then_some((mean, aim))
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
    use super::super::metering::PadLevels;
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

    /// A sunny frame: grass of `ground` and a white pad of `paper` (radiance units of
    /// [`scene`]) covering `pad_share` of the frame, both clipping at 255; what the metering
    /// reads with the markers decoded (`decoded`) or not.
    fn sunny(
        s: ExposureSetting,
        ground: u32,
        paper: u32,
        pad_share: f32,
        decoded: bool,
    ) -> Metering {
        let (g, w) = (scene(s, ground), scene(s, paper));
        let mean = (f32::from(g) * (1.0 - pad_share) + f32::from(w) * pad_share) as u8;
        Metering {
            mean,
            highlight: if pad_share >= 1.0 / 256.0 { w } else { g },
            pad: decoded.then_some(PadLevels {
                white: w,
                // Blooming lifts the black of a clipped pad.
                black: if w == 255 { 190 } else { w / 8 },
            }),
            max_exposure_us: None,
        }
    }

    #[test]
    fn a_clipped_pad_brings_the_exposure_down_and_its_white_is_held_below_clipping() {
        let mut ae = qvga();
        // Paper 4x brighter than the grass; the mean alone would put the grass at 110 and the
        // paper far beyond 255.
        for _ in 0..20 {
            let m = sunny(ae.setting(), 500, 2_000, 0.02, false);
            ae.update(m.mean);
        }
        assert_eq!(scene(ae.setting(), 2_000), 255);
        // The markers decode (clipped): the exposure halves, then the white settles at the
        // target with its headroom.
        let before = ae.setting();
        let after = ae
            .update_metered(&sunny(before, 500, 2_000, 0.02, true))
            .unwrap();
        let product = |s: ExposureSetting| u32::from(s.lines) * u32::from(s.gain.0);
        assert!(
            product(after) * 2 <= product(before) + 16,
            "{before:?} -> {after:?}"
        );
        for _ in 0..20 {
            let m = sunny(ae.setting(), 500, 2_000, 0.02, true);
            ae.update_metered(&m);
        }
        let white = scene(ae.setting(), 2_000);
        assert!(
            white.abs_diff(PAD_WHITE_TARGET) <= PAD_DEADBAND && white < PAD_CLIPPED,
            "white {white}, {:?}",
            ae.setting()
        );
        // The pad lost for a frame or two: the setting is held, not handed back to the mean.
        let held = ae.setting();
        for _ in 0..usize::from(PAD_HOLD_FRAMES) {
            assert_eq!(
                ae.update_metered(&sunny(held, 500, 2_000, 0.0, false)),
                None
            );
        }
        // Lost for longer: the scene's mean takes over again.
        assert!(ae
            .update_metered(&sunny(held, 500, 2_000, 0.0, false))
            .is_some());
    }

    #[test]
    fn a_sensor_two_frames_late_does_not_make_the_loop_oscillate() {
        // The board's timing: the setting computed from frame n first exposes frame n + 2. A
        // clipped pad (paper 4x the grass) after the mean alone set the exposure.
        let mut ae = qvga();
        for _ in 0..20 {
            ae.update(scene(ae.setting(), 500));
        }
        let mut exposed = [ae.setting(); 2];
        let mut whites = [0u8; 40];
        for white in whites.iter_mut() {
            let m = sunny(exposed[0], 500, 2_000, 0.02, true);
            *white = m.pad.map_or(0, |p| p.white);
            ae.update_metered(&m);
            exposed = [exposed[1], ae.setting()];
        }
        assert_eq!(whites[0], 255);
        // Settled within the first half and held there: no frame of the second half clipped
        // or off its target by more than the deadband.
        for &white in &whites[20..] {
            assert!(
                white.abs_diff(PAD_WHITE_TARGET) <= PAD_DEADBAND,
                "whites {whites:?}"
            );
        }
        // Without the settling frames the same loop cycles for ever between clipping and
        // a quarter of the light (the failure this guards against).
        let mut ae = qvga();
        for _ in 0..20 {
            ae.update(scene(ae.setting(), 500));
        }
        let mut exposed = [ae.setting(); 2];
        let mut clipped_late = 0;
        for frame in 0..40 {
            let m = sunny(exposed[0], 500, 2_000, 0.02, true);
            if frame >= 20 && m.pad.is_some_and(|p| p.white >= PAD_CLIPPED) {
                clipped_late += 1;
            }
            ae.settling = 0;
            ae.update_metered(&m);
            exposed = [exposed[1], ae.setting()];
        }
        assert!(clipped_late >= 3, "clipped {clipped_late}");
    }

    /// The setting `ae` holds most often over frames 30-60 of a scene metered by `meter`
    /// (the search's probes aside).
    fn resting(
        ae: &mut AutoExposure,
        meter: impl Fn(ExposureSetting) -> Metering,
    ) -> ExposureSetting {
        let mut seen: heapless::Vec<(ExposureSetting, u32), 32> = heapless::Vec::new();
        for frame in 0..60 {
            ae.update_metered(&meter(ae.setting()));
            if frame >= 30 {
                let s = ae.setting();
                match seen.iter_mut().find(|(x, _)| *x == s) {
                    Some((_, n)) => *n += 1,
                    None => {
                        let _ = seen.push((s, 1));
                    }
                }
            }
        }
        seen.iter()
            .max_by_key(|(_, n)| *n)
            .map(|(s, _)| *s)
            .unwrap()
    }

    #[test]
    fn a_pad_the_scene_s_aim_does_not_decode_is_found_by_a_probe_and_held() {
        // Sun and a shadow edge across the pad: it decodes only at 1.3 times the exposure the
        // scene's metering rests at (and its white cells are then at 200 * 1.3 / 1.54).
        let mut ae = qvga();
        let rest = resting(&mut ae, |s| sunny(s, 500, 2_000, 0.02, false));
        let product = |s: ExposureSetting| u32::from(s.lines) * u32::from(s.gain.0);
        let needed = product(rest) * 13 / 10;
        let shadowed = |s: ExposureSetting| {
            let decoded = product(s) >= needed;
            let white = (u32::from(PAD_WHITE_TARGET) * product(s) * 10 / (product(rest) * 154))
                .min(255) as u8;
            Metering {
                pad: decoded.then_some(PadLevels { white, black: 10 }),
                ..sunny(s, 500, 2_000, 0.02, false)
            }
        };
        let mut first = None;
        let mut missed_after = 0;
        for frame in 0..60 {
            let m = shadowed(ae.setting());
            if m.pad.is_some() {
                first.get_or_insert(frame);
            } else if first.is_some() {
                missed_after += 1;
            }
            ae.update_metered(&m);
        }
        // Found within two probes (the first may be the darker one), then held.
        let cycle = usize::from(SEARCH_PROBE_AFTER_FRAMES + 2 * SETTLE_FRAMES + 2);
        assert!(
            first.is_some_and(|f| f <= 2 * cycle),
            "first {first:?} missed {missed_after}"
        );
        assert_eq!(missed_after, 0, "first {first:?}");
        // Without the probes it is never found once the scene's metering has settled.
        let mut ae = qvga();
        for _ in 0..40 {
            ae.search_frames = 0;
            ae.update_metered(&sunny(ae.setting(), 500, 2_000, 0.02, false));
        }
        for _ in 0..60 {
            let m = shadowed(ae.setting());
            assert!(m.pad.is_none(), "{:?}", ae.setting());
            ae.search_frames = 0;
            ae.update_metered(&m);
        }
    }

    #[test]
    fn without_markers_the_highlight_guard_keeps_a_small_pad_out_of_clipping() {
        let mut ae = qvga();
        // The setting it rests at between the search's probes.
        let s = resting(&mut ae, |s| sunny(s, 500, 2_000, 0.02, false));
        let (grass, paper) = (scene(s, 500), scene(s, 2_000));
        assert!(
            paper < HIGHLIGHT_CLIPPED,
            "paper {paper}, grass {grass}, {s:?}"
        );
        assert!(
            u16::from(paper) + 40 >= u16::from(HIGHLIGHT_CEILING),
            "paper {paper}, {s:?}"
        );
        // The mean alone would have put the grass near the target.
        assert!(grass < 80, "grass {grass}");
    }

    #[test]
    fn the_guard_cannot_black_out_the_scene() {
        let mut ae = qvga();
        // A white roof that always clips (radiance far beyond anything reachable), a tenth
        // of the frame: the guard lowers the mean to a quarter of the target and no further.
        let s = resting(&mut ae, |s| Metering {
            mean: scene(s, 300),
            highlight: 255,
            pad: None,
            max_exposure_us: None,
        });
        let mean = scene(s, 300);
        let floor = (110 / GUARD_FLOOR_DIVISOR) as u8;
        assert!(
            mean + 12 >= floor && mean <= floor + 12 + 2,
            "mean {mean}, {:?}",
            ae.setting()
        );
    }

    #[test]
    fn the_body_rate_caps_the_exposure_and_gain_takes_over() {
        let mut ae = qvga();
        // A dark scene: 4 ms (33 lines) and 8x.
        for _ in 0..20 {
            ae.update(scene(ae.setting(), 10));
        }
        // A dim scene that needs 20 lines at unity gain.
        let mut ae = qvga();
        let radiance = 1_000 * 110 / (20 * 16);
        for _ in 0..20 {
            ae.update(scene(ae.setting(), radiance));
        }
        let free = ae.setting();
        assert!(free.lines >= 15 && free.gain == GainX16::ONE, "{free:?}");
        // Turning fast: at most 1.2 ms (10 lines); the same light from the gain.
        let turning = |s: ExposureSetting| Metering {
            max_exposure_us: Some(1_200),
            ..Metering::mean_only(scene(s, radiance))
        };
        let capped = ae.update_metered(&turning(ae.setting())).unwrap();
        assert_eq!(capped.lines, 10);
        let product = |s: ExposureSetting| u32::from(s.lines) * u32::from(s.gain.0);
        assert!(
            product(capped).abs_diff(product(free)) <= 16,
            "{free:?} -> {capped:?}"
        );
        for _ in 0..10 {
            ae.update_metered(&turning(ae.setting()));
            assert!(ae.setting().lines <= 10);
        }
        // The turn ends: the exposure takes the light back from the gain.
        for _ in 0..3 {
            ae.update(scene(ae.setting(), radiance));
        }
        assert_eq!(ae.setting().gain, GainX16::ONE, "{:?}", ae.setting());
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
