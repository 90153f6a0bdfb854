//! The generated family tables (`core/src/family/tables`, `firmware/src/user_family.rs`)
//! against what the core parser makes of their sources: every shared family file, and the
//! example custom marker `tools/examples/custom8x8.txt`.
//!
//! The firmware's table is read as the text `tools/gen_families.py` wrote (its `Family`
//! fields, `CODES` and `SORTED`), not compiled in: it is the firmware's source, and this
//! test checks that what it says is what the parser makes of the family file.
//!
//! The shared data is found at `$TOUCHDOWN_DATA`, else `<repo>/../shared/data`; without it
//! the shared-file test prints "skipping: ..." and passes.

use std::path::{Path, PathBuf};

use touchdown_core::family::{parse_family, tables, Family};

/// A generated table as `tools/gen_families.py` writes it: the scalar fields of its `Family`
/// literal and the `CODES` and `SORTED` arrays, owned.
struct GeneratedTable {
    name: String,
    /// grid, quiet_rings, border_ring, bits, min_hamming, max_correction.
    layout: [u8; 6],
    codes: Vec<u64>,
    sorted_ids: Vec<u16>,
}

impl GeneratedTable {
    /// Reads a generated Rust table; `Err` names what is missing.
    fn parse(text: &str) -> Result<GeneratedTable, String> {
        let field = |key: &str| -> Result<&str, String> {
            let prefix = format!("{key}: ");
            text.lines()
                .find_map(|l| l.trim().strip_prefix(&prefix))
                .map(|v| v.trim_end_matches(','))
                .ok_or_else(|| format!("no `{key}:` field"))
        };
        let small = |key: &str| -> Result<u8, String> {
            field(key)?.parse().map_err(|e| format!("`{key}`: {e}"))
        };
        // The body of `static NAME: [T; N] = [ ... ];`, split at commas.
        let array = |name: &str| -> Result<Vec<String>, String> {
            let start = text
                .find(&format!("static {name}: "))
                .ok_or_else(|| format!("no static {name}"))?;
            let body = text[start..]
                .split_once("= [")
                .and_then(|(_, rest)| rest.split_once("];"))
                .ok_or_else(|| format!("static {name} is not an array literal"))?
                .0;
            Ok(body
                .split(',')
                .map(str::trim)
                .filter(|v| !v.is_empty())
                .map(str::to_string)
                .collect())
        };
        let codes = array("CODES")?
            .iter()
            .map(|v| u64::from_str_radix(v.trim_start_matches("0x"), 16))
            .collect::<Result<Vec<u64>, _>>()
            .map_err(|e| format!("CODES: {e}"))?;
        let sorted_ids = array("SORTED")?
            .iter()
            .map(|v| v.parse())
            .collect::<Result<Vec<u16>, _>>()
            .map_err(|e| format!("SORTED: {e}"))?;
        Ok(GeneratedTable {
            name: field("name")?.trim_matches('"').to_string(),
            layout: [
                small("grid")?,
                small("quiet_rings")?,
                small("border_ring")?,
                small("bits")?,
                small("min_hamming")?,
                small("max_correction")?,
            ],
            codes,
            sorted_ids,
        })
    }

    /// The table as the core's family type (no multi-index: these tables are small).
    fn family(&self) -> Family<'_> {
        let [grid, quiet_rings, border_ring, bits, min_hamming, max_correction] = self.layout;
        Family {
            name: &self.name,
            grid,
            quiet_rings,
            border_ring,
            bits,
            min_hamming,
            max_correction,
            codes: &self.codes,
            sorted_ids: &self.sorted_ids,
            index: None,
        }
    }
}

/// The repository's root.
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn data_dir() -> PathBuf {
    touchdown_host_tests::shared_data_dir()
}

/// A family file's name (`# family`) as the contract spells it: the ArUco files are named
/// `tagAruco6x6_250`, `tagArucoMIP_36h12`; AprilTag names are the same in both.
fn contract_name(file_name: &str) -> String {
    match file_name.strip_prefix("tagAruco") {
        Some(rest) => format!(
            "aruco_{}",
            rest.trim_start_matches('_').to_ascii_lowercase()
        ),
        None => file_name.to_string(),
    }
}

