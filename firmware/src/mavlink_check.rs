//! Compile-time guard: the MAVLink 2 extension fields must be in the generated messages.
//!
//! LANDING_TARGET (#149) is only useful to ArduPilot and PX4 with its MAVLink 2 extensions
//! (`x`, `y`, `z`, `q`, `type`, `position_valid`), and the mavlink crate generates them in a
//! no_std build only when mavlink-bindgen's `mav2-message-extensions` feature reaches its build
//! script (see the `[build-dependencies]` note in Cargo.toml). If a dependency change ever
//! loses that feature, this module stops compiling instead of the firmware silently sending
//! 30-byte LANDING_TARGETs that flight controllers ignore for precision landing.

use mavlink::dialects::common::{LandingTargetType, MavBool, LANDING_TARGET_DATA};
use mavlink::MessageData;

/// Payload length of LANDING_TARGET with every extension field (30 base bytes + 30).
const FULL_LANDING_TARGET_LEN: usize = 60;

const _: () = assert!(
    <LANDING_TARGET_DATA as MessageData>::ENCODED_LEN == FULL_LANDING_TARGET_LEN,
    "mavlink was generated without MAVLink 2 extension fields"
);

/// Names every extension field issue 5 fills in.
const _: LANDING_TARGET_DATA = LANDING_TARGET_DATA {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    q: [1.0, 0.0, 0.0, 0.0],
    mavtype: LandingTargetType::LANDING_TARGET_TYPE_VISION_FIDUCIAL,
    position_valid: MavBool::MAV_BOOL_TRUE,
    ..LANDING_TARGET_DATA::DEFAULT
};
