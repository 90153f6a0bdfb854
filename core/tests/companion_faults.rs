//! The companion against a simulated autopilot that misbehaves, every emitted byte checked
//! by pymavlink (`autopilot_sim`): garbage, truncated frames and flipped bits on its stream,
//! 10 s of silence, a reboot (its clock restarts, its streams are forgotten), and the pad
//! lost for 1.5 s. Figures are printed; run with `--nocapture` to see them.

mod autopilot_sim;

use touchdown_core::companion::Profile;

use autopilot_sim::{
    accuracy, decode_with_pymavlink, heartbeats_ok, landing_targets, report, simulate, Scenario,
    Target, PROCESS_DELAY_US,
};

#[test]
fn faults_garbage_truncation_bad_crc() {
    let mut s = Scenario::new("faults", Profile::Px4);
    s.corrupt = true;
    s.duration_us = 10_000_000;
    let run = simulate(&s);
    let d = run.damage;
    let st = run.stats;
    println!(
        "[faults] autopilot sent {} frames: {} intact, {} truncated, {} bit-flipped, {} garbage bursts inserted",
        d.frames, d.intact, d.truncated, d.flipped, d.garbage_bursts
    );
    println!(
        "[faults] companion: {} frames accepted, {} bad CRC, {} garbage bytes skipped, {} unknown; \
         dropped {} = exactly the damaged ones",
        st.link.frames,
        st.link.bad_crc,
        st.link.garbage_bytes,
        st.link.unknown,
        d.frames - st.link.frames
    );
    assert!(d.truncated > 10 && d.flipped > 10 && d.garbage_bursts > 10);
    // Every intact frame is found; no damaged one gets through.
    assert_eq!(st.link.frames, d.intact);
    assert!(st.link.bad_crc >= d.truncated + d.flipped - 5);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    let targets = landing_targets(&run, &msgs, s.profile);
    assert!(targets.len() > 250, "{} targets", targets.len());
    let (_, worst) = accuracy(&run, &targets, s.profile);
    assert!(worst <= 1.0);
}

/// When the first LANDING_TARGET at or after `from` was sent.
fn first_target_after(targets: &[Target], from: u64) -> Option<u64> {
    targets.iter().map(|t| t.tx_us).find(|&t| t >= from)
}

#[test]
fn autopilot_silent_for_ten_seconds() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let name = match profile {
            Profile::ArduPilot => "silent-ardupilot",
            Profile::Px4 => "silent-px4",
            Profile::ArduPilotLocalFrd => unreachable!("not run in LOCAL_FRD"),
        };
        let mut s = Scenario::new(name, profile);
        s.duration_us = 18_000_000;
        s.silent = Some((4_000_000, 14_000_000));
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        let targets = landing_targets(&run, &msgs, profile);
        let during = targets
            .iter()
            .filter(|t| t.exposure_us >= 4_100_000 && t.exposure_us < 14_000_000)
            .count();
        let back = run.first_link_frame_after.unwrap();
        let first = first_target_after(&targets, 14_000_000).unwrap();
        println!(
            "[{name}] {during} targets while the autopilot was silent for 10 s; link back at \
             {:.3} s, first target {:.0} ms later",
            back as f64 * 1e-6,
            (first.saturating_sub(back)) as f64 * 1e-3
        );
        match profile {
            // No vehicle state needed: the camera-frame tracker carries on.
            Profile::ArduPilot | Profile::ArduPilotLocalFrd => assert!(during > 280, "{during}"),
            // Vehicle state stale: nothing (the last one within 60 ms + latency of the silence).
            Profile::Px4 => {
                assert_eq!(during, 0);
                assert!(first - back <= 1_000_000, "recovery {} us", first - back);
            }
        }
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
        heartbeats_ok(&run, &msgs, s.duration_us);
    }
}

#[test]
fn autopilot_reboot_resets_the_clock() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let name = match profile {
            Profile::ArduPilot => "reboot-ardupilot",
            Profile::Px4 => "reboot-px4",
            Profile::ArduPilotLocalFrd => unreachable!("not run in LOCAL_FRD"),
        };
        let mut s = Scenario::new(name, profile);
        s.duration_us = 10_000_000;
        s.reboot_at = Some(4_000_000);
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        assert_eq!(run.stats.autopilot_reboots, 1);
        let targets = landing_targets(&run, &msgs, profile);
        let back = run.first_link_frame_after.unwrap();
        // After the reboot the autopilot's clock is ours minus 4 s.
        let new_offset = -4_000_000i64;
        let recovered = targets
            .iter()
            .find(|t| {
                t.tx_us >= back
                    && match profile {
                        Profile::ArduPilot | Profile::ArduPilotLocalFrd => {
                            (t.clock_us - new_offset).abs() <= 1_000
                        }
                        Profile::Px4 => true,
                    }
            })
            .map(|t| t.tx_us)
            .unwrap();
        println!(
            "[{name}] reboot: link back at {:.3} s, first correct target {:.0} ms later",
            back as f64 * 1e-6,
            (recovered - back) as f64 * 1e-3
        );
        assert!(recovered - back <= 1_000_000);
        if profile == Profile::ArduPilot {
            // Once re-synchronised, never the old clock again.
            for t in targets.iter().filter(|t| t.tx_us >= recovered) {
                assert!((t.clock_us - new_offset).abs() <= 1_000, "{t:?}");
            }
        }
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
    }
}

#[test]
fn target_lost_sends_nothing() {
    let mut s = Scenario::new("lost", Profile::ArduPilot);
    s.lost = Some((3_000_000, 4_500_000));
    let run = simulate(&s);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    let targets = landing_targets(&run, &msgs, s.profile);
    let during = targets
        .iter()
        .filter(|t| t.exposure_us >= 3_000_000 && t.exposure_us < 4_500_000)
        .count();
    let last_before = targets
        .iter()
        .filter(|t| t.exposure_us < 3_000_000)
        .map(|t| t.tx_us)
        .max()
        .unwrap();
    let first_after = first_target_after(&targets, 4_500_000).unwrap();
    println!(
        "[lost] pad lost 3.0-4.5 s: {during} targets for lost frames; last target at {:.3} s, \
         next at {:.3} s ({:.0} ms after the pad is back)",
        last_before as f64 * 1e-6,
        first_after as f64 * 1e-6,
        (first_after - 4_500_000) as f64 * 1e-3
    );
    assert_eq!(during, 0);
    assert!(last_before < 3_000_000 + PROCESS_DELAY_US + 5_000);
    assert!(first_after - 4_500_000 < 1_000_000);
}
