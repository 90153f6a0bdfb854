//! Frames from the board to a host viewer: the record the board writes and the command that
//! asks for it (the format is the contract's, `docs/interfaces.md`, "Frame stream").
//!
//! The stream shares the debug probe's RTT with the logs, so it is built for a byte pipe that
//! may be joined half-way and may stall: every record starts with a magic and a fixed
//! preamble that says how long it is, and ends with a checksum over all of it, so a reader
//! that joins mid-record (or loses bytes to a bug) skips to the next magic and loses one
//! frame, never decodes a wrong one. The checksum is Adler-32: the board computes it while it
//! sends, a few cycles a byte, where a table-less CRC-32 over a frame would cost milliseconds.
//!
//! A record is encoded in two parts so the board never copies a frame twice: [`encode_head`]
//! writes the preamble and the metadata (time, camera, detections, pad fix) into a small
//! buffer; the pixels follow as they are in the frame buffer; [`Adler32`] runs over both and
//! its value closes the record. The board streams only while a host keeps asking for it
//! ([`ViewRequest`], repeated at least every [`REQUEST_LIFETIME_US`]), so a viewer left
//! attached, or unplugged, cannot keep the board streaming through a flight.

use crate::camera::CameraModel;
use crate::detect::Detection;
use crate::family::Family;

/// First bytes of every frame record.
pub const MAGIC: [u8; 4] = *b"TDVF";
/// First bytes of every request from the host.
pub const REQUEST_MAGIC: [u8; 4] = *b"TDVR";
/// The record layout this module writes.
pub const VERSION: u8 = 1;
/// Magic, version, flags, metadata length, pixel count.
pub const PREAMBLE_LEN: usize = 12;
/// Most detections a record carries (the pad fix uses at most 40 of a frame's too).
pub const MAX_MARKERS: usize = 40;
/// Bytes per detection: family, hamming, id, four corners of two f32.
pub const MARKER_LEN: usize = 36;
/// Longest family list (names joined by `,`), bytes.
pub const MAX_FAMILIES_LEN: usize = 96;
/// Longest pad name, bytes.
pub const MAX_PAD_NAME_LEN: usize = 32;
/// Metadata bytes before the variable parts (see [`encode_head`]).
pub const META_FIXED_LEN: usize = 100;
/// Longest metadata.
pub const MAX_META_LEN: usize =
    META_FIXED_LEN + MAX_FAMILIES_LEN + 1 + MAX_PAD_NAME_LEN + MAX_MARKERS * MARKER_LEN;
/// Longest head ([`encode_head`]'s output).
pub const MAX_HEAD_LEN: usize = PREAMBLE_LEN + MAX_META_LEN;
/// Largest frame a record carries, pixels (VGA).
pub const MAX_PIXELS: usize = 640 * 480;
/// Checksum bytes that close a record.
pub const TRAILER_LEN: usize = 4;
/// A request keeps the stream on for this long, µs.
pub const REQUEST_LIFETIME_US: u64 = 3_000_000;
/// Bytes of a request.
pub const REQUEST_LEN: usize = 8;

/// Flag bit: the record carries a pad fix.
const FLAG_FIX: u8 = 1;

/// Why a record could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamError {
    /// The output buffer is shorter than [`MAX_HEAD_LEN`].
    BufferTooSmall,
    /// Width times height is zero or over [`MAX_PIXELS`].
    BadFrameSize,
}

/// The pad fix a record carries: where the camera is over the pad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamedFix {
    /// The camera centre in the pad frame, metres.
    pub camera_position: [f32; 3],
    /// Layout markers whose corners the fix used.
    pub markers_used: u8,
    /// RMS reprojection error of the fix, pixels.
    pub reprojection_rms_px: f32,
}

/// What a record says besides its pixels.
#[derive(Debug, Clone, Copy)]
pub struct FrameMeta<'a> {
    /// The board's frame counter.
    pub index: u32,
    /// The frame's time (middle row at mid-exposure), board µs.
    pub t_us: u64,
    /// Width of the pixels sent.
    pub width: u16,
    /// Height of the pixels sent.
    pub height: u16,
    /// Sensor pixels per sent pixel along each axis (1: full resolution, 2: halved).
    pub scale: u8,
    /// The exposure, µs.
    pub exposure_us: u32,
    /// The sensor's gain, 1/16 steps (16 = x1).
    pub gain_x16: u16,
    /// Time the per-frame path took, µs.
    pub process_us: u32,
    /// The camera model the board solves with (at full resolution).
    pub camera: &'a CameraModel,
    /// Families searched, in the order [`Detection::family`] indexes them.
    pub families: &'a [&'a Family<'a>],
    /// The pad's name (a shipped design's).
    pub pad_name: &'a str,
    /// The pad's size against its built size (TD_TAG_SIZE's scale).
    pub pad_scale: f32,
    /// The markers decoded (at most [`MAX_MARKERS`] are sent), full-resolution pixels.
    pub detections: &'a [Detection],
    /// The pad fix, if the frame gave one.
    pub fix: Option<StreamedFix>,
}

