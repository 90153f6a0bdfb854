//! The write sequence of [`super::super::Ov2640::init`]: the tables and the derived values in
//! order, each in its bank, with one bank select per change of bank, and every derived value
//! the last written to its register.

extern crate std;
use std::vec;
use std::vec::Vec;

use super::super::setup::dsp_scaling;
use super::*;

/// What the driver writes after the reset for QVGA, 30 fps from 24 MHz, the sensor's
/// AEC with an 8x ceiling (the default configuration), spelled out: the tables by name,
/// the derived values as numbers.
fn default_sequence() -> Vec<Setting> {
    let derived_window = [
        Setting::sensor(sensor::COM7, 0x40),    // SVGA mode
        Setting::sensor(sensor::HREFST, 0x11),  // 137 >> 3
        Setting::sensor(sensor::HREFEND, 0x43), // 537 >> 3
        Setting::sensor(sensor::REG32, 0x09),   // 537 & 7 = 1, 137 & 7 = 1
        Setting::sensor(sensor::VSTRT, 0x00),   // 2 >> 2
        Setting::sensor(sensor::VEND, 0x4B),    // 302 >> 2
        Setting::sensor(sensor::COM1, 0x0A),    // 302 & 3 = 2, 2 & 3 = 2
    ];
    let derived_clock = [
        Setting::sensor(sensor::CLKRC, 0x00), // 24 MHz / 1
        Setting::sensor(sensor::REG2A, 0x00),
        Setting::sensor(sensor::FRARL, 0x00),
        Setting::sensor(sensor::FLL, 0x00), // no dummy lines
        Setting::sensor(sensor::FLH, 0x00),
        Setting::sensor(sensor::COM10, 0x02), // VSYNC negative
        Setting::sensor(sensor::REG04, 0x28), // no flip, reserved + HREF[0]
    ];
    let derived_dsp = [
        Setting::dsp(dsp::RESET, 0x04),
        Setting::dsp(dsp::HSIZE8, 0x64), // 800 / 8
        Setting::dsp(dsp::VSIZE8, 0x4B), // 600 / 8
        Setting::dsp(dsp::SIZEL, 0x00),
        Setting::dsp(dsp::CTRL2, 0x3D),
        Setting::dsp(dsp::CTRLI, 0x89), // LP_DP, halve both ways
        Setting::dsp(dsp::HSIZE, 0xC8), // 800 / 4
        Setting::dsp(dsp::VSIZE, 0x96), // 600 / 4
        Setting::dsp(dsp::XOFFL, 0x00),
        Setting::dsp(dsp::YOFFL, 0x00),
        Setting::dsp(dsp::VHYX, 0x00),
        Setting::dsp(dsp::TEST, 0x00),
        Setting::dsp(dsp::ZMOW, 0x50), // 320 / 4
        Setting::dsp(dsp::ZMOH, 0x3C), // 240 / 4
        Setting::dsp(dsp::ZMHH, 0x00),
        Setting::dsp(dsp::R_DVP_SP, 0x04), // manual, PCLK = 2 x 24 MHz / 4
        Setting::dsp(dsp::IMAGE_MODE, 0x00), // YUV 4:2:2, Y first
    ];
    let derived_end = [
        Setting::dsp(dsp::CTRL0, 0xCE), // statistics bits kept, U first, YUV 4:2:2
        Setting::dsp(dsp::RESET, 0x00),
        Setting::dsp(dsp::R_BYPASS, 0x00),
        Setting::sensor(sensor::COM9, 0x50), // 8x ceiling (bits 7:5 = 010), bit 4 kept
        Setting::sensor(sensor::COM8, 0xC5), // AEC + AGC on, banding filter off
    ];
    let parts: [&[Setting]; 10] = [
        table::DSP_PRELUDE,
        table::SENSOR_COMMON,
        table::DSP_COMMON,
        &[Setting::dsp(dsp::R_BYPASS, 0x01)],
        &derived_window,
        table::SVGA_TIMING,
        &derived_clock,
        &derived_dsp,
        table::YUV422,
        &derived_end,
    ];
    parts.concat()
}

