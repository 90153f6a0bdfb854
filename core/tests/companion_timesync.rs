//! The companion answers the autopilot's TIMESYNC request first: ahead of a pending
//! LANDING_TARGET and of a parameter list being streamed (checked by pymavlink,
//! `autopilot_sim`), so the autopilot's round trip is not inflated by our queue.

mod autopilot_sim;

use nalgebra::{Matrix3, Matrix6, Vector3};
use serde_json::Value;
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, TIMESYNC_DATA,
};
use touchdown_core::companion::{
    Companion, CompanionConfig, Profile, TargetOutcome, MAX_FRAME_LEN,
};
use touchdown_core::pose::{PadFix, Pose};

use autopilot_sim::{
    decode_with_pymavlink, encode, gcs_message, heartbeat, FixEstimator, ParamAction,
    FRAME_PERIOD_US, PROCESS_DELAY_US,
};

/// A TIMESYNC request is answered by the very next frame out, ahead of a pending target and a
/// parameter list being streamed.
#[test]
fn timesync_reply_goes_ahead_of_the_queue() {
    let mut companion = Companion::new(CompanionConfig::default());
    let mut ap_seq = 0u8;
    let mut gcs_seq = 0u8;
    let mut out = [0u8; MAX_FRAME_LEN];
    let ardupilot = heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    companion.receive(&encode(&mut ap_seq, 1, 1, &ardupilot), 0);
    assert_eq!(companion.profile(), Some(Profile::ArduPilot));
    let mut tx: Vec<(u64, Vec<u8>)> = Vec::new();
    let drain = |c: &mut Companion, now: u64, tx: &mut Vec<(u64, Vec<u8>)>, out: &mut [u8]| {
        while let Some(n) = c.poll_transmit(now, out) {
            tx.push((now, out[..n].to_vec()));
        }
    };
    drain(&mut companion, 0, &mut tx, &mut out);
    // Frames of a pad straight below until a target is pending (no attitude: camera-frame
    // tracker), a parameter list requested, nothing drained.
    let fix = PadFix {
        pose: Pose {
            rotation: Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            translation: Vector3::new(0.1, 0.2, 5.0),
        },
        covariance: Matrix6::identity() * 1e-4,
        markers_used: 1,
        reprojection_rms_px: 0.3,
        alternative_rms_px: f32::INFINITY,
    };
    let mut now = 10_000;
    let mut queued = false;
    let mut estimator = FixEstimator::new();
    for _ in 0..30 {
        now += FRAME_PERIOD_US;
        let outcome = estimator.deliver(&mut companion, now - PROCESS_DELAY_US, Some(fix), now);
        queued = outcome == TargetOutcome::TargetQueued;
        if queued {
            break;
        }
        drain(&mut companion, now, &mut tx, &mut out);
    }
    assert!(queued);
    companion.receive(&gcs_message(&mut gcs_seq, ParamAction::RequestList), now);
    // Let the list start filling the queue (paced), then the autopilot's TIMESYNC request.
    let ts1 = 123_456_789_000i64;
    let request = MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1,
        target_system: 0,
        target_component: 0,
    });
    companion.receive(&encode(&mut ap_seq, 1, 1, &request), now);
    let first = tx.len();
    drain(&mut companion, now, &mut tx, &mut out);
    let Some(msgs) = decode_with_pymavlink("timesync-first", &tx) else {
        return;
    };
    let after: Vec<&Value> = msgs[first..].iter().collect();
    assert!(after.len() >= 3, "{after:?}");
    assert_eq!(after[0]["_type"], "TIMESYNC", "{after:?}");
    assert_eq!(after[0]["ts1"].as_i64(), Some(ts1));
    assert_eq!(after[0]["tc1"].as_i64(), Some(now as i64 * 1000));
    // The rest still goes out: the target, then the queue (parameters among it).
    assert_eq!(after[1]["_type"], "LANDING_TARGET", "{after:?}");
    assert!(after.iter().any(|m| m["_type"] == "PARAM_VALUE"));
}
