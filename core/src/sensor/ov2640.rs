//! OmniVision OV2640: 2-megapixel (UXGA, 1600x1200) CMOS sensor with an on-chip DSP,
//! configured over SCCB.
//!
//! The OV2640 has two register banks behind one SCCB address: the *sensor* bank (array
//! timing, window, clock, exposure, gain) and the *DSP* bank (colour processing, scaling,
//! output format). Register 0xFF selects the bank every other access goes to. The driver
//! remembers the selected bank and only writes 0xFF when the next access needs the other one;
//! it selects again regardless after the register reset, at every id check (the sensor may
//! have been reset through its pins since) and after a bank select that failed.
//!
//! What this driver sets up, and nothing else (every other register keeps its reset value):
//!
//! - **Identity**: PIDH/PIDL must read `0x26`/`0x40..=0x42` and MIDH/MIDL `0x7F`/`0xA2`
//!   before anything but the bank select is written, so a wrong device is an error, not a
//!   device we scribble on.
//! - **Reset**: COM7 bit 7 in the sensor bank puts every register back to its default
//!   ([`RESET_SETTLE_US`]).
//! - **Sensor window: SVGA.** COM7 selects the 800x600 mode, which reads the whole
//!   1600x1200 array subsampled by two in each direction: the full field of view, at up to
//!   30 fps, with a 600-line readout. The UXGA mode reads all 1200 lines, so it tops out at
//!   15 fps and its rolling shutter skews the image over twice as long, which is worse for a
//!   camera on a moving drone than the resolution it adds is better (QVGA and VGA are smaller
//!   than SVGA either way). The window registers (HREFST/HREFEND/REG32, VSTRT/VEND/COM1)
//!   span 800x600 ([`SVGA_WINDOW`]).
//! - **Scaling to QVGA or VGA** in the DSP: the DSP is told its input is 800x600
//!   (HSIZE8/VSIZE8, HSIZE/VSIZE), QVGA first halves it (CTRLI down-sampling, to 400x300),
//!   and the zoom stage (ZMOW/ZMOH) scales by 0.8 to 320x240 or 640x480. Both are 4:3 like
//!   the window, so nothing is cropped and pixels stay square.
//! - **Format**: YUV 4:2:2 with Y first (`Y0 U0 Y1 V0 ...`): IMAGE_MODE selects YUV 4:2:2
//!   with its byte-swap bit 0 clear (high byte, Y, first) and CTRL0's V-first bit clear
//!   (U before V). The camera interface keeps every first byte of a pair: 8-bit grey.
//! - **Frame rate**: the sensor clock is `XCLK x (2 if CLKRC's doubler) / (CLKRC[5:0] + 1)`,
//!   one SVGA line is 1190 sensor clocks and one frame 672 lines (OmniVision's frame-rate
//!   note for the SVGA mode: 24 MHz gives 30.01 fps); [`plan_clock`] picks the doubler and
//!   divider and adds dummy lines (FLL/FLH) to hit the requested rate.
//! - **Sync signals**: VSYNC is inverted (COM10 bit 1) so it is high between frames like the
//!   OV7725's; HREF (high during a line's data) and PCLK (data changes on the falling edge)
//!   stay as reset. One camera interface set-up then serves both sensors (see
//!   [`super::any`]).
//! - **Exposure and gain**: the sensor's own AEC/AGC with a gain ceiling (COM8, COM9), or
//!   manual exposure (16 bits of line periods split over REG45, AEC and REG04) and gain
//!   (GAIN). With a hard exposure limit, run [`super::exposure::AutoExposure`] and feed its
//!   manual settings here.
//!
//! The bus is SCCB: a register read is a write of the register address, a STOP, then a
//! separate one-byte read ([`Ov2640::read_register`]), never `write_read`.
//!
//! Sources for the register semantics: the OV2640 datasheet's register tables (sensor bank:
//! GAIN, COM1, REG04, AEC, CLKRC, COM7..COM10, window, REG32, REG45, FLL/FLH, PIDH/PIDL,
//! MIDH/MIDL; DSP bank: R_BYPASS, CTRLI, size and zoom registers, CTRL0/CTRL2, R_DVP_SP,
//! IMAGE_MODE, RESET), OmniVision's software application notes (SVGA frame timing, dummy
//! lines) and the bit definitions documented in the Linux `ov2640` driver. The register
//! values below are derived here, not copied from any table.

use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;

use super::ov7725::{gain_from_register, gain_register};
use super::{gain_ceiling_log2, Config, ConfigError, Exposure, FrameTiming, GainX16, Resolution};

/// 7-bit SCCB address (0x60 to write, 0x61 to read in 8-bit notation).
pub const I2C_ADDRESS: u8 = 0x30;
/// Product id, high byte (PIDH).
pub const PRODUCT_ID_HIGH: u8 = 0x26;
/// Product id, low byte (PIDL): silicon revisions read 0x40, 0x41 or 0x42.
pub const PRODUCT_ID_LOW: core::ops::RangeInclusive<u8> = 0x40..=0x42;
/// Manufacturer id (MIDH, MIDL): OmniVision.
pub const MANUFACTURER_ID: u16 = 0x7FA2;
/// Wait after the register reset before the next access, µs. The datasheet gives no figure
/// for the software reset; 10 ms leaves a wide margin over the few milliseconds the sensor
/// takes to answer again.
pub const RESET_SETTLE_US: u32 = 10_000;
/// Input clock range of the sensor (datasheet key specifications), Hz.
pub const XCLK_RANGE_HZ: core::ops::RangeInclusive<u32> = 6_000_000..=36_000_000;
/// Highest sensor clock [`plan_clock`] uses, Hz: OmniVision's rating of the SVGA mode is
/// 30 fps, which is exactly this clock (1190 x 672 clocks per frame).
pub const MAX_SENSOR_CLOCK_HZ: u32 = 24_000_000;
/// A frame rate within this many parts per million of the request counts as exact.
pub const FPS_TOLERANCE_PPM: u64 = 5_000;

/// Sensor clocks per line in the SVGA mode, no dummy pixels (OmniVision's frame-rate note).
pub const SVGA_LINE_CLOCKS: u32 = 1190;
/// Lines per frame in the SVGA mode, no dummy lines.
pub const SVGA_FRAME_LINES: u32 = 672;
/// Image lines read out per SVGA frame.
pub const SVGA_ACTIVE_LINES: u32 = 600;
/// Width of the SVGA image the DSP receives.
pub const SVGA_WIDTH: u16 = 800;
/// Height of the SVGA image the DSP receives.
pub const SVGA_HEIGHT: u16 = 600;

/// The register banks, as written to [`reg::BANK_SEL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Bank {
    /// The DSP bank (0): image processing, scaling, output format.
    Dsp = 0,
    /// The sensor bank (1): array timing, window, clock, exposure and gain.
    Sensor = 1,
}

/// Register addresses (the subset this driver touches), with what each one does.
pub mod reg {
    /// Bank select, in both banks: 0 DSP bank, 1 sensor bank.
    pub const BANK_SEL: u8 = 0xFF;

