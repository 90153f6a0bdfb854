//! The vision task: camera frames in, pad fixes out to the MAVLink link.
//!
//! Per frame: capture (DMA, [`crate::capture`]) of frame n+1 runs while frame n is searched
//! for markers ([`Detector`]), the pad pose is solved ([`pad_pose()`]) and the result is posted
//! to the link task with the frame's exposure time. The software auto-exposure
//! ([`AutoExposure`]) adjusts the sensor from each frame's mean brightness.
//!
//! The sensor: at start the task power-cycles it and asks the SCCB bus which supported sensor
//! answers ([`Camera::detect`]: an OV7725 at 0x21 or an OV2640 at 0x30), until one does; each
//! failed round logs, tells the ground station ("camera not responding") and waits
//! [`INIT_RETRY`]. Then it configures that sensor, drives its exposure and gain, and solves
//! the pose with that sensor's lens model ([`config::camera_model`]). Both sensors deliver
//! the same Y-only stream to the same capture set-up; apart from the lens model, only the
//! line and frame timing the driver reports ([`FrameTiming`]: exposure units, readout time
//! for the time stamp) differ between them.
//!
//! Settings from the MAVLink parameters (TD_MAX_HAMMING, TD_TAG_SIZE, TD_EXP_MAX_US,
//! TD_GAIN_MAX, TD_EXP_TARGET) arrive as a [`VisionSettings`]: at boot as the task's argument
//! (from the parameters restored from flash, before the first frame), afterwards through
//! [`SETTINGS`], which the link task signals whenever a PARAM_SET changed them. They are
//! taken between frames, never during one: the detector's correction cap
//! ([`Detector::set_config`]), the pad (the built [`config::PAD`], scaled to TD_TAG_SIZE) and
//! the exposure limits ([`AutoExposure::set_limits`], written to the sensor at once when the
//! current exposure is outside them). No restart, no lost frame.
//!
//! Faults: a capture error (DCMI overrun, timeout) costs that frame and is counted; after
//! [`MAX_CONSECUTIVE_ERRORS`] in a row the camera is power-cycled and configured again, and the
//! ground station gets a STATUSTEXT. The sensor found at start is kept: a re-initialisation
//! that keeps failing (also when the id no longer matches) means no finished frames, and only
//! finished frames feed the watchdog, so a camera that never comes back ends in a reset and
//! the probe at the next start.
//!
//! Logs: once a second at `info`, frames per second, detection time (mean and max), frames
//! lost to capture errors, overruns and re-initialisations.

use defmt::{debug, info, warn};
use embassy_futures::join::join;
use embassy_stm32::gpio::Output;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Delay, Duration, Instant, Timer};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{FrameResult, MavSeverity, VisionSettings};
use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_core::image::GrayImage;
use touchdown_core::pad::PadLayout;
use touchdown_core::pose::pad_pose;
use touchdown_core::sensor::any::{self, Camera};
use touchdown_core::sensor::exposure::{mean_brightness, AutoExposure};
use touchdown_core::sensor::FrameTiming;

use crate::capture::{Capture, CaptureError, FrameBuffer, HEIGHT, WIDTH};
use crate::config;
use crate::families::SEARCHED;
use crate::link::{self, LinkEvent};
use crate::sccb::Sccb;
use crate::watchdog;
use crate::Workspace;

/// Capture errors in a row that trigger a camera re-initialisation.
pub const MAX_CONSECUTIVE_ERRORS: u32 = 3;
/// Pause between failed camera initialisations.
const INIT_RETRY: Duration = Duration::from_millis(500);
/// Interval of the `info` summary.
const SUMMARY_PERIOD: Duration = Duration::from_secs(1);
/// Sample every 8th pixel of every 8th row for the exposure loop.
const BRIGHTNESS_STEP: usize = 8;

/// New settings from the link task (the newest wins if several arrive within one frame).
pub static SETTINGS: Signal<CriticalSectionRawMutex, VisionSettings> = Signal::new();

/// The sensor's control pins.
pub struct SensorPins {
    /// RESETB (active low).
    pub reset_n: Output<'static>,
    /// PWDN (active high).
    pub power_down: Output<'static>,
}

impl SensorPins {
    /// Power down and hold in reset, then wake up and release (datasheets: >1 ms each).
    async fn power_cycle(&mut self) {
        self.power_down.set_high();
        self.reset_n.set_low();
        Timer::after_millis(5).await;
        self.power_down.set_low();
        Timer::after_millis(5).await;
        self.reset_n.set_high();
        Timer::after_millis(5).await;
    }
}

/// The sensor found on the SCCB bus (OV7725 or OV2640) with its control pins.
struct Sensor {
    camera: Camera<Sccb>,
    pins: SensorPins,
}

