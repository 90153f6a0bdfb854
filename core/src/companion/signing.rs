//! MAVLink 2 message signing on the board's link: who may change the board.
//!
//! The flight controller routes a ground station's messages, over whatever radio or network
//! the vehicle uses, to every link, the board's included; without signing, whoever reaches the
//! vehicle can set the marker size or the mount in flight. With a key set (SETUP_SIGNING,
//! kept with the parameters, [`crate::params::SigningSecret`]) the companion takes
//! PARAM_SET, COMMAND_LONG and SETUP_SIGNING only from frames signed with that key, and
//! signs every frame it sends (ArduPilot, once it has a key, drops unsigned frames on every
//! link but its first). Reading stays open: PARAM_REQUEST_* and the autopilot's telemetry
//! are taken signed or not, and a frame whose signature fails is treated as unsigned, since
//! it proves no more than one without.
//!
//! A signature is the first 6 bytes of SHA-256 over the key, the frame (header, payload,
//! CRC) and the signature's link id and 48-bit timestamp (10 µs units since 2015-01-01 UTC);
//! [`Signing::check`] recomputes it and applies the specification's replay rules, per stream
//! (sender system, component and link id): a timestamp must be newer than the stream's last,
//! and a stream not seen before may be at most [`NEW_STREAM_WINDOW`] behind our own
//! timestamp. Our timestamp runs with our clock from the newest of: the key's saved timestamp,
//! any valid signed frame received, and the autopilot's GPS time (SYSTEM_TIME); each frame we
//! sign takes a newer one. After a reboot the saved timestamp may be older than what the
//! autopilot last saw from us: our first frames are then refused there until the
//! autopilot's first signed frame (its HEARTBEAT, within a second) brings our timestamp up to
//! date.
//!
//! The streams are forgotten at a reboot, and the one-minute window alone would then let a
//! recorded write be played again. So the saved timestamp is also a floor: no signed frame
//! older than it counts, and every signed write the board applies moves it past that write's
//! timestamp (saved with the write: [`crate::params::SigningSecret::after_write`]).

use super::framing::{RawFrame, SIGNATURE_LEN};
use crate::params::KEY_LEN;
use crate::sha256::Sha256;
use heapless::Vec;

/// How far behind our timestamp a stream never seen before may start (one minute, as the
/// MAVLink specification suggests), 10 µs units.
pub const NEW_STREAM_WINDOW: u64 = 6_000_000;
/// How many senders' streams are remembered for the replay check; when full, the stalest
/// is forgotten (its next frame is then judged as a new stream's, within the window).
pub const MAX_SIGNING_STREAMS: usize = 8;
/// Our link id in the signatures we send (the board has one link).
pub const LINK_ID: u8 = 0;
/// Signing timestamps at and above this do not fit the signature's 48 bits.
const TIMESTAMP_LIMIT: u64 = 1 << 48;
/// Unix time of the signing epoch, 2015-01-01 00:00:00 UTC, µs.
const EPOCH_UNIX_US: u64 = 1_420_070_400_000_000;

/// What a received frame's signature proves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Authenticity {
    /// Signed with our key, and newer than anything its stream sent before.
    Signed,
    /// Not signed, or we have no key to check it by.
    Unsigned,
    /// Signed, but not with our key (or altered).
    BadSignature,
    /// Signed with our key, but not newer than its stream's last frame (or, from a new
    /// stream, more than [`NEW_STREAM_WINDOW`] old): a replay.
    Replayed,
}

/// One sender's newest timestamp.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stream {
    system_id: u8,
    component_id: u8,
    link_id: u8,
    timestamp: u64,
}

/// The signing state of the link: our timestamp and the streams' (the key is the
/// parameters', passed in).
#[derive(Debug, Clone)]
pub(super) struct Signing {
    /// No signed frame older than this counts (the key's saved timestamp).
    floor: u64,
    /// Our timestamp at `base_us` on our clock.
    base: u64,
    base_us: u64,
    /// The last timestamp we signed with.
    last_sent: u64,
    streams: Vec<Stream, MAX_SIGNING_STREAMS>,
}

impl Signing {
    /// Starts our timestamp from `initial` (the saved key's) at `now_us`.
    pub(super) fn new(initial: u64, now_us: u64) -> Self {
        Signing {
            floor: initial,
            base: initial.min(TIMESTAMP_LIMIT - 1),
            base_us: now_us,
            last_sent: 0,
            streams: Vec::new(),
        }
    }

    /// Our timestamp now: the base run on with our clock (10 µs a tick).
    pub(super) fn timestamp(&self, now_us: u64) -> u64 {
        let run = now_us.saturating_sub(self.base_us) / 10;
        self.base
            .saturating_add(run)
            .max(self.last_sent)
            .min(TIMESTAMP_LIMIT - 1)
    }

