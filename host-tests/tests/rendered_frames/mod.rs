//! What the rendered-frame tests share (`tests/rendered.rs`: single markers by size, rotation
//! and imaging condition; `tests/rendered_scenes.rs`: several markers per frame, the paper's
//! method): the imaging conditions, the bench that renders, detects and scores a frame, the
//! pass criteria and the printed tables. Each test binary uses part of it, hence the
//! `dead_code` allowance.
//!
//! The detector on rendered frames of every shipped family, with exact truth.
//!
//! Frames come from `touchdown_sim::render` (area-sampled, so small markers look as on a real
//! sensor). Each test prints a compact table, then asserts:
//! - **never a wrong id**: any detection that is not a rendered marker (family, id and place)
//!   fails, under every condition, as does a marker reported twice;
//! - **recall** where the marker is resolvable: [`must_find`] says when (enough pixels per
//!   cell along the marker's shortest projected side, and blur, noise and tilt within the
//!   "moderate" bounds);
//! - **corner error** (max over the four corners): at most [`CLEAN_CORNER_PX`] for clean,
//!   untilted markers of at least [`LARGE_EDGE_PX`], at most [`MODERATE_CORNER_PX`] under
//!   moderate conditions.
//!
//! The searched family set is the rendered family alone (the ArUco dictionaries are nested,
//! `aruco_4x4_50` is the start of `aruco_4x4_100`, so searching both would make the
//! "right family" ambiguous); the multi-marker frames search two families at once and
//! `negatives.rs` checks markers against the other families of their layout.
//!
//! Everything is seeded, so a failure reproduces with the configuration it prints.
#![allow(dead_code)]

use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_core::family::{tables, Family};
use touchdown_eval::scoring::{score_frame, Expected, FrameScore};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::image_io::GrayFrame;
use touchdown_sim::render::{render_markers, Background, FrameOptions, MarkerPattern, Placement};

/// Clean, untilted markers at least this large must have corners within [`CLEAN_CORNER_PX`].
pub const LARGE_EDGE_PX: f64 = 32.0;
/// Corner error bound for clean, untilted, large markers.
pub const CLEAN_CORNER_PX: f32 = 0.5;
/// Corner error bound under moderate conditions.
pub const MODERATE_CORNER_PX: f32 = 1.0;
/// Pixels per cell (of the black-bordered square, along its shortest projected side) from
/// which a clean marker must be found: below 2 the cells alias into each other.
pub const MIN_PX_PER_CELL_CLEAN: f32 = 2.0;
/// Pixels per cell from which a marker under moderate blur, noise and tilt must be found.
pub const MIN_PX_PER_CELL_MODERATE: f32 = 3.0;

/// Imaging conditions of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    pub tilt_deg: f64,
    pub blur_sigma: f64,
    pub noise_sigma: f64,
    pub low_contrast: bool,
    pub textured: bool,
}

impl Condition {
    pub const CLEAN: Condition = Condition {
        tilt_deg: 0.0,
        blur_sigma: 0.0,
        noise_sigma: 0.0,
        low_contrast: false,
        textured: false,
    };

    pub fn is_clean(&self) -> bool {
        self.tilt_deg == 0.0
            && self.blur_sigma == 0.0
            && self.noise_sigma == 0.0
            && !self.low_contrast
    }

    /// Within what a landing camera sees on a good day: tilt up to 40 degrees, blur up to
    /// 0.8 px, noise up to 3 grey levels, full or low (90 -> 170) contrast.
    pub fn is_moderate(&self) -> bool {
        self.tilt_deg <= 40.0 && self.blur_sigma <= 0.8 && self.noise_sigma <= 3.0
    }

    pub fn label(&self) -> String {
        format!(
            "tilt {:.0} blur {:.1} noise {:.0} {}{}",
            self.tilt_deg,
            self.blur_sigma,
            self.noise_sigma,
            if self.low_contrast { "low" } else { "full" },
            if self.textured { " textured" } else { "" }
        )
    }
}

