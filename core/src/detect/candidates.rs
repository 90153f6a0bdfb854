//! Steps 3 to 6 for one closed boundary: quad fit (through the lens when the camera is known,
//! `lens`), quick look, refinement, decoding and de-duplication, charged to the frame's work
//! budget.
//!
//! Separate from the scan in the parent module, which only finds the boundaries and hands
//! each one to [`Candidates::process`]; the method's choices come from the [`Strategy`].

use super::{
    contour, deblur, decode, lens, pattern_fit, quad, DetectStats, Detection, DetectorConfig, Look,
    Strategy, MAX_DETECTIONS, WORK_CANDIDATE, WORK_COMPLETION_PER_PIXEL, WORK_FIT,
    WORK_PER_SAMPLE_X2, WORK_SCREEN_PIXELS,
};
use crate::camera::CameraModel;
use crate::family::Family;
use crate::geometry::cyclic;
use crate::image::GrayImage;

/// What every candidate of a frame is checked against.
pub(super) struct Candidates<'f, 'i, 'a> {
    /// The method's choices.
    pub(super) strategy: &'f dyn Strategy,
    pub(super) image: &'f GrayImage<'i>,
    pub(super) families: &'f [&'f Family<'a>],
    pub(super) config: &'f DetectorConfig,
    /// Cells across the largest detected square among the families: bounds how far an edge
    /// may be moved without reaching the next edge inside the marker.
    pub(super) max_quad_cells: usize,
    /// Some family decodes an all-black or all-white grid, so a candidate with a flat
    /// interior may still be one of its markers ([`decode::uniform_grid_decodes`]).
    pub(super) uniform_decodes: bool,
    /// Every family has a quiet (white) ring right outside its border: then a marker's
    /// outline is a clean quad (the screening's convexity test holds) and
    /// [`decode::precheck`] can take that ring as the white reference. tagStandard41h12 has
    /// data cells there instead.
    pub(super) quiet_margins: bool,
    /// The lens, when the detector was given a distorting one: boundaries are fitted
    /// undistorted (`lens`).
    pub(super) camera: Option<&'f CameraModel>,
    /// The largest small candidate so far whose first read found no code: whether it is a
    /// hole, its corners and its area ([`Candidates::read_the_largest_unread`]).
    pub(super) unread: core::cell::Cell<Option<(bool, [crate::geometry::Point; 4], f32)>>,
}

