//! The generated family tables (`core/src/family/tables`, `firmware/src/user_family.rs`)
//! against what the core parser makes of their sources: every shared family file, and the
//! example custom marker `tools/examples/custom8x8.txt`.
//!
//! The shared data is found at `$TOUCHDOWN_DATA`, else `<repo>/../shared/data`; without it
//! the shared-file test prints "skipping: ..." and passes.

use std::path::{Path, PathBuf};

use touchdown_core::family::{parse_family, tables, Family};

/// The generated firmware table, compiled here exactly as the firmware compiles it.
#[path = "../../firmware/src/user_family.rs"]
mod user_family;

fn data_dir() -> PathBuf {
    touchdown_host::shared_data::shared_data_dir()
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
fn check_against_table(path: &Path, table: Option<&Family<'static>>) -> Result<String, String> {
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
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/examples/custom8x8.txt");
    let line = check_against_table(&path, Some(&user_family::USER_FAMILY)).unwrap();
    println!("{line}");
    let f = &user_family::USER_FAMILY;
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
