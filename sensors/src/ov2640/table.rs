//! OmniVision's reference register values: what the driver writes besides the values it
//! derives.
//!
//! The three open drivers that run this sensor (Linux, OpenMV, esp32-camera) write the same
//! vendor set-up after the reset, most of it to registers the datasheet marks reserved. The
//! values are facts about the silicon taken from them; the grouping, the order relative to
//! the derived values and the omissions are this driver's:
//!
//! - Every register the driver derives is left out (COM7, CLKRC, COM8, COM9, COM10, REG04,
//!   FLL/FLH, the window, the DSP sizes and zoom, R_DVP_SP, IMAGE_MODE, CTRL0, R_BYPASS).
//!   The references write some of them with other values (the UXGA mode with zoom, AEC and
//!   AGC with the banding filter on, 0x22 dummy lines, the automatic PCLK mode, a CTRL0 with
//!   the AEC statistics bits cleared); here the derived value is the only one written.
//!   COM3 (banding auto-detection, written by Linux and OpenMV) keeps its reset value: the
//!   banding filter stays off.
//!   The one overlap is the DSP's RESET: [`table::DSP_COMMON`](DSP_COMMON) holds the JPEG and output blocks in
//!   reset as the references do, and the derived sequence releases them last.
//! - The reference set-up is for the UXGA mode; the SVGA mode's analog timing replaces its
//!   UXGA values ([`table::SVGA_TIMING`](SVGA_TIMING)), written after the mode select as esp32-camera, the one
//!   reference that runs the SVGA mode, does.
//! - Registers named `0x..` without a constant are undocumented: their meaning is unknown
//!   and the value is the vendor's.
//!
//! Separate from the driver because it is data taken from the reference drivers, not derived
//! here; the tests below check that it stays clear of every register the driver derives.

use super::reg::{dsp, sensor};
use super::Setting;

const fn s(register: u8, value: u8) -> Setting {
    Setting::sensor(register, value)
}

const fn d(register: u8, value: u8) -> Setting {
    Setting::dsp(register, value)
}

/// Two undocumented DSP registers every reference writes first, before anything in the
/// sensor bank. Kept first for that reason (whether the order matters is not documented).
pub const DSP_PRELUDE: &[Setting] = &[d(0x2C, 0xFF), d(0x2E, 0xDF)];

/// The sensor bank's common set-up (the same for every mode; Linux's and OpenMV's
/// values, which esp32-camera shares except where noted).
pub const SENSOR_COMMON: &[Setting] = &[
    // Undocumented.
    s(0x3C, 0x32),
    // Output drive 3x: the PCLK and data edges stay sharp at 24 MHz over the module's
    // ribbon and the board's traces.
    s(sensor::COM2, 0x02),
    // Undocumented.
    s(0x2C, 0x0C),
    s(0x33, 0x78),
    s(0x3A, 0x33),
    s(0x3B, 0xFB),
    s(0x3E, 0x00),
    s(0x43, 0x11),
    s(0x16, 0x10),
    // Undocumented (Linux and OpenMV write them with the AEC settings below).
    s(0x4A, 0x81),
    s(0x21, 0x99),
    // The sensor's own AEC/AGC (used with `Exposure::Auto`): target band of the mean
    // luminance and the fast-mode band around it.
    s(sensor::AEW, 0x40),
    s(sensor::AEB, 0x38),
    s(sensor::VV, 0x82),
    // Undocumented.
    s(0x5C, 0x00),
    s(0x63, 0x00),
    // AEC zone weights (a heavier centre) and histogram levels; esp32-camera keeps the
    // reset values. Only the sensor's AEC reads them.
    s(sensor::REG5D, 0x55),
    s(sensor::REG5D + 1, 0x7D),
    s(sensor::REG5D + 2, 0x7D),
    s(sensor::REG5D + 3, 0x55),
    s(sensor::HISTO_LOW, 0x70),
    s(sensor::HISTO_HIGH, 0x80),
    // Undocumented.
    s(0x7C, 0x05),
    s(0x20, 0x80),
    s(0x28, 0x30),
    s(0x6C, 0x00),
    s(0x6E, 0x00),
    s(0x70, 0x02),
    s(0x71, 0x94),
    s(0x73, 0xC1),
];

