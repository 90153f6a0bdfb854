//! The camera sensor as the algorithms see it, independent of which sensor it is and of any
//! bus: the units a sensor is set in ([`GainX16`]; exposure counts in line periods), the
//! timing a configured sensor runs at ([`FrameTiming`]: frame period, rolling-shutter
//! readout, frame time stamps, capture timeouts, settling time) and the software
//! auto-exposure loop that drives it.
//!
//! What this module offers: [`GainX16`] and [`FrameTiming`], which the drivers report and the
//! per-frame path stamps frames with, and the auto-exposure loop, [`AutoExposure`] (within
//! [`AutoExposureLimits`], a new [`ExposureSetting`] per frame from the frame's
//! [`Metering`]: the decoded markers' white and black, the scene's mean and highlight, the
//! exposure the body rate allows), which sets up the frames the detector ([`crate::detect`])
//! reads. The loop is in the private submodule `exposure`, what it is fed in `metering`
//! (measured by the per-frame path, [`crate::pipeline::FramePipeline::process`], so that the
//! firmware and a replay meter alike).
//!
//! The drivers that talk to a sensor (OV7725, OV2640: register tables and SCCB transactions)
//! are not here but in the `touchdown-sensors` crate (`sensors/`), which builds on these
//! types: a driver reports the [`FrameTiming`] of the set-up it wrote and takes its manual
//! exposure and gain in these units. The module keeps the name `sensor` because that is what
//! its contents describe, a sensor's quantities and the control loop over them; what it no
//! longer holds is anything that touches one. Everything here is arithmetic on plain values,
//! tested on the host, and used by the firmware's vision task, the parameters
//! ([`crate::params`]) and the no-panic proof of the per-frame path.

mod exposure;
mod metering;

pub use exposure::{
    mean_brightness, AutoExposure, AutoExposureLimits, ExposureSetting, GUARD_FLOOR_DIVISOR,
    HIGHLIGHT_CEILING, HIGHLIGHT_CLIPPED, PAD_CLIPPED, PAD_DEADBAND, PAD_HOLD_FRAMES,
    PAD_WHITE_TARGET,
};
pub use metering::{
    motion_cap_us, pad_levels, scene_levels, Metering, PadLevels, HIGHLIGHT_SHARE,
    MAX_METERED_GRID, MAX_METERED_MARKERS, MAX_MOTION_BLUR_PX, MIN_CELL_PX, MIN_PAD_CONTRAST,
    SCENE_STEP,
};

/// Analog gain as a multiple of 1/16 (16 = 1x, 32 = 2x, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainX16(pub u16);

impl GainX16 {
    /// Unity gain.
    pub const ONE: GainX16 = GainX16(16);
}

/// The line and frame timing a configuration results in, for time stamps and exposure maths.
///
/// Lines are the *sensor's* lines, the unit its exposure registers count in. For a sensor
/// that outputs its array rows one to one (the OV7725) they are the output rows; for one
/// whose DSP scales the image (the OV2640 reads 600 rows and outputs 240 or 480) they are
/// not, and `active_lines` is the number of array rows read per frame, which is what sets
/// the rolling shutter's top-to-bottom skew.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameTiming {
    /// Pixel clock on the parallel bus (one byte per clock), Hz.
    pub pclk_hz: u32,
    /// Duration of one sensor line (active pixels plus horizontal blanking), nanoseconds:
    /// the unit of the exposure registers.
    pub line_ns: u32,
    /// Sensor lines per frame, blanking and dummy lines included.
    pub frame_lines: u32,
    /// Sensor lines read out per frame (the image rows before any scaling).
    pub active_lines: u32,
}

impl FrameTiming {
    /// Frame period, microseconds.
    pub fn frame_period_us(&self) -> u32 {
        let ns = u64::from(self.line_ns) * u64::from(self.frame_lines);
        u32::try_from(ns / 1000).unwrap_or(u32::MAX)
    }