#[test]
fn init_qvga_auto_writes_the_tables_and_the_derived_values_in_order() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    let mut delay = MockDelay::default();
    let plan = block_on(camera.init(&mut delay, &Config::default())).unwrap();
    let bus = camera.release();
    // The id check: the sensor bank, then the four id reads, before any other write.
    assert_eq!(
        bus.log[..5],
        [
            Access::Write(I2C_ADDRESS, BANK_SEL, 1),
            Access::Read(I2C_ADDRESS, sensor::PIDH),
            Access::Read(I2C_ADDRESS, sensor::PIDL),
            Access::Read(I2C_ADDRESS, sensor::MIDH),
            Access::Read(I2C_ADDRESS, sensor::MIDL),
        ]
    );
    assert_eq!(bus.log[5], Access::Write(I2C_ADDRESS, sensor::COM7, 0x80));
    assert_eq!(banked_after_reset(&bus), default_sequence());
    // Bank selects: one after the reset, then one per change of bank in the sequence
    // (DSP, sensor, DSP, sensor, DSP, sensor).
    let selects = after_reset(&bus)
        .iter()
        .filter(|(r, _)| *r == BANK_SEL)
        .count();
    assert_eq!(selects, 6);
    // The two reads after the reset: CTRL0 in the DSP bank, COM9 in the sensor bank.
    let reads: Vec<_> = bus
        .log
        .iter()
        .skip(6)
        .filter_map(|a| match *a {
            Access::Read(_, r) => Some(r),
            Access::Write(..) => None,
        })
        .collect();
    assert_eq!(reads, [dsp::CTRL0, sensor::COM9]);
    // The reset was waited for.
    assert!(delay.total_ns >= u64::from(RESET_SETTLE_US) * 1000);
    // 24 MHz sensor clock: 1190 x 672 clocks = 30.01 fps, PCLK 12 MHz at QVGA.
    assert_eq!(
        (plan.doubler, plan.divider, plan.dummy_lines),
        (false, 0, 0)
    );
    assert_eq!(plan.sensor_clock_hz, 24_000_000);
    assert_eq!(plan.timing.pclk_hz, 12_000_000);
    assert_eq!(plan.timing.line_ns, 49_583);
    assert_eq!(plan.timing.frame_lines, 672);
    assert_eq!(plan.timing.active_lines, 600);
    assert_eq!(plan.timing.frame_period_us(), 33_319);
}

#[test]
fn every_write_goes_to_its_bank_with_one_select_per_change_of_bank() {
    // Every configuration the firmware can ask for: both sizes, auto and manual, flips.
    for resolution in [Resolution::Qvga, Resolution::Vga] {
        for exposure in [
            Exposure::Auto {
                max_gain: GainX16(16 * 32),
            },
            Exposure::Manual {
                lines: 300,
                gain: GainX16(20),
            },
        ] {
            let config = Config {
                resolution,
                exposure,
                vflip: true,
                ..Config::default()
            };
            let mut camera = Ov2640::new(ov2640_bus(0x41));
            let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
            let bus = camera.release();
            let exposure_part = match exposure {
                Exposure::Auto { .. } => vec![
                    Setting::sensor(sensor::COM9, 0x90), // 32x ceiling, bit 4 kept
                    Setting::sensor(sensor::COM8, COM8_AUTO),
                ],
                Exposure::Manual { .. } => vec![
                    Setting::sensor(sensor::COM8, COM8_MANUAL),
                    Setting::sensor(sensor::REG45, 0x00),
                    Setting::sensor(sensor::AEC, 75),     // 300 >> 2
                    Setting::sensor(sensor::REG04, 0x78), // flip, VREF[0], 300 & 3 = 0
                    Setting::sensor(sensor::GAIN, 0x04),  // 1.25x
                ],
            };
            let expected: Vec<Setting> = [
                table::DSP_PRELUDE,
                table::SENSOR_COMMON,
                table::DSP_COMMON,
                &BYPASS_DSP,
                &MODE_AND_WINDOW,
                table::SVGA_TIMING,
                &clock_and_sync(&plan, 0x78),
                &dsp_scaling(resolution),
                table::YUV422,
                &dsp_start(0xC0 | CTRL0_V_FIRST),
                &exposure_part,
            ]
            .concat();
            // banked_after_reset fails on a select that does not change the bank.
            assert_eq!(banked_after_reset(&bus), expected);
            let changes = expected.windows(2).filter(|w| w[0].bank != w[1].bank);
            let selects = after_reset(&bus)
                .iter()
                .filter(|(r, _)| *r == BANK_SEL)
                .count();
            assert_eq!(selects, 1 + changes.count());
        }
    }
}

