//! The companion (core/src/companion) against a simulated autopilot of each stack, with every
//! emitted byte checked by pymavlink (`autopilot_sim`): ArduPilot (BODY_FRD targets in its
//! clock, the parameter protocol, VISION_POSITION_ESTIMATE, TIMESYNC answers, stream
//! requests), PX4 (LOCAL_NED targets in our clock, TIMESYNC answered in the millisecond), and
//! TD_PROFILE auto following the autopilot's HEARTBEAT and not a gimbal's. Figures are
//! printed; run with `--nocapture` to see them.

mod autopilot_sim;

use nalgebra::Vector3;
use serde_json::Value;
use touchdown_core::companion::Profile;
use touchdown_core::params::PARAM_COUNT;

use autopilot_sim::{
    accuracy, decode_with_pymavlink, f, heartbeats_ok, landing_targets, pad_ned, report, simulate,
    ParamAction, Run, Scenario, Target, VehiclePath, AP_AHEAD_US, PROCESS_DELAY_US,
};

/// Flies `s` and checks what pymavlink decoded of it: our HEARTBEATs, every LANDING_TARGET's
/// invariants, more than `min_targets` of them, all within the allowed error (their RMS
/// error is printed). `None` without pymavlink.
fn fly_and_check_targets(
    s: &Scenario,
    min_targets: usize,
) -> Option<(Run, Vec<Value>, Vec<Target>)> {
    let run = simulate(s);
    let msgs = decode_with_pymavlink(s.name, &run.tx)?;
    report(s.name, &run, &msgs);
    heartbeats_ok(&run, &msgs, s.duration_us);
    let targets = landing_targets(&run, &msgs, s.profile);
    assert!(targets.len() > min_targets, "{} targets", targets.len());
    let (rms, worst) = accuracy(&run, &targets, s.profile);
    let frame = match s.profile {
        Profile::ArduPilot => "BODY_FRD",
        Profile::Px4 => "LOCAL_NED",
        Profile::ArduPilotLocalFrd => "LOCAL_FRD",
    };
    println!(
        "[{}] {} LANDING_TARGET ({frame}): RMS error x {:.3} y {:.3} z {:.3} m; worst {:.2} of the allowed 4 sigma",
        s.name,
        targets.len(),
        rms.x,
        rms.y,
        rms.z,
        worst
    );
    assert!(worst <= 1.0);
    Some((run, msgs, targets))
}

