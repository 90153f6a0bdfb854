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
//! What this driver sets up, and nothing else (every register not named here or in the
//! [`table`]s keeps its reset value):
//!
//! - **Identity**: PIDH/PIDL must read `0x26`/`0x40..=0x42` and MIDH/MIDL `0x7F`/`0xA2`
//!   before anything but the bank select is written, so a wrong device is an error, not a
//!   device we scribble on.
//! - **Reset**: COM7 bit 7 in the sensor bank puts every register back to its default
//!   ([`RESET_SETTLE_US`]).
//! - **OmniVision's reference set-up** ([`table`]): the sensor's reserved analog and readout
//!   registers, the tuning of its own AEC, the SVGA mode's analog timing and the DSP's
//!   colour-processing block (pixel correction, gamma, white balance, colour matrix), with
//!   the values every working OV2640 driver writes. Most of these registers are marked
//!   reserved in the datasheet and their meaning is not published; left at their power-up
//!   values the sensor is not in the state any of those drivers run it in, and the image is
//!   likely unusable. The tables leave out every register this driver derives itself (the
//!   items below), so nothing in them can undo the mode, the window, the clock plan, the
//!   scaling, the format, the sync polarity or the exposure mode.
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
//!   (U before V), plus the DSP output settings OmniVision pairs with that byte order
//!   ([`table::YUV422`]). The camera interface keeps every first byte of a pair: 8-bit grey.
//! - **Frame rate**: the sensor clock is `XCLK x (2 if CLKRC's doubler) / (CLKRC[5:0] + 1)`,
//!   one SVGA line is 1190 sensor clocks and one frame 672 lines (OmniVision's frame-rate
//!   note for the SVGA mode: 24 MHz gives 30.01 fps; the SVGA banding steps in
//!   [`table::SVGA_TIMING`], 202 lines per 10 ms, say the same); [`plan_clock`] picks the
//!   doubler and divider and adds dummy lines (FLL/FLH) to hit the requested rate. The
//!   output pixel clock is set by hand (R_DVP_SP, automatic mode off), so it is the one
//!   [`FrameTiming::pclk_hz`] reports.
//! - **Sync signals**: VSYNC is inverted (COM10 bit 1) so it is high between frames like the
//!   OV7725's; HREF (high during a line's data) and PCLK (data changes on the falling edge)
//!   stay as reset. One camera interface set-up then serves both sensors (see
//!   [`crate::any`]).
//! - **Exposure and gain**: the sensor's own AEC/AGC with a gain ceiling (COM8, COM9), or
//!   manual exposure (16 bits of line periods split over REG45, AEC and REG04) and gain
//!   (GAIN). With a hard exposure limit, run
//!   [`touchdown_core::sensor::exposure::AutoExposure`] and feed its manual settings here.
//!   The banding filter stays off in both.
//!
//! The whole set-up is data: the tables and the values derived here are lists of
//! [`Setting`]s that one loop writes ([`Ov2640::init`]), so the firmware carries one copy of
//! the register-write code instead of one per register. A write that fails stops the set-up
//! with [`Error::Write`], which names the bank and register.
//!
//! The bus is SCCB: a register read is a write of the register address, a STOP, then a
//! separate one-byte read ([`Ov2640::read_register`]), never `write_read`.
//!
//! Sources for the register semantics: the OV2640 datasheet's register tables (sensor bank:
//! GAIN, COM1, REG04, COM2, AEC, CLKRC, COM7..COM10, window, AEW/AEB/VV, REG32, REG45,
//! FLL/FLH, COM25, BD50/BD60, PIDH/PIDL, MIDH/MIDL; DSP bank: R_BYPASS, CTRLI, size and zoom
//! registers, CTRL0/CTRL2/CTRL3, R_DVP_SP, IMAGE_MODE, RESET, MC_BIST), OmniVision's
//! software application notes (SVGA frame timing, dummy lines) and the bit definitions
//! documented in the Linux `ov2640` driver. The derived values are computed here. The values
//! in [`table`] are OmniVision's reference settings as three open drivers carry them (Linux
//! `drivers/media/i2c/ov2640.c`, OpenMV `drivers/sensors/ov2640.c`, esp32-camera
//! `sensors/private_include/ov2640_settings.h`); each table says which one it follows where
//! they differ.

