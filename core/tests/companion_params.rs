//! The camera parameters (TD_TAG_SIZE, TD_MAX_HAMMING, the auto-exposure limits
//! TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET, and the mount's TD_CAM_ROLL and TD_CAM_CAL),
//! without pymavlink: a ground station's
//! PARAM_SETs are range-checked, the resulting vision settings are what the firmware's vision
//! task applies, and the values survive the flash log across a reboot, read back by name and by
//! index. (The parameter protocol on the wire, decoded by pymavlink, is in
//! `companion_profiles.rs`.)

mod autopilot_sim;

use touchdown_core::companion::mavlink::dialects::common::MavMessage;
use touchdown_core::companion::{Companion, CompanionConfig, FrameParser, MAX_FRAME_LEN};
use touchdown_core::detect::DetectorConfig;
use touchdown_core::filter::MountCalibrationMode;
use touchdown_core::pad::designs;
use touchdown_core::params::name_str;
use touchdown_core::params::{
    FlashFailed, Geometry, ParamId, ParamSet, PipelineSettings, SlotFlash, SlotKey, Store, ERASED,
    PARAM_COUNT, SECTORS, SLOT_LEN,
};
use touchdown_core::sensor::{AutoExposureLimits, GainX16};

use autopilot_sim::{gcs_message, ParamAction};

/// Sends `action` from the ground station at `now` and returns every PARAM_VALUE the
/// companion answers with (name, value), decoded by our own parser.
fn ground_station(
    companion: &mut Companion,
    seq: &mut u8,
    action: ParamAction,
    now: u64,
) -> Vec<(String, f32)> {
    companion.receive(&gcs_message(seq, action), now);
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut parser = FrameParser::new();
    let mut values = Vec::new();
    while let Some(n) = companion.poll_transmit(now, &mut out) {
        parser.push(&out[..n], |raw| {
            if let Ok(MavMessage::PARAM_VALUE(v)) = raw.decode() {
                values.push((name_str(&v.param_id[..]).to_string(), v.param_value));
            }
        });
    }
    values
}

