//! The vision task: camera frames in, pad estimates out to the MAVLink link.
//!
//! Per frame: capture (DMA, [`crate::capture`]) of frame n+1 runs while frame n goes through
//! core's [`FramePipeline`] (markers, the pad fix, the estimator: the very code the host tools
//! and the replay run, with the vehicle state the link task last published in
//! [`channels::VEHICLE`]) and the estimate is posted to the link task with the frame's
//! exposure time. The software auto-exposure ([`AutoExposure`]) adjusts the sensor from each
//! frame's metering, which the pipeline measures with the frame
//! ([`touchdown_core::pipeline::FrameReport::metering`]: the decoded markers' white and black,
//! the scene's mean and highlight, the longest exposure the body rate allows), so a replay
//! that closes the loop meters as the board does.
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
//! Settings from the MAVLink parameters (TD_MAX_HAMMING, TD_TAG_SIZE, TD_PAD, the lens's
//! TD_CAM_FX ... TD_CAM_K3, the mount's TD_CAM_YAW, TD_CAM_ROLL, TD_CAM_PITCH and TD_CAM_CAL,
//! TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET) arrive
//! as a [`PipelineSettings`]: at boot as the task's argument (from the parameters restored
//! from flash, before the first frame), afterwards through [`PIPELINE_SETTINGS`], which the
//! link task signals whenever the parameters changed them: a ground station's PARAM_SET, or
//! the companion adopting the estimator's mount calibration (which arrives with a frame's
//! estimate, [`touchdown_core::filter::FrameEstimate::mount_correction`], posted to the link
//! like every estimate). They are taken before a frame is processed, never during it: the detector's
//! correction cap, the pad (the built [`config::PAD`] or TD_PAD's design, scaled to
//! TD_TAG_SIZE), the lens (over the sensor's built model) and the camera mount, all by
//! [`FramePipeline::apply`],
//! and the exposure limits ([`AutoExposure::set_limits`], written to the sensor at once when the
//! current exposure is outside them). No restart, no lost frame.
//!
//! # Keeping the capture armed
//!
//! The DCMI captures in snapshot mode: once armed, it waits for the next frame start. So
//! nothing slow may sit between the end of one capture and the arming of the next, or the
//! sensor's vertical blanking passes and the next frame is lost. Each pass of the loop joins
//! the capture of frame n+1 (polled first, so the DMA is armed at once) with everything else:
//! taking new settings, processing frame n, and writing exposure or gain changes to the
//! sensor over SCCB (three to five register writes, about 0.3 ms at 400 kHz). All of that
//! runs while the DMA fills the other buffer. The writes now land inside frame n+1 rather
//! than in the blanking after it; the sensor latches exposure registers at a frame boundary
//! of its own, so a change takes effect no later than before (whether a change can straddle
//! that boundary and give one frame a mixed setting is on the first-hardware-run checklist
//! in `firmware/README.md`).
//!
//! # Settling and faults
//!
//! After each set-up the task waits [`FrameTiming::settling_time_us`] (ten frame periods, at
//! least 300 ms) before the first capture: the OV7725's first frames after its register
//! set-up may be short or badly exposed, and a short frame never completes the DMA transfer,
//! so without the wait the first captures would time out and the error count would restart
//! the camera (and with it the settling) over and over. A capture gives up after
//! [`FrameTiming::capture_timeout_us`] (two frame periods and a margin), or at once on a DCMI
//! overrun ([`crate::capture`] tells overrun, short frame, synchronisation error and timeout
//! apart). A capture error costs that frame and is counted; after [`MAX_CONSECUTIVE_ERRORS`]
//! in a row the camera is power-cycled and configured again, and the ground station gets a
//! STATUSTEXT. The sensor found at start is kept: a re-initialisation that keeps failing (also
//! when the id no longer matches) means no finished frames, and only finished frames feed the
//! watchdog, so a camera that never comes back ends in a reset and the probe at the next
//! start. From the last finished frame to the first after a restart (three failed captures of
//! at most 76 ms, power cycle 15 ms, set-up, settling 334 ms at 30 fps, first frame) is
//! about 0.7 s, well inside the watchdog's 2 s stall limit.
//!
//! Logs: once a second at `info`, frames per second, detection time (mean and max), and the
//! frames lost: `dropped` is the sum of the frames the sensor sent between two successful
//! captures without being captured (`skipped`: processing overran a frame period, or a
//! capture was armed late) and the failed captures by cause (overrun, short frame, timeout,
//! synchronisation error); then re-initialisations.

