//! Marker families chosen on the command line: a shipped family by name, or a family file.
//!
//! `--family NAME|FILE` first looks `NAME` up among the shipped tables (case-insensitively;
//! the file names of `shared/data/families`, such as `tagAruco6x6_250`, are accepted as
//! aliases of the contract names such as `aruco_6x6_250`), then tries it as a path to a
//! family file in the contract's text format, parsed by the core parser. A file family
//! owns its codes ([`FileFamily`]) and lends the detector a [`Family`] view of them, exactly
//! like the `'static` tables do.

use std::fmt;
use std::path::{Path, PathBuf};

use touchdown_core::family::{parse_family, tables, Family, FamilyError};

/// Why `--family` could not be resolved. Displays as one line.
#[derive(Debug)]
pub enum FamilyResolveError {
    /// Neither a shipped family name nor an existing file.
    Unknown {
        /// What the user typed.
        name: String,
    },
    /// The file exists but cannot be read as text.
    Unreadable {
        /// The file.
        path: PathBuf,
        /// The I/O error, one line.
        reason: String,
    },
    /// The file is not a valid family file.
    Invalid {
        /// The file.
        path: PathBuf,
        /// Parser error with its line number.
        error: FamilyError,
    },
}

impl fmt::Display for FamilyResolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FamilyResolveError::Unknown { name } => {
                let names = shipped_names();
                let list = if names.is_empty() {
                    "none are built into this binary".to_string()
                } else {
                    names.join(", ")
                };
                write!(
                    f,
                    "unknown family `{name}`: not a shipped family and no such file (shipped families: {list})"
                )
            }
            FamilyResolveError::Unreadable { path, reason } => {
                write!(f, "{}: cannot read family file: {reason}", path.display())
            }
            // FamilyError displays as "line N: reason" (or just the reason for whole-file
            // problems), which gives the contract's "PATH: line N: reason".
            FamilyResolveError::Invalid { path, error } => write!(f, "{}: {error}", path.display()),
        }
    }
}

impl std::error::Error for FamilyResolveError {}

/// The names of every shipped family, in table order.
pub fn shipped_names() -> Vec<&'static str> {
    tables::names().collect()
}

/// A shipped family by name, ignoring case and accepting the `shared/data/families` file
/// names (`tagAruco4x4_50`, `tagArucoMIP_36h12`) for the ArUco families.
pub fn shipped(name: &str) -> Option<&'static Family<'static>> {
    tables::by_name(name).or_else(|| tables::by_name(&canonical_name(name)))
}

/// Maps the AprilTag-repository spelling of the ArUco families (`tagAruco6x6_250`) to the
/// contract's (`aruco_6x6_250`); other names are returned unchanged.
fn canonical_name(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    match lower.strip_prefix("tagaruco") {
        Some(rest) => format!("aruco_{rest}"),
        None => lower,
    }
}

/// A family read from a file: owns the codes and the sorted index the core parser filled in.
#[derive(Debug, Clone)]
pub struct FileFamily {
    /// Where it came from.
    pub path: PathBuf,
    name: String,
    codes: Vec<u64>,
    sorted_ids: Vec<u16>,
    /// The layout and distance figures computed by the core when the file was loaded; the
    /// slices of this copy are empty and are filled in from the owned vectors by
    /// [`FileFamily::family`].
    layout: Family<'static>,
}

impl FileFamily {
    /// Reads and checks a family file. The family is named by its `# family` line, else by
    /// the file stem.
    pub fn load(path: &Path) -> Result<FileFamily, FamilyResolveError> {
        let text = std::fs::read_to_string(path).map_err(|e| FamilyResolveError::Unreadable {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "custom".to_string());
        let invalid = |error| FamilyResolveError::Invalid {
            path: path.to_path_buf(),
            error,
        };
        // One slot per code line, plus one so that a file with more codes than a family may
        // hold (65,535) makes the parser report the offending line instead of us guessing.
        let code_lines = text
            .lines()
            .map(str::trim)
            .filter(|line| !line.is_empty() && !line.starts_with('#'))
            .count()
            .clamp(1, usize::from(u16::MAX) + 1);
        let mut codes = vec![0u64; code_lines];
        let header = parse_family(&text, &stem, &mut codes).map_err(invalid)?;
        let name = header.name.to_string();
        let mut sorted_ids = vec![0u16; header.count];
        let family = header
            .into_family(&codes, &mut sorted_ids)
            .map_err(invalid)?;
        let layout = Family {
            name: "",
            grid: family.grid,
            quiet_rings: family.quiet_rings,
            border_ring: family.border_ring,
            bits: family.bits,
            min_hamming: family.min_hamming,
            max_correction: family.max_correction,
            codes: &[],
            sorted_ids: &[],
            index: None,
        };
        codes.truncate(header.count);
        Ok(FileFamily {
            path: path.to_path_buf(),
            name,
            codes,
            sorted_ids,
            layout,
        })
    }

    /// The family's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The detector's view of the family.
    pub fn family(&self) -> Family<'_> {
        Family {
            name: &self.name,
            codes: &self.codes,
            sorted_ids: &self.sorted_ids,
            ..self.layout
        }
    }
}

