//! cargo-fuzz target `detect`: see [`touchdown_fuzz_harness::detect`] for the input layout and what is
//! checked (the harness is shared with fuzz/harness/tests/regressions.rs).
#![no_main]

use std::cell::RefCell;

use libfuzzer_sys::fuzz_target;
use touchdown_fuzz_harness::DetectState;

thread_local! {
    /// Work memory and detectors, allocated once per process.
    static STATE: RefCell<DetectState> = RefCell::new(DetectState::default());
}

fuzz_target!(
    |data: &[u8]| STATE.with(|state| touchdown_fuzz_harness::detect(&mut state.borrow_mut(), data))
);
