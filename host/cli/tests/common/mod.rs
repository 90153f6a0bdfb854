//! What the companion tests share: the autopilot's frames (a HEARTBEAT) as bytes, and a scratch
//! directory under the target directory (not /tmp, where every run would leave one more).
//! Each test binary includes this module with `mod common;`.

use std::path::PathBuf;

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};

/// An ArduCopter HEARTBEAT (system 1, component 1) as MAVLink 2 bytes, sequence `seq`,
/// disarmed.
pub fn ardupilot_heartbeat(seq: u8) -> Vec<u8> {
    ardupilot_heartbeat_with(seq, MavModeFlag::empty())
}

/// An ArduCopter HEARTBEAT as [`ardupilot_heartbeat`]'s, with `base_mode`.
pub fn ardupilot_heartbeat_with(seq: u8, base_mode: MavModeFlag) -> Vec<u8> {
    let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    autopilot_frame(&mut { seq }, &msg)
}

/// `msg` as the autopilot (system 1, component 1) sends it, MAVLink 2, sequence `*seq`, which
/// then steps on.
pub fn autopilot_frame(seq: &mut u8, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: *seq,
        },
        msg,
    );
    *seq = seq.wrapping_add(1);
    raw.raw_bytes().to_vec()
}

/// The scratch directory `name` of the test group `group` under the target directory,
/// emptied: what a previous run left there goes first.
pub fn scratch(group: &str, name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(group)
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}
