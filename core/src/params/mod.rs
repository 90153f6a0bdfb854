//! The board's MAVLink parameters: a fixed table, range-checked, exportable for flash.
//!
//! What this module offers: [`ParamSet`] (the values, by [`ParamId`], of the table [`PARAMS`]),
//! which the [`crate::companion::Companion`] reads and writes for the ground station;
//! [`PipelineSettings`], what the values set on the per-frame path
//! ([`crate::pipeline::FramePipeline::apply`]); and the flash log the firmware keeps them in,
//! [`Store`] (over the firmware's [`SlotFlash`], in [`Geometry`]) with [`SaveDebounce`] to
//! decide when to save. The log is in the private submodule `persist`, the settings in
//! `settings`.
//!
//! Users tune the board from Mission Planner or QGroundControl through the MAVLink parameter
//! protocol (PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET / PARAM_VALUE); the
//! [`crate::companion::Companion`] speaks the protocol, this module holds the values.
//!
//! Every parameter is sent as `MAV_PARAM_TYPE_REAL32`, integers included. The protocol has two
//! incompatible encodings for integer parameters (ArduPilot's C cast, PX4's bytewise copy) and
//! a ground station picks one from the autopilot's capabilities, which a companion does not
//! announce; a float holding an integral value reads the same in both. Integer parameters
//! refuse non-integral values.
//!
//! A rejected PARAM_SET (unknown name, out of range, not finite, not integral) changes nothing
//! and is answered with the **old** value, which is how a ground station learns that the write
//! failed.
//!
//! The parameters of the per-frame path (TD_TAG_SIZE, TD_MAX_HAMMING, the mount TD_CAM_YAW,
//! TD_CAM_ROLL, TD_CAM_PITCH and its calibration TD_CAM_CAL, the auto-exposure limits
//! TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET) are turned into the settings the pipeline
//! applies by [`PipelineSettings::from_params`]. New parameters are appended to the table:
//! its order is the MAVLink `param_index`, and a blob saved by an older firmware (which ends
//! before them) imports with the new ones at their defaults.
//!
//! Persistence is the firmware's job: [`ParamSet::export`] writes the values as bytes
//! (magic, version, `name + value` records, CRC) and [`ParamSet::import`] reads them back.
//! Records are matched by name, so a firmware with a changed table still reads what it knows;
//! each imported value is range-checked again and a bad one keeps its default.

use crate::crc::crc16_x25;

mod persist;
mod secret;
mod settings;

pub use persist::{
    Boot, Cleanup, FlashFailed, Geometry, Op, Restored, SaveDebounce, SaveError, Saved, SlotFlash,
    SlotKey, Store, ERASED, SAVE_DEBOUNCE_US, SECTORS, SLOT_LEN,
};

pub use secret::{SigningSecret, KEY_LEN};
pub use settings::{LensSettings, PipelineSettings, PAD_DESIGNS, VPE_POSITION, VPE_VELOCITY};

/// Longest parameter name (MAVLink's `param_id`, not NUL-terminated when exactly 16).
pub const PARAM_NAME_LEN: usize = 16;

/// What a parameter holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamKind {
    /// An integer (sent as a float holding an integral value).
    Int,
    /// A real number.
    Real,
}

/// One entry of the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamDef {
    /// Name, at most [`PARAM_NAME_LEN`] ASCII characters.
    pub name: &'static str,
    /// Integer or real.
    pub kind: ParamKind,
    /// Value until set.
    pub default: f32,
    /// Smallest accepted value.
    pub min: f32,
    /// Largest accepted value.
    pub max: f32,
    /// 0 is accepted besides `[min, max]` and means "not set: the build's own value" (for a
    /// parameter whose meaningful range excludes 0, like a marker size).
    pub zero_is_unset: bool,
    /// What it does (for docs and `touchdown companion --list-params`).
    pub help: &'static str,
}