use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;

use crate::ov7725::{gain_from_register, gain_register};
use crate::{gain_ceiling_log2, Config, ConfigError, Exposure, FrameTiming, GainX16, Resolution};

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

/// Register addresses: the documented ones this driver or its [`table`]s write, with
/// what each one does. (The tables write further registers by number: those whose meaning
/// is not published.)
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
        /// COM2: bit 4 standby, bits \[1:0\] output drive strength (00 1x, 01 2x, 10 3x, 11
        /// 4x).
        pub const COM2: u8 = 0x09;
        /// Product id MSB, read-only (0x26).
        pub const PIDH: u8 = 0x0A;
        /// Product id LSB, read-only (0x40..=0x42).
        pub const PIDL: u8 = 0x0B;
        /// COM4: named in OmniVision's register list, its bits not documented. The SVGA
        /// timing table writes it with the mode's other analog settings.
        pub const COM4: u8 = 0x0D;
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
        /// AEW: the sensor's AEC/AGC stable region, upper limit (average luminance).
        pub const AEW: u8 = 0x24;
        /// AEB: the sensor's AEC/AGC stable region, lower limit.
        pub const AEB: u8 = 0x25;
        /// VV: the AEC/AGC fast-mode region, bits \[7:4\] upper and \[3:0\] lower threshold.
        pub const VV: u8 = 0x26;
        /// REG2A: bits \[7:4\] dummy pixels per line \[11:8\] (longer line; unused, written 0).
        pub const REG2A: u8 = 0x2A;
        /// FRARL: dummy pixels per line \[7:0\].
        pub const FRARL: u8 = 0x2B;
        /// REG32: bits \[7:6\] PCLK divider (00 none), bits \[5:3\] horizontal window end
        /// \[2:0\], bits \[2:0\] horizontal window start \[2:0\].
        pub const REG32: u8 = 0x32;
        /// ARCOM2: bit 2 zoom window horizontal start point; the other bits are not
        /// documented. Part of the SVGA mode's analog timing.
        pub const ARCOM2: u8 = 0x34;
        /// Reserved in the datasheet. OmniVision's frame-rate note writes 0x38 with the SVGA
        /// mode (0x34 with UXGA) as part of every SVGA clock set-up; it goes with the
        /// mode's readout timing, and [`super::super::table::SVGA_TIMING`] writes it.
        pub const REG3D: u8 = 0x3D;
        /// REG45: bits \[7:6\] AGC\[9:8\] (extra gain beyond GAIN; written 0), bits
        /// \[5:0\] exposure AEC\[15:10\].
        pub const REG45: u8 = 0x45;
        /// FLL: dummy lines per frame \[7:0\] (longer frame: lower frame rate).
        pub const FLL: u8 = 0x46;
        /// FLH: dummy lines per frame \[15:8\].
        pub const FLH: u8 = 0x47;
        /// COM25: bits \[7:6\] 50 Hz banding step \[9:8\], bits \[5:4\] 60 Hz banding step
        /// \[9:8\] (see [`BD50`], [`BD60`]).
        pub const COM25: u8 = 0x4E;
        /// BD50: 50 Hz banding step \[7:0\], in lines: the exposure of 1/100 s, the step the
        /// banding filter (COM8 bit 5) holds the exposure to under 50 Hz light.
        pub const BD50: u8 = 0x4F;
        /// BD60: 60 Hz banding step \[7:0\], in lines: the exposure of 1/120 s.
        pub const BD60: u8 = 0x50;
        /// REG5A: bits \[7:4\] most 50 Hz banding steps per frame minus one, bits \[3:0\]
        /// most 60 Hz banding steps minus one.
        pub const REG5A: u8 = 0x5A;
        /// REG5D..REG60: AEC weights of the 16 zones of the image (2 bits each), the
        /// first of four.
        pub const REG5D: u8 = 0x5D;
        /// HISTO_LOW: the AEC histogram algorithm's low level.
        pub const HISTO_LOW: u8 = 0x61;
        /// HISTO_HIGH: the AEC histogram algorithm's high level.
        pub const HISTO_HIGH: u8 = 0x62;
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
        /// BPADDR: address port of the special-digital-effects (SDE) registers, which are
        /// reached indirectly: write the address here, then the data to [`BPDATA`] (the
        /// address steps on by one with each data byte).
        pub const BPADDR: u8 = 0x7C;
        /// BPDATA: data port of the SDE registers.
        pub const BPDATA: u8 = 0x7D;
        /// CTRL2: bit 5 down-sampling (DCW) on, bit 4 special digital effects, bit 3 UV
        /// adjust, bit 2 UV average, bit 0 colour matrix (RGB to YUV).
        pub const CTRL2: u8 = 0x86;
        /// CTRL3: bit 7 black-pixel correction, bit 6 white-pixel correction; bit 4 is set
        /// by OmniVision's settings and not documented.
        pub const CTRL3: u8 = 0x87;
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
        /// MC_BIST: bit 7 resets the DSP's microcontroller, bit 6 selects its boot ROM.
        pub const MC_BIST: u8 = 0xF9;
    }
}

