//! The receive side of the link: a MAVLink 1/2 frame parser over a byte stream.
//!
//! A UART gives bytes, not frames: a frame may arrive in pieces, line noise inserts garbage,
//! a byte may be lost (a truncated frame), and a flipped bit breaks a checksum. The parser
//! owns one fixed buffer of [`MAX_FRAME_LEN`] + 1 bytes (the longest MAVLink 2 frame,
//! signature included, and the byte after it) and works like this:
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
//! A message id the common dialect does not know (ArduPilot's or PX4's own messages, which a
//! router forwards) has no CRC_EXTRA, so its CRC cannot be checked; only its framing can be.
//!
//! - MAVLink 2: when the byte right after its declared end (payload length, plus 13 when
//!   the signed flag is set) is a start marker, and the span holds no whole frame of a known
//!   id with a matching CRC, it is a frame of another dialect: counted once in
//!   [`ParserStats::unknown`] and skipped whole, its payload never scanned for start markers
//!   (scanning it would make one frame count twice, and stall the frames behind it while a
//!   false "frame" inside it waits for its length). The parser waits for that one byte: on a
//!   link it is the next frame's first, so no frame waits behind it meanwhile.
//! - Otherwise the declared length does not lead to a frame: garbage that began with `0xFD`
//!   and passed the incompatibility-flags check, or a frame whose length byte was garbled or
//!   which lost bytes. It is counted once in [`ParserStats::bad_crc`] (corrupt, whatever its
//!   id) and only its start byte is skipped, as for a bad CRC, so that the frames its false
//!   length covers are found. The known-frame test matters: a false length ends at a start
//!   marker far more often than chance, because a link is dense with frame boundaries (a
//!   frame cut inside its header takes its id from the next frame's header, and its length
//!   then spans whole frames). What remains is a false length that ends on a `0xFD`/`0xFE`
//!   byte inside the payload of a known frame it cuts in two (about 1 in 128 such cuts): that
//!   frame is lost.
//! - MAVLink 1 (no flags byte to tell garbage from a frame, and a one-byte id, outside common
//!   for about half of all byte values): a known id whose declared length is not that
//!   message's MAVLink 1 length is not a frame, and its start byte is dropped at the header,
//!   without waiting for the length ([`v1_payload_len`]); an unknown id is counted once as
//!   unknown, also at the header, and scanned again from its second byte. Either way a false
//!   `0xFE` holds no frame behind it.
//!
//! One damaged frame counts once: a rejected candidate (bad CRC, unknown MAVLink 1 id, or an
//! unknown MAVLink 2 id that is not skipped) that starts inside the declared length of the
//! last counted one is a start marker of the same damaged stretch, counted as a garbage byte,
//! not as another frame. A valid frame found inside that stretch is handed out as usual and
//! ends it.
//!
//! A signed MAVLink 2 frame is handed out with its signature ([`Signature`]): whether it
//! counts is the companion's decision (`signing`), not the parser's. Frames with unknown
//! incompatibility flags are dropped, as the MAVLink 2 specification requires.

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
pub(super) const IFLAG_SIGNED: u8 = 0x01;
/// Length of a MAVLink 2 signature: link id (1), timestamp (6), signature (6).
pub(super) const SIGNATURE_LEN: usize = 13;

/// Largest MAVLink payload.
const MAX_PAYLOAD_LEN: usize = 255;
/// The parser's buffer: the longest frame, and the byte after it that tells whether a frame
/// of an unknown id ends where it says.
const BUF_LEN: usize = MAX_FRAME_LEN + 1;

