//! The receive side of the link: a MAVLink 1/2 frame parser over a byte stream.
//!
//! A UART gives bytes, not frames: a frame may arrive in pieces, line noise inserts garbage,
//! a byte may be lost (a truncated frame), and a flipped bit breaks a checksum. The parser
//! owns one fixed buffer of [`MAX_FRAME_LEN`] bytes (the longest MAVLink 2 frame, signature
//! included) and works like this:
//!
//! 1. Drop bytes until a start marker (`0xFD` MAVLink 2, `0xFE` MAVLink 1); they are counted
//!    as garbage.
//! 2. Wait until the whole frame the header announces is buffered.
//! 3. Check the CRC (X.25 over the header and payload plus the message's CRC_EXTRA). A valid
//!    frame is handed out and consumed.
//! 4. A bad CRC consumes **only the start byte**: the "frame" may have been garbage that
//!    happened to contain a start marker, with a real frame starting inside it, so the rest
//!    is scanned again. This is what makes the parser resynchronise after a truncated frame:
//!    the truncated frame swallows the beginning of the next one, fails its CRC, and the next
//!    frame after it is found intact.
//!
//! A message id the common dialect does not know has no CRC_EXTRA, so its CRC cannot be
//! checked, and its announced length cannot be trusted either: random garbage starting with
//! `0xFD` almost always carries an unknown id, and skipping its whole "length" would swallow
//! the real frames behind it. So only its start byte is skipped, as for garbage (counted in
//! [`ParserStats::unknown`]). A real frame of another dialect (ArduPilot's own messages) is
//! then scanned byte by byte: it costs a little time and may show up in the bad-CRC count
//! when its payload contains a start marker, but a frame we know is never lost.
//!
//! Signed MAVLink 2 frames are accepted without checking the signature (the link is a wire
//! between two boards); frames with unknown incompatibility flags are dropped, as the
//! MAVLink 2 specification requires.

use crate::crc::crc16_x25;
use mavlink::dialects::common::MavMessage;
use mavlink::{MavlinkVersion, Message, MessageData};

/// Longest MAVLink frame: MAVLink 2 header (10) + payload (255) + CRC (2) + signature (13).
pub const MAX_FRAME_LEN: usize = 280;
/// MAVLink 2 start marker.
pub const STX_V2: u8 = 0xFD;
/// MAVLink 1 start marker.
pub const STX_V1: u8 = 0xFE;
/// MAVLink 2 header length, start marker included.
pub const V2_HEADER_LEN: usize = 10;
/// MAVLink 1 header length, start marker included.
pub const V1_HEADER_LEN: usize = 6;
/// MAVLink 2 incompatibility flag: the frame is signed (13 more bytes).
const IFLAG_SIGNED: u8 = 0x01;
/// Length of a MAVLink 2 signature.
const SIGNATURE_LEN: usize = 13;

/// Largest MAVLink payload.
const MAX_PAYLOAD_LEN: usize = 255;

/// Serialises one unsigned MAVLink 2 frame of `data` into the front of `out`: its length, or
/// `None` when `out` is shorter than the frame. The payload is trimmed of trailing zeros as
/// MAVLink 2 requires. Byte for byte what `MAVLinkV2MessageRaw::serialize_message_data`
/// produces for an 8-bit system id, but with every length visible to the optimiser: the
/// mavlink crate's header and checksum slicing keeps panic paths in the firmware, and the
/// no-panic link check (nopanic/) needs none.
pub fn write_v2_frame<D: MessageData>(
    out: &mut [u8],
    sequence: u8,
    system_id: u8,
    component_id: u8,
    data: &D,
) -> Option<usize> {
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let len = data
        .ser(MavlinkVersion::V2, &mut payload)
        .min(MAX_PAYLOAD_LEN);
    let id = D::ID.to_le_bytes();
    let header: [u8; V2_HEADER_LEN] = [
        STX_V2,
        len as u8,
        0, // incompatibility flags: unsigned, 8-bit system id
        0, // compatibility flags
        sequence,
        system_id,
        component_id,
        id[0],
        id[1],
        id[2],
    ];
    let frame = out.get_mut(..V2_HEADER_LEN + len + 2)?;
    let (head, rest) = frame.split_at_mut(V2_HEADER_LEN);
    let (body, checksum) = rest.split_at_mut(len);
    head.copy_from_slice(&header);
    body.copy_from_slice(payload.get(..len)?);
    let (_, covered) = header.split_at(1); // the checksum skips the start byte
    let crc = crc16_x25(crc16_x25(0xFFFF, covered), body);
    let crc = crc16_x25(crc, &[D::EXTRA_CRC]);
    checksum.copy_from_slice(&crc.to_le_bytes());
    Some(V2_HEADER_LEN + len + 2)
}