/// The parameters, in table order (the order is the MAVLink `param_index`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ParamId {
    /// Output profile: 0 ArduPilot (BODY_FRD), 1 PX4 (LOCAL_NED), 2 auto (from the
    /// autopilot's HEARTBEAT), 3 ArduPilot 4.7+ (LOCAL_FRD).
    Profile = 0,
    /// Most LANDING_TARGETs per second.
    RateHz,
    /// Edge of the pad's largest marker, metres; the whole pad is scaled to it (a pad printed
    /// at another size). 0: the pad as built.
    TagSize,
    /// Camera mount: rotation about the optical axis from "image top toward the nose", degrees.
    CamYaw,
    /// Largest Hamming distance the decoder accepts.
    MaxHamming,
    /// Our MAVLink system id.
    SysId,
    /// Our MAVLink component id.
    CompId,
    /// Vision estimates sent besides the targets, bits: 1 VISION_POSITION_ESTIMATE, 2 the
    /// vehicle's velocity (ODOMETRY under PX4, VISION_SPEED_ESTIMATE under ArduPilot).
    VpeEnable,
    /// Serial baud rate to the flight controller (applied at boot).
    Baud,
    /// Time base of `time_usec`: 0 by profile, 1 autopilot clock, 2 companion boot clock.
    TimeBase,
    /// Auto-exposure: longest exposure, µs (motion blur).
    ExpMaxUs,
    /// Auto-exposure: highest analog gain, times (noise).
    GainMax,
    /// Auto-exposure: mean grey level aimed for.
    ExpTarget,
    /// Camera mount: roll about body x (forward) after TD_CAM_YAW, degrees.
    CamRoll,
    /// Camera mount: pitch about body y (right) after TD_CAM_ROLL, degrees.
    CamPitch,
    /// In-flight mount calibration: 0 off, 1 estimate and report, 2 estimate, report and
    /// set TD_CAM_ROLL/TD_CAM_PITCH.
    CamCal,
    /// Camera position relative to the vehicle's origin, body x (forward), metres (PX4
    /// profile only: ArduPilot applies its own PLND_CAM_POS).
    CamPosX,
    /// The same, body y (right), metres.
    CamPosY,
    /// The same, body z (down), metres.
    CamPosZ,
    /// PX4 profile: below this camera height over the pad the LOCAL_NED point is shifted
    /// against the vehicle's measured offset from the pad (the outer loop,
    /// `companion::shift`), metres; 0 turns it off.
    Px4OuterLoopAlt,
    /// The bearing of the pad's top edge (+y), degrees clockwise from north: the vision
    /// estimate's frame is held to it (`companion::bearing`); negative: the autopilot's
    /// heading.
    PadYaw,
    /// Whether the pad moves: 0 at rest, 1 moving (a deck, a roof, a dock), 2 auto (decided
    /// from its velocity over the ground, `companion::pad_motion`).
    PadMotion,
    /// The flight lock: 1, while the autopilot reports armed, every parameter but this one is
    /// refused over the link (and the signing key cannot change); 0 off.
    Lock,
    /// The lens's focal length along x, pixels of the board's frames (0: the build's lens).
    CamFx,
    /// The focal length along y, pixels (0: the build's lens).
    CamFy,
    /// The principal point's x, pixels (0: the build's lens).
    CamCx,
    /// The principal point's y, pixels (0: the build's lens).
    CamCy,
    /// Radial distortion k1 (OpenCV's Brown-Conrady order).
    CamK1,
    /// Radial distortion k2.
    CamK2,
    /// Tangential distortion p1.
    CamP1,
    /// Tangential distortion p2.
    CamP2,
    /// Radial distortion k3.
    CamK3,
    /// The pad searched for: 0 the build's, 1-4 a shipped design
    /// ([`PipelineSettings::pad_design`]).
    Pad,
}

/// Number of parameters.
pub const PARAM_COUNT: usize = 33;