impl Candidates<'_, '_, '_> {
    /// Quad fit, refinement and decoding of one closed boundary, charging the work to
    /// `tracer`'s budget. Returns false when the scan must stop: the work budget or the
    /// candidate budget ran out.
    pub(super) fn process(
        &self,
        boundary: contour::Boundary<'_>,
        detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
        stats: &mut DetectStats,
        tracer: &mut contour::Tracer<'_>,
    ) -> bool {
        let config = self.config;
        let contour::Boundary {
            points: boundary,
            length,
        } = boundary;
        let screened = quad::screen(boundary, length, config.min_edge_px, self.quiet_margins);
        let mut quad = None;
        if let Ok(screened) = &screened {
            // Through the lens first, for boundaries long enough to be bent (see `lens`): the
            // fit on the boundary as an ideal lens draws it, its corners taken back into the
            // frame.
            if let Some(camera) = self.camera.filter(|_| length >= lens::MIN_LENS_LENGTH) {
                let count = boundary.len().min(lens::MAX_LENS_POINTS) as u32;
                if !tracer.charge(WORK_FIT + count * (1 + lens::WORK_UNDISTORT)) {
                    return false;
                }
                let mut straight = [contour::Pixel::default(); lens::MAX_LENS_POINTS];
                quad = lens::straighten(camera, boundary, &mut straight).and_then(|s| {
                    let points = straight.get(..s.points)?;
                    let screened = quad::screen(points, length, config.min_edge_px, false).ok()?;
                    let fitted = quad::fit(points, &screened, config.min_edge_px)?;
                    lens::bend_back(camera, &s, &fitted)
                });
            }
            if quad.is_none() {
                if !tracer.charge(WORK_FIT + boundary.len() as u32) {
                    return false;
                }
                quad = quad::fit(boundary, screened, config.min_edge_px);
            }
        }
        if let Some(quad) = quad {
            return self.examine(&quad, detections, stats, tracer);
        }
        let area2 = match screened {
            Ok(s) => s.area2,
            Err(u) => u.area2,
        };
        self.complete(boundary, length, area2, detections, stats, tracer)
    }

    /// A boundary that is not a quad whole: perhaps a marker joined at one corner by something
    /// dark ([`quad::complete`]), for families whose outline is a clean quad. `area2` is the
    /// screening's (twice the signed area; 0 when not measured). Returns false when the scan
    /// must stop.
    fn complete(
        &self,
        boundary: &[contour::Pixel],
        length: usize,
        area2: i32,
        detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
        stats: &mut DetectStats,
        tracer: &mut contour::Tracer<'_>,
    ) -> bool {
        let min_edge = self.config.min_edge_px;
        if !self.quiet_margins
            || !self.strategy.completes_corners()
            || !quad::might_complete(length, area2, min_edge)
            // Inside a marker already found: its cells, or its border's inner edge.
            || within_detection(boundary, detections)
        {
            return true;
        }
        if !tracer.charge(boundary.len() as u32 / WORK_SCREEN_PIXELS) {
            return false;
        }
        if !quad::worth_completing(boundary, length, min_edge) {
            return true;
        }
        if !tracer.charge(WORK_FIT + boundary.len() as u32 * WORK_COMPLETION_PER_PIXEL) {
            return false;
        }
        // By reference: a heapless vector's owning iterator has a panic path the no-panic
        // check finds.
        for quad in &quad::complete(boundary, min_edge) {
            if !self.examine(quad, detections, stats, tracer) {
                return false;
            }
        }
        true
    }

    /// Steps 4 to 6 for one quad: the quick look, refinement, decoding and de-duplication.
    /// Returns false when the scan must stop.
    fn examine(
        &self,
        quad: &quad::Quad,
        detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
        stats: &mut DetectStats,
        tracer: &mut contour::Tracer<'_>,
    ) -> bool {
        let config = self.config;
        let strategy = self.strategy;
        if !self.families.iter().any(|f| strategy.wanted(f, quad.hole)) {
            return true;
        }
        stats.quads += 1;
        match strategy.quick_look(self, quad, tracer) {
            Look::Candidate => {}
            Look::Rejected => return true,
            Look::OutOfBudget => return false,
        }
        // The candidate's work is counted as it is done (image samples) and charged after;
        // it starts only while some budget is left, so a frame overruns its budget by at most
        // one candidate.
        if stats.refined >= u32::from(config.max_candidates) || tracer.remaining() == 0 {
            return false;
        }
        stats.refined += 1;
        let mut samples = 0u32;
        let corners = strategy.corners(self, quad, &mut samples);
        if !quad::check_shape(&corners, 0.8 * config.min_edge_px) || !self.inside(&corners) {
            return tracer.charge(candidate_work(samples));
        }
        let (bordered, decoded) =
            self.read_and_look_up(quad.hole, &corners, false, detections, stats, &mut samples);
        if bordered {
            stats.bordered += 1;
        }
        // A lone small marker's scale is only as good as the pattern fit at the frame's end
        // (without it a far marker's is off by a percent or two): its work is held back from
        // the rest of the scan, so that a cluttered frame spends it on the marker found rather
        // than on the clutter. Once a second marker is found the scan's own work is worth
        // more (the markers' spread sets the scale, and the frame may hold more of them).
        if decoded && strategy.fits_patterns(config) {
            if detections.len() == 1 && pattern_fit::fits(&corners) {
                tracer.hold(pattern_fit::WORK_PATTERN_FIT);
            } else {
                tracer.release();
            }
        }
        if !decoded && deblur::is_small(&corners, self.max_quad_cells) {
            // The largest small candidate without a code is read again at the frame's end.
            let size = crate::geometry::quad_area(&corners).abs();
            if self.unread.get().is_none_or(|(_, _, s)| size > s) {
                self.unread.set(Some((quad.hole, corners, size)));
            }
        }
        tracer.charge(candidate_work(samples))
    }

    /// At the frame's end: the largest small candidate whose cells gave no code, read again
    /// with the blur taken out ([`super::deblur`]). One a frame: a far frame has one marker
    /// that far, and a frame of many small look-alikes (a sheet of random codes) pays for
    /// one second read, not one each.
    pub(super) fn read_the_largest_unread(
        &self,
        detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
        stats: &mut DetectStats,
        tracer: &mut contour::Tracer<'_>,
    ) {
        let Some((hole, corners, _)) = self.unread.take() else {
            return;
        };
        // A candidate on a marker already found (one of its own boundaries, or the marker
        // outlined again) would only read that marker again, from worse corners.
        let centre = corners
            .iter()
            .fold(crate::geometry::Point::default(), |a, c| {
                crate::geometry::Point::new(a.x + 0.25 * c.x, a.y + 0.25 * c.y)
            });
        if inside_detection(centre, detections) {
            return;
        }
        // A second look, not part of the frame's search: nothing is missed without it.
        if tracer.remaining() == 0 {
            return;
        }
        let mut samples = 0u32;
        self.read_and_look_up(hole, &corners, true, detections, stats, &mut samples);
        // A method without the read (the paper's) reads nothing and pays nothing.
        if samples > 0 {
            stats.deblurred += 1;
            tracer.charge(candidate_work(samples));
        }
    }

    /// Reads the cells through `corners` for every family a candidate (a hole when `hole`)
    /// can be, by the method's first read or (`deblurred`) its deblurred one, looks the codes
    /// up and keeps what decodes. Returns whether some family's read found a marker grid and
    /// whether some family decoded.
    fn read_and_look_up(
        &self,
        hole: bool,
        corners: &[crate::geometry::Point; 4],
        deblurred: bool,
        detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
        stats: &mut DetectStats,
        samples: &mut u32,
    ) -> (bool, bool) {
        let strategy = self.strategy;
        let (mut bordered, mut decoded) = (false, false);
        // The last layout read and its result: consecutive families with the same layout
        // (the default tag36h11 + aruco_6x6_250 pair) sample and threshold the cells once.
        let mut last: Option<(&Family<'_>, Option<decode::GridRead>)> = None;
        for (index, family) in self.families.iter().enumerate() {
            if !strategy.wanted(family, hole) {
                continue;
            }
            let grid = match last {
                Some((seen, grid)) if seen.same_layout(family) => grid,
                _ => {
                    let grid = strategy.read(self, family, corners, deblurred, samples);
                    last = Some((family, grid));
                    grid
                }
            };
            let Some(grid) = grid else {
                continue;
            };
            bordered = true;
            let max_hamming = strategy.max_hamming(self.config);
            let Some(read) = decode::lookup(family, &grid, max_hamming) else {
                continue;
            };
            stats.decoded += 1;
            decoded = true;
            let detection = Detection {
                family: index as u8,
                id: read.decoded.id,
                hamming: read.decoded.hamming,
                corners: read.corners,
                center: read.center,
                decision_margin: read.margin,
                contrast: read.contrast,
            };
            if !insert_unique(detections, detection) {
                stats.truncated = true;
            }
        }
        (bordered, decoded)
    }
}