/// Serialises one unsigned MAVLink 2 frame of `data` into the front of `out`: its length, or
/// `None` when `out` is shorter than the frame. The payload is trimmed of trailing zeros as
/// MAVLink 2 requires. Byte for byte what `MAVLinkV2MessageRaw::serialize_message_data`
/// produces for an 8-bit system id, but with every length visible to the optimiser: the
/// mavlink crate's header and checksum slicing keeps panic paths in the firmware, and the
/// no-panic link check (nopanic/) needs none.
#[cfg(test)]
pub fn write_v2_frame<D: MessageData>(
    out: &mut [u8],
    sequence: u8,
    system_id: u8,
    component_id: u8,
    data: &D,
) -> Option<usize> {
    write_v2_frame_flagged(out, 0, sequence, system_id, component_id, data)
}

/// [`write_v2_frame`] with the incompatibility flags `incompat` in the header (the signed
/// flag, [`IFLAG_SIGNED`], for a frame the caller then signs): the length without a
/// signature.
pub(super) fn write_v2_frame_flagged<D: MessageData>(
    out: &mut [u8],
    incompat: u8,
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
        incompat,
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
    /// The MAVLink 2 signature, when the frame is signed (not yet checked).
    pub signature: Option<Signature<'a>>,
}

/// A signed frame's signature, and the bytes it signs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Signature<'a> {
    /// The sender's link id.
    pub link_id: u8,
    /// The sender's timestamp, 10 µs units since 2015-01-01 UTC (48 bits).
    pub timestamp: u64,
    /// The first 6 bytes of the SHA-256 the sender computed.
    pub tag: [u8; 6],
    /// The frame's header, payload and CRC: what the signature covers besides the key, the
    /// link id and the timestamp.
    pub covered: &'a [u8],
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
    /// Candidate frames rejected as corrupted or garbage: a known id whose CRC did not match,
    /// or a MAVLink 2 unknown id whose declared length does not end at a start marker; once
    /// per damaged stretch (see the module documentation).
    pub bad_crc: u32,
    /// Bytes dropped while looking for a start marker (including the bytes of rejected
    /// candidates after their start byte, and start bytes inside them).
    pub garbage_bytes: u32,
    /// Frames of message ids the common dialect does not know (skipped), once each.
    pub unknown: u32,
}

/// What the header at the start of the buffer says.
enum Candidate {
    /// Need more bytes.
    Incomplete,
    /// Not a frame: drop the start byte.
    Invalid,
    /// A MAVLink 1 header of an id the dialect does not know, declaring `len` bytes.
    UnknownV1 { len: usize },
    /// A complete frame of `len` bytes.
    Complete { len: usize },
}

/// The incremental frame parser (see the module documentation).
#[derive(Clone)]
pub struct FrameParser {
    buf: [u8; BUF_LEN],
    len: usize,
    /// Bytes at the front of the buffer that still lie within the declared length of the last
    /// counted rejected candidate: a rejected candidate starting there is not counted again.
    damaged: usize,
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
            .field("damaged", &self.damaged)
            .field("stats", &self.stats)
            .finish()
    }
}