    /// Moves our timestamp up to `timestamp` (never back).
    pub(super) fn advance_to(&mut self, timestamp: u64, now_us: u64) {
        if timestamp > self.timestamp(now_us) && timestamp < TIMESTAMP_LIMIT {
            self.base = timestamp;
            self.base_us = now_us;
        }
    }

    /// Moves our timestamp up to the autopilot's GPS time (`time_unix_usec`; 0, or a time
    /// before the epoch, is no time).
    pub(super) fn advance_to_unix(&mut self, time_unix_us: u64, now_us: u64) {
        if let Some(since) = time_unix_us.checked_sub(EPOCH_UNIX_US) {
            self.advance_to(since / 10, now_us);
        }
    }

    /// Forgets the streams (a new key: their timestamps were under the old one) and takes
    /// `floor` as the oldest timestamp that counts.
    pub(super) fn restart(&mut self, floor: u64) {
        self.streams.clear();
        self.floor = floor;
    }

    /// Raises the floor to `floor` (a write applied, see the module documentation).
    pub(super) fn raise_floor(&mut self, floor: u64) {
        self.floor = self.floor.max(floor);
    }

    /// What `frame`'s signature proves under `key`; a valid signature moves its stream and
    /// our timestamp on.
    pub(super) fn check(
        &mut self,
        key: Option<&[u8; KEY_LEN]>,
        frame: &RawFrame<'_>,
        now_us: u64,
    ) -> Authenticity {
        let (Some(key), Some(signature)) = (key, frame.signature) else {
            return Authenticity::Unsigned;
        };
        if signature_tag(
            key,
            signature.covered,
            signature.link_id,
            signature.timestamp,
        ) != signature.tag
        {
            return Authenticity::BadSignature;
        }
        let ts = signature.timestamp;
        if ts < self.floor {
            return Authenticity::Replayed;
        }
        let ours = self.timestamp(now_us);
        let stream = self.streams.iter_mut().find(|s| {
            (s.system_id, s.component_id, s.link_id)
                == (frame.system_id, frame.component_id, signature.link_id)
        });
        match stream {
            Some(s) if ts <= s.timestamp => return Authenticity::Replayed,
            Some(s) => s.timestamp = ts,
            None => {
                if ts.saturating_add(NEW_STREAM_WINDOW) < ours {
                    return Authenticity::Replayed;
                }
                let new = Stream {
                    system_id: frame.system_id,
                    component_id: frame.component_id,
                    link_id: signature.link_id,
                    timestamp: ts,
                };
                // When full, the stalest sender's place is taken.
                if let Err(new) = self.streams.push(new) {
                    if let Some(stalest) = self.streams.iter_mut().min_by_key(|s| s.timestamp) {
                        *stalest = new;
                    }
                }
            }
        }
        self.advance_to(ts, now_us);
        Authenticity::Signed
    }

    /// Signs the unsigned-length `len` frame at the front of `out` (written with the signed
    /// incompatibility flag), appending the 13-byte signature: the signed length, or `None`
    /// when `out` is too short.
    pub(super) fn sign(
        &mut self,
        key: &[u8; KEY_LEN],
        out: &mut [u8],
        len: usize,
        now_us: u64,
    ) -> Option<usize> {
        let ts = self
            .timestamp(now_us)
            .saturating_add(1)
            .min(TIMESTAMP_LIMIT - 1);
        self.last_sent = ts;
        let frame = out.get_mut(..len + SIGNATURE_LEN)?;
        let (covered, signature) = frame.split_at_mut(len);
        let tag = signature_tag(key, covered, LINK_ID, ts);
        let (head, tag_out) = signature.split_at_mut(SIGNATURE_LEN - 6);
        let (link, stamp) = head.split_at_mut(1);
        link.copy_from_slice(&[LINK_ID]);
        let ts_bytes = ts.to_le_bytes();
        stamp.copy_from_slice(ts_bytes.get(..6)?);
        tag_out.copy_from_slice(&tag);
        Some(len + SIGNATURE_LEN)
    }
}

