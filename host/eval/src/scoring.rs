//! Scoring of a detector's output against the rendered truth, for the rendered-frame tests
//! and the recall report: which rendered markers were found, how far their corners are off,
//! and which detections are no rendered marker at all.
//!
//! It is evaluation, not rendering: it reads the truth the renderer produces
//! ([`MarkerTruth`]) and nothing else of it.

use touchdown_core::detect::Detection;
use touchdown_core::family::Family;
use touchdown_core::geometry::Point;

use touchdown_sim::render::MarkerTruth;

/// A marker a frame was rendered with, for [`score_frame`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expected<'a> {
    /// Family name ([`Family::name`]).
    pub family: &'a str,
    /// Id within the family.
    pub id: u16,
    /// Where it is.
    pub truth: MarkerTruth,
}

/// How the detections of one frame compare with what was rendered.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameScore {
    /// Per expected marker, in order: the corner error of its detection (max over the four
    /// corners, pixels), `None` when it was missed.
    pub corner_errors: Vec<Option<f32>>,
    /// Detections that are no rendered marker (wrong family, wrong id, or nowhere near the
    /// marker with that id), described for the failure message.
    pub wrong: Vec<String>,
    /// Further detections of a marker that was already found.
    pub duplicates: usize,
}

impl FrameScore {
    /// Number of expected markers found.
    pub fn found(&self) -> usize {
        self.corner_errors.iter().filter(|e| e.is_some()).count()
    }
}

/// Whether a detection centred at `found` lies on a marker centred at `center` whose
/// shortest side is `min_side_px`: within half that side (at least 2 px).
pub fn on_marker(center: Point, min_side_px: f32, found: Point) -> bool {
    center.distance(found) <= (0.5 * min_side_px).max(2.0)
}

/// Matches detections to the rendered markers: a detection matches when its family name and
/// id are those of a rendered marker whose true centre is within half the marker's shortest
/// side (at least 2 px) of the reported centre. Everything else is "wrong".
pub fn score_frame(
    detections: &[Detection],
    families: &[&Family<'_>],
    expected: &[Expected<'_>],
) -> FrameScore {
    let mut score = FrameScore {
        corner_errors: vec![None; expected.len()],
        ..FrameScore::default()
    };
    for d in detections {
        let name = families.get(d.family as usize).map_or("?", |f| f.name);
        let hit = expected.iter().position(|e| {
            e.family == name
                && e.id == d.id
                && on_marker(e.truth.center, e.truth.min_side_px(), d.center)
        });
        match hit {
            Some(k) => {
                let error = expected[k].truth.corner_error(&d.corners);
                match &mut score.corner_errors[k] {
                    Some(previous) => {
                        score.duplicates += 1;
                        *previous = previous.min(error);
                    }
                    slot => *slot = Some(error),
                }
            }
            None => score.wrong.push(format!(
                "{name} id {} at ({:.1}, {:.1}) hamming {} margin {:.2}",
                d.id, d.center.x, d.center.y, d.hamming, d.decision_margin
            )),
        }
    }
    score
}
