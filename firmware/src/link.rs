//! The MAVLink link to the flight controller: the UART and the companion state machine.
//!
//! One task owns the [`Companion`] (touchdown-core's sans-IO MAVLink state machine) and the
//! UART; everything else talks to it through the [`LINK_EVENTS`] channel
//! ([`crate::channels`]): the vision task posts each frame's estimate ([`LinkEvent::Frame`])
//! and faults ([`LinkEvent::Status`]), the parameter store its faults. After each received
//! chunk that changed it, the link publishes the companion's vehicle state
//! ([`channels::publish_vehicle`]) for the vision task's estimator. One owner and a channel
//! keeps it simple: no lock around the companion, no task ever waits on another's critical
//! section, and the vision task never blocks on the link (a full channel drops and counts the
//! event rather than stall a frame).
//!
//! The loop waits for whichever comes first: bytes from the UART, an event, or a 5 ms tick
//! (heartbeats, TIMESYNC, parameter streaming, target expiry are driven by
//! `poll_transmit`'s clock). After each, it drains `poll_transmit` into the UART.
//!
//! The UART is embassy's interrupt-driven `BufferedUart`: its ring buffers are in DTCM, which
//! DMA cannot reach but the CPU (the interrupt handler copies each byte) can, so neither DMA
//! reachability nor cache maintenance comes into it; at the few kB/s a MAVLink telemetry
//! port carries the interrupt load is small.
//!
//! Parameter changes (PARAM_SET from a ground station, and the signing key a SETUP_SIGNING
//! set, which lives in the same `ParamSet`) are saved to flash once they have been
//! stable for two seconds ([`SaveDebounce`]): the link signals [`SAVE`] to the
//! parameter store task. So are TD_CAM_ROLL and TD_CAM_PITCH when the companion adopts the
//! mount calibration that came with a frame's estimate (in [`Companion::on_estimate`]: the
//! same parameter path). Those of the camera (TD_MAX_HAMMING, TD_TAG_SIZE, the auto-exposure
//! limits, the mount's TD_CAM_YAW, TD_CAM_ROLL, TD_CAM_PITCH, TD_CAM_CAL) take effect at once: after every input the link converts the parameters
//! with [`PipelineSettings::from_params`] and, when the result differs from what it last
//! published, signals [`PIPELINE_SETTINGS`] (the vision task started with the settings of the
//! parameters
//! restored at boot). A changed TD_TAG_SIZE is confirmed to the ground station with a
//! STATUSTEXT giving the pad's scale, so a size typed for the wrong marker shows before the
//! flight.

use core::fmt::Write as _;

use defmt::{info, warn};
use embassy_futures::select::{select3, Either3};
use embassy_stm32::usart::BufferedUart;
use embassy_time::{Duration, Instant, Ticker};
use embedded_io_async::{Read, Write};
use touchdown_core::companion::{Companion, MavSeverity, MAX_FRAME_LEN};
use touchdown_core::params::{ParamId, PipelineSettings, SaveDebounce};

use crate::channels::{self, LinkEvent, LINK_EVENTS, PIPELINE_SETTINGS, SAVE};
use crate::config;

/// How often the link runs its periodic work without any input.
const TICK: Duration = Duration::from_millis(5);
/// Interval of the `info` summary.
const SUMMARY_PERIOD: Duration = Duration::from_secs(1);

/// Microseconds since boot (the companion's clock).
fn now_us() -> u64 {
    Instant::now().as_micros()
}

