//! Heap-allocated detector work memory sized to any frame (the firmware uses the fixed
//! `QvgaWorkspace` / `VgaWorkspace` of the core instead).
//!
//! It lives in the evaluation because the evaluation is where the host runs the detector
//! over frames of any size; its other users (the command line's `detect` and `companion`,
//! the integration tests, the benchmarks and examples) depend on the evaluation anyway.

use touchdown_core::detect::{buffer_sizes, Buffers, DetectError, Detection, Detector};
use touchdown_core::family::Family;
use touchdown_core::image::GrayImage;

/// Work memory that grows to the largest frame seen.
#[derive(Debug, Default)]
pub struct HostWorkspace {
    bitmap: Vec<u32>,
    visited: Vec<u32>,
    tiles: Vec<u8>,
}

impl HostWorkspace {
    /// Empty; grows on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Buffers large enough for a `width` x `height` frame.
    pub fn buffers(&mut self, width: usize, height: usize) -> Buffers<'_> {
        let sizes = buffer_sizes(width, height);
        if self.bitmap.len() < sizes.bitmap_words {
            self.bitmap.resize(sizes.bitmap_words, 0);
            self.visited.resize(sizes.bitmap_words, 0);
        }
        if self.tiles.len() < sizes.tile_bytes {
            self.tiles.resize(sizes.tile_bytes, 0);
        }
        Buffers {
            bitmap: &mut self.bitmap,
            visited: &mut self.visited,
            tiles: &mut self.tiles,
        }
    }

    /// Runs `detector` on `image` and returns a copy of its detections.
    pub fn detect(
        &mut self,
        detector: &mut Detector,
        image: &GrayImage<'_>,
        families: &[&Family<'_>],
    ) -> Result<Vec<Detection>, DetectError> {
        let mut buffers = self.buffers(image.width(), image.height());
        detector
            .detect(image, families, &mut buffers)
            .map(|d| d.to_vec())
    }
}
