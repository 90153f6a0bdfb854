//! Frame capture: the camera sensor (OV7725 or OV2640) on the DCMI, DMA into two frame
//! buffers, frame time stamps.
//!
//! # Data path
//!
//! The sensor sends YUV 4:2:2 with Y first (`Y U Y V ...`, one byte per pixel clock). Both
//! drivers set up this format and the same sync polarities (`touchdown_sensors::any`), so
//! this module is the same for either and is configured before it is known which one answers
//! on the SCCB bus. The DCMI's byte select keeps every other byte starting with the first
//! (RM0433 §34.5.1 DCMI_CR, BSM = 01, OEBS = 0), so the DMA writes 8-bit grey straight into
//! the frame buffer: 76,800 bytes per QVGA frame, 19,200 32-bit words.
//!
//! # The 65,535-word limit and VGA
//!
//! embassy-stm32's `Dcmi::capture` is one DMA transfer per frame, and a DMA1/DMA2 stream
//! counts at most 65,535 items (NDTR is 16 bits): 262,140 bytes. A 640x480 grey frame is
//! 307,200 bytes, so with the `camera-vga` feature the DCMI crops the frame to its middle
//! 640x400 rows (RM0433 §34.5.9/§34.5.10 DCMI_CWSTRT/DCMI_CWSIZE: 256,000 bytes, 64,000
//! words). Both sensors deliver the same 640x480 (the OV7725 from its VGA window, the OV2640
//! from its DSP's scaling of the 800x600 readout), so the crop is the same for both, and so
//! is the shift of the principal point up by the 40 cropped rows in either camera model
//! ([`crate::config`]).
//!
//! # Double buffering
//!
//! `Dcmi::capture` arms the DMA and enables the DCMI on its first poll and completes at the
//! end of the frame. The vision task joins the capture of frame n+1 (into one buffer) with
//! the processing of frame n (the other buffer), capture polled first: while the detector
//! runs on the CPU, the DMA fills the other buffer. Then the buffers swap. The DCMI runs in
//! snapshot mode (one frame per capture: once the CAPTURE bit is set it waits for the next
//! frame start; RM0433's DCMI chapter, "Capture modes") and is re-armed within microseconds of the
//! previous frame's end, inside the sensor's vertical blanking, so no frame is lost as long
//! as processing takes less than a frame period. Anything slow between two captures (the
//! SCCB writes of an exposure change) would push the re-arm past the next frame start and
//! cost a frame, so the vision task does that work while the next capture runs.
//!
//! # Faults and how embassy reports them
//!
//! embassy's `Dcmi::capture` (embassy-stm32 0.6, `dcmi.rs`) joins the DMA transfer with a
//! wait for the DCMI's flags and returns only when *both* are done. On a FIFO overrun
//! (OVR_RIS) the frame's remaining data never reaches the DMA, so the transfer never
//! completes and the capture never returns: without more, an overrun looks exactly like a
//! dead camera and ends in the timeout. The same holds for a frame that ends (FRAME_RIS)
//! before the buffer is full (a short frame: fewer lines than configured, as just after
//! the set-up). It returns `Err(Overrun)` only if the DMA got its words anyway. So
//! [`FrameStamp`], which runs in the DCMI interrupt right after embassy's handler (which
//! masks the flag's interrupt but leaves the flag set), reads DCMI_RIS itself: an overrun
//! (or a synchronisation error) ends the capture at once through [`DCMI_FAULT`], and a
//! frame-complete flag is remembered with its time stamp, so a capture that then times out
//! is told apart as a short frame ([`CaptureError::ShortFrame`]) from one that saw no frame
//! end at all ([`CaptureError::Timeout`]). Either way the capture future is dropped (which
//! stops the DMA stream: embassy's `Transfer` drop disables it and waits), and [`stop_dcmi`]
//! disables the DCMI and clears its flags. DMA transfer errors (TEIF) never get here:
//! embassy's DMA interrupt handler panics on them. The timeout is the sensor's: two frame
//! periods and a margin ([`FrameTiming::capture_timeout_us`]), not a fixed time that a slower
//! frame rate would exceed on every frame.
//!
//! (Reasoned from embassy's sources and RM0433, not yet observed on hardware: see the
//! first-hardware-run checklist in `firmware/README.md`.)
//!
//! # Cache coherence
//!
//! The buffers are in AXI SRAM, which the Cortex-M7 caches (write-back). The choice here is
//! cache maintenance rather than a non-cacheable MPU region: the detector reads every pixel
//! several times (threshold tiles, boundary following, decoding), and with the D-cache those
//! reads hit 32-byte lines instead of going over the AXI bus each time. So before a capture
//! the buffer's lines are cleaned and invalidated (no dirty line can later be evicted over
//! the DMA's data), and after it they are invalidated again (lines the core fetched
//! speculatively during the transfer are dropped). The buffers are 32-byte aligned and a
//! whole number of lines long, so the maintenance never touches a neighbour.
//!
//! # Time stamps
//!
//! [`FrameStamp`] runs in the DCMI interrupt (it is bound next to embassy's own handler) and
//! notes `Instant::now()` when the frame-complete flag rises, i.e. at the end of the frame's
//! last captured line, even while the detector keeps the thread busy (with the VGA crop that is the
//! crop's last line, 40 rows before the sensor's last: RM0433 §34.5.3 DCMI_RIS FRAME_RIS).
//! The vision task turns that into the frame's mid-exposure time with
//! [`FrameTiming::mid_exposure_before_frame_end_us`], from the rows kept ([`HEIGHT`]) of the
//! rows the sensor sends ([`SENSOR_RESOLUTION`]).
//!
//! [`FrameTiming::capture_timeout_us`]: touchdown_core::sensor::FrameTiming::capture_timeout_us
//! [`FrameTiming::mid_exposure_before_frame_end_us`]:
//!     touchdown_core::sensor::FrameTiming::mid_exposure_before_frame_end_us

