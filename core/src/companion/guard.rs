//! Who may change the board: the signing check and the flight lock, applied to every write
//! that arrives over the link (PARAM_SET, SETUP_SIGNING, COMMAND_LONG).
//!
//! - With a signing key set, a write must come in a frame signed with it (`signing`); an
//!   unsigned, wrongly signed or replayed one is refused.
//! - With TD_LOCK 1 (the default), while the latched autopilot's last HEARTBEAT says armed,
//!   every parameter but TD_LOCK itself, and the signing key, refuse writes: a landing's
//!   geometry (marker size, pad, mount, profile, ids) does not change under it. The owner
//!   who means to change one in flight sets TD_LOCK 0 first. Until an autopilot has been
//!   heard the board counts as disarmed, so a board on the bench can be set up.
//!
//! Only writes from the link are guarded: the board's own mount calibration
//! (TD_CAM_CAL 2) and [`super::Companion::set_param`] (a host tool's own process) are not.
//! A refused PARAM_SET is still answered with the value that holds, so the sender sees that
//! nothing changed; a STATUSTEXT says why, at most one per [`REFUSAL_TEXT_PERIOD_US`] (a flood
//! of writes must not become a flood of texts).

use super::signing::Authenticity;
use super::State;
use crate::params::ParamId;
use core::fmt::Write as _;
use mavlink::dialects::common::MavSeverity;

/// At most one refusal STATUSTEXT this often, µs.
pub const REFUSAL_TEXT_PERIOD_US: u64 = 2_000_000;

/// A write arriving over the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Write {
    Param(ParamId),
    SigningKey,
    Command,
}

impl Write {
    /// Whether TD_LOCK holds this write while armed: every parameter but TD_LOCK, and the
    /// key (no command is implemented, so none changes anything).
    fn locked_in_flight(self) -> bool {
        match self {
            Write::Param(id) => id != ParamId::Lock,
            Write::SigningKey => true,
            Write::Command => false,
        }
    }
}

/// Why a write was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Refusal {
    NotSigned(Authenticity),
    Locked,
}

impl State {
    /// Whether the latched autopilot's last HEARTBEAT said armed and TD_LOCK is on.
    pub(super) fn flight_locked(&self) -> bool {
        self.autopilot_armed && self.params.get_int(ParamId::Lock) == 1
    }

    /// Decides a write of `what` that came in a frame of `authenticity`: `true` to apply it;
    /// `false` when refused (counted, and said by a rate-limited STATUSTEXT).
    pub(super) fn may_write(
        &mut self,
        what: Write,
        authenticity: Authenticity,
        now_us: u64,
    ) -> bool {
        let refusal = if self.params.signing_secret().is_set()
            && authenticity != Authenticity::Signed
        {
            self.stats.writes_refused_unsigned =
                self.stats.writes_refused_unsigned.saturating_add(1);
            Refusal::NotSigned(authenticity)
        } else if self.flight_locked() && what.locked_in_flight() {
            self.stats.writes_refused_locked = self.stats.writes_refused_locked.saturating_add(1);
            Refusal::Locked
        } else {
            return true;
        };
        if now_us >= self.next_refusal_text_us {
            self.next_refusal_text_us = now_us.saturating_add(REFUSAL_TEXT_PERIOD_US);
            let mut text = heapless::String::<{ super::STATUS_TEXT_LEN }>::new();
            let subject = match what {
                Write::Param(id) => id.def().name,
                Write::SigningKey => "signing key",
                Write::Command => "command",
            };
            let why = match refusal {
                Refusal::NotSigned(Authenticity::BadSignature) => "bad signature",
                Refusal::NotSigned(Authenticity::Replayed) => "replayed",
                Refusal::NotSigned(_) => "not signed",
                Refusal::Locked => "armed (TD_LOCK)",
            };
            // The longest name (14) and reason fit the 50 bytes: the write cannot fail.
            let _ = write!(text, "touchdown: {subject} refused: {why}");
            self.queue_status_text(MavSeverity::MAV_SEVERITY_WARNING, &text);
        }
        false
    }
}