/// COM7 bit 7: reset every register to its default.
const COM7_RESET: u8 = 0x80;
/// COM7 bits \[6:4\] = 100: the SVGA mode (zoom and colour bar off).
const COM7_SVGA: u8 = 0x40;
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

/// One register write of the set-up: the bank, the register in it, the value.
///
/// The set-up is a list of these ([`table`] and the values derived here), written in order by
/// one loop that selects the bank only when it changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Setting {
    /// The bank the register is in.
    pub bank: Bank,
    /// The register address in that bank (never [`reg::BANK_SEL`]: the driver selects banks).
    pub register: u8,
    /// The value written.
    pub value: u8,
}

impl Setting {
    /// A write to the sensor bank.
    pub const fn sensor(register: u8, value: u8) -> Self {
        Setting {
            bank: Bank::Sensor,
            register,
            value,
        }
    }

    /// A write to the DSP bank.
    pub const fn dsp(register: u8, value: u8) -> Self {
        Setting {
            bank: Bank::Dsp,
            register,
            value,
        }
    }
}

/// OmniVision's reference register values: what the driver writes besides the values it
/// derives.
///
/// The three open drivers that run this sensor (Linux, OpenMV, esp32-camera) write the same
/// vendor set-up after the reset, most of it to registers the datasheet marks reserved. The
/// values are facts about the silicon taken from them; the grouping, the order relative to
/// the derived values and the omissions are this driver's:
///
/// - Every register the driver derives is left out (COM7, CLKRC, COM8, COM9, COM10, REG04,
///   FLL/FLH, the window, the DSP sizes and zoom, R_DVP_SP, IMAGE_MODE, CTRL0, R_BYPASS).
///   The references write some of them with other values (the UXGA mode with zoom, AEC and
///   AGC with the banding filter on, 0x22 dummy lines, the automatic PCLK mode, a CTRL0 with
///   the AEC statistics bits cleared); here the derived value is the only one written.
///   COM3 (banding auto-detection, written by Linux and OpenMV) keeps its reset value: the
///   banding filter stays off.
///   The one overlap is the DSP's RESET: [`table::DSP_COMMON`] holds the JPEG and output blocks in
///   reset as the references do, and the derived sequence releases them last.
/// - The reference set-up is for the UXGA mode; the SVGA mode's analog timing replaces its
///   UXGA values ([`table::SVGA_TIMING`]), written after the mode select as esp32-camera, the one
///   reference that runs the SVGA mode, does.
/// - Registers named `0x..` without a constant are undocumented: their meaning is unknown
///   and the value is the vendor's.
pub mod table {
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
}

/// The SVGA mode select and the window (sensor bank), derived from [`SVGA_WINDOW`]: the
/// window registers hold the start and end in units of two pixels (HREFST/HREFEND the MSBs,
/// REG32 the 3 LSBs of each) and two lines (VSTRT/VEND the MSBs, COM1 the 2 LSBs).
const MODE_AND_WINDOW: [Setting; 7] = {
    use reg::sensor::*;
    let (h_start, width, v_start, height) = SVGA_WINDOW;
    let h_end = h_start + width;
    let v_end = v_start + height;
    [
        Setting::sensor(COM7, COM7_SVGA),
        Setting::sensor(HREFST, (h_start >> 3) as u8),
        Setting::sensor(HREFEND, (h_end >> 3) as u8),
        Setting::sensor(REG32, (((h_end & 0x7) << 3) | (h_start & 0x7)) as u8),
        Setting::sensor(VSTRT, (v_start >> 2) as u8),
        Setting::sensor(VEND, (v_end >> 2) as u8),
        Setting::sensor(COM1, (((v_end & 0x3) << 2) | (v_start & 0x3)) as u8),
    ]
};