    /// Sensor bank (BANK_SEL = 1).
    pub mod sensor {
        /// AGC gain \[7:0\]. Bits \[7:4\] each double the gain (set from bit 4 upwards), bits
        /// \[3:0\] add sixteenths: gain = 2^(set high bits) x (1 + \[3:0\]/16), 1x to 31x.
        /// Written by the AGC when on.
        pub const GAIN: u8 = 0x00;
        /// COM1: bits \[7:6\] dummy frames, bits \[3:2\] vertical window end \[1:0\], bits \[1:0\]
        /// vertical window start \[1:0\].
        pub const COM1: u8 = 0x03;
        /// REG04: bit 7 horizontal mirror, bit 6 vertical flip, bit 5 reserved (set), bit 4
        /// vertical window start bit 0 (VREF\[0\]), bit 3 horizontal window start bit 0
        /// (HREF\[0\]), bits \[1:0\] exposure AEC\[1:0\].
        pub const REG04: u8 = 0x04;
        /// Product id MSB, read-only (0x26).
        pub const PIDH: u8 = 0x0A;
        /// Product id LSB, read-only (0x40..=0x42).
        pub const PIDL: u8 = 0x0B;
        /// Exposure AEC\[9:2\], in line periods. Written by the AEC when on.
        pub const AEC: u8 = 0x10;
        /// CLKRC: bit 7 internal clock doubler, bits \[5:0\] divider n: sensor clock =
        /// XCLK x (2 if doubled) / (n + 1).
        pub const CLKRC: u8 = 0x11;
        /// COM7: bit 7 register reset (self-clearing), bits \[6:4\] sensor mode (000 UXGA,
        /// 010 CIF, 100 SVGA), bit 2 zoom, bit 1 colour bar test pattern.
        pub const COM7: u8 = 0x12;
        /// COM8: bits \[7:6\] reserved (written 1), bit 5 banding filter, bit 2 AGC on, bit 0
        /// AEC on.
        pub const COM8: u8 = 0x13;
        /// COM9: bits \[7:5\] AGC gain ceiling (000 2x, 001 4x, ... 100 32x); other bits are
        /// kept as read.
        pub const COM9: u8 = 0x14;
        /// COM10: bit 5 PCLK only during HREF, bit 4 data changes on PCLK's rising edge,
        /// bit 3 HREF negative, bit 1 VSYNC negative, bit 0 HSYNC negative.
        pub const COM10: u8 = 0x15;
        /// Horizontal window start \[10:3\] (units of two pixels).
        pub const HREFST: u8 = 0x17;
        /// Horizontal window end \[10:3\].
        pub const HREFEND: u8 = 0x18;
        /// Vertical window start \[9:2\] (units of two lines).
        pub const VSTRT: u8 = 0x19;
        /// Vertical window end \[9:2\].
        pub const VEND: u8 = 0x1A;
        /// Manufacturer id MSB, read-only (0x7F).
        pub const MIDH: u8 = 0x1C;
        /// Manufacturer id LSB, read-only (0xA2).
        pub const MIDL: u8 = 0x1D;
        /// REG2A: bits \[7:4\] dummy pixels per line \[11:8\] (longer line; unused, written 0).
        pub const REG2A: u8 = 0x2A;
        /// FRARL: dummy pixels per line \[7:0\].
        pub const FRARL: u8 = 0x2B;
        /// REG32: bits \[7:6\] PCLK divider (00 none), bits \[5:3\] horizontal window end
        /// \[2:0\], bits \[2:0\] horizontal window start \[2:0\].
        pub const REG32: u8 = 0x32;
        /// Reserved in the datasheet. OmniVision's frame-rate note writes 0x38 with the SVGA
        /// mode (0x34 with UXGA) as part of every SVGA clock set-up; it goes with the
        /// mode's readout timing.
        pub const REG3D: u8 = 0x3D;
        /// REG45: bits \[7:6\] AGC\[9:8\] (extra gain beyond GAIN; written 0), bits
        /// \[5:0\] exposure AEC\[15:10\].
        pub const REG45: u8 = 0x45;
        /// FLL: dummy lines per frame \[7:0\] (longer frame: lower frame rate).
        pub const FLL: u8 = 0x46;
        /// FLH: dummy lines per frame \[15:8\].
        pub const FLH: u8 = 0x47;
    }

    /// DSP bank (BANK_SEL = 0).
    pub mod dsp {
        /// R_BYPASS: bit 0 bypass the DSP (sensor data straight out). Set while the DSP is
        /// reconfigured, cleared to use it.
        pub const R_BYPASS: u8 = 0x05;
        /// CTRLI: bit 7 LP_DP (set by OmniVision's settings whenever the output is scaled
        /// down; not further documented), bits \[5:3\] vertical and \[2:0\] horizontal
        /// down-sampling: divide by 2^n before the zoom stage.
        pub const CTRLI: u8 = 0x50;
        /// Zoom input width \[7:0\], in units of 4 pixels.
        pub const HSIZE: u8 = 0x51;
        /// Zoom input height \[7:0\], in units of 4 lines.
        pub const VSIZE: u8 = 0x52;
        /// Zoom input horizontal offset \[7:0\].
        pub const XOFFL: u8 = 0x53;
        /// Zoom input vertical offset \[7:0\].
        pub const YOFFL: u8 = 0x54;
        /// VHYX: bit 7 VSIZE\[8\], bits \[6:4\] YOFF\[10:8\], bit 3 HSIZE\[8\], bits
        /// \[2:0\] XOFF\[10:8\].
        pub const VHYX: u8 = 0x55;
        /// TEST: bit 7 HSIZE\[9\].
        pub const TEST: u8 = 0x57;
        /// Zoom output width \[7:0\] (ZMOW), in units of 4 pixels.
        pub const ZMOW: u8 = 0x5A;
        /// Zoom output height \[7:0\] (ZMOH), in units of 4 lines.
        pub const ZMOH: u8 = 0x5B;
        /// ZMHH: bits \[7:4\] zoom speed, bit 2 output height \[8\], bits \[1:0\] output width
        /// \[9:8\].
        pub const ZMHH: u8 = 0x5C;
        /// CTRL2: bit 5 down-sampling (DCW) on, bit 4 special digital effects, bit 3 UV
        /// adjust, bit 2 UV average, bit 0 colour matrix (RGB to YUV).
        pub const CTRL2: u8 = 0x86;
        /// SIZEL: bit 6 input width \[11\], bits \[5:3\] input width \[2:0\], bits \[2:0\] input
        /// height \[2:0\].
        pub const SIZEL: u8 = 0x8C;
        /// HSIZE8: the DSP's input width \[10:3\].
        pub const HSIZE8: u8 = 0xC0;
        /// VSIZE8: the DSP's input height \[10:3\].
        pub const VSIZE8: u8 = 0xC1;
        /// CTRL0: bits \[7:5\] statistics for the sensor's AEC (kept as read), bit 4 V before
        /// U, bit 3 YUV 4:2:2, bit 2 YUV output, bit 1 RGB path, bit 0 raw output.
        pub const CTRL0: u8 = 0xC2;
        /// R_DVP_SP: bit 7 automatic PCLK, bits \[6:0\] divider: output PCLK = DSP clock /
        /// divider in YUV. The DSP clock is documented as 48 MHz with the 24 MHz reference
        /// clock, so this driver takes it as twice the sensor clock.
        pub const R_DVP_SP: u8 = 0xD3;
        /// IMAGE_MODE: bit 6 Y-only output, bit 4 JPEG, bits \[3:2\] format (00 YUV 4:2:2, 01
        /// raw, 10 RGB565), bit 0 byte swap (1: low byte, U/V, first).
        pub const IMAGE_MODE: u8 = 0xDA;
        /// RESET: bit 6 microcontroller, bit 4 JPEG, bit 2 DVP (the output port), bit 0 CIF.
        pub const RESET: u8 = 0xE0;
    }
}