/// Runs the link forever.
#[embassy_executor::task]
pub async fn task(uart: BufferedUart<'static>, mut companion: Companion) {
    let (mut tx, mut rx) = uart.split();
    let mut rx_buf = [0u8; 256];
    let mut tx_buf = [0u8; MAX_FRAME_LEN];
    let mut ticker = Ticker::every(TICK);
    let mut debounce = SaveDebounce::new(*companion.params());
    let mut uart_errors = 0u32;
    // The vehicle state's revision last copied for the vision task (the shared copy starts as
    // a new state, revision 0, as the companion's does).
    let mut published_vehicle = companion.vehicle().revision();
    let mut next_summary = Instant::now() + SUMMARY_PERIOD;
    // What the vision task runs with: main gave it the settings of the restored parameters.
    let mut pipeline_settings = PipelineSettings::from_params(companion.params());
    if pipeline_settings.tag_size_m.is_some() {
        announce_pad_scale(&mut companion, &pipeline_settings);
    }
    info!(
        "link: profile {}, sysid {}, compid {}",
        companion.profile(),
        companion.params().get_int(ParamId::SysId),
        companion.params().get_int(ParamId::CompId)
    );

    loop {
        match select3(rx.read(&mut rx_buf), LINK_EVENTS.receive(), ticker.next()).await {
            Either3::First(Ok(n)) => {
                companion.receive(rx_buf.get(..n).unwrap_or(&[]), now_us());
                // Copied for the vision task only when a sample came in (or was dropped).
                if companion.vehicle().revision() != published_vehicle {
                    published_vehicle = companion.vehicle().revision();
                    channels::publish_vehicle(companion.vehicle());
                }
            }
            Either3::First(Err(e)) => {
                // Framing/noise/overrun: the parser resynchronises on the next frame start.
                uart_errors = uart_errors.wrapping_add(1);
                defmt::debug!("link: uart {}", e);
            }
            Either3::Second(LinkEvent::Frame(frame)) => {
                companion.on_estimate(&frame, now_us());
            }
            Either3::Second(LinkEvent::Status(severity, text)) => {
                companion.queue_status_text(severity, text);
            }
            Either3::Third(()) => {}
        }
        let settings = PipelineSettings::from_params(companion.params());
        if settings != pipeline_settings {
            if settings.tag_size_m != pipeline_settings.tag_size_m {
                announce_pad_scale(&mut companion, &settings);
            }
            PIPELINE_SETTINGS.signal(settings);
            pipeline_settings = settings;
        }
        while let Some(n) = companion.poll_transmit(now_us(), &mut tx_buf) {
            if let Err(e) = tx.write_all(tx_buf.get(..n).unwrap_or(&[])).await {
                warn!("link: uart write {}", e);
            }
        }
        if let Some(params) = debounce.poll(companion.params(), now_us()) {
            SAVE.signal(params);
            debounce.saved(&params);
        }
        channels::link_alive();

        if Instant::now() >= next_summary {
            next_summary += SUMMARY_PERIOD;
            let s = companion.stats();
            info!(
                "link: tx {} frames, {} targets (exposure to send: mean {} us, max {} us), {} status; rx {} frames ({} bad crc, {} uart errors); autopilot {}, dropped events {}",
                s.tx_frames,
                s.landing_targets,
                s.target_latency.mean_us().unwrap_or(0),
                s.target_latency.max_us,
                s.status_texts,
                s.link.frames,
                s.link.bad_crc,
                uart_errors,
                s.autopilot,
                channels::dropped_link_events()
            );
        }
    }
}

/// Tells the ground station what TD_TAG_SIZE does to the built pad (its scale in percent).
fn announce_pad_scale(companion: &mut Companion, settings: &PipelineSettings) {
    // Room to spare: `queue_status_text` cuts at STATUSTEXT's 50 bytes, which these texts fit
    // (50 with a four-digit percentage).
    let mut text = heapless::String::<64>::new();
    let written = match settings.tag_size_m {
        Some(_) => write!(
            text,
            "touchdown: TD_TAG_SIZE: pad at {}% of built size",
            config::pad_scale_percent(settings)
        ),
        None => write!(text, "touchdown: TD_TAG_SIZE 0: pad as built"),
    };
    if written.is_err() {
        warn!("link: pad scale text too long");
    }
    info!("link: {=str}", text.as_str());
    companion.queue_status_text(MavSeverity::MAV_SEVERITY_NOTICE, &text);
}