/// The DSP bank's common set-up: Linux's and OpenMV's values (the same table). Where
/// esp32-camera differs (no black-pixel correction in CTRL3, other values in the 0x93
/// table, no 0xA6/0xA7 table, a CTRL1 write) the older two are followed. Left out: the
/// automatic PCLK mode (R_DVP_SP) and CTRL0, which the driver derives.
pub const DSP_COMMON: &[Setting] = &[
    // 0xE5 is written 0x7F here and 0x1F at the end of the block, in every reference:
    // it looks like an unlock bracket around what follows (undocumented).
    d(0xE5, 0x7F),
    // Reset the DSP's microcontroller and boot it from ROM.
    d(dsp::MC_BIST, 0xC0),
    // Undocumented.
    d(0x41, 0x24),
    // JPEG and output blocks held in reset while the DSP is set up (released at the end
    // of the derived sequence).
    d(dsp::RESET, 0x14),
    // Undocumented.
    d(0x76, 0xFF),
    d(0x33, 0xA0),
    d(0x42, 0x20),
    d(0x43, 0x18),
    d(0x4C, 0x00),
    // Black- and white-pixel correction on: hot and dead pixels would otherwise be
    // single-pixel specks, candidate edges for the fiducial detector. (Bit 4: vendor's.)
    d(dsp::CTRL3, 0xD0),
    // Undocumented.
    d(0x88, 0x3F),
    d(0xD7, 0x03),
    d(0xD9, 0x10),
    d(0xC8, 0x08),
    d(0xC9, 0x80),
    // SDE registers through their address/data ports: address 0 (effect enables: none),
    // addresses 3-4 (U and V saturation, 0x48 each: the neutral level), addresses 8-10
    // (undocumented).
    d(dsp::BPADDR, 0x00),
    d(dsp::BPDATA, 0x00),
    d(dsp::BPADDR, 0x03),
    d(dsp::BPDATA, 0x48),
    d(dsp::BPDATA, 0x48),
    d(dsp::BPADDR, 0x08),
    d(dsp::BPDATA, 0x20),
    d(dsp::BPDATA, 0x10),
    d(dsp::BPDATA, 0x0E),
    // An undocumented indirect table (address port 0x90, data port 0x91, from address
    // 0). Its 15 rising values look like a tone (gamma) curve; unconfirmed.
    d(0x90, 0x00),
    d(0x91, 0x0E),
    d(0x91, 0x1A),
    d(0x91, 0x31),
    d(0x91, 0x5A),
    d(0x91, 0x69),
    d(0x91, 0x75),
    d(0x91, 0x7E),
    d(0x91, 0x88),
    d(0x91, 0x8F),
    d(0x91, 0x96),
    d(0x91, 0xA3),
    d(0x91, 0xAF),
    d(0x91, 0xC4),
    d(0x91, 0xD7),
    d(0x91, 0xE8),
    d(0x91, 0x20),
    // Another undocumented indirect table (ports 0x92/0x93).
    d(0x92, 0x00),
    d(0x93, 0x06),
    d(0x93, 0xE3),
    d(0x93, 0x03),
    d(0x93, 0x03),
    d(0x93, 0x00),
    d(0x93, 0x02),
    d(0x93, 0x00),
    d(0x93, 0x00),
    d(0x93, 0x00),
    d(0x93, 0x00),
    d(0x93, 0x00),
    d(0x93, 0x00),
    d(0x93, 0x00),
    // Another undocumented indirect table (ports 0x96/0x97).
    d(0x96, 0x00),
    d(0x97, 0x08),
    d(0x97, 0x19),
    d(0x97, 0x02),
    d(0x97, 0x0C),
    d(0x97, 0x24),
    d(0x97, 0x30),
    d(0x97, 0x28),
    d(0x97, 0x26),
    d(0x97, 0x02),
    d(0x97, 0x98),
    d(0x97, 0x80),
    d(0x97, 0x00),
    d(0x97, 0x00),
    // Undocumented; 0xB0..0xC7 hold the white-balance settings (0xC7 = 0x10 selects
    // the simpler of its two AWB algorithms, by the Linux driver's notes).
    d(0xA4, 0x00),
    d(0xA8, 0x00),
    d(0xC5, 0x11),
    d(0xC6, 0x51),
    d(0xBF, 0x80),
    d(0xC7, 0x10),
    d(0xB6, 0x66),
    d(0xB8, 0xA5),
    d(0xB7, 0x64),
    d(0xB9, 0x7C),
    d(0xB3, 0xAF),
    d(0xB4, 0x97),
    d(0xB5, 0xFF),
    d(0xB0, 0xC5),
    d(0xB1, 0x94),
    d(0xB2, 0x0F),
    d(0xC4, 0x5C),
    // An undocumented indirect table (ports 0xA6/0xA7): three groups of six, one per
    // colour channel by the look of it.
    d(0xA6, 0x00),
    d(0xA7, 0x20),
    d(0xA7, 0xD8),
    d(0xA7, 0x1B),
    d(0xA7, 0x31),
    d(0xA7, 0x00),
    d(0xA7, 0x18),
    d(0xA7, 0x20),
    d(0xA7, 0xD8),
    d(0xA7, 0x19),
    d(0xA7, 0x31),
    d(0xA7, 0x00),
    d(0xA7, 0x18),
    d(0xA7, 0x20),
    d(0xA7, 0xD8),
    d(0xA7, 0x19),
    d(0xA7, 0x31),
    d(0xA7, 0x00),
    d(0xA7, 0x18),
    // Undocumented; 0xE5 closes the bracket opened above. (0xE1 is written again, with
    // its YUV value, by [`YUV422`].)
    d(0x7F, 0x00),
    d(0xE5, 0x1F),
    d(0xE1, 0x77),
    d(0xDD, 0x7F),
];

