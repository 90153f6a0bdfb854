//! What the TOML files (`camera.toml`, `pad.toml`) share: their error types ([`ConfigError`],
//! [`ParseError`]) and the helpers that turn a toml/serde error into one line naming the key
//! and the line, so every error names the file, and the key and line when known, in one line:
//! `pads/nested.toml: line 12: marker[2].size: must be positive`.

use std::fmt;
use std::path::{Path, PathBuf};

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
    pub(crate) fn at(self, path: &Path) -> ConfigError {
        ConfigError {
            path: path.to_path_buf(),
            line: self.line,
            key: self.key,
            reason: self.reason,
        }
    }
}

pub(crate) fn read(path: &Path, what: &str) -> Result<String, ConfigError> {
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
pub(crate) fn toml_error(text: &str, e: toml::de::Error) -> ParseError {
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
pub(crate) fn line_of_key(text: &str, table: Option<(&str, usize)>, key: &str) -> Option<usize> {
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

/// A TOML basic string (quoted and escaped), for the writers here and for other TOML the host
/// writes (`touchdown simulate`'s `simulation.toml`).
pub fn toml_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
