//! Host benchmarks (criterion) of the simulator's renderer on the frames `touchdown sitl`
//! renders in wall-clock time: the landing scenario's camera, pad and flight effects
//! (`touchdown_eval::closed_loop::scene`, issue 15's landing: VGA, rolling shutter, mount
//! vibration and misalignment), one frame at a time on one thread, as the closed loop runs
//! it:
//!
//! ```text
//! cargo bench -p touchdown-host-tests --bench render [-- FILTER]
//! ```
//!
//! Benches: `render/vga-landing-Hm`, one frame of the landing scenario's descent where the
//! camera is H metres over the ground (20, 5 and 1 m: the pad a small part of the image, a
//! large one, and filling it; a frame's cost follows how much of it shows the pad's edges
//! and how fine a footprint the ground's texture is evaluated at), and
//! `render/qvga-landing-5m`, the same at `touchdown sitl --qvga`'s 320x240.
//! `render/warp-vga-landing-Hm` and `render/warp-qvga-landing-5m`: the same frames through
//! the warp renderer (`Renderer::Warp`; its world is rasterised before the timing).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use touchdown_eval::closed_loop::{scene, LandingConfig};
use touchdown_sim::{Renderer, Simulator};

/// Camera heights over the ground the frames are rendered at, metres.
const HEIGHTS_M: [f64; 3] = [20.0, 5.0, 1.0];

/// The time at which the landing scenario's descent passes `height` metres (its flight only
/// goes down, so a bisection finds it).
fn time_at_height(simulator: &Simulator, height: f64) -> f64 {
    let trajectory = &simulator.scenario.trajectory;
    let (mut lo, mut hi) = (0.0, trajectory.end_time());
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if trajectory.state(mid).position[2] > height {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn landing(c: &mut Criterion) {
    for (qvga, heights) in [(false, &HEIGHTS_M[..]), (true, &HEIGHTS_M[1..2])] {
        let config = LandingConfig {
            qvga,
            ..LandingConfig::issue_15(1)
        };
        let simulator =
            Simulator::new(scene(&config).expect("the landing scene builds")).with_threads(1);
        let size = if qvga { "qvga" } else { "vga" };
        for &height in heights {
            let t_us = (time_at_height(&simulator, height) * 1e6).round() as u64;
            c.bench_function(&format!("render/{size}-landing-{height}m"), |b| {
                b.iter(|| black_box(simulator.render_at(black_box(t_us), 7)))
            });
        }
    }
    for (qvga, heights) in [(false, &HEIGHTS_M[..]), (true, &HEIGHTS_M[1..2])] {
        let config = LandingConfig {
            qvga,
            ..LandingConfig::issue_15(1)
        };
        let simulator = Simulator::new(scene(&config).expect("the landing scene builds"))
            .with_threads(1)
            .with_renderer(Renderer::Warp);
        let size = if qvga { "qvga" } else { "vga" };
        for &height in heights {
            let t_us = (time_at_height(&simulator, height) * 1e6).round() as u64;
            c.bench_function(&format!("render/warp-{size}-landing-{height}m"), |b| {
                b.iter(|| black_box(simulator.render_at(black_box(t_us), 7)))
            });
        }
    }
}

criterion_group!(benches, landing);
criterion_main!(benches);