/// The table (index = [`ParamId`] as usize).
pub const PARAMS: [ParamDef; PARAM_COUNT] = [
    ParamDef {
        name: "TD_PROFILE",
        kind: ParamKind::Int,
        // Auto by default: a forced profile the autopilot refuses (PX4 drops BODY_FRD) loses
        // every target; the autopilot's HEARTBEAT says which one it takes.
        // 3 (LOCAL_FRD) was added after 0-2 and keeps their meaning: never chosen by auto, as
        // the autopilot's HEARTBEAT does not say whether it takes LOCAL_FRD.
        default: 2.0,
        min: 0.0,
        max: 3.0,
        zero_is_unset: false,
        help: "0 ArduPilot (BODY_FRD), 1 PX4 (LOCAL_NED), 2 auto (HEARTBEAT), 3 ArduPilot 4.7+ (LOCAL_FRD)",
    },
    ParamDef {
        name: "TD_RATE_HZ",
        kind: ParamKind::Int,
        default: 30.0,
        min: 1.0,
        max: 100.0,
        zero_is_unset: false,
        help: "most LANDING_TARGET messages per second",
    },
    ParamDef {
        name: "TD_TAG_SIZE",
        kind: ParamKind::Real,
        default: 0.0,
        min: 0.02,
        max: 5.0,
        zero_is_unset: true,
        help: "edge of the pad's largest marker, metres: the pad is scaled to it (0 = as built)",
    },
    ParamDef {
        name: "TD_CAM_YAW",
        kind: ParamKind::Real,
        default: 0.0,
        min: -180.0,
        max: 180.0,
        zero_is_unset: false,
        help: "camera turned about its optical axis from image-top-forward, degrees",
    },
    ParamDef {
        name: "TD_MAX_HAMMING",
        kind: ParamKind::Int,
        default: 1.0,
        min: 0.0,
        max: 3.0,
        zero_is_unset: false,
        help: "largest corrected bit errors per marker",
    },
    ParamDef {
        name: "TD_SYSID",
        kind: ParamKind::Int,
        default: 1.0,
        min: 1.0,
        max: 255.0,
        zero_is_unset: false,
        help: "our MAVLink system id (the vehicle's)",
    },
    ParamDef {
        name: "TD_COMPID",
        kind: ParamKind::Int,
        default: 191.0,
        min: 1.0,
        max: 255.0,
        zero_is_unset: false,
        help: "our MAVLink component id (191 = MAV_COMP_ID_ONBOARD_COMPUTER)",
    },
    ParamDef {
        name: "TD_VPE_EN",
        kind: ParamKind::Int,
        default: 0.0,
        min: 0.0,
        max: 3.0,
        zero_is_unset: false,
        help: "bits: 1 also send VISION_POSITION_ESTIMATE (vehicle in a pad-centred NED frame), 2 the vehicle's velocity (PX4 ODOMETRY, ArduPilot VISION_SPEED_ESTIMATE)",
    },
    ParamDef {
        name: "TD_BAUD",
        kind: ParamKind::Int,
        default: 921_600.0,
        min: 9_600.0,
        max: 3_000_000.0,
        zero_is_unset: false,
        help: "UART baud rate to the flight controller (applied at boot)",
    },
    ParamDef {
        name: "TD_TIME_BASE",
        kind: ParamKind::Int,
        default: 0.0,
        min: 0.0,
        max: 2.0,
        zero_is_unset: false,
        help: "time_usec clock: 0 by profile, 1 autopilot (TIMESYNC), 2 companion boot",
    },
    // The auto-exposure limits (`sensor::AutoExposureLimits`); the defaults are
    // `AutoExposureLimits::default()` (a test checks it).
    ParamDef {
        name: "TD_EXP_MAX_US",
        kind: ParamKind::Int,
        default: 4_000.0,
        min: 100.0,
        max: 33_000.0,
        zero_is_unset: false,
        help: "longest auto-exposure time, us (motion blur; capped at the frame period)",
    },
    ParamDef {
        name: "TD_GAIN_MAX",
        kind: ParamKind::Real,
        default: 8.0,
        min: 1.0,
        max: 32.0,
        zero_is_unset: false,
        help: "highest auto-exposure analog gain, times (noise)",
    },
    ParamDef {
        name: "TD_EXP_TARGET",
        kind: ParamKind::Int,
        default: 110.0,
        min: 40.0,
        max: 220.0,
        zero_is_unset: false,
        help: "mean grey level (0-255) the auto-exposure aims for",
    },
    // The mount's tilt (see `PipelineSettings::mount`): appended, so the blobs of older
    // firmware, which end before them, keep importing. The range: a camera screwed on by hand
    // is 1-3 degrees off; 10 is far beyond any misalignment and still small enough that the
    // small-tilt reasoning of the estimator holds (a mount meant to look elsewhere is another
    // configured mount, not a calibration).
    ParamDef {
        name: "TD_CAM_ROLL",
        kind: ParamKind::Real,
        default: 0.0,
        min: -10.0,
        max: 10.0,
        zero_is_unset: false,
        help: "camera mount roll about body x (after TD_CAM_YAW), degrees (TD_CAM_CAL=2 sets it)",
    },
    ParamDef {
        name: "TD_CAM_PITCH",
        kind: ParamKind::Real,
        default: 0.0,
        min: -10.0,
        max: 10.0,
        zero_is_unset: false,
        help: "camera mount pitch about body y (after the roll), degrees (TD_CAM_CAL=2 sets it)",
    },
    ParamDef {
        name: "TD_CAM_CAL",
        kind: ParamKind::Int,
        default: 2.0,
        min: 0.0,
        max: 2.0,
        zero_is_unset: false,
        help: "in-flight mount calibration: 0 off, 1 report, 2 report and set TD_CAM_ROLL/PITCH",
    },
    // The camera's position on the vehicle (appended, like the mount's tilt). PX4's LOCAL_NED
    // target is the pad's absolute position and PX4 adds no camera offset to it, so the PX4
    // profile adds it; ArduPilot adds its own PLND_CAM_POS to BODY_FRD and LOCAL_FRD targets,
    // so its profiles do not (both would count it twice). 5 m covers any multicopter's arms.
    ParamDef {
        name: "TD_CAM_POS_X",
        kind: ParamKind::Real,
        default: 0.0,
        min: -5.0,
        max: 5.0,
        zero_is_unset: false,
        help: "camera position forward of the vehicle origin, m (PX4 profile; ArduPilot: PLND_CAM_POS_X)",
    },
    ParamDef {
        name: "TD_CAM_POS_Y",
        kind: ParamKind::Real,
        default: 0.0,
        min: -5.0,
        max: 5.0,
        zero_is_unset: false,
        help: "camera position right of the vehicle origin, m (PX4 profile; ArduPilot: PLND_CAM_POS_Y)",
    },
    ParamDef {
        name: "TD_CAM_POS_Z",
        kind: ParamKind::Real,
        default: 0.0,
        min: -5.0,
        max: 5.0,
        zero_is_unset: false,
        help: "camera position below the vehicle origin, m (PX4 profile; ArduPilot: PLND_CAM_POS_Z)",
    },
    // PX4's outer loop (appended; companion::shift). Off by default: in the closed-loop model
    // it brings PX4's 30-50 cm misses to under 10 cm, but on PX4 SIH (752ecd3d) it made three
    // landings worse (1.2-1.7 m against 0.4-0.7 m without it; docs/setup-px4.md) with the
    // point swinging +-0.5 m at some 12 s: PX4's real lag from our point to the vehicle is
    // longer than measured so far. 15 m is where it would run when switched on: the loop
    // needs some three time constants before the pad leaves the view near 1 m.
    ParamDef {
        name: "TD_PX4_OL_ALT",
        kind: ParamKind::Real,
        default: 0.0,
        min: 0.0,
        max: 50.0,
        zero_is_unset: false,
        help: "PX4 profile, experimental: below this camera height over the pad, shift the target to cancel PX4's steady offset, m (0 off; try 15)",
    },
    // The pad's bearing (appended; companion::bearing). Unset by default: the vision
    // estimate's frame then turns with the autopilot's heading, as it always did.
    ParamDef {
        name: "TD_PAD_YAW",
        kind: ParamKind::Real,
        default: -1.0,
        min: -1.0,
        max: 360.0,
        zero_is_unset: false,
        help: "bearing of the pad's top edge, degrees clockwise from north: VISION_POSITION_ESTIMATE's frame and yaw hold to it (-1 = the autopilot's heading)",
    },
    // Whether the pad moves (appended; companion::pad_motion). Auto by default: a pad at rest
    // is decided at rest and loses nothing, and a user whose pad moves is told so.
    ParamDef {
        name: "TD_PAD_MOTION",
        kind: ParamKind::Int,
        default: 2.0,
        min: 0.0,
        max: 2.0,
        zero_is_unset: false,
        help: "the pad moves: 0 no, 1 yes (no vision estimates, no mount calibration applied), 2 auto (from its velocity over the ground)",
    },
    // On by default: a parameter written in flight (a ground station's whole-file write, or
    // anyone the autopilot routes to the link) changes the geometry under a landing without a
    // sign; the owner who means it sets 0 first.
    ParamDef {
        name: "TD_LOCK",
        kind: ParamKind::Int,
        default: 1.0,
        min: 0.0,
        max: 1.0,
        zero_is_unset: false,
        help: "flight lock: 1 the other parameters and the signing key refuse writes while the autopilot is armed, 0 off",
    },
    // The lens (appended; PipelineSettings::lens): a calibrated camera without rebuilding the
    // firmware. Each of the four intrinsics left at 0 keeps the build's value, so the board
    // runs as built until they are set, and a half-set lens is still a whole camera.
    lens_param("TD_CAM_FX", 1.0, 20_000.0, true, "lens focal length along x, pixels of the board's frames (0 = the build's lens)"),
    lens_param("TD_CAM_FY", 1.0, 20_000.0, true, "lens focal length along y, pixels (0 = the build's lens)"),
    lens_param("TD_CAM_CX", 1.0, 20_000.0, true, "lens principal point x, pixels ((0, 0) = the top-left pixel's centre; 0 = the build's lens)"),
    lens_param("TD_CAM_CY", 1.0, 20_000.0, true, "lens principal point y, pixels (0 = the build's lens)"),
    lens_param("TD_CAM_K1", -5.0, 5.0, false, "lens radial distortion k1 (OpenCV's order)"),
    lens_param("TD_CAM_K2", -5.0, 5.0, false, "lens radial distortion k2"),
    lens_param("TD_CAM_P1", -1.0, 1.0, false, "lens tangential distortion p1"),
    lens_param("TD_CAM_P2", -1.0, 1.0, false, "lens tangential distortion p2"),
    lens_param("TD_CAM_K3", -5.0, 5.0, false, "lens radial distortion k3"),
    // The pad (appended; PipelineSettings::pad_design): a shipped design without rebuilding.
    ParamDef {
        name: "TD_PAD",
        kind: ParamKind::Int,
        default: 0.0,
        min: 0.0,
        max: 4.0,
        zero_is_unset: false,
        help: "pad searched for: 0 the build's, 1 nested-field, 2 nested-rest, 3 nested, 4 paper-single (then scaled by TD_TAG_SIZE)",
    },
];