impl Sensor {
    /// Power-cycles and probes until a supported sensor answers (each failed round logs,
    /// sends a STATUSTEXT and waits [`INIT_RETRY`]).
    async fn probe(mut pins: SensorPins, mut bus: Sccb) -> Self {
        loop {
            pins.power_cycle().await;
            match Camera::detect(bus).await {
                Ok(camera) => {
                    info!("vision: {} found", camera.model().name());
                    return Sensor { camera, pins };
                }
                Err(undetected) => {
                    warn!("vision: no camera: {}", undetected.error);
                    link::post(LinkEvent::Status(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "touchdown: camera not responding",
                    ));
                    bus = undetected.bus;
                    Timer::after(INIT_RETRY).await;
                }
            }
        }
    }

    /// Power-cycles the sensor through its pins and configures it.
    async fn start(&mut self) -> Result<FrameTiming, any::Error<crate::sccb::SccbError>> {
        self.pins.power_cycle().await;
        self.camera.init(&mut Delay, &config::sensor_config()).await
    }

    /// The pinhole model of this sensor with the board's lens.
    fn camera_model(&self) -> &'static CameraModel {
        config::camera_model(self.camera.model())
    }
}

/// Counters of one summary period.
#[derive(Default)]
struct Summary {
    frames: u32,
    markers: u32,
    fixes: u32,
    capture_errors: u32,
    overruns: u32,
    timeouts: u32,
    reinits: u32,
    total_detect: Duration,
    max_detect: Duration,
}

/// What the vision task applies from the parameters: the detector and the pad (the exposure
/// loop is rebuilt with each camera start and updated in place).
struct Applied {
    settings: VisionSettings,
    pad: PadLayout<'static>,
}

impl Applied {
    /// Applies `settings` to the detector and the pad (the caller updates the exposure loop).
    fn new(settings: VisionSettings, detector: &mut Detector) -> Self {
        detector.set_config(settings.detector_config(DetectorConfig::default()));
        let pad = match settings.pad(config::PAD) {
            Ok(pad) => pad,
            Err(e) => {
                // Only an empty built pad cannot be scaled, and a test keeps the shipped pads
                // non-empty; searching the pad as built is the best left to do.
                warn!("vision: pad '{}' not scaled: {}", config::PAD.name(), e);
                *config::PAD
            }
        };
        info!(
            "vision: max hamming {}, pad '{}' at {} % of its built size, exposure {}",
            settings.max_hamming,
            pad.name(),
            percent(settings.pad_scale(config::PAD)),
            settings.exposure
        );
        Applied { settings, pad }
    }
}

/// `factor` in whole percent (for logs and STATUSTEXT; saturates, NaN gives 0).
pub fn percent(factor: f32) -> u32 {
    (factor * 100.0 + 0.5) as u32
}

/// Runs the camera and the detector forever, starting with `settings` (the parameters
/// restored at boot) and following [`SETTINGS`].
#[embassy_executor::task]
pub async fn task(
    pins: SensorPins,
    sccb: Sccb,
    mut capture: Capture,
    buffers: [&'static mut FrameBuffer; 2],
    workspace: &'static mut Workspace,
    settings: VisionSettings,
) {
    let mut sensor = Sensor::probe(pins, sccb).await;
    let camera = sensor.camera_model();
    let mut detector = Detector::new(DetectorConfig::default());
    let mut applied = Applied::new(settings, &mut detector);
    let [mut front, mut back] = buffers;
    info!(
        "vision: {}x{} grey, searching {} famil(ies), pad '{}'",
        WIDTH,
        HEIGHT,
        SEARCHED.len(),
        config::PAD.name()
    );

    let mut summary = Summary::default();
    let mut next_summary = Instant::now() + SUMMARY_PERIOD;
    loop {
        // (Re)start the camera until it answers.
        let timing = loop {
            match sensor.start().await {
                Ok(timing) => break timing,
                Err(e) => {
                    warn!("vision: camera init failed: {}", e);
                    link::post(LinkEvent::Status(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "touchdown: camera not responding",
                    ));
                    Timer::after(INIT_RETRY).await;
                }
            }
        };
        info!(
            "vision: {} up, PCLK {} Hz, {} lines of {} ns, {} fps",
            sensor.camera.model().name(),
            timing.pclk_hz,
            timing.frame_lines,
            timing.line_ns,
            timing.fps()
        );
        let mut exposure = AutoExposure::new(
            applied.settings.exposure,
            timing.line_ns,
            timing.frame_lines,
        );
        let setting = exposure.setting();
        if let Err(e) = sensor.camera.set_manual(setting.lines, setting.gain).await {
            warn!("vision: exposure: {}", e);
        }

        // The first frame has nothing to overlap with.
        let mut front_end = match capture.capture(front).await {
            Ok(end) => Some(end),
            Err(e) => {
                count_error(&mut summary, e);
                None
            }
        };
        let mut consecutive_errors = 0u32;
        while consecutive_errors < MAX_CONSECUTIVE_ERRORS {
            // Parameter changes, between frames.
            if let Some(settings) = SETTINGS.try_take() {
                applied = Applied::new(settings, &mut detector);
                if let Some(setting) =
                    exposure.set_limits(settings.exposure, timing.line_ns, timing.frame_lines)
                {
                    if let Err(e) = sensor.camera.set_manual(setting.lines, setting.gain).await {
                        warn!("vision: exposure: {}", e);
                    }
                }
            }
            // Capture into `back` (polled first, so the DMA is armed before the detector
            // takes the CPU) while `front` is processed.
            let (captured, processed) = join(capture.capture(back), async {
                front_end.map(|end| {
                    let geometry = Geometry {
                        pad: &applied.pad,
                        camera,
                    };
                    process(
                        front,
                        end,
                        &timing,
                        &exposure,
                        &geometry,
                        &mut detector,
                        workspace,
                    )
                })
            })
            .await;

            if let Some(p) = processed {
                summary.frames += 1;
                summary.markers += p.markers;
                summary.fixes += u32::from(p.fix);
                summary.total_detect += p.detect;
                summary.max_detect = summary.max_detect.max(p.detect);
                watchdog::frame_done();
                if let Some(setting) = exposure.update(p.mean) {
                    if let Err(e) = sensor.camera.set_manual(setting.lines, setting.gain).await {
                        warn!("vision: exposure: {}", e);
                    }
                }
            }
            front_end = match captured {
                Ok(end) => {
                    consecutive_errors = 0;
                    Some(end)
                }
                Err(e) => {
                    count_error(&mut summary, e);
                    consecutive_errors += 1;
                    None
                }
            };
            core::mem::swap(&mut front, &mut back);

            if Instant::now() >= next_summary {
                next_summary += SUMMARY_PERIOD;
                log_summary(&summary);
                summary = Summary::default();
            }
        }
        warn!(
            "vision: {} capture errors in a row, restarting the camera",
            consecutive_errors
        );
        link::post(LinkEvent::Status(
            MavSeverity::MAV_SEVERITY_ERROR,
            "touchdown: camera capture failing, restarting it",
        ));
        summary.reinits += 1;
    }
}

fn count_error(summary: &mut Summary, e: CaptureError) {
    summary.capture_errors += 1;
    match e {
        CaptureError::Dcmi(embassy_stm32::dcmi::Error::Overrun) => summary.overruns += 1,
        CaptureError::Timeout => summary.timeouts += 1,
        CaptureError::Dcmi(_) => {}
    }
    debug!("vision: capture {}", e);
}

/// What processing one frame gave.
struct Processed {
    markers: u32,
    fix: bool,
    detect: Duration,
    mean: u8,
}

/// What the pose is solved against: the pad (scaled by TD_TAG_SIZE) seen through the found
/// sensor's camera model.
struct Geometry<'a> {
    pad: &'a PadLayout<'a>,
    camera: &'a CameraModel,
}

