//! cargo-fuzz target `recording`: see [`touchdown_fuzz::recording`] for the input layout and what is
//! checked (the harness is shared with host-tests/tests/fuzz_regressions.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| touchdown_fuzz::recording(data));
