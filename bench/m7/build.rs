//! Build script of the M7 benchmark: puts this directory's `memory.x` (the QEMU mps2-an500
//! map, not the STM32H743's) where cortex-m-rt's `link.x` finds it, and checks the rustflags
//! (see .cargo/config.toml).

use std::env;
use std::error::Error;
use std::fs;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn Error>> {
    let manifest_dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let memory_x = manifest_dir.join("memory.x");
    let out = PathBuf::from(env::var("OUT_DIR")?);
    let map =
        fs::read(&memory_x).map_err(|e| format!("cannot read {}: {e}", memory_x.display()))?;
    fs::write(out.join("memory.x"), map)?;
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=frames");

    // Counts without the M7's FPU/DSP instructions would be meaningless: make sure the
    // rustflags (this directory's .cargo/config.toml joined with the root's) name the core.
    let flags = env::var("CARGO_ENCODED_RUSTFLAGS").unwrap_or_default();
    let flags: Vec<&str> = flags.split('\x1f').collect();
    let cpu_m7 = flags
        .windows(2)
        .any(|w| w[0] == "-C" && w[1] == "target-cpu=cortex-m7")
        || flags.contains(&"-Ctarget-cpu=cortex-m7");
    // cortex-m-rt's linker script: the root .cargo/config.toml passes it already; link it
    // exactly once (it INCLUDEs memory.x, whose regions cannot be defined twice).
    if !flags.contains(&"link-arg=-Tlink.x") && !flags.contains(&"-Clink-arg=-Tlink.x") {
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
    }
    if !cpu_m7 {
        return Err(
            "the M7 benchmark needs `-C target-cpu=cortex-m7` in the rustflags \
                    (bench/m7/.cargo/config.toml); RUSTFLAGS in the environment replaces them"
                .into(),
        );
    }
    Ok(())
}
