//! Compile-time defaults: camera, lens, pad, MAVLink profile.
//!
//! What users tune in the field is a MAVLink parameter (`touchdown_core::params`,
//! persisted in flash by [`crate::param_store`]): among them the auto-exposure limits
//! (TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET, defaults `AutoExposureLimits::default()`), the
//! decoder's correction cap (TD_MAX_HAMMING) and the printed size of the pad (TD_TAG_SIZE);
//! see [`crate::vision`]. What depends on the hardware build is here. Change these to match
//! your lens and pad, then rebuild.

use touchdown_core::camera::CameraModel;
use touchdown_core::pad::{designs, PadLayout};
use touchdown_core::params::PipelineSettings;
use touchdown_core::sensor::GainX16;
use touchdown_sensors::any::Model;
use touchdown_sensors::{Config, Exposure};

use crate::capture::{HEIGHT, SENSOR_RESOLUTION, WIDTH};

/// Frames per second asked of the sensor.
pub const FPS: u32 = 30;

/// The sensor set-up: QVGA (or VGA with `camera-vga`), YUV, the board's XCLK. Exposure
/// starts manual at a medium value; the software auto-exposure then drives it per frame within
/// the limits of the TD_EXP_MAX_US / TD_GAIN_MAX parameters.
pub fn sensor_config() -> Config {
    Config {
        resolution: SENSOR_RESOLUTION,
        xclk_hz: crate::board::XCLK_HZ,
        fps: FPS,
        exposure: Exposure::Manual {
            lines: 16,
            gain: GainX16::ONE,
        },
        vflip: false,
        mirror: false,
    }
}

/// Nominal pinhole model of the OV7725 with the usual 2.8 mm M12 lens: 6 µm pixels at VGA, so
/// f = 2.8 mm / 6 µm = 467 px at 640x480 (233.5 px at QVGA), principal point at the centre.
/// Calibrate your own lens (e.g. with OpenCV's chessboard calibration) and put the numbers here for
/// metre-accurate poses. Its line time is [`OV7725_LINE_TIME_US`].
pub const CAMERA: CameraModel = centred_pinhole(467.0, OV7725_LINE_TIME_US);

/// Nominal pinhole model of the OV2640 with the same 2.8 mm lens.
///
/// The focal length in pixels is the lens focal length over the pitch of one *output* pixel
/// on the array, which the driver's readout sets (`touchdown_sensors::ov2640`):
///
/// - the array's 1600x1200 active pixels are 2.2 µm (3.52 mm x 2.64 mm);
/// - the SVGA mode reads all of it subsampled by two each way: 800x600 at 4.4 µm;
/// - the DSP's zoom scales that by 0.8 (ZMOW/ZMOH 640x480 from HSIZE/VSIZE 800x600) to VGA:
///   1600 x 2.2 µm / 640 = 5.5 µm per output pixel, so f = 2.8 mm / 5.5 µm = 509.1 px;
/// - QVGA halves the 800x600 first (CTRLI) and zooms by 0.8 to 320x240: 11 µm, f = 254.5 px
///   (half the VGA value, as [`centred_pinhole`] takes it).
///
/// Dividing 2.2 µm by 0.8 (2.75 µm) would forget the subsampling: f = 1018 px, twice the
/// true value, and every range the pose gives twice too long. Both scalings are 4:3 like the
/// window, so pixels stay square and the principal point stays at the centre. The array is
/// 8 % narrower than the OV7725's (3.52 mm against 3.84 mm), so the same lens sees 64° across
/// instead of 69°. OV2640 modules come with many lenses: f scales with the lens focal length,
/// and a calibration (as for [`CAMERA`]) replaces all of this. Its line time is
/// [`OV2640_LINE_TIME_US`].
pub const CAMERA_OV2640: CameraModel = centred_pinhole(509.0, OV2640_LINE_TIME_US);

// The line times below are for the clock plans of FPS frames per second (other rates add
// dummy lines or change the pixel clock, and the row-to-row time with them).
const _: () = assert!(FPS == 30, "recompute the line times for the new frame rate");

