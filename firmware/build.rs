//! Build script: puts the repository's `memory.x` where the linker looks for it.
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`. The file lives at the workspace root (one
//! memory map for the board, reviewed in one place), so it is copied into `OUT_DIR` and that
//! directory is added to the linker search path. We do this ourselves instead of enabling
//! embassy-stm32's `memory-x` feature, whose generated map knows nothing of our `.axisram`
//! section and puts RAM in AXI SRAM rather than DTCM.
//!
//! The linker scripts themselves (`-Tlink.x`, `-Tdefmt.x`) are passed by the rustflags in the
//! root `.cargo/config.toml`; adding them here too would include them twice.

use std::env;
use std::error::Error;
use std::fs;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn Error>> {
    let manifest_dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let memory_x = manifest_dir.join("..").join("memory.x");
    let out = PathBuf::from(env::var("OUT_DIR")?);

    let map =
        fs::read(&memory_x).map_err(|e| format!("cannot read {}: {e}", memory_x.display()))?;
    fs::write(out.join("memory.x"), map)?;

    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
