//! Recall, wrong ids and corner error by marker size, for touchdown's detector and the
//! paper's method, on rendered frames under a fixed mix of conditions.
//!
//! ```text
//! cargo run --release -p touchdown-host-tests --example recall_report -- \
//!     [--trials N] [--sizes 8,10,12,...] [--write DIR]
//! ```
//!
//! For each family and marker edge (pixels, outer black border) it renders `--trials` frames
//! (default 50), each with its own deterministic draw of id, sub-pixel position, in-plane
//! rotation (0-360 degrees), tilt (0-50 degrees about a random axis), blur (sigma 0-1 px),
//! noise (sigma 0-4 grey levels), contrast (70 %: ink 20 on paper 235; else 90 on 170) and
//! ground (30 % textured). Both methods see the same frames. A detection counts as found when
//! family, id and place match the rendered marker; anything else counts as a wrong id.
//!
//! `--sizes` replaces the default edge list (8, 10, 12, 14, 16, 20, 24, 32, 48 px).
//! `--write DIR` also saves the frames of the smallest size as PNG with a `truth.csv`
//! (contract corner order and pixel convention), so other detectors (OpenCV, AprilTag) can be
//! run on exactly the same frames.

use std::fmt::Write as _;
use std::path::PathBuf;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_core::family::{tables, Family};
use touchdown_eval::scoring::{score_frame, Expected};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::image_io::save_png;
use touchdown_sim::render::{
    render_markers, Background, FrameOptions, MarkerPattern, MarkerTruth, Placement,
};

const FAMILIES: [&str; 6] = [
    "tag36h11",
    "aruco_6x6_250",
    "aruco_4x4_50",
    "tag16h5",
    "tagStandard41h12",
    "aruco_7x7_250",
];
const SIZES: [f64; 9] = [8.0, 10.0, 12.0, 14.0, 16.0, 20.0, 24.0, 32.0, 48.0];

struct Args {
    trials: usize,
    sizes: Vec<f64>,
    write: Option<PathBuf>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        trials: 50,
        sizes: SIZES.to_vec(),
        write: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--trials" => {
                let value = it.next().ok_or("--trials needs a number")?;
                args.trials = value.parse().map_err(|_| format!("bad --trials {value}"))?;
            }
            "--sizes" => {
                let value = it.next().ok_or("--sizes needs a list like 8,12,16")?;
                args.sizes = value
                    .split(',')
                    .map(|v| v.trim().parse::<f64>().ok().filter(|&e| e >= 4.0))
                    .collect::<Option<Vec<f64>>>()
                    .ok_or(format!("bad --sizes {value} (edges of at least 4 px)"))?;
                args.sizes.sort_by(f64::total_cmp);
                if args.sizes.is_empty() {
                    return Err("--sizes needs at least one edge".to_string());
                }
            }
            "--write" => {
                args.write = Some(PathBuf::from(it.next().ok_or("--write needs a directory")?))
            }
            "--help" | "-h" => {
                return Err(
                    "usage: recall_report [--trials N] [--sizes 8,10,12] [--write DIR]".to_string(),
                );
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(args)
}

/// One drawn trial: everything needed to render (and to write the truth row).
struct Trial {
    id: usize,
    placement: Placement,
    options: FrameOptions,
}

fn draw_trial(family: &Family<'_>, edge_px: f64, seed: u64) -> Trial {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Codes equal to one of their own rotations have no defined corner order; skip them.
    let id = loop {
        let id = rng.random_range(0..family.codes.len());
        let code = family.codes[id];
        if (1..4).all(|k| family.rotate_code(code, k) != code) {
            break id;
        }
    };
    let side = (edge_px * 2.2).ceil() as usize + 24;
    let placement = Placement::new(
        side as f64 * 0.5 + rng.random_range(-0.5..0.5),
        side as f64 * 0.5 + rng.random_range(-0.5..0.5),
        edge_px,
    )
    .rotated(rng.random_range(0.0..360.0))
    .tilted(rng.random_range(0.0..50.0), rng.random_range(0.0..180.0));
    let low = rng.random_bool(0.3);
    let (black, white, ground) = if low {
        (90.0, 170.0, 130.0)
    } else {
        (20.0, 235.0, 128.0)
    };
    let background = if rng.random_bool(0.3) {
        Background::Texture {
            mean: ground,
            amplitude: 0.6 * (white - black),
            scale_px: 48.0,
        }
    } else {
        Background::Flat(ground)
    };
    let options = FrameOptions {
        background,
        black,
        white,
        blur_sigma: rng.random_range(0.0..1.0),
        noise_sigma: rng.random_range(0.0..4.0),
        seed: rng.random(),
        ..FrameOptions::sized(side, side)
    };
    Trial {
        id,
        placement,
        options,
    }
}

#[derive(Default)]
struct Tally {
    found: usize,
    wrong: usize,
    errors: Vec<f32>,
}