/// Adler-32 (RFC 1950), updated chunk by chunk.
#[derive(Debug, Clone, Copy)]
pub struct Adler32 {
    a: u32,
    b: u32,
}

impl Default for Adler32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Adler32 {
    /// Largest run that cannot overflow `b` before the modulo (RFC 1950's NMAX).
    const NMAX: usize = 5552;
    const MOD: u32 = 65_521;

    /// The checksum of nothing.
    pub const fn new() -> Self {
        Adler32 { a: 1, b: 0 }
    }

    /// Adds `bytes`.
    pub fn update(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(Self::NMAX) {
            for &byte in chunk {
                self.a += u32::from(byte);
                self.b += self.a;
            }
            self.a %= Self::MOD;
            self.b %= Self::MOD;
        }
    }

    /// The checksum so far.
    pub fn value(&self) -> u32 {
        (self.b << 16) | self.a
    }
}

/// A little-endian writer over a slice that remembers whether it ran out.
struct Writer<'a> {
    out: &'a mut [u8],
    at: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, bytes: &[u8]) {
        if let Some(slot) = self.out.get_mut(self.at..self.at + bytes.len()) {
            slot.copy_from_slice(bytes);
        }
        self.at += bytes.len();
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
}

/// Writes the longest prefix of `text` that fits in `max` bytes and ends on a character
/// boundary, preceded by its length.
fn short_text(w: &mut Writer<'_>, text: &str, max: usize) {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    let bytes = text.as_bytes().get(..end).unwrap_or_default();
    w.u8(bytes.len() as u8);
    w.bytes(bytes);
}

/// Writes a record's preamble and metadata into `out` and returns their length; the record
/// goes on with `width * height` pixels, row by row, and ends with the [`Adler32`] of the
/// head and the pixels, little-endian. Families past [`MAX_FAMILIES_LEN`] bytes and
/// detections past [`MAX_MARKERS`] are left out (the record says how many it holds).
pub fn encode_head(meta: &FrameMeta<'_>, out: &mut [u8]) -> Result<usize, StreamError> {
    if out.len() < MAX_HEAD_LEN {
        return Err(StreamError::BufferTooSmall);
    }
    let pixels = usize::from(meta.width) * usize::from(meta.height);
    if pixels == 0 || pixels > MAX_PIXELS {
        return Err(StreamError::BadFrameSize);
    }
    let mut w = Writer { out, at: 0 };
    w.bytes(&MAGIC);
    w.u8(VERSION);
    w.u8(if meta.fix.is_some() { FLAG_FIX } else { 0 });
    w.u16(0); // metadata length, filled in below
    w.u32(pixels as u32);

    w.u32(meta.index);
    w.bytes(&meta.t_us.to_le_bytes());
    w.u16(meta.width);
    w.u16(meta.height);
    w.u8(meta.scale);
    w.u8(0);
    w.u16(meta.gain_x16);
    w.u32(meta.exposure_us);
    w.u32(meta.process_us);
    let c = meta.camera;
    w.u16(c.width.min(u32::from(u16::MAX)) as u16);
    w.u16(c.height.min(u32::from(u16::MAX)) as u16);
    for v in [c.fx, c.fy, c.cx, c.cy] {
        w.f32(v);
    }
    for v in c.distortion {
        w.f32(v);
    }
    w.f32(c.line_time_us);
    w.f32(meta.pad_scale);
    let fix = meta.fix.unwrap_or(StreamedFix {
        camera_position: [0.0; 3],
        markers_used: 0,
        reprojection_rms_px: 0.0,
    });
    for v in fix.camera_position {
        w.f32(v);
    }
    w.f32(fix.reprojection_rms_px);
    w.u8(fix.markers_used);
    let markers = meta.detections.len().min(MAX_MARKERS);
    w.u8(markers as u8);
    w.u16(0);
    // The variable parts: families, pad name, detections.
    let mut families_len = 0usize;
    let mut families_count = 0u8;
    for family in meta.families {
        let extra = family.name.len() + usize::from(families_len > 0);
        if families_len + extra > MAX_FAMILIES_LEN {
            break;
        }
        families_len += extra;
        families_count += 1;
    }
    w.u8(families_count);
    w.u8(families_len as u8);
    w.u16(0);
    for (i, family) in meta
        .families
        .iter()
        .take(usize::from(families_count))
        .enumerate()
    {
        if i > 0 {
            w.u8(b',');
        }
        w.bytes(family.name.as_bytes());
    }
    short_text(&mut w, meta.pad_name, MAX_PAD_NAME_LEN);
    for d in meta.detections.iter().take(markers) {
        w.u8(d.family);
        w.u8(d.hamming);
        w.u16(d.id);
        for corner in d.corners {
            w.f32(corner.x);
            w.f32(corner.y);
        }
    }
    let len = w.at;
    let meta_len = (len - PREAMBLE_LEN) as u16;
    if let Some(slot) = w.out.get_mut(6..8) {
        slot.copy_from_slice(&meta_len.to_le_bytes());
    }
    Ok(len)
}

