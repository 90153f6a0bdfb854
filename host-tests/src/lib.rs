//! touchdown's integration tests of the host libraries (`touchdown-formats`, `touchdown-sim`,
//! `touchdown-eval`) with the core on recorded, rendered and simulated frames and on real
//! photos; the criterion benchmarks (`benches/`) and the examples (`examples/`). The tests of
//! the `touchdown` binary live with it (`host/cli/tests/`), the core's own with the core.
//!
//! This library is only the tests' support: where the shared evaluation data lives (real
//! photos, pose ground truth, family files). It is here, not in a library the tool ships,
//! because only these tests read that data. It is never copied into the repository: tests
//! read it from `$TOUCHDOWN_DATA`, else from `shared/data` beside the repository (where CI
//! has it). In a clone without it, the tests that need it print that they skip.

use std::path::{Path, PathBuf};

/// The shared data directory, whether or not it exists.
pub fn shared_data_dir() -> PathBuf {
    match std::env::var_os("TOUCHDOWN_DATA") {
        Some(dir) => PathBuf::from(dir),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
    }
}

/// The shared data directory, or `None` after printing `skipping: shared data not found at
/// ...` when it is absent.
pub fn shared_data_or_skip() -> Option<PathBuf> {
    let dir = shared_data_dir();
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("skipping: shared data not found at {}", dir.display());
        None
    }
}
