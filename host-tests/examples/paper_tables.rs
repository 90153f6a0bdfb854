//! The paper's Tables 2-4 reproduced in simulation: the published values, the paper's
//! method in our code, and ours (see `touchdown_eval` for what is compared and how,
//! and `eval::paper_geometry` for the simulated set-up).
//!
//!     cargo run --release -p touchdown-host-tests --example paper_tables [-- --frames N] [-- --seed S]

use std::time::Instant;

use touchdown_core::pipeline::PipelineConfig;
use touchdown_eval::paper_geometry::{self, Config};
use touchdown_eval::{Method, Stage};

fn main() {
    let mut config = Config {
        frames_per_set_point: 50,
        ..Config::default()
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let value = it.next().and_then(|v| v.parse::<u64>().ok());
        match (flag.as_str(), value) {
            ("--frames", Some(v)) => config.frames_per_set_point = v as usize,
            ("--seed", Some(v)) => config.seed = v,
            _ => {
                eprintln!("usage: paper_tables [--frames N] [--seed S]");
                std::process::exit(2);
            }
        }
    }
    let methods = [
        Method::paper().named("paper's method in our code"),
        Method::ours(),
        Method::board(
            "ours, 6-DOF pose (tilt from the image)",
            PipelineConfig {
                level_fix: false,
                ..PipelineConfig::default()
            },
        ),
        Method::ours()
            .without_attitude()
            .named("ours, vision only (no attitude)"),
    ];
    println!(
        "Simulated paper geometry: 1.0 m {} id 0 on textured ground, {}x{} camera, {}° HFOV \
         (f = {:.2} px), looking down; hover wander {} cm / {}°; noise {} grey levels, blur {} px; \
         {} settling + {} scored frames per set point at {} Hz, seed {}.",
        paper_geometry::FAMILY,
        paper_geometry::WIDTH,
        paper_geometry::HEIGHT,
        paper_geometry::HFOV_DEG,
        paper_geometry::focal_px(),
        100.0 * config.position_jitter_m,
        config.attitude_jitter_deg,
        config.noise_sigma,
        config.blur_sigma,
        config.settle_frames,
        config.frames_per_set_point,
        config.frame_rate_hz,
        config.seed
    );
    println!(
        "X = pad x, Y = pad y, Z = altitude (camera centre in the marker frame); error = truth - \
         estimate, cm; X rows offset along the image's 640-px axis, Y rows with the vehicle \
         turned 90° (also along the 640-px axis)."
    );
    let start = Instant::now();
    let report = match paper_geometry::run(&config, &methods) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("simulation failed: {e:?}");
            std::process::exit(1);
        }
    };
    let elapsed = start.elapsed();
    println!("\nFiltered estimates (what the paper averages):");
    print!("{}", report.table(Stage::Filtered));
    println!("\nRaw per-frame poses (before filtering):");
    print!("{}", report.table(Stage::Raw));
    println!("\n{:.1} s", elapsed.as_secs_f64());
}
