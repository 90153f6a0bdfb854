//! Stack high-water mark by painting: fill the free stack below the stack pointer with a
//! pattern, run the code, then find the deepest word that no longer holds the pattern.

use core::arch::asm;
use core::ptr::read_volatile;

/// Bytes painted below the stack pointer; a depth this large is reported as overflowing.
const PAINT_BYTES: usize = 64 * 1024;
/// The paint.
const PATTERN: u32 = 0xC0DE_5AFE;

/// A painted stack area: `[low, top)`, `top` the stack pointer when it was painted.
pub struct Painted {
    low: usize,
    top: usize,
}

/// How deep the stack went below the painting stack pointer.
pub struct Depth {
    /// Bytes used below the stack pointer at [`paint`].
    pub bytes: usize,
    /// The deepest painted word was overwritten: the real depth may be larger.
    pub overflowed: bool,
}

/// Paints the `PAINT_BYTES` below the current stack pointer. Inlined so that the stack
/// pointer is the caller's, which measures everything the caller calls afterwards.
#[inline(always)]
pub fn paint() -> Painted {
    let top: usize;
    let low: usize;
    // SAFETY: the memory below the stack pointer is unused (no red zone on ARM, no interrupts
    // in the benchmark) and the RAM block holds far more than PAINT_BYTES of stack beyond the
    // statics (memory.x: 4 MB). The loop writes whole words from an 8-byte-aligned address up
    // to the stack pointer, using registers only.
    unsafe {
        asm!(
            "mov {top}, sp",
            "sub {low}, {top}, {bytes}",
            "mov {p}, {low}",
            "2:",
            "str {pattern}, [{p}], #4",
            "cmp {p}, {top}",
            "blo 2b",
            top = out(reg) top,
            low = out(reg) low,
            p = out(reg) _,
            bytes = in(reg) PAINT_BYTES,
            pattern = in(reg) PATTERN,
            options(nostack),
        );
    }
    Painted { low, top }
}

impl Painted {
    /// The deepest use of the painted area so far.
    pub fn depth(&self) -> Depth {
        let mut p = self.low;
        // SAFETY: reads words of the painted area, which is RAM below the stack pointer
        // recorded by `paint`, above which this function's own frame lies.
        while p < self.top && unsafe { read_volatile(p as *const u32) } == PATTERN {
            p += 4;
        }
        Depth {
            bytes: self.top - p,
            overflowed: p == self.low,
        }
    }
}