impl Tally {
    fn add(
        &mut self,
        detections: &[touchdown_core::detect::Detection],
        family: &Family<'_>,
        expected: &Expected<'_>,
    ) {
        let score = score_frame(detections, &[family], std::slice::from_ref(expected));
        self.wrong += score.wrong.len();
        if let Some(Some(e)) = score.corner_errors.first() {
            self.found += 1;
            self.errors.push(*e);
        }
    }

    fn quantile(&self, q: f64) -> Option<f32> {
        let mut e = self.errors.clone();
        e.sort_by(f32::total_cmp);
        let k = ((e.len() as f64 - 1.0) * q).round() as usize;
        e.get(k).copied()
    }

    fn cells(&self, trials: usize) -> String {
        let q = |v: Option<f32>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        format!(
            "{:>6.1} {:>5} {:>6} {:>6}",
            100.0 * self.found as f64 / trials as f64,
            self.wrong,
            q(self.quantile(0.5)),
            q(self.quantile(0.95))
        )
    }
}

fn truth_row(file: &str, family: &str, trial: &Trial, truth: &MarkerTruth) -> String {
    let p = &trial.placement;
    let o = &trial.options;
    let mut row = format!(
        "{file},{family},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{}",
        trial.id,
        p.edge_px,
        p.rotation_deg,
        p.tilt_deg,
        p.tilt_axis_deg,
        o.blur_sigma,
        o.noise_sigma,
        o.black < 50.0
    );
    for c in &truth.corners {
        let _ = write!(row, ",{:.4},{:.4}", c.x, c.y);
    }
    row
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let mut csv = String::from(
        "file,family,id,edge_px,rotation_deg,tilt_deg,tilt_axis_deg,blur_sigma,noise_sigma,full_contrast,\
         x0,y0,x1,y1,x2,y2,x3,y3\n",
    );
    if let Some(dir) = &args.write {
        if let Err(e) = std::fs::create_dir_all(dir) {
            eprintln!("cannot create {}: {e}", dir.display());
            std::process::exit(2);
        }
    }
    let mut robust = Detector::new(DetectorConfig::default());
    let mut paper = Detector::new(DetectorConfig::paper());
    let mut workspace = HostWorkspace::new();
    println!(
        "recall report: {} trials per cell; rotation 0-360, tilt 0-50 deg, blur 0-1 px, noise 0-4, 30 % low contrast, 30 % textured ground",
        args.trials
    );
    println!("recall %, wrong ids (count), corner error median / p95 (px, found markers)\n");
    println!(
        "{:<18} {:>5}  | {:>6} {:>5} {:>6} {:>6}  | {:>6} {:>5} {:>6} {:>6}",
        "family", "edge", "robust", "wrong", "med", "p95", "paper", "wrong", "med", "p95"
    );
    for (f, name) in FAMILIES.iter().enumerate() {
        let Some(family) = tables::by_name(name) else {
            eprintln!("family {name} is not shipped");
            std::process::exit(2);
        };
        for (s, &edge) in args.sizes.iter().enumerate() {
            let (mut ours, mut theirs) = (Tally::default(), Tally::default());
            for t in 0..args.trials {
                // From the edge itself, so a frame is the same whatever --sizes lists.
                let seed = ((f as u64) << 40) ^ (((edge * 100.0) as u64) << 20) ^ t as u64;
                let trial = draw_trial(family, edge, seed);
                let pattern =
                    MarkerPattern::from_code(family, trial.id).expect("drawn id is valid");
                let rendered = render_markers(&[(pattern, trial.placement)], &trial.options);
                let expected = Expected {
                    family: family.name,
                    id: trial.id as u16,
                    truth: rendered.truths[0],
                };
                let view = rendered.frame.view();
                match workspace.detect(&mut robust, &view, &[family]) {
                    Ok(d) => ours.add(&d, family, &expected),
                    Err(e) => eprintln!("robust detector error {e:?}"),
                }
                match workspace.detect(&mut paper, &view, &[family]) {
                    Ok(d) => theirs.add(&d, family, &expected),
                    Err(e) => eprintln!("paper detector error {e:?}"),
                }
                if let (Some(dir), 0) = (&args.write, s) {
                    let file = format!("{name}_{edge}px_{t:03}.png");
                    if let Err(e) = save_png(&dir.join(&file), &rendered.frame) {
                        eprintln!("{e}");
                        std::process::exit(2);
                    }
                    csv.push_str(&truth_row(&file, name, &trial, &rendered.truths[0]));
                    csv.push('\n');
                }
            }
            println!(
                "{:<18} {:>5}  | {}  | {}",
                name,
                edge,
                ours.cells(args.trials),
                theirs.cells(args.trials)
            );
        }
    }
    if let Some(dir) = &args.write {
        let path = dir.join("truth.csv");
        if let Err(e) = std::fs::write(&path, csv) {
            eprintln!("cannot write {}: {e}", path.display());
            std::process::exit(2);
        }
        println!(
            "\nwrote the {} px frames and truth.csv to {}",
            args.sizes[0],
            dir.display()
        );
    }
}