/// One family selected by the user.
#[derive(Debug, Clone)]
pub enum SelectedFamily {
    /// A shipped table.
    Shipped(&'static Family<'static>),
    /// A family file.
    File(FileFamily),
}

impl SelectedFamily {
    /// The detector's view of the family.
    pub fn family(&self) -> Family<'_> {
        match self {
            SelectedFamily::Shipped(family) => **family,
            SelectedFamily::File(file) => file.family(),
        }
    }

    /// The family's name, as reported in detections.
    pub fn name(&self) -> &str {
        match self {
            SelectedFamily::Shipped(family) => family.name,
            SelectedFamily::File(file) => file.name(),
        }
    }
}

/// Resolves one `--family` argument: a shipped name first, then a file path.
pub fn resolve(argument: &str) -> Result<SelectedFamily, FamilyResolveError> {
    if let Some(family) = shipped(argument) {
        return Ok(SelectedFamily::Shipped(family));
    }
    let path = Path::new(argument);
    if path.is_file() {
        return FileFamily::load(path).map(SelectedFamily::File);
    }
    if path.exists() {
        return Err(FamilyResolveError::Unreadable {
            path: path.to_path_buf(),
            reason: "not a regular file".to_string(),
        });
    }
    Err(FamilyResolveError::Unknown {
        name: argument.to_string(),
    })
}

/// The families a pad's markers name, each resolved once, in name order (a pad names the
/// families it uses, usually on several markers; unlike [`resolve_all`], a pad that names
/// none gets none, not the defaults).
pub fn resolve_pad(pad: &crate::pad::PadConfig) -> Result<Vec<SelectedFamily>, FamilyResolveError> {
    let mut names: Vec<String> = pad.markers.iter().map(|m| m.family.clone()).collect();
    names.sort();
    names.dedup();
    if names.is_empty() {
        return Ok(Vec::new());
    }
    resolve_all(&names)
}

/// Resolves every `--family` argument, or gives the default families
/// ([`tables::DEFAULT`]: tag36h11 and aruco_6x6_250) when there is none. The same shipped
/// family named twice is searched once.
pub fn resolve_all(arguments: &[String]) -> Result<Vec<SelectedFamily>, FamilyResolveError> {
    if arguments.is_empty() {
        return Ok(tables::DEFAULT
            .iter()
            .copied()
            .map(SelectedFamily::Shipped)
            .collect());
    }
    let mut selected: Vec<SelectedFamily> = Vec::with_capacity(arguments.len());
    for argument in arguments {
        let family = resolve(argument)?;
        let repeated = selected.iter().any(|known| match (known, &family) {
            (SelectedFamily::Shipped(a), SelectedFamily::Shipped(b)) => std::ptr::eq(*a, *b),
            _ => false,
        });
        if !repeated {
            selected.push(family);
        }
    }
    Ok(selected)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aruco_file_names_map_to_contract_names() {
        assert_eq!(canonical_name("tagAruco6x6_250"), "aruco_6x6_250");
        assert_eq!(canonical_name("tagArucoMIP_36h12"), "aruco_mip_36h12");
        assert_eq!(canonical_name("TAG36H11"), "tag36h11");
    }

    #[test]
    fn shipped_names_resolve_in_any_case() {
        assert_eq!(resolve("TAG36H11").unwrap().name(), "tag36h11");
        assert_eq!(resolve("tagAruco6x6_250").unwrap().name(), "aruco_6x6_250");
        assert_eq!(
            resolve("tagStandard41h12").unwrap().name(),
            "tagStandard41h12"
        );
        let defaults = resolve_all(&[]).unwrap();
        let names: Vec<&str> = defaults.iter().map(SelectedFamily::name).collect();
        assert_eq!(names, ["tag36h11", "aruco_6x6_250"]);
        let twice = resolve_all(&["tag36h11".into(), "Tag36h11".into()]).unwrap();
        assert_eq!(twice.len(), 1);
    }

    #[test]
    fn unknown_name_lists_the_shipped_ones() {
        let error = resolve("no-such-family-or-file").unwrap_err();
        let text = error.to_string();
        assert!(text.contains("no-such-family-or-file"), "{text}");
        assert!(
            text.contains("tag36h11, tag36h10") || text.contains("tag36h10, tag36h11"),
            "{text}"
        );
        assert!(!text.contains('\n'));
    }

    #[test]
    fn file_family_owns_its_codes() {
        let dir = std::env::temp_dir().join(format!("touchdown-families-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("my_marker.txt");
        // A paper-style 8x8 marker: black ring 0, 6x6 data inside, no header.
        std::fs::write(
            &path,
            "0000000001100110011111100100001001011010011001100100001000000000\n",
        )
        .unwrap();
        let selected = resolve(path.to_str().unwrap()).unwrap();
        assert_eq!(selected.name(), "my_marker");
        let family = selected.family();
        assert_eq!((family.grid, family.border_ring, family.bits), (8, 0, 36));
        assert_eq!(family.codes.len(), 1);
        assert!(family.validate().is_ok());

        std::fs::write(&path, "# cells 8\n0101\n").unwrap();
        let text = resolve(path.to_str().unwrap()).unwrap_err().to_string();
        assert!(text.ends_with("my_marker.txt: line 2: code line length is not cells*cells (a square of 3..16, matching `# cells`)"), "{text}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
