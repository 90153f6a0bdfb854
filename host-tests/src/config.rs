//! Readers of the contract's configuration files: `CAMERA.toml` (camera intrinsics) and
//! `pad.toml` (landing pad layout), into the core's [`CameraModel`] and [`PadLayout`].
//!
//! Both are parsed with serde + toml with unknown keys refused (a misspelt `yaw` must not
//! silently become 0), then checked by the core's own validation, so the host accepts
//! exactly what the firmware would. Every error names the file, and the key and line when
//! known, in one line: `pads/nested.toml: line 12: marker[2].size: must be positive`.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use touchdown_core::camera::{CameraError, CameraModel};
use touchdown_core::pad::{PadError, PadLayout, PadMarker};

/// A configuration file that cannot be used.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// The offending key (`fx`, `marker[2].size`), when known.
    pub key: Option<String>,
    /// What is wrong.
    pub reason: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ": line {line}")?;
        }
        if let Some(key) = &self.key {
            write!(f, ": {key}")?;
        }
        write!(f, ": {}", self.reason)
    }
}

impl std::error::Error for ConfigError {}

/// An error before the file name is attached.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// The key, when known.
    pub key: Option<String>,
    /// What is wrong.
    pub reason: String,
}

impl ParseError {
    fn at(self, path: &Path) -> ConfigError {
        ConfigError {
            path: path.to_path_buf(),
            line: self.line,
            key: self.key,
            reason: self.reason,
        }
    }
}

fn read(path: &Path, what: &str) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|e| ConfigError {
        path: path.to_path_buf(),
        line: None,
        key: None,
        reason: format!("cannot read {what}: {e}"),
    })
}

/// A toml/serde error as one line with its line number.
///
/// A missing key has no line of its own: toml points its span at the whole table (line 1
/// of the file, or the `[[marker]]` header), which would send the user to the wrong place,
/// so that error names the key and the table's header line only.
fn toml_error(text: &str, e: toml::de::Error) -> ParseError {
    let reason = e.message().trim().replace('\n', " ");
    let line_at = |offset: usize| text.get(..offset).unwrap_or(text).matches('\n').count() + 1;
    if let Some(key) = missing_field(&reason) {
        // The span of a table that lacks the key starts at its header, if it has one.
        let header = e
            .span()
            .map(|span| span.start)
            .filter(|&start| text.get(start..).is_some_and(|rest| rest.starts_with('[')));
        return ParseError {
            line: header.map(line_at),
            key: None,
            reason: format!("missing key `{key}`"),
        };
    }
    ParseError {
        line: e.span().map(|span| line_at(span.start)),
        key: None,
        reason,
    }
}

/// The key of serde's "missing field `name`" message.
fn missing_field(message: &str) -> Option<&str> {
    let rest = message.strip_prefix("missing field `")?;
    rest.split('`').next()
}

/// Line of `key = ...`, searching the whole file (`table = None`) or the `n`-th
/// `[[table]]` section.
fn line_of_key(text: &str, table: Option<(&str, usize)>, key: &str) -> Option<usize> {
    let mut section: Option<usize> = None;
    let mut seen = 0usize;
    for (number, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if let Some((name, index)) = table {
            if line.starts_with("[[") {
                let inside = line.trim_start_matches("[[").trim_end_matches("]]").trim();
                section = (inside == name).then_some(seen);
                if inside == name {
                    seen += 1;
                }
                if section == Some(index) && key.is_empty() {
                    return Some(number + 1);
                }
                continue;
            }
            if section != Some(index) {
                continue;
            }
        } else if line.starts_with('[') {
            break;
        }
        if let Some(rest) = line.strip_prefix(key) {
            if rest.trim_start().starts_with('=') {
                return Some(number + 1);
            }
        }
    }
    None
}

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
    })?;
    Ok(camera)
}

/// Reads and checks a camera file.
pub fn load_camera(path: &Path) -> Result<CameraModel, ConfigError> {
    let text = read(path, "camera file")?;
    parse_camera(&text).map_err(|e| e.at(path))
}

/// One `[[marker]]` of `pad.toml` as written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerConfig {
    /// Family name.
    pub family: String,
    /// Id in the family.
    pub id: u16,
    /// Outer black-border edge, metres.
    pub size: f64,
    /// Centre in the pad frame, metres.
    pub x: f64,
    /// Centre in the pad frame, metres.
    pub y: f64,
    /// Rotation about the pad z axis, degrees (default 0).
    #[serde(default)]
    pub yaw_deg: f64,
}