/// Parses a family file with the core parser and checks it against a generated table.
fn check_against_table(path: &Path, table: Option<&Family<'_>>) -> Result<String, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("family");
    let capacity = text.lines().count();
    let mut codes = vec![0u64; capacity];
    let header =
        parse_family(&text, stem, &mut codes).map_err(|e| format!("{}: {e}", path.display()))?;
    let header_min = header.min_hamming;
    let file_name = header.name;
    let mut ids = vec![0u16; capacity];
    let parsed = header
        .into_family(&codes, &mut ids)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let table = match table {
        Some(t) => t,
        None => tables::by_name(&contract_name(file_name)).ok_or_else(|| {
            format!(
                "{}: no generated table named {}",
                path.display(),
                contract_name(file_name)
            )
        })?,
    };
    let what = format!("{} vs table {}", path.display(), table.name);
    assert_eq!(parsed.codes, table.codes, "codes of {what}");
    assert_eq!(
        (
            parsed.grid,
            parsed.quiet_rings,
            parsed.border_ring,
            parsed.bits
        ),
        (table.grid, table.quiet_rings, table.border_ring, table.bits),
        "layout (grid, quiet rings, border ring, bits) of {what}"
    );
    assert_eq!(
        parsed.min_hamming, table.min_hamming,
        "min_hamming of {what}"
    );
    assert_eq!(
        parsed.max_correction, table.max_correction,
        "max_correction of {what}"
    );
    // Both indexes are validated sorted permutations of the ids; the codes are unique (the
    // minimum distance is above 0), so the order by code is unique and they are equal.
    assert_eq!(parsed.validate(), Ok(()), "{what}");
    assert_eq!(table.validate(), Ok(()), "{what}");
    assert_eq!(parsed.sorted_ids, table.sorted_ids, "sorted ids of {what}");
    let note = match header_min {
        Some(h) if h != table.min_hamming => format!(" (file header says min_hamming {h})"),
        _ => String::new(),
    };
    Ok(format!(
        "{:<17} {:>5} codes, {:>2} bits, min distance {:>2}, corrects {}{note}",
        table.name,
        table.codes.len(),
        table.bits,
        table.min_hamming,
        table.max_correction
    ))
}

#[test]
fn shared_family_files_equal_the_generated_tables() {
    let dir = data_dir().join("families");
    if !dir.is_dir() {
        println!("skipping: shared data not found at {}", dir.display());
        return;
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "txt"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no family files in {}", dir.display());
    let mut covered = Vec::new();
    let mut failures = Vec::new();
    for path in &files {
        match check_against_table(path, None) {
            Ok(line) => {
                println!("{line}");
                covered.push(line.split_whitespace().next().unwrap().to_string());
            }
            Err(e) => failures.push(e),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // Every shipped table comes from a shared file, except OpenCV's DICT_ARUCO_ORIGINAL.
    for name in tables::names() {
        assert!(
            name == "aruco_original" || covered.iter().any(|c| c == name),
            "table {name} has no shared family file"
        );
    }
}

#[test]
fn example_custom_marker_equals_the_firmware_table() {
    let path = repo().join("tools/examples/custom8x8.txt");
    let generated = repo().join("firmware/src/user_family.rs");
    let text = std::fs::read_to_string(&generated).unwrap();
    let table =
        GeneratedTable::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", generated.display()));
    assert!(
        text.contains("pub static USER_FAMILY: Family<'static> = Family {"),
        "{} does not define the USER_FAMILY the firmware uses",
        generated.display()
    );
    let f = &table.family();
    let line = check_against_table(&path, Some(f)).unwrap();
    println!("{line}");
    assert_eq!(
        (f.grid, f.quiet_rings, f.border_ring, f.bits, f.codes.len()),
        (8, 0, 0, 36, 1)
    );
    // The design promise: far from its own rotations, so the orientation is never in doubt.
    assert!(
        f.min_hamming >= 16,
        "custom marker only {} bits from its rotations",
        f.min_hamming
    );
    let code = f.codes[0];
    for turn in 0..4u8 {
        let readings = [0u8, 1, 2, 3].map(|k| f.rotate_code(f.rotate_code(code, turn), k));
        let d = f.decode(&readings, f.max_correction).unwrap();
        assert_eq!((d.id, d.hamming), (0, 0));
        assert_eq!(readings[d.rotation as usize], code);
    }
}
