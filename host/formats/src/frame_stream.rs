//! The board's frame stream, read: records of `touchdown_core::frame_stream` found in a byte
//! stream that may start mid-record or lose bytes (the contract's "Frame stream").
//!
//! [`StreamReader`] is sans-IO: feed it whatever the transport gave, take the whole records
//! out. Anything that is not a record with a good checksum is skipped a byte at a time and
//! counted, so a viewer that attaches half-way shows the next whole frame and says how many
//! bytes it could not use.

use touchdown_core::camera::{resampled_coordinate, CameraModel};
use touchdown_core::frame_stream::{
    encode_head, Adler32, FrameMeta, StreamError, MAGIC, MAX_HEAD_LEN, MAX_META_LEN, MAX_PIXELS,
    META_FIXED_LEN, PREAMBLE_LEN, TRAILER_LEN, VERSION,
};

pub use touchdown_core::frame_stream::StreamedFix;

/// A whole record as the board writes it (head, `pixels`, checksum): for tools and tests that
/// stand in for a board. `pixels` must be `meta.width * meta.height` bytes.
pub fn encode_record(meta: &FrameMeta<'_>, pixels: &[u8]) -> Result<Vec<u8>, StreamError> {
    if pixels.len() != usize::from(meta.width) * usize::from(meta.height) {
        return Err(StreamError::BadFrameSize);
    }
    let mut head = [0u8; MAX_HEAD_LEN];
    let len = encode_head(meta, &mut head)?;
    let mut sum = Adler32::new();
    sum.update(&head[..len]);
    sum.update(pixels);
    let mut out = head[..len].to_vec();
    out.extend_from_slice(pixels);
    out.extend_from_slice(&sum.value().to_le_bytes());
    Ok(out)
}

/// One detection as the board sent it (full-resolution pixels).
#[derive(Debug, Clone, PartialEq)]
pub struct StreamedMarker {
    /// The family's name (from the record's family list; `?` if it is not in the list).
    pub family: String,
    /// The marker's id.
    pub id: u16,
    /// Bits corrected.
    pub hamming: u8,
    /// Outer corners, the detector's order, pixels.
    pub corners: [[f32; 2]; 4],
}

/// One frame record.
#[derive(Debug, Clone)]
pub struct StreamedFrame {
    /// The board's frame counter.
    pub index: u32,
    /// The frame's time, board µs.
    pub t_us: u64,
    /// Width of [`StreamedFrame::pixels`].
    pub width: usize,
    /// Height of [`StreamedFrame::pixels`].
    pub height: usize,
    /// Sensor pixels per sent pixel along each axis.
    pub scale: u8,
    /// The exposure, µs.
    pub exposure_us: u32,
    /// The sensor gain, 1/16 steps.
    pub gain_x16: u16,
    /// The per-frame path's time, µs.
    pub process_us: u32,
    /// The camera model the board solves with (full resolution).
    pub camera: CameraModel,
    /// Families the board searches.
    pub families: Vec<String>,
    /// The board's pad (a shipped design's name).
    pub pad_name: String,
    /// The pad's size against its built size.
    pub pad_scale: f32,
    /// The markers the board decoded.
    pub markers: Vec<StreamedMarker>,
    /// The board's pad fix.
    pub fix: Option<StreamedFix>,
    /// Grey pixels, row by row.
    pub pixels: Vec<u8>,
}

impl StreamedFrame {
    /// Sent pixels per board pixel (1, or 0.5 for halved frames).
    fn factor(&self) -> f32 {
        1.0 / f32::from(self.scale.max(1))
    }

    /// The camera model of the pixels as sent: the board's, scaled down with them.
    pub fn sent_camera(&self) -> CameraModel {
        self.camera
            .resampled(self.factor(), self.width as u32, self.height as u32)
    }

    /// A marker's corners (the board's full-resolution pixels) in the pixels as sent.
    pub fn sent_corners(&self, marker: &StreamedMarker) -> [[f32; 2]; 4] {
        let f = self.factor();
        marker
            .corners
            .map(|[x, y]| [resampled_coordinate(x, f), resampled_coordinate(y, f)])
    }
}

/// Counts of what the reader could not use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StreamStats {
    /// Whole records decoded.
    pub records: u64,
    /// Records whose checksum did not match (skipped).
    pub bad_checksums: u64,
    /// Bytes skipped looking for a record's start (a join mid-record, garbage).
    pub skipped_bytes: u64,
}