/// One checked frame, borrowed from the parser's buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawFrame<'a> {
    /// MAVLink 1 or 2.
    pub version: MavlinkVersion,
    /// Sequence number.
    pub sequence: u8,
    /// Sender system id.
    pub system_id: u8,
    /// Sender component id.
    pub component_id: u8,
    /// Message id.
    pub message_id: u32,
    /// Payload as sent (MAVLink 2 trims trailing zeros; decoding pads them back).
    pub payload: &'a [u8],
}

impl RawFrame<'_> {
    /// Decodes the payload with the common dialect.
    pub fn decode(&self) -> Result<MavMessage, mavlink::error::ParserError> {
        MavMessage::parse(self.version, self.message_id, self.payload)
    }
}

/// Counters of the parser (saturating).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ParserStats {
    /// Bytes fed in.
    pub bytes: u64,
    /// Frames with a valid CRC handed out.
    pub frames: u32,
    /// Candidate frames whose CRC did not match (corrupted or garbage).
    pub bad_crc: u32,
    /// Bytes dropped while looking for a start marker.
    pub garbage_bytes: u32,
    /// Frames of message ids the common dialect does not know (skipped).
    pub unknown: u32,
}

/// What the header at the start of the buffer says.
enum Candidate {
    /// Need more bytes.
    Incomplete,
    /// Not a frame: drop the start byte.
    Invalid,
    /// A complete frame of `len` bytes.
    Complete { len: usize },
}

/// The incremental frame parser (see the module documentation).
#[derive(Clone)]
pub struct FrameParser {
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
    stats: ParserStats,
}

impl Default for FrameParser {
    fn default() -> Self {
        Self::new()
    }
}

impl core::fmt::Debug for FrameParser {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FrameParser")
            .field("buffered", &self.len)
            .field("stats", &self.stats)
            .finish()
    }
}

impl FrameParser {
    /// An empty parser.
    pub const fn new() -> Self {
        FrameParser {
            buf: [0; MAX_FRAME_LEN],
            len: 0,
            stats: ParserStats {
                bytes: 0,
                frames: 0,
                bad_crc: 0,
                garbage_bytes: 0,
                unknown: 0,
            },
        }
    }

    /// The counters.
    pub fn stats(&self) -> ParserStats {
        self.stats
    }

    /// Bytes buffered (an incomplete frame).
    pub fn buffered(&self) -> usize {
        self.len
    }