/// What the host asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ViewRequest {
    /// Send every this many frames (at least 1).
    pub every: u8,
    /// Sensor pixels per sent pixel (1 or 2: halved by averaging 2x2).
    pub scale: u8,
}

impl ViewRequest {
    /// The request's bytes: magic, every, scale, and an X.25 checksum over them.
    pub fn encode(&self) -> [u8; REQUEST_LEN] {
        let mut out = [0u8; REQUEST_LEN];
        out[..4].copy_from_slice(&REQUEST_MAGIC);
        out[4] = self.every;
        out[5] = self.scale;
        let crc = crate::crc::crc16_x25(0xFFFF, &out[..6]);
        out[6..].copy_from_slice(&crc.to_le_bytes());
        out
    }
}

/// Finds requests in what the host sent, a few bytes at a time (sans-IO: the board feeds it
/// whatever its down channel held).
#[derive(Debug, Default)]
pub struct RequestParser {
    buf: [u8; REQUEST_LEN],
    len: usize,
}

impl RequestParser {
    /// An empty parser.
    pub const fn new() -> Self {
        RequestParser {
            buf: [0; REQUEST_LEN],
            len: 0,
        }
    }

    /// Feeds `bytes`; returns the last valid request among them. Garbage is skipped a byte at
    /// a time; a request with a bad checksum, or asking for nothing sensible, is dropped.
    pub fn push(&mut self, bytes: &[u8]) -> Option<ViewRequest> {
        let mut found = None;
        for &byte in bytes {
            if let Some(&want) = REQUEST_MAGIC.get(self.len) {
                if byte != want {
                    // Restart, possibly at this byte.
                    self.len = usize::from(byte == REQUEST_MAGIC[0]);
                    self.buf[0] = byte;
                    continue;
                }
            }
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = byte;
            }
            self.len += 1;
            if self.len >= REQUEST_LEN {
                self.len = 0;
                let [m0, m1, m2, m3, every, scale, c0, c1] = self.buf;
                let crc = crate::crc::crc16_x25(0xFFFF, &[m0, m1, m2, m3, every, scale]);
                let request = ViewRequest { every, scale };
                if crc.to_le_bytes() == [c0, c1] && every >= 1 && matches!(scale, 1 | 2) {
                    found = Some(request);
                }
            }
        }
        found
    }
}

/// Whether the stream is on, from the requests and the time (the board's side).
#[derive(Debug, Clone, Copy, Default)]
pub struct StreamSwitch {
    request: Option<(ViewRequest, u64)>,
    frames: u32,
}

impl StreamSwitch {
    /// Off.
    pub const fn new() -> Self {
        StreamSwitch {
            request: None,
            frames: 0,
        }
    }

    /// Takes a request received at `now_us`.
    pub fn requested(&mut self, request: ViewRequest, now_us: u64) {
        self.request = Some((request, now_us));
    }

    /// Whether the frame at `now_us` is to be sent, and at which scale (each frame asks once).
    pub fn take(&mut self, now_us: u64) -> Option<u8> {
        let (request, at) = self.request?;
        if now_us.saturating_sub(at) > REQUEST_LIFETIME_US {
            self.request = None;
            self.frames = 0;
            return None;
        }
        self.frames = self.frames.wrapping_add(1);
        self.frames
            .is_multiple_of(u32::from(request.every.max(1)))
            .then_some(request.scale)
    }

    /// Whether a host asked within the lifetime (as of the last [`StreamSwitch::take`]).
    pub fn is_on(&self) -> bool {
        self.request.is_some()
    }
}