#[test]
fn the_reserved_registers_of_the_svga_mode_and_yuv_are_written_in_their_banks() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    block_on(camera.init(&mut MockDelay::default(), &Config::default())).unwrap();
    let bus = camera.release();
    let sequence = banked_after_reset(&bus);
    // The last value written to (bank, register).
    let last = |bank: Bank, register: u8| {
        sequence
            .iter()
            .rev()
            .find(|s| s.bank == bank && s.register == register)
            .map(|s| s.value)
    };
    // The SVGA mode's analog timing, banding steps and readout (sensor bank), and the
    // YUV output settings (DSP bank), with the values they end with.
    for (register, value) in [
        (0x35, 0xDA),
        (0x22, 0x1A),
        (0x37, 0xC3),
        (0x39, 0x92),
        (sensor::ARCOM2, 0xC0),
        (0x06, 0x88),
        (0x07, 0xC0),
        (sensor::COM4, 0x87),
        (0x0E, 0x41),
        (0x42, 0x03),
        (sensor::BD50, 0xCA),
        (sensor::BD60, 0xA8),
        (sensor::REG5A, 0x23),
        (0x6D, 0x00),
        (sensor::REG3D, 0x38),
    ] {
        assert_eq!(
            last(Bank::Sensor, register),
            Some(value),
            "sensor {register:#04x}"
        );
    }
    for (register, value) in [(0xD7, 0x03), (0xE1, 0x67), (0xE5, 0x1F), (0x33, 0xA0)] {
        assert_eq!(
            last(Bank::Dsp, register),
            Some(value),
            "dsp {register:#04x}"
        );
    }
    // The same addresses in the other bank are other registers, with other values: the
    // sensor's 0x33 is not the DSP's.
    assert_eq!(last(Bank::Sensor, 0x33), Some(0x78));
    assert_eq!(last(Bank::Dsp, 0x42), Some(0x20));
    // The SVGA values are written after the mode select.
    let com7 = sequence
        .iter()
        .position(|s| *s == Setting::sensor(sensor::COM7, COM7_SVGA))
        .unwrap();
    let first_analog = sequence
        .iter()
        .position(|s| s.bank == Bank::Sensor && s.register == 0x35)
        .unwrap();
    assert!(com7 < first_analog);
}

