//! Frame capture: the camera sensor (OV7725 or OV2640) on the DCMI, DMA into two frame
//! buffers, frame time stamps.
//!
//! # Data path
//!
//! The sensor sends YUV 4:2:2 with Y first (`Y U Y V ...`, one byte per pixel clock). Both
//! drivers set up this format and the same sync polarities (`touchdown_core::sensor::any`), so
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
//! snapshot mode (one frame per capture) and is re-armed within microseconds of the
//! previous frame's end, inside the sensor's vertical blanking, so no frame is lost as long
//! as processing takes less than a frame period.
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
//! last line, even while the detector keeps the thread busy. The vision task turns that into
//! the frame's mid-exposure time with the sensor timing.

use core::cell::Cell;

use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::interrupt;
use embassy_stm32::pac;
use embassy_stm32::peripherals::DCMI;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_time::{with_timeout, Duration, Instant};

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

/// How long a capture may take before the camera counts as stalled: three frame periods at
/// 30 fps (a capture waits up to one frame for the next VSYNC, then one frame of readout).
pub const CAPTURE_TIMEOUT: Duration = Duration::from_millis(100);

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

/// Stops the DCMI after an abandoned capture (timeout): RM0433 §34.5.1 DCMI_CR bit 0 CAPTURE
/// and bit 14 ENABLE cleared. embassy re-enables both at the next capture.
fn stop_dcmi() {
    pac::DCMI.cr().modify(|w| {
        w.set_capture(false);
        w.set_enable(false);
    });
}

/// When the last frame-complete flag rose (set in the interrupt, taken by the vision task).
static FRAME_END: Mutex<CriticalSectionRawMutex, Cell<Option<Instant>>> =
    Mutex::new(Cell::new(None));

/// Second handler on the DCMI interrupt (after embassy's, which masks the flag it saw but
/// leaves it set until the capture future clears it): time-stamps the end of each frame.
pub struct FrameStamp;

impl interrupt::typelevel::Handler<interrupt::typelevel::DCMI> for FrameStamp {
    unsafe fn on_interrupt() {
        // Read only: RM0433 §34.5.3 DCMI_RIS bit 0 FRAME_RIS, the frame-complete flag.
        if pac::DCMI.ris().read().frame_ris() {
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
    /// The DCMI's FIFO overflowed (the DMA fell behind), or a synchronisation error.
    Dcmi(dcmi::Error),
    /// No complete frame within [`CAPTURE_TIMEOUT`] (camera stopped, clock lost, wiring).
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

    /// Captures the next whole frame into `buffer`; returns when the frame ended.
    pub async fn capture(&mut self, buffer: &mut FrameBuffer) -> Result<Instant, CaptureError> {
        // SAFETY: stealing the core peripherals only for D-cache maintenance by address on
        // `buffer`, which this function borrows exclusively; no other state is touched.
        let mut scb = unsafe { cortex_m::Peripherals::steal() }.SCB;
        // Write back and drop any line of the buffer before the DMA owns it.
        scb.clean_dcache_by_slice(&buffer.0);
        // SAFETY: the lines were just cleaned, so invalidating loses nothing.
        unsafe { scb.invalidate_dcache_by_slice(&mut buffer.0) };
        FRAME_END.lock(|t| t.set(None));

        let result = with_timeout(CAPTURE_TIMEOUT, self.dcmi.capture(&mut buffer.0)).await;

        // Drop lines fetched speculatively while the DMA was writing.
        // SAFETY: the CPU has not written the buffer since the clean above; the DMA is done.
        unsafe { scb.invalidate_dcache_by_slice(&mut buffer.0) };
        match result {
            Ok(Ok(())) => Ok(FRAME_END.lock(|t| t.take()).unwrap_or_else(Instant::now)),
            Ok(Err(e)) => Err(CaptureError::Dcmi(e)),
            Err(_) => {
                stop_dcmi();
                Err(CaptureError::Timeout)
            }
        }
    }
}