/// COM7 bit 7: reset every register to its default.
const COM7_RESET: u8 = 0x80;
/// COM7 bits \[6:4\] = 100: the SVGA mode (zoom and colour bar off).
const COM7_SVGA: u8 = 0x40;
/// REG3D in the SVGA mode (see [`reg::sensor::REG3D`]).
const REG3D_SVGA: u8 = 0x38;
/// REG04 bit 7: horizontal mirror.
const REG04_MIRROR: u8 = 0x80;
/// REG04 bit 6: vertical flip.
const REG04_VFLIP: u8 = 0x40;
/// REG04 bit 5: reserved, written 1 as in OmniVision's settings.
const REG04_RESERVED: u8 = 0x20;
/// REG04 bit 4: vertical window start bit 0. Set with the vertical flip: the flipped readout
/// then starts one row later, on the same Bayer colour row as the unflipped one, so the
/// DSP's colour interpolation (and with it Y) stays right.
const REG04_VREF0: u8 = 0x10;
/// REG04 bit 3: horizontal window start bit 0, set as in OmniVision's settings (the Bayer
/// phase of the unflipped readout).
const REG04_HREF0: u8 = 0x08;
/// REG04 bits \[1:0\]: exposure AEC\[1:0\].
const REG04_AEC_MASK: u8 = 0x03;
/// CLKRC bit 7: clock doubler.
const CLKRC_DOUBLER: u8 = 0x80;
/// Largest CLKRC divider field value (6 bits).
const CLKRC_MAX_DIVIDER: u8 = 63;
/// COM10 bit 1: VSYNC negative, i.e. high between frames and low during them, as the
/// OV7725's VSYNC at its reset default.
const COM10_VSYNC_NEGATIVE: u8 = 0x02;
/// COM8 bits \[7:6\]: reserved, written 1 as in OmniVision's settings.
const COM8_RESERVED: u8 = 0xC0;
/// COM8 bit 2: AGC.
const COM8_AGC: u8 = 0x04;
/// COM8 bit 0: AEC.
const COM8_AEC: u8 = 0x01;
/// COM8 with the sensor's AEC and AGC on and the banding filter (bit 5) off: it would hold
/// the exposure at multiples of 1/100 s, far too long outdoors.
const COM8_AUTO: u8 = COM8_RESERVED | COM8_AGC | COM8_AEC;
/// COM8 for manual exposure and gain: AEC and AGC off.
const COM8_MANUAL: u8 = COM8_RESERVED;
/// COM9 bits \[7:5\]: gain ceiling field.
const COM9_CEILING_MASK: u8 = 0xE0;
/// REG45 bits \[5:0\]: exposure AEC\[15:10\]; bits \[7:6\] (AGC\[9:8\]) are written 0.
const REG45_AEC_MASK: u8 = 0x3F;

/// R_BYPASS bit 0: bypass the DSP.
const R_BYPASS_BYPASS: u8 = 0x01;
/// R_BYPASS = 0: use the DSP.
const R_BYPASS_USE_DSP: u8 = 0x00;
/// RESET bit 2: hold the output port (DVP) in reset.
const RESET_DVP: u8 = 0x04;
/// CTRLI bit 7 (LP_DP).
const CTRLI_LP_DP: u8 = 0x80;
/// CTRL2: down-sampling (bit 5), special digital effects (bit 4, neutral at reset), UV
/// adjust (bit 3), UV average (bit 2), colour matrix (bit 0: it forms Y from RGB). Every
/// OmniVision setting for a scaled YUV output enables exactly these.
const CTRL2_YUV_SCALED: u8 = 0x20 | 0x10 | 0x08 | 0x04 | 0x01;
/// CTRL0 bit 4: V before U.
const CTRL0_V_FIRST: u8 = 0x10;
/// CTRL0 bits 3, 2, 1: YUV 4:2:2, YUV output, RGB path (the colour matrix works on it).
const CTRL0_YUV422: u8 = 0x08 | 0x04 | 0x02;
/// CTRL0 bit 0: raw output.
const CTRL0_RAW: u8 = 0x01;
/// IMAGE_MODE = 0: YUV 4:2:2, byte swap off (high byte first: `Y U Y V`), no JPEG, not
/// Y-only (the camera interface's byte select does that, as for the OV7725).
const IMAGE_MODE_YUV422_Y_FIRST: u8 = 0x00;

/// The SVGA sensor window in the window registers' units (two pixels, two lines):
/// (horizontal start, width, vertical start, height). 400 x 300 units are the 800x600 the
/// DSP is told it receives; the start offsets are OmniVision's for the SVGA mode (column
/// unit 137, row unit 2), which skip the array's border.
pub const SVGA_WINDOW: (u16, u16, u16, u16) = (137, 400, 2, 300);

/// Why the sensor could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SCCB/I2C transfer failed (no device, NACK, bus fault).
    Bus(E),
    /// Something answered, but it is not an OV2640 (the ids as read).
    WrongChip {
        /// PIDH as read.
        pid: u8,
        /// PIDL as read.
        ver: u8,
        /// MIDH:MIDL as read.
        manufacturer: u16,
    },
    /// The configuration cannot be realised.
    Config(ConfigError),
}

/// The identification registers as read ([`Ov2640::read_id`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChipId {
    /// PIDH.
    pub pid: u8,
    /// PIDL.
    pub ver: u8,
    /// MIDH:MIDL.
    pub manufacturer: u16,
}

impl ChipId {
    /// Whether these are an OV2640's ids ([`PRODUCT_ID_HIGH`], [`PRODUCT_ID_LOW`],
    /// [`MANUFACTURER_ID`]).
    pub fn is_ov2640(&self) -> bool {
        self.pid == PRODUCT_ID_HIGH
            && PRODUCT_ID_LOW.contains(&self.ver)
            && self.manufacturer == MANUFACTURER_ID
    }
}