use defmt::{debug, info, unwrap, warn};
use embassy_futures::join::join;
use embassy_stm32::gpio::Output;
use embassy_time::{Delay, Duration, Instant, Timer};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::MavSeverity;
use touchdown_core::filter::{EstimatorConfig, PadEstimator, VehicleState};
use touchdown_core::frame_stream::{self, FrameMeta, StreamSwitch, StreamedFix};
use touchdown_core::image::GrayImage;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig, SettingsError};
use touchdown_core::sensor::{AutoExposure, ExposureSetting, FrameTiming, Metering};
use touchdown_sensors::any::{self, Camera};

use crate::capture::{Capture, CaptureError, FrameBuffer, HEIGHT, SENSOR_RESOLUTION, WIDTH};
use crate::channels::{self, LinkEvent, PIPELINE_SETTINGS};
use crate::config;
use crate::families::SEARCHED;
use crate::sccb::{Sccb, SccbError};
use crate::view::{ViewFrame, VIEW_PIXELS};
use crate::Workspace;

/// Capture errors in a row that trigger a camera re-initialisation.
pub const MAX_CONSECUTIVE_ERRORS: u32 = 3;
/// Pause between failed camera initialisations.
const INIT_RETRY: Duration = Duration::from_millis(500);
/// Interval of the `info` summary.
const SUMMARY_PERIOD: Duration = Duration::from_secs(1);

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
                    channels::post_to_link(LinkEvent::Status(
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
    async fn start(&mut self) -> Result<FrameTiming, any::Error<SccbError>> {
        self.pins.power_cycle().await;
        self.camera.init(&mut Delay, &config::sensor_config()).await
    }

    /// The pinhole model of this sensor with the board's lens.
    fn camera_model(&self) -> &'static CameraModel {
        config::camera_model(self.camera.model())
    }
}

/// Writes an exposure and gain to the sensor; a failed write is logged and the loop goes on
/// (the next change writes again, and a bus that stays dead shows as capture errors).
async fn write_exposure(camera: &mut Camera<Sccb>, setting: ExposureSetting) {
    if let Err(e) = camera.set_manual(setting.lines, setting.gain).await {
        warn!("vision: exposure: {}", e);
    }
}

/// Counters of one summary period.
#[derive(Default)]
struct Summary {
    frames: u32,
    markers: u32,
    fixes: u32,
    skipped: u32,
    overruns: u32,
    short_frames: u32,
    timeouts: u32,
    sync_errors: u32,
    reinits: u32,
    total_detect: Duration,
    max_detect: Duration,
}

/// Hands `settings` to the pipeline (the caller updates the exposure loop) and logs what
/// they do.
fn apply_settings(pipeline: &mut FramePipeline<'static>, settings: PipelineSettings) {
    if let Err(e) = pipeline.apply(settings) {
        // Only an empty pad cannot be scaled (a test keeps the shipped pads non-empty), and
        // the parameters' ranges leave few lenses that make no camera; the pipeline then
        // searches the pad as built, or through the build's lens.
        warn!("vision: settings not all taken: {}", e);
        if matches!(e, SettingsError::Camera(_)) {
            channels::post_to_link(LinkEvent::Status(
                MavSeverity::MAV_SEVERITY_WARNING,
                "touchdown: TD_CAM_* make no usable camera, using the built lens",
            ));
        }
    }
    info!(
        "vision: max hamming {}, pad '{}' at {} % of its built size, lens fx {} fy {} cx {} cy {} k1 {}, camera yaw {} roll {} pitch {} deg (calibration {}), exposure {}",
        settings.max_hamming,
        pipeline.pad().name(),
        config::pad_scale_percent(&settings),
        pipeline.camera().fx,
        pipeline.camera().fy,
        pipeline.camera().cx,
        pipeline.camera().cy,
        pipeline.camera().distortion[0],
        settings.cam_yaw_deg,
        settings.cam_roll_deg,
        settings.cam_pitch_deg,
        settings.mount_calibration,
        settings.exposure
    );
}

