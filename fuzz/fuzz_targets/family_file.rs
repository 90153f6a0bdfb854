//! cargo-fuzz target `family_file`: see [`touchdown_fuzz::family_file`] for the input layout and what is
//! checked (the harness is shared with host-tests/tests/fuzz_regressions.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| touchdown_fuzz::family_file(data));