#[test]
fn ardupilot_profile_pymavlink() {
    let mut s = Scenario::new("ardupilot", Profile::ArduPilot);
    s.vision = 3.0;
    s.params = vec![
        (2_000_000, ParamAction::RequestList),
        (3_000_000, ParamAction::ReadName("TD_RATE_HZ")),
        (3_100_000, ParamAction::ReadIndex(2)),
        // The flight is armed: the flight lock holds the parameters until it is off.
        (3_800_000, ParamAction::Set("TD_TAG_SIZE", 0.4)),
        (3_900_000, ParamAction::Set("TD_LOCK", 0.0)),
        (4_000_000, ParamAction::Set("TD_RATE_HZ", 1.0e9)),
        (4_100_000, ParamAction::Set("TD_TAG_SIZE", f32::NAN)),
        (4_200_000, ParamAction::Set("TD_MAX_HAMMING", 1.5)),
        (4_300_000, ParamAction::Set("TD_TAG_SIZE", 0.5)),
        (4_400_000, ParamAction::Set("TD_NO_SUCH", 1.0)),
    ];
    // 30 Hz for 8 s, less the first frames (track confirmation).
    let Some((run, msgs, targets)) = fly_and_check_targets(&s, 220) else {
        return;
    };
    // time_usec: the autopilot's clock once TIMESYNC has an answer (after ~0.5 s).
    let synced: Vec<_> = targets.iter().filter(|t| t.tx_us > 1_500_000).collect();
    assert!(!synced.is_empty());
    for t in &synced {
        assert!(
            (t.clock_us - AP_AHEAD_US as i64).abs() <= 1_000,
            "time_usec not in the autopilot clock: {t:?}"
        );
    }
    let worst_clock = synced
        .iter()
        .map(|t| (t.clock_us - AP_AHEAD_US as i64).abs())
        .max()
        .unwrap();
    println!(
        "[{}] time_usec vs autopilot clock: worst {worst_clock} us",
        s.name
    );
    // Parameters.
    let pv: Vec<(u64, &Value)> = run
        .tx
        .iter()
        .zip(&msgs)
        .filter(|(_, m)| m["_type"] == "PARAM_VALUE")
        .map(|((t, _), m)| (*t, m))
        .collect();
    let listed: Vec<_> = pv
        .iter()
        .filter(|(t, _)| (2_000_000..3_000_000).contains(t))
        .collect();
    assert_eq!(listed.len(), PARAM_COUNT, "the full list");
    for (k, (_, m)) in listed.iter().enumerate() {
        assert_eq!(m["param_index"], k);
        assert_eq!(m["param_count"], PARAM_COUNT);
        assert_eq!(m["param_type"], 9, "MAV_PARAM_TYPE_REAL32");
    }
    let span = listed.last().unwrap().0 - listed.first().unwrap().0;
    assert!(
        span >= (PARAM_COUNT as u64 - 1) * 19_000,
        "paced: {span} us"
    );
    let by_time = |lo: u64| -> Vec<&Value> {
        pv.iter()
            .filter(|(t, _)| (lo..lo + 50_000).contains(t))
            .map(|(_, m)| *m)
            .collect()
    };
    assert_eq!(by_time(3_000_000)[0]["param_id"], "TD_RATE_HZ");
    assert_eq!(by_time(3_100_000)[0]["param_id"], "TD_TAG_SIZE");
    // Absurd values: answered with the old value.
    let r = by_time(3_800_000);
    assert_eq!(f(r[0], "param_value"), 0.0, "locked in flight: {}", r[0]);
    assert_eq!(f(by_time(3_900_000)[0], "param_value"), 0.0, "TD_LOCK off");
    let r = by_time(4_000_000);
    assert_eq!(
        (r[0]["param_id"].clone(), f(r[0], "param_value")),
        ("TD_RATE_HZ".into(), 30.0)
    );
    let r = by_time(4_100_000);
    assert_eq!(f(r[0], "param_value"), 0.0, "{}", r[0]);
    let r = by_time(4_200_000);
    assert_eq!(f(r[0], "param_value"), 1.0);
    let r = by_time(4_300_000);
    assert!(
        (f(r[0], "param_value") - 0.5).abs() < 1e-6,
        "accepted: {}",
        r[0]
    );
    assert!(by_time(4_400_000).is_empty(), "unknown names get no answer");
    assert_eq!(run.stats.param_sets_rejected, 3);
    assert_eq!(run.stats.param_sets_accepted, 2, "TD_LOCK and TD_TAG_SIZE");
    assert_eq!(run.stats.writes_refused_locked, 1);
    // VISION_POSITION_ESTIMATE: the vehicle in the pad-centred NED frame, with covariance.
    let vpe: Vec<&Value> = msgs
        .iter()
        .filter(|m| m["_type"] == "VISION_POSITION_ESTIMATE")
        .collect();
    assert!(vpe.len() > 200);
    let last = vpe.last().unwrap();
    let t_end = *run.truth.keys().last().unwrap() as f32 * 1e-6;
    let truth = VehiclePath::APPROACH.position(t_end) - pad_ned();
    assert!((f(last, "x") as f32 - truth.x).abs() < 0.3, "{last}");
    assert!((f(last, "z") as f32 - truth.z).abs() < 0.5, "{last}");
    assert_eq!(last["covariance"].as_array().unwrap().len(), 21);
    assert!(last["covariance"][0].as_f64().unwrap() > 0.0, "{last}");
    // VISION_SPEED_ESTIMATE (TD_VPE_EN bit 1): the vehicle's velocity, NED.
    let speeds = velocities(&msgs, "VISION_SPEED_ESTIMATE");
    assert!(speeds.len() > 200, "{}", speeds.len());
    let mut sq = Vector3::<f64>::zeros();
    for m in &speeds {
        // usec: the autopilot's clock once TIMESYNC has an answer, ours before.
        let usec = m["usec"].as_u64().unwrap();
        let ours = if usec > AP_AHEAD_US {
            usec - AP_AHEAD_US
        } else {
            usec
        };
        let truth = VehiclePath::APPROACH.velocity(ours as f32 * 1e-6);
        for (axis, key) in ["x", "y", "z"].into_iter().enumerate() {
            sq[axis] += (f(m, key) - truth[axis] as f64).powi(2);
        }
    }
    let rms = (sq / speeds.len() as f64).map(f64::sqrt);
    println!("[ardupilot] VISION_SPEED_ESTIMATE: RMS error {rms:.3?} m/s");
    assert!(rms.max() < 0.2, "{rms:?}");
    let last = speeds.last().unwrap();
    let cov = last["covariance"].as_array().unwrap();
    assert_eq!(cov.len(), 9);
    for k in [0, 4, 8] {
        let v = cov[k].as_f64().unwrap();
        assert!(v > 0.0 && v < 0.1, "{last}");
    }
    // TIMESYNC answers to the autopilot's requests, SET_MESSAGE_INTERVAL requests.
    let answers = msgs
        .iter()
        .filter(|m| m["_type"] == "TIMESYNC" && m["tc1"].as_i64() != Some(0))
        .count();
    assert!(answers >= 7, "{answers} TIMESYNC answers");
    let requests = msgs
        .iter()
        .filter(|m| m["_type"] == "COMMAND_LONG" && m["command"] == 511)
        .count();
    assert!(requests >= 1);
    assert!(run.stats.interval_acks_accepted >= 1);
}