/// Sensor clock, frame length and output clock for a frame rate ([`plan_clock`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockPlan {
    /// CLKRC bit 7: the input clock is doubled.
    pub doubler: bool,
    /// CLKRC\[5:0\]: the (doubled) input clock is divided by this plus one.
    pub divider: u8,
    /// Dummy lines added to the frame (FLL/FLH).
    pub dummy_lines: u16,
    /// Resulting sensor clock, Hz.
    pub sensor_clock_hz: u32,
    /// R_DVP_SP: the output PCLK divider of the mode.
    pub dvp_divider: u8,
    /// Resulting line and frame timing (with the output PCLK).
    pub timing: FrameTiming,
}

impl ClockPlan {
    /// The CLKRC register value.
    const fn clkrc(&self) -> u8 {
        let doubler = if self.doubler { CLKRC_DOUBLER } else { 0 };
        doubler | (self.divider & CLKRC_MAX_DIVIDER)
    }
}

/// How the DSP turns the 800x600 window into the output size: CTRLI down-sampling (log2,
/// the same both ways) and the output PCLK divider R_DVP_SP.
///
/// QVGA halves the window to 400x300 first, VGA does not; the zoom then scales by 0.8 in
/// both. The PCLK divider gives the output port enough bandwidth with margin: per sensor
/// line (1190 sensor clocks) VGA emits on average 0.8 output lines of 1280 bytes, QVGA 0.4
/// lines of 640 bytes. With the DSP clock at twice the sensor clock (see
/// [`reg::dsp::R_DVP_SP`]), dividing by 2 (VGA) gives PCLK = sensor clock (the port 86% busy),
/// by 4 (QVGA) half of it (43% busy).
const fn scaling(resolution: Resolution) -> (u8, u8) {
    match resolution {
        Resolution::Qvga => (1, 4),
        Resolution::Vga => (0, 2),
    }
}

/// Chooses the clock doubler, divider and dummy lines for `fps` frames per second from an
/// input clock of `xclk_hz`, with the output clock of `resolution`.
///
/// Among settings within [`FPS_TOLERANCE_PPM`] of the request, the one with the fewest dummy
/// lines wins (the mode's natural timing), then the lower sensor clock, then the one
/// without the doubler. If none is within tolerance, the closest rate wins.
pub fn plan_clock(
    xclk_hz: u32,
    resolution: Resolution,
    fps: u32,
) -> Result<ClockPlan, ConfigError> {
    if !XCLK_RANGE_HZ.contains(&xclk_hz) {
        return Err(ConfigError::XclkOutOfRange);
    }
    if fps == 0 {
        return Err(ConfigError::FrameRateUnreachable);
    }
    let (_, dvp_divider) = scaling(resolution);
    let fps = u64::from(fps);
    let line = u64::from(SVGA_LINE_CLOCKS);
    // (out of tolerance, dummy lines or error, sensor clock) -> plan; smallest key wins,
    // the first found on a tie (no doubler is tried first).
    let mut best: Option<((bool, u64, u64), ClockPlan)> = None;
    for doubler in [false, true] {
        for divider in 0..=CLKRC_MAX_DIVIDER {
            let multiplier = if doubler { 2 } else { 1 };
            let clock = u64::from(xclk_hz) * multiplier / (u64::from(divider) + 1);
            if clock == 0 || clock > u64::from(MAX_SENSOR_CLOCK_HZ) {
                continue;
            }
            let lines = (clock / fps + line / 2) / line;
            let Some(dummy) = lines.checked_sub(u64::from(SVGA_FRAME_LINES)) else {
                continue;
            };
            let Ok(dummy_lines) = u16::try_from(dummy) else {
                continue;
            };
            // Achieved rate in milli-fps against the request.
            let achieved = clock * 1000 / (lines * line);
            let error_ppm = achieved.abs_diff(fps * 1000) * 1_000_000 / (fps * 1000);
            let out = error_ppm > FPS_TOLERANCE_PPM;
            let key = (out, if out { error_ppm } else { dummy }, clock);
            if best.as_ref().is_some_and(|(k, _)| *k <= key) {
                continue;
            }
            let sensor_clock_hz = u32::try_from(clock).unwrap_or(u32::MAX);
            // Output PCLK = DSP clock (2 x sensor clock) / R_DVP_SP.
            let pclk = clock * 2 / u64::from(dvp_divider);
            let line_ns = u32::try_from(line * 1_000_000_000 / clock).unwrap_or(u32::MAX);
            best = Some((
                key,
                ClockPlan {
                    doubler,
                    divider,
                    dummy_lines,
                    sensor_clock_hz,
                    dvp_divider,
                    timing: FrameTiming {
                        pclk_hz: u32::try_from(pclk).unwrap_or(u32::MAX),
                        line_ns,
                        frame_lines: u32::try_from(lines).unwrap_or(u32::MAX),
                        active_lines: SVGA_ACTIVE_LINES,
                    },
                },
            ));
        }
    }
    best.map(|(_, plan)| plan)
        .ok_or(ConfigError::FrameRateUnreachable)
}

/// Splits a 16-bit exposure (line periods) into its registers: (REG45\[5:0\] = AEC\[15:10\],
/// AEC = AEC\[9:2\], REG04\[1:0\] = AEC\[1:0\]).
pub const fn exposure_fields(lines: u16) -> (u8, u8, u8) {
    (
        ((lines >> 10) as u8) & REG45_AEC_MASK,
        (lines >> 2) as u8,
        (lines as u8) & REG04_AEC_MASK,
    )
}

/// Joins the exposure registers (REG45, AEC, REG04 as read) into line periods.
pub const fn exposure_from_fields(reg45: u8, aec: u8, reg04: u8) -> u16 {
    (((reg45 & REG45_AEC_MASK) as u16) << 10)
        | ((aec as u16) << 2)
        | ((reg04 & REG04_AEC_MASK) as u16)
}

/// The OV2640 on an SCCB (I2C) bus.
#[derive(Debug)]
pub struct Ov2640<I> {
    i2c: I,
    /// The bank the sensor has selected, if known.
    bank: Option<Bank>,
    /// REG04 without the exposure bits (flip, mirror, window LSBs), so a manual exposure
    /// update writes REG04 without reading it first.
    reg04: u8,
    /// Longest exposure the frame allows (the sensor caps the exposure at one frame), lines.
    max_exposure_lines: u16,
}

impl<I: I2c> Ov2640<I> {
    /// A driver for the sensor at [`I2C_ADDRESS`] on `i2c`. Nothing is sent yet.
    pub fn new(i2c: I) -> Self {
        Ov2640 {
            i2c,
            bank: None,
            reg04: REG04_RESERVED | REG04_HREF0,
            max_exposure_lines: u16::MAX,
        }
    }

    /// Gives the bus back.
    pub fn release(self) -> I {
        self.i2c
    }

    /// The longest manual exposure [`Ov2640::set_manual`] writes, line periods: the frame
    /// length after [`Ov2640::init`], the register's range before.
    pub fn max_exposure_lines(&self) -> u16 {
        self.max_exposure_lines
    }