/// One rendered single-marker frame and what the detector made of it.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub family: &'static str,
    pub id: usize,
    pub edge_px: f64,
    pub rotation_deg: f64,
    pub tilt_axis_deg: f64,
    pub seed: u64,
    pub condition: Condition,
    /// Pixels per cell along the shortest projected side of the black-bordered square.
    pub px_per_cell: f32,
    pub score: FrameScore,
}

impl Outcome {
    pub fn corner_error(&self) -> Option<f32> {
        self.score.corner_errors.first().copied().flatten()
    }

    pub fn describe(&self) -> String {
        format!(
            "{} id {} edge {} px rotation {} axis {} seed {} {} ({:.2} px/cell)",
            self.family,
            self.id,
            self.edge_px,
            self.rotation_deg,
            self.tilt_axis_deg,
            self.seed,
            self.condition.label(),
            self.px_per_cell
        )
    }
}

/// Whether the marker of `o` must be found (see the module docs).
pub fn must_find(o: &Outcome) -> bool {
    (o.condition.is_clean() && o.px_per_cell >= MIN_PX_PER_CELL_CLEAN)
        || (o.condition.is_moderate() && o.px_per_cell >= MIN_PX_PER_CELL_MODERATE)
}

/// The corner bound that applies to `o`, if any.
pub fn corner_bound(o: &Outcome) -> Option<f32> {
    if o.condition.is_clean() && o.edge_px >= LARGE_EDGE_PX {
        Some(CLEAN_CORNER_PX)
    } else if o.condition.is_moderate() && o.px_per_cell >= MIN_PX_PER_CELL_MODERATE {
        Some(MODERATE_CORNER_PX)
    } else {
        None
    }
}

/// Every failure of a batch of outcomes, one line each.
pub fn failures(outcomes: &[Outcome]) -> Vec<String> {
    let mut out = Vec::new();
    for o in outcomes {
        for w in &o.score.wrong {
            out.push(format!("WRONG detection {w} on {}", o.describe()));
        }
        if o.score.duplicates > 0 {
            out.push(format!(
                "DUPLICATE detection ({}) on {}",
                o.score.duplicates,
                o.describe()
            ));
        }
        match o.corner_error() {
            None if must_find(o) => out.push(format!("MISSED {}", o.describe())),
            Some(e) if corner_bound(o).is_some_and(|b| e > b) => out.push(format!(
                "CORNERS off by {e:.2} px (bound {:.1}) on {}",
                corner_bound(o).unwrap_or(0.0),
                o.describe()
            )),
            _ => {}
        }
    }
    out
}

pub fn assert_no_failures(what: &str, outcomes: &[Outcome]) {
    let failed = failures(outcomes);
    assert!(
        failed.is_empty(),
        "{what}: {} failure(s) in {} frames:\n{}",
        failed.len(),
        outcomes.len(),
        failed.join("\n")
    );
}

/// The shipped families; fails loudly if the generated tables are missing.
pub fn families() -> &'static [&'static Family<'static>] {
    assert!(
        tables::ALL.len() >= 23,
        "expected the 23 shipped families, tables::ALL has {}",
        tables::ALL.len()
    );
    tables::ALL
}

/// The first, a middle and the last id, avoiding codes that equal one of their own rotations
/// (their orientation, hence their corner order, is ambiguous: aruco_original id 1023).
pub fn test_ids(family: &Family<'_>) -> [usize; 3] {
    let last = family.codes.len() - 1;
    let usable = |id: usize| {
        let code = family.codes[id];
        (1..4).all(|k| family.rotate_code(code, k) != code)
    };
    let pick = |mut id: usize| {
        while id > 0 && !usable(id) {
            id -= 1;
        }
        id
    };
    [pick(0), pick(last / 2), pick(last)]
}

/// A small deterministic hash for sub-pixel offsets and tilt axes.
pub fn mix(seed: u64) -> u64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

pub fn unit(seed: u64) -> f64 {
    (mix(seed) >> 11) as f64 / (1u64 << 53) as f64
}