/// The decoded messages of type `kind`, in order.
fn velocities<'a>(msgs: &'a [Value], kind: &str) -> Vec<&'a Value> {
    msgs.iter().filter(|m| m["_type"] == kind).collect()
}

#[test]
fn px4_profile_pymavlink() {
    let mut s = Scenario::new("px4", Profile::Px4);
    s.vision = 2.0;
    let Some((run, msgs, targets)) = fly_and_check_targets(&s, 200) else {
        return;
    };
    // ODOMETRY (TD_VPE_EN bit 2): the velocity alone, in PX4's NED axes, as EKF2 reads it:
    // position and attitude NaN (None here), the velocity variances at 0, 6 and 11 of the
    // 6 x 6 upper triangle, estimator type VISION. No VISION_POSITION_ESTIMATE (bit 0 clear).
    assert_eq!(velocities(&msgs, "VISION_POSITION_ESTIMATE").len(), 0);
    assert_eq!(velocities(&msgs, "VISION_SPEED_ESTIMATE").len(), 0);
    let odometry = velocities(&msgs, "ODOMETRY");
    assert!(odometry.len() > 200, "{}", odometry.len());
    assert_eq!(run.stats.vision_velocities as usize, odometry.len());
    // Against the path's velocity at each exposure: the RMS error small, and inside what the
    // message claims (its variance) on every axis.
    let mut sq = Vector3::<f64>::zeros();
    let mut sum = Vector3::<f64>::zeros();
    let mut claimed = Vector3::<f64>::zeros();
    for m in &odometry {
        let t = m["time_usec"].as_u64().unwrap() as f32 * 1e-6;
        let truth = VehiclePath::APPROACH.velocity(t);
        let cov = m["velocity_covariance"].as_array().unwrap();
        for (axis, (key, k)) in [("vx", 0), ("vy", 6), ("vz", 11)].into_iter().enumerate() {
            sq[axis] += (f(m, key) - truth[axis] as f64).powi(2);
            sum[axis] += f(m, key) - truth[axis] as f64;
            claimed[axis] += cov[k].as_f64().unwrap();
        }
    }
    let n = odometry.len() as f64;
    let rms = (sq / n).map(f64::sqrt);
    let sigma = (claimed / n).map(f64::sqrt);
    println!(
        "[px4] ODOMETRY velocity: RMS error {rms:.3?} m/s (mean {:.3?}), claimed sigma {sigma:.3?}",
        sum / n
    );
    for axis in 0..3 {
        assert!(rms[axis] < 0.2, "{rms:?}");
        assert!(rms[axis] < sigma[axis], "{rms:?} vs claimed {sigma:?}");
    }
    let last = odometry.last().unwrap();
    for key in ["x", "y", "z", "rollspeed"] {
        assert!(last[key].is_null(), "{key} not NaN: {last}");
    }
    assert!(last["q"][0].is_null(), "{last}");
    assert!(last["pose_covariance"][0].is_null(), "{last}");
    assert_eq!((f(last, "frame_id"), f(last, "child_frame_id")), (1.0, 1.0));
    assert_eq!(f(last, "estimator_type"), 2.0, "MAV_ESTIMATOR_TYPE_VISION");
    let cov = last["velocity_covariance"].as_array().unwrap();
    for k in [0, 6, 11] {
        let v = cov[k].as_f64().unwrap();
        assert!(v > 0.0 && v < 0.1, "{k}: {last}");
    }
    // Sent with the target it belongs to: the same time stamp (our exposure time).
    let stamps: std::collections::BTreeSet<u64> = targets.iter().map(|t| t.exposure_us).collect();
    assert!(odometry
        .iter()
        .all(|m| stamps.contains(&m["time_usec"].as_u64().unwrap())));
    // PX4 converts time_usec itself (its TIMESYNC with us): our exposure time, exactly.
    for t in &targets {
        assert_eq!(t.clock_us, 0, "{t:?}");
    }
    // Both streams requested.
    let requested: Vec<f64> = msgs
        .iter()
        .filter(|m| m["_type"] == "COMMAND_LONG" && m["command"] == 511)
        .map(|m| f(m, "param1"))
        .collect();
    assert!(
        requested.contains(&31.0) && requested.contains(&32.0),
        "{requested:?}"
    );
    // Every answer to PX4's TIMESYNC requests goes out in the millisecond its request
    // arrived (tc1 is our time at receipt, in ns), whatever else was waiting.
    let answers: Vec<(u64, i64)> = run
        .tx
        .iter()
        .zip(&msgs)
        .filter(|(_, m)| m["_type"] == "TIMESYNC" && m["tc1"].as_i64() != Some(0))
        .map(|((t, _), m)| (*t, m["tc1"].as_i64().unwrap()))
        .collect();
    assert!(answers.len() >= 7, "{answers:?}");
    for (tx_us, tc1) in answers {
        assert_eq!(tx_us as i64, tc1 / 1000, "answered late");
    }
}