#[test]
fn camera_params_are_range_checked_applied_and_persisted() {
    let mut companion = Companion::new(CompanionConfig::default());
    let mut seq = 0u8;
    let mut now = 1_000_000u64;
    // (name, value sent, value answered: the new one if accepted, else the old one)
    let sets: [(&str, f32, f32); 21] = [
        ("TD_EXP_MAX_US", 2_000.0, 2_000.0),
        ("TD_EXP_MAX_US", 50.0, 2_000.0),     // below 100 us
        ("TD_EXP_MAX_US", 40_000.0, 2_000.0), // above 33 ms
        ("TD_EXP_MAX_US", 1_500.5, 2_000.0),  // an integer
        ("TD_GAIN_MAX", 2.5, 2.5),
        ("TD_GAIN_MAX", 0.5, 2.5),  // below unity
        ("TD_GAIN_MAX", 40.0, 2.5), // above 32x
        ("TD_GAIN_MAX", f32::NAN, 2.5),
        ("TD_EXP_TARGET", 90.0, 90.0),
        ("TD_EXP_TARGET", 250.0, 90.0), // above 220
        ("TD_EXP_TARGET", 30.0, 90.0),  // below 40
        ("TD_TAG_SIZE", 0.01, 0.0),     // between "unset" and 2 cm
        ("TD_TAG_SIZE", 0.625, 0.625),
        ("TD_TAG_SIZE", -0.625, 0.625),
        ("TD_TAG_SIZE", f32::INFINITY, 0.625),
        ("TD_MAX_HAMMING", 2.0, 2.0),
        ("TD_MAX_HAMMING", 4.0, 2.0), // above 3
        ("TD_CAM_ROLL", 1.5, 1.5),
        ("TD_CAM_ROLL", 12.0, 1.5), // beyond +-10 degrees
        ("TD_CAM_CAL", 1.0, 1.0),
        ("TD_CAM_CAL", 3.0, 1.0), // 0, 1 or 2
    ];
    for (name, sent, answered) in sets {
        now += 10_000;
        let replies = ground_station(&mut companion, &mut seq, ParamAction::Set(name, sent), now);
        assert_eq!(
            replies,
            vec![(name.to_string(), answered)],
            "{name} = {sent}"
        );
    }
    let stats = companion.stats();
    assert_eq!(
        (stats.param_sets_accepted, stats.param_sets_rejected),
        (7, 14)
    );

    // What the firmware's vision task gets.
    let settings = PipelineSettings::from_params(companion.params());
    assert_eq!(
        settings,
        PipelineSettings {
            max_hamming: 2,
            tag_size_m: Some(0.625),
            exposure: AutoExposureLimits {
                target: 90,
                max_exposure_us: 2_000,
                max_gain: GainX16(40),
                ..AutoExposureLimits::default()
            },
            cam_yaw_deg: 0.0,
            cam_roll_deg: 1.5,
            cam_pitch_deg: 0.0,
            mount_calibration: MountCalibrationMode::Report,
            view_margin: false,
            lens: Default::default(),
            pad_design: 0,
        }
    );
    assert_eq!(
        settings
            .detector_config(DetectorConfig::default())
            .max_hamming,
        2
    );
    // The nested pad (largest marker 1.25 m) printed at half size.
    let pad = settings.pad(&designs::NESTED).unwrap();
    assert_eq!(settings.pad_scale(&designs::NESTED), 0.5);
    assert_eq!(
        pad.find("tag36h11", 0).map(|m| (m.size, m.y)),
        Some((0.625, 0.7))
    );
    // The defaults are the compile-time ones.
    let defaults = PipelineSettings::from_params(&ParamSet::default());
    assert_eq!(defaults.exposure, AutoExposureLimits::default());
    assert_eq!(defaults.pad(&designs::NESTED), Ok(designs::NESTED));

    // Saved to the flash log the way the firmware saves (core's `Store`, after a first save
    // of the defaults), restored at the next boot.
    let geometry = Geometry::new(8 * SLOT_LEN as u32).unwrap();
    let mut flash = RamSectors::new(geometry);
    let mut fresh = ParamSet::default();
    let (mut store, boot) = Store::open(geometry, |s, o, b| flash.read(s, o, b), &mut fresh);
    assert_eq!(boot.restored, None);
    block_on(store.save(&mut flash, &ParamSet::default())).unwrap();
    block_on(store.save(&mut flash, companion.params())).unwrap();
    let mut restored = ParamSet::default();
    let (_, boot) = Store::open(geometry, |s, o, b| flash.read(s, o, b), &mut restored);
    let found = boot.restored.expect("a valid slot");
    assert_eq!(found.key, SlotKey::Seq(1));
    assert_eq!(usize::from(found.report.applied), PARAM_COUNT);
    assert_eq!((found.report.rejected, found.report.unknown), (0, 0));
    assert_eq!(boot.bad_slots, 0);
    assert_eq!(&restored, companion.params());
    assert_eq!(PipelineSettings::from_params(&restored), settings);

    // After the reboot a ground station reads the new parameters back, by name and by index.
    let mut rebooted = Companion::new(CompanionConfig {
        params: restored,
        ..CompanionConfig::default()
    });
    let mut seq = 0u8;
    assert_eq!(
        ground_station(
            &mut rebooted,
            &mut seq,
            ParamAction::ReadName("TD_EXP_MAX_US"),
            100_000
        ),
        vec![("TD_EXP_MAX_US".to_string(), 2_000.0)]
    );
    for (id, want) in [
        (ParamId::ExpMaxUs, 2_000.0),
        (ParamId::GainMax, 2.5),
        (ParamId::ExpTarget, 90.0),
        (ParamId::CamRoll, 1.5),
        (ParamId::CamCal, 1.0),
    ] {
        let i = id.index() as i16;
        assert_eq!(
            ground_station(&mut rebooted, &mut seq, ParamAction::ReadIndex(i), 200_000),
            vec![(id.def().name.to_string(), want)]
        );
    }
}

/// Two flash sectors in RAM for [`persist::Store`]: erased is 0xFF, a program may only go to
/// erased bytes (what the H7 requires; the test fails if the store ever programs over data).
struct RamSectors {
    len: usize,
    bytes: Vec<u8>,
}

impl RamSectors {
    fn new(geometry: Geometry) -> Self {
        let len = geometry.sector_len() as usize;
        RamSectors {
            len,
            bytes: vec![ERASED; SECTORS * len],
        }
    }

    fn read(&self, sector: usize, offset: u32, buf: &mut [u8]) -> bool {
        let start = sector * self.len + offset as usize;
        match self.bytes.get(start..start + buf.len()) {
            Some(src) => {
                buf.copy_from_slice(src);
                true
            }
            None => false,
        }
    }
}

impl SlotFlash for RamSectors {
    async fn erase(&mut self, sector: usize) -> Result<(), FlashFailed> {
        let start = sector * self.len;
        self.bytes[start..start + self.len].fill(ERASED);
        Ok(())
    }

    async fn write(&mut self, sector: usize, offset: u32, bytes: &[u8]) -> Result<(), FlashFailed> {
        let start = sector * self.len + offset as usize;
        let dst = &mut self.bytes[start..start + bytes.len()];
        assert!(dst.iter().all(|&b| b == ERASED), "programmed over data");
        dst.copy_from_slice(bytes);
        Ok(())
    }
}

/// Runs a future that never waits (the RAM flash is ready at once) to completion.
fn block_on<F: std::future::Future>(future: F) -> F::Output {
    use std::task::{Context, Poll, Waker};
    let mut future = std::pin::pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    match future.as_mut().poll(&mut cx) {
        Poll::Ready(output) => output,
        Poll::Pending => panic!("the RAM flash never waits"),
    }
}