/// The 6-byte signature of a frame whose header, payload and CRC are `covered`.
fn signature_tag(key: &[u8; KEY_LEN], covered: &[u8], link_id: u8, timestamp: u64) -> [u8; 6] {
    let mut h = Sha256::new();
    h.update(key);
    h.update(covered);
    h.update(&[link_id]);
    h.update(timestamp.to_le_bytes().get(..6).unwrap_or(&[]));
    let digest = h.finish();
    let mut tag = [0u8; 6];
    for (t, d) in tag.iter_mut().zip(digest) {
        *t = d;
    }
    tag
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::companion::framing::{write_v2_frame_flagged, FrameParser, IFLAG_SIGNED};
    use mavlink::dialects::common::HEARTBEAT_DATA;

    const KEY: [u8; KEY_LEN] = [9; KEY_LEN];

    /// A HEARTBEAT from system `sys` signed with `key` at timestamp `ts` (link 0).
    fn signed(sys: u8, ts: u64, key: &[u8; KEY_LEN]) -> ([u8; 280], usize) {
        let mut out = [0u8; 280];
        let n = write_v2_frame_flagged(&mut out, IFLAG_SIGNED, 0, sys, 1, &HEARTBEAT_DATA::DEFAULT)
            .unwrap();
        let n = Signing::new(ts - 1, 0).sign(key, &mut out, n, 0).unwrap();
        (out, n)
    }

    /// What `board` makes of `frame` at `now_us`.
    fn judge(board: &mut Signing, frame: &[u8], now_us: u64) -> Authenticity {
        let mut parser = FrameParser::new();
        let mut verdict = None;
        parser.push(frame, |raw| {
            verdict = Some(board.check(Some(&KEY), raw, now_us))
        });
        verdict.unwrap()
    }

    #[test]
    fn replay_rules_per_stream_window_and_floor() {
        let mut board = Signing::new(1_000, 0);
        let now = 120_000_000; // two minutes on: our timestamp 12,001,000
        assert_eq!(board.timestamp(now), 12_001_000);
        let (f, n) = signed(5, 5_000_000, &KEY);
        assert_eq!(
            judge(&mut board, &f[..n], now),
            Authenticity::Replayed,
            "7 s over a minute behind"
        );
        let (f, n) = signed(6, 7_000_000, &KEY);
        assert_eq!(
            judge(&mut board, &f[..n], now),
            Authenticity::Signed,
            "within the minute"
        );
        assert_eq!(
            judge(&mut board, &f[..n], now),
            Authenticity::Replayed,
            "the same again"
        );
        let (f, n) = signed(6, 7_000_001, &KEY);
        assert_eq!(judge(&mut board, &f[..n], now), Authenticity::Signed);
        let (f, n) = signed(6, 7_000_002, &[8; KEY_LEN]);
        assert_eq!(judge(&mut board, &f[..n], now), Authenticity::BadSignature);
        // Under the floor, even as a new stream at the start.
        let mut fresh = Signing::new(1_000, 0);
        let (f, n) = signed(7, 999, &KEY);
        assert_eq!(judge(&mut fresh, &f[..n], 0), Authenticity::Replayed);
        let (f, n) = signed(7, 1_000, &KEY);
        assert_eq!(judge(&mut fresh, &f[..n], 0), Authenticity::Signed);
        // A valid frame from further on moves our timestamp there.
        let (f, n) = signed(8, 50_000_000, &KEY);
        assert_eq!(judge(&mut fresh, &f[..n], 0), Authenticity::Signed);
        assert_eq!(fresh.timestamp(0), 50_000_000);
    }

    #[test]
    fn a_full_table_forgets_its_stalest_sender() {
        let mut board = Signing::new(0, 0);
        let frames: [_; MAX_SIGNING_STREAMS + 1] =
            core::array::from_fn(|i| signed(i as u8 + 1, 1_000 + i as u64, &KEY));
        for (f, n) in &frames {
            assert_eq!(judge(&mut board, &f[..*n], 0), Authenticity::Signed);
        }
        assert_eq!(board.streams.len(), MAX_SIGNING_STREAMS);
        // The newest sender is remembered; the first, the stalest, was forgotten, so its frame
        // is judged as a new stream's again (within the window, above the floor).
        let (f, n) = &frames[MAX_SIGNING_STREAMS];
        assert_eq!(judge(&mut board, &f[..*n], 0), Authenticity::Replayed);
        let (f, n) = &frames[0];
        assert_eq!(judge(&mut board, &f[..*n], 0), Authenticity::Signed);
    }

    #[test]
    fn the_timestamps_we_sign_with_rise_by_one_at_least() {
        let mut s = Signing::new(100, 0);
        let mut last = 0;
        let mut out = [0u8; 280];
        for i in 0..50u64 {
            let n =
                write_v2_frame_flagged(&mut out, IFLAG_SIGNED, 0, 1, 191, &HEARTBEAT_DATA::DEFAULT)
                    .unwrap();
            // The clock stands still for the first 25, then runs.
            let now = if i < 25 { 0 } else { i * 1_000 };
            let n = s.sign(&KEY, &mut out, n, now).unwrap();
            let mut ts = [0u8; 8];
            ts[..6].copy_from_slice(&out[n - 12..n - 6]);
            let ts = u64::from_le_bytes(ts);
            assert!(ts > last, "{ts} after {last}");
            last = ts;
        }
        assert!(last >= 100 + 49 * 100, "{last}");
    }
}