pub fn frame_options(width: usize, height: usize, c: &Condition, seed: u64) -> FrameOptions {
    let (black, white, ground) = if c.low_contrast {
        (90.0, 170.0, 130.0)
    } else {
        (20.0, 235.0, 128.0)
    };
    FrameOptions {
        background: if c.textured {
            Background::Texture {
                mean: ground,
                amplitude: 0.6 * (white - black),
                scale_px: 48.0,
            }
        } else {
            Background::Flat(ground)
        },
        black,
        white,
        blur_sigma: c.blur_sigma,
        noise_sigma: c.noise_sigma,
        seed,
        ..FrameOptions::sized(width, height)
    }
}

/// Runs one detector on frames; holds the work memory.
pub struct Bench {
    detector: Detector,
    workspace: HostWorkspace,
}

impl Bench {
    pub fn new(config: DetectorConfig) -> Self {
        Bench {
            detector: Detector::new(config),
            workspace: HostWorkspace::new(),
        }
    }

    pub fn score(
        &mut self,
        frame: &GrayFrame,
        families: &[&Family<'_>],
        expected: &[Expected<'_>],
    ) -> FrameScore {
        let detections = self
            .workspace
            .detect(&mut self.detector, &frame.view(), families)
            .expect("detector accepts the frame and families");
        score_frame(&detections, families, expected)
    }

    /// Renders code `id` of `family` alone, at a sub-pixel position near the frame centre, and
    /// detects it searching `family` only.
    pub fn single(
        &mut self,
        family: &'static Family<'static>,
        id: usize,
        edge_px: f64,
        rotation_deg: f64,
        condition: Condition,
        seed: u64,
    ) -> Outcome {
        // The paper (quiet ring + 1 cell) spans about 1.6 edges; perspective enlarges the
        // near side of a tilted marker.
        let side = (edge_px * 2.2).ceil() as usize + 24;
        let tilt_axis_deg = (unit(seed ^ 0xa) * 180.0).round();
        let placement = Placement::new(
            side as f64 * 0.5 + unit(seed ^ 0xb) - 0.5,
            side as f64 * 0.5 + unit(seed ^ 0xc) - 0.5,
            edge_px,
        )
        .rotated(rotation_deg)
        .tilted(condition.tilt_deg, tilt_axis_deg);
        let pattern = MarkerPattern::from_code(family, id).expect("valid id");
        let cells = pattern.edge_cells() as f32;
        let rendered = render_markers(
            &[(pattern, placement)],
            &frame_options(side, side, &condition, seed),
        );
        let truth = rendered.truths[0];
        let expected = [Expected {
            family: family.name,
            id: id as u16,
            truth,
        }];
        let score = self.score(&rendered.frame, &[family], &expected);
        Outcome {
            family: family.name,
            id,
            edge_px,
            rotation_deg,
            tilt_axis_deg,
            seed,
            condition,
            px_per_cell: truth.min_side_px() / cells,
            score,
        }
    }
}

/// Prints found/total and the worst corner error per family and column.
pub fn print_table(
    title: &str,
    columns: &[String],
    outcomes: &[Outcome],
    column_of: impl Fn(&Outcome) -> usize,
) {
    println!("\n{title}");
    print!("{:<18}", "family");
    for c in columns {
        print!(" {c:>13}");
    }
    println!("   (found/frames worst-corner-px; wrong ids)");
    for family in families() {
        print!("{:<18}", family.name);
        let mine: Vec<&Outcome> = outcomes
            .iter()
            .filter(|o| o.family == family.name)
            .collect();
        for col in 0..columns.len() {
            let cell: Vec<&&Outcome> = mine.iter().filter(|o| column_of(o) == col).collect();
            let found = cell.iter().filter(|o| o.corner_error().is_some()).count();
            let worst = cell
                .iter()
                .filter_map(|o| o.corner_error())
                .fold(0.0f32, f32::max);
            let text = if cell.is_empty() {
                "-".to_string()
            } else if found == 0 {
                format!("0/{}", cell.len())
            } else {
                format!("{found}/{} {worst:.2}", cell.len())
            };
            print!(" {text:>13}");
        }
        let wrong: usize = mine.iter().map(|o| o.score.wrong.len()).sum();
        println!("   {wrong}");
    }
}