use core::cell::Cell;

use embassy_futures::select::{select3, Either3};
use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::interrupt;
use embassy_stm32::pac;
use embassy_stm32::peripherals::DCMI;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Timer};
use touchdown_sensors::Resolution;

/// What the sensor is asked to send (the DCMI keeps all of it, or with `camera-vga` the
/// middle [`HEIGHT`] rows).
#[cfg(not(feature = "camera-vga"))]
pub const SENSOR_RESOLUTION: Resolution = Resolution::Qvga;
/// What the sensor is asked to send (the DCMI keeps all of it, or with `camera-vga` the
/// middle [`HEIGHT`] rows).
#[cfg(feature = "camera-vga")]
pub const SENSOR_RESOLUTION: Resolution = Resolution::Vga;
/// Frame width in pixels.
#[cfg(not(feature = "camera-vga"))]
pub const WIDTH: usize = 320;
/// Frame height in pixels.
#[cfg(not(feature = "camera-vga"))]
pub const HEIGHT: usize = 240;
/// Frame width in pixels.
#[cfg(feature = "camera-vga")]
pub const WIDTH: usize = 640;
/// Frame height in pixels (the middle 400 of the sensor's 480 rows, see the module docs).
#[cfg(feature = "camera-vga")]
pub const HEIGHT: usize = 400;
/// Rows cropped off the top of the sensor's frame.
#[cfg(feature = "camera-vga")]
pub const CROP_TOP: usize = 40;
/// Bytes of one 8-bit grey frame.
pub const FRAME_BYTES: usize = WIDTH * HEIGHT;
/// 32-bit DMA words per frame.
pub const FRAME_WORDS: usize = FRAME_BYTES / 4;
/// A DMA1/DMA2 stream moves at most this many items in one transfer (16-bit NDTR).
const MAX_DMA_ITEMS: usize = 65_535;
const _: () = assert!(
    FRAME_WORDS <= MAX_DMA_ITEMS,
    "a frame must fit one DMA transfer"
);
// Cache maintenance by address works on whole 32-byte lines.
const _: () = assert!(FRAME_BYTES.is_multiple_of(32));
// The frame is the sensor's, whole or (VGA) cropped symmetrically top and bottom.
#[cfg(not(feature = "camera-vga"))]
const _: () = assert!(
    WIDTH == SENSOR_RESOLUTION.width() as usize && HEIGHT == SENSOR_RESOLUTION.height() as usize
);
#[cfg(feature = "camera-vga")]
const _: () = assert!(
    WIDTH == SENSOR_RESOLUTION.width() as usize
        && HEIGHT + 2 * CROP_TOP == SENSOR_RESOLUTION.height() as usize
);

/// One 8-bit grey frame, aligned to the Cortex-M7's 32-byte cache line.
///
/// Stored as 32-bit words because the DCMI's DMA fills a `&mut [u32]`; it packs four
/// consecutive pixels into each word, first pixel in the lowest byte, so on the little-endian
/// Cortex-M7 the bytes are in pixel order.
#[repr(C, align(32))]
pub struct FrameBuffer([u32; FRAME_WORDS]);

impl FrameBuffer {
    /// A black frame (a `const fn`: usable as the initialiser of a static).
    pub const fn new() -> Self {
        FrameBuffer([0; FRAME_WORDS])
    }

