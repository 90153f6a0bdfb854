//! Unit tests of the companion's own behaviour (the end-to-end tests with a simulated
//! autopilot are in core/tests/companion_*.rs).

extern crate std;
use std::string::{String, ToString};

use super::*;
use crate::filter::{FrameEstimate, PadEstimate};
use mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavSysStatusSensor, MavType, HEARTBEAT_DATA,
};
use nalgebra::Vector3;

#[test]
fn landing_target_has_extension_fields() {
    assert_eq!(
        <LANDING_TARGET_DATA as MessageData>::ENCODED_LEN,
        LANDING_TARGET_FULL_LEN
    );
}

#[test]
fn heartbeat_first_and_at_one_hertz() {
    let mut c = Companion::new(CompanionConfig::default());
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut heartbeats = 0;
    for ms in 0..3000u64 {
        while let Some(n) = c.poll_transmit(ms * 1000, &mut out) {
            // MAVLink 2, message id 0.
            assert_eq!(out[0], 0xFD);
            assert_eq!(&out[7..10], &[0, 0, 0]);
            assert!(n > 12);
            heartbeats += 1;
        }
    }
    assert_eq!(heartbeats, 3);
}

#[test]
fn status_text_is_sent_once_and_cut_to_the_field() {
    let mut c = Companion::new(CompanionConfig::default());
    let mut out = [0u8; MAX_FRAME_LEN];
    // Drain the first heartbeat.
    while c.poll_transmit(0, &mut out).is_some() {}
    let long = "camera: no frame for 2 s, re-initialising the OV7725 sensor now";
    assert!(long.len() > STATUS_TEXT_LEN);
    assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_ERROR, long));
    let mut texts = 0;
    let mut parser = FrameParser::new();
    while let Some(n) = c.poll_transmit(1000, &mut out) {
        parser.push(&out[..n], |frame| {
            if let Ok(MavMessage::STATUSTEXT(s)) = frame.decode() {
                assert_eq!(s.severity, MavSeverity::MAV_SEVERITY_ERROR);
                assert_eq!(s.text.to_str().unwrap(), &long[..STATUS_TEXT_LEN]);
                texts += 1;
            }
        });
    }
    assert_eq!(texts, 1);
    assert_eq!(c.stats().status_texts, 1);
    // A full queue refuses and counts.
    for _ in 0..STATUS_QUEUE_CAPACITY {
        assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, "x"));
    }
    assert!(!c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, "x"));
    assert_eq!(c.stats().queue_overflows, 1);
    // Multi-byte characters are never split.
    let mut c = Companion::new(CompanionConfig::default());
    let accents = "é".repeat(30); // 60 bytes
    assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, &accents));
    assert_eq!(c.state.status.front().unwrap().text[48..], [0xC3, 0xA9]);
}

fn heartbeat_from(c: &mut Companion, sys: u8, comp: u8, autopilot: MavAutopilot) {
    heartbeat_with(c, sys, comp, autopilot, MavModeFlag::empty());
}

/// ArduPilot's HEARTBEAT from the board's own system, armed or not.
fn ardupilot_heartbeat(c: &mut Companion, armed: bool) {
    let mode = if armed {
        MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
    } else {
        MavModeFlag::empty()
    };
    heartbeat_with(c, 1, 1, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA, mode);
}

fn heartbeat_with(
    c: &mut Companion,
    sys: u8,
    comp: u8,
    autopilot: MavAutopilot,
    base_mode: MavModeFlag,
) {
    let mut out = [0u8; MAX_FRAME_LEN];
    let data = HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot,
        base_mode,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    };
    let n = framing::write_v2_frame(&mut out, 0, sys, comp, &data).unwrap();
    c.receive(&out[..n], 0);
}