    /// Selects `bank` unless it is known to be selected already.
    async fn select_bank(&mut self, bank: Bank) -> Result<(), I::Error> {
        if self.bank == Some(bank) {
            return Ok(());
        }
        // Unknown until the write is known to have landed.
        self.bank = None;
        self.i2c
            .write(I2C_ADDRESS, &[reg::BANK_SEL, bank as u8])
            .await?;
        self.bank = Some(bank);
        Ok(())
    }

    /// Reads one register of `bank`: the address in one write transaction, STOP, then a
    /// one-byte read (SCCB has no repeated start).
    pub async fn read_register(&mut self, bank: Bank, register: u8) -> Result<u8, Error<I::Error>> {
        self.read_raw(bank, register).await.map_err(Error::Bus)
    }

    /// [`Ov2640::read_register`] with the bus's own error.
    async fn read_raw(&mut self, bank: Bank, register: u8) -> Result<u8, I::Error> {
        self.select_bank(bank).await?;
        self.i2c.write(I2C_ADDRESS, &[register]).await?;
        let mut value = [0u8];
        self.i2c.read(I2C_ADDRESS, &mut value).await?;
        let [value] = value;
        Ok(value)
    }

    /// Writes one register of `bank`. (To switch banks, pass the bank; a direct write of
    /// [`reg::BANK_SEL`] goes through, and the driver then re-selects before the next access.)
    pub async fn write_register(
        &mut self,
        bank: Bank,
        register: u8,
        value: u8,
    ) -> Result<(), Error<I::Error>> {
        self.select_bank(bank).await.map_err(Error::Bus)?;
        let result = self
            .i2c
            .write(I2C_ADDRESS, &[register, value])
            .await
            .map_err(Error::Bus);
        if register == reg::BANK_SEL {
            // The caller switched banks behind the driver's back: forget which is selected.
            self.bank = None;
        }
        result
    }

    /// Reads PIDH/PIDL and MIDH/MIDL (sensor bank). The bank select before the reads is the
    /// only write; it is always sent, because the sensor may have been reset or power-cycled
    /// through its pins since the driver last selected a bank.
    pub async fn read_id(&mut self) -> Result<ChipId, I::Error> {
        self.bank = None;
        let pid = self.read_raw(Bank::Sensor, reg::sensor::PIDH).await?;
        let ver = self.read_raw(Bank::Sensor, reg::sensor::PIDL).await?;
        let midh = self.read_raw(Bank::Sensor, reg::sensor::MIDH).await?;
        let midl = self.read_raw(Bank::Sensor, reg::sensor::MIDL).await?;
        Ok(ChipId {
            pid,
            ver,
            manufacturer: u16::from_be_bytes([midh, midl]),
        })
    }

    /// Reads the ids ([`Ov2640::read_id`]) and checks that they say OV2640.
    pub async fn check_id(&mut self) -> Result<(), Error<I::Error>> {
        let id = self.read_id().await.map_err(Error::Bus)?;
        if id.is_ov2640() {
            Ok(())
        } else {
            Err(Error::WrongChip {
                pid: id.pid,
                ver: id.ver,
                manufacturer: id.manufacturer,
            })
        }
    }

    /// Checks the id, resets the sensor and configures it (see the module documentation for
    /// the sequence). Returns the clock plan in force. The configuration is validated before
    /// anything is sent.
    pub async fn init<D: DelayNs>(
        &mut self,
        delay: &mut D,
        config: &Config,
    ) -> Result<ClockPlan, Error<I::Error>> {
        let plan =
            plan_clock(config.xclk_hz, config.resolution, config.fps).map_err(Error::Config)?;
        if let Exposure::Manual { lines: 0, .. } = config.exposure {
            return Err(Error::Config(ConfigError::ZeroExposure));
        }
        self.check_id().await?;

        // Every register back to its default, then give the sensor time to come back. The
        // reset may or may not reset the bank select as well: select again before the next
        // access.
        self.write_register(Bank::Sensor, reg::sensor::COM7, COM7_RESET)
            .await?;
        self.bank = None;
        delay.delay_us(RESET_SETTLE_US).await;

        self.configure_sensor(config, &plan).await?;
        self.configure_dsp(config.resolution).await?;

        self.max_exposure_lines = u16::try_from(plan.timing.frame_lines).unwrap_or(u16::MAX);
        self.set_exposure(config.exposure).await?;
        Ok(plan)
    }

    /// Sensor bank: mode, window, clock, frame length, sync polarity, orientation.
    async fn configure_sensor(
        &mut self,
        config: &Config,
        plan: &ClockPlan,
    ) -> Result<(), Error<I::Error>> {
        use reg::sensor::*;
        // The 800x600 mode (full field of view, subsampled by two).
        self.write_register(Bank::Sensor, COM7, COM7_SVGA).await?;
        // The window: 400 x 300 units of two pixels, split into the MSB registers and the
        // LSB fields of REG32 (horizontal, 3 bits) and COM1 (vertical, 2 bits).
        let (h_start, width, v_start, height) = SVGA_WINDOW;
        let h_end = h_start + width;
        let v_end = v_start + height;
        self.write_register(Bank::Sensor, HREFST, (h_start >> 3) as u8)
            .await?;
        self.write_register(Bank::Sensor, HREFEND, (h_end >> 3) as u8)
            .await?;
        self.write_register(
            Bank::Sensor,
            REG32,
            (((h_end & 0x7) << 3) | (h_start & 0x7)) as u8,
        )
        .await?;
        self.write_register(Bank::Sensor, VSTRT, (v_start >> 2) as u8)
            .await?;
        self.write_register(Bank::Sensor, VEND, (v_end >> 2) as u8)
            .await?;
        self.write_register(
            Bank::Sensor,
            COM1,
            (((v_end & 0x3) << 2) | (v_start & 0x3)) as u8,
        )
        .await?;
        // The SVGA readout timing (see REG3D) and the sensor clock.
        self.write_register(Bank::Sensor, REG3D, REG3D_SVGA).await?;
        self.write_register(Bank::Sensor, CLKRC, plan.clkrc())
            .await?;
        // Line length: no dummy pixels (the frame rate is set with whole lines).
        self.write_register(Bank::Sensor, REG2A, 0x00).await?;
        self.write_register(Bank::Sensor, FRARL, 0x00).await?;
        // Frame length: the dummy lines of the plan.
        let [dummy_lo, dummy_hi] = plan.dummy_lines.to_le_bytes();
        self.write_register(Bank::Sensor, FLL, dummy_lo).await?;
        self.write_register(Bank::Sensor, FLH, dummy_hi).await?;
        // VSYNC high between frames (as the OV7725's), HREF and PCLK as reset.
        self.write_register(Bank::Sensor, COM10, COM10_VSYNC_NEGATIVE)
            .await?;
        // Orientation; the exposure bits [1:0] are written with the exposure.
        let mut reg04 = REG04_RESERVED | REG04_HREF0;
        if config.mirror {
            reg04 |= REG04_MIRROR;
        }
        if config.vflip {
            reg04 |= REG04_VFLIP | REG04_VREF0;
        }
        self.reg04 = reg04;
        self.write_register(Bank::Sensor, REG04, reg04).await
    }