#[test]
fn derived_values_are_the_last_written_to_their_registers() {
    for config in [
        Config::default(),
        Config {
            resolution: Resolution::Vga,
            xclk_hz: 12_000_000,
            fps: 25,
            exposure: Exposure::Manual {
                lines: 500,
                gain: GainX16(32),
            },
            vflip: true,
            mirror: true,
        },
    ] {
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        let sequence = banked_after_reset(&camera.release());
        let last = |bank: Bank, register: u8| {
            sequence
                .iter()
                .rev()
                .find(|s| s.bank == bank && s.register == register)
                .map(|s| s.value)
        };
        let manual = matches!(config.exposure, Exposure::Manual { .. });
        let [fll, flh] = plan.dummy_lines.to_le_bytes();
        assert_eq!(last(Bank::Sensor, sensor::COM7), Some(COM7_SVGA));
        assert_eq!(last(Bank::Sensor, sensor::CLKRC), Some(plan.clkrc()));
        assert_eq!(last(Bank::Sensor, sensor::FLL), Some(fll));
        assert_eq!(last(Bank::Sensor, sensor::FLH), Some(flh));
        assert_eq!(last(Bank::Sensor, sensor::COM10), Some(0x02));
        assert_eq!(
            last(Bank::Sensor, sensor::COM8),
            Some(if manual { 0xC0 } else { 0xC5 })
        );
        assert_eq!(last(Bank::Sensor, sensor::REG32), Some(0x09));
        assert_eq!(last(Bank::Sensor, sensor::COM1), Some(0x0A));
        assert_eq!(last(Bank::Dsp, dsp::R_DVP_SP), Some(plan.dvp_divider));
        assert_eq!(last(Bank::Dsp, dsp::IMAGE_MODE), Some(0x00));
        assert_eq!(last(Bank::Dsp, dsp::RESET), Some(0x00));
        assert_eq!(last(Bank::Dsp, dsp::R_BYPASS), Some(0x00));
        assert_eq!(last(Bank::Dsp, dsp::CTRL0), Some(0xCE));
        let (w, h) = (config.resolution.width(), config.resolution.height());
        assert_eq!(last(Bank::Dsp, dsp::ZMOW), Some((w / 4) as u8));
        assert_eq!(last(Bank::Dsp, dsp::ZMOH), Some((h / 4) as u8));
        // Every register of the derived parts ends with its derived value.
        let derived: [&[Setting]; 4] = [
            &MODE_AND_WINDOW,
            &clock_and_sync(&plan, orientation(&config)),
            &dsp_scaling(config.resolution),
            &dsp_start(0xC0 | CTRL0_V_FIRST),
        ];
        for s in derived.concat() {
            if s.bank == Bank::Dsp && s.register == dsp::RESET {
                continue; // held, then released: checked above
            }
            if s.bank == Bank::Sensor && s.register == sensor::REG04 {
                continue; // gains the exposure bits: checked below
            }
            assert_eq!(last(s.bank, s.register), Some(s.value), "{s:?}");
        }
        let reg04 = last(Bank::Sensor, sensor::REG04).unwrap();
        assert_eq!(reg04 & !REG04_AEC_MASK, orientation(&config));
    }
}

#[test]
fn qvga_and_vga_differ_only_in_scaling_and_output_clock() {
    let run = |resolution| {
        let mut camera = Ov2640::new(ov2640_bus(0x41));
        let config = Config {
            resolution,
            ..Config::default()
        };
        let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        (after_reset(&camera.release()), plan)
    };
    let (qvga, qvga_plan) = run(Resolution::Qvga);
    let (vga, vga_plan) = run(Resolution::Vga);
    assert_eq!(qvga.len(), vga.len());
    let differences: Vec<_> = qvga
        .iter()
        .zip(&vga)
        .filter(|(q, v)| q != v)
        .map(|(q, v)| (q.0, q.1, v.1))
        .collect();
    assert_eq!(
        differences,
        [
            (dsp::CTRLI, 0x89, 0x80),    // QVGA halves first, VGA does not
            (dsp::ZMOW, 0x50, 0xA0),     // 320 / 4, 640 / 4
            (dsp::ZMOH, 0x3C, 0x78),     // 240 / 4, 480 / 4
            (dsp::R_DVP_SP, 0x04, 0x02), // PCLK = sensor clock / 2, / 1
        ]
    );
    // Same sensor timing, twice the output clock for four times the bytes per frame.
    assert_eq!(qvga_plan.timing.line_ns, vga_plan.timing.line_ns);
    assert_eq!(qvga_plan.timing.frame_lines, vga_plan.timing.frame_lines);
    assert_eq!(vga_plan.timing.pclk_hz, 24_000_000);
}
