//! `pad.toml`: the landing pad's layout (its name and one `[[marker]]` table per marker:
//! family, id, size, position and yaw), the contract's format (`docs/interfaces.md`), read
//! into a [`PadConfig`] (which owns the strings a core [`PadLayout`] borrows) and written
//! from one.
//!
//! Reading refuses unknown keys (a misspelt `yaw` must not silently become 0) and checks the
//! layout with the core's own validation, so the host accepts exactly what the firmware
//! would. Writing gives numbers in their shortest exact form, so a pad written and read back
//! is identical.

use std::path::Path;

use serde::Deserialize;
use touchdown_core::pad::{PadError, PadLayout, PadMarker};

use crate::toml_file::{line_of_key, read, toml_error, toml_string, ConfigError, ParseError};

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

/// An `f32` as the `f64` of its shortest decimal form (`0.4f32` becomes `0.4`, not
/// `0.4000000059604645`), so files written from `f32` layouts read naturally.
pub fn f32_decimal(v: f32) -> f64 {
    format!("{v:?}").parse().unwrap_or(f64::from(v))
}

/// A core layout as `pad.toml` contents.
pub fn config_of_layout(layout: &PadLayout<'_>) -> PadConfig {
    PadConfig {
        name: layout.name().to_string(),
        markers: layout
            .markers()
            .iter()
            .map(|m| MarkerConfig {
                family: m.family.to_string(),
                id: m.id,
                size: f32_decimal(m.size),
                x: f32_decimal(m.x),
                y: f32_decimal(m.y),
                yaw_deg: f32_decimal(m.yaw_deg),
            })
            .collect(),
    }
}

/// `pad.toml` text for a layout (the contract's format). Numbers are written in their
/// shortest exact form, so reading the file back gives the same `f64`s.
pub fn pad_toml(config: &PadConfig) -> String {
    let mut out = format!("name = {}\n", toml_string(&config.name));
    for m in &config.markers {
        out.push_str(&format!(
            "\n[[marker]]\nfamily = {}\nid = {}\nsize = {:?}\nx = {:?}\ny = {:?}\nyaw_deg = {:?}\n",
            toml_string(&m.family),
            m.id,
            m.size,
            m.x,
            m.y,
            m.yaw_deg
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn missing_key_in_a_marker_names_its_header_line() {
        // In a [[marker]] table: that table's header line.
        let e = parse_pad(&PAD.replace("size = 0.2\n", "")).unwrap_err();
        assert_eq!((e.line, e.reason.as_str()), (Some(9), "missing key `size`"));
    }

    #[test]
    fn pad_toml_round_trips() {
        let config = config_of_layout(&touchdown_core::pad::designs::NESTED);
        assert_eq!(config.markers[1].size, 0.4);
        let text = pad_toml(&config);
        assert_eq!(parse_pad(&text).unwrap(), config);
    }
}
