//! The companion's bookkeeping shared by receive and transmit: the profile in force, the
//! parameters, our ids, which clock `time_usec` is in, and the queues.

use super::framing::RawFrame;
use super::pad_motion::PadMotionSetting;
use super::profile::{Profile, ProfileSetting};
use super::{Pending, State, StatusText, TimeBase, STATUS_TEXT_LEN};
use crate::params::{ParamError, ParamId};
use mavlink::dialects::common::MavSeverity;

impl State {
    pub(super) fn profile_setting(&self) -> ProfileSetting {
        ProfileSetting::from_param(self.params.get_int(ParamId::Profile))
    }

    pub(super) fn profile(&self) -> Option<Profile> {
        self.profile_setting().resolve(self.detected)
    }

    /// Announces the auto profile by STATUSTEXT when it is first known or changes, so the
    /// pilot sees which frame the targets are in; a forced profile is the user's own choice
    /// and is not announced. A pending target formatted for the previous profile is dropped
    /// (the other stack would refuse it).
    pub(super) fn refresh_profile(&mut self) {
        if self.profile_setting() != ProfileSetting::Auto {
            // Back to auto later: announce again.
            self.announced = None;
            return;
        }
        if let Some(p) = self.detected {
            if self.announced != Some(p) {
                if self.announced.is_some() {
                    self.target = None;
                }
                self.announced = Some(p);
                let text = match p {
                    Profile::ArduPilot => "touchdown: profile auto: ArduPilot (BODY_FRD)",
                    Profile::Px4 => "touchdown: profile auto: PX4 (LOCAL_NED)",
                    // Never detected (auto does not choose it).
                    Profile::ArduPilotLocalFrd => "touchdown: profile auto: ArduPilot (LOCAL_FRD)",
                };
                self.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, text);
            }
        }
    }

    pub(super) fn queue_status_text(&mut self, severity: MavSeverity, text: &str) -> bool {
        let mut end = text.len().min(STATUS_TEXT_LEN);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0u8; STATUS_TEXT_LEN];
        if let (Some(dst), Some(src)) = (bytes.get_mut(..end), text.as_bytes().get(..end)) {
            dst.copy_from_slice(src);
        }
        if self
            .status
            .push_back(StatusText {
                severity,
                text: bytes,
            })
            .is_err()
        {
            self.stats.queue_overflows = self.stats.queue_overflows.saturating_add(1);
            return false;
        }
        true
    }

    pub(super) fn pad_motion_setting(&self) -> PadMotionSetting {
        PadMotionSetting::from_param(self.params.get_int(ParamId::PadMotion))
    }

    /// TD_PAD_MOTION 1, or 2 once the pad's velocity has decided it moves.
    pub(super) fn pad_moving(&self) -> bool {
        match self.pad_motion_setting() {
            PadMotionSetting::AtRest => false,
            PadMotionSetting::Moving => true,
            PadMotionSetting::Auto => self.pad_motion.moving(),
        }
    }

    pub(super) fn sysid(&self) -> u8 {
        u8::try_from(self.params.get_int(ParamId::SysId)).unwrap_or(1)
    }

    pub(super) fn compid(&self) -> u8 {
        u8::try_from(self.params.get_int(ParamId::CompId)).unwrap_or(191)
    }

    pub(super) fn time_base(&self) -> TimeBase {
        match TimeBase::from_param(self.params.get_int(ParamId::TimeBase)) {
            TimeBase::ByProfile => match self.profile() {
                // No profile: no target either; the autopilot clock is the contract's default.
                Some(Profile::ArduPilot | Profile::ArduPilotLocalFrd) | None => TimeBase::Autopilot,
                Some(Profile::Px4) => TimeBase::Companion,
            },
            other => other,
        }
    }

    pub(super) fn autopilot_alive(&self, now_us: u64) -> bool {
        self.autopilot_rx_us
            .is_some_and(|t| now_us.saturating_sub(t) <= self.config.autopilot_timeout_us)
    }

    pub(super) fn set_param(&mut self, id: ParamId, value: f32) -> Result<(), ParamError> {
        let old = self.params.get(id);
        self.params.set(id, value)?;
        if id == ParamId::Profile && old != self.params.get(id) {
            self.refresh_profile();
        }
        Ok(())
    }

    pub(super) fn enqueue(&mut self, p: Pending) {
        if self.queue.push_back(p).is_err() {
            self.stats.queue_overflows = self.stats.queue_overflows.saturating_add(1);
        }
    }

    pub(super) fn addressed_to_us(&self, target_system: u8, target_component: u8) -> bool {
        (target_system == 0 || target_system == self.sysid())
            && (target_component == 0 || target_component == self.compid())
    }

    pub(super) fn is_from_autopilot(&self, frame: &RawFrame<'_>) -> bool {
        self.autopilot == Some((frame.system_id, frame.component_id))
    }
}