/// Runs the camera and the detector forever, starting with `settings` (the parameters
/// restored at boot) and following [`PIPELINE_SETTINGS`].
#[embassy_executor::task]
pub async fn task(
    pins: SensorPins,
    sccb: Sccb,
    mut capture: Capture,
    buffers: [&'static mut FrameBuffer; 2],
    workspace: &'static mut Workspace,
    settings: PipelineSettings,
) {
    let mut sensor = Sensor::probe(pins, sccb).await;
    let estimator = unwrap!(
        PadEstimator::new(EstimatorConfig::default()).ok(),
        "the default tracker configuration is valid"
    );
    // Built in place (see `FramePipeline::with_estimator` for why not `new`).
    let mut pipeline = FramePipeline::with_estimator(
        SEARCHED,
        config::PAD,
        *sensor.camera_model(),
        PipelineConfig::default(),
        estimator,
        settings,
    );
    // The estimator's copy of the vehicle state, refreshed before each frame.
    let mut vehicle = VehicleState::new();
    apply_settings(&mut pipeline, settings);
    let [mut front, mut back] = buffers;
    info!(
        "vision: {}x{} grey, searching {} famil(ies), pad '{}'",
        WIDTH,
        HEIGHT,
        SEARCHED.len(),
        config::PAD.name()
    );

    let mut view = ViewOffer {
        switch: StreamSwitch::new(),
        frame: None,
        index: 0,
    };
    let mut summary = Summary::default();
    let mut next_summary = Instant::now() + SUMMARY_PERIOD;
    loop {
        // (Re)start the camera until it answers.
        let timing = loop {
            match sensor.start().await {
                Ok(timing) => break timing,
                Err(e) => {
                    warn!("vision: camera init failed: {}", e);
                    channels::post_to_link(LinkEvent::Status(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "touchdown: camera not responding",
                    ));
                    Timer::after(INIT_RETRY).await;
                }
            }
        };
        let settle = Duration::from_micros(u64::from(timing.settling_time_us()));
        let timeout = Duration::from_micros(u64::from(timing.capture_timeout_us()));
        info!(
            "vision: {} up, PCLK {} Hz, {} lines of {} ns, {} fps; settling {} ms, capture timeout {} ms",
            sensor.camera.model().name(),
            timing.pclk_hz,
            timing.frame_lines,
            timing.line_ns,
            timing.fps(),
            settle.as_millis(),
            timeout.as_millis()
        );
        let mut exposure = AutoExposure::new(
            pipeline.settings().exposure,
            timing.line_ns,
            timing.frame_lines,
        );
        // No capture is armed yet, so this write costs no frame.
        write_exposure(&mut sensor.camera, exposure.setting()).await;
        // The first frames after the set-up are not to be trusted (see the module docs).
        Timer::after(settle).await;

        // The first frame has nothing to overlap with.
        let mut front_end = match capture.capture(front, timeout).await {
            Ok(end) => Some(end),
            Err(e) => {
                count_error(&mut summary, e);
                None
            }
        };
        let mut consecutive_errors = 0u32;
        while consecutive_errors < MAX_CONSECUTIVE_ERRORS {
            // Capture into `back` (polled first, so the DMA is armed before anything else
            // runs) while the rest of the frame's work overlaps it: see the module docs.
            let (captured, processed) = join(capture.capture(back, timeout), async {
                if let Some(settings) = PIPELINE_SETTINGS.try_take() {
                    apply_settings(&mut pipeline, settings);
                    if let Some(setting) =
                        exposure.set_limits(settings.exposure, timing.line_ns, timing.frame_lines)
                    {
                        write_exposure(&mut sensor.camera, setting).await;
                    }
                }
                let end = front_end?;
                channels::read_vehicle(&mut vehicle);
                let processed = process(
                    front,
                    end,
                    &timing,
                    &exposure,
                    &mut pipeline,
                    &vehicle,
                    workspace,
                );
                view.offer(front, &processed, &timing, &exposure, &pipeline);
                if let Some(setting) = exposure.update_metered(&processed.metering) {
                    write_exposure(&mut sensor.camera, setting).await;
                }
                Some(processed)
            })
            .await;

            if let Some(p) = processed {
                summary.frames += 1;
                summary.markers += p.markers;
                summary.fixes += u32::from(p.fix.is_some());
                summary.total_detect += p.detect;
                summary.max_detect = summary.max_detect.max(p.detect);
                channels::frame_done();
            }
            front_end = match captured {
                Ok(end) => {
                    consecutive_errors = 0;
                    // Frames the sensor sent between the two captures (only between two
                    // successful ones: a failed capture is counted as such).
                    if let Some(previous) = front_end {
                        let interval = end.as_micros().saturating_sub(previous.as_micros());
                        summary.skipped = summary
                            .skipped
                            .saturating_add(timing.frames_skipped(interval));
                    }
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
        channels::post_to_link(LinkEvent::Status(
            MavSeverity::MAV_SEVERITY_ERROR,
            "touchdown: camera capture failing, restarting it",
        ));
        summary.reinits += 1;
    }
}

fn count_error(summary: &mut Summary, e: CaptureError) {
    match e {
        CaptureError::Overrun => summary.overruns += 1,
        CaptureError::ShortFrame => summary.short_frames += 1,
        CaptureError::Timeout => summary.timeouts += 1,
        CaptureError::SyncError => {
            // Cannot happen with hardware sync signals; if it does, the DCMI set-up is wrong.
            warn!("vision: DCMI synchronisation error");
            summary.sync_errors += 1;
        }
    }
    debug!("vision: capture {}", e);
}

/// What processing one frame gave.
struct Processed {
    /// The frame's time (middle row at mid-exposure), µs.
    exposure_at: u64,
    markers: u32,
    /// The pad fix, as a viewer is sent it.
    fix: Option<StreamedFix>,
    detect: Duration,
    metering: Metering,
}

/// Runs the frame through the pipeline and posts the result to the link. Runs on the CPU
/// without yielding (the capture of the next frame proceeds by DMA meanwhile).
fn process(
    frame: &FrameBuffer,
    frame_end: Instant,
    timing: &FrameTiming,
    exposure: &AutoExposure,
    pipeline: &mut FramePipeline<'static>,
    vehicle: &VehicleState,
    workspace: &mut Workspace,
) -> Processed {
    // The frame's time: the captured image's middle row at mid-exposure.
    let before_end_us = timing.mid_exposure_before_frame_end_us(
        exposure.setting().lines,
        HEIGHT as u32,
        SENSOR_RESOLUTION.height(),
    );
    let exposure_at = frame_end
        .as_micros()
        .saturating_sub(u64::from(before_end_us));

    let Ok(image) = GrayImage::new(frame.pixels(), WIDTH, HEIGHT) else {
        // Unreachable: the buffer has exactly WIDTH x HEIGHT bytes.
        return Processed {
            exposure_at,
            markers: 0,
            fix: None,
            detect: Duration::from_ticks(0),
            metering: Metering::mean_only(0),
        };
    };
    let started = Instant::now();
    let report = pipeline.process(&image, exposure_at, vehicle, &mut workspace.buffers());
    let detect = started.elapsed();
    if let Some(e) = report.detect_error {
        debug!("vision: detect failed: {}", e);
    }
    channels::post_to_link(LinkEvent::Frame(report.estimate));
    Processed {
        exposure_at,
        markers: u32::try_from(report.markers).unwrap_or(u32::MAX),
        fix: report.fix.as_ref().map(|fix| {
            let c = fix.camera_position();
            StreamedFix {
                camera_position: [c.x, c.y, c.z],
                markers_used: fix.markers_used,
                reprojection_rms_px: fix.reprojection_rms_px,
            }
        }),
        detect,
        metering: report.metering,
    }
}

/// The vision task's side of the frame stream to a host viewer ([`crate::view`]).
struct ViewOffer {
    /// Whether a viewer asks, and for which frames.
    switch: StreamSwitch,
    /// The record, while the view task has handed it back.
    frame: Option<&'static mut ViewFrame>,
    /// Frames processed, the record's frame counter.
    index: u32,
}

impl ViewOffer {
    /// Fills the record with this frame and hands it to the view task, when a viewer asks for
    /// this frame and the record is back from sending the last one; otherwise does nothing
    /// (never waits).
    fn offer(
        &mut self,
        frame: &FrameBuffer,
        processed: &Processed,
        timing: &FrameTiming,
        exposure: &AutoExposure,
        pipeline: &FramePipeline<'static>,
    ) {
        self.index = self.index.wrapping_add(1);
        if let Some((request, at)) = channels::view_request() {
            self.switch.requested(request, at);
        }
        let Some(scale) = self.switch.take(Instant::now().as_micros()) else {
            return;
        };
        if self.frame.is_none() {
            self.frame = channels::VIEW_FREE.try_take();
        }
        let Some(record) = self.frame.take() else {
            return;
        };
        // Full resolution only when it fits the record (QVGA); a VGA frame goes halved.
        let scale = if WIDTH * HEIGHT > VIEW_PIXELS {
            2
        } else {
            scale
        };
        let pixels = frame.pixels();
        let (width, height) = if scale == 1 {
            match record.pixels.get_mut(..pixels.len()) {
                Some(out) => {
                    out.copy_from_slice(pixels);
                    (WIDTH, HEIGHT)
                }
                None => (0, 0),
            }
        } else {
            frame_stream::halve(pixels, WIDTH, HEIGHT, &mut record.pixels).unwrap_or((0, 0))
        };
        record.pixel_len = width * height;
        let setting = exposure.setting();
        let settings = pipeline.settings();
        let meta = FrameMeta {
            index: self.index,
            t_us: processed.exposure_at,
            width: width as u16,
            height: height as u16,
            scale,
            exposure_us: (u64::from(setting.lines) * u64::from(timing.line_ns) / 1000) as u32,
            gain_x16: setting.gain.0,
            process_us: u32::try_from(processed.detect.as_micros()).unwrap_or(u32::MAX),
            camera: pipeline.camera(),
            families: SEARCHED,
            pad_name: pipeline.pad().name(),
            pad_scale: settings.pad_scale(pipeline.built_pad()),
            detections: pipeline.detector().detections(),
            fix: processed.fix,
        };
        match frame_stream::encode_head(&meta, &mut record.head) {
            Ok(len) if record.pixel_len > 0 => {
                record.head_len = len;
                channels::VIEW_READY.signal(record);
            }
            _ => self.frame = Some(record),
        }
    }
}

fn log_summary(s: &Summary) {
    let mean_us = s
        .total_detect
        .as_micros()
        .checked_div(u64::from(s.frames))
        .unwrap_or(0);
    let dropped = s.skipped + s.overruns + s.short_frames + s.timeouts + s.sync_errors;
    info!(
        "vision: {} fps, {} markers, {} fixes, detect mean {} us max {} us; dropped {} (skipped {}, overrun {}, short {}, timeout {}, sync {}), reinit {}",
        s.frames,
        s.markers,
        s.fixes,
        mean_us,
        s.max_detect.as_micros(),
        dropped,
        s.skipped,
        s.overruns,
        s.short_frames,
        s.timeouts,
        s.sync_errors,
        s.reinits
    );
}
