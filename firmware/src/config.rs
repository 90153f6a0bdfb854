//! Compile-time defaults: camera, lens, pad, MAVLink profile.
//!
//! What users tune in the field is a MAVLink parameter (`touchdown_core::companion::params`,
//! persisted in flash by [`crate::param_store`]): among them the auto-exposure limits
//! (TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET, defaults `AutoExposureLimits::default()`), the
//! decoder's correction cap (TD_MAX_HAMMING) and the printed size of the pad (TD_TAG_SIZE);
//! see [`crate::vision`]. What depends on the hardware build is here. Change these to match
//! your lens and pad, then rebuild.

use touchdown_core::camera::CameraModel;
use touchdown_core::pad::{designs, PadLayout};
use touchdown_core::sensor::ov7725::{self, Exposure};
use touchdown_core::sensor::{GainX16, Resolution};

use crate::capture::{HEIGHT, WIDTH};

/// Frames per second asked of the sensor.
pub const FPS: u32 = 30;

/// The sensor set-up: QVGA (or VGA with `camera-vga`), YUV, the board's XCLK. Exposure
/// starts manual at a medium value; the software auto-exposure then drives it per frame within
/// the limits of the TD_EXP_MAX_US / TD_GAIN_MAX parameters.
pub fn sensor_config() -> ov7725::Config {
    ov7725::Config {
        resolution: if cfg!(feature = "camera-vga") {
            Resolution::Vga
        } else {
            Resolution::Qvga
        },
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
/// f = 2.8 mm / 6 µm = 467 px at 640x480 (233 px at QVGA), principal point at the centre.
/// Calibrate your own lens (e.g. with OpenCV's chessboard calibration) and put the numbers here for
/// metre-accurate poses.
pub const CAMERA: CameraModel = if cfg!(feature = "camera-vga") {
    // The DCMI crops 40 rows off the top: the centre row 239.5 becomes 199.5.
    CameraModel::pinhole(
        WIDTH as u32,
        HEIGHT as u32,
        467.0,
        467.0,
        319.5,
        239.5 - 40.0,
    )
} else {
    CameraModel::pinhole(WIDTH as u32, HEIGHT as u32, 233.5, 233.5, 159.5, 119.5)
};

/// The pad the firmware looks for: touchdown's nested tag36h11 pad (`pads/nested.toml`), at
/// the size it is built with. A pad printed at another scale is set with TD_TAG_SIZE (the
/// edge of its largest marker as printed: the whole layout is scaled to it), no rebuild.
pub const PAD: &PadLayout<'static> = &designs::NESTED;

/// Default UART baud rate; TD_BAUD overrides it at boot.
pub const DEFAULT_BAUD: u32 = 921_600;