/// Halves a `width x height` frame into `out` by averaging each 2x2 block (an odd last row or
/// column is dropped); returns the halved size, or `None` when `out` is too small or the
/// sizes do not match `pixels`.
pub fn halve(pixels: &[u8], width: usize, height: usize, out: &mut [u8]) -> Option<(usize, usize)> {
    let (w2, h2) = (width / 2, height / 2);
    let whole = width.checked_mul(height)?;
    if w2 == 0 || h2 == 0 || pixels.len() < whole || out.len() < w2 * h2 {
        return None;
    }
    let mut rows = pixels.chunks_exact(width.max(2));
    for out_row in out.chunks_exact_mut(w2).take(h2) {
        let (Some(top), Some(bottom)) = (rows.next(), rows.next()) else {
            break;
        };
        let blocks = top.chunks_exact(2).zip(bottom.chunks_exact(2));
        for (o, (t, b)) in out_row.iter_mut().zip(blocks) {
            let sum: u16 = t.iter().chain(b).map(|&p| u16::from(p)).sum();
            *o = ((sum + 2) / 4) as u8;
        }
    }
    Some((w2, h2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::family::tables;
    use crate::geometry::Point;

    fn camera() -> CameraModel {
        CameraModel::pinhole(320, 240, 233.5, 233.5, 159.5, 119.5)
    }

    #[test]
    fn adler32_check_value() {
        let mut a = Adler32::new();
        a.update(b"Wikipedia");
        assert_eq!(a.value(), 0x11E6_0398);
        // Chunked the same as whole, across the NMAX boundary.
        let data: [u8; 12_000] = core::array::from_fn(|i| (i * 7 + 3) as u8);
        let mut whole = Adler32::new();
        whole.update(&data);
        let mut parts = Adler32::new();
        for chunk in data.chunks(1000) {
            parts.update(chunk);
        }
        assert_eq!(whole.value(), parts.value());
    }

    #[test]
    fn head_layout() {
        let detections = [Detection {
            family: 0,
            id: 7,
            hamming: 1,
            corners: [
                Point::new(1.0, 2.0),
                Point::new(3.0, 2.0),
                Point::new(3.0, 4.0),
                Point::new(1.0, 4.0),
            ],
            center: Point::new(2.0, 3.0),
            decision_margin: 1.0,
            contrast: 100.0,
        }];
        let cam = camera();
        let meta = FrameMeta {
            index: 5,
            t_us: 123,
            width: 320,
            height: 240,
            scale: 1,
            exposure_us: 1000,
            gain_x16: 16,
            process_us: 9000,
            camera: &cam,
            families: &[&tables::TAG36H11, &tables::ARUCO_4X4_50],
            pad_name: "nested-field",
            pad_scale: 1.0,
            detections: &detections,
            fix: None,
        };
        let mut out = [0u8; MAX_HEAD_LEN];
        let len = encode_head(&meta, &mut out).unwrap();
        assert_eq!(&out[..4], b"TDVF");
        let meta_len = u16::from_le_bytes([out[6], out[7]]) as usize;
        assert_eq!(PREAMBLE_LEN + meta_len, len);
        let families = "tag36h11,aruco_4x4_50".len();
        assert_eq!(
            len,
            PREAMBLE_LEN + META_FIXED_LEN + families + 1 + "nested-field".len() + MARKER_LEN
        );
        assert_eq!(
            u32::from_le_bytes(out[8..12].try_into().unwrap()),
            320 * 240
        );
        let mut small = [0u8; 16];
        assert_eq!(
            encode_head(&meta, &mut small),
            Err(StreamError::BufferTooSmall)
        );
        let empty = FrameMeta { width: 0, ..meta };
        assert_eq!(
            encode_head(&empty, &mut out),
            Err(StreamError::BadFrameSize)
        );
    }

    #[test]
    fn requests_survive_garbage_and_expire() {
        let request = ViewRequest { every: 2, scale: 1 };
        let mut parser = RequestParser::new();
        let mut bytes = [0u8; 3 + REQUEST_LEN];
        bytes[..3].copy_from_slice(b"TDx");
        bytes[3..].copy_from_slice(&request.encode());
        // Fed one byte at a time too.
        let mut found = None;
        for b in bytes {
            found = parser.push(&[b]).or(found);
        }
        assert_eq!(found, Some(request));
        let mut corrupt = request.encode();
        corrupt[5] ^= 1;
        assert_eq!(parser.push(&corrupt), None);

        let mut switch = StreamSwitch::new();
        assert_eq!(switch.take(0), None);
        switch.requested(request, 1_000);
        assert_eq!(switch.take(2_000), None);
        assert_eq!(switch.take(3_000), Some(1));
        assert_eq!(switch.take(1_000 + REQUEST_LIFETIME_US + 1), None);
        assert!(!switch.is_on());
    }

    #[test]
    fn halving_averages_blocks() {
        let pixels: [u8; 10] = [0, 4, 8, 12, 100, 101, 102, 103, 255, 255];
        let mut out = [0u8; 2];
        // 5 x 2: the odd column is dropped.
        assert_eq!(halve(&pixels, 5, 2, &mut out), Some((2, 1)));
        assert_eq!(
            out,
            [
                (4 + 101 + 102 + 2) / 4,
                ((8 + 12 + 103 + 255 + 2) / 4) as u8
            ]
        );
        assert_eq!(halve(&pixels, 5, 3, &mut out), None);
        assert_eq!(halve(&pixels, 1, 10, &mut out), None);
        assert_eq!(halve(&pixels, 0, 0, &mut out), None);
    }
}
