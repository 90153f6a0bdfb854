//! cargo-fuzz target `frame_stream`: see [`touchdown_fuzz_harness::frame_stream`] for the input
//! layout and what is checked (the harness is shared with fuzz/harness/tests/regressions.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| touchdown_fuzz_harness::frame_stream(data));