    /// Forgets any partial frame.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Feeds bytes; calls `on_frame` for every complete frame with a valid CRC, in order.
    pub fn push(&mut self, mut bytes: &[u8], mut on_frame: impl FnMut(&RawFrame<'_>)) {
        self.stats.bytes = self.stats.bytes.saturating_add(bytes.len() as u64);
        loop {
            let space = MAX_FRAME_LEN.saturating_sub(self.len);
            let take = space.min(bytes.len());
            let (head, rest) = bytes.split_at(take);
            if let Some(dst) = self.buf.get_mut(self.len..self.len + take) {
                dst.copy_from_slice(head);
                self.len += take;
            }
            bytes = rest;
            self.process(&mut on_frame);
            // `process` leaves at most an incomplete frame, shorter than the buffer, so every
            // round makes room for at least one more byte.
            if bytes.is_empty() {
                break;
            }
        }
    }

    fn consume(&mut self, n: usize) {
        // `len` never exceeds the buffer; saying so lets the optimiser drop copy_within's
        // range check (the no-panic link check, nopanic/, needs every panic path gone).
        let len = self.len.min(self.buf.len());
        let n = n.min(len);
        self.buf.copy_within(n..len, 0);
        self.len = len - n;
    }

    fn byte(&self, i: usize) -> Option<u8> {
        self.buf.get(..self.len).and_then(|b| b.get(i)).copied()
    }

    fn candidate(&self) -> Candidate {
        let (Some(stx), Some(payload_len)) = (self.byte(0), self.byte(1)) else {
            return Candidate::Incomplete;
        };
        let payload_len = usize::from(payload_len);
        let len = match stx {
            STX_V2 => {
                let Some(incompat) = self.byte(2) else {
                    return Candidate::Incomplete;
                };
                if incompat & !IFLAG_SIGNED != 0 {
                    return Candidate::Invalid;
                }
                let signature = if incompat & IFLAG_SIGNED != 0 {
                    SIGNATURE_LEN
                } else {
                    0
                };
                V2_HEADER_LEN + payload_len + 2 + signature
            }
            STX_V1 => V1_HEADER_LEN + payload_len + 2,
            _ => return Candidate::Invalid,
        };
        if self.len < len {
            Candidate::Incomplete
        } else {
            Candidate::Complete { len }
        }
    }

    fn process(&mut self, on_frame: &mut impl FnMut(&RawFrame<'_>)) {
        loop {
            let buffered = self.buf.get(..self.len).unwrap_or(&[]);
            match buffered.iter().position(|&b| b == STX_V2 || b == STX_V1) {
                None => {
                    self.stats.garbage_bytes =
                        self.stats.garbage_bytes.saturating_add(self.len as u32);
                    self.len = 0;
                    return;
                }
                Some(0) => {}
                Some(skip) => {
                    self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(skip as u32);
                    self.consume(skip);
                }
            }
            match self.candidate() {
                Candidate::Incomplete => return,
                Candidate::Invalid => {
                    self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(1);
                    self.consume(1);
                }
                Candidate::Complete { len } => match self.check(len) {
                    Check::Valid => {
                        self.stats.frames = self.stats.frames.saturating_add(1);
                        if let Some(frame) = self.frame() {
                            on_frame(&frame);
                        }
                        self.consume(len);
                    }
                    Check::BadCrc => {
                        self.stats.bad_crc = self.stats.bad_crc.saturating_add(1);
                        self.consume(1);
                    }
                    Check::Unknown => {
                        // Cannot be checked: treated like garbage (see the module docs).
                        self.stats.unknown = self.stats.unknown.saturating_add(1);
                        self.consume(1);
                    }
                },
            }
        }
    }

    /// Header fields of the buffered frame: (version, header length, message id).
    fn header(&self) -> Option<(MavlinkVersion, usize, u32)> {
        match self.byte(0)? {
            STX_V2 => {
                let id = u32::from_le_bytes([self.byte(7)?, self.byte(8)?, self.byte(9)?, 0]);
                Some((MavlinkVersion::V2, V2_HEADER_LEN, id))
            }
            STX_V1 => Some((MavlinkVersion::V1, V1_HEADER_LEN, u32::from(self.byte(5)?))),
            _ => None,
        }
    }

    fn check(&self, _len: usize) -> Check {
        let Some((_, header_len, id)) = self.header() else {
            return Check::BadCrc;
        };
        let extra = MavMessage::extra_crc(id);
        if extra == 0 {
            return Check::Unknown;
        }
        let payload_len = usize::from(self.byte(1).unwrap_or(0));
        let end = header_len + payload_len;
        let (Some(covered), Some(lo), Some(hi)) =
            (self.buf.get(1..end), self.byte(end), self.byte(end + 1))
        else {
            return Check::BadCrc;
        };
        let crc = crc16_x25(crc16_x25(0xFFFF, covered), &[extra]);
        if crc == u16::from_le_bytes([lo, hi]) {
            Check::Valid
        } else {
            Check::BadCrc
        }
    }

    fn frame(&self) -> Option<RawFrame<'_>> {
        let (version, header_len, message_id) = self.header()?;
        let payload_len = usize::from(self.byte(1)?);
        let (sequence, system_id, component_id) = match version {
            MavlinkVersion::V2 => (self.byte(4)?, self.byte(5)?, self.byte(6)?),
            MavlinkVersion::V1 => (self.byte(2)?, self.byte(3)?, self.byte(4)?),
        };
        Some(RawFrame {
            version,
            sequence,
            system_id,
            component_id,
            message_id,
            payload: self.buf.get(header_len..header_len + payload_len)?,
        })
    }
}

enum Check {
    Valid,
    BadCrc,
    Unknown,
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::HEARTBEAT_DATA;
    use mavlink::{MAVLinkV2MessageRaw, MavHeader};

