//! The filter comparison: a simulated descent (1 m/s down from 30 m to 1 m, 0.5 m/s
//! drift, 30 Hz, range-dependent pose noise, dropped frames, outliers), scored for the raw
//! pose, the paper's filter (equations 8-14, Table 1) and ours.
//!
//!     cargo run -p touchdown-host --example descent [-- --wobble DEG] [-- --seed N]
//!
//! The scenario and the definitions of RMS and lag are in `tests/filter_sim/mod.rs`.

#[path = "../tests/filter_sim/mod.rs"]
mod filter_sim;

use filter_sim::{compare, SimConfig};

fn main() {
    let mut cfg = SimConfig::default();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let value = it.next().and_then(|v| v.parse::<f64>().ok());
        match (a.as_str(), value) {
            ("--wobble", Some(v)) => cfg.wobble_deg = v,
            ("--seed", Some(v)) => cfg.seed = v as u64,
            _ => {
                eprintln!("usage: descent [--wobble DEG] [--seed N]");
                std::process::exit(2);
            }
        }
    }
    println!(
        "Descent {:.0} m -> {:.0} m at {} m/s, drift {} m/s, {} Hz, roll/pitch wobble {}°, seed {}",
        cfg.start_altitude,
        cfg.end_altitude,
        cfg.descent_speed,
        cfg.drift_speed,
        cfg.rate_hz,
        cfg.wobble_deg,
        cfg.seed
    );
    println!(
        "pose noise: range sigma = {} px * d^2 / ({} px * {} m), cross-range sigma = {} px * d / {} px; \
         {:.0} % frames dropped + a burst of {}, {:.0} % outliers (3-8 m)",
        cfg.k_range_px,
        cfg.focal_px,
        cfg.marker_size_m,
        cfg.k_centre_px,
        cfg.focal_px,
        cfg.drop_probability * 100.0,
        cfg.burst.1,
        cfg.outlier_probability * 100.0
    );
    let c = compare(&cfg);
    print!("{}", c.table());
    println!(
        "ours / raw inliers RMS: {:.2}; paper / raw inliers RMS: {:.2}",
        c.ours.rms_total / c.raw_inliers.rms_total,
        c.paper.rms_total / c.raw_inliers.rms_total
    );
}
