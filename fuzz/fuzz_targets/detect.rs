//! cargo-fuzz target `detect`: see [`touchdown_fuzz::detect`] for the input layout and what is
//! checked (the harness is shared with host-tests/tests/fuzz_regressions.rs).
#![no_main]

use std::cell::RefCell;

use libfuzzer_sys::fuzz_target;
use touchdown_fuzz::DetectState;

thread_local! {
    /// Work memory and detectors, allocated once per process.
    static STATE: RefCell<DetectState> = RefCell::new(DetectState::default());
}

fuzz_target!(
    |data: &[u8]| STATE.with(|state| touchdown_fuzz::detect(&mut state.borrow_mut(), data))
);
