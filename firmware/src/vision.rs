//! The vision task: frames in, markers out.
//!
//! It owns the [`Detector`] (fixed-capacity candidate storage, ~20 KB, kept in the task's
//! static storage in DTCM) and borrows the frame-sized work memory ([`QvgaWorkspace`]) that
//! `main` placed in AXI SRAM. Each frame from the [`frame_source`](crate::frame_source) is
//! searched for the [`SEARCHED`](crate::families::SEARCHED) families; the result is logged
//! with defmt (a summary every second at `info`, every frame at `debug`), and each finished
//! frame is reported to the [`watchdog`](crate::watchdog).
//!
//! Issue 5 adds pose estimation and hands the result to the MAVLink task here.

use defmt::{debug, info, warn};
use embassy_time::{Duration, Instant};
use touchdown_core::detect::{DetectStats, Detector, DetectorConfig, QvgaWorkspace};

use crate::families::SEARCHED;
use crate::frame_source::TestPattern;
use crate::watchdog;

/// Interval of the `info` summary.
const SUMMARY_PERIOD: Duration = Duration::from_secs(1);

/// Runs the detector on every frame of `source`, forever.
#[embassy_executor::task]
pub async fn task(mut source: TestPattern, workspace: &'static mut QvgaWorkspace) {
    let mut detector = Detector::new(DetectorConfig::default());
    let mut summary = Summary::new();
    info!("vision: searching {} famil(ies)", SEARCHED.len());
    for family in SEARCHED {
        info!("vision:   {=str}", family.name);
    }

    loop {
        let frame = match source.next_frame().await {
            Ok(frame) => frame,
            Err(e) => {
                warn!("vision: bad frame: {}", e);
                continue;
            }
        };
        let started = Instant::now();
        let result = detector
            .detect(&frame.image, SEARCHED, &mut workspace.buffers())
            .map(|detections| detections.len());
        let elapsed = started.elapsed();

        match result {
            Ok(count) => {
                debug!(
                    "frame {}: {} marker(s), detect {} us, {} us after capture, {}",
                    frame.sequence,
                    count,
                    elapsed.as_micros(),
                    frame.captured.elapsed().as_micros(),
                    detector.stats()
                );
                for d in detector.detections() {
                    let family = SEARCHED.get(d.family as usize).map_or("?", |f| f.name);
                    debug!(
                        "  {=str} id {} hamming {} margin {} centre ({}, {})",
                        family, d.id, d.hamming, d.decision_margin, d.center.x, d.center.y
                    );
                }
                summary.add(count, elapsed, *detector.stats());
            }
            Err(e) => {
                summary.errors += 1;
                debug!("frame {}: detect failed: {}", frame.sequence, e);
            }
        }
        watchdog::frame_done();

        if summary.since.elapsed() >= SUMMARY_PERIOD {
            summary.log(&detector);
            summary = Summary::new();
        }
    }
}

/// Counters of one summary period.
struct Summary {
    since: Instant,
    frames: u32,
    errors: u32,
    markers: u32,
    max_detect: Duration,
    total_detect: Duration,
    last_stats: DetectStats,
}

impl Summary {
    fn new() -> Self {
        Summary {
            since: Instant::now(),
            frames: 0,
            errors: 0,
            markers: 0,
            max_detect: Duration::from_ticks(0),
            total_detect: Duration::from_ticks(0),
            last_stats: DetectStats::default(),
        }
    }

    fn add(&mut self, markers: usize, elapsed: Duration, stats: DetectStats) {
        self.frames += 1;
        self.markers += markers as u32;
        self.max_detect = self.max_detect.max(elapsed);
        self.total_detect += elapsed;
        self.last_stats = stats;
    }

    fn log(&self, detector: &Detector) {
        let mean_us = self
            .total_detect
            .as_micros()
            .checked_div(u64::from(self.frames))
            .unwrap_or(0);
        info!(
            "vision: {} frames ({} failed), {} markers, detect mean {} us max {} us; last {}",
            self.frames + self.errors,
            self.errors,
            self.markers,
            mean_us,
            self.max_detect.as_micros(),
            self.last_stats
        );
        if let Some(d) = detector.detections().first() {
            info!(
                "vision: last frame saw id {} (+{} more)",
                d.id,
                detector.detections().len().saturating_sub(1)
            );
        }
        if self.errors > 0 && self.frames == 0 {
            warn!("vision: every frame failed; check the family tables and buffer sizes");
        }
    }
}
