//! The OV2640's clock plan: the clock doubler, divider and dummy lines for a frame rate, and
//! the output clock of each size.
//!
//! Separate from the driver because it is pure arithmetic on the SVGA mode's frame timing: it
//! touches no bus, and the derived set-up only writes the plan's register values (CLKRC,
//! FLL/FLH, R_DVP_SP).

use super::{
    CLKRC_DOUBLER, CLKRC_MAX_DIVIDER, FPS_TOLERANCE_PPM, MAX_SENSOR_CLOCK_HZ, SVGA_ACTIVE_LINES,
    SVGA_FRAME_LINES, SVGA_LINE_CLOCKS, XCLK_RANGE_HZ,
};
use crate::{ConfigError, FrameTiming, Resolution};

/// Sensor clock, frame length and output clock for a frame rate ([`plan_clock`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockPlan {
    /// CLKRC bit 7: the input clock is doubled.
    pub doubler: bool,
    /// CLKRC\[5:0\]: the (doubled) input clock is divided by this plus one.
    pub divider: u8,
    /// Dummy lines added to the frame (FLL/FLH).
    pub dummy_lines: u16,
    /// Resulting sensor clock, Hz.
    pub sensor_clock_hz: u32,
    /// R_DVP_SP: the output PCLK divider of the mode.
    pub dvp_divider: u8,
    /// Resulting line and frame timing (with the output PCLK).
    pub timing: FrameTiming,
}

impl ClockPlan {
    /// The CLKRC register value.
    pub(super) const fn clkrc(&self) -> u8 {
        let doubler = if self.doubler { CLKRC_DOUBLER } else { 0 };
        doubler | (self.divider & CLKRC_MAX_DIVIDER)
    }
}

/// How the DSP turns the 800x600 window into the output size: CTRLI down-sampling (log2,
/// the same both ways) and the output PCLK divider R_DVP_SP.
///
/// QVGA halves the window to 400x300 first, VGA does not; the zoom then scales by 0.8 in
/// both. The PCLK divider gives the output port enough bandwidth with margin: per sensor
/// line (1190 sensor clocks) VGA emits on average 0.8 output lines of 1280 bytes, QVGA 0.4
/// lines of 640 bytes. With the DSP clock at twice the sensor clock (see
/// [`reg::dsp::R_DVP_SP`](super::reg::dsp::R_DVP_SP)), dividing by 2 (VGA) gives PCLK = sensor clock (the port 86% busy),
/// by 4 (QVGA) half of it (43% busy).
pub(super) const fn scaling(resolution: Resolution) -> (u8, u8) {
    match resolution {
        Resolution::Qvga => (1, 4),
        Resolution::Vga => (0, 2),
    }
}

/// Chooses the clock doubler, divider and dummy lines for `fps` frames per second from an
/// input clock of `xclk_hz`, with the output clock of `resolution`.
///
/// Among settings within [`FPS_TOLERANCE_PPM`] of the request, the one with the fewest dummy
/// lines wins (the mode's natural timing), then the lower sensor clock, then the one
/// without the doubler. If none is within tolerance, the closest rate wins.
pub fn plan_clock(
    xclk_hz: u32,
    resolution: Resolution,
    fps: u32,
) -> Result<ClockPlan, ConfigError> {
    if !XCLK_RANGE_HZ.contains(&xclk_hz) {
        return Err(ConfigError::XclkOutOfRange);
    }
    if fps == 0 {
        return Err(ConfigError::FrameRateUnreachable);
    }
    let (_, dvp_divider) = scaling(resolution);
    let fps = u64::from(fps);
    let line = u64::from(SVGA_LINE_CLOCKS);
    // (out of tolerance, dummy lines or error, sensor clock) -> plan; smallest key wins,
    // the first found on a tie (no doubler is tried first).
    let mut best: Option<((bool, u64, u64), ClockPlan)> = None;
    for doubler in [false, true] {
        for divider in 0..=CLKRC_MAX_DIVIDER {
            let multiplier = if doubler { 2 } else { 1 };
            let clock = u64::from(xclk_hz) * multiplier / (u64::from(divider) + 1);
            if clock == 0 || clock > u64::from(MAX_SENSOR_CLOCK_HZ) {
                continue;
            }
            let lines = (clock / fps + line / 2) / line;
            let Some(dummy) = lines.checked_sub(u64::from(SVGA_FRAME_LINES)) else {
                continue;
            };
            let Ok(dummy_lines) = u16::try_from(dummy) else {
                continue;
            };
            // Achieved rate in milli-fps against the request.
            let achieved = clock * 1000 / (lines * line);
            let error_ppm = achieved.abs_diff(fps * 1000) * 1_000_000 / (fps * 1000);
            let out = error_ppm > FPS_TOLERANCE_PPM;
            let key = (out, if out { error_ppm } else { dummy }, clock);
            if best.as_ref().is_some_and(|(k, _)| *k <= key) {
                continue;
            }
            let sensor_clock_hz = u32::try_from(clock).unwrap_or(u32::MAX);
            // Output PCLK = DSP clock (2 x sensor clock) / R_DVP_SP.
            let pclk = clock * 2 / u64::from(dvp_divider);
            let line_ns = u32::try_from(line * 1_000_000_000 / clock).unwrap_or(u32::MAX);
            best = Some((
                key,
                ClockPlan {
                    doubler,
                    divider,
                    dummy_lines,
                    sensor_clock_hz,
                    dvp_divider,
                    timing: FrameTiming {
                        pclk_hz: u32::try_from(pclk).unwrap_or(u32::MAX),
                        line_ns,
                        frame_lines: u32::try_from(lines).unwrap_or(u32::MAX),
                        active_lines: SVGA_ACTIVE_LINES,
                    },
                },
            ));
        }
    }
    best.map(|(_, plan)| plan)
        .ok_or(ConfigError::FrameRateUnreachable)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_plans() {
        // 30 fps from 24 MHz: the input clock as it is (OmniVision's reference set-up).
        let p = plan_clock(24_000_000, Resolution::Qvga, 30).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (false, 0, 0));
        // 25 fps from 24 MHz: 135 dummy lines, as in OmniVision's frame-rate note.
        let p = plan_clock(24_000_000, Resolution::Qvga, 25).unwrap();
        assert_eq!(p.dummy_lines, 135);
        assert!((p.timing.fps() - 25.0).abs() < 0.05, "{}", p.timing.fps());
        // A 12 MHz clock (OpenMV-style) needs the doubler for 30 fps.
        let p = plan_clock(12_000_000, Resolution::Vga, 30).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (true, 0, 0));
        assert_eq!(p.timing.pclk_hz, 24_000_000);
        // ... and not for 15 fps.
        let p = plan_clock(12_000_000, Resolution::Qvga, 15).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (false, 0, 0));
        // A slow rate is reached with the divider, then dummy lines.
        let p = plan_clock(24_000_000, Resolution::Qvga, 1).unwrap();
        assert!((p.timing.fps() - 1.0).abs() < 0.005, "{}", p.timing.fps());
        // Beyond the SVGA mode's 30 fps, and zero, are refused.
        assert_eq!(
            plan_clock(24_000_000, Resolution::Qvga, 31),
            Err(ConfigError::FrameRateUnreachable)
        );
        assert_eq!(
            plan_clock(24_000_000, Resolution::Qvga, 0),
            Err(ConfigError::FrameRateUnreachable)
        );
        assert_eq!(
            plan_clock(40_000_000, Resolution::Qvga, 30),
            Err(ConfigError::XclkOutOfRange)
        );
    }
}