/// Detects, solves the pose of the pad and posts the frame to the link. Runs on the CPU without
/// yielding (the capture of the next frame proceeds by DMA meanwhile).
fn process(
    frame: &FrameBuffer,
    frame_end: Instant,
    timing: &FrameTiming,
    exposure: &AutoExposure,
    geometry: &Geometry<'_>,
    detector: &mut Detector,
    workspace: &mut Workspace,
) -> Processed {
    // Mid-exposure of the middle row: the frame ended when its last row was read out; the
    // middle row was read half a readout earlier, and exposed for the exposure time before
    // its read.
    let exposure_us = u64::from(exposure.setting().lines) * u64::from(timing.line_ns) / 1000;
    let back_us = u64::from(timing.readout_us()) / 2 + exposure_us / 2;
    let exposure_at = frame_end.as_micros().saturating_sub(back_us);

    let Ok(image) = GrayImage::new(frame.pixels(), WIDTH, HEIGHT) else {
        // Unreachable: the buffer has exactly WIDTH x HEIGHT bytes.
        return Processed {
            markers: 0,
            fix: false,
            detect: Duration::from_ticks(0),
            mean: 0,
        };
    };
    let mean = mean_brightness(&image, BRIGHTNESS_STEP);
    let started = Instant::now();
    let (markers, fix) = match detector.detect(&image, SEARCHED, &mut workspace.buffers()) {
        Ok(detections) => {
            let fix = pad_pose(detections, SEARCHED, geometry.pad, geometry.camera).ok();
            (detections.len() as u32, fix)
        }
        Err(e) => {
            debug!("vision: detect failed: {}", e);
            (0, None)
        }
    };
    let detect = started.elapsed();
    let has_fix = fix.is_some();
    link::post(LinkEvent::Frame(FrameResult {
        exposure_us: exposure_at,
        fix,
    }));
    Processed {
        markers,
        fix: has_fix,
        detect,
        mean,
    }
}

fn log_summary(s: &Summary) {
    let mean_us = s
        .total_detect
        .as_micros()
        .checked_div(u64::from(s.frames))
        .unwrap_or(0);
    info!(
        "vision: {} fps, {} markers, {} fixes, detect mean {} us max {} us; dropped {} (overrun {}, timeout {}), reinit {}",
        s.frames,
        s.markers,
        s.fixes,
        mean_us,
        s.max_detect.as_micros(),
        s.capture_errors,
        s.overruns,
        s.timeouts,
        s.reinits
    );
}
