//! What the two detection methods do differently, as the [`Strategy`] the shared steps ask,
//! and touchdown's own method ([`Robust`]); the paper's is in [`super::paper`].
//!
//! Separate from the entry in the parent module so the shared steps read without the
//! methods' choices, and the choices of each method sit together.

use super::{
    contour, deblur, decode, quad, refine, threshold, Candidates, DetectorConfig, WORK_PRECHECK,
    WORK_THRESHOLD_BLOCK,
};
use crate::camera::CameraModel;
use crate::family::Family;
use crate::geometry::{cyclic, Point};
use crate::image::GrayImage;

/// What the two methods ([`Method`](super::Method)) do differently, as the steps they share ask it: the
/// binary image, which boundaries are followed, which quads are candidates for which family,
/// the quick look, the corners the cells are read through, the cell reading and the look-up's
/// error bound. [`Detector::detect`](super::Detector::detect) picks one per frame ([`Robust`], [`paper::Paper`](super::paper::Paper)), so
/// the shared steps have no branches on the method and the paper's choices stay in
/// [`paper`](super::paper).
pub(super) trait Strategy {
    /// Step 1: the bitmap whose boundaries are traced. `tiles` is the frame's scratch memory
    /// ([`Buffers::tiles`](super::Buffers::tiles)). Returns the work units of the part of its
    /// cost that depends on the image (charged to the frame's budget; the part that is the
    /// same for every frame of a size is not).
    fn binarise(
        &self,
        image: &GrayImage<'_>,
        config: &DetectorConfig,
        bitmap: &mut [u32],
        tiles: &mut [u8],
    ) -> u32;
    /// Which boundaries of the bitmap start a trace when searching for `families`.
    fn start_rule(&self, families: &[&Family<'_>]) -> contour::StartRule;
    /// Whether a quad (a light region when `hole`) can be a marker of `family`.
    fn wanted(&self, family: &Family<'_>, hole: bool) -> bool;
    /// The quick look at a candidate's rough corners before it is refined and read, charging
    /// its work to `tracer`.
    fn quick_look(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        quad: &quad::Quad,
        tracer: &mut contour::Tracer<'_>,
    ) -> Look;
    /// The corners the cells are read through, adding the image reads to `samples`.
    fn corners(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        quad: &quad::Quad,
        samples: &mut u32,
    ) -> [Point; 4];
    /// Reads the cells of `family`'s layout through `corners`, adding the image reads to
    /// `samples`; with `deblurred`, the second read of a small candidate that no family's
    /// first read found a code in, with the blur taken out ([`super::deblur`]; `None` when
    /// the method has no such read).
    fn read(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        family: &Family<'_>,
        corners: &[Point; 4],
        deblurred: bool,
        samples: &mut u32,
    ) -> Option<decode::GridRead>;
    /// Most bits the code look-up may correct.
    fn max_hamming(&self, config: &DetectorConfig) -> u8;
    /// Whether a boundary that is not a quad is searched for a marker joined at one corner
    /// ([`quad::complete`]).
    fn completes_corners(&self) -> bool;
    /// Whether the scan takes the frame's middle quarter first (see `scan_rows`) rather
    /// than every row in order.
    fn scans_middle_first(&self) -> bool;
    /// Step 7: whether the small markers' corners are fitted with their decoded pattern
    /// ([`super::pattern_fit`]).
    fn fits_patterns(&self, config: &DetectorConfig) -> bool;
}

/// What the quick look ([`Strategy::quick_look`]) made of a candidate.
pub(super) enum Look {
    /// Refine and read it.
    Candidate,
    /// Not a marker.
    Rejected,
    /// The work budget ran out.
    OutOfBudget,
}

/// touchdown's method ([`Method::Robust`](super::Method::Robust)), binarising at `level`:
/// the mid-level over a frame, the ratio where a lost pad is looked for again
/// ([`super::Detector::detect_region`]).
pub(super) struct Robust {
    pub(super) level: ThresholdLevel,
}

/// Where between a window's darkest and lightest level a pixel turns dark.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ThresholdLevel {
    /// Halfway ([`threshold::local_threshold`]): the frame's search.
    MidLevel,
    /// At the ratio of the extrema ([`threshold::ratio_threshold`]): the second look.
    Ratio,
}

impl Strategy for Robust {
    fn binarise(
        &self,
        image: &GrayImage<'_>,
        config: &DetectorConfig,
        bitmap: &mut [u32],
        tiles: &mut [u8],
    ) -> u32 {
        let max_rows = threshold::MaxRows::for_frame(image.width(), image.height());
        match self.level {
            ThresholdLevel::MidLevel => {
                // The same bitmap and count either way; each target the faster of the two.
                let compared = if cfg!(target_pointer_width = "64") {
                    threshold::local_threshold_vectorised(
                        image,
                        config.min_contrast,
                        max_rows,
                        bitmap,
                        tiles,
                    )
                } else {
                    threshold::local_threshold(image, config.min_contrast, max_rows, bitmap, tiles)
                };
                compared.saturating_mul(WORK_THRESHOLD_BLOCK)
            }
            // Every pixel is compared, whatever the image: a cost of the frame's size. (The
            // second look runs on a region around a lost pad, not a whole frame.)
            ThresholdLevel::Ratio => {
                threshold::ratio_threshold(image, config.min_contrast, bitmap, tiles);
                0
            }
        }
    }

    /// Hole boundaries are only candidates for white-on-black families; for the others
    /// following them is wasted time (see `contour`).
    fn start_rule(&self, families: &[&Family<'_>]) -> contour::StartRule {
        if families.iter().any(|f| f.reversed()) {
            contour::StartRule::AllBoundaries
        } else {
            contour::StartRule::OuterOnly
        }
    }

    /// The binarisation knows polarity: a hole is a light region, which only the reversed
    /// families are detected by.
    fn wanted(&self, family: &Family<'_>, hole: bool) -> bool {
        family.reversed() == hole
    }

    /// [`decode::precheck`], for dark-on-light families with a quiet margin (a hole is a
    /// white-on-black one's).
    fn quick_look(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        quad: &quad::Quad,
        tracer: &mut contour::Tracer<'_>,
    ) -> Look {
        if quad.hole || !candidates.quiet_margins {
            return Look::Candidate;
        }
        if !tracer.charge(WORK_PRECHECK) {
            return Look::OutOfBudget;
        }
        let rough = refine::rough_half_pixel_adjusted(quad);
        let flat_rejects = !candidates.uniform_decodes;
        let cells = candidates.max_quad_cells;
        let min_contrast = candidates.config.min_contrast;
        match decode::precheck(candidates.image, cells, &rough, min_contrast, flat_rejects) {
            decode::Precheck::Candidate => Look::Candidate,
            decode::Precheck::Flat | decode::Precheck::NoBorder => Look::Rejected,
        }
    }

    fn corners(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        quad: &quad::Quad,
        samples: &mut u32,
    ) -> [Point; 4] {
        if !candidates.config.refine_edges {
            return refine::half_pixel_adjusted(quad);
        }
        let c = &quad.corners;
        let shortest = (0..4)
            .map(|k| cyclic(c, k).distance(cyclic(c, k + 1)))
            .fold(f32::MAX, f32::min);
        let radius = (0.5 * shortest / candidates.max_quad_cells as f32).clamp(0.75, 4.0);
        refine::refine_corners(
            candidates.image,
            quad,
            radius,
            lens_for(candidates, c),
            samples,
        )
    }

    fn read(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        family: &Family<'_>,
        corners: &[Point; 4],
        deblurred: bool,
        samples: &mut u32,
    ) -> Option<decode::GridRead> {
        let (image, config) = (candidates.image, candidates.config);
        let lens = lens_for(candidates, corners);
        if deblurred {
            deblur::read_deblurred(image, family, corners, lens, config, samples)
        } else {
            decode::read_robust(image, family, corners, lens, config, samples)
        }
    }

    fn max_hamming(&self, config: &DetectorConfig) -> u8 {
        config.max_hamming
    }

    fn fits_patterns(&self, config: &DetectorConfig) -> bool {
        config.refine_edges && config.fit_small_markers
    }

    fn completes_corners(&self) -> bool {
        true
    }

    fn scans_middle_first(&self) -> bool {
        true
    }
}

/// The lens a candidate with these corners is refined and read through: the detector's
/// camera, for markers of at least [`refine::MIN_LENS_PERIMETER_PX`] around; smaller ones
/// have straight edges to within the refinement's own precision, and their cells are read by
/// the homography alone.
fn lens_for<'c>(
    candidates: &Candidates<'c, '_, '_>,
    corners: &[Point; 4],
) -> Option<&'c CameraModel> {
    // Measured only with a camera: without one (the firmware's lenses) nothing is spent.
    candidates.camera.filter(|_| {
        let perimeter: f32 = (0..4)
            .map(|k| cyclic(corners, k).distance(cyclic(corners, k + 1)))
            .sum();
        perimeter >= refine::MIN_LENS_PERIMETER_PX
    })
}