/// Finds records in a byte stream (see the module docs).
#[derive(Debug, Default)]
pub struct StreamReader {
    buf: Vec<u8>,
    stats: StreamStats,
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let slice = self.bytes.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(slice)
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.take(1)?[0])
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes(self.take(2)?.try_into().ok()?))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn text(&mut self, n: usize) -> Option<String> {
        Some(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
}

impl StreamReader {
    /// An empty reader.
    pub fn new() -> Self {
        Self::default()
    }

    /// What could not be used so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Adds bytes from the transport.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next whole record, if the bytes so far hold one.
    pub fn next_frame(&mut self) -> Option<StreamedFrame> {
        loop {
            // Skip to a magic (keeping a partial one at the end).
            let start = self
                .buf
                .windows(MAGIC.len())
                .position(|w| w == MAGIC)
                .unwrap_or(self.buf.len().saturating_sub(MAGIC.len() - 1));
            if start > 0 {
                self.stats.skipped_bytes += start as u64;
                self.buf.drain(..start);
            }
            if self.buf.len() < PREAMBLE_LEN {
                return None;
            }
            let meta_len = usize::from(u16::from_le_bytes([self.buf[6], self.buf[7]]));
            let pixel_len =
                u32::from_le_bytes([self.buf[8], self.buf[9], self.buf[10], self.buf[11]]) as usize;
            if self.buf[4] != VERSION
                || !(META_FIXED_LEN..=MAX_META_LEN).contains(&meta_len)
                || pixel_len == 0
                || pixel_len > MAX_PIXELS
            {
                self.skip_one();
                continue;
            }
            let total = PREAMBLE_LEN + meta_len + pixel_len + TRAILER_LEN;
            if self.buf.len() < total {
                return None;
            }
            let body = &self.buf[..total - TRAILER_LEN];
            let mut sum = Adler32::new();
            sum.update(body);
            let stored = u32::from_le_bytes([
                self.buf[total - 4],
                self.buf[total - 3],
                self.buf[total - 2],
                self.buf[total - 1],
            ]);
            if sum.value() != stored {
                self.stats.bad_checksums += 1;
                self.skip_one();
                continue;
            }
            let frame = parse_record(&self.buf[..total - TRAILER_LEN], meta_len, pixel_len);
            match frame {
                Some(frame) => {
                    self.buf.drain(..total);
                    self.stats.records += 1;
                    return Some(frame);
                }
                None => {
                    // A checksum over nonsense: written by something else.
                    self.stats.bad_checksums += 1;
                    self.skip_one();
                }
            }
        }
    }

    fn skip_one(&mut self) {
        self.buf.drain(..1);
        self.stats.skipped_bytes += 1;
    }
}

fn parse_record(record: &[u8], meta_len: usize, pixel_len: usize) -> Option<StreamedFrame> {
    let flags = record[5];
    let mut c = Cursor {
        bytes: &record[..PREAMBLE_LEN + meta_len],
        at: PREAMBLE_LEN,
    };
    let index = c.u32()?;
    let t_us = c.u64()?;
    let width = usize::from(c.u16()?);
    let height = usize::from(c.u16()?);
    let scale = c.u8()?;
    c.u8()?;
    let gain_x16 = c.u16()?;
    let exposure_us = c.u32()?;
    let process_us = c.u32()?;
    let cam_w = u32::from(c.u16()?);
    let cam_h = u32::from(c.u16()?);
    let (fx, fy, cx, cy) = (c.f32()?, c.f32()?, c.f32()?, c.f32()?);
    let mut distortion = [0.0f32; 5];
    for d in &mut distortion {
        *d = c.f32()?;
    }
    let line_time_us = c.f32()?;
    let pad_scale = c.f32()?;
    let position = [c.f32()?, c.f32()?, c.f32()?];
    let rms = c.f32()?;
    let markers_used = c.u8()?;
    let marker_count = usize::from(c.u8()?);
    c.u16()?;
    let _family_count = c.u8()?;
    let families_len = usize::from(c.u8()?);
    c.u16()?;
    let families: Vec<String> = c
        .text(families_len)?
        .split(',')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect();
    let pad_len = usize::from(c.u8()?);
    let pad_name = c.text(pad_len)?;
    let mut markers = Vec::with_capacity(marker_count);
    for _ in 0..marker_count {
        let family = usize::from(c.u8()?);
        let hamming = c.u8()?;
        let id = c.u16()?;
        let mut corners = [[0.0f32; 2]; 4];
        for corner in &mut corners {
            *corner = [c.f32()?, c.f32()?];
        }
        markers.push(StreamedMarker {
            family: families
                .get(family)
                .cloned()
                .unwrap_or_else(|| "?".to_string()),
            id,
            hamming,
            corners,
        });
    }
    if c.at != PREAMBLE_LEN + meta_len || width * height != pixel_len || !(1..=2).contains(&scale) {
        return None;
    }
    let camera = CameraModel {
        width: cam_w,
        height: cam_h,
        fx,
        fy,
        cx,
        cy,
        distortion,
        line_time_us,
    };
    Some(StreamedFrame {
        index,
        t_us,
        width,
        height,
        scale,
        exposure_us,
        gain_x16,
        process_us,
        camera,
        families,
        pad_name,
        pad_scale,
        markers,
        fix: (flags & 1 != 0).then_some(StreamedFix {
            camera_position: position,
            markers_used,
            reprojection_rms_px: rms,
        }),
        pixels: record[PREAMBLE_LEN + meta_len..].to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_core::detect::Detection;
    use touchdown_core::family::tables;
    use touchdown_core::geometry::Point;

    /// A record as the board writes it: head, pixels, checksum.
    fn record(index: u32, pixels: &[u8], width: u16, height: u16) -> Vec<u8> {
        let camera = CameraModel::pinhole(640, 480, 500.0, 501.0, 320.0, 240.0);
        let detections = [Detection {
            family: 1,
            id: 3,
            hamming: 0,
            corners: [
                Point::new(10.0, 20.0),
                Point::new(30.5, 20.0),
                Point::new(30.0, 40.25),
                Point::new(10.0, 40.0),
            ],
            center: Point::new(20.0, 30.0),
            decision_margin: 1.0,
            contrast: 90.0,
        }];
        let meta = FrameMeta {
            index,
            t_us: 1_000_000 + u64::from(index),
            width,
            height,
            scale: 2,
            exposure_us: 4000,
            gain_x16: 32,
            process_us: 7000,
            camera: &camera,
            families: &[&tables::TAG36H11, &tables::ARUCO_4X4_50],
            pad_name: "nested-field",
            pad_scale: 0.5,
            detections: &detections,
            fix: Some(StreamedFix {
                camera_position: [0.1, -0.2, 3.0],
                markers_used: 4,
                reprojection_rms_px: 0.3,
            }),
        };
        encode_record(&meta, pixels).unwrap()
    }

    #[test]
    fn round_trip_through_garbage_and_a_cut_record() {
        let pixels: Vec<u8> = (0..12u8).collect();
        let first = record(1, &pixels, 4, 3);
        let second = record(2, &pixels, 4, 3);
        let mut stream = b"TDVFgarbage".to_vec();
        // A record joined half-way, then a corrupted one, then a whole one.
        stream.extend_from_slice(&first[first.len() / 2..]);
        let mut bad = first.clone();
        bad[PREAMBLE_LEN + 3] ^= 0x40;
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&second);
        let mut reader = StreamReader::new();
        let mut frames = Vec::new();
        for chunk in stream.chunks(7) {
            reader.push(chunk);
            while let Some(f) = reader.next_frame() {
                frames.push(f);
            }
        }
        assert_eq!(frames.len(), 1);
        let f = &frames[0];
        assert_eq!((f.index, f.width, f.height, f.scale), (2, 4, 3, 2));
        assert_eq!(f.pixels, pixels);
        assert_eq!(f.families, ["tag36h11", "aruco_4x4_50"]);
        assert_eq!(f.pad_name, "nested-field");
        assert_eq!(f.markers.len(), 1);
        assert_eq!(f.markers[0].family, "aruco_4x4_50");
        assert_eq!(f.markers[0].corners[2], [30.0, 40.25]);
        assert_eq!(f.fix.unwrap().markers_used, 4);
        assert_eq!(f.camera.fy, 501.0);
        assert_eq!(reader.stats().records, 1);
        assert_eq!(reader.stats().bad_checksums, 1);
        assert!(reader.stats().skipped_bytes > 0);
        // Halved: the sent camera's pixel centres.
        let sent = f.sent_camera();
        assert_eq!((sent.fx, sent.cx, sent.width), (250.0, 159.75, 4));
    }
}