/// The DSP in bypass (sensor data straight through) while its sizes change, so no
/// half-configured frame goes out.
const BYPASS_DSP: [Setting; 1] = [Setting::dsp(reg::dsp::R_BYPASS, R_BYPASS_BYPASS)];

/// The DSP's sizes, scaling, output clock and format for `resolution` (DSP bank).
///
/// The output port is held in reset, the DSP is told it receives 800x600 (multiples of 8:
/// SIZEL's LSB fields are 0), the zoom stage takes all of it with no offset (units of 4),
/// QVGA halves it first ([`scaling`]), the zoom scales to the output size (units of 4), the
/// output PCLK divider is set by hand (bit 7, the automatic mode, clear), and the format is
/// YUV 4:2:2 with Y first.
const fn dsp_scaling(resolution: Resolution) -> [Setting; 17] {
    use reg::dsp::*;
    let (w_in, h_in) = (SVGA_WIDTH, SVGA_HEIGHT);
    let sizel = (((w_in >> 11) & 0x1) << 6) | ((w_in & 0x7) << 3) | (h_in & 0x7);
    let (zw, zh) = (w_in / 4, h_in / 4);
    let vhyx = (((zh >> 8) & 0x1) << 7) | (((zw >> 8) & 0x1) << 3);
    let (down, dvp_divider) = scaling(resolution);
    let out_w = (resolution.width() / 4) as u16;
    let out_h = (resolution.height() / 4) as u16;
    let zmhh = ((out_w >> 8) & 0x3) | (((out_h >> 8) & 0x1) << 2);
    [
        Setting::dsp(RESET, RESET_DVP),
        Setting::dsp(HSIZE8, (w_in >> 3) as u8),
        Setting::dsp(VSIZE8, (h_in >> 3) as u8),
        Setting::dsp(SIZEL, sizel as u8),
        Setting::dsp(CTRL2, CTRL2_YUV_SCALED),
        Setting::dsp(CTRLI, CTRLI_LP_DP | (down << 3) | down),
        Setting::dsp(HSIZE, zw as u8),
        Setting::dsp(VSIZE, zh as u8),
        Setting::dsp(XOFFL, 0x00),
        Setting::dsp(YOFFL, 0x00),
        Setting::dsp(VHYX, vhyx as u8),
        Setting::dsp(TEST, (((zw >> 9) & 0x1) << 7) as u8),
        Setting::dsp(ZMOW, out_w as u8),
        Setting::dsp(ZMOH, out_h as u8),
        Setting::dsp(ZMHH, zmhh as u8),
        Setting::dsp(R_DVP_SP, dvp_divider),
        Setting::dsp(IMAGE_MODE, IMAGE_MODE_YUV422_Y_FIRST),
    ]
}

/// [`dsp_scaling`] for QVGA, computed at compile time.
const DSP_QVGA: [Setting; 17] = dsp_scaling(Resolution::Qvga);
/// [`dsp_scaling`] for VGA, computed at compile time.
const DSP_VGA: [Setting; 17] = dsp_scaling(Resolution::Vga);

/// The clock, frame length, sync polarity and orientation (sensor bank), from the clock plan
/// and REG04 (orientation bits; the exposure bits \[1:0\] are written with the exposure).
fn clock_and_sync(plan: &ClockPlan, reg04: u8) -> [Setting; 7] {
    use reg::sensor::*;
    let [dummy_lo, dummy_hi] = plan.dummy_lines.to_le_bytes();
    [
        Setting::sensor(CLKRC, plan.clkrc()),
        // Line length: no dummy pixels (the frame rate is set with whole lines).
        Setting::sensor(REG2A, 0x00),
        Setting::sensor(FRARL, 0x00),
        // Frame length: the dummy lines of the plan.
        Setting::sensor(FLL, dummy_lo),
        Setting::sensor(FLH, dummy_hi),
        // VSYNC high between frames (as the OV7725's), HREF and PCLK as reset.
        Setting::sensor(COM10, COM10_VSYNC_NEGATIVE),
        Setting::sensor(REG04, reg04),
    ]
}