/// The SVGA mode's analog and readout timing (sensor bank), written after COM7 selects
/// the mode and the window is set: esp32-camera's SVGA values, which replace the UXGA
/// values of the Linux/OpenMV set-up (0x35 0x88, 0x22 0x0A, 0x37 0x40, 0x39 0x02,
/// ARCOM2 0xA0, 0x06 0x02, COM4 0xB7, 0x0E 0x01, 0x42 0x83, 0x3D 0x34, 0x5A 0x57,
/// BD50 0xBB, BD60 0x9C, 0x6D 0x80). The order is esp32-camera's, 0x37's two writes
/// included (undocumented, so the intermediate value is kept rather than guessed away).
pub const SVGA_TIMING: &[Setting] = &[
    s(0x37, 0xC0),
    // Banding steps for this mode's line time at the 24 MHz, 30 fps reference clock:
    // 202 lines = 10.0 ms and 168 lines = 8.33 ms at 49.58 us a line, at most 3 and 4
    // steps per frame (606 and 672 of its 672 lines). Only the banding filter reads
    // them, and it stays off; they are also a check of the 1190-clock line and the
    // 672-line frame (see the tests).
    s(sensor::COM25, 0x00),
    s(sensor::BD50, 0xCA),
    s(sensor::BD60, 0xA8),
    s(sensor::REG5A, 0x23),
    // Undocumented.
    s(0x6D, 0x00),
    // The SVGA readout timing that goes with the 1190 x 672 frame (see REG3D).
    s(sensor::REG3D, 0x38),
    // Undocumented analog settings of the mode.
    s(0x39, 0x92),
    s(0x35, 0xDA),
    s(0x22, 0x1A),
    s(0x37, 0xC3),
    s(0x23, 0x00),
    s(sensor::ARCOM2, 0xC0),
    s(0x06, 0x88),
    s(0x07, 0xC0),
    s(sensor::COM4, 0x87),
    s(0x0E, 0x41),
    s(0x42, 0x03),
    s(0x4C, 0x00),
];

/// DSP output settings for YUV 4:2:2 with the high byte (Y) first, written after
/// IMAGE_MODE. Undocumented; the values are Linux's and OpenMV's for this byte order
/// (esp32-camera writes 0xD7 = 0x01, which Linux pairs with the swapped, U-first order).
pub const YUV422: &[Setting] = &[d(0xD7, 0x03), d(0x33, 0xA0), d(0xE5, 0x1F), d(0xE1, 0x67)];

#[cfg(test)]
mod tests {
    use super::super::reg::BANK_SEL;
    use super::super::{plan_clock, table, Bank, Resolution, Setting};
    use super::*;

