//! `camera.toml`: the camera's intrinsics (image size, focal lengths, principal point and
//! optional OpenCV distortion), the contract's `CAMERA.toml` (`docs/interfaces.md`), read
//! into and written from the core's [`CameraModel`].
//!
//! Reading uses serde + toml with unknown keys refused (a misspelt `k1` must not silently
//! become 0), then the core's own validation, so the host accepts exactly what the firmware
//! would. Writing gives every `f32` in the shortest decimal that reads back to the same
//! `f32`, so a camera written and read back is identical.

use std::path::Path;

use serde::Deserialize;
use touchdown_core::camera::{CameraError, CameraModel};

use crate::toml_file::{line_of_key, read, toml_error, ConfigError, ParseError};

/// `CAMERA.toml` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    #[serde(default)]
    distortion: Option<Vec<f64>>,
    #[serde(default)]
    line_time_us: f64,
}

/// Parses the text of a camera file (the contract's `CAMERA.toml`).
pub fn parse_camera(text: &str) -> Result<CameraModel, ParseError> {
    let file: CameraFile = toml::from_str(text).map_err(|e| toml_error(text, e))?;
    let fail = |key: &str, reason: String| ParseError {
        line: line_of_key(text, None, key),
        key: Some(key.to_string()),
        reason,
    };
    let mut distortion = [0.0f32; 5];
    if let Some(values) = &file.distortion {
        if !matches!(values.len(), 4 | 5) {
            return Err(fail(
                "distortion",
                format!(
                    "must be [k1, k2, p1, p2, k3] (5 values, or 4 with k3 = 0); got {} values",
                    values.len()
                ),
            ));
        }
        for (slot, value) in distortion.iter_mut().zip(values) {
            *slot = *value as f32;
        }
    }
    let camera = CameraModel {
        width: file.width,
        height: file.height,
        fx: file.fx as f32,
        fy: file.fy as f32,
        cx: file.cx as f32,
        cy: file.cy as f32,
        distortion,
        line_time_us: file.line_time_us as f32,
    };
    camera.validate().map_err(|e| match e {
        CameraError::EmptyImage => fail(
            if file.width == 0 { "width" } else { "height" },
            "must be positive".to_string(),
        ),
        CameraError::BadFocalLength => {
            let key = if file.fx.is_finite() && file.fx > 0.0 {
                "fy"
            } else {
                "fx"
            };
            fail(key, "must be a positive focal length in pixels".to_string())
        }
        CameraError::BadAspect => fail(
            "fy",
            format!(
                "fx / fy = {:.3} is implausible (a typo?)",
                file.fx / file.fy
            ),
        ),
        CameraError::BadPrincipalPoint => {
            let w = f64::from(file.width);
            let key = if file.cx.is_finite() && (file.cx - 0.5 * w).abs() <= w {
                "cy"
            } else {
                "cx"
            };
            fail(
                key,
                "principal point must be finite and near the image".to_string(),
            )
        }
        CameraError::BadDistortion => fail(
            "distortion",
            "coefficients must be finite numbers".to_string(),
        ),
        CameraError::BadLineTime => fail(
            "line_time_us",
            format!(
                "must be 0 (global shutter) or a row-to-row time in microseconds whose \
                 frame readout ({:.0} µs) is under {:.0} µs",
                file.line_time_us * f64::from(file.height),
                touchdown_core::camera::MAX_READOUT_US
            ),
        ),
    })?;
    Ok(camera)
}

/// Reads and checks a camera file.
pub fn load_camera(path: &Path) -> Result<CameraModel, ConfigError> {
    let text = read(path, "camera file")?;
    parse_camera(&text).map_err(|e| e.at(path))
}

/// `camera.toml` text (the contract's format) for a camera model, exact.
pub fn camera_toml(camera: &CameraModel) -> String {
    let mut out = format!(
        "# camera intrinsics, pixels ((0, 0) = centre of the top-left pixel)\n\
         width = {}\nheight = {}\nfx = {}\nfy = {}\ncx = {}\ncy = {}\n",
        camera.width,
        camera.height,
        exact_f32(camera.fx),
        exact_f32(camera.fy),
        exact_f32(camera.cx),
        exact_f32(camera.cy)
    );
    if camera.has_distortion() {
        let d: Vec<String> = camera.distortion.iter().map(|&k| exact_f32(k)).collect();
        out.push_str(&format!(
            "distortion = [{}]   # k1, k2, p1, p2, k3 (OpenCV order)\n",
            d.join(", ")
        ));
    }
    if camera.line_time_us != 0.0 {
        out.push_str(&format!(
            "line_time_us = {}   # rolling shutter: row-to-row exposure time\n",
            exact_f32(camera.line_time_us)
        ));
    }
    out
}