impl FrameParser {
    /// An empty parser.
    pub const fn new() -> Self {
        FrameParser {
            buf: [0; BUF_LEN],
            len: 0,
            damaged: 0,
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
        self.damaged = 0;
    }

    /// Feeds bytes; calls `on_frame` for every complete frame with a valid CRC, in order.
    pub fn push(&mut self, mut bytes: &[u8], mut on_frame: impl FnMut(&RawFrame<'_>)) {
        self.stats.bytes = self.stats.bytes.saturating_add(bytes.len() as u64);
        loop {
            let space = BUF_LEN.saturating_sub(self.len);
            let take = space.min(bytes.len());
            let (head, rest) = bytes.split_at(take);
            if let Some(dst) = self.buf.get_mut(self.len..self.len + take) {
                dst.copy_from_slice(head);
                self.len += take;
            }
            bytes = rest;
            self.process(&mut on_frame);
            // `process` leaves at most an incomplete frame, or a whole frame of an unknown id
            // waiting for the byte after it: shorter than the buffer either way, so every
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
        self.damaged = self.damaged.saturating_sub(n);
    }

    fn byte(&self, i: usize) -> Option<u8> {
        self.data().get(i).copied()
    }

    /// The buffered bytes.
    fn data(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }

    fn process(&mut self, on_frame: &mut impl FnMut(&RawFrame<'_>)) {
        loop {
            match self.data().iter().position(|&b| b == STX_V2 || b == STX_V1) {
                None => {
                    self.stats.garbage_bytes =
                        self.stats.garbage_bytes.saturating_add(self.len as u32);
                    self.consume(self.len);
                    return;
                }
                Some(0) => {}
                Some(skip) => {
                    self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(skip as u32);
                    self.consume(skip);
                }
            }
            match candidate(self.data()) {
                Candidate::Incomplete => return,
                Candidate::Invalid => {
                    self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(1);
                    self.consume(1);
                }
                Candidate::UnknownV1 { len } => self.reject(len, Rejected::Unknown),
                Candidate::Complete { len } => match check(self.data(), len) {
                    Check::Valid => {
                        self.stats.frames = self.stats.frames.saturating_add(1);
                        if let Some(frame) = self.frame() {
                            on_frame(&frame);
                        }
                        self.consume(len);
                        self.damaged = 0;
                    }
                    Check::UnknownFramed => {
                        // Skipped whole: nothing in its payload is counted (see the module docs).
                        self.stats.unknown = self.stats.unknown.saturating_add(1);
                        self.consume(len);
                        self.damaged = 0;
                    }
                    Check::AwaitNextByte => return,
                    Check::BadCrc | Check::UnknownUnframed => self.reject(len, Rejected::BadCrc),
                },
            }
        }
    }

    /// Drops the start byte of a rejected candidate of `len` bytes, the rest to be scanned
    /// again; counted as `counter` unless it starts inside the last counted one.
    fn reject(&mut self, len: usize, counter: Rejected) {
        if self.damaged > 0 {
            self.stats.garbage_bytes = self.stats.garbage_bytes.saturating_add(1);
            self.consume(1);
            return;
        }
        match counter {
            Rejected::BadCrc => self.stats.bad_crc = self.stats.bad_crc.saturating_add(1),
            Rejected::Unknown => self.stats.unknown = self.stats.unknown.saturating_add(1),
        }
        self.consume(1);
        self.damaged = len.saturating_sub(1);
    }

    fn frame(&self) -> Option<RawFrame<'_>> {
        let (version, header_len, message_id) = header(self.data())?;
        let payload_len = usize::from(self.byte(1)?);
        let (sequence, system_id, component_id) = match version {
            MavlinkVersion::V2 => (self.byte(4)?, self.byte(5)?, self.byte(6)?),
            MavlinkVersion::V1 => (self.byte(2)?, self.byte(3)?, self.byte(4)?),
        };
        let signed = version == MavlinkVersion::V2 && self.byte(2)? & IFLAG_SIGNED != 0;
        let signature = if signed {
            let covered_len = header_len + payload_len + 2;
            let covered = self.buf.get(..covered_len)?;
            let sig = self.buf.get(covered_len..covered_len + SIGNATURE_LEN)?;
            let (&link_id, rest) = sig.split_first()?;
            let (stamp, tag) = rest.split_first_chunk::<6>()?;
            let mut ts = [0u8; 8];
            for (d, s) in ts.iter_mut().zip(stamp) {
                *d = *s;
            }
            let mut t = [0u8; 6];
            for (d, s) in t.iter_mut().zip(tag) {
                *d = *s;
            }
            Some(Signature {
                link_id,
                timestamp: u64::from_le_bytes(ts),
                tag: t,
                covered,
            })
        } else {
            None
        };
        Some(RawFrame {
            version,
            sequence,
            system_id,
            component_id,
            message_id,
            payload: self.buf.get(header_len..header_len + payload_len)?,
            signature,
        })
    }
}

/// What the header at the start of `bytes` (a start marker) announces.
fn candidate(bytes: &[u8]) -> Candidate {
    let (Some(&stx), Some(&payload_len)) = (bytes.first(), bytes.get(1)) else {
        return Candidate::Incomplete;
    };
    let payload_len = usize::from(payload_len);
    let len = match stx {
        STX_V2 => {
            let Some(&incompat) = bytes.get(2) else {
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
        STX_V1 => {
            let Some(&id) = bytes.get(5) else {
                return Candidate::Incomplete;
            };
            let len = V1_HEADER_LEN + payload_len + 2;
            match v1_payload_len(u32::from(id)) {
                Some(known) if known != payload_len => return Candidate::Invalid,
                Some(_) => len,
                // Nothing after the header can make it a frame we use (no CRC_EXTRA to check
                // it by): decided now, not after its length has arrived.
                None => return Candidate::UnknownV1 { len },
            }
        }
        _ => return Candidate::Invalid,
    };
    if bytes.len() < len {
        Candidate::Incomplete
    } else {
        Candidate::Complete { len }
    }
}

/// The payload length of message `id` in MAVLink 1, if the dialect knows it: its fields
/// without the MAVLink 2 extensions, never truncated (MAVLink 1 has neither), so a frame of a
/// known id declares exactly this. A false start (`0xFE` in garbage, or inside a payload)
/// declares a random length: checked at the header, it is dropped at once instead of holding
/// the frames behind it until that length has arrived (up to 263 bytes, tens of milliseconds
/// of a busy link).
fn v1_payload_len(id: u32) -> Option<usize> {
    let message = MavMessage::default_message_from_id(id)?;
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    Some(message.ser(MavlinkVersion::V1, &mut payload))
}

/// Header fields of the frame at the start of `bytes`: (version, header length, message id).
fn header(bytes: &[u8]) -> Option<(MavlinkVersion, usize, u32)> {
    let byte = |i: usize| bytes.get(i).copied();
    match byte(0)? {
        STX_V2 => {
            let id = u32::from_le_bytes([byte(7)?, byte(8)?, byte(9)?, 0]);
            Some((MavlinkVersion::V2, V2_HEADER_LEN, id))
        }
        STX_V1 => Some((MavlinkVersion::V1, V1_HEADER_LEN, u32::from(byte(5)?))),
        _ => None,
    }
}

/// Whether the frame at the start of `bytes` has a known id and its CRC matches.
fn crc_matches(bytes: &[u8]) -> bool {
    let Some((_, header_len, id)) = header(bytes) else {
        return false;
    };
    let extra = MavMessage::extra_crc(id);
    if extra == 0 {
        return false;
    }
    let payload_len = usize::from(bytes.get(1).copied().unwrap_or(0));
    let end = header_len + payload_len;
    let (Some(covered), Some(&lo), Some(&hi)) =
        (bytes.get(1..end), bytes.get(end), bytes.get(end + 1))
    else {
        return false;
    };
    crc16_x25(crc16_x25(0xFFFF, covered), &[extra]) == u16::from_le_bytes([lo, hi])
}

/// Whether a whole frame of a known id with a matching CRC starts after the first byte of
/// `span` and ends within it: then `span` is not one frame of another dialect, whatever
/// follows it (a truncated frame whose id bytes came from the next frame's header, or
/// garbage, whose false length happened to end at a frame boundary).
fn holds_a_known_frame(span: &[u8]) -> bool {
    (1..span.len()).any(|i| {
        let inner = span.get(i..).unwrap_or(&[]);
        matches!(inner.first(), Some(&(STX_V2 | STX_V1)))
            && matches!(candidate(inner), Candidate::Complete { .. })
            && crc_matches(inner)
    })
}

/// What the complete candidate of `len` bytes at the start of `bytes` is (`bytes` may hold
/// more: the byte after it decides for an unknown MAVLink 2 id).
fn check(bytes: &[u8], len: usize) -> Check {
    let Some((version, _, id)) = header(bytes) else {
        return Check::BadCrc;
    };
    if MavMessage::extra_crc(id) != 0 {
        return if crc_matches(bytes) {
            Check::Valid
        } else {
            Check::BadCrc
        };
    }
    match (version, bytes.get(len)) {
        // Not reached: `candidate` decides a MAVLink 1 id the dialect does not know at the
        // header.
        (MavlinkVersion::V1, _) => Check::BadCrc,
        (MavlinkVersion::V2, None) => Check::AwaitNextByte,
        (MavlinkVersion::V2, Some(&(STX_V2 | STX_V1)))
            if !holds_a_known_frame(bytes.get(..len).unwrap_or(&[])) =>
        {
            Check::UnknownFramed
        }
        (MavlinkVersion::V2, Some(_)) => Check::UnknownUnframed,
    }
}

/// What a complete candidate is.
enum Check {
    /// A known id with a matching CRC.
    Valid,
    /// A known id whose CRC does not match.
    BadCrc,
    /// MAVLink 2, an unknown id, followed by a start marker: a frame of another dialect.
    UnknownFramed,
    /// MAVLink 2, an unknown id, not followed by a start marker, or holding a whole valid
    /// frame of a known id: garbage or a damaged frame.
    UnknownUnframed,
    /// MAVLink 2, an unknown id, the byte after it not received yet.
    AwaitNextByte,
}

/// The counter a rejected candidate goes to.
enum Rejected {
    BadCrc,
    Unknown,
}

#[cfg(test)]
mod tests {
    // Test code only: the vectors below never reach the firmware.
    extern crate std;

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

    /// A MAVLink 1 false start of a known id whose length is not that message's does not
    /// hold the frame behind it: a heartbeat right after `0xFE 200 .. id 0` (HEARTBEAT's
    /// MAVLink 1 length is 9) is handed out as soon as its last byte is in, not 208 bytes
    /// later.
    #[test]
    fn a_false_mavlink1_start_is_dropped_at_its_header() {
        assert_eq!(v1_payload_len(0), Some(9));
        assert_eq!(v1_payload_len(149), Some(30)); // LANDING_TARGET without its extensions
                                                   // Every MAVLink 1 id with a length has a CRC_EXTRA: `check` never sees an unknown one.
        for id in 0..=255u32 {
            if v1_payload_len(id).is_some() {
                assert_ne!(MavMessage::extra_crc(id), 0, "id {id}");
            }
        }
        let mut p = FrameParser::new();
        let (a, n) = heartbeat_bytes(1);
        let mut seen = 0;
        p.push(&[0xFE, 200, 7, 1, 1, 0, 0x55], |_| seen += 1);
        p.push(&a[..n], |f| {
            assert_eq!(f.message_id, 0);
            seen += 1;
        });
        assert_eq!(seen, 1, "{:?}", p.stats());
        assert_eq!(p.buffered(), 0);
        // Nor does one of an id the dialect does not know (180: ArduPilot's own range),
        // counted once as unknown.
        assert_eq!(v1_payload_len(180), None);
        let mut p = FrameParser::new();
        let mut seen = 0;
        p.push(&[0xFE, 200, 7, 1, 1, 180, 0x55], |_| seen += 1);
        p.push(&a[..n], |_| seen += 1);
        assert_eq!(seen, 1, "{:?}", p.stats());
        assert_eq!(p.stats().unknown, 1);
        // A false start with the right length still waits for its CRC, as before: the frame
        // behind it is found once the CRC has failed.
        let mut p = FrameParser::new();
        let mut seen = 0;
        p.push(&[0xFE, 9, 7, 1, 1, 0, 0x55], |_| seen += 1);
        p.push(&a[..n], |_| seen += 1);
        p.push(&a[..n], |_| seen += 1);
        assert_eq!(seen, 2, "{:?}", p.stats());
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

    /// A MAVLink 2 frame (`incompat` flags, 13 signature bytes when signed) of any id, its
    /// CRC over `extra` (an unknown id has none we know: any byte).
    fn v2_frame(id: u32, payload: &[u8], incompat: u8, extra: u8) -> ([u8; BUF_LEN], usize) {
        let mut f = [0u8; BUF_LEN];
        let id = id.to_le_bytes();
        let header = [
            STX_V2,
            payload.len() as u8,
            incompat,
            0,
            7,
            1,
            1,
            id[0],
            id[1],
            id[2],
        ];
        f[..V2_HEADER_LEN].copy_from_slice(&header);
        let end = V2_HEADER_LEN + payload.len();
        f[V2_HEADER_LEN..end].copy_from_slice(payload);
        let crc = crc16_x25(crc16_x25(0xFFFF, &f[1..end]), &[extra]);
        f[end..end + 2].copy_from_slice(&crc.to_le_bytes());
        let signature = if incompat & IFLAG_SIGNED != 0 {
            SIGNATURE_LEN
        } else {
            0
        };
        for (i, b) in f[end + 2..end + 2 + signature].iter_mut().enumerate() {
            *b = 0x30 + i as u8;
        }
        (f, end + 2 + signature)
    }

    /// ArduPilot's AHRS (163, not in common), its 28-byte payload with two false frame starts
    /// inside (a MAVLink 2 one with valid flags, a MAVLink 1 one), as real payloads have.
    fn ahrs_payload() -> [u8; 28] {
        let mut p = [0u8; 28];
        for (i, b) in p.iter_mut().enumerate() {
            *b = 0x10 + i as u8;
        }
        p[4..8].copy_from_slice(&[STX_V2, 0x03, 0x00, 0x00]);
        p[16..18].copy_from_slice(&[STX_V1, 0x02]);
        p
    }

    /// Feeds `stream` whole and byte by byte; both must agree. Returns the message ids handed
    /// out and the counters.
    fn parse(stream: &[u8]) -> (std::vec::Vec<u32>, ParserStats) {
        let mut whole = FrameParser::new();
        let mut ids = std::vec::Vec::new();
        whole.push(stream, |f| ids.push(f.message_id));
        let mut bytewise = FrameParser::new();
        let mut ids_bytewise = std::vec::Vec::new();
        for b in stream {
            bytewise.push(core::slice::from_ref(b), |f| {
                ids_bytewise.push(f.message_id)
            });
        }
        assert_eq!(ids, ids_bytewise);
        assert_eq!(whole.stats(), bytewise.stats());
        (ids, whole.stats())
    }

    fn concat(parts: &[&[u8]]) -> std::vec::Vec<u8> {
        parts.iter().flat_map(|p| p.iter().copied()).collect()
    }

    /// A frame of another dialect, start markers in its payload included, is one "unknown"
    /// and nothing else: skipped by its declared length, its payload not scanned.
    #[test]
    fn an_unknown_frame_counts_once_and_is_skipped_whole() {
        let (u, un) = v2_frame(163, &ahrs_payload(), 0, 127);
        let (h, hn) = heartbeat_bytes(1);
        let stream = concat(&[&u[..un], &h[..hn], &u[..un], &h[..hn]]);
        let (ids, st) = parse(&stream);
        assert_eq!(ids, [0, 0]);
        assert_eq!(
            (st.unknown, st.bad_crc, st.garbage_bytes),
            (2, 0, 0),
            "{st:?}"
        );
        // Signed: 13 more bytes, skipped as well.
        let (s, sn) = v2_frame(163, &ahrs_payload(), IFLAG_SIGNED, 127);
        let (ids, st) = parse(&concat(&[&s[..sn], &h[..hn]]));
        assert_eq!(ids, [0]);
        assert_eq!(
            (st.unknown, st.bad_crc, st.garbage_bytes),
            (1, 0, 0),
            "{st:?}"
        );
    }

    /// Whether an unknown frame ends where it says is known only from the byte after it: the
    /// parser waits for it (nothing is behind it to wait), then counts the frame once.
    #[test]
    fn an_unknown_frame_waits_for_the_byte_after_it() {
        let (u, un) = v2_frame(163, &ahrs_payload(), 0, 127);
        let mut p = FrameParser::new();
        p.push(&u[..un], |_| panic!("not a frame we know"));
        assert_eq!((p.buffered(), p.stats().unknown), (un, 0));
        let (h, hn) = heartbeat_bytes(2);
        let mut seen = 0;
        p.push(&h[..hn], |_| seen += 1);
        assert_eq!((seen, p.stats().unknown, p.buffered()), (1, 1, 0));
        // The longest frame (255-byte payload, signed) and its next byte fit the buffer.
        let (big, bn) = v2_frame(163, &[0x55; 255], IFLAG_SIGNED, 0);
        assert_eq!(bn, MAX_FRAME_LEN);
        let (ids, st) = parse(&concat(&[&big[..bn], &h[..hn]]));
        assert_eq!((ids.len(), st.unknown, st.bad_crc), (1, 1, 0));
    }

    /// The garbled-length cases: a length byte too long or too short, or a byte lost, leaves
    /// the unknown frame's declared end off a start marker: it is counted once as bad (corrupt),
    /// its start byte alone skipped, the start markers inside it not counted again, and the
    /// frames its false length covers are found.
    #[test]
    fn an_unknown_frame_with_a_garbled_length_is_one_bad_frame() {
        let (u, un) = v2_frame(163, &ahrs_payload(), 0, 127);
        let (h1, n1) = heartbeat_bytes(3);
        let (h2, n2) = heartbeat_bytes(4);
        for (what, delta) in [
            ("3 too long", 3i32),
            ("5 too short", -5),
            ("20 too long", 20),
        ] {
            let mut garbled = u;
            garbled[1] = (i32::from(garbled[1]) + delta) as u8;
            let stream = concat(&[&garbled[..un], &h1[..n1], &h2[..n2]]);
            let end = V2_HEADER_LEN + usize::from(garbled[1]) + 2;
            assert!(stream[end] != STX_V2 && stream[end] != STX_V1, "{what}");
            let (ids, st) = parse(&stream);
            assert_eq!(ids, [0, 0], "{what}: {st:?}");
            assert_eq!((st.bad_crc, st.unknown), (1, 0), "{what}: {st:?}");
            // Every byte of the garbled frame after its start is garbage, none a frame.
            assert_eq!(st.garbage_bytes as usize, un - 1, "{what}: {st:?}");
        }
        // Its last byte lost: the declared end is the heartbeat's length byte.
        let stream = concat(&[&u[..un - 1], &h1[..n1]]);
        let (ids, st) = parse(&stream);
        assert_eq!(ids, [0]);
        assert_eq!((st.bad_crc, st.unknown), (1, 0), "{st:?}");
        // A frame cut inside its header takes its id from the next frame's header (here
        // 3 << 16, unknown) and, with 14 bytes of payload declared, spans that whole heartbeat
        // to end at the next one's start marker: not skipped, as it holds a known frame.
        let stream = concat(&[&[STX_V2, 14, 0, 0, 7], &h1[..n1], &h2[..n2]]);
        assert_eq!(
            header(&stream),
            Some((MavlinkVersion::V2, V2_HEADER_LEN, 3 << 16))
        );
        assert_eq!(stream[V2_HEADER_LEN + 14 + 2], STX_V2);
        let (ids, st) = parse(&stream);
        assert_eq!(ids, [0, 0], "{st:?}");
        assert_eq!((st.bad_crc, st.unknown), (1, 0), "{st:?}");
        // Garbled onto the next frame's end (a start marker): the span holds a whole known
        // frame, so it is not skipped, and that frame is found.
        let mut garbled = u;
        garbled[1] += n1 as u8;
        let (ids, st) = parse(&concat(&[&garbled[..un], &h1[..n1], &h2[..n2]]));
        assert_eq!(ids, [0, 0]);
        assert_eq!((st.bad_crc, st.unknown), (1, 0), "{st:?}");
        // The case that remains: garbled onto a start marker inside the payload of the next
        // frame, which it cuts in two. That frame is lost; the one after it is found.
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: 9,
            },
            &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: u32::from(STX_V2),
                ..HEARTBEAT_DATA::default()
            }),
        );
        let cut = raw.raw_bytes();
        assert_eq!(cut[V2_HEADER_LEN], STX_V2);
        let mut garbled = u;
        garbled[1] += V2_HEADER_LEN as u8;
        let (ids, st) = parse(&concat(&[&garbled[..un], cut, &h2[..n2]]));
        assert_eq!(ids, [0], "{st:?}");
        assert_eq!(st.unknown, 1, "{st:?}");
    }

    /// A known frame with a bad CRC and a start marker inside is one bad CRC, not two.
    #[test]
    fn a_corrupted_frame_counts_once() {
        let (h, hn) = heartbeat_bytes(5);
        let mut bad = h;
        // custom_mode: a MAVLink 2 start with valid flags, then the CRC broken.
        bad[V2_HEADER_LEN..V2_HEADER_LEN + 4].copy_from_slice(&[STX_V2, 0x01, 0x00, 0x00]);
        let stream = concat(&[&bad[..hn], &h[..hn]]);
        let (ids, st) = parse(&stream);
        assert_eq!(ids, [0]);
        assert_eq!((st.bad_crc, st.unknown), (1, 0), "{st:?}");
        // A MAVLink 1 frame of an unknown id is scanned again from its second byte, and
        // counted once too.
        let mut v1 = [0u8; 6 + 10 + 2];
        v1[..6].copy_from_slice(&[STX_V1, 10, 9, 1, 1, 163]);
        v1[6..9].copy_from_slice(&[STX_V2, 0x00, 0x00]);
        let (ids, st) = parse(&concat(&[&v1, &h[..hn]]));
        assert_eq!(ids, [0]);
        assert_eq!((st.unknown, st.bad_crc), (1, 0), "{st:?}");
    }

    /// Random bytes between the frames of a link (as line noise inserts them) and frames cut
    /// short lose no intact frame: a MAVLink 2 start in noise almost always fails the flags
    /// check, and a false unknown frame is rescanned unless its declared end is a start
    /// marker and it holds no whole known frame.
    #[test]
    fn noise_and_truncation_lose_no_intact_frame() {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let (u, un) = v2_frame(163, &ahrs_payload(), 0, 127);
        let mut stream = std::vec::Vec::new();
        let mut heartbeats = 0;
        let mut cut = 0;
        for i in 0..2000u32 {
            let (h, hn) = heartbeat_bytes(i as u8);
            if i % 5 == 2 {
                // Cut anywhere, the header included.
                stream.extend_from_slice(&h[..1 + (next() as usize % (hn - 1))]);
                cut += 1;
            } else {
                stream.extend_from_slice(&h[..hn]);
                heartbeats += 1;
            }
            if i % 3 == 0 {
                stream.extend_from_slice(&u[..un]);
            }
            if i % 4 == 0 {
                for _ in 0..(next() % 24) {
                    stream.push(next() as u8);
                }
            }
        }
        let (ids, st) = parse(&stream);
        assert_eq!(ids.len(), heartbeats, "{st:?}");
        // Every cut frame is one bad CRC (or, cut inside its id, one unknown), give or take
        // the few that share a damaged stretch with noise.
        assert!(st.bad_crc + st.unknown >= cut * 9 / 10, "{cut} cut: {st:?}");
        std::println!("{cut} cut, {heartbeats} intact: {st:?}");
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
