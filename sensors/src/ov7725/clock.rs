//! The OV7725's clock plan: PLL, prescaler and dummy lines for a frame rate.
//!
//! Separate from the driver because it is pure arithmetic on the mode's frame geometry: it
//! touches no bus, and the driver only writes the plan's register values (COM4, CLKRC,
//! DM_LNL/DM_LNH) and reports its [`FrameTiming`].

use super::{
    ConfigError, CLKRC_DIRECT, CLKRC_MAX_N, CLKRC_RESERVED, FPS_TOLERANCE_PPM, MAX_PCLK_HZ,
    XCLK_RANGE_HZ,
};
use crate::{FrameTiming, Resolution};

/// The sensor's PLL setting (`COM4[7:6]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pll {
    /// PLL bypassed (x1).
    Bypass,
    /// x4.
    X4,
    /// x6.
    X6,
    /// x8.
    X8,
}

impl Pll {
    const ALL: [Pll; 4] = [Pll::Bypass, Pll::X4, Pll::X6, Pll::X8];

    /// The multiplier.
    pub const fn multiplier(self) -> u32 {
        match self {
            Pll::Bypass => 1,
            Pll::X4 => 4,
            Pll::X6 => 6,
            Pll::X8 => 8,
        }
    }

    /// `COM4[7:6]`.
    pub(super) const fn com4_bits(self) -> u8 {
        match self {
            Pll::Bypass => 0x00,
            Pll::X4 => 0x40,
            Pll::X6 => 0x80,
            Pll::X8 => 0xC0,
        }
    }
}

/// The clock prescaler (CLKRC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Prescaler {
    /// CLKRC bit 6: no division.
    Direct,
    /// `CLKRC[5:0]` = n: divide by (n + 1) x 2.
    Divide(u8),
}

impl Prescaler {
    /// The division factor.
    pub const fn divisor(self) -> u32 {
        match self {
            Prescaler::Direct => 1,
            Prescaler::Divide(n) => (n as u32 + 1) * 2,
        }
    }

    /// The CLKRC register value (reserved bit 7 kept at its reset value 1).
    pub(super) const fn clkrc(self) -> u8 {
        match self {
            Prescaler::Direct => CLKRC_RESERVED | CLKRC_DIRECT,
            Prescaler::Divide(n) => CLKRC_RESERVED | (n & 0x3F),
        }
    }
}

/// Pixel clock and frame length for a frame rate ([`plan_clock`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockPlan {
    /// PLL multiplier.
    pub pll: Pll,
    /// Prescaler.
    pub prescaler: Prescaler,
    /// Dummy lines added to the frame (DM_LNL/DM_LNH).
    pub dummy_lines: u16,
    /// Resulting pixel clock, Hz.
    pub pclk_hz: u32,
    /// Resulting line and frame timing.
    pub timing: FrameTiming,
}

/// Pixel clocks per line and lines per frame (blanking included, no dummy lines), and active
/// lines, of each mode. In YUV each pixel takes two pixel clocks (one byte each).
const fn geometry(resolution: Resolution) -> (u32, u32, u32) {
    match resolution {
        // 784 pixel periods per line, 510 lines per frame.
        Resolution::Vga => (784 * 2, 510, 480),
        // 576 pixel periods per line, 278 lines per frame.
        Resolution::Qvga => (576 * 2, 278, 240),
    }
}

/// Chooses PLL, prescaler and dummy lines for `fps` frames per second from an input clock of
/// `xclk_hz`.
///
/// Among settings within [`FPS_TOLERANCE_PPM`] of the request, the one with the fewest dummy
/// lines wins (the sensor's natural timing, as every reference configuration uses), then the
/// lower pixel clock. If none is within tolerance, the closest rate wins.
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
    let (line_pclks, base_lines, active_lines) = geometry(resolution);
    let fps = u64::from(fps);
    // (out of tolerance, dummy lines or error, pixel clock) -> plan; smallest key wins.
    let mut best: Option<((bool, u64, u64), ClockPlan)> = None;
    let prescalers =
        core::iter::once(Prescaler::Direct).chain((0..=CLKRC_MAX_N).map(Prescaler::Divide));
    for pll in Pll::ALL {
        for prescaler in prescalers.clone() {
            let pclk =
                u64::from(xclk_hz) * u64::from(pll.multiplier()) / u64::from(prescaler.divisor());
            if pclk == 0 || pclk > u64::from(MAX_PCLK_HZ) {
                continue;
            }
            let line = u64::from(line_pclks);
            let lines = (pclk / fps + line / 2) / line;
            let Some(dummy) = lines.checked_sub(u64::from(base_lines)) else {
                continue;
            };
            let Ok(dummy_lines) = u16::try_from(dummy) else {
                continue;
            };
            // Achieved rate in milli-fps against the request.
            let achieved = pclk * 1000 / (lines * line);
            let error_ppm = achieved.abs_diff(fps * 1000) * 1_000_000 / (fps * 1000);
            let out = error_ppm > FPS_TOLERANCE_PPM;
            let key = (out, if out { error_ppm } else { dummy }, pclk);
            if best.as_ref().is_some_and(|(k, _)| *k <= key) {
                continue;
            }
            let pclk_hz = u32::try_from(pclk).unwrap_or(u32::MAX);
            let line_ns = u32::try_from(line * 1_000_000_000 / pclk).unwrap_or(u32::MAX);
            best = Some((
                key,
                ClockPlan {
                    pll,
                    prescaler,
                    dummy_lines,
                    pclk_hz,
                    timing: FrameTiming {
                        pclk_hz,
                        line_ns,
                        frame_lines: u32::try_from(lines).unwrap_or(u32::MAX),
                        active_lines,
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
        // VGA 30 fps needs the full 24 MHz: input clock used directly.
        let p = plan_clock(24_000_000, Resolution::Vga, 30).unwrap();
        assert_eq!(
            (p.pll, p.prescaler, p.dummy_lines),
            (Pll::Bypass, Prescaler::Direct, 0)
        );
        // QVGA 60 fps: 19.2 MHz = 24 x 8 / 10.
        let p = plan_clock(24_000_000, Resolution::Qvga, 60).unwrap();
        assert_eq!(p.pclk_hz, 19_200_000);
        assert_eq!(p.dummy_lines, 0);
        assert!((p.timing.fps() - 60.0).abs() < 0.1, "{}", p.timing.fps());
        // QVGA 25 fps: 8 MHz = 24 x 4 / 12.
        let p = plan_clock(24_000_000, Resolution::Qvga, 25).unwrap();
        assert!((p.timing.fps() - 25.0).abs() < 0.1, "{}", p.timing.fps());
        // VGA 60 fps would need 48 MHz: beyond the pixel clock limit.
        assert_eq!(
            plan_clock(24_000_000, Resolution::Vga, 60),
            Err(ConfigError::FrameRateUnreachable)
        );
        assert_eq!(
            plan_clock(24_000_000, Resolution::Vga, 0),
            Err(ConfigError::FrameRateUnreachable)
        );
        // A 12 MHz clock (OpenMV-style) still reaches QVGA 30 fps.
        let p = plan_clock(12_000_000, Resolution::Qvga, 30).unwrap();
        assert!((p.timing.fps() - 30.0).abs() < 0.2, "{}", p.timing.fps());
    }
}