    /// DSP bank: input size, down-sampling, zoom to the output size, output clock, format.
    async fn configure_dsp(&mut self, resolution: Resolution) -> Result<(), Error<I::Error>> {
        use reg::dsp::*;
        // Sensor data straight through and the output port held in reset while the DSP's
        // sizes change, so no half-configured frame goes out.
        self.write_register(Bank::Dsp, R_BYPASS, R_BYPASS_BYPASS)
            .await?;
        self.write_register(Bank::Dsp, RESET, RESET_DVP).await?;

        // The image the DSP receives: 800x600 (multiples of 8: SIZEL's LSB fields are 0).
        let (w_in, h_in) = (SVGA_WIDTH, SVGA_HEIGHT);
        self.write_register(Bank::Dsp, HSIZE8, (w_in >> 3) as u8)
            .await?;
        self.write_register(Bank::Dsp, VSIZE8, (h_in >> 3) as u8)
            .await?;
        let sizel = (((w_in >> 11) & 0x1) << 6) | ((w_in & 0x7) << 3) | (h_in & 0x7);
        self.write_register(Bank::Dsp, SIZEL, sizel as u8).await?;
        self.write_register(Bank::Dsp, CTRL2, CTRL2_YUV_SCALED)
            .await?;

        // The zoom stage's input window: all of it, no offset (units of 4).
        let (zw, zh) = (w_in / 4, h_in / 4);
        let (down, dvp_divider) = scaling(resolution);
        self.write_register(Bank::Dsp, CTRLI, CTRLI_LP_DP | (down << 3) | down)
            .await?;
        self.write_register(Bank::Dsp, HSIZE, zw as u8).await?;
        self.write_register(Bank::Dsp, VSIZE, zh as u8).await?;
        self.write_register(Bank::Dsp, XOFFL, 0x00).await?;
        self.write_register(Bank::Dsp, YOFFL, 0x00).await?;
        let vhyx = (((zh >> 8) & 0x1) << 7) | (((zw >> 8) & 0x1) << 3);
        self.write_register(Bank::Dsp, VHYX, vhyx as u8).await?;
        self.write_register(Bank::Dsp, TEST, (((zw >> 9) & 0x1) << 7) as u8)
            .await?;

        // The output size (units of 4) and its pixel clock.
        let out_w = (resolution.width() / 4) as u16;
        let out_h = (resolution.height() / 4) as u16;
        self.write_register(Bank::Dsp, ZMOW, out_w as u8).await?;
        self.write_register(Bank::Dsp, ZMOH, out_h as u8).await?;
        let zmhh = ((out_w >> 8) & 0x3) | (((out_h >> 8) & 0x1) << 2);
        self.write_register(Bank::Dsp, ZMHH, zmhh as u8).await?;
        self.write_register(Bank::Dsp, R_DVP_SP, dvp_divider)
            .await?;

        // YUV 4:2:2, Y first: byte swap off, U before V; CTRL0's statistics bits as read.
        self.write_register(Bank::Dsp, IMAGE_MODE, IMAGE_MODE_YUV422_Y_FIRST)
            .await?;
        let ctrl0 = self.read_register(Bank::Dsp, CTRL0).await?;
        let ctrl0 = (ctrl0 & !(CTRL0_V_FIRST | CTRL0_RAW)) | CTRL0_YUV422;
        self.write_register(Bank::Dsp, CTRL0, ctrl0).await?;

        // Output port running, DSP in the path.
        self.write_register(Bank::Dsp, RESET, 0x00).await?;
        self.write_register(Bank::Dsp, R_BYPASS, R_BYPASS_USE_DSP)
            .await
    }

    /// Switches exposure control (sensor AEC/AGC with a gain ceiling, or manual values).
    pub async fn set_exposure(&mut self, exposure: Exposure) -> Result<(), Error<I::Error>> {
        match exposure {
            Exposure::Auto { max_gain } => {
                let ceiling = (gain_ceiling_log2(max_gain) - 1) << 5;
                let com9 = self.read_register(Bank::Sensor, reg::sensor::COM9).await?;
                let com9 = (com9 & !COM9_CEILING_MASK) | ceiling;
                self.write_register(Bank::Sensor, reg::sensor::COM9, com9)
                    .await?;
                self.write_register(Bank::Sensor, reg::sensor::COM8, COM8_AUTO)
                    .await
            }
            Exposure::Manual { lines, gain } => {
                if lines == 0 {
                    return Err(Error::Config(ConfigError::ZeroExposure));
                }
                // AEC/AGC off first, or they overwrite the values below.
                self.write_register(Bank::Sensor, reg::sensor::COM8, COM8_MANUAL)
                    .await?;
                self.set_manual(lines, gain).await
            }
        }
    }

    /// Writes exposure (line periods, limited to 1 ..= [`Ov2640::max_exposure_lines`]) and
    /// gain (1x ..= 31x) while in manual mode: four register writes (plus a bank select if
    /// the DSP bank was selected), what a software exposure loop calls per adjustment.
    pub async fn set_manual(&mut self, lines: u16, gain: GainX16) -> Result<(), Error<I::Error>> {
        let lines = lines.clamp(1, self.max_exposure_lines.max(1));
        let (high, middle, low) = exposure_fields(lines);
        self.write_register(Bank::Sensor, reg::sensor::REG45, high)
            .await?;
        self.write_register(Bank::Sensor, reg::sensor::AEC, middle)
            .await?;
        self.write_register(Bank::Sensor, reg::sensor::REG04, self.reg04 | low)
            .await?;
        // GAIN has the OV7725's encoding (same formula in both datasheets).
        self.write_register(Bank::Sensor, reg::sensor::GAIN, gain_register(gain))
            .await
    }