/// A real lens parameter, 0 by default.
const fn lens_param(
    name: &'static str,
    min: f32,
    max: f32,
    zero_is_unset: bool,
    help: &'static str,
) -> ParamDef {
    ParamDef {
        name,
        kind: ParamKind::Real,
        default: 0.0,
        min,
        max,
        zero_is_unset,
        help,
    }
}

impl ParamId {
    /// All ids in table order.
    pub const ALL: [ParamId; PARAM_COUNT] = [
        ParamId::Profile,
        ParamId::RateHz,
        ParamId::TagSize,
        ParamId::CamYaw,
        ParamId::MaxHamming,
        ParamId::SysId,
        ParamId::CompId,
        ParamId::VpeEnable,
        ParamId::Baud,
        ParamId::TimeBase,
        ParamId::ExpMaxUs,
        ParamId::GainMax,
        ParamId::ExpTarget,
        ParamId::CamRoll,
        ParamId::CamPitch,
        ParamId::CamCal,
        ParamId::CamPosX,
        ParamId::CamPosY,
        ParamId::CamPosZ,
        ParamId::Px4OuterLoopAlt,
        ParamId::PadYaw,
        ParamId::PadMotion,
        ParamId::Lock,
        ParamId::CamFx,
        ParamId::CamFy,
        ParamId::CamCx,
        ParamId::CamCy,
        ParamId::CamK1,
        ParamId::CamK2,
        ParamId::CamP1,
        ParamId::CamP2,
        ParamId::CamK3,
        ParamId::Pad,
    ];

