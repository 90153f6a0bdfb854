//! The board's auto-exposure closed around a rendered scenario: each frame is rendered with
//! the exposure time and gain the board's loop ([`AutoExposure`], the firmware's) chose from
//! the frames before it, as the camera board drives its sensor.
//!
//! The loop is fed what the board's pipeline metered in each frame (the "ours" method's
//! [`Metering`]: the decoded markers' white and black, the scene's mean and highlight, the
//! motion cap from the body rate the companion received), and its setting reaches the sensor
//! [`LATENCY_FRAMES`] frames later: the firmware writes it after processing frame n, while
//! frame n + 1 is already being exposed. The simulator turns the setting into electrons
//! (exposure time x its sensitivity), grey levels (x the analog gain) and motion blur (over
//! the exposure time): [`touchdown_sim::sensor::Exposure::Manual`].
//!
//! Before the first frame the camera has been running (the vehicle climbed to where the
//! recording starts): [`PREROLL_FRAMES`] frames at the first frame's pose go through a
//! pipeline of their own, unscored, only to settle the loop. Between set points (a scenario
//! that records only its hovers) the loop keeps its state, as it would over the flight
//! between them.
//!
//! The sensor timing is the OV7725's at VGA, 30 fps (the simulated camera is 640 x 480):
//! 510 lines of 65.33 µs; the limits are the board's defaults (TD_EXP_MAX_US, TD_GAIN_MAX,
//! TD_EXP_TARGET, [`AutoExposureLimits::default`]) unless `--board-params` sets them.

use super::input::Input;
use crate::CliError;
use std::collections::VecDeque;
use touchdown_core::family::Family;
use touchdown_core::filter::VehicleState;
use touchdown_core::pad::PadLayout;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_core::sensor::{AutoExposure, AutoExposureLimits, ExposureSetting, Metering};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_sim::sensor::ManualExposure;

/// Frames between the one a setting is computed from and the first one exposed with it.
pub const LATENCY_FRAMES: usize = 2;
/// Frames the loop runs on before the first one replayed (one second at 30 fps).
pub const PREROLL_FRAMES: usize = 30;
/// One sensor line at VGA 30 fps on the OV7725 (1,568 pixel clocks at 24 MHz), ns.
pub const LINE_NS: u32 = 65_333;
/// Sensor lines per frame at VGA 30 fps on the OV7725.
pub const FRAME_LINES: u32 = 510;

/// The board's loop and the settings on their way to the sensor.
#[derive(Debug, Clone)]
pub struct BoardExposure {
    loop_: AutoExposure,
    /// Settings written but not yet exposed, oldest first: the front one is the frame's.
    pending: VecDeque<ExposureSetting>,
}

impl BoardExposure {
    /// The loop within `limits`, at its start-up setting (which the first
    /// [`LATENCY_FRAMES`] frames are exposed with).
    pub fn new(limits: AutoExposureLimits) -> Self {
        let loop_ = AutoExposure::new(limits, LINE_NS, FRAME_LINES);
        BoardExposure {
            pending: std::iter::repeat_n(loop_.setting(), LATENCY_FRAMES).collect(),
            loop_,
        }
    }

    /// The exposure of the next frame.
    pub fn next_frame(&self) -> ManualExposure {
        manual(
            self.pending
                .front()
                .copied()
                .unwrap_or(self.loop_.setting()),
        )
    }

    /// The frame just exposed was metered as `metering` (`None`: not processed): the loop
    /// updates and its setting joins the queue.
    pub fn after_frame(&mut self, metering: Option<&Metering>) {
        if let Some(m) = metering {
            self.loop_.update_metered(m);
        }
        self.pending.pop_front();
        self.pending.push_back(self.loop_.setting());
    }

    /// The loop's current setting.
    #[cfg(test)]
    pub fn setting(&self) -> ExposureSetting {
        self.loop_.setting()
    }

    /// The exposures of the next [`LATENCY_FRAMES`] frames, in order.
    pub fn queued(&self) -> Vec<ManualExposure> {
        self.pending.iter().copied().map(manual).collect()
    }

    /// The exposure of the frame [`LATENCY_FRAMES`] after the one just metered (the newest
    /// setting).
    pub fn newest(&self) -> ManualExposure {
        manual(self.loop_.setting())
    }
}

/// Settles `loop_` on [`PREROLL_FRAMES`] renders of `input`'s first frame, each exposed as
/// the loop's queue says and metered by a board pipeline of its own (the default
/// configuration and settings: only its metering is used, its estimates are dropped).
pub fn preroll(
    loop_: &mut BoardExposure,
    input: &Input,
    families: &[&Family<'_>],
    layout: PadLayout<'_>,
) -> Result<(), CliError> {
    let mut pipeline = FramePipeline::new(
        families,
        &layout,
        input.camera,
        PipelineConfig::default(),
        PipelineSettings::default(),
    )
    .map_err(|e| CliError(format!("cannot set up the exposure's pre-roll: {e:?}")))?;
    let mut workspace = HostWorkspace::new();
    let vehicle = VehicleState::new();
    for _ in 0..PREROLL_FRAMES {
        let frame = input.frame(0, Some(loop_.next_frame()))?;
        let image = frame.image.view();
        let mut buffers = workspace.buffers(image.width(), image.height());
        let report = pipeline.process(&image, frame.t_us, &vehicle, &mut buffers);
        loop_.after_frame(Some(&report.metering));
    }
    Ok(())
}

/// A setting as the simulated sensor takes it.
pub fn manual(setting: ExposureSetting) -> ManualExposure {
    ManualExposure {
        exposure_s: f64::from(setting.lines) * f64::from(LINE_NS) * 1e-9,
        analog_gain: f64::from(setting.gain.0) / 16.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_core::sensor::GainX16;

    #[test]
    fn a_setting_reaches_the_sensor_two_frames_late() {
        let mut ae = BoardExposure::new(AutoExposureLimits::default());
        let start = ae.next_frame();
        // 4 ms / 65.3 µs = 61 lines; the loop starts at half: 30 lines, 1.96 ms, unity gain.
        assert_eq!(ae.setting().lines, 30);
        assert!((start.exposure_s - 30.0 * 65.333e-6).abs() < 1e-9);
        assert_eq!(start.analog_gain, 1.0);
        // A bright frame: the loop halves at once, the sensor two frames later.
        ae.after_frame(Some(&Metering::mean_only(255)));
        assert_eq!(ae.setting().lines, 15);
        assert_eq!(ae.next_frame(), start);
        ae.after_frame(None);
        assert!((ae.next_frame().exposure_s - 15.0 * 65.333e-6).abs() < 1e-9);
        let doubled = manual(ExposureSetting {
            lines: 1,
            gain: GainX16(32),
        });
        assert_eq!(doubled.analog_gain, 2.0);
    }
}
