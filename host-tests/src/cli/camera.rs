//! `CAMERA.toml`: the pinhole camera a pose is computed with (the contract's format).
//!
//! ```toml
//! width = 640
//! height = 480
//! fx = 554.3
//! fy = 554.3
//! cx = 319.5
//! cy = 239.5
//! distortion = [k1, k2, p1, p2, k3]   # optional, OpenCV's Brown-Conrady order
//! ```
//! Unknown keys are errors, so a misspelt key cannot silently fall back to a default.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// Camera intrinsics as written in the file (pixels; (0, 0) = centre of the top-left pixel).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Image width the intrinsics are for, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// `[k1, k2, p1, p2, k3]` (OpenCV's order); 4 values mean k3 = 0; absent means none.
    #[serde(default)]
    pub distortion: Option<Vec<f64>>,
}

/// A camera file that cannot be used. Displays as one line naming the file.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line of the problem, when known.
    pub line: Option<usize>,
    /// What is wrong.
    pub reason: String,
}

impl fmt::Display for CameraError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}: line {line}: {}", self.path.display(), self.reason),
            None => write!(f, "{}: {}", self.path.display(), self.reason),
        }
    }
}

impl std::error::Error for CameraError {}

impl Camera {
    /// Reads and checks a camera file.
    pub fn load(path: &Path) -> Result<Camera, CameraError> {
        let text = std::fs::read_to_string(path).map_err(|e| CameraError {
            path: path.to_path_buf(),
            line: None,
            reason: format!("cannot read camera file: {e}"),
        })?;
        Camera::parse(&text).map_err(|(line, reason)| CameraError {
            path: path.to_path_buf(),
            line,
            reason,
        })
    }

    /// Parses and checks the text of a camera file; errors carry the line when known.
    pub fn parse(text: &str) -> Result<Camera, (Option<usize>, String)> {
        let camera: Camera = toml::from_str(text).map_err(|e| {
            // toml's own Display draws a multi-line source excerpt; the contract wants one
            // line, so keep its message and turn the byte span into a line number.
            let line = e
                .span()
                .map(|span| text.get(..span.start).unwrap_or(text).matches('\n').count() + 1);
            (line, e.message().trim().replace('\n', " "))
        })?;
        camera.check().map_err(|reason| (None, reason))?;
        Ok(camera)
    }

    fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "width and height must be positive (got {}x{})",
                self.width, self.height
            ));
        }
        for (key, value) in [("fx", self.fx), ("fy", self.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!(
                    "{key} must be a positive focal length in pixels (got {value})"
                ));
            }
        }
        for (key, value) in [("cx", self.cx), ("cy", self.cy)] {
            if !value.is_finite() {
                return Err(format!("{key} must be a finite number (got {value})"));
            }
        }
        if let Some(coefficients) = &self.distortion {
            if !matches!(coefficients.len(), 4 | 5) {
                return Err(format!(
                    "distortion must be [k1, k2, p1, p2, k3] (5 values, or 4 with k3 = 0); got {} values",
                    coefficients.len()
                ));
            }
            if coefficients.iter().any(|k| !k.is_finite()) {
                return Err("distortion coefficients must be finite numbers".to_string());
            }
        }
        Ok(())
    }

    /// The five Brown-Conrady coefficients `[k1, k2, p1, p2, k3]` (zeros when absent).
    pub fn distortion_coefficients(&self) -> [f64; 5] {
        let mut out = [0.0; 5];
        if let Some(coefficients) = &self.distortion {
            for (slot, value) in out.iter_mut().zip(coefficients) {
                *slot = *value;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str =
        "width = 640\nheight = 480\nfx = 554.3\nfy = 554.3\ncx = 319.5\ncy = 239.5\n";

    #[test]
    fn reads_the_contract_example() {
        let camera = Camera::parse(GOOD).unwrap();
        assert_eq!(
            (camera.width, camera.height, camera.fx, camera.cy),
            (640, 480, 554.3, 239.5)
        );
        assert_eq!(camera.distortion_coefficients(), [0.0; 5]);
        let with = format!("{GOOD}distortion = [0.1, -0.2, 0.001, 0.002, 0.05]\n");
        assert_eq!(
            Camera::parse(&with).unwrap().distortion_coefficients(),
            [0.1, -0.2, 0.001, 0.002, 0.05]
        );
        // Integers are accepted where floats are expected (`fx = 700`).
        assert!(Camera::parse(&GOOD.replace("554.3", "700")).is_ok());
    }

    #[test]
    fn errors_are_one_line_with_the_line_number() {
        let (line, reason) =
            Camera::parse(&GOOD.replace("fy = 554.3", "fy = \"fast\"")).unwrap_err();
        assert_eq!(line, Some(4));
        assert!(!reason.contains('\n'), "{reason}");
        let (_, reason) = Camera::parse(&GOOD.replace("cy = 239.5\n", "")).unwrap_err();
        assert!(reason.contains("cy"), "{reason}");
        let (line, reason) = Camera::parse(&format!("{GOOD}fz = 1.0\n")).unwrap_err();
        assert_eq!(line, Some(7));
        assert!(reason.contains("fz"), "{reason}");
        let (_, reason) = Camera::parse(&GOOD.replace("fx = 554.3", "fx = -1.0")).unwrap_err();
        assert!(reason.contains("fx"), "{reason}");
        let (_, reason) = Camera::parse(&format!("{GOOD}distortion = [0.1]\n")).unwrap_err();
        assert!(reason.contains("distortion"), "{reason}");
    }
}
