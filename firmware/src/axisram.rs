//! Statics in AXI SRAM.
//!
//! Frame buffers and the detector's frame-sized work memory are too large for DTCM (128 KB,
//! shared with the stack) and must be reachable by the camera's DMA, so they live in the
//! `.axisram` output section that `memory.x` places in the 512 KB AXI SRAM.
//!
//! That section is `NOLOAD`: cortex-m-rt neither copies nor zeroes it (only `.data`/`.bss` in
//! DTCM are initialised), so a plain `#[link_section = ".axisram"] static X: T = value;` would
//! start with whatever the SRAM held, not `value`. [`axisram_static!`] therefore keeps the
//! storage as `MaybeUninit<T>`, writes the initial value at run time, and hands out the one
//! `&'static mut T` guarded by a "taken" flag that lives in ordinary `.bss`. Writing every byte
//! before it is read also keeps the SRAM's ECC words consistent (reads of never-written AXI
//! SRAM can report ECC errors).

/// Claims a `&'static mut $ty` in AXI SRAM, initialised to `$init`.
///
/// Evaluates to `Some(&'static mut $ty)` the first time this call site runs and `None` on any
/// later run (each expansion has its own storage), like `cortex_m::singleton!`. Write it where
/// it runs once (`main`). The value is constructed in place by the optimiser in release builds;
/// avoid initialisers that are expensive to build on the stack in debug builds.
macro_rules! axisram_static {
    ($ty:ty = $init:expr) => {
        $crate::axisram::axisram_static!(".axisram", $ty = $init)
    };
    // The same in another NOLOAD section of memory.x (e.g. ".sram123").
    ($section:literal, $ty:ty = $init:expr) => {{
        #[link_section = $section]
        static mut SLOT: ::core::mem::MaybeUninit<$ty> = ::core::mem::MaybeUninit::uninit();
        // In .bss (DTCM), so it really starts `false`.
        static TAKEN: ::core::sync::atomic::AtomicBool =
            ::core::sync::atomic::AtomicBool::new(false);

        if TAKEN.swap(true, ::core::sync::atomic::Ordering::AcqRel) {
            None
        } else {
            // SAFETY: `TAKEN` was false and is now true, so this is the only reference ever
            // made to `SLOT`; `write` initialises it before the reference is handed out, and
            // the storage is 'static.
            let slot = unsafe { &mut *::core::ptr::addr_of_mut!(SLOT) };
            let value: &'static mut $ty = slot.write($init);
            Some(value)
        }
    }};
}

pub(crate) use axisram_static;
