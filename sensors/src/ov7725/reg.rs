//! OV7725 register addresses (the subset this driver touches), with what each one does.
//!
//! The register map on its own: the addresses and the meaning of their bits, as the datasheet
//! gives them. The values the driver writes into them are derived in the parent module.

/// AGC gain. Bits `[7:4]` each double the gain (set from bit 4 upwards), bits `[3:0]` add
/// sixteenths: gain = 2^(set high bits) x (1 + `[3:0]`/16). Written by the AGC when on.
pub const GAIN: u8 = 0x00;
/// Exposure, bits `[15:8]` (`AEC[15:8]`), in line periods. Written by the AEC when on.
pub const AECH: u8 = 0x08;
/// Product id MSB, read-only (0x77).
pub const PID: u8 = 0x0A;
/// Product id LSB, read-only (0x21 for the OV7725).
pub const VER: u8 = 0x0B;
/// COM3: bit 7 vertical flip, bit 6 horizontal mirror, bit 4 YUV byte order (1: Y
/// first), bit 0 colour bar test pattern.
pub const COM3: u8 = 0x0C;
/// COM4: bits `[7:6]` PLL (00 bypass, 01 x4, 10 x6, 11 x8), bits `[5:4]` AEC evaluation
/// window (00 full frame), bit 0 reserved (reset value 1, kept).
pub const COM4: u8 = 0x0D;
/// Exposure, bits `[7:0]` (`AEC[7:0]`), in line periods.
pub const AEC: u8 = 0x10;
/// CLKRC: bit 7 reserved (reset value 1, kept), bit 6 use the input clock directly (no
/// prescaler), bits `[5:0]` prescaler n: internal clock = input / ((n + 1) x 2).
pub const CLKRC: u8 = 0x11;
/// COM7: bit 7 register reset (self-clearing), bit 6 resolution (1 QVGA, 0 VGA), bits
/// `[1:0]` output format (00 YUV, 01 processed Bayer, 10 RGB, 11 raw Bayer).
pub const COM7: u8 = 0x12;
/// COM8: bit 7 fast AEC/AGC, bit 6 unlimited AEC step, bit 5 banding filter, bit 4 AEC
/// below the banding value, bit 3 exposures shorter than one line, bit 2 AGC, bit 1
/// AWB, bit 0 AEC. Reset value 0xCF.
pub const COM8: u8 = 0x13;
/// COM9: bits `[6:4]` AGC gain ceiling (000 2x ... 100 32x); other bits kept as read.
pub const COM9: u8 = 0x14;
/// Horizontal window start, bits `[9:2]` (pixels).
pub const HSTART: u8 = 0x17;
/// Horizontal window size, bits `[9:2]` (pixels).
pub const HSIZE: u8 = 0x18;
/// Vertical window start, bits `[8:1]` (lines).
pub const VSTART: u8 = 0x19;
/// Vertical window size, bits `[8:1]` (lines).
pub const VSIZE: u8 = 0x1A;
/// Output width, bits `[9:2]` (pixels).
pub const HOUTSIZE: u8 = 0x29;
/// EXHCH: bits `[7:4]` dummy pixels `[11:8]`, bit 2 output height LSB, bits `[1:0]` output
/// width LSBs.
pub const EXHCH: u8 = 0x2A;
/// Dummy pixels per line, bits `[7:0]` (lengthen the line; unused, written 0).
pub const EXHCL: u8 = 0x2B;
/// Output height, bits `[8:1]` (lines).
pub const VOUTSIZE: u8 = 0x2C;
/// HREF: LSBs of the window: bit 6 `VSTART[0]`, bits `[5:4]` `HSTART[1:0]`, bit 2 `VSIZE[0]`,
/// bits `[1:0]` `HSIZE[1:0]`.
pub const HREF: u8 = 0x32;
/// Dummy lines per frame, bits `[7:0]` (lengthen the frame: lower frame rate).
pub const DM_LNL: u8 = 0x33;
/// Dummy lines per frame, bits `[15:8]`.
pub const DM_LNH: u8 = 0x34;
/// DSP_CTRL4: bits `[1:0]` DSP output (00 YUV/RGB, 10 RAW8, 11 RAW10).
pub const DSP_CTRL4: u8 = 0x67;