    /// The id at table `index`.
    pub fn from_index(index: usize) -> Option<ParamId> {
        Self::ALL.get(index).copied()
    }

    /// The id named `name` (exact, case-sensitive, as MAVLink names are).
    pub fn from_name(name: &str) -> Option<ParamId> {
        Self::ALL.iter().copied().find(|id| id.def().name == name)
    }

    /// Table index (MAVLink `param_index`).
    pub fn index(self) -> usize {
        self as usize
    }

    /// The table entry.
    pub fn def(self) -> &'static ParamDef {
        // `PARAMS` has one entry per variant; the fallback is never taken.
        PARAMS.get(self.index()).unwrap_or(&PARAMS[0])
    }
}

/// Why a value was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// No parameter of that name or index.
    Unknown,
    /// NaN or infinite.
    NotFinite,
    /// Outside `[min, max]`.
    OutOfRange,
    /// An integer parameter given a fractional value.
    NotIntegral,
}

/// Why [`ParamSet::import`] refused a blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImportError {
    /// Shorter than its header or than the records it announces.
    Truncated,
    /// Not a parameter blob (erased flash reads `0xFF...`).
    BadMagic,
    /// Written by an incompatible format version.
    BadVersion,
    /// The checksum does not match (a torn write).
    BadCrc,
}

/// What [`ParamSet::import`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImportReport {
    /// Values taken over.
    pub applied: u8,
    /// Records whose value failed the range check (the parameter kept its default).
    pub rejected: u8,
    /// Records of names this firmware does not know (ignored).
    pub unknown: u8,
}

/// Blob magic, "TDPR".
const MAGIC: [u8; 4] = *b"TDPR";
/// Blob format version.
const FORMAT_VERSION: u8 = 1;
/// Header: magic (4), version (1), record count (1), CRC-16 (2) over the records.
const HEADER_LEN: usize = 8;
/// One record: name (16, NUL-padded) + value (f32 little-endian).
const RECORD_LEN: usize = PARAM_NAME_LEN + 4;
/// Bytes [`ParamSet::export`] needs: the table's records and the signing secret's.
pub const EXPORT_LEN: usize = HEADER_LEN + (PARAM_COUNT + secret::RECORDS) * RECORD_LEN;
const _: () = assert!(PARAM_COUNT + secret::RECORDS <= u8::MAX as usize);

/// The parameter values, and the signing secret saved with them ([`SigningSecret`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSet {
    values: [f32; PARAM_COUNT],
    secret: SigningSecret,
}

impl Default for ParamSet {
    fn default() -> Self {
        ParamSet {
            values: PARAMS.map(|p| p.default),
            secret: SigningSecret::NONE,
        }
    }
}

/// Checks `value` against `def`: finite, in `[min, max]` (or 0 where that means "unset"),
/// integral for an integer parameter.
pub fn validate(def: &ParamDef, value: f32) -> Result<f32, ParamError> {
    if !value.is_finite() {
        return Err(ParamError::NotFinite);
    }
    if def.zero_is_unset && value == 0.0 {
        return Ok(0.0);
    }
    if !(value >= def.min && value <= def.max) {
        return Err(ParamError::OutOfRange);
    }
    if def.kind == ParamKind::Int && libm::truncf(value) != value {
        return Err(ParamError::NotIntegral);
    }
    // -0.0 and 0.0 compare equal; store the canonical one.
    Ok(if value == 0.0 { 0.0 } else { value })
}

impl ParamSet {
    /// The value of `id`.
    pub fn get(&self, id: ParamId) -> f32 {
        self.values
            .get(id.index())
            .copied()
            .unwrap_or(id.def().default)
    }

    /// The value of `id` as an integer (for [`ParamKind::Int`] parameters).
    pub fn get_int(&self, id: ParamId) -> i32 {
        self.get(id) as i32
    }

    /// Sets `id` to `value` after [`validate`]; the old value stays on error.
    pub fn set(&mut self, id: ParamId, value: f32) -> Result<(), ParamError> {
        let v = validate(id.def(), value)?;
        let slot = self.values.get_mut(id.index()).ok_or(ParamError::Unknown)?;
        *slot = v;
        Ok(())
    }

    /// Sets the parameter named `name` (see [`ParamSet::set`]).
    pub fn set_by_name(&mut self, name: &str, value: f32) -> Result<ParamId, ParamError> {
        let id = ParamId::from_name(name).ok_or(ParamError::Unknown)?;
        self.set(id, value)?;
        Ok(id)
    }

    /// The signing secret (not a parameter: see [`SigningSecret`]).
    pub fn signing_secret(&self) -> &SigningSecret {
        &self.secret
    }

    /// Replaces the signing secret (the companion's SETUP_SIGNING; a host tool's own key).
    pub fn set_signing_secret(&mut self, secret: SigningSecret) {
        self.secret = secret;
    }