    /// The pixels, row by row (`WIDTH` x `HEIGHT` bytes).
    pub fn pixels(&self) -> &[u8] {
        bytemuck::cast_slice(&self.0)
    }
}

/// DCMI signal polarities, the same for both sensors: VSYNC high between frames, HREF high
/// while a line's data is valid, data stable on the rising edge of PCLK. The OV7725 does this
/// at its reset defaults; the OV2640's VSYNC is the other way round at reset (high during the
/// frame), so its driver inverts it (COM10 bit 1) to match. (OpenMV's DCMI set-up agrees: it
/// uses VSYNC-high-is-blanking for the OV7725 and the opposite for an OV2640 left at reset.)
pub fn dcmi_config() -> dcmi::Config {
    let mut config = dcmi::Config::default();
    config.vsync_level = dcmi::VSyncDataInvalidLevel::High;
    config.hsync_level = dcmi::HSyncDataInvalidLevel::Low;
    config.pixclk_polarity = dcmi::PixelClockPolarity::RisingEdge;
    config
}

/// DCMI_CR bits 17:16, BSM (byte select mode) = 01: capture every other byte
/// (RM0433 §34.5.1 DCMI_CR).
const CR_BSM_MASK: u32 = 0b11 << 16;
const CR_BSM_EVERY_OTHER_BYTE: u32 = 0b01 << 16;
/// DCMI_CR bit 18, OEBS (odd/even byte select): 0 keeps the first byte of each pair, the Y
/// of `Y U Y V` (RM0433 §34.5.1 DCMI_CR).
const CR_OEBS: u32 = 1 << 18;

/// Sets the DCMI options embassy's driver does not expose: Y-only byte select and, for VGA,
/// the crop window. Call once after `Dcmi::new_8bit` and before the first capture (the
/// fields may only change while the DCMI is disabled; embassy enables it only inside
/// `capture`).
pub fn configure_dcmi() {
    pac::DCMI.cr().modify(|w| {
        // RM0433 §34.5.1 DCMI_CR: BSM = 01 (bits 17:16), OEBS = 0 (bit 18).
        w.0 = (w.0 & !(CR_BSM_MASK | CR_OEBS)) | CR_BSM_EVERY_OTHER_BYTE;
        // RM0433 §34.5.1 DCMI_CR bit 2 CROP: capture only the window set below.
        w.set_crop(cfg!(feature = "camera-vga"));
    });
    #[cfg(feature = "camera-vga")]
    {
        // RM0433 §34.5.9 DCMI_CWSTRT: VST (bits 28:16) = first captured line, HOFFCNT
        // (bits 13:0) = pixel clocks skipped at the start of each line (none).
        pac::DCMI.cwstrt().write(|w| {
            w.set_vst(CROP_TOP as u16);
            w.set_hoffcnt(0);
        });
        // RM0433 §34.5.10 DCMI_CWSIZE: VLINE (bits 29:16) = lines - 1; CAPCNT (bits 13:0) =
        // pixel clocks per line - 1. The count is in pixel clocks before byte selection:
        // two per pixel in YUV 4:2:2, so 1280 for 640 pixels.
        pac::DCMI.cwsize().write(|w| {
            w.set_vline((HEIGHT - 1) as u16);
            w.set_capcnt((2 * WIDTH - 1) as u16);
        });
    }
}

/// Stops the DCMI after an abandoned capture (fault or timeout; the DMA stream was already
/// stopped by dropping embassy's capture future): RM0433 §34.5.1 DCMI_CR bit 0 CAPTURE and
/// bit 14 ENABLE cleared, then RM0433 §34.5.6 DCMI_ICR FRAME_ISC, OVR_ISC, ERR_ISC written to
/// clear the flags the abandoned capture left. embassy enables the DCMI, clears the flags and
/// unmasks their interrupts again at the next capture.
fn stop_dcmi() {
    pac::DCMI.cr().modify(|w| {
        w.set_capture(false);
        w.set_enable(false);
    });
    pac::DCMI.icr().write(|w| {
        w.set_frame_isc(true);
        w.set_ovr_isc(true);
        w.set_err_isc(true);
    });
}

/// When the last frame-complete flag rose (set in the interrupt, taken by the capture).
static FRAME_END: Mutex<CriticalSectionRawMutex, Cell<Option<Instant>>> =
    Mutex::new(Cell::new(None));

/// An overrun or synchronisation error the interrupt saw during the current capture.
static DCMI_FAULT: Signal<CriticalSectionRawMutex, CaptureError> = Signal::new();

/// Second handler on the DCMI interrupt (after embassy's, which masks the flag it saw but
/// leaves it set until the capture future clears it): time-stamps the end of each frame and
/// reports faults the capture future would not return (see the module docs).
pub struct FrameStamp;