    fn heartbeat_bytes(seq: u8) -> ([u8; MAX_FRAME_LEN], usize) {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: seq,
            },
            &MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()),
        );
        let bytes = raw.raw_bytes();
        let mut out = [0u8; MAX_FRAME_LEN];
        out[..bytes.len()].copy_from_slice(bytes);
        (out, bytes.len())
    }

    #[test]
    fn byte_by_byte_with_garbage_and_corruption() {
        let mut p = FrameParser::new();
        let mut seen = 0;
        let (a, n) = heartbeat_bytes(1);
        let mut stream = [0u8; 2048];
        let mut len = 0;
        let mut put = |s: &[u8], len: &mut usize| {
            stream[*len..*len + s.len()].copy_from_slice(s);
            *len += s.len();
        };
        put(&[0x00, 0xFD, 0x13, 0xFE, 0x42], &mut len);
        put(&a[..n], &mut len);
        let mut bad = a;
        bad[12] ^= 0x40;
        put(&bad[..n], &mut len);
        put(&a[..n - 4], &mut len); // truncated
        put(&a[..n], &mut len);
        put(&a[..n], &mut len);
        for b in &stream[..len] {
            p.push(core::slice::from_ref(b), |f| {
                assert_eq!(f.message_id, 0);
                seen += 1;
            });
        }
        // Garbage "0xFD 0x13" may swallow bytes until its CRC fails; everything valid is found.
        assert_eq!(seen, 3, "{:?}", p.stats());
        assert!(p.stats().bad_crc >= 2);
    }

    /// `write_v2_frame` is byte-identical to the mavlink crate's own serialiser.
    #[test]
    fn write_v2_frame_matches_the_mavlink_crate() {
        use mavlink::dialects::common::{LANDING_TARGET_DATA, PARAM_VALUE_DATA};
        fn check<D: MessageData>(data: &D, sequence: u8) {
            let mut raw = MAVLinkV2MessageRaw::new();
            let header = MavHeader {
                system_id: 42,
                component_id: 191,
                sequence,
            };
            raw.serialize_message_data(header, data);
            let mut out = [0u8; MAX_FRAME_LEN];
            let n = write_v2_frame(&mut out, sequence, 42, 191, data).unwrap();
            assert_eq!(&out[..n], raw.raw_bytes());
            assert_eq!(
                write_v2_frame(&mut out[..n - 1], sequence, 42, 191, data),
                None
            );
        }
        check(&HEARTBEAT_DATA::DEFAULT, 0);
        check(
            &LANDING_TARGET_DATA {
                time_usec: 123_456_789,
                angle_x: 0.25,
                distance: 7.5,
                x: -1.0,
                q: [1.0, 0.0, 0.0, 0.0],
                ..LANDING_TARGET_DATA::DEFAULT
            },
            200,
        );
        check(
            &PARAM_VALUE_DATA {
                param_value: 3.5,
                param_count: 10,
                param_index: 2,
                param_id: "TD_TAG_SIZE".into(),
                ..PARAM_VALUE_DATA::DEFAULT
            },
            255,
        );
    }
}