    /// Reads the exposure (line periods) and gain in force (useful with the sensor's AEC on;
    /// the gain is GAIN's part, which covers the whole range up to the 32x ceiling).
    pub async fn read_exposure(&mut self) -> Result<(u16, GainX16), Error<I::Error>> {
        let reg45 = self.read_register(Bank::Sensor, reg::sensor::REG45).await?;
        let aec = self.read_register(Bank::Sensor, reg::sensor::AEC).await?;
        let reg04 = self.read_register(Bank::Sensor, reg::sensor::REG04).await?;
        let gain = self.read_register(Bank::Sensor, reg::sensor::GAIN).await?;
        Ok((
            exposure_from_fields(reg45, aec, reg04),
            gain_from_register(gain),
        ))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec;
    use std::vec::Vec;

    use super::reg::{dsp, sensor, BANK_SEL};
    use super::*;
    use crate::sensor::mock::{Access, Device, MockBus, MockDelay, Nack};
    use embassy_futures::block_on;

    /// An OV2640 at its address with the datasheet's id registers (and a few reset values
    /// the driver reads back).
    fn ov2640_bus(pidl: u8) -> MockBus {
        let mut device = Device::banked(I2C_ADDRESS);
        let s = Bank::Sensor as usize;
        device.regs[s][usize::from(sensor::PIDH)] = PRODUCT_ID_HIGH;
        device.regs[s][usize::from(sensor::PIDL)] = pidl;
        device.regs[s][usize::from(sensor::MIDH)] = 0x7F;
        device.regs[s][usize::from(sensor::MIDL)] = 0xA2;
        device.regs[s][usize::from(sensor::COM9)] = 0x50; // 8x ceiling, bit 4 set
        device.regs[Bank::Dsp as usize][usize::from(dsp::CTRL0)] = 0xC0 | CTRL0_V_FIRST;
        MockBus::with(vec![device])
    }

    fn bank(b: Bank) -> (u8, u8) {
        (BANK_SEL, b as u8)
    }

    /// The writes after the reset (the id check writes only the bank select before it).
    fn after_reset(bus: &MockBus) -> Vec<(u8, u8)> {
        let w = bus.writes();
        let reset = w
            .iter()
            .position(|&x| x == (sensor::COM7, COM7_RESET))
            .unwrap();
        w[reset + 1..].to_vec()
    }

    #[test]
    fn init_qvga_auto_writes_the_documented_sequence() {
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
        assert_eq!(
            after_reset(&bus),
            [
                bank(Bank::Sensor),      // re-selected after the reset
                (sensor::COM7, 0x40),    // SVGA mode
                (sensor::HREFST, 0x11),  // 137 >> 3
                (sensor::HREFEND, 0x43), // 537 >> 3
                (sensor::REG32, 0x09),   // 537 & 7 = 1, 137 & 7 = 1
                (sensor::VSTRT, 0x00),   // 2 >> 2
                (sensor::VEND, 0x4B),    // 302 >> 2
                (sensor::COM1, 0x0A),    // 302 & 3 = 2, 2 & 3 = 2
                (sensor::REG3D, 0x38),
                (sensor::CLKRC, 0x00), // 24 MHz / 1
                (sensor::REG2A, 0x00),
                (sensor::FRARL, 0x00),
                (sensor::FLL, 0x00), // no dummy lines
                (sensor::FLH, 0x00),
                (sensor::COM10, 0x02), // VSYNC negative
                (sensor::REG04, 0x28), // no flip, reserved + HREF[0]
                bank(Bank::Dsp),
                (dsp::R_BYPASS, 0x01),
                (dsp::RESET, 0x04),
                (dsp::HSIZE8, 0x64), // 800 / 8
                (dsp::VSIZE8, 0x4B), // 600 / 8
                (dsp::SIZEL, 0x00),
                (dsp::CTRL2, 0x3D),
                (dsp::CTRLI, 0x89), // LP_DP, halve both ways
                (dsp::HSIZE, 0xC8), // 800 / 4
                (dsp::VSIZE, 0x96), // 600 / 4
                (dsp::XOFFL, 0x00),
                (dsp::YOFFL, 0x00),
                (dsp::VHYX, 0x00),
                (dsp::TEST, 0x00),
                (dsp::ZMOW, 0x50), // 320 / 4
                (dsp::ZMOH, 0x3C), // 240 / 4
                (dsp::ZMHH, 0x00),
                (dsp::R_DVP_SP, 0x04),
                (dsp::IMAGE_MODE, 0x00), // YUV 4:2:2, Y first
                (dsp::CTRL0, 0xCE),      // statistics bits kept, U first, YUV 4:2:2
                (dsp::RESET, 0x00),
                (dsp::R_BYPASS, 0x00),
                bank(Bank::Sensor),
                (sensor::COM9, 0x50), // 8x ceiling (bits 7:5 = 010), bit 4 as read
                (sensor::COM8, 0xC5), // AEC + AGC on, banding filter off
            ]
        );
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

    #[test]
    fn manual_exposure_and_flips_at_init() {
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        let config = Config {
            resolution: Resolution::Vga,
            fps: 15,
            exposure: Exposure::Manual {
                lines: 0x0123,
                gain: GainX16(40), // 2.5x
            },
            vflip: true,
            mirror: true,
            ..Config::default()
        };
        let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        // 15 fps: 24 MHz / 2 = 12 MHz, no dummy lines.
        assert_eq!(
            (plan.doubler, plan.divider, plan.dummy_lines),
            (false, 1, 0)
        );
        assert_eq!(camera.max_exposure_lines(), 672);
        let w = after_reset(&camera.release());
        assert!(w.contains(&(sensor::CLKRC, 0x01)));
        // Mirror, flip and the one-row shift that keeps the Bayer phase.
        assert!(w.contains(&(sensor::REG04, 0xF8)));
        let tail = &w[w.len() - 5..];
        assert_eq!(
            tail,
            [
                (sensor::COM8, 0xC0),  // AEC and AGC off first
                (sensor::REG45, 0x00), // 0x0123 >> 10
                (sensor::AEC, 0x48),   // (0x0123 >> 2) & 0xFF
                (sensor::REG04, 0xFB), // flips kept, AEC[1:0] = 3
                (sensor::GAIN, 0x14),  // 2 x (1 + 4/16)
            ]
        );
    }

    #[test]
    fn set_manual_splits_and_clamps() {
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        // Before init the whole 16-bit range is accepted.
        block_on(camera.set_manual(0xFFFF, GainX16(16 * 64))).unwrap();
        block_on(camera.set_manual(0, GainX16(0))).unwrap();
        let bus = camera.release();
        assert_eq!(
            bus.writes(),
            [
                bank(Bank::Sensor),
                (sensor::REG45, 0x3F), // AEC[15:10], AGC[9:8] = 0
                (sensor::AEC, 0xFF),
                (sensor::REG04, 0x2B),
                (sensor::GAIN, 0xFF), // 64x clamped to 31x, the register's top
                // No bank select: the sensor bank is still selected.
                (sensor::REG45, 0x00), // 0 lines clamped to 1
                (sensor::AEC, 0x00),
                (sensor::REG04, 0x29),
                (sensor::GAIN, 0x00), // below 1x clamped to 1x
            ]
        );
        // After init: at most one frame (25 fps: 672 + 135 dummy lines = 807).
        let mut camera = Ov2640::new(bus);
        let config = Config {
            fps: 25,
            exposure: Exposure::Manual {
                lines: 100,
                gain: GainX16::ONE,
            },
            ..Config::default()
        };
        let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        assert_eq!(plan.dummy_lines, 135);
        assert_eq!(camera.max_exposure_lines(), 807);
        block_on(camera.set_manual(5000, GainX16::ONE)).unwrap();
        let w = camera.release().writes();
        assert_eq!(
            w[w.len() - 4..],
            [
                (sensor::REG45, 0x00),
                (sensor::AEC, 0xC9), // 807 = 0b11_0010_0111: 807 >> 2 = 201
                (sensor::REG04, 0x2B),
                (sensor::GAIN, 0x00),
            ]
        );
    }

    #[test]
    fn wrong_id_is_an_error_and_only_the_bank_select_is_written() {
        // An OV7670-like id, and an OV2640 id with another manufacturer.
        for (pid, ver, mid) in [
            (0x76, 0x73, 0x7FA2),
            (0x26, 0x42, 0x0000),
            (0x26, 0x43, 0x7FA2),
        ] {
            let mut bus = ov2640_bus(ver);
            let s = Bank::Sensor as usize;
            let device = bus.device(I2C_ADDRESS);
            device.regs[s][usize::from(sensor::PIDH)] = pid;
            let [midh, midl] = u16::to_be_bytes(mid);
            device.regs[s][usize::from(sensor::MIDH)] = midh;
            device.regs[s][usize::from(sensor::MIDL)] = midl;
            let mut camera = Ov2640::new(bus);
            let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
            assert_eq!(
                r,
                Err(Error::WrongChip {
                    pid,
                    ver,
                    manufacturer: mid
                })
            );
            assert_eq!(camera.release().writes(), [bank(Bank::Sensor)]);
        }
    }

    #[test]
    fn missing_sensor_is_a_bus_error_and_the_bank_is_reselected() {
        let mut camera = Ov2640::new(MockBus::default());
        let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
        assert_eq!(r, Err(Error::Bus(Nack)));
        // A failed bank select leaves the bank unknown: the next access selects it again.
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        block_on(camera.check_id()).unwrap();
        camera.bank = None;
        block_on(camera.set_manual(10, GainX16::ONE)).unwrap();
        let w = camera.release().writes();
        assert_eq!(w.iter().filter(|&&x| x == bank(Bank::Sensor)).count(), 2);
    }

    #[test]
    fn bad_configuration_is_refused_before_any_bus_traffic() {
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        let slow = Config {
            xclk_hz: 1_000_000,
            ..Config::default()
        };
        let r = block_on(camera.init(&mut MockDelay::default(), &slow));
        assert_eq!(r, Err(Error::Config(ConfigError::XclkOutOfRange)));
        let fast = Config {
            fps: 60,
            ..Config::default()
        };
        let r = block_on(camera.init(&mut MockDelay::default(), &fast));
        assert_eq!(r, Err(Error::Config(ConfigError::FrameRateUnreachable)));
        let zero = Config {
            exposure: Exposure::Manual {
                lines: 0,
                gain: GainX16::ONE,
            },
            ..Config::default()
        };
        let r = block_on(camera.init(&mut MockDelay::default(), &zero));
        assert_eq!(r, Err(Error::Config(ConfigError::ZeroExposure)));
        assert!(camera.release().log.is_empty());
    }

    #[test]
    fn clock_plans() {
        // 30 fps from 24 MHz: the input clock as it is (OmniVision's reference set-up).
        let p = plan_clock(24_000_000, Resolution::Qvga, 30).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (false, 0, 0));
        // 25 fps from 24 MHz: 135 dummy lines, as in OmniVision's frame-rate note.
        let p = plan_clock(24_000_000, Resolution::Qvga, 25).unwrap();
        assert_eq!(p.dummy_lines, 135);
        assert!((p.timing.fps() - 25.0).abs() < 0.05, "{}", p.timing.fps());
        // A 12 MHz clock (OpenMV-style) needs the doubler for 30 fps.
        let p = plan_clock(12_000_000, Resolution::Vga, 30).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (true, 0, 0));
        assert_eq!(p.timing.pclk_hz, 24_000_000);
        // ... and not for 15 fps.
        let p = plan_clock(12_000_000, Resolution::Qvga, 15).unwrap();
        assert_eq!((p.doubler, p.divider, p.dummy_lines), (false, 0, 0));
        // A slow rate is reached with the divider, then dummy lines.
        let p = plan_clock(24_000_000, Resolution::Qvga, 1).unwrap();
        assert!((p.timing.fps() - 1.0).abs() < 0.005, "{}", p.timing.fps());
        // Beyond the SVGA mode's 30 fps, and zero, are refused.
        assert_eq!(
            plan_clock(24_000_000, Resolution::Qvga, 31),
            Err(ConfigError::FrameRateUnreachable)
        );
        assert_eq!(
            plan_clock(24_000_000, Resolution::Qvga, 0),
            Err(ConfigError::FrameRateUnreachable)
        );
        assert_eq!(
            plan_clock(40_000_000, Resolution::Qvga, 30),
            Err(ConfigError::XclkOutOfRange)
        );
    }

