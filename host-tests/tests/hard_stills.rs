//! The detector on the hard still set (`touchdown_eval::stills`), on both image models: no
//! wrong id anywhere, and each class's recall at least its bound. Long (`--ignored`, CI's
//! long step): 240 frames rendered at 640x480.
//!
//! The bounds: issue 39's goal, 0.98, for the four classes together and for the oblique,
//! wide-lens and small classes each; the shadow-corner class, a hard shadow's edge across a
//! corner of the black border or of the margin beside it, each at 0.9 (it reads 0.933 on
//! seed 0; its misses are in docs/accuracy.md, "Hard stills").
//!
//! Not long: two shadow-corner stills whose markers the shadow's band joins at a corner, found
//! only by completing the outline's hidden corner (`quad::complete`).

use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_eval::stills::{detect_still, render_still, score_class, StillClass};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_sim::Renderer;

/// Stills per class and renderer.
const STILLS: u64 = 30;

fn bound(class: StillClass) -> f64 {
    match class {
        StillClass::ShadowCorner => 0.90,
        StillClass::Oblique | StillClass::WideLens | StillClass::Small => 0.98,
    }
}

#[test]
#[ignore = "long: 240 stills rendered; CI's long step runs it"]
fn the_hard_stills_are_found_on_both_renderers_without_a_wrong_id() {
    let mut failures = Vec::new();
    for renderer in [Renderer::Raster, Renderer::Warp] {
        let (mut found, mut stills) = (0, 0);
        for class in StillClass::ALL {
            let score = score_class(class, STILLS, renderer, 0);
            (found, stills) = (found + score.found, stills + score.stills);
            println!("{} {}: {}", renderer.name(), class.name(), score.summary());
            for missed in &score.missed {
                println!("    missed {missed}");
            }
            if !score.wrong.is_empty() {
                failures.push(format!(
                    "{} {}: wrong ids: {:?}",
                    renderer.name(),
                    class.name(),
                    score.wrong
                ));
            }
            if score.recall() < bound(class) {
                failures.push(format!(
                    "{} {}: recall {:.3} below {}",
                    renderer.name(),
                    class.name(),
                    score.recall(),
                    bound(class)
                ));
            }
        }
        let recall = found as f64 / stills as f64;
        println!(
            "{}: recall {recall:.3} over the four classes",
            renderer.name()
        );
        if recall < 0.98 {
            failures.push(format!(
                "{}: recall {recall:.3} over the four classes below 0.98",
                renderer.name()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Seed 1's shadow-corner stills 11 and 4, on both image models: the band along the shadow's
/// edge joins the marker's outline at a corner, so the outline is three corners of the marker
/// and the band (both missed before `quad::complete`).
#[test]
fn markers_joined_at_a_corner_by_a_shadows_band_are_found() {
    let mut detector = Detector::new(DetectorConfig::offline());
    let mut workspace = HostWorkspace::new();
    for renderer in [Renderer::Raster, Renderer::Warp] {
        for index in [11, 4] {
            let still = render_still(StillClass::ShadowCorner, index, renderer, 1)
                .expect("the still renders");
            let outcome = detect_still(&mut detector, &mut workspace, &still);
            let what = format!("{} shadow-corner seed 1 #{index}", renderer.name());
            assert!(outcome.wrong.is_empty(), "{what}: {:?}", outcome.wrong);
            let error = outcome
                .corner_error_px
                .unwrap_or_else(|| panic!("{what}: missed"));
            assert!(error < 3.0, "{what}: a corner {error:.2} px off");
        }
    }
}