/// The last DSP writes: CTRL0 (as read, with YUV 4:2:2 on, raw off, U before V), then the
/// output port out of reset and the DSP back in the path.
const fn dsp_start(ctrl0_as_read: u8) -> [Setting; 3] {
    use reg::dsp::*;
    let ctrl0 = (ctrl0_as_read & !(CTRL0_V_FIRST | CTRL0_RAW)) | CTRL0_YUV422;
    [
        Setting::dsp(CTRL0, ctrl0),
        Setting::dsp(RESET, 0x00),
        Setting::dsp(R_BYPASS, R_BYPASS_USE_DSP),
    ]
}

/// REG04 for `config`'s orientation, without the exposure bits.
const fn orientation(config: &Config) -> u8 {
    let mut reg04 = REG04_RESERVED | REG04_HREF0;
    if config.mirror {
        reg04 |= REG04_MIRROR;
    }
    if config.vflip {
        reg04 |= REG04_VFLIP | REG04_VREF0;
    }
    reg04
}

/// Why the sensor could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// A register read failed (no device, NACK, bus fault): the id check, or the read of a
    /// read-modify-write.
    Bus(E),
    /// A register write failed (NACK, bus fault): the bank and register it was for
    /// ([`reg::BANK_SEL`] for a failed bank select) and the bus error. The writes before it
    /// went through, so the sensor is half set up: run [`Ov2640::init`] again.
    Write {
        /// The bank of the register.
        bank: Bank,
        /// The register.
        register: u8,
        /// The bus error.
        error: E,
    },
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
    /// A failure is [`Error::Write`] naming the register, or [`reg::BANK_SEL`] if the bank
    /// select before it failed.
    pub async fn write_register(
        &mut self,
        bank: Bank,
        register: u8,
        value: u8,
    ) -> Result<(), Error<I::Error>> {
        self.select_bank(bank).await.map_err(|error| Error::Write {
            bank,
            register: reg::BANK_SEL,
            error,
        })?;
        let result = self
            .i2c
            .write(I2C_ADDRESS, &[register, value])
            .await
            .map_err(|error| Error::Write {
                bank,
                register,
                error,
            });
        if register == reg::BANK_SEL {
            // The caller switched banks behind the driver's back: forget which is selected.
            self.bank = None;
        }
        result
    }

    /// Writes every [`Setting`] of every part, in order, stopping at the first failure.
    ///
    /// Every multi-register write of the driver goes through here: one loop, one await, so
    /// the register-write code exists once in the firmware instead of once per register.
    async fn write_settings(&mut self, parts: &[&[Setting]]) -> Result<(), Error<I::Error>> {
        for part in parts {
            for setting in *part {
                self.write_register(setting.bank, setting.register, setting.value)
                    .await?;
            }
        }
        Ok(())
    }

    /// Reads PIDH/PIDL and MIDH/MIDL (sensor bank). The bank select before the reads is the
    /// only write; it is always sent, because the sensor may have been reset or power-cycled
    /// through its pins since the driver last selected a bank.
    pub async fn read_id(&mut self) -> Result<ChipId, I::Error> {
        use reg::sensor::{MIDH, MIDL, PIDH, PIDL};
        self.bank = None;
        let mut id = [0u8; 4];
        for (value, register) in id.iter_mut().zip([PIDH, PIDL, MIDH, MIDL]) {
            *value = self.read_raw(Bank::Sensor, register).await?;
        }
        let [pid, ver, midh, midl] = id;
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

    /// Checks the id, resets the sensor and configures it. Returns the clock plan in force.
    /// The configuration is validated before anything is sent.
    ///
    /// The order of the writes after the reset, each part a list of [`Setting`]s:
    ///
    /// 1. [`table::DSP_PRELUDE`], [`table::SENSOR_COMMON`], [`table::DSP_COMMON`]: the
    ///    vendor's common set-up.
    /// 2. The DSP in bypass, COM7 = SVGA and the window, [`table::SVGA_TIMING`] (after the
    ///    mode select, as the reference that runs this mode writes it).
    /// 3. The derived sensor values: CLKRC and the frame length from [`plan_clock`], COM10,
    ///    REG04.
    /// 4. The derived DSP values: sizes, scaling, PCLK divider, IMAGE_MODE; then
    ///    [`table::YUV422`]; then CTRL0 (read, modified, written), the output port out of
    ///    reset and the DSP back in the path.
    /// 5. The exposure mode ([`Ov2640::set_exposure`]): COM8 (and COM9) last, so the
    ///    sensor's AEC/AGC are in the mode asked for whatever came before.
    ///
    /// No table holds a register of parts 2-5 (but the DSP's RESET, released in part 4), so
    /// every derived value is the last written to its register.
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

        self.reg04 = orientation(config);
        let clock = clock_and_sync(&plan, self.reg04);
        let dsp: &[Setting] = match config.resolution {
            Resolution::Qvga => &DSP_QVGA,
            Resolution::Vga => &DSP_VGA,
        };
        self.write_settings(&[
            table::DSP_PRELUDE,
            table::SENSOR_COMMON,
            table::DSP_COMMON,
            &BYPASS_DSP,
            &MODE_AND_WINDOW,
            table::SVGA_TIMING,
            &clock,
            dsp,
            table::YUV422,
        ])
        .await?;
        // CTRL0's AEC statistics bits [7:5] are kept as the sensor has them.
        let ctrl0 = self.read_register(Bank::Dsp, reg::dsp::CTRL0).await?;
        self.write_settings(&[&dsp_start(ctrl0)]).await?;

        self.max_exposure_lines = u16::try_from(plan.timing.frame_lines).unwrap_or(u16::MAX);
        self.set_exposure(config.exposure).await?;
        Ok(plan)
    }

    /// Switches exposure control (sensor AEC/AGC with a gain ceiling, or manual values).
    pub async fn set_exposure(&mut self, exposure: Exposure) -> Result<(), Error<I::Error>> {
        use reg::sensor::{COM8, COM9};
        match exposure {
            Exposure::Auto { max_gain } => {
                let ceiling = (gain_ceiling_log2(max_gain) - 1) << 5;
                let com9 = self.read_register(Bank::Sensor, COM9).await?;
                let com9 = (com9 & !COM9_CEILING_MASK) | ceiling;
                self.write_settings(&[&[
                    Setting::sensor(COM9, com9),
                    Setting::sensor(COM8, COM8_AUTO),
                ]])
                .await
            }
            Exposure::Manual { lines, gain } => {
                if lines == 0 {
                    return Err(Error::Config(ConfigError::ZeroExposure));
                }
                // AEC/AGC off first, or they overwrite the values after it.
                let manual = self.manual_settings(lines, gain);
                self.write_settings(&[&[Setting::sensor(COM8, COM8_MANUAL)], &manual])
                    .await
            }
        }
    }

    /// Writes exposure (line periods, limited to 1 ..= [`Ov2640::max_exposure_lines`]) and
    /// gain (1x ..= 31x) while in manual mode: four register writes (plus a bank select if
    /// the DSP bank was selected), what a software exposure loop calls per adjustment.
    pub async fn set_manual(&mut self, lines: u16, gain: GainX16) -> Result<(), Error<I::Error>> {
        let manual = self.manual_settings(lines, gain);
        self.write_settings(&[&manual]).await
    }

    /// The register writes of a manual exposure and gain ([`Ov2640::set_manual`]).
    fn manual_settings(&self, lines: u16, gain: GainX16) -> [Setting; 4] {
        use reg::sensor::{AEC, GAIN, REG04, REG45};
        let lines = lines.clamp(1, self.max_exposure_lines.max(1));
        let (high, middle, low) = exposure_fields(lines);
        [
            Setting::sensor(REG45, high),
            Setting::sensor(AEC, middle),
            Setting::sensor(REG04, self.reg04 | low),
            // GAIN has the OV7725's encoding (same formula in both datasheets).
            Setting::sensor(GAIN, gain_register(gain)),
        ]
    }

    /// Reads the exposure (line periods) and gain in force (useful with the sensor's AEC on;
    /// the gain is GAIN's part, which covers the whole range up to the 32x ceiling).
    pub async fn read_exposure(&mut self) -> Result<(u16, GainX16), Error<I::Error>> {
        use reg::sensor::{AEC, GAIN, REG04, REG45};
        let mut values = [0u8; 4];
        for (value, register) in values.iter_mut().zip([REG45, AEC, REG04, GAIN]) {
            *value = self.read_register(Bank::Sensor, register).await?;
        }
        let [reg45, aec, reg04, gain] = values;
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
    use crate::mock::{Access, Device, MockBus, MockDelay, Nack};
    use embassy_futures::block_on;
    use embedded_hal_async::i2c::{ErrorType, I2c, Operation};

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

    /// The writes after the reset with the bank each went to, bank selects taken out. Fails
    /// the test if a bank select does not change the bank (the first one after the reset
    /// excepted: the reset leaves the bank unknown), or if a register is written before any
    /// bank was selected.
    fn banked_after_reset(bus: &MockBus) -> Vec<Setting> {
        let mut selected: Option<Bank> = None;
        let mut out = Vec::new();
        for (i, (register, value)) in after_reset(bus).into_iter().enumerate() {
            if register == BANK_SEL {
                let b = if value == 0 { Bank::Dsp } else { Bank::Sensor };
                assert!(
                    selected != Some(b),
                    "write {i}: bank {b:?} selected again while selected"
                );
                selected = Some(b);
            } else {
                let bank = selected.expect("a register written before any bank select");
                out.push(Setting {
                    bank,
                    register,
                    value,
                });
            }
        }
        out
    }

    /// A bus that refuses (NACKs) the `nth` write (0-based) to one register of one bank of
    /// the OV2640 and passes everything else to the mock.
    struct Refusing {
        bus: MockBus,
        bank: Bank,
        register: u8,
        nth: usize,
        seen: usize,
    }

    impl ErrorType for Refusing {
        type Error = Nack;
    }

    impl I2c for Refusing {
        async fn transaction(
            &mut self,
            address: u8,
            operations: &mut [Operation<'_>],
        ) -> Result<(), Nack> {
            if let [Operation::Write([register, _])] = operations {
                let bank = self.bus.device(I2C_ADDRESS).bank;
                if *register == self.register && bank == self.bank as usize {
                    self.seen += 1;
                    if self.seen == self.nth + 1 {
                        return Err(Nack);
                    }
                }
            }
            self.bus.transaction(address, operations).await
        }
    }

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
                        Setting::sensor(sensor::AEC, 75), // 300 >> 2
                        Setting::sensor(sensor::REG04, 0x78), // flip, VREF[0], 300 & 3 = 0
                        Setting::sensor(sensor::GAIN, 0x04), // 1.25x
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
    fn a_refused_write_is_an_error_naming_its_register_and_nothing_follows_it() {
        // The whole set-up on a bus that acknowledges everything.
        let mut camera = Ov2640::new(ov2640_bus(0x42));
        block_on(camera.init(&mut MockDelay::default(), &Config::default())).unwrap();
        let full = camera.release().log;
        // (bank selected when the write is refused, register, which of its writes in that
        // bank is refused, the error's bank).
        for (bank, register, nth, named_bank) in [
            (Bank::Sensor, 0x35, 0, Bank::Sensor),  // mid SVGA_TIMING
            (Bank::Dsp, dsp::BPDATA, 3, Bank::Dsp), // mid DSP_COMMON, a data port
            (Bank::Dsp, 0xE1, 1, Bank::Dsp),        // YUV422 (DSP_COMMON wrote it first)
            (Bank::Sensor, sensor::CLKRC, 0, Bank::Sensor), // a derived value
            // The select of the DSP bank right after the reset (the sensor bank still
            // selected): named as a write of BANK_SEL for the DSP bank.
            (Bank::Sensor, BANK_SEL, 0, Bank::Dsp),
        ] {
            let mut camera = Ov2640::new(Refusing {
                bus: ov2640_bus(0x42),
                bank,
                register,
                nth,
                seen: 0,
            });
            let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
            assert_eq!(
                r,
                Err(Error::Write {
                    bank: named_bank,
                    register,
                    error: Nack
                }),
                "{register:#04x}"
            );
            // What went through is the set-up up to the refused write, and nothing after it.
            let log = camera.release().bus.log;
            assert_eq!(log[..], full[..log.len()], "{register:#04x}");
            assert!(
                matches!(full[log.len()], Access::Write(_, r, _) if r == register),
                "{register:#04x}: {:?}",
                full[log.len()]
            );
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