/// The STATUSTEXTs sent, in order.
fn status_texts(msgs: &[Value]) -> Vec<String> {
    msgs.iter()
        .filter(|m| m["_type"] == "STATUSTEXT")
        .map(|m| {
            m["text"]
                .as_str()
                .unwrap()
                .trim_end_matches('\0')
                .to_string()
        })
        .collect()
}

#[test]
fn auto_profile_follows_the_autopilot_heartbeat_not_a_gimbal() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let (name, announcement) = match profile {
            Profile::ArduPilot => (
                "auto-ardupilot",
                "touchdown: profile auto: ArduPilot (BODY_FRD)",
            ),
            Profile::Px4 => ("auto-px4", "touchdown: profile auto: PX4 (LOCAL_NED)"),
            Profile::ArduPilotLocalFrd => unreachable!("auto never chooses LOCAL_FRD"),
        };
        let mut s = Scenario::new(name, profile);
        s.auto = true;
        // A gimbal heartbeats from the start (before the autopilot is heard, and just before
        // each of its heartbeats); the autopilot's first heartbeat comes at 1 s.
        s.gimbal = true;
        s.autopilot_from_us = 1_000_000;
        // A pad turned by 30 degrees under a camera turned by 90 (TD_CAM_YAW).
        s.pad_yaw = 30f32.to_radians();
        s.cam_yaw_deg = 90.0;
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        // The frame each stack takes (checked per target by `landing_targets`), and the pad's
        // orientation and the angles (checked per target by `accuracy`).
        let targets = landing_targets(&run, &msgs, profile);
        assert!(targets.len() > 180, "{} targets", targets.len());
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
        // Nothing until the autopilot said what it is (its heartbeat arrives at 1.003 s).
        let first = targets.first().unwrap().tx_us;
        assert!(
            first >= 1_003_000,
            "target at {first} us before the autopilot"
        );
        assert!(run.stats.no_profile >= 20, "{}", run.stats.no_profile);
        // The autopilot is 1/1, the gimbal never took over, the choice announced once.
        assert_eq!(run.stats.autopilot, Some((1, 1)));
        let (announced, lags): (Vec<String>, Vec<String>) = status_texts(&msgs)
            .into_iter()
            .partition(|t| t.starts_with("touchdown: profile"));
        assert_eq!(announced, vec![announcement.to_string()]);
        // The exposure-to-send delay, reported after 100 targets and at each doubling: the
        // simulated processing delay (PROCESS_DELAY_US) plus up to one poll of the loop.
        let sent = run.stats.landing_targets;
        let expected = [100, 200, 400, 800].iter().filter(|&&n| sent >= n).count();
        assert_eq!(lags.len(), expected, "{lags:?} after {sent} targets");
        let process_ms = PROCESS_DELAY_US as f64 / 1000.0;
        for lag in &lags {
            let mean: f64 = lag
                .strip_prefix("touchdown: lag ")
                .and_then(|rest| rest.split(' ').next())
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("not a lag report: {lag}"));
            assert!(
                (process_ms..process_ms + 2.0).contains(&mean),
                "{lag}: expected {process_ms} ms and a little"
            );
        }
        println!(
            "[{name}] first target at {:.3} s; {} frames with a fix before the autopilot was \
             identified; announced: {announcement}",
            first as f64 * 1e-6,
            run.stats.no_profile
        );
        heartbeats_ok(&run, &msgs, s.duration_us);
    }
}