    /// Time to read out the active lines (the rolling shutter's top-to-bottom skew), µs.
    pub fn readout_us(&self) -> u32 {
        let ns = u64::from(self.line_ns) * u64::from(self.active_lines);
        u32::try_from(ns / 1000).unwrap_or(u32::MAX)
    }

    /// Frames per second (0.0 for a degenerate timing).
    pub fn fps(&self) -> f32 {
        let period = self.frame_period_us();
        if period == 0 {
            0.0
        } else {
            1.0e6 / period as f32
        }
    }

    /// How long before the camera interface's frame-complete flag the captured image's middle
    /// row was half-way through its exposure, µs: the time stamp of the frame is that flag's
    /// time minus this.
    ///
    /// The flag rises when the last captured row has been read out. With a rolling shutter the
    /// rows are read one after another over [`readout_us`](Self::readout_us), and each row is
    /// exposed for `exposure_lines` line periods *before* its read. So the middle row of the
    /// captured band was read half the band's readout before the flag, and was at mid-exposure
    /// half the exposure time before that read.
    ///
    /// `captured_rows` of the sensor's `output_rows` rows are kept: all of them, or a
    /// contiguous band when the camera interface crops (then the flag rises at the end of the
    /// band's last row, not the frame's). The band's share of the readout is
    /// `captured_rows / output_rows` wherever the band sits, because its middle is always
    /// half its height before its end. Output rows are spread evenly over the sensor's
    /// readout also when a DSP scales the image (the OV2640 outputs 240 or 480 rows over its
    /// 600-line readout), so the fraction holds for both drivers. A band larger than the
    /// frame, or a frame of no rows, counts as the whole frame.
    ///
    /// Saturates at `u32::MAX` instead of overflowing.
    pub fn mid_exposure_before_frame_end_us(
        &self,
        exposure_lines: u16,
        captured_rows: u32,
        output_rows: u32,
    ) -> u32 {
        // u32 x u32 and u32 x u16 products fit a u64.
        let line_ns = u64::from(self.line_ns);
        let readout_ns = line_ns * u64::from(self.active_lines);
        let band_readout_ns = if output_rows == 0 || captured_rows >= output_rows {
            readout_ns
        } else {
            // readout x captured / output without the u64 overflow of the product (and
            // without u128 division, a library call on the Cortex-M7): both terms are exact
            // and the sum is at most `readout_ns`.
            let (output, captured) = (u64::from(output_rows), u64::from(captured_rows));
            readout_ns / output * captured + readout_ns % output * captured / output
        };
        let exposure_ns = line_ns * u64::from(exposure_lines);
        let before_ns = band_readout_ns.saturating_add(exposure_ns) / 2;
        u32::try_from(before_ns / 1000).unwrap_or(u32::MAX)
    }

    /// Longest wait for one frame from arming a snapshot capture, µs: up to one frame period
    /// until the next frame starts (the capture may be armed just after a start), then one
    /// frame period until it has been read out (readout plus whatever blanking the sensor puts
    /// before the frame-complete flag), plus [`CAPTURE_MARGIN_US`] for interrupt and executor
    /// latency. Longer means the camera has stalled. Saturates at `u32::MAX`.
    pub fn capture_timeout_us(&self) -> u32 {
        self.frame_period_us()
            .saturating_mul(2)
            .saturating_add(CAPTURE_MARGIN_US)
    }

    /// How long to leave a freshly configured sensor running before its frames are used, µs:
    /// the longer of [`SETTLE_MIN_US`] and [`SETTLE_FRAMES`] frame periods. Until then the
    /// OV7725 may still deliver short or badly exposed frames (its datasheet asks for 300 ms
    /// or 10 frames after the register set-up; OpenMV waits 300 ms after configuring any
    /// sensor); the same wait is used for the OV2640. Saturates at `u32::MAX`.
    pub fn settling_time_us(&self) -> u32 {
        self.frame_period_us()
            .saturating_mul(SETTLE_FRAMES)
            .max(SETTLE_MIN_US)
    }

