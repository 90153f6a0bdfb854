//! PLACEHOLDER frame source: a rendered test pattern instead of the camera.
//!
//! Issue 5 replaces this module with the OV7725 on the DCMI (SCCB set-up over I2C, XCLK from
//! MCO1, DMA into the frame buffer). Until then [`TestPattern`] paces frames at the camera's
//! 30 fps and draws one marker of the searched family into the QVGA buffer in AXI SRAM, so
//! the whole vision path (buffer placement, detector, logging, watchdog) runs on the board
//! without a camera and the log shows real detections. The marker slides left and right and
//! its id changes every second, so a stuck pipeline is obvious in the log.
//!
//! What issue 5 must keep: the [`FrameBuffer`] type (32-byte aligned, a whole number of cache
//! lines, placed in AXI SRAM by `main`) and the shape of [`TestPattern::next_frame`] (await
//! the next frame, get a [`Frame`] borrowing the buffer with its capture time). What it must
//! add: with the D-cache on (see `main`), invalidate the buffer's cache lines after each DMA
//! transfer (`SCB::invalidate_dcache_by_slice`) before the detector reads it, or map the buffer
//! non-cacheable with the MPU; otherwise the CPU reads stale lines.

use embassy_time::{Duration, Instant, Ticker};
use touchdown_core::family::Family;
use touchdown_core::image::{GrayImage, ImageError};

/// Frame width in pixels (QVGA).
pub const WIDTH: usize = 320;
/// Frame height in pixels (QVGA).
pub const HEIGHT: usize = 240;
/// Bytes of one 8-bit grey frame.
pub const FRAME_BYTES: usize = WIDTH * HEIGHT;
/// Frame period of the OV7725 at QVGA, 30 fps.
pub const FRAME_PERIOD: Duration = Duration::from_micros(33_333);

/// One 8-bit grey QVGA frame, aligned to the Cortex-M7's 32-byte cache line.
///
/// Stored as 32-bit words because the DCMI's DMA (embassy's `Dcmi::capture`) fills a
/// `&mut [u32]`; it packs four consecutive pixels into each word, first pixel in the lowest
/// byte, so on the little-endian Cortex-M7 the bytes are in pixel order.
#[repr(C, align(32))]
pub struct FrameBuffer([u32; FRAME_BYTES / 4]);

// Cache maintenance by address works on whole lines: keep the buffer a whole number of them.
const _: () = assert!(FRAME_BYTES.is_multiple_of(32));

impl FrameBuffer {
    /// A black frame (a `const fn`: usable as the initialiser of a static).
    pub const fn new() -> Self {
        FrameBuffer([0; FRAME_BYTES / 4])
    }

    /// The pixels, row by row (`WIDTH` x `HEIGHT` bytes).
    pub fn pixels(&self) -> &[u8] {
        bytemuck::cast_slice(&self.0)
    }

    /// The pixels, writable.
    pub fn pixels_mut(&mut self) -> &mut [u8] {
        bytemuck::cast_slice_mut(&mut self.0)
    }
}

/// A frame handed to the vision task.
pub struct Frame<'a> {
    /// The pixels.
    pub image: GrayImage<'a>,
    /// Frame counter since boot (wraps).
    pub sequence: u32,
    /// When the frame was captured (for the camera: start of exposure).
    pub captured: Instant,
}

/// Side of one marker cell in the test pattern, pixels.
const CELL_PX: usize = 8;
/// Grey levels of the test pattern.
const BACKGROUND: u8 = 170;
const WHITE: u8 = 220;
const BLACK: u8 = 35;
/// Frames per marker id (one second).
const FRAMES_PER_ID: u32 = 30;
/// Ids drawn in turn.
const IDS: u32 = 4;

/// The placeholder camera: renders a marker of `family` into the frame buffer at 30 fps.
pub struct TestPattern {
    buffer: &'static mut FrameBuffer,
    family: Option<&'static Family<'static>>,
    ticker: Ticker,
    sequence: u32,
}

impl TestPattern {
    /// A test pattern drawing markers of `family` (a flat grey frame when `None`).
    pub fn new(buffer: &'static mut FrameBuffer, family: Option<&'static Family<'static>>) -> Self {
        TestPattern {
            buffer,
            family,
            ticker: Ticker::every(FRAME_PERIOD),
            sequence: 0,
        }
    }

    /// Waits for the next frame period and returns the freshly drawn frame.
    pub async fn next_frame(&mut self) -> Result<Frame<'_>, ImageError> {
        self.ticker.next().await;
        let captured = Instant::now();
        let sequence = self.sequence;
        self.sequence = self.sequence.wrapping_add(1);
        render(self.buffer.pixels_mut(), self.family, sequence);
        Ok(Frame {
            image: GrayImage::new(self.buffer.pixels(), WIDTH, HEIGHT)?,
            sequence,
            captured,
        })
    }
}

/// Draws frame `sequence` of the test pattern into `pixels` (WIDTH x HEIGHT, packed).
fn render(pixels: &mut [u8], family: Option<&Family<'_>>, sequence: u32) {
    pixels.fill(BACKGROUND);
    let Some(family) = family else {
        return;
    };
    let grid = family.grid as usize;
    let side = grid * CELL_PX;
    if side == 0 || side > WIDTH || side > HEIGHT {
        return;
    }
    // Slide horizontally over the free width and back (a triangle wave, one pixel per frame).
    let travel = WIDTH - side;
    let x0 = if travel == 0 {
        0
    } else {
        let phase = (sequence as usize) % (2 * travel);
        if phase <= travel {
            phase
        } else {
            2 * travel - phase
        }
    };
    let y0 = (HEIGHT - side) / 2;
    let id = ((sequence / FRAMES_PER_ID) % IDS) as usize;

    for row in 0..grid {
        for col in 0..grid {
            // Unknown cells (an id past the family's end) are drawn white: no false marker.
            let level = match family.cell_is_white(id, row, col) {
                Some(false) => BLACK,
                Some(true) | None => WHITE,
            };
            let x = x0 + col * CELL_PX;
            for y in (y0 + row * CELL_PX)..(y0 + (row + 1) * CELL_PX) {
                if let Some(span) = pixels.get_mut(y * WIDTH + x..y * WIDTH + x + CELL_PX) {
                    span.fill(level);
                }
            }
        }
    }
}