impl Candidates<'_, '_, '_> {
    /// Whether every corner lies on the image (pixel centres span `0..=size - 1`). A marker
    /// cut by the frame's edge has its outline closed along the edge; the corners refined
    /// from it land on or past the edge and its cells past the edge read the edge's pixels,
    /// so it can still decode, with a corner pixels off that skews a multi-marker fix.
    fn inside(&self, corners: &[crate::geometry::Point; 4]) -> bool {
        let (w, h) = (self.image.width() as f32, self.image.height() as f32);
        corners
            .iter()
            .all(|c| c.x >= 0.0 && c.y >= 0.0 && c.x <= w - 1.0 && c.y <= h - 1.0)
    }
}

/// Whether the boundary's first pixel lies inside the corners of a detected marker: the
/// boundary is then the marker's own (a cell, its border's inner edge), no other marker's.
fn within_detection(
    boundary: &[contour::Pixel],
    detections: &heapless::Vec<Detection, MAX_DETECTIONS>,
) -> bool {
    let Some(first) = boundary.first() else {
        return false;
    };
    let p = crate::geometry::Point::new(f32::from(first.x), f32::from(first.y));
    inside_detection(p, detections)
}

/// Whether `p` lies inside the corners of a detected marker.
fn inside_detection(
    p: crate::geometry::Point,
    detections: &heapless::Vec<Detection, MAX_DETECTIONS>,
) -> bool {
    detections.iter().any(|d| {
        let c = &d.corners;
        // On the same side of every edge, whichever way round the corners run.
        let side = |k: usize| {
            let (a, b) = (cyclic(c, k), cyclic(c, k + 1));
            (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
        };
        let sides = [side(0), side(1), side(2), side(3)];
        sides.iter().all(|&s| s > 0.0) || sides.iter().all(|&s| s < 0.0)
    })
}

/// Work units of a refined and read candidate that took `samples` weighted image reads.
fn candidate_work(samples: u32) -> u32 {
    WORK_CANDIDATE.saturating_add(samples.saturating_mul(WORK_PER_SAMPLE_X2) / 2)
}

/// Mean edge length of a detection, pixels.
fn edge_length(d: &Detection) -> f32 {
    let c = &d.corners;
    (0..4)
        .map(|k| cyclic(c, k).distance(cyclic(c, k + 1)))
        .sum::<f32>()
        * 0.25
}

/// Adds a detection unless the same physical marker is already there; of two, the one with
/// fewer corrected bits, then the larger decision margin, is kept. Two detections are the
/// same marker when their centres nearly coincide and their sizes agree (a small marker
/// printed inside a large one is a different marker). Returns false when full.
fn insert_unique(
    detections: &mut heapless::Vec<Detection, MAX_DETECTIONS>,
    new: Detection,
) -> bool {
    let size = edge_length(&new);
    for existing in detections.iter_mut() {
        let other = edge_length(existing);
        let ratio = size.max(other) / size.min(other).max(1e-3);
        if new.center.distance(existing.center) < 0.25 * size.min(other) && ratio < 1.5 {
            let better =
                (new.hamming, -new.decision_margin) < (existing.hamming, -existing.decision_margin);
            if better {
                *existing = new;
            }
            return true;
        }
    }
    detections.push(new).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point;

    /// A boundary starting inside a detected marker is its own, whichever way its corners
    /// run; one starting outside is not.
    #[test]
    fn a_boundary_inside_a_detection_is_the_markers_own() {
        let corners =
            [(10.0, 10.0), (50.0, 12.0), (48.0, 50.0), (8.0, 48.0)].map(|(x, y)| Point::new(x, y));
        let mut detections = heapless::Vec::new();
        let detection = |corners| Detection {
            family: 0,
            id: 0,
            hamming: 0,
            corners,
            center: Point::new(29.0, 30.0),
            decision_margin: 1.0,
            contrast: 100.0,
        };
        detections.push(detection(corners)).unwrap();
        let at = |x, y| [contour::Pixel { x, y }];
        assert!(within_detection(&at(30, 30), &detections));
        assert!(!within_detection(&at(60, 30), &detections));
        let mut reversed = corners;
        reversed.reverse();
        detections[0] = detection(reversed);
        assert!(within_detection(&at(30, 30), &detections));
        assert!(!within_detection(&at(30, 5), &detections));
        assert!(!within_detection(&[], &detections));
    }
}
