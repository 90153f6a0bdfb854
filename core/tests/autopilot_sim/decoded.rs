//! Everything the companion sent, decoded by pymavlink with `robust_parsing` off
//! (`scripts/mavlink_decode.py`: each frame must have a valid CRC), and the decoded values
//! checked against the truth: the LANDING_TARGETs' invariants, frame, time stamp and accuracy
//! (position, angles, the pad's orientation), the HEARTBEAT's rate. Without pymavlink the
//! tests print `skipping: pymavlink not installed` (CI installs it).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use touchdown_core::companion::Profile;

use super::{pad_ned, Run, AP_AHEAD_US, SIGMA_RANGE};

/// pymavlink's decoding of every frame, in order; `None` when pymavlink is not installed.
pub fn decode_with_pymavlink(name: &str, tx: &[(u64, Vec<u8>)]) -> Option<Vec<Value>> {
    let mut path = std::env::temp_dir();
    path.push(format!(
        "touchdown-companion-{name}-{}.bin",
        std::process::id()
    ));
    let bytes: Vec<u8> = tx.iter().flat_map(|(_, b)| b.iter().copied()).collect();
    std::fs::write(&path, &bytes).unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/mavlink_decode.py");
    let output = Command::new("python3").arg(&script).arg(&path).output();
    let _ = std::fs::remove_file(&path);
    let output = match output {
        Ok(o) => o,
        Err(e) => {
            println!("skipping: pymavlink not installed (python3: {e})");
            return None;
        }
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    if output.status.code() == Some(3) {
        println!("skipping: pymavlink not installed");
        return None;
    }
    assert!(
        output.status.success(),
        "pymavlink refused the stream: {stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut msgs: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let summary = msgs.pop().unwrap();
    assert_eq!(summary["_summary"], true);
    assert_eq!(summary["leftover"], 0, "undecoded bytes left");
    assert_eq!(
        msgs.len(),
        tx.len(),
        "pymavlink decoded {} messages from {} frames",
        msgs.len(),
        tx.len()
    );
    for m in &msgs {
        assert_ne!(m["_type"], "BAD_DATA");
        assert_eq!(m["_version"], 2, "{m}");
        assert_eq!(m["_src"], serde_json::json!([1, 191]), "{m}");
    }
    Some(msgs)
}

/// The number `key` of the decoded message `v`.
pub fn f(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("no {key} in {v}"))
}

/// One decoded LANDING_TARGET matched to its frame.
#[derive(Debug, Clone, Copy)]
pub struct Target {
    pub tx_us: u64,
    pub exposure_us: u64,
    /// time_usec minus the exposure (0: our clock; the offset: the autopilot's).
    pub clock_us: i64,
    pub xyz: Vector3<f32>,
    pub angle_x: f32,
    pub angle_y: f32,
    pub distance: f32,
    /// The pad's orientation, decoded (normalised).
    pub q: UnitQuaternion<f32>,
}

/// Checks the LANDING_TARGETs' invariants and matches each to the frame it came from.
pub fn landing_targets(run: &Run, msgs: &[Value], profile: Profile) -> Vec<Target> {
    let mut out = Vec::new();
    for ((tx_us, _), m) in run.tx.iter().zip(msgs) {
        if m["_type"] != "LANDING_TARGET" {
            continue;
        }
        let frame = match profile {
            Profile::ArduPilot => 12,         // MAV_FRAME_BODY_FRD
            Profile::Px4 => 1,                // MAV_FRAME_LOCAL_NED
            Profile::ArduPilotLocalFrd => 20, // MAV_FRAME_LOCAL_FRD
        };
        assert_eq!(m["frame"], frame, "{m}");
        assert_eq!(m["_mlen"], 60, "extension fields missing: {m}");
        assert_eq!(m["type"], 2, "LANDING_TARGET_TYPE_VISION_FIDUCIAL: {m}");
        assert_eq!(m["position_valid"], 1, "{m}");
        assert!(f(m, "distance") > 0.0, "{m}");
        // The frame: processed at most ~200 ms before transmission, and time_usec is its
        // exposure in one of the clocks it may be in (ours, the autopilot's, the rebooted
        // autopilot's), to within 3 ms.
        let time_usec = m["time_usec"].as_u64().unwrap();
        let mut clocks = vec![0i64, AP_AHEAD_US as i64];
        if let Some(r) = run.reboot_at {
            clocks.push(-(r as i64));
        }
        let Some((exposure_us, clock_us)) = run
            .truth
            .range(tx_us.saturating_sub(200_000)..=*tx_us)
            .map(|(&te, _)| (te, time_usec as i64 - te as i64))
            .find(|&(_, c)| clocks.iter().any(|k| (c - k).abs() < 3_000))
        else {
            panic!("LANDING_TARGET at {tx_us} with time_usec {time_usec} matches no frame");
        };
        out.push(Target {
            tx_us: *tx_us,
            exposure_us,
            clock_us,
            xyz: Vector3::new(f(m, "x") as f32, f(m, "y") as f32, f(m, "z") as f32),
            angle_x: f(m, "angle_x") as f32,
            angle_y: f(m, "angle_y") as f32,
            distance: f(m, "distance") as f32,
            q: {
                let q: Vec<f32> = (0..4).map(|k| m["q"][k].as_f64().unwrap() as f32).collect();
                UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]))
            },
        });
    }
    out
}