    /// Writes the values and the signing secret into `out` for flash; returns the bytes
    /// written (0 when `out` is shorter than [`EXPORT_LEN`]).
    pub fn export(&self, out: &mut [u8]) -> usize {
        self.export_with(PARAM_COUNT, true, out)
    }

    /// [`ParamSet::export`] of the first `records` parameters of the table only, without the
    /// secret: the blob a firmware whose table ended there wrote (the tests' older firmware).
    /// Returns the bytes written (0 when `out` is too short); `records` is capped at
    /// [`PARAM_COUNT`].
    #[cfg(test)]
    pub(crate) fn export_records(&self, records: usize, out: &mut [u8]) -> usize {
        self.export_with(records, false, out)
    }

    /// [`ParamSet::export_records`] with the secret after them: the blob of a firmware with
    /// signing whose table ended after `records` parameters.
    #[cfg(test)]
    pub(crate) fn export_records_with_secret(&self, records: usize, out: &mut [u8]) -> usize {
        self.export_with(records, true, out)
    }

    fn export_with(&self, records: usize, with_secret: bool, out: &mut [u8]) -> usize {
        let table = records.min(PARAM_COUNT);
        let secret = if with_secret { secret::RECORDS } else { 0 };
        let count = table + secret;
        let len = HEADER_LEN + count * RECORD_LEN;
        let Some(out) = out.get_mut(..len) else {
            return 0;
        };
        let (header, records) = out.split_at_mut(HEADER_LEN);
        let table_records = PARAMS
            .iter()
            .zip(self.values.iter())
            .take(table)
            .map(|(def, value)| (def.name, value.to_le_bytes()));
        let secret_records = self.secret.records().into_iter().take(secret);
        for (record, (name_str, value)) in records
            .chunks_exact_mut(RECORD_LEN)
            .zip(table_records.chain(secret_records))
        {
            let (name, val) = record.split_at_mut(PARAM_NAME_LEN);
            name.fill(0);
            for (dst, src) in name.iter_mut().zip(name_str.as_bytes()) {
                *dst = *src;
            }
            val.copy_from_slice(&value);
        }
        let crc = crc16_x25(0xFFFF, records);
        let mut h = [0u8; HEADER_LEN];
        h[..4].copy_from_slice(&MAGIC);
        h[4] = FORMAT_VERSION;
        // The record count fits a byte (checked where EXPORT_LEN is defined).
        h[5] = count as u8;
        h[6..8].copy_from_slice(&crc.to_le_bytes());
        header.copy_from_slice(&h);
        len
    }

    /// Reads a blob written by [`ParamSet::export`] (this or another firmware version):
    /// known names with valid values replace the current ones. Nothing changes on error.
    pub fn import(&mut self, blob: &[u8]) -> Result<ImportReport, ImportError> {
        let header = blob.get(..HEADER_LEN).ok_or(ImportError::Truncated)?;
        if header.get(..4) != Some(&MAGIC[..]) {
            return Err(ImportError::BadMagic);
        }
        if header.get(4) != Some(&FORMAT_VERSION) {
            return Err(ImportError::BadVersion);
        }
        let count = usize::from(header.get(5).copied().unwrap_or(0));
        let crc = u16::from_le_bytes([
            header.get(6).copied().unwrap_or(0),
            header.get(7).copied().unwrap_or(0),
        ]);
        let records = blob
            .get(HEADER_LEN..HEADER_LEN + count * RECORD_LEN)
            .ok_or(ImportError::Truncated)?;
        if crc16_x25(0xFFFF, records) != crc {
            return Err(ImportError::BadCrc);
        }
        let mut report = ImportReport::default();
        let mut next = *self;
        let mut secret = secret::SecretRecords::default();
        for record in records.chunks_exact(RECORD_LEN) {
            let (name, val) = record.split_at(PARAM_NAME_LEN);
            let name = name_str(name);
            let mut v = [0u8; 4];
            v.copy_from_slice(val);
            if secret.take(name, v) {
                continue;
            }
            match ParamId::from_name(name) {
                None => report.unknown = report.unknown.saturating_add(1),
                Some(id) => match next.set(id, f32::from_le_bytes(v)) {
                    Ok(()) => report.applied = report.applied.saturating_add(1),
                    Err(_) => report.rejected = report.rejected.saturating_add(1),
                },
            }
        }
        if let Some(secret) = secret.finish() {
            next.secret = secret;
        }
        *self = next;
        Ok(report)
    }
}

