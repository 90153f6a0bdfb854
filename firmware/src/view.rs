//! The view task: frames out to a host viewer (`touchdown view`) over the debug probe's RTT.
//!
//! Off until a host asks: the host writes a request ([`touchdown_core::frame_stream`]) into
//! the RTT down channel and repeats it; the stream stops by itself a few seconds after the
//! last one, so a viewer left attached or unplugged cannot keep the board streaming through a
//! flight. While it is on, the vision task copies every n-th frame (full or halved) with its
//! detections into the one [`ViewFrame`] when this task has handed it back, and never waits
//! for it: a frame the viewer is still receiving costs the vision task nothing but the
//! skipped copy. This task then trickles the record into the RTT up channel as the probe
//! drains it, yielding between chunks, on the thread executor beside the vision task and
//! below the link's interrupt executor; so the flight path's frame rate and the link's
//! timing do not depend on whether a viewer is attached or how fast the probe reads.
//!
//! The record's head (time, camera, detections, pad fix) is encoded by the vision task,
//! which has them; the pixels are copied once, into [`ViewFrame::pixels`]; the checksum is
//! computed here, chunk by chunk, as the bytes go out.

use defmt::{info, warn};
use embassy_time::{Duration, Instant, Timer};
use rtt_target::{DownChannel, UpChannel};
use touchdown_core::frame_stream::{Adler32, RequestParser, MAX_HEAD_LEN};

use crate::channels::{self, VIEW_FREE, VIEW_READY};

/// Bytes of the RTT up channel for frames (DTCM: the probe reads it without the D-cache in the
/// way; the stack needs the rest of DTCM). A debugger that empties it every 10 ms can take
/// up to 800 KB/s; one that polls every 100 ms, one QVGA frame a second.
pub const RTT_BUFFER: usize = 8 * 1024;
/// Pixels the view buffer holds: a QVGA frame, or a halved VGA one.
pub const VIEW_PIXELS: usize = 320 * 240;
/// How often the down channel is read and a stalled up channel looked at again.
const POLL: Duration = Duration::from_millis(5);
/// A record that has made no progress for this long is abandoned (the viewer went away);
/// the reader skips the cut record and picks up the next.
const STALL_LIMIT: Duration = Duration::from_secs(1);
/// Largest piece written between yields.
const CHUNK: usize = 2048;

/// One record waiting to go out: the head the vision task encoded and the pixels it copied.
pub struct ViewFrame {
    /// Preamble and metadata.
    pub head: [u8; MAX_HEAD_LEN],
    /// Bytes of `head` in use.
    pub head_len: usize,
    /// The frame's pixels (full or halved), row by row.
    pub pixels: [u8; VIEW_PIXELS],
    /// Bytes of `pixels` in use.
    pub pixel_len: usize,
}

impl ViewFrame {
    /// An empty record (a `const fn`: the initialiser of a static).
    pub const fn new() -> Self {
        ViewFrame {
            head: [0; MAX_HEAD_LEN],
            head_len: 0,
            pixels: [0; VIEW_PIXELS],
            pixel_len: 0,
        }
    }
}

/// Writes `bytes` into the up channel as the probe drains it, adding them to `sum`; false when
/// the channel made no progress for [`STALL_LIMIT`] (the rest is dropped).
async fn send(up: &mut UpChannel, down: &mut Reader<'_>, bytes: &[u8], sum: &mut Adler32) -> bool {
    let mut rest = bytes;
    let mut progress_at = Instant::now();
    while !rest.is_empty() {
        let take = rest.len().min(CHUNK);
        let written = up.write(&rest[..take]).min(take);
        sum.update(&rest[..written]);
        rest = &rest[written..];
        if written > 0 {
            progress_at = Instant::now();
            embassy_futures::yield_now().await;
        } else if progress_at.elapsed() > STALL_LIMIT {
            return false;
        } else {
            down.poll();
            Timer::after(POLL).await;
        }
    }
    true
}

/// The down channel and its request parser.
struct Reader<'a> {
    down: &'a mut DownChannel,
    parser: RequestParser,
}

impl Reader<'_> {
    /// Reads what the host wrote and publishes the newest valid request for the vision task.
    fn poll(&mut self) {
        let mut buf = [0u8; 32];
        loop {
            let n = self.down.read(&mut buf);
            if n == 0 {
                break;
            }
            if let Some(request) = self.parser.push(&buf[..n.min(buf.len())]) {
                channels::request_view(request, Instant::now().as_micros());
            }
        }
    }
}

/// Serves the viewer forever: requests in, records out.
#[embassy_executor::task]
pub async fn task(mut up: UpChannel, mut down: DownChannel, frame: &'static mut ViewFrame) {
    let mut reader = Reader {
        down: &mut down,
        parser: RequestParser::new(),
    };
    // The buffer starts with the vision task.
    VIEW_FREE.signal(frame);
    let mut sent = 0u32;
    let mut abandoned = 0u32;
    loop {
        reader.poll();
        let Some(frame) = VIEW_READY.try_take() else {
            Timer::after(POLL).await;
            continue;
        };
        let mut sum = Adler32::new();
        let head_len = frame.head_len.min(MAX_HEAD_LEN);
        let pixel_len = frame.pixel_len.min(VIEW_PIXELS);
        let whole = send(&mut up, &mut reader, &frame.head[..head_len], &mut sum).await
            && send(&mut up, &mut reader, &frame.pixels[..pixel_len], &mut sum).await
            && send(
                &mut up,
                &mut reader,
                &sum.value().to_le_bytes(),
                &mut Adler32::new(),
            )
            .await;
        if whole {
            sent = sent.wrapping_add(1);
            if sent == 1 {
                info!("view: streaming frames to the probe");
            }
        } else {
            abandoned = abandoned.wrapping_add(1);
            warn!(
                "view: the probe stopped reading; record dropped ({} sent, {} dropped)",
                sent, abandoned
            );
        }
        VIEW_FREE.signal(frame);
    }
}