/// The shortest decimal that reads back (through `f64`, as the config reader does) to `v`.
fn exact_f32(v: f32) -> String {
    let short = format!("{v:?}");
    if short.parse::<f64>().map(|x| x as f32) == Ok(v) {
        short
    } else {
        format!("{:?}", f64::from(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAMERA: &str =
        "width = 640\nheight = 480\nfx = 554.3\nfy = 554.3\ncx = 319.5\ncy = 239.5\n";

    #[test]
    fn camera_contract_example() {
        let c = parse_camera(CAMERA).unwrap();
        assert_eq!(
            (c.width, c.fx, c.cy, c.distortion),
            (640, 554.3, 239.5, [0.0; 5])
        );
        let c = parse_camera(&format!("{CAMERA}distortion = [0.1, -0.2, 0.001, 0.002]\n")).unwrap();
        assert_eq!(c.distortion, [0.1, -0.2, 0.001, 0.002, 0.0]);
        assert!(parse_camera(&CAMERA.replace("554.3", "700")).is_ok());
    }

    #[test]
    fn camera_errors_name_key_and_line() {
        let e = parse_camera(&CAMERA.replace("fy = 554.3", "fy = -2.0")).unwrap_err();
        assert_eq!((e.line, e.key.as_deref()), (Some(4), Some("fy")));
        let e = parse_camera(&CAMERA.replace("fy = 554.3", "fy = \"x\"")).unwrap_err();
        assert_eq!(e.line, Some(4));
        let e = parse_camera(&format!("{CAMERA}k1 = 0.1\n")).unwrap_err();
        assert!(e.reason.contains("k1"), "{e:?}");
        let e = parse_camera(&format!("{CAMERA}distortion = [0.1]\n")).unwrap_err();
        assert_eq!((e.line, e.key.as_deref()), (Some(7), Some("distortion")));
        let e = ParseError { ..e }.at(Path::new("CAMERA.toml"));
        assert!(
            e.to_string()
                .starts_with("CAMERA.toml: line 7: distortion: "),
            "{e}"
        );
    }

    #[test]
    fn missing_keys_are_named_without_a_wrong_line() {
        let e = parse_camera(&CAMERA.replace("fy = 554.3\n", "")).unwrap_err();
        assert_eq!((e.line, e.reason.as_str()), (None, "missing key `fy`"));
        let e = e.at(Path::new("CAMERA.toml"));
        assert_eq!(e.to_string(), "CAMERA.toml: missing key `fy`");
    }

    #[test]
    fn camera_toml_is_exact() {
        let camera = CameraModel {
            distortion: [-0.12, 0.03, 0.0005, -0.0003, 0.0],
            ..CameraModel::pinhole(640, 480, 554.256_3, 554.256_3, 319.5, 239.5)
        };
        let back = parse_camera(&camera_toml(&camera)).unwrap();
        assert_eq!(back, camera);
        let pinhole = CameraModel::pinhole(64, 48, 1.0e-1, 0.1, 31.5, 23.5);
        assert_eq!(parse_camera(&camera_toml(&pinhole)).unwrap(), pinhole);
        let rolling = CameraModel {
            line_time_us: 63.492_06,
            ..pinhole
        };
        assert_eq!(parse_camera(&camera_toml(&rolling)).unwrap(), rolling);
    }

    #[test]
    fn a_line_time_in_milliseconds_is_refused_by_name() {
        // 480 rows of 30 ms: a 14 s readout, surely milliseconds typed for microseconds.
        let text = format!("{CAMERA}line_time_us = 30000\n");
        let e = parse_camera(&text).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("line_time_us"), "{e:?}");
        let e = parse_camera(&format!("{CAMERA}line_time_us = -1\n")).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("line_time_us"), "{e:?}");
        let ok = parse_camera(&format!("{CAMERA}line_time_us = 52.5\n")).unwrap();
        assert_eq!(ok.line_time_us, 52.5);
    }
}