impl interrupt::typelevel::Handler<interrupt::typelevel::DCMI> for FrameStamp {
    unsafe fn on_interrupt() {
        // Read only (clearing is the capture's job): RM0433 §34.5.3 DCMI_RIS bit 0 FRAME_RIS
        // (frame complete), bit 1 OVR_RIS (FIFO overrun), bit 2 ERR_RIS (synchronisation
        // error; only with embedded sync codes, which this set-up does not use).
        let ris = pac::DCMI.ris().read();
        if ris.ovr_ris() {
            DCMI_FAULT.signal(CaptureError::Overrun);
        } else if ris.err_ris() {
            DCMI_FAULT.signal(CaptureError::SyncError);
        }
        if ris.frame_ris() {
            let now = Instant::now();
            FRAME_END.lock(|t| {
                if t.get().is_none() {
                    t.set(Some(now));
                }
            });
        }
    }
}

/// Why a capture failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum CaptureError {
    /// The DCMI's FIFO overflowed (OVR_RIS: the DMA fell behind the pixel clock); the frame
    /// is lost.
    Overrun,
    /// The DCMI saw a synchronisation error (ERR_RIS). Only possible with embedded sync
    /// codes; with the hardware HSYNC/VSYNC used here it points at a DCMI set-up gone wrong.
    SyncError,
    /// The frame ended (FRAME_RIS) before it filled the buffer: the sensor sent fewer lines
    /// or pixels than [`WIDTH`] x [`HEIGHT`] (a frame while the sensor settles, or a window
    /// that does not match).
    ShortFrame,
    /// No frame ended within the timeout (camera stopped, clock lost, sync wiring).
    Timeout,
}

/// The DCMI side of the camera.
pub struct Capture {
    dcmi: Dcmi<'static, DCMI>,
}

impl Capture {
    /// Takes the DCMI driver (already configured with [`configure_dcmi`]).
    pub fn new(dcmi: Dcmi<'static, DCMI>) -> Self {
        Capture { dcmi }
    }

    /// Captures the next whole frame into `buffer`; returns when the frame ended (the time
    /// its frame-complete flag rose). Gives up after `timeout` (see
    /// [`FrameTiming::capture_timeout_us`]) or at once on a DCMI fault.
    ///
    /// [`FrameTiming::capture_timeout_us`]:
    ///     touchdown_core::sensor::FrameTiming::capture_timeout_us
    pub async fn capture(
        &mut self,
        buffer: &mut FrameBuffer,
        timeout: Duration,
    ) -> Result<Instant, CaptureError> {
        // SAFETY: stealing the core peripherals only for D-cache maintenance by address on
        // `buffer`, which this function borrows exclusively; no other state is touched.
        let mut scb = unsafe { cortex_m::Peripherals::steal() }.SCB;
        // Write back and drop any line of the buffer before the DMA owns it.
        scb.clean_dcache_by_slice(&buffer.0);
        // SAFETY: the lines were just cleaned, so invalidating loses nothing.
        unsafe { scb.invalidate_dcache_by_slice(&mut buffer.0) };
        // Forget the previous capture's end and faults (the DCMI is off between captures, so
        // its interrupt cannot set them again before this one is armed).
        FRAME_END.lock(|t| t.set(None));
        DCMI_FAULT.reset();

        // Polled in this order: the capture first, so it is armed at once.
        let result = select3(
            self.dcmi.capture(&mut buffer.0),
            DCMI_FAULT.wait(),
            Timer::after(timeout),
        )
        .await;

        // Drop lines fetched speculatively while the DMA was writing.
        // SAFETY: the CPU has not written the buffer since the clean above; the DMA is done
        // (finished, or stopped when the capture future was dropped).
        unsafe { scb.invalidate_dcache_by_slice(&mut buffer.0) };
        let frame_end = FRAME_END.lock(|t| t.take());
        match result {
            Either3::First(Ok(())) => Ok(frame_end.unwrap_or_else(Instant::now)),
            // Overrun after the DMA had every word anyway; embassy's driver has stopped the
            // DCMI and cleared the flag itself.
            Either3::First(Err(dcmi::Error::Overrun)) => Err(CaptureError::Overrun),
            // embassy's only other error (PeripheralError) is ERR_RIS.
            Either3::First(Err(_)) => Err(CaptureError::SyncError),
            Either3::Second(fault) => {
                stop_dcmi();
                Err(fault)
            }
            Either3::Third(()) => {
                stop_dcmi();
                Err(match frame_end {
                    Some(_) => CaptureError::ShortFrame,
                    None => CaptureError::Timeout,
                })
            }
        }
    }
}