    /// The registers the driver derives: no table may write them (but RESET, see
    /// [`table`]).
    const DERIVED: &[(Bank, u8)] = &[
        (Bank::Sensor, sensor::GAIN),
        (Bank::Sensor, sensor::COM1),
        (Bank::Sensor, sensor::REG04),
        (Bank::Sensor, sensor::AEC),
        (Bank::Sensor, sensor::CLKRC),
        (Bank::Sensor, sensor::COM7),
        (Bank::Sensor, sensor::COM8),
        (Bank::Sensor, sensor::COM9),
        (Bank::Sensor, sensor::COM10),
        (Bank::Sensor, sensor::HREFST),
        (Bank::Sensor, sensor::HREFEND),
        (Bank::Sensor, sensor::VSTRT),
        (Bank::Sensor, sensor::VEND),
        (Bank::Sensor, sensor::REG2A),
        (Bank::Sensor, sensor::FRARL),
        (Bank::Sensor, sensor::REG32),
        (Bank::Sensor, sensor::REG45),
        (Bank::Sensor, sensor::FLL),
        (Bank::Sensor, sensor::FLH),
        (Bank::Dsp, dsp::R_BYPASS),
        (Bank::Dsp, dsp::CTRLI),
        (Bank::Dsp, dsp::HSIZE),
        (Bank::Dsp, dsp::VSIZE),
        (Bank::Dsp, dsp::XOFFL),
        (Bank::Dsp, dsp::YOFFL),
        (Bank::Dsp, dsp::VHYX),
        (Bank::Dsp, dsp::TEST),
        (Bank::Dsp, dsp::ZMOW),
        (Bank::Dsp, dsp::ZMOH),
        (Bank::Dsp, dsp::ZMHH),
        (Bank::Dsp, dsp::CTRL2),
        (Bank::Dsp, dsp::SIZEL),
        (Bank::Dsp, dsp::HSIZE8),
        (Bank::Dsp, dsp::VSIZE8),
        (Bank::Dsp, dsp::CTRL0),
        (Bank::Dsp, dsp::R_DVP_SP),
        (Bank::Dsp, dsp::IMAGE_MODE),
    ];

    const TABLES: [(&str, &[Setting]); 5] = [
        ("DSP_PRELUDE", table::DSP_PRELUDE),
        ("SENSOR_COMMON", table::SENSOR_COMMON),
        ("DSP_COMMON", table::DSP_COMMON),
        ("SVGA_TIMING", table::SVGA_TIMING),
        ("YUV422", table::YUV422),
    ];

    #[test]
    fn no_table_writes_a_derived_register_or_the_bank_select() {
        for (name, t) in TABLES {
            for s in t {
                assert_ne!(s.register, BANK_SEL, "{name} selects a bank");
                assert!(
                    !DERIVED.contains(&(s.bank, s.register)),
                    "{name} writes derived register {:?} {:#04x}",
                    s.bank,
                    s.register
                );
            }
        }
        // Each table is in one bank (so its bank selects are one at its start, if any).
        for (name, t, b) in [
            ("DSP_PRELUDE", table::DSP_PRELUDE, Bank::Dsp),
            ("SENSOR_COMMON", table::SENSOR_COMMON, Bank::Sensor),
            ("DSP_COMMON", table::DSP_COMMON, Bank::Dsp),
            ("SVGA_TIMING", table::SVGA_TIMING, Bank::Sensor),
            ("YUV422", table::YUV422, Bank::Dsp),
        ] {
            assert!(t.iter().all(|s| s.bank == b), "{name}");
        }
    }

    #[test]
    fn the_svga_banding_steps_match_the_planned_line_time() {
        // The vendor's SVGA banding steps are 1/100 s and 1/120 s in lines of the reference
        // timing (24 MHz, 30 fps): the same line time plan_clock derives from 1190 clocks.
        let plan = plan_clock(24_000_000, Resolution::Qvga, 30).unwrap();
        let line_ns = u64::from(plan.timing.line_ns);
        let find = |register: u8| {
            table::SVGA_TIMING
                .iter()
                .find(|s| s.register == register)
                .map(|s| u64::from(s.value))
                .unwrap()
        };
        assert_eq!((10_000_000 + line_ns / 2) / line_ns, find(sensor::BD50));
        assert_eq!((8_333_333 + line_ns / 2) / line_ns, find(sensor::BD60));
        // The most steps per frame fit in one frame: 3 x 202 = 606 and 4 x 168 = 672 of its
        // 672 lines.
        let steps = find(sensor::REG5A);
        let frame = u64::from(plan.timing.frame_lines);
        assert!(((steps >> 4) + 1) * find(sensor::BD50) <= frame);
        assert_eq!(((steps & 0xF) + 1) * find(sensor::BD60), frame);
    }
}