/// VISION_POSITION_ESTIMATE's covariance holds what the board does not know: with the camera
/// mount tilted 2.1 degrees from what the board was told, and no calibration applied, the
/// position it sends of the vehicle is within two of its reported horizontal sigmas of the
/// truth in at least 95 % of the messages (the mount's error alone is some 0.3 m at these
/// 10-12 m, which the level track's own covariance, centimetres, does not hold).
#[test]
fn vision_estimate_error_is_within_its_covariance_pymavlink() {
    let mut s = Scenario::new("vision-mount", Profile::ArduPilot);
    s.vision = 1.0;
    s.mount_error_deg = (1.5, -1.5);
    let run = simulate(&s);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    let vpe = velocities(&msgs, "VISION_POSITION_ESTIMATE");
    assert!(vpe.len() > 200, "{}", vpe.len());
    let (mut inside, mut worst_error, mut sigmas) = (0usize, 0.0f64, Vec::new());
    for m in &vpe {
        let usec = m["usec"].as_u64().unwrap();
        let ours = if usec > AP_AHEAD_US {
            usec - AP_AHEAD_US
        } else {
            usec
        };
        let truth = VehiclePath::APPROACH.position(ours as f32 * 1e-6) - pad_ned();
        let error = (f(m, "x") - truth.x as f64).hypot(f(m, "y") - truth.y as f64);
        let cov = m["covariance"].as_array().unwrap();
        let sigma = cov[0]
            .as_f64()
            .unwrap()
            .max(cov[6].as_f64().unwrap())
            .sqrt();
        inside += usize::from(error <= 2.0 * sigma);
        worst_error = worst_error.max(error);
        sigmas.push(sigma);
    }
    sigmas.sort_by(f64::total_cmp);
    let share = inside as f64 / vpe.len() as f64;
    println!(
        "[{}] {} VISION_POSITION_ESTIMATEs: {:.1} % within 2 sigma; worst error {:.3} m; \
         median sigma {:.3} m",
        s.name,
        vpe.len(),
        100.0 * share,
        worst_error,
        sigmas[sigmas.len() / 2]
    );
    assert!(
        worst_error > 0.15,
        "the mount's error is there to be covered"
    );
    assert!(share >= 0.95, "{share}");
    // Not fit to navigate on: nothing announced as fit, and SYS_STATUS (once a second)
    // says the vision position is there, on, and not healthy.
    assert!(!status_texts(&msgs)
        .iter()
        .any(|t| t.starts_with("touchdown: position fit")));
    const VISION_POSITION: u64 = 128;
    let health: Vec<(u64, u64, u64)> = msgs
        .iter()
        .filter(|m| m["_type"] == "SYS_STATUS")
        .map(|m| {
            for k in ["present", "enabled", "health"] {
                let extended = format!("onboard_control_sensors_{k}_extended");
                assert_eq!(m[&extended].as_u64(), Some(0), "{m}");
            }
            let bits = |k: &str| m[k].as_u64().unwrap() & VISION_POSITION;
            (
                bits("onboard_control_sensors_present"),
                bits("onboard_control_sensors_enabled"),
                bits("onboard_control_sensors_health"),
            )
        })
        .collect();
    let seconds = (s.duration_us / 1_000_000) as usize;
    assert!(health.len() >= seconds, "{} SYS_STATUS", health.len());
    assert!(
        health
            .iter()
            .all(|&h| h == (VISION_POSITION, VISION_POSITION, 0)),
        "{health:?}"
    );
}