    /// Frames the sensor sent but nobody captured between two consecutive captures whose
    /// frame-complete flags were `interval_us` apart: the interval in whole frame periods
    /// (rounded), less the one frame that was captured. 0 for a degenerate timing.
    pub fn frames_skipped(&self, interval_us: u64) -> u32 {
        let period = u64::from(self.frame_period_us());
        let Some(frames) = interval_us.saturating_add(period / 2).checked_div(period) else {
            return 0;
        };
        u32::try_from(frames.saturating_sub(1)).unwrap_or(u32::MAX)
    }
}

/// Latency allowance of [`FrameTiming::capture_timeout_us`], µs: the frame-complete interrupt
/// and the wake-up of the waiting task, with room for the longest stretch another task may
/// hold the CPU.
pub const CAPTURE_MARGIN_US: u32 = 10_000;
/// Shortest settling time after configuring a sensor, µs ([`FrameTiming::settling_time_us`]).
pub const SETTLE_MIN_US: u32 = 300_000;
/// Frames a freshly configured sensor is given to settle ([`FrameTiming::settling_time_us`]).
pub const SETTLE_FRAMES: u32 = 10;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_timing_derived_values() {
        let t = FrameTiming {
            pclk_hz: 24_000_000,
            line_ns: 49_583,
            frame_lines: 672,
            active_lines: 600,
        };
        assert_eq!(t.frame_period_us(), 33_319);
        assert_eq!(t.readout_us(), 29_749);
        assert!((t.fps() - 30.013).abs() < 0.01, "{}", t.fps());
        let zero = FrameTiming { line_ns: 0, ..t };
        assert_eq!(zero.fps(), 0.0);
    }

    /// The OV7725 at QVGA, 30 fps from 24 MHz: 278 lines of 120 µs, 240 read out.
    const OV7725_QVGA: FrameTiming = FrameTiming {
        pclk_hz: 9_600_000,
        line_ns: 120_000,
        frame_lines: 278,
        active_lines: 240,
    };
    /// The OV2640 in its SVGA mode, 30 fps from 24 MHz: 672 lines, 600 read out (the DSP
    /// scales them to 240 or 480 output rows).
    const OV2640_SVGA: FrameTiming = FrameTiming {
        pclk_hz: 24_000_000,
        line_ns: 49_583,
        frame_lines: 672,
        active_lines: 600,
    };

    #[test]
    fn mid_exposure_of_a_whole_frame_is_half_the_readout_and_half_the_exposure_back() {
        // 240 x 120 µs = 28.8 ms readout, 16 x 120 µs = 1.92 ms exposure.
        assert_eq!(
            OV7725_QVGA.mid_exposure_before_frame_end_us(16, 240, 240),
            14_400 + 960
        );
        // No exposure: the middle row's read.
        assert_eq!(
            OV7725_QVGA.mid_exposure_before_frame_end_us(0, 240, 240),
            OV7725_QVGA.readout_us() / 2
        );
        // The OV2640's output rows span its 600-line readout at either output size.
        let qvga = OV2640_SVGA.mid_exposure_before_frame_end_us(100, 240, 240);
        let vga = OV2640_SVGA.mid_exposure_before_frame_end_us(100, 480, 480);
        assert_eq!(qvga, vga);
        // (600 + 100) x 49.583 µs / 2 = 17,354 µs.
        assert_eq!(qvga, 17_354);
    }

    #[test]
    fn mid_exposure_of_a_cropped_band_counts_only_the_band_readout() {
        // The VGA build keeps the middle 400 of 480 rows: the flag rises 40 rows before the
        // frame's end, and the band's middle is 200 rows before that.
        // OV2640: 29,749.8 µs x 400 / 480 / 2 + 100 x 49.583 µs / 2 = 12,395.75 + 2,479.15.
        assert_eq!(
            OV2640_SVGA.mid_exposure_before_frame_end_us(100, 400, 480),
            14_874
        );
        let vga7725 = FrameTiming {
            line_ns: 63_500,
            frame_lines: 525,
            active_lines: 480,
            ..OV7725_QVGA
        };
        // 480 x 63.5 µs x 400/480 / 2 = 12,700 µs, and 10 lines of exposure / 2 = 317.5 µs.
        assert_eq!(
            vga7725.mid_exposure_before_frame_end_us(10, 400, 480),
            13_017
        );
        // Shorter than the uncropped value by the 40 rows' share of the readout.
        assert!(
            vga7725.mid_exposure_before_frame_end_us(10, 400, 480)
                < vga7725.mid_exposure_before_frame_end_us(10, 480, 480)
        );
    }

    #[test]
    fn mid_exposure_degenerate_and_saturating_values() {
        // A band larger than the frame, or a frame of no rows: the whole readout.
        let whole = OV7725_QVGA.mid_exposure_before_frame_end_us(16, 240, 240);
        assert_eq!(
            OV7725_QVGA.mid_exposure_before_frame_end_us(16, 500, 240),
            whole
        );
        assert_eq!(
            OV7725_QVGA.mid_exposure_before_frame_end_us(16, 0, 0),
            whole
        );
        // No rows captured: only the exposure.
        assert_eq!(
            OV7725_QVGA.mid_exposure_before_frame_end_us(16, 0, 240),
            960
        );
        // A zero timing is no time at all.
        let zero = FrameTiming {
            pclk_hz: 0,
            line_ns: 0,
            frame_lines: 0,
            active_lines: 0,
        };
        assert_eq!(zero.mid_exposure_before_frame_end_us(u16::MAX, 240, 240), 0);
        // Everything at its maximum saturates instead of overflowing.
        let max = FrameTiming {
            pclk_hz: u32::MAX,
            line_ns: u32::MAX,
            frame_lines: u32::MAX,
            active_lines: u32::MAX,
        };
        assert_eq!(
            max.mid_exposure_before_frame_end_us(u16::MAX, u32::MAX - 1, u32::MAX),
            u32::MAX
        );
        assert_eq!(max.capture_timeout_us(), u32::MAX);
        assert_eq!(max.settling_time_us(), u32::MAX);
        assert_eq!(max.frames_skipped(u64::MAX), u32::MAX);
        assert_eq!(zero.capture_timeout_us(), CAPTURE_MARGIN_US);
        assert_eq!(zero.settling_time_us(), SETTLE_MIN_US);
        assert_eq!(zero.frames_skipped(100_000), 0);
    }

    #[test]
    fn capture_timeout_is_two_frames_and_the_margin() {
        // 278 x 120 µs = 33,360 µs per frame.
        assert_eq!(
            OV7725_QVGA.capture_timeout_us(),
            2 * 33_360 + CAPTURE_MARGIN_US
        );
        // A slow frame rate gets a longer timeout (a fixed 100 ms would be one 10 fps frame).
        let slow = FrameTiming {
            frame_lines: 278 * 3,
            ..OV7725_QVGA
        };
        assert_eq!(slow.capture_timeout_us(), 2 * 100_080 + CAPTURE_MARGIN_US);
    }

    #[test]
    fn settling_time_is_ten_frames_but_at_least_300_ms() {
        // 30 fps: ten frames, 333.6 ms.
        assert_eq!(OV7725_QVGA.settling_time_us(), 333_600);
        // 60 fps: ten frames are 167 ms, so 300 ms.
        let fast = FrameTiming {
            frame_lines: 139,
            ..OV7725_QVGA
        };
        assert_eq!(fast.settling_time_us(), SETTLE_MIN_US);
    }

    #[test]
    fn frames_skipped_rounds_the_interval_to_whole_frames() {
        let period = u64::from(OV7725_QVGA.frame_period_us());
        assert_eq!(OV7725_QVGA.frames_skipped(period), 0);
        // Interrupt latency jitters the interval a little either way.
        assert_eq!(OV7725_QVGA.frames_skipped(period + period / 3), 0);
        assert_eq!(OV7725_QVGA.frames_skipped(period - period / 3), 0);
        assert_eq!(OV7725_QVGA.frames_skipped(2 * period), 1);
        assert_eq!(OV7725_QVGA.frames_skipped(5 * period + 100), 4);
        assert_eq!(OV7725_QVGA.frames_skipped(0), 0);
    }
}
