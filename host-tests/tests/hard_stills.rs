//! The detector on the hard still set (`touchdown_eval::stills`), on both image models: no
//! wrong id anywhere, and each class's recall at least its bound. Long (`--ignored`, CI's
//! long step): 240 frames rendered at 640x480.
//!
//! The bounds: issue 39's goal, 0.98, for the oblique, wide-lens and small classes; the
//! shadow-corner class is held at what it reads now (0.833 on seed 0) while its misses, a
//! hard shadow's edge across a corner of the black border or of the margin beside it (the
//! band along the edge joins the marker's outline), are open work (docs/accuracy.md, "Hard
//! stills").

use touchdown_eval::stills::{score_class, StillClass};
use touchdown_sim::Renderer;

/// Stills per class and renderer.
const STILLS: u64 = 30;

fn bound(class: StillClass) -> f64 {
    match class {
        StillClass::ShadowCorner => 0.80,
        StillClass::Oblique | StillClass::WideLens | StillClass::Small => 0.98,
    }
}

#[test]
#[ignore = "long: 240 stills rendered; CI's long step runs it"]
fn the_hard_stills_are_found_on_both_renderers_without_a_wrong_id() {
    let mut failures = Vec::new();
    for renderer in [Renderer::Raster, Renderer::Warp] {
        for class in StillClass::ALL {
            let score = score_class(class, STILLS, renderer, 0);
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
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