#[test]
fn auto_profile_latches_on_the_autopilot_only() {
    let mut c = Companion::new(CompanionConfig::default());
    assert_eq!(c.profile(), None);
    let frame = FrameEstimate {
        exposure_us: 0,
        fix_found: true,
        estimate: Some(PadEstimate {
            body_frd: Vector3::new(0.0, 0.0, 5.0),
            level: None,
            vehicle_position: None,
            orientation_body: None,
            orientation_ned: None,
            view_margin_m: None,
        }),
        mount_correction: None,
    };
    assert_eq!(c.on_estimate(&frame, 1000), TargetOutcome::NoProfile);
    assert_eq!(c.stats().no_profile, 1);
    // A gimbal (component 154), another system's autopilot: ignored.
    heartbeat_from(&mut c, 1, 154, MavAutopilot::MAV_AUTOPILOT_GENERIC);
    heartbeat_from(&mut c, 2, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
    assert_eq!((c.profile(), c.stats().autopilot), (None, None));
    heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
    assert_eq!(c.profile(), Some(Profile::Px4));
    assert_eq!(c.stats().autopilot, Some((1, 1)));
    heartbeat_from(&mut c, 1, 154, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert_eq!(c.profile(), Some(Profile::Px4));
    // Announced once; again when the autopilot changes.
    heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
    assert_eq!(c.state.status.len(), 1);
    heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert_eq!(c.profile(), Some(Profile::ArduPilot));
    assert_eq!(c.state.status.len(), 2);
    // A forced profile wins.
    c.set_param(ParamId::Profile, 1.0).unwrap();
    assert_eq!(c.profile(), Some(Profile::Px4));
}

/// Every sent target's exposure-to-send delay is counted, and the figures reach the ground
/// station after 100 targets and at each doubling of the count, not in between.
#[test]
fn target_latency_is_measured_and_reported_at_doublings() {
    let mut c = Companion::new(CompanionConfig::default());
    heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut reports = std::vec::Vec::new();
    let mut parser = FrameParser::new();
    let mut drain = |c: &mut Companion, now_us: u64, reports: &mut std::vec::Vec<(u32, String)>| {
        while let Some(n) = c.poll_transmit(now_us, &mut out) {
            parser.push(&out[..n], |frame| {
                if let Ok(MavMessage::STATUSTEXT(s)) = frame.decode() {
                    let text = s.text.to_str().unwrap_or("").to_string();
                    if text.contains("lag") {
                        reports.push((c.stats().target_latency.count, text));
                    }
                }
            });
        }
    };
    drain(&mut c, 0, &mut reports);
    let period_us = 100_000; // 10 Hz, TD_RATE_HZ's default passes every frame
    for k in 0..400u64 {
        let exposure_us = 1_000_000 + k * period_us;
        let frame = FrameEstimate {
            exposure_us,
            fix_found: true,
            estimate: Some(PadEstimate {
                body_frd: Vector3::new(0.1, -0.2, 5.0),
                level: None,
                vehicle_position: None,
                orientation_body: None,
                orientation_ned: None,
                view_margin_m: None,
            }),
            mount_correction: None,
        };
        // Processing takes 20 ms, the 100th frame 45 ms.
        let delay_us = if k == 99 { 45_000 } else { 20_000 };
        let now_us = exposure_us + delay_us;
        assert_eq!(
            c.on_estimate(&frame, now_us),
            TargetOutcome::TargetQueued,
            "frame {k}"
        );
        drain(&mut c, now_us, &mut reports);
    }
    let latency = c.stats().target_latency;
    assert_eq!(latency.count, 400);
    assert_eq!((latency.max_us, latency.last_us), (45_000, 20_000));
    assert_eq!(latency.mean_us(), Some(20_062)); // (399 * 20,000 + 45,000) / 400
    let counts: std::vec::Vec<u32> = reports.iter().map(|(n, _)| *n).collect();
    assert_eq!(counts, [100, 200, 400]);
    assert_eq!(reports[0].1, "touchdown: lag 20.3 ms mean, 45.0 ms max");
    assert_eq!(reports[2].1, "touchdown: lag 20.1 ms mean, 45.0 ms max");
}

/// Every frame sent, decoded: the STATUSTEXTs and the PARAM_VALUEs.
fn drain_texts_and_params(
    c: &mut Companion,
    now_us: u64,
) -> (std::vec::Vec<String>, std::vec::Vec<(String, f32)>) {
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut parser = FrameParser::new();
    let (mut texts, mut values) = (std::vec::Vec::new(), std::vec::Vec::new());
    while let Some(n) = c.poll_transmit(now_us, &mut out) {
        parser.push(&out[..n], |frame| match frame.decode() {
            Ok(MavMessage::STATUSTEXT(s)) => texts.push(s.text.to_str().unwrap().to_string()),
            Ok(MavMessage::PARAM_VALUE(v)) => values.push((
                crate::params::name_str(&v.param_id[..]).to_string(),
                v.param_value,
            )),
            _ => {}
        });
    }
    (texts, values)
}

/// A frame (no fix) carrying a mount correction of the mount (0.2, -0.1) deg to (1.21, -1.58).
fn frame_with_correction(exposure_us: u64) -> FrameEstimate {
    FrameEstimate {
        exposure_us,
        fix_found: false,
        estimate: None,
        mount_correction: Some(crate::filter::MountCorrection {
            roll_deg: 1.01,
            pitch_deg: -1.48,
            mount_roll_deg: 1.21,
            mount_pitch_deg: -1.58,
            sigma_deg: 0.06,
            frames: 240,
        }),
    }
}

#[test]
fn a_mount_correction_is_set_announced_and_reported() {
    let mut params = ParamSet::default();
    params.set(ParamId::CamRoll, 0.2).unwrap();
    params.set(ParamId::CamPitch, -0.1).unwrap();
    let mut c = Companion::new(CompanionConfig {
        params,
        ..CompanionConfig::default()
    });
    drain_texts_and_params(&mut c, 0);
    c.on_estimate(&frame_with_correction(1_000_000), 1_020_000);
    assert_eq!(
        (
            c.params().get(ParamId::CamRoll),
            c.params().get(ParamId::CamPitch)
        ),
        (1.21, -1.58)
    );
    let (texts, values) = drain_texts_and_params(&mut c, 1_020_000);
    assert_eq!(texts, ["touchdown: mount r+1.21 p-1.58 deg +-0.06 applied"]);
    assert_eq!(
        values,
        [
            ("TD_CAM_ROLL".to_string(), 1.21),
            ("TD_CAM_PITCH".to_string(), -1.58)
        ]
    );
    let s = c.stats();
    assert_eq!((s.mount_corrections, s.mount_corrections_applied), (1, 1));
    // The settings the pipeline gets next carry the new mount.
    let settings = crate::params::PipelineSettings::from_params(c.params());
    assert_eq!(
        (settings.cam_roll_deg, settings.cam_pitch_deg),
        (1.21, -1.58)
    );
}

#[test]
fn with_td_cam_cal_1_a_correction_is_only_reported_and_with_0_ignored() {
    let mut c = Companion::new(CompanionConfig::default());
    c.set_param(ParamId::CamCal, 1.0).unwrap();
    drain_texts_and_params(&mut c, 0);
    c.on_estimate(&frame_with_correction(1_000_000), 1_020_000);
    assert_eq!(c.params().get(ParamId::CamRoll), 0.0);
    let (texts, values) = drain_texts_and_params(&mut c, 1_020_000);
    assert_eq!(texts, ["touchdown: mount r+1.21 p-1.58 deg +-0.06 not set"]);
    assert!(values.is_empty());
    assert_eq!(
        (
            c.stats().mount_corrections,
            c.stats().mount_corrections_applied
        ),
        (1, 0)
    );
    c.set_param(ParamId::CamCal, 0.0).unwrap();
    c.on_estimate(&frame_with_correction(2_000_000), 2_020_000);
    assert_eq!(drain_texts_and_params(&mut c, 2_020_000).0.len(), 0);
    // Out of range (an estimate beyond +-10 degrees): reported, nothing set.
    c.set_param(ParamId::CamCal, 2.0).unwrap();
    let mut far = frame_with_correction(3_000_000);
    if let Some(m) = far.mount_correction.as_mut() {
        m.mount_roll_deg = -11.5;
    }
    c.on_estimate(&far, 3_020_000);
    assert_eq!(
        (
            c.params().get(ParamId::CamRoll),
            c.params().get(ParamId::CamPitch)
        ),
        (0.0, 0.0)
    );
    let (texts, values) = drain_texts_and_params(&mut c, 3_020_000);
    assert_eq!(
        texts,
        ["touchdown: mount r-11.50 p-1.58 deg +-0.06 too big"]
    );
    assert!(values.is_empty());
}

#[test]
fn footprint_is_small() {
    // The firmware keeps one in static RAM: stay well under 8 KiB.
    let size = core::mem::size_of::<Companion>();
    assert!(size < 8192, "{size} bytes");
}

/// A frame with a fix: the pad at `rel_ned` from the camera, the vehicle at `attitude` and
/// (when given) `position`, so every profile has what it needs.
fn frame_at(
    exposure_us: u64,
    rel_ned: Vector3<f32>,
    attitude: crate::filter::Attitude,
    position: Option<Vector3<f32>>,
) -> FrameEstimate {
    use crate::filter::{Estimate, LevelEstimate, PositionSample};
    let estimate = Estimate {
        t_us: exposure_us,
        position: rel_ned,
        velocity: Vector3::zeros(),
        position_covariance: nalgebra::Matrix3::identity() * 0.01,
        velocity_covariance: nalgebra::Matrix3::identity() * 0.01,
        since_update_us: 0,
    };
    FrameEstimate {
        exposure_us,
        fix_found: true,
        estimate: Some(PadEstimate {
            body_frd: attitude.ned_to_body(&rel_ned),
            level: Some(LevelEstimate {
                estimate,
                attitude,
                mount_sigma_deg: 0.0,
            }),
            vehicle_position: position.map(|position| PositionSample {
                position,
                velocity: Vector3::zeros(),
            }),
            orientation_body: None,
            orientation_ned: Some([1.0, 0.0, 0.0, 0.0]),
            view_margin_m: None,
        }),
        mount_correction: None,
    }
}

/// The LANDING_TARGET (and VISION_POSITION_ESTIMATE) frames the companion sends for `frame`,
/// with TD_PROFILE `profile` and the parameters `params`, the vehicle armed: the decoded
/// target and each message's length on the wire.
fn sent_for(
    profile: f32,
    params: &[(ParamId, f32)],
    frame: &FrameEstimate,
) -> (LANDING_TARGET_DATA, Option<usize>, Option<usize>) {
    let mut c = Companion::new(CompanionConfig::default());
    c.set_param(ParamId::Profile, profile).unwrap();
    for (id, v) in params {
        c.set_param(*id, *v).unwrap();
    }
    ardupilot_heartbeat(&mut c, true);
    let mut out = [0u8; MAX_FRAME_LEN];
    while c.poll_transmit(0, &mut out).is_some() {}
    assert_eq!(c.on_estimate(frame, 1000), TargetOutcome::TargetQueued);
    let (mut target, mut target_len, mut vpe_len) = (None, None, None);
    let mut parser = FrameParser::new();
    while let Some(n) = c.poll_transmit(1000, &mut out) {
        parser.push(&out[..n], |f| match f.decode() {
            Ok(MavMessage::LANDING_TARGET(t)) => {
                target = Some(t);
                target_len = Some(n);
            }
            Ok(MavMessage::VISION_POSITION_ESTIMATE(_)) => vpe_len = Some(n),
            _ => {}
        });
    }
    (target.expect("a LANDING_TARGET"), target_len, vpe_len)
}

#[test]
fn td_cam_pos_moves_the_px4_target_by_the_turned_offset_and_not_the_ardupilot_one() {
    use crate::filter::Attitude;
    use mavlink::dialects::common::MavFrame;
    // Nose east, rolled 10 deg right; the pad 6 m below the camera, the vehicle at (3, -2, -6).
    let att = Attitude::from_euler(0.17, 0.0, core::f32::consts::FRAC_PI_2).unwrap();
    let rel = Vector3::new(0.5, -0.3, 6.0);
    let frame = frame_at(2_000_000, rel, att, Some(Vector3::new(3.0, -2.0, -6.0)));
    let cam_pos = Vector3::new(0.25, -0.1, 0.05);
    let offset = [
        (ParamId::CamPosX, cam_pos.x),
        (ParamId::CamPosY, cam_pos.y),
        (ParamId::CamPosZ, cam_pos.z),
    ];
    let xyz = |t: &LANDING_TARGET_DATA| Vector3::new(t.x, t.y, t.z);
    // PX4: the absolute point moves by R * cam_pos (ArduPilot-style distance unchanged).
    let (px4_0, _, _) = sent_for(1.0, &[], &frame);
    let (px4, _, _) = sent_for(1.0, &offset, &frame);
    assert_eq!(px4.frame, MavFrame::MAV_FRAME_LOCAL_NED);
    let moved = xyz(&px4) - xyz(&px4_0);
    assert!((moved - att.body_to_ned(&cam_pos)).amax() < 1e-5, "{moved}");
    assert!(moved.amax() > 0.1);
    assert_eq!(px4.distance, px4_0.distance);
    // ArduPilot (BODY_FRD and LOCAL_FRD): unchanged, PLND_CAM_POS is ArduPilot's own.
    for profile in [0.0, 3.0] {
        let (ap_0, _, _) = sent_for(profile, &[], &frame);
        let (ap, _, _) = sent_for(profile, &offset, &frame);
        assert_eq!(xyz(&ap), xyz(&ap_0), "TD_PROFILE {profile}");
    }
}

#[test]
fn local_frd_removes_roll_and_pitch_and_falls_back_to_body_frd_without_attitude() {
    use crate::filter::Attitude;
    use mavlink::dialects::common::MavFrame;
    let att = Attitude::from_euler(-0.12, 0.2, 2.5).unwrap();
    let rel = Vector3::new(1.0, 2.0, 7.0);
    let (t, _, _) = sent_for(3.0, &[], &frame_at(1_000_000, rel, att, None));
    assert_eq!(t.frame, MavFrame::MAV_FRAME_LOCAL_FRD);
    let v = Vector3::new(t.x, t.y, t.z);
    // Level: down stays down; turned by the heading back to NED it is the NED vector.
    assert!((att.local_frd_to_ned(&v) - rel).amax() < 1e-5, "{v}");
    // No level estimate (no attitude at the exposure): BODY_FRD from the camera's vector.
    let mut no_att = frame_at(1_000_000, rel, att, None);
    if let Some(e) = no_att.estimate.as_mut() {
        e.level = None;
        e.body_frd = Vector3::new(0.3, 0.1, 5.0);
    }
    let (b, _, _) = sent_for(3.0, &[], &no_att);
    assert_eq!(b.frame, MavFrame::MAV_FRAME_BODY_FRD);
    assert_eq!((b.x, b.y, b.z), (0.3, 0.1, 5.0));
}

/// What the broadcast load in the docs is worked out from: a LANDING_TARGET is 72 bytes on
/// the wire, a VISION_POSITION_ESTIMATE 128 (MAVLink 2 drops the zero reset_counter), a
/// SYS_STATUS 43.
#[test]
fn target_and_vision_estimate_sizes_on_the_wire() {
    use crate::filter::Attitude;
    let frame = frame_at(
        1_000_000,
        Vector3::new(1.0, 2.0, 7.0),
        Attitude::from_euler(0.05, -0.02, 0.3).unwrap(),
        Some(Vector3::new(1.0, 1.0, -7.0)),
    );
    for profile in [0.0, 1.0, 3.0] {
        let (_, target, vpe) = sent_for(profile, &[(ParamId::VpeEnable, 1.0)], &frame);
        assert_eq!((target, vpe), (Some(72), Some(128)), "TD_PROFILE {profile}");
    }
    let (_, _, vpe) = sent_for(0.0, &[], &frame);
    assert_eq!(vpe, None);
    // SYS_STATUS beside the HEARTBEAT with TD_VPE_EN bit 0 (its extensions, all 0, dropped),
    // and none without.
    let sys_status_lengths = |vpe_enable: f32| {
        let mut c = Companion::new(CompanionConfig::default());
        c.set_param(ParamId::VpeEnable, vpe_enable).unwrap();
        let mut out = [0u8; MAX_FRAME_LEN];
        let mut lengths = std::vec::Vec::new();
        let mut parser = FrameParser::new();
        for now_us in [0, 1_000_000] {
            while let Some(n) = c.poll_transmit(now_us, &mut out) {
                parser.push(&out[..n], |f| {
                    if let Ok(MavMessage::SYS_STATUS(_)) = f.decode() {
                        lengths.push(n);
                    }
                });
            }
        }
        lengths
    };
    assert_eq!(sys_status_lengths(1.0), [43, 43]);
    assert!(sys_status_lengths(2.0).is_empty());
}

/// Every SET_MESSAGE_INTERVAL the companion sends in `[from_ms, to_ms)`, polled each
/// millisecond: (time, message id, interval), with every frame's sequence number appended to
/// `sequences`.
fn interval_requests(
    c: &mut Companion,
    from_ms: u64,
    to_ms: u64,
    sequences: &mut std::vec::Vec<u8>,
) -> std::vec::Vec<(u64, u32, f32)> {
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut parser = FrameParser::new();
    let mut requests = std::vec::Vec::new();
    for ms in from_ms..to_ms {
        while let Some(n) = c.poll_transmit(ms * 1000, &mut out) {
            parser.push(&out[..n], |frame| {
                sequences.push(frame.sequence);
                if let Ok(MavMessage::COMMAND_LONG(cmd)) = frame.decode() {
                    assert_eq!(cmd.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
                    assert_eq!((cmd.target_system, cmd.target_component), (1, 1));
                    requests.push((ms, cmd.param1 as u32, cmd.param2));
                }
            });
        }
    }
    requests
}

/// A host tool's stream (`touchdown sitl`'s ground truth) is asked for like the companion's own:
/// at once, again every second while it does not arrive, no more once it flows, again when it
/// stops; every request in the companion's one unbroken sequence.
#[test]
fn a_requested_stream_is_asked_for_until_it_flows_in_the_one_sequence() {
    use mavlink::dialects::common::SIM_STATE_DATA;
    let mut c = Companion::new(CompanionConfig::default());
    assert_eq!(c.request_stream(108, 0), Err(StreamError::ZeroInterval));
    c.request_stream(108, 20_000).unwrap();
    let mut sequences = std::vec::Vec::new();
    // Nobody to ask before the autopilot's HEARTBEAT.
    assert!(interval_requests(&mut c, 0, 500, &mut sequences).is_empty());
    heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    let sim_state_at = |c: &mut Companion, ms: u64| {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = framing::write_v2_frame(&mut out, 0, 1, 1, &SIM_STATE_DATA::DEFAULT).unwrap();
        c.receive(&out[..n], ms * 1000);
    };
    // Silent stream: asked for at once and each second (the attitude with it).
    let sim_state = |r: &[(u64, u32, f32)]| -> std::vec::Vec<u64> {
        r.iter().filter(|q| q.1 == 108).map(|q| q.0).collect()
    };
    let asked = interval_requests(&mut c, 500, 2600, &mut sequences);
    assert_eq!(sim_state(&asked), [500, 1500, 2500]);
    assert!(asked.iter().all(|q| q.1 != 108 || q.2 == 20_000.0));
    assert!(
        asked.iter().any(|q| q.1 == 31),
        "the attitude is asked for too"
    );
    // Flowing: not asked again while it arrives within the stream timeout (its frames keep
    // the autopilot heard, too).
    let mut quiet = std::vec::Vec::new();
    for ms in (2600..5000).step_by(100) {
        sim_state_at(&mut c, ms);
        quiet.extend(interval_requests(&mut c, ms, ms + 100, &mut sequences));
    }
    assert!(sim_state(&quiet).is_empty(), "{quiet:?}");
    // It stops: asked again once the timeout has passed.
    let again = interval_requests(&mut c, 5000, 6200, &mut sequences);
    assert_eq!(sim_state(&again), [5901]);
    // One sender: each frame's sequence number follows the last one's.
    assert!(sequences.len() > 10);
    assert!(sequences.windows(2).all(|w| w[1] == w[0].wrapping_add(1)));
    // A changed interval is asked for at once; the list is bounded.
    c.request_stream(108, 10_000).unwrap();
    let changed = interval_requests(&mut c, 6200, 6201, &mut sequences);
    assert_eq!(changed, [(6200, 108, 10_000.0)]);
    // The same interval again changes nothing: no request before the period is out.
    c.request_stream(108, 10_000).unwrap();
    assert!(interval_requests(&mut c, 6201, 6300, &mut sequences).is_empty());
    for id in 200..(200 + MAX_STREAMS as u32 - 3) {
        c.request_stream(id, 50_000).unwrap();
    }
    assert_eq!(c.request_stream(999, 50_000), Err(StreamError::Full));
}

fn px4_heartbeat(c: &mut Companion, custom_mode: u32, now_us: u64) {
    let mut out = [0u8; MAX_FRAME_LEN];
    let data = HEARTBEAT_DATA {
        custom_mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    };
    let n = framing::write_v2_frame(&mut out, 0, 1, 1, &data).unwrap();
    c.receive(&out[..n], now_us);
}

/// The LOCAL_NED point sent for `frame` now (draining everything else).
fn px4_point(c: &mut Companion, frame: &FrameEstimate, now_us: u64) -> Option<Vector3<f32>> {
    let outcome = c.on_estimate(frame, now_us);
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut parser = FrameParser::new();
    let mut point = None;
    while let Some(n) = c.poll_transmit(now_us, &mut out) {
        parser.push(&out[..n], |f| {
            if let Ok(MavMessage::LANDING_TARGET(t)) = f.decode() {
                point = Some(Vector3::new(t.x, t.y, t.z));
            }
        });
    }
    assert_eq!(outcome == TargetOutcome::TargetQueued, point.is_some());
    point
}

/// PX4 in Precision Land with the vehicle sitting 30 cm south of the pad: the point sent moves
/// north by the integral of the offset (0.15 /s), only in a landing mode, and TD_PX4_OL_ALT 0
/// turns it off; targets keep coming with the camera 12 cm over the pad (at rest on it).
#[test]
fn px4_outer_loop_shifts_the_point_in_precision_land_only() {
    use crate::filter::Attitude;
    const PRECLAND: u32 = (9 << 24) | (4 << 16);
    const LOITER: u32 = (3 << 24) | (4 << 16);
    let att = Attitude::from_euler(0.0, 0.0, 0.4).unwrap();
    let vehicle = Vector3::new(-0.3, 0.0, -4.0);
    let rel = Vector3::new(0.3, 0.0, 4.0);
    let fly = |mode: u32, alt: f32, seconds: u64, height: f32| {
        let mut c = Companion::new(CompanionConfig::default());
        c.set_param(ParamId::Px4OuterLoopAlt, alt).unwrap();
        let mut last = None;
        for k in 0..seconds * 30 {
            let t = 1_000_000 + k * 33_333;
            px4_heartbeat(&mut c, mode, t);
            let mut rel = rel;
            rel.z = height;
            last = px4_point(&mut c, &frame_at(t, rel, att, Some(vehicle)), t + 1000);
        }
        (last.expect("a target"), c.px4_shift())
    };
    let (plain, s0) = fly(LOITER, 8.0, 2, 4.0);
    assert_eq!(s0, nalgebra::Vector2::zeros());
    assert!(
        (plain - Vector3::new(0.0, 0.0, 0.0)).amax() < 1e-5,
        "{plain}"
    );
    let (shifted, s1) = fly(PRECLAND, 8.0, 2, 4.0);
    // About 0.15 /s * 0.3 m * 2 s north, nothing east or down.
    assert!((s1.x - 0.09).abs() < 0.005 && s1.y == 0.0, "{s1}");
    assert!((shifted - plain - Vector3::new(s1.x, s1.y, 0.0)).amax() < 1e-5);
    let (off, s2) = fly(PRECLAND, 0.0, 2, 4.0);
    assert_eq!((off, s2), (plain, nalgebra::Vector2::zeros()));
    // Resting on the pad: still sent (PX4 must not lose the target before it has landed),
    // the shift held (below the floor).
    let (rest, s3) = fly(PRECLAND, 8.0, 2, 0.12);
    assert_eq!(s3, nalgebra::Vector2::zeros());
    assert!(rest.iter().all(|v| v.is_finite()));
}

/// `frame_at`'s frame with the level estimate's position covariance `variance` I and the
/// mount's tilt sigma `mount_sigma_deg`.
fn vision_frame(
    exposure_us: u64,
    rel_ned: Vector3<f32>,
    variance: f32,
    mount_sigma_deg: f32,
) -> FrameEstimate {
    let att = crate::filter::Attitude::from_euler(0.05, -0.03, 0.4).unwrap();
    let mut frame = frame_at(
        exposure_us,
        rel_ned,
        att,
        Some(Vector3::new(1.0, 2.0, -12.0)),
    );
    if let Some(l) = frame.estimate.as_mut().and_then(|e| e.level.as_mut()) {
        l.estimate.position_covariance = nalgebra::Matrix3::identity() * variance;
        l.mount_sigma_deg = mount_sigma_deg;
    }
    frame
}

/// Feeds `frame` at `now_us` to `c` and returns everything it then sends: each frame's
/// message id and its decoded message.
fn sent_after(
    c: &mut Companion,
    frame: &FrameEstimate,
    now_us: u64,
) -> std::vec::Vec<(u32, MavMessage)> {
    let mut out = [0u8; MAX_FRAME_LEN];
    let _ = c.on_estimate(frame, now_us);
    let mut parser = FrameParser::new();
    let mut sent = std::vec::Vec::new();
    while let Some(n) = c.poll_transmit(now_us, &mut out) {
        parser.push(&out[..n], |f| {
            sent.push((f.message_id, f.decode().expect("our own frames decode")));
        });
    }
    sent
}

/// The STATUSTEXTs among `sent`.
fn texts_in(sent: &[(u32, MavMessage)]) -> std::vec::Vec<String> {
    sent.iter()
        .filter_map(|(_, m)| match m {
            MavMessage::STATUSTEXT(s) => Some(s.text.to_str().unwrap().to_string()),
            _ => None,
        })
        .collect()
}

/// Feeds `frame` at `now_us` to `c` and returns the VISION_POSITION_ESTIMATE and the
/// STATUSTEXTs sent for it.
fn vision_sent(
    c: &mut Companion,
    frame: &FrameEstimate,
    now_us: u64,
) -> (Option<VISION_POSITION_ESTIMATE_DATA>, std::vec::Vec<String>) {
    let sent = sent_after(c, frame, now_us);
    let vpe = sent.iter().rev().find_map(|(_, m)| match m {
        MavMessage::VISION_POSITION_ESTIMATE(v) => Some(v.clone()),
        _ => None,
    });
    (vpe, texts_in(&sent))
}

/// A companion for the vision tests: ArduPilot profile, TD_VPE_EN 1, `params` on top, the
/// autopilot armed (in flight), its start-up messages drained.
fn vision_companion(params: &[(ParamId, f32)]) -> Companion {
    let mut c = Companion::new(CompanionConfig::default());
    c.set_param(ParamId::Profile, 0.0).unwrap();
    c.set_param(ParamId::VpeEnable, 1.0).unwrap();
    for (id, v) in params {
        c.set_param(*id, *v).unwrap();
    }
    ardupilot_heartbeat(&mut c, true);
    let mut out = [0u8; MAX_FRAME_LEN];
    while c.poll_transmit(0, &mut out).is_some() {}
    c
}

#[test]
fn vision_estimate_is_the_vehicle_origin_with_the_mount_error_in_its_covariance() {
    let cam_pos = Vector3::new(0.2, -0.1, 0.08);
    let mut c = vision_companion(&[
        (ParamId::CamPosX, cam_pos.x),
        (ParamId::CamPosY, cam_pos.y),
        (ParamId::CamPosZ, cam_pos.z),
    ]);
    let rel = Vector3::new(0.5, -0.3, 12.0);
    let frame = vision_frame(1_000_000, rel, 0.0004, 2.0);
    let (vpe, _) = vision_sent(&mut c, &frame, 1_000_000);
    let vpe = vpe.expect("a VISION_POSITION_ESTIMATE");
    let att = frame.estimate.unwrap().level.unwrap().attitude;
    // The vehicle's origin: minus the pad from the camera, minus the turned lever arm.
    let expected = -(att.body_to_ned(&cam_pos) + rel);
    let got = Vector3::new(vpe.x, vpe.y, vpe.z);
    assert!((got - expected).amax() < 1e-5, "{got} vs {expected}");
    assert!((got + rel).amax() > 0.1, "the lever arm is applied");
    // The mount's 2 degrees and the attitude's slow error across 12 m of line of sight:
    // 0.42 m one sigma, north and east alike, beside which the track's 2 cm and the heading's
    // turn of the 0.58 m beside the pad are small; hardly anything along the line (down).
    let tilt_deg = libm::hypotf(2.0, crate::filter::ATTITUDE_BIAS_DEG);
    let turned = crate::filter::turn_covariance(&rel, tilt_deg.to_radians())
        + super::vision::heading_covariance(&rel, super::vision::HEADING_SIGMA_DEG.to_radians());
    let north = vpe.covariance[0];
    let east = vpe.covariance[6];
    let down = vpe.covariance[11];
    assert!((north - (0.0004 + turned[(0, 0)])).abs() < 1e-5, "{north}");
    assert!((east - (0.0004 + turned[(1, 1)])).abs() < 1e-5, "{east}");
    assert!(turned[(0, 0)] > crate::filter::turn_covariance(&rel, 2f32.to_radians())[(0, 0)]);
    assert!(
        (libm::sqrtf(north) - 0.42).abs() < 0.01,
        "{}",
        libm::sqrtf(north)
    );
    assert!(down < 0.001, "{down}");
    // The same frame with a calibrated mount (0.1 degree): a few centimetres.
    let mut c = vision_companion(&[]);
    let (vpe, _) = vision_sent(
        &mut c,
        &vision_frame(1_000_000, rel, 0.0004, 0.1),
        1_000_000,
    );
    let north = vpe.unwrap().covariance[0];
    assert!(libm::sqrtf(north) < 0.07, "{}", libm::sqrtf(north));
}

#[test]
fn a_heading_error_turns_a_vehicle_beside_the_pad_around_it() {
    // 10 m beside the pad, 2 m up: the heading's turn moves the vehicle across the line to
    // the pad (east, for a pad due north) by 10 m times the heading's sigma; along it
    // (north) hardly at all.
    let mut c = vision_companion(&[]);
    let rel = Vector3::new(10.0, 0.0, 2.0);
    let (vpe, _) = vision_sent(
        &mut c,
        &vision_frame(1_000_000, rel, 0.0001, 0.0),
        1_000_000,
    );
    let cov = vpe.expect("an estimate").covariance;
    let across = 10.0 * super::vision::HEADING_SIGMA_DEG.to_radians();
    assert!(
        (libm::sqrtf(cov[6]) - across).abs() < 0.02 * across,
        "{}",
        cov[6]
    );
    assert!(libm::sqrtf(cov[0]) < 0.2 * across, "{}", cov[0]);
}

#[test]
fn the_reset_counter_steps_when_the_stream_resumes_after_a_gap() {
    let mut c = vision_companion(&[]);
    let rel = Vector3::new(0.1, 0.2, 5.0);
    let mut counters = std::vec::Vec::new();
    // 10 frames at 30 Hz, a gap of 0.6 s (no fix), 10 more, a gap of 0.4 s, 10 more.
    let mut t = 1_000_000u64;
    for (frames, gap_us) in [(10, 600_000u64), (10, 400_000), (10, 0)] {
        for _ in 0..frames {
            let (vpe, _) = vision_sent(&mut c, &vision_frame(t, rel, 0.0004, 0.1), t);
            counters.push(vpe.expect("an estimate").reset_counter);
            t += 33_333;
        }
        let gap_end = t + gap_us;
        while t < gap_end {
            let mut lost = vision_frame(t, rel, 0.0004, 0.1);
            lost.fix_found = false;
            lost.estimate = None;
            let _ = vision_sent(&mut c, &lost, t);
            t += 33_333;
        }
    }
    assert!(counters[..10].iter().all(|&r| r == 0), "{counters:?}");
    assert!(counters[10..].iter().all(|&r| r == 1), "{counters:?}");
    assert_eq!(c.stats().vision_resets, 1);
}

#[test]
fn fit_to_navigate_is_announced_when_it_changes() {
    let mut c = vision_companion(&[]);
    let rel = Vector3::new(0.1, 0.2, 12.0);
    let mut t = 1_000_000u64;
    let mut feed = |c: &mut Companion, mount_sigma_deg: f32, fix: bool| {
        let mut frame = vision_frame(t, rel, 0.0004, mount_sigma_deg);
        if !fix {
            frame.fix_found = false;
            frame.estimate = None;
        }
        let (_, texts) = vision_sent(c, &frame, t);
        t += 33_333;
        texts
    };
    // An uncalibrated mount at 12 m: not fit, and nothing said (it never was).
    assert!(feed(&mut c, 2.0, true).is_empty());
    assert!(!c.stats().vision_fit);
    // Calibrated: fit, said once.
    assert_eq!(
        feed(&mut c, 0.1, true),
        ["touchdown: position fit to navigate +-0.06 m"]
    );
    assert!(feed(&mut c, 0.1, true).is_empty());
    assert!(c.stats().vision_fit);
    // Within the hysteresis (0.12 m: over the 0.10 to become fit, under the 0.15 to stop).
    assert!(feed(&mut c, 0.55, true).is_empty());
    // Worse than that: not fit.
    assert_eq!(
        feed(&mut c, 2.0, true),
        ["touchdown: position not fit +-0.42 m"]
    );
    assert!(!c.stats().vision_fit);
    // Fit again, then the pad lost for more than half a second.
    assert_eq!(feed(&mut c, 0.1, true).len(), 1);
    let texts: std::vec::Vec<String> = (0..20).flat_map(|_| feed(&mut c, 0.1, false)).collect();
    assert_eq!(texts, ["touchdown: position not fit: pad lost"]);
    assert!(!c.stats().vision_fit);
}

/// What `c` sends at `now_us` after `frame`: the message ids, STATUSTEXTs, and the
/// vision-position health of the last SYS_STATUS (`None`: none sent).
fn sent_with_health(
    c: &mut Companion,
    frame: &FrameEstimate,
    now_us: u64,
) -> (std::vec::Vec<u32>, std::vec::Vec<String>, Option<bool>) {
    let sent = sent_after(c, frame, now_us);
    let vision = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_VISION_POSITION;
    let health = sent.iter().rev().find_map(|(_, m)| match m {
        MavMessage::SYS_STATUS(s) => {
            assert!(s.onboard_control_sensors_present.contains(vision));
            Some(s.onboard_control_sensors_health.contains(vision))
        }
        _ => None,
    });
    let ids = sent.iter().map(|(id, _)| *id).collect();
    (ids, texts_in(&sent), health)
}

#[test]
fn before_take_off_only_a_position_fit_to_take_off_on_goes_out() {
    const VPE: u32 = 102;
    const SPEED: u32 = 103;
    // On the pad, velocity too (TD_VPE_EN 3).
    let rel = Vector3::new(0.02, -0.01, 0.25);
    let mut c = vision_companion(&[(ParamId::VpeEnable, 3.0)]);
    ardupilot_heartbeat(&mut c, false);
    let mut t = 1_000_000u64;
    let mut feed = |c: &mut Companion, mount_sigma_deg: f32| {
        let r = sent_with_health(c, &vision_frame(t, rel, 0.0004, mount_sigma_deg), t);
        t += 100_000;
        r
    };
    // The mount not calibrated: nothing the autopilot's arming check could take, said once,
    // unhealthy.
    let mut held = std::vec::Vec::new();
    let mut health = std::vec::Vec::new();
    for _ in 0..20 {
        let (ids, texts, h) = feed(&mut c, 2.0);
        assert!(!ids.contains(&VPE) && !ids.contains(&SPEED), "{ids:?}");
        held.extend(texts);
        health.extend(h);
    }
    assert_eq!(held, ["touchdown: position held: mount not calibrated"]);
    assert!(
        !health.is_empty() && health.iter().all(|h| !h),
        "{health:?}"
    );
    assert_eq!(c.stats().vision_held, 20);
    assert!(!c.stats().vision_fit);
    // Calibrated on the pad: fit, said, sent, healthy; the velocity follows.
    let (ids, texts, _) = feed(&mut c, 0.3);
    assert!(ids.contains(&VPE), "{ids:?}");
    assert_eq!(texts, ["touchdown: position fit to navigate +-0.02 m"]);
    let (mut ids, mut health) = (std::vec::Vec::new(), std::vec::Vec::new());
    for _ in 0..20 {
        let (i, _, h) = feed(&mut c, 0.3);
        ids.extend(i);
        health.extend(h);
    }
    assert!(ids.contains(&SPEED), "{ids:?}");
    assert!(
        !health.is_empty() && health.iter().all(|h| *h),
        "{health:?}"
    );
    assert_eq!(c.stats().vision_held, 20);

    // Armed, the same uncalibrated mount high up: sent, with its covariance, not fit.
    let mut c = vision_companion(&[]);
    let (vpe, texts) = vision_sent(&mut c, &vision_frame(t, rel * 40.0, 0.0004, 2.0), t);
    assert!(vpe.is_some() && texts.is_empty(), "{texts:?}");
    assert!(!c.stats().vision_fit);
    // TD_CAM_CAL 0: the mount was set by hand, nothing to wait for.
    let mut c = vision_companion(&[(ParamId::CamCal, 0.0)]);
    ardupilot_heartbeat(&mut c, false);
    let (vpe, _) = vision_sent(&mut c, &vision_frame(t, rel, 0.0004, 2.0), t);
    assert!(vpe.is_some());
    assert_eq!(c.stats().vision_held, 0);
}

#[test]
fn the_view_margin_goes_out_twice_a_second_with_the_vision_estimates() {
    let rel = Vector3::new(0.1, 0.2, 8.0);
    let margins = |vpe_enable: f32| {
        let mut c = vision_companion(&[(ParamId::VpeEnable, vpe_enable)]);
        let mut out = [0u8; MAX_FRAME_LEN];
        let mut sent = std::vec::Vec::new();
        // 3 s at 30 Hz.
        for k in 0..90u64 {
            let t = 1_000_000 + k * 33_333;
            let mut frame = vision_frame(t, rel, 0.0004, 0.1);
            if let Some(e) = frame.estimate.as_mut() {
                e.view_margin_m = Some(1.25 + k as f32 * 0.01);
            }
            let _ = c.on_estimate(&frame, t + 20_000);
            let mut parser = FrameParser::new();
            while let Some(n) = c.poll_transmit(t + 20_000, &mut out) {
                parser.push(&out[..n], |f| {
                    if let Ok(MavMessage::NAMED_VALUE_FLOAT(v)) = f.decode() {
                        let name = v.name.to_str().unwrap().to_string();
                        // The pad's bearing goes out beside it (its own test).
                        if name != "TD_PAD_BRG" {
                            sent.push((v.time_boot_ms, name, v.value));
                        }
                    }
                });
            }
        }
        sent
    };
    let sent = margins(1.0);
    // Every 0.5 s of exposures: the first frame's, then the first at least 0.5 s after the
    // last one sent (every 16th at 30 Hz).
    assert_eq!(sent.len(), 6, "{sent:?}");
    for (k, (ms, name, value)) in sent.iter().enumerate() {
        assert_eq!(name, "TD_VIEW");
        let frame = 16 * k as u64;
        assert!(
            (value - (1.25 + frame as f32 * 0.01)).abs() < 1e-5,
            "{sent:?}"
        );
        assert_eq!(u64::from(*ms), (1_000_000 + frame * 33_333 + 20_000) / 1000);
    }
    // Only with the vision estimates (TD_VPE_EN bit 0).
    assert!(margins(2.0).is_empty());
}

/// A frame for the pad-bearing tests: the autopilot's heading `heading_error` (radians)
/// clockwise of the truth, so that the pad relative to the vehicle (truly `rel_true`, NED) and
/// the pad's top edge (truly at `pad_bearing`), levelled with that heading, are both seen
/// turned clockwise by it.
fn turned_frame(
    exposure_us: u64,
    rel_true: Vector3<f32>,
    true_yaw: f32,
    pad_bearing: f32,
    heading_error: f32,
) -> FrameEstimate {
    use super::bearing::tests::flat_pad;
    use super::bearing::turn_matrix;
    let att = crate::filter::Attitude::from_euler(0.02, -0.01, true_yaw + heading_error).unwrap();
    let mut frame = frame_at(
        exposure_us,
        turn_matrix(heading_error) * rel_true,
        att,
        None,
    );
    if let Some(e) = frame.estimate.as_mut() {
        e.orientation_ned = Some(flat_pad(pad_bearing + heading_error));
    }
    frame
}

#[test]
fn with_the_pad_bearing_set_the_vision_estimate_holds_the_pads_frame() {
    let rel_true = Vector3::new(-1.5f32, 1.0, 12.0);
    let (true_yaw, pad_bearing) = (0.7f32, 35f32.to_radians());
    let truth = -rel_true;
    let error = 3f32.to_radians();
    // Unset: the autopilot's frame, turned by its heading error, and its own yaw.
    let mut c = vision_companion(&[]);
    let frame = turned_frame(1_000_000, rel_true, true_yaw, pad_bearing, error);
    let vpe = vision_sent(&mut c, &frame, 1_000_000).0.unwrap();
    let got = Vector3::new(vpe.x, vpe.y, vpe.z);
    assert!((got - truth).xy().norm() > 0.08, "turned: {got}");
    assert!((vpe.yaw - (true_yaw + error)).abs() < 1e-4);
    // Set to the pad's bearing: the true position and heading, whatever the autopilot's error.
    let mut c = vision_companion(&[(ParamId::PadYaw, 35.0)]);
    for (k, e) in [error, error, -error].into_iter().enumerate() {
        let t = 1_000_000 + k as u64 * super::vision::RESUME_GAP_US * 2;
        let frame = turned_frame(t, rel_true, true_yaw, pad_bearing, e);
        let (vpe, texts) = vision_sent(&mut c, &frame, t);
        let vpe = vpe.unwrap();
        let got = Vector3::new(vpe.x, vpe.y, vpe.z);
        assert!((got - truth).amax() < 1e-4, "{got} vs {truth}");
        assert!((vpe.yaw - true_yaw).abs() < 1e-4, "{}", vpe.yaw);
        assert!(texts.iter().all(|t| !t.contains("TD_PAD_YAW")), "{texts:?}");
    }
    // Its covariance turned with it: the same, in the pad's frame, whatever the turn.
    let covariance = |error: f32| {
        let mut c = vision_companion(&[(ParamId::PadYaw, 35.0)]);
        let frame = turned_frame(1_000_000, rel_true, true_yaw, pad_bearing, error);
        vision_sent(&mut c, &frame, 1_000_000).0.unwrap().covariance
    };
    let (straight, turned) = (covariance(0.0), covariance(0.5));
    for (a, b) in straight.iter().zip(turned.iter()) {
        assert!((a - b).abs() < 1e-5, "{straight:?} vs {turned:?}");
    }
    assert!(
        (straight[0] - straight[6]).abs() > 1e-3,
        "not isotropic: the test can fail"
    );
}

#[test]
fn a_pad_bearing_far_from_the_heading_is_reported_and_nothing_is_sent_before_a_bearing() {
    let mut c = vision_companion(&[(ParamId::PadYaw, 90.0)]);
    // No usable pad rotation yet: no estimate rather than one in a frame about to turn.
    let mut frame = turned_frame(1_000_000, Vector3::new(0.3, 0.2, 8.0), 0.0, 0.0, 0.0);
    frame.estimate.as_mut().unwrap().orientation_ned = None;
    assert!(vision_sent(&mut c, &frame, 1_000_000).0.is_none());
    // The pad is truly at 0 degrees, the user said 90: the board says so, once.
    let mut warnings = 0;
    for k in 0..10u64 {
        let t = 1_100_000 + k * 66_667;
        let frame = turned_frame(t, Vector3::new(0.3, 0.2, 8.0), 0.0, 0.0, 0.0);
        let (vpe, texts) = vision_sent(&mut c, &frame, t);
        assert!(vpe.is_some());
        warnings += texts
            .iter()
            .filter(|t| t.as_str() == "touchdown: pad 90 deg off heading: TD_PAD_YAW?")
            .count();
    }
    assert_eq!(warnings, 1);
}

#[test]
fn the_pads_bearing_goes_out_twice_a_second_whatever_td_vpe_en() {
    // The pad truly at 35 degrees, the autopilot's heading 3 degrees clockwise of the truth:
    // the board reports the bearing it sees, 38 degrees, for the user to set TD_PAD_YAW from
    // in a flight whose heading GPS holds.
    let mut c = vision_companion(&[(ParamId::VpeEnable, 0.0)]);
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut sent = std::vec::Vec::new();
    for k in 0..30u64 {
        let t = 1_000_000 + k * 33_333;
        let frame = turned_frame(
            t,
            Vector3::new(0.2, 0.1, 6.0),
            0.3,
            35f32.to_radians(),
            3f32.to_radians(),
        );
        let _ = c.on_estimate(&frame, t);
        let mut parser = FrameParser::new();
        while let Some(n) = c.poll_transmit(t, &mut out) {
            parser.push(&out[..n], |f| {
                if let Ok(MavMessage::NAMED_VALUE_FLOAT(v)) = f.decode() {
                    sent.push((v.name.to_str().unwrap().to_string(), v.value, n));
                }
            });
        }
    }
    assert_eq!(sent.len(), 2, "{sent:?}");
    for (name, value, len) in &sent {
        assert_eq!(name, "TD_PAD_BRG");
        // On the wire (docs/setup-ardupilot.md, section 3a): an 18-byte payload and 12.
        assert_eq!(*len, 30);
        assert!((value - 38.0).abs() < 1e-3, "{value}");
    }
}

/// A pad driving 1 m/s north under a vehicle holding still at 12 m, frame by frame at 15 Hz
/// from `t0_us` for `frames` frames: the vision frames (`vision_frame`'s attitude), the pad
/// starting `start_north` metres north.
fn driving_pad_frames(t0_us: u64, start_north: f32, frames: u64) -> std::vec::Vec<FrameEstimate> {
    (0..frames)
        .map(|k| {
            let t = t0_us + k * 66_667;
            let north = start_north + 0.066_667 * k as f32;
            vision_frame(t, Vector3::new(north, 0.3, 12.0), 0.0004, 0.2)
        })
        .collect()
}

#[test]
fn a_pad_driving_off_is_taken_as_moving_and_the_vision_estimates_stop() {
    let mut c = vision_companion(&[]);
    assert_eq!(c.params().get(ParamId::PadMotion), 2.0, "auto by default");
    // Still for 3 s: vision estimates go out, nothing said about motion.
    let mut t = 1_000_000;
    for frame in driving_pad_frames(t, 0.0, 1).iter().cycle().take(45) {
        let frame = FrameEstimate {
            exposure_us: t,
            ..*frame
        };
        let (vpe, texts) = vision_sent(&mut c, &frame, t + 20_000);
        assert!(
            vpe.is_some() && texts.iter().all(|s| !s.contains("pad")),
            "{texts:?}"
        );
        t += 66_667;
    }
    assert!(!c.pad_moving());
    // Then it drives off at 1 m/s: taken as moving once it has kept moving long enough.
    let mut moving_at = None;
    for frame in driving_pad_frames(t, 0.0, 60) {
        let now = frame.exposure_us + 20_000;
        let (vpe, texts) = vision_sent(&mut c, &frame, now);
        if texts
            .iter()
            .any(|s| s == "touchdown: pad moving 1.0 m/s, vision msgs off")
        {
            moving_at = Some(frame.exposure_us - t);
        }
        if moving_at.is_some() {
            assert!(vpe.is_none(), "a vision estimate on a moving pad");
        }
    }
    let after_us = moving_at.expect("never taken as moving");
    assert!((2_000_000..=3_000_000).contains(&after_us), "{after_us}");
    assert!(c.pad_moving());
    let v = c.pad_velocity_ne().expect("a velocity");
    assert!((v - nalgebra::Vector2::new(1.0, 0.0)).norm() < 0.1, "{v}");
    // A mount correction while it moves is reported, not set.
    c.set_param(ParamId::CamCal, 2.0).unwrap();
    c.on_estimate(&frame_with_correction(t + 5_000_000), t + 5_020_000);
    assert_eq!(c.params().get(ParamId::CamRoll), 0.0);
    let (texts, _) = drain_texts_and_params(&mut c, t + 5_020_000);
    assert_eq!(texts, ["touchdown: mount r+1.21 p-1.58 deg +-0.06 not set"]);
}

#[test]
fn with_td_pad_motion_1_nothing_is_decided_and_nothing_from_the_pad_as_ground_goes_out() {
    let mut c = vision_companion(&[(ParamId::PadMotion, 1.0)]);
    assert!(c.pad_moving());
    for frame in driving_pad_frames(1_000_000, 0.0, 60) {
        let (vpe, texts) = vision_sent(&mut c, &frame, frame.exposure_us + 20_000);
        assert!(vpe.is_none() && texts.iter().all(|s| !s.contains("pad moving")));
    }
    assert_eq!(c.stats().pad_motion_changes, 0);
    // With 0 the same drive is not watched: vision estimates go on (the user's word).
    let mut c = vision_companion(&[(ParamId::PadMotion, 0.0)]);
    let frames = driving_pad_frames(1_000_000, 0.0, 60);
    let sent = frames
        .iter()
        .filter(|f| vision_sent(&mut c, f, f.exposure_us + 20_000).0.is_some())
        .count();
    assert_eq!(sent, frames.len());
    assert!(!c.pad_moving() && c.pad_velocity_ne().is_none());
}
