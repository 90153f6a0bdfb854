//! PX4 Precision Land in the closed-loop model, with and without the board's outer loop
//! (TD_PX4_OL_ALT): per seed, a start 10-12 m up and 1.5-3 m off the pad (as the SITL runs
//! of issue 37), a velocity-estimate error of the given size in a seeded direction, wind.
//!
//! `cargo run --release -p touchdown-eval --example px4_landing -- [SEEDS] [BIAS_MPS] [WIND_MPS]
//! [OL_ALT_M]` (defaults 8 seeds, 0.3 m/s, 0-6 m/s by seed, 15 m). One line per seed and
//! flight; QVGA, 60 degrees, 15 frames per second.

use nalgebra::Vector2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_eval::closed_loop::px4::Px4Params;
use touchdown_eval::closed_loop::{fly, Autopilot, LandingConfig, LandingOutcome};

fn config(seed: u64, bias: f64, wind: Option<f64>, ol_alt: f32) -> LandingConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7078_3437); // "px47"
    let bearing: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let height: f64 = rng.random_range(10.0..12.0);
    let offset: f64 = rng.random_range(1.5..3.0);
    let wind = wind.unwrap_or([0.0, 2.0, 4.0, 6.0][(seed % 4) as usize]);
    LandingConfig {
        start_height_m: height,
        offset_m: offset,
        wind_mps: wind,
        gust_mps: wind * 0.5,
        qvga: true,
        max_flight_s: 90.0,
        params: vec![("TD_PX4_OL_ALT".to_string(), ol_alt)],
        autopilot: Autopilot::Px4(Px4Params {
            velocity_bias_ne: Vector2::new(bias * bearing.cos(), bias * bearing.sin()),
            ..Px4Params::defaults()
        }),
        ..LandingConfig::issue_15(seed)
    }
}

fn line(label: &str, c: &LandingConfig, o: &LandingOutcome) -> String {
    let miss = o.touchdown.map_or("no touchdown".to_string(), |t| {
        format!(
            "miss {:5.1} cm (N {:+5.1}, E {:+5.1})",
            t.horizontal_m() * 100.0,
            t.north_m * 100.0,
            t.east_m * 100.0
        )
    });
    format!(
        "seed {:3} wind {:.0} m/s {label:>4}: {miss}; last target at {:.2} m, shift ({:+.2}, {:+.2}) m, descent at {}, lost {}",
        c.seed,
        c.wind_mps,
        o.last_target_height_m.unwrap_or(f64::NAN),
        o.last_shift_ne.0,
        o.last_shift_ne.1,
        o.low_s.map_or("-".into(), |t| format!("{t:.1} s")),
        o.lost_s.map_or("no".into(), |t| format!("at {t:.1} s")),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize| args.get(i).and_then(|a| a.parse::<f64>().ok());
    let seeds = arg(0).unwrap_or(8.0) as u64;
    let bias = arg(1).unwrap_or(0.3);
    let wind = arg(2);
    let ol_alt = arg(3).unwrap_or(15.0) as f32;
    let jobs: Vec<(u64, &str, f32)> = (1..=seeds)
        .flat_map(|s| [(s, "off", 0.0), (s, "on", ol_alt)])
        .collect();
    let results = std::sync::Mutex::new(Vec::new());
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                let Some(&(seed, label, alt)) = jobs.get(i) else {
                    break;
                };
                let c = config(seed, bias, wind, alt);
                let text = match fly(&c, &mut |_| Ok(())) {
                    Ok(o) => (line(label, &c, &o), o.touchdown.map(|t| t.horizontal_m())),
                    Err(e) => (format!("seed {seed} {label}: {e}"), None),
                };
                eprintln!("{}", text.0);
                results.lock().unwrap().push((i, label, text));
            });
        }
    });
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|r| r.0);
    println!("bias {bias} m/s, TD_PX4_OL_ALT {ol_alt} m");
    for (_, _, (text, _)) in &results {
        println!("{text}");
    }
    for label in ["off", "on"] {
        let mut m: Vec<f64> = results
            .iter()
            .filter(|r| r.1 == label)
            .map(|r| r.2 .1.unwrap_or(f64::INFINITY) * 100.0)
            .collect();
        m.sort_by(f64::total_cmp);
        println!(
            "{label:>4}: median {:.1} cm, worst {:.1} cm, within 5 cm {}/{}",
            m[m.len() / 2],
            m[m.len() - 1],
            m.iter().filter(|v| **v <= 5.0).count(),
            m.len()
        );
    }
}
