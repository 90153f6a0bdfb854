//! The register values this driver derives from the configuration rather than copies from
//! the vendor's [`super::table`]s: the SVGA mode and window, the DSP's sizes, scaling, output
//! clock and format, the clock and frame length of the plan, the sync polarity and the
//! orientation.
//!
//! Each part is a list of [`Setting`]s that [`super::Ov2640::init`] writes in order with the
//! tables; kept apart from the driver so the set-up reads as data, and from the tables because
//! every value here is computed from a documented register layout.

use super::clock::scaling;
use super::*;

/// The SVGA mode select and the window (sensor bank), derived from [`SVGA_WINDOW`]: the
/// window registers hold the start and end in units of two pixels (HREFST/HREFEND the MSBs,
/// REG32 the 3 LSBs of each) and two lines (VSTRT/VEND the MSBs, COM1 the 2 LSBs).
pub(super) const MODE_AND_WINDOW: [Setting; 7] = {
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
pub(super) const BYPASS_DSP: [Setting; 1] = [Setting::dsp(reg::dsp::R_BYPASS, R_BYPASS_BYPASS)];

/// The DSP's sizes, scaling, output clock and format for `resolution` (DSP bank).
///
/// The output port is held in reset, the DSP is told it receives 800x600 (multiples of 8:
/// SIZEL's LSB fields are 0), the zoom stage takes all of it with no offset (units of 4),
/// QVGA halves it first ([`scaling`]), the zoom scales to the output size (units of 4), the
/// output PCLK divider is set by hand (bit 7, the automatic mode, clear), and the format is
/// YUV 4:2:2 with Y first.
pub(super) const fn dsp_scaling(resolution: Resolution) -> [Setting; 17] {
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
pub(super) const DSP_QVGA: [Setting; 17] = dsp_scaling(Resolution::Qvga);
/// [`dsp_scaling`] for VGA, computed at compile time.
pub(super) const DSP_VGA: [Setting; 17] = dsp_scaling(Resolution::Vga);

/// The clock, frame length, sync polarity and orientation (sensor bank), from the clock plan
/// and REG04 (orientation bits; the exposure bits \[1:0\] are written with the exposure).
pub(super) fn clock_and_sync(plan: &ClockPlan, reg04: u8) -> [Setting; 7] {
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
pub(super) const fn dsp_start(ctrl0_as_read: u8) -> [Setting; 3] {
    use reg::dsp::*;
    let ctrl0 = (ctrl0_as_read & !(CTRL0_V_FIRST | CTRL0_RAW)) | CTRL0_YUV422;
    [
        Setting::dsp(CTRL0, ctrl0),
        Setting::dsp(RESET, 0x00),
        Setting::dsp(R_BYPASS, R_BYPASS_USE_DSP),
    ]
}

/// REG04 for `config`'s orientation, without the exposure bits.
pub(super) const fn orientation(config: &Config) -> u8 {
    let mut reg04 = REG04_RESERVED | REG04_HREF0;
    if config.mirror {
        reg04 |= REG04_MIRROR;
    }
    if config.vflip {
        reg04 |= REG04_VFLIP | REG04_VREF0;
    }
    reg04
}
