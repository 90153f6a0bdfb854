//! Register addresses: the documented ones this driver or its [`table`](super::table)s write, with
//! what each one does. (The tables write further registers by number: those whose meaning
//! is not published.)
//!
//! The register map on its own, bank by bank: the addresses and what their bits do, as the
//! datasheet documents them. The values written are the tables' and the derived set-up's.

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