/// Compares the targets with the truth: returns (RMS error per axis, worst error / allowed).
pub fn accuracy(run: &Run, targets: &[Target], profile: Profile) -> (Vector3<f32>, f32) {
    let mut sq = Vector3::zeros();
    let mut worst = 0.0f32;
    for t in targets {
        let truth = run.truth[&t.exposure_us];
        let expected = match profile {
            Profile::ArduPilot => truth.rel_body,
            Profile::Px4 => pad_ned(),
            Profile::ArduPilotLocalFrd => unreachable!("no LOCAL_FRD scenario here"),
        };
        let err = t.xyz - expected;
        // "Within the pose's accuracy": 4 sigma of one fix's range noise (the filtered value
        // must do better), at least 5 cm.
        let allowed = (4.0 * SIGMA_RANGE * truth.distance).max(0.05);
        worst = worst.max(err.amax() / allowed);
        sq += err.component_mul(&err);
        // angle_x/angle_y/distance consistent with x/y/z (default mount: camera x = body y,
        // camera y = -body x, camera z = body z).
        // ArduPilot's line of sight from the angles (AC_PrecLand_MAVLink, position_valid 0):
        // (-tan(angle_y), tan(angle_x), 1) normalised, body FRD, whatever the mount.
        let los = Vector3::new(-t.angle_y.tan(), t.angle_x.tan(), 1.0).normalize();
        // The pad's orientation: its yaw within a degree (the whole rotation too).
        let want_q = match profile {
            Profile::ArduPilot => truth.pad_body,
            Profile::Px4 => truth.pad_ned,
            Profile::ArduPilotLocalFrd => unreachable!("no LOCAL_FRD scenario here"),
        };
        let yaw_err = (t.q.euler_angles().2 - want_q.euler_angles().2).to_degrees();
        let yaw_err = (yaw_err + 540.0).rem_euclid(360.0) - 180.0;
        assert!(yaw_err.abs() < 1.0, "q yaw off by {yaw_err} deg: {t:?}");
        assert!(t.q.angle_to(&want_q).to_degrees() < 1.0, "{t:?}");
        if profile == Profile::ArduPilot {
            let b = t.xyz;
            assert!((los - b / t.distance).amax() < 1e-4, "{los} {t:?}");
            assert!((t.distance - b.norm()).abs() < 1e-3, "{t:?}");
        } else {
            // The angles are the body vector at the exposure (the autopilot's attitude).
            assert!(
                (los - truth.rel_body.normalize()).amax() < 0.02,
                "{los} {t:?}"
            );
            assert!(
                (t.distance - truth.distance).abs() < 0.1 * truth.distance,
                "{t:?}"
            );
        }
    }
    let n = targets.len().max(1) as f32;
    ((sq / n).map(f32::sqrt), worst)
}

/// Prints what the companion sent and its counters.
pub fn report(name: &str, run: &Run, msgs: &[Value]) {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for m in msgs {
        *counts
            .entry(m["_type"].as_str().unwrap().to_string())
            .or_default() += 1;
    }
    let s = &run.stats;
    println!(
        "[{name}] sent {} frames ({} bytes): {counts:?}",
        s.tx_frames, s.tx_bytes
    );
    println!(
        "[{name}] rx: {} bytes, {} frames ok, {} bad CRC, {} garbage bytes, {} unknown; \
         timesync {} samples (offset {:?} us, source {:?}); reboots {}; targets: {} sent, \
         {} expired, {} no estimate, {} no vehicle state",
        s.link.bytes,
        s.link.frames,
        s.link.bad_crc,
        s.link.garbage_bytes,
        s.link.unknown,
        s.timesync_samples,
        s.clock_offset_us,
        s.time_source,
        s.autopilot_reboots,
        s.landing_targets,
        s.targets_expired,
        s.no_estimate,
        s.no_vehicle_state
    );
}

/// Our HEARTBEATs: an onboard controller's, one a second for the whole flight.
pub fn heartbeats_ok(run: &Run, msgs: &[Value], duration_us: u64) {
    let hb: Vec<u64> = run
        .tx
        .iter()
        .zip(msgs)
        .filter(|(_, m)| m["_type"] == "HEARTBEAT")
        .map(|((t, _), m)| {
            assert_eq!(m["type"], 18, "MAV_TYPE_ONBOARD_CONTROLLER");
            assert_eq!(m["autopilot"], 8, "MAV_AUTOPILOT_INVALID");
            *t
        })
        .collect();
    assert_eq!(hb.len() as u64, duration_us.div_ceil(1_000_000), "{hb:?}");
    for w in hb.windows(2) {
        assert!((w[1] - w[0]).abs_diff(1_000_000) <= 2_000, "{hb:?}");
    }
}