    #[test]
    fn exposure_fields_round_trip() {
        for lines in [0u16, 1, 3, 4, 0x3FF, 0x400, 0x1234, 0xFFFF] {
            let (high, middle, low) = exposure_fields(lines);
            assert!(high <= 0x3F && low <= 0x03);
            // Whatever else the registers hold (flip bits, AGC[9:8]) is ignored.
            assert_eq!(exposure_from_fields(high | 0xC0, middle, low | 0xFC), lines);
        }
    }

    #[test]
    fn read_exposure_uses_the_sensor_bank_and_separate_transactions() {
        let mut bus = ov2640_bus(0x42);
        let device = bus.device(I2C_ADDRESS);
        let s = Bank::Sensor as usize;
        device.regs[s][usize::from(sensor::REG45)] = 0xC1; // AGC[9:8] set, AEC[15:10] = 1
        device.regs[s][usize::from(sensor::AEC)] = 0x02;
        device.regs[s][usize::from(sensor::REG04)] = 0x2A;
        device.regs[s][usize::from(sensor::GAIN)] = 0x30; // 4x

        // Something else at GAIN's address in the DSP bank, to catch a read from the wrong bank.
        device.regs[Bank::Dsp as usize][usize::from(sensor::GAIN)] = 0xFF;
        let mut camera = Ov2640::new(bus);
        let (lines, gain) = block_on(camera.read_exposure()).unwrap();
        assert_eq!((lines, gain), (0x040A, GainX16(64)));
    }

    #[test]
    fn init_after_a_power_cycle_selects_the_bank_again() {
        // Detected (sensor bank selected and remembered), then power-cycled through the
        // pins, which puts the bank select back to the DSP bank.
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        block_on(camera.check_id()).unwrap();
        camera.i2c.device(I2C_ADDRESS).bank = Bank::Dsp as usize;
        block_on(camera.init(&mut MockDelay::default(), &Config::default())).unwrap();
        let w = camera.release().writes();
        assert_eq!(
            w[..3],
            [bank(Bank::Sensor), bank(Bank::Sensor), (sensor::COM7, 0x80)]
        );
    }

    #[test]
    fn explicit_bank_select_write_forgets_the_bank() {
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        block_on(camera.write_register(Bank::Sensor, BANK_SEL, 0)).unwrap();
        block_on(camera.write_register(Bank::Sensor, sensor::GAIN, 0x10)).unwrap();
        let bus = camera.release();
        assert_eq!(
            bus.writes(),
            [
                bank(Bank::Sensor),
                (BANK_SEL, 0),
                bank(Bank::Sensor),
                (sensor::GAIN, 0x10)
            ]
        );
        let mut bus = bus;
        assert_eq!(bus.device(I2C_ADDRESS).regs[1][0], 0x10);
    }
}