/// The name in a NUL-padded `param_id` (empty when not ASCII/UTF-8).
pub fn name_str(raw: &[u8]) -> &str {
    let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
    core::str::from_utf8(raw.get(..end).unwrap_or(&[])).unwrap_or("")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_consistent() {
        for (i, (def, id)) in PARAMS.iter().zip(ParamId::ALL).enumerate() {
            assert_eq!(id.index(), i);
            assert!(def.name.len() <= PARAM_NAME_LEN, "{}", def.name);
            assert_eq!(validate(def, def.default), Ok(def.default), "{}", def.name);
            assert!(def.min <= def.max, "{}", def.name);
            assert!(
                (def.min <= def.default && def.default <= def.max)
                    || (def.zero_is_unset && def.default == 0.0),
                "{}",
                def.name
            );
            assert_eq!(ParamId::from_name(def.name), Some(id));
        }
    }

    #[test]
    fn zero_means_unset_only_where_declared() {
        let mut p = ParamSet::default();
        // TD_TAG_SIZE: 0 (as built) or 0.02..5 m; nothing in between.
        assert_eq!(p.set(ParamId::TagSize, 0.5), Ok(()));
        assert_eq!(p.set(ParamId::TagSize, 0.01), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::TagSize, -0.5), Err(ParamError::OutOfRange));
        assert_eq!(p.get(ParamId::TagSize), 0.5);
        assert_eq!(p.set(ParamId::TagSize, -0.0), Ok(()));
        assert_eq!(p.get(ParamId::TagSize).to_bits(), 0.0f32.to_bits());
        // Elsewhere 0 is just a value like any other.
        assert_eq!(p.set(ParamId::GainMax, 0.0), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::ExpMaxUs, 0.0), Err(ParamError::OutOfRange));
    }

    #[test]
    fn exposure_params_are_range_checked() {
        let mut p = ParamSet::default();
        assert_eq!(p.set(ParamId::ExpMaxUs, 99.0), Err(ParamError::OutOfRange));
        assert_eq!(
            p.set(ParamId::ExpMaxUs, 33_001.0),
            Err(ParamError::OutOfRange)
        );
        assert_eq!(
            p.set(ParamId::ExpMaxUs, 1_500.5),
            Err(ParamError::NotIntegral)
        );
        assert_eq!(p.set(ParamId::ExpMaxUs, 1_500.0), Ok(()));
        assert_eq!(p.set(ParamId::GainMax, 0.5), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::GainMax, 33.0), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::GainMax, 2.5), Ok(()));
        assert_eq!(p.set(ParamId::ExpTarget, 39.0), Err(ParamError::OutOfRange));
        assert_eq!(
            p.set(ParamId::ExpTarget, 221.0),
            Err(ParamError::OutOfRange)
        );
        assert_eq!(p.set(ParamId::ExpTarget, 90.0), Ok(()));
        assert_eq!(
            (
                p.get(ParamId::ExpMaxUs),
                p.get(ParamId::GainMax),
                p.get(ParamId::ExpTarget)
            ),
            (1_500.0, 2.5, 90.0)
        );
    }

    /// A blob of an older firmware whose table ended before `records` parameters.
    fn older_blob(params: &ParamSet, records: usize) -> [u8; EXPORT_LEN] {
        let mut blob = [0u8; EXPORT_LEN];
        params.export(&mut blob);
        let end = HEADER_LEN + records * RECORD_LEN;
        blob[end..].fill(0);
        blob[5] = records as u8;
        let crc = crc16_x25(0xFFFF, &blob[HEADER_LEN..end]);
        blob[6..8].copy_from_slice(&crc.to_le_bytes());
        blob
    }

    #[test]
    fn a_blob_without_the_newer_params_keeps_their_defaults() {
        let mut saved = ParamSet::default();
        saved.set(ParamId::RateHz, 10.0).unwrap();
        saved.set(ParamId::ExpMaxUs, 2_000.0).unwrap();
        // Saved by a firmware with the first ten parameters only (before TD_EXP_MAX_US).
        let blob = older_blob(&saved, ParamId::ExpMaxUs.index());
        let mut now = ParamSet::default();
        now.set(ParamId::GainMax, 4.0).unwrap();
        let r = now.import(&blob).unwrap();
        assert_eq!((r.applied, r.rejected, r.unknown), (10, 0, 0));
        assert_eq!(now.get(ParamId::RateHz), 10.0);
        // Not in the blob: unchanged.
        assert_eq!(now.get(ParamId::ExpMaxUs), 4_000.0);
        assert_eq!(now.get(ParamId::GainMax), 4.0);
    }

    #[test]
    fn a_blob_of_the_thirteen_parameter_firmware_keeps_the_mount_defaults() {
        // The table before TD_CAM_ROLL, TD_CAM_PITCH and TD_CAM_CAL was appended.
        let mut saved = ParamSet::default();
        saved.set(ParamId::CamYaw, 90.0).unwrap();
        saved.set(ParamId::ExpTarget, 120.0).unwrap();
        saved.set(ParamId::CamRoll, 3.0).unwrap();
        let blob = older_blob(&saved, 13);
        assert_eq!(ParamId::CamRoll.index(), 13);
        let mut now = ParamSet::default();
        let r = now.import(&blob).unwrap();
        assert_eq!((r.applied, r.rejected, r.unknown), (13, 0, 0));
        assert_eq!(
            (now.get(ParamId::CamYaw), now.get(ParamId::ExpTarget)),
            (90.0, 120.0)
        );
        assert_eq!(
            (
                now.get(ParamId::CamRoll),
                now.get(ParamId::CamPitch),
                now.get(ParamId::CamCal)
            ),
            (0.0, 0.0, 2.0)
        );
    }

    #[test]
    fn the_mount_parameters_validate_and_round_trip() {
        let mut p = ParamSet::default();
        assert_eq!(p.set(ParamId::CamRoll, 10.5), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::CamPitch, -10.5), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::CamCal, 3.0), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::CamCal, 1.5), Err(ParamError::NotIntegral));
        p.set(ParamId::CamRoll, 1.21).unwrap();
        p.set(ParamId::CamPitch, -1.58).unwrap();
        p.set(ParamId::CamCal, 1.0).unwrap();
        let mut blob = [0u8; EXPORT_LEN];
        assert_eq!(p.export(&mut blob), EXPORT_LEN);
        let mut q = ParamSet::default();
        assert_eq!(q.import(&blob).unwrap().applied as usize, PARAM_COUNT);
        assert_eq!(q, p);
        assert_eq!(ParamId::from_name("TD_CAM_PITCH"), Some(ParamId::CamPitch));
        assert_eq!(ParamId::from_index(15), Some(ParamId::CamCal));
    }

    #[test]
    fn the_camera_position_validates_and_round_trips() {
        let mut p = ParamSet::default();
        for id in [ParamId::CamPosX, ParamId::CamPosY, ParamId::CamPosZ] {
            assert_eq!(p.get(id), 0.0);
            assert_eq!(p.set(id, 5.5), Err(ParamError::OutOfRange));
            assert_eq!(p.set(id, -5.5), Err(ParamError::OutOfRange));
            assert_eq!(p.set(id, f32::NAN), Err(ParamError::NotFinite));
        }
        p.set(ParamId::CamPosX, 0.12).unwrap();
        p.set(ParamId::CamPosY, -0.05).unwrap();
        p.set(ParamId::CamPosZ, 0.08).unwrap();
        let mut blob = [0u8; EXPORT_LEN];
        assert_eq!(p.export(&mut blob), EXPORT_LEN);
        let mut q = ParamSet::default();
        assert_eq!(q.import(&blob).unwrap().applied as usize, PARAM_COUNT);
        assert_eq!(q, p);
        assert_eq!(ParamId::from_name("TD_CAM_POS_Z"), Some(ParamId::CamPosZ));
        assert_eq!(ParamId::from_index(18), Some(ParamId::CamPosZ));
    }

    #[test]
    fn a_blob_of_the_sixteen_parameter_firmware_keeps_the_camera_at_the_origin() {
        // The table before TD_CAM_POS_X/Y/Z was appended.
        let mut saved = ParamSet::default();
        saved.set(ParamId::CamCal, 1.0).unwrap();
        saved.set(ParamId::CamPosX, 0.3).unwrap();
        let blob = older_blob(&saved, 16);
        assert_eq!(ParamId::CamPosX.index(), 16);
        let mut now = ParamSet::default();
        let r = now.import(&blob).unwrap();
        assert_eq!((r.applied, r.rejected, r.unknown), (16, 0, 0));
        assert_eq!(now.get(ParamId::CamCal), 1.0);
        assert_eq!(now.get(ParamId::CamPosX), 0.0);
    }

    #[test]
    fn td_profile_takes_local_frd_and_nothing_beyond() {
        let mut p = ParamSet::default();
        assert_eq!(p.set(ParamId::Profile, 3.0), Ok(()));
        assert_eq!(p.set(ParamId::Profile, 4.0), Err(ParamError::OutOfRange));
        assert_eq!(p.get(ParamId::Profile), 3.0);
    }

    #[test]
    fn set_validates() {
        let mut p = ParamSet::default();
        assert_eq!(p.set(ParamId::RateHz, 1.0e9), Err(ParamError::OutOfRange));
        assert_eq!(p.set(ParamId::RateHz, f32::NAN), Err(ParamError::NotFinite));
        assert_eq!(p.set(ParamId::RateHz, 2.5), Err(ParamError::NotIntegral));
        assert_eq!(p.get(ParamId::RateHz), 30.0);
        assert_eq!(p.set(ParamId::CamYaw, 90.0), Ok(()));
        assert_eq!(p.get(ParamId::CamYaw), 90.0);
    }

    #[test]
    fn export_import_round_trip_and_corruption() {
        let mut p = ParamSet::default();
        p.set(ParamId::Profile, 1.0).unwrap();
        p.set(ParamId::TagSize, 0.5).unwrap();
        p.set(ParamId::ExpMaxUs, 2_500.0).unwrap();
        p.set(ParamId::GainMax, 3.5).unwrap();
        p.set(ParamId::ExpTarget, 150.0).unwrap();
        let mut blob = [0u8; EXPORT_LEN];
        assert_eq!(p.export(&mut blob), EXPORT_LEN);
        let mut q = ParamSet::default();
        let r = q.import(&blob).unwrap();
        assert_eq!(r.applied as usize, PARAM_COUNT);
        assert_eq!(q, p);
        let mut torn = blob;
        torn[20] ^= 1;
        assert_eq!(q.import(&torn), Err(ImportError::BadCrc));
        assert_eq!(q.import(&[0xFF; EXPORT_LEN]), Err(ImportError::BadMagic));
        assert_eq!(q.import(&blob[..30]), Err(ImportError::Truncated));
    }
}