/// A `pad.toml` as read: owns the strings a [`PadLayout`] borrows.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PadConfig {
    /// The pad's name.
    pub name: String,
    /// Its markers (`[[marker]]` tables).
    #[serde(rename = "marker", default)]
    pub markers: Vec<MarkerConfig>,
}

impl PadConfig {
    /// The core layout (borrowing the family names from `self`).
    pub fn layout(&self) -> Result<PadLayout<'_>, PadError> {
        let markers: Vec<PadMarker<'_>> = self
            .markers
            .iter()
            .map(|m| PadMarker {
                family: &m.family,
                id: m.id,
                size: m.size as f32,
                x: m.x as f32,
                y: m.y as f32,
                yaw_deg: m.yaw_deg as f32,
            })
            .collect();
        PadLayout::new(&self.name, &markers)
    }
}

/// Parses and checks the text of a pad file.
pub fn parse_pad(text: &str) -> Result<PadConfig, ParseError> {
    let config: PadConfig = toml::from_str(text).map_err(|e| toml_error(text, e))?;
    let at = |index: u8, key: &str, reason: &str| {
        let i = usize::from(index);
        ParseError {
            line: line_of_key(text, Some(("marker", i)), key)
                .or_else(|| line_of_key(text, Some(("marker", i)), "")),
            key: Some(format!("marker[{i}].{key}")),
            reason: reason.to_string(),
        }
    };
    match config.layout() {
        Ok(_) => Ok(config),
        Err(e) => Err(match e {
            PadError::Empty => ParseError {
                line: None,
                key: Some("marker".to_string()),
                reason: "a pad needs at least one [[marker]]".to_string(),
            },
            PadError::TooManyMarkers => ParseError {
                line: None,
                key: Some("marker".to_string()),
                reason: format!(
                    "{} markers; at most {} fit the firmware's layout",
                    config.markers.len(),
                    touchdown_core::pad::MAX_PAD_MARKERS
                ),
            },
            PadError::BadSize { index } => at(index, "size", "must be a positive length in metres"),
            PadError::BadPlacement { index } => {
                at(index, "x", "x, y and yaw_deg must be finite numbers")
            }
            PadError::NoFamily { index } => at(index, "family", "must name a family"),
            PadError::Duplicate { index } => at(
                index,
                "id",
                "the same family and id appear twice on the pad; detections could not be told apart",
            ),
        }),
    }
}

/// Reads and checks a pad file.
pub fn load_pad(path: &Path) -> Result<PadConfig, ConfigError> {
    let text = read(path, "pad file")?;
    parse_pad(&text).map_err(|e| e.at(path))
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
        // In a [[marker]] table: that table's header line.
        let e = parse_pad(&PAD.replace("size = 0.2\n", "")).unwrap_err();
        assert_eq!((e.line, e.reason.as_str()), (Some(9), "missing key `size`"));
    }

    const PAD: &str = "name = \"t\"\n[[marker]]\nfamily = \"tag36h11\"\nid = 1\nsize = 0.5\nx = 0.0\ny = 0.0\n\n[[marker]]\nfamily = \"tag36h11\"\nid = 2\nsize = 0.2\nx = 1.0\ny = 0.0\nyaw_deg = 90.0\n";

    #[test]
    fn pad_reads_and_checks() {
        let pad = parse_pad(PAD).unwrap();
        let layout = pad.layout().unwrap();
        assert_eq!(layout.markers().len(), 2);
        assert_eq!(layout.markers()[1].yaw_deg, 90.0);
        let e = parse_pad(&PAD.replace("size = 0.2", "size = -0.2")).unwrap_err();
        assert_eq!(
            (e.line, e.key.as_deref()),
            (Some(12), Some("marker[1].size"))
        );
        let e = parse_pad(&PAD.replace("id = 2", "id = 1")).unwrap_err();
        assert_eq!(e.key.as_deref(), Some("marker[1].id"));
        let e = parse_pad(&PAD.replace("yaw_deg", "yaw")).unwrap_err();
        assert!(e.reason.contains("yaw"), "{e:?}");
        assert!(parse_pad("name = \"empty\"\n").is_err());
    }
}