/// The OV7725's rolling shutter: the time from one output row's exposure to the next's, µs,
/// at 30 fps (the pipeline corrects the corners for the camera's motion over it:
/// [`CameraModel::line_time_us`]). The sensor outputs its array rows one to one, so a row
/// takes one sensor line: the datasheet's line length in pixel periods, two pixel clocks
/// each in YUV, over the pixel clock of the 30 fps plan (`touchdown_sensors::ov7725`'s
/// `plan_clock`, the same from a 12 or a 24 MHz XCLK):
///
/// - QVGA: 576 pixel periods per line (576 x 278 per frame) = 1152 clocks at 9.6 MHz
///   (24 MHz x 4 / 10): 120.0 µs; the 240 rows read in 28.8 ms;
/// - VGA: 784 pixel periods per line (784 x 510 per frame) = 1568 clocks at 24 MHz:
///   65.33 µs; 480 rows in 31.4 ms, of which the 400 kept (`camera-vga`) span 26.1 ms.
///
/// The frame's time stamp is the middle row of the rows kept (`crate::capture`), which is
/// the model's `(height - 1) / 2` also for the cropped VGA frame.
pub const OV7725_LINE_TIME_US: f32 = if cfg!(feature = "camera-vga") {
    1568.0 / 24.0
} else {
    120.0
};

/// The OV2640's rolling shutter, µs per output row at 30 fps (see [`OV7725_LINE_TIME_US`]).
/// The driver's SVGA mode reads 600 array lines per frame of 1190 sensor clocks each
/// (OmniVision's frame-rate note: 1190 x 672 clocks per frame) at a 24 MHz sensor clock
/// (the 30 fps plan, from 24 MHz directly or 12 MHz doubled): 49.583 µs a line, 29.75 ms for
/// the 600 lines. The DSP scales those 600 lines to the output rows evenly, so an output row
/// takes 600 / rows sensor lines: VGA (480 rows) 61.98 µs, QVGA (240 rows) 123.96 µs.
pub const OV2640_LINE_TIME_US: f32 = if cfg!(feature = "camera-vga") {
    1190.0 / 24.0 * 600.0 / 480.0
} else {
    1190.0 / 24.0 * 600.0 / 240.0
};

/// A pinhole model with focal length `f_vga` pixels at 640x480 (half that at QVGA), the
/// principal point at the centre of the sensor's frame and the rolling shutter's
/// `line_time_us`. With `camera-vga` the DCMI crops 40 rows off the top, so the centre row
/// 239.5 becomes 199.5.
const fn centred_pinhole(f_vga: f32, line_time_us: f32) -> CameraModel {
    let pinhole = if cfg!(feature = "camera-vga") {
        CameraModel::pinhole(
            WIDTH as u32,
            HEIGHT as u32,
            f_vga,
            f_vga,
            319.5,
            239.5 - 40.0,
        )
    } else {
        let f = f_vga * 0.5;
        CameraModel::pinhole(WIDTH as u32, HEIGHT as u32, f, f, 159.5, 119.5)
    };
    CameraModel {
        line_time_us,
        ..pinhole
    }
}

/// The camera model of the sensor the vision task found.
pub const fn camera_model(model: Model) -> &'static CameraModel {
    match model {
        Model::Ov7725 => &CAMERA,
        Model::Ov2640 => &CAMERA_OV2640,
    }
}

/// The pad the firmware looks for: touchdown's recommended tag36h11 pad
/// (`pads/nested-field.toml`), at the size it is built with: a marker stays in view with the
/// vehicle blown 30 cm off the landing point in the last metre, and its rest field keeps
/// markers in view with the vehicle on the pad (a position to arm on without GPS, the mount
/// calibrated before take-off). It shares the `nested-rest` pad's rest field (ids 10-34) and
/// the nested pads' altitude marker (id 0), in their places; for a printed `nested-rest` or
/// `nested` pad, build with `designs::NESTED_REST` or `designs::NESTED`. A pad printed at
/// another scale is set with TD_TAG_SIZE (the edge of its largest marker as printed: the
/// whole layout is scaled to it), no rebuild.
pub const PAD: &PadLayout<'static> = designs::RECOMMENDED;

/// The size `settings` (TD_TAG_SIZE) scales the pad in force ([`PAD`], or the design TD_PAD
/// chose) to, in whole percent of its built size (for logs and STATUSTEXT; saturates, NaN
/// gives 0).
pub fn pad_scale_percent(settings: &PipelineSettings) -> u32 {
    (settings.pad_scale(&settings.built_pad(PAD)) * 100.0 + 0.5) as u32
}

/// Default UART baud rate; TD_BAUD overrides it at boot.
pub const DEFAULT_BAUD: u32 = 921_600;
