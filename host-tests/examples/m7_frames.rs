//! Renders the typical landing frames of the Cortex-M7 benchmark (`bench/m7`) into
//! `bench/m7/frames/*.pgm`, and checks that the host detector finds every marker in them.
//!
//! ```text
//! cargo run --release -p touchdown-host-tests --example m7_frames [-- OUT_DIR]
//! ```
//!
//! The frames are deterministic (fixed placements and seeds), so re-running this rewrites
//! the same bytes unless the renderer changed. They are committed; the benchmark includes
//! them with `include_bytes!`. The adversarial frames (noise, checkerboard, small squares)
//! are not rendered here: the benchmark generates them itself at run time.
//!
//! | file | size | markers |
//! |---|---|---|
//! | `qvga-landing-1.pgm` | 320x240 | one tag36h11, 40 px, rotated and tilted |
//! | `qvga-multi-6.pgm` | 320x240 | three tag36h11 and three aruco_6x6_250, 16-56 px |
//! | `qvga-far-1.pgm` | 320x240 | one tag36h11, 14 px |
//! | `vga-landing-3.pgm` | 640x480 | two tag36h11 and one aruco_6x6_250, 40-96 px |
//!
//! All on a textured ground with a little blur and sensor noise.

use std::path::PathBuf;

use touchdown_core::detect::{buffer_sizes, Buffers, Detector, DetectorConfig};
use touchdown_core::family::{tables, Family};
use touchdown_formats::image_io::GrayFrame;
use touchdown_formats::pgm::save_pgm;
use touchdown_sim::render::{render_markers, Background, FrameOptions, MarkerPattern, Placement};

/// One benchmark frame: name, size, markers (family, id, placement), seed.
struct FrameSpec {
    name: &'static str,
    width: usize,
    height: usize,
    markers: Vec<(&'static Family<'static>, usize, Placement)>,
    seed: u64,
}

fn specs() -> Vec<FrameSpec> {
    let tag = &tables::TAG36H11;
    let aruco = &tables::ARUCO_6X6_250;
    vec![
        FrameSpec {
            name: "qvga-landing-1",
            width: 320,
            height: 240,
            markers: vec![(
                tag,
                7,
                Placement::new(171.3, 113.6, 40.0)
                    .rotated(17.0)
                    .tilted(12.0, 60.0),
            )],
            seed: 1,
        },
        FrameSpec {
            name: "qvga-multi-6",
            width: 320,
            height: 240,
            markers: vec![
                (tag, 0, Placement::new(62.4, 66.7, 56.0).rotated(8.0)),
                (tag, 1, Placement::new(160.2, 58.3, 32.0).rotated(-21.0)),
                (tag, 2, Placement::new(258.7, 61.1, 20.0).tilted(20.0, 10.0)),
                (aruco, 3, Placement::new(70.6, 175.2, 44.0).rotated(33.0)),
                (
                    aruco,
                    4,
                    Placement::new(165.3, 178.8, 26.0).tilted(15.0, 100.0),
                ),
                (aruco, 5, Placement::new(255.1, 172.4, 18.0).rotated(-5.0)),
            ],
            seed: 2,
        },
        FrameSpec {
            name: "qvga-far-1",
            width: 320,
            height: 240,
            markers: vec![(tag, 11, Placement::new(149.6, 127.3, 14.0).rotated(6.0))],
            seed: 3,
        },
        FrameSpec {
            name: "vga-landing-3",
            width: 640,
            height: 480,
            markers: vec![
                (
                    tag,
                    21,
                    Placement::new(300.4, 230.9, 96.0)
                        .rotated(-12.0)
                        .tilted(10.0, 45.0),
                ),
                (tag, 22, Placement::new(505.2, 110.7, 40.0).rotated(25.0)),
                (aruco, 9, Placement::new(140.8, 370.3, 64.0).rotated(3.0)),
            ],
            seed: 4,
        },
    ]
}

fn render(spec: &FrameSpec) -> GrayFrame {
    let markers: Vec<(MarkerPattern, Placement)> = spec
        .markers
        .iter()
        .map(|&(family, id, placement)| {
            let pattern = MarkerPattern::from_code(family, id).expect("id within the family");
            (pattern, placement)
        })
        .collect();
    let options = FrameOptions {
        background: Background::Texture {
            mean: 125.0,
            amplitude: 30.0,
            scale_px: 48.0,
        },
        blur_sigma: 0.6,
        noise_sigma: 2.0,
        seed: spec.seed,
        ..FrameOptions::sized(spec.width, spec.height)
    };
    render_markers(&markers, &options).frame
}

/// Detections of the default families (what the firmware searches) in `frame`.
fn detect_count(frame: &GrayFrame) -> usize {
    let sizes = buffer_sizes(frame.width, frame.height);
    let mut bitmap = vec![0u32; sizes.bitmap_words];
    let mut visited = vec![0u32; sizes.bitmap_words];
    let mut tiles = vec![0u8; sizes.tile_bytes];
    let mut buffers = Buffers {
        bitmap: &mut bitmap,
        visited: &mut visited,
        tiles: &mut tiles,
    };
    let mut detector = Detector::new(DetectorConfig::default());
    detector
        .detect(&frame.view(), tables::DEFAULT, &mut buffers)
        .map(|d| d.len())
        .unwrap_or(0)
}

fn main() {
    let out = std::env::args_os().nth(1).map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../bench/m7/frames"),
        PathBuf::from,
    );
    std::fs::create_dir_all(&out).expect("create the output directory");
    let mut missing = 0;
    for spec in specs() {
        let frame = render(&spec);
        let path = out.join(format!("{}.pgm", spec.name));
        save_pgm(&path, &frame).expect("write the frame");
        let found = detect_count(&frame);
        println!(
            "{}: {}x{}, {} marker(s), host detector finds {}",
            path.display(),
            spec.width,
            spec.height,
            spec.markers.len(),
            found
        );
        if found != spec.markers.len() {
            missing += 1;
        }
    }
    if missing > 0 {
        eprintln!("{missing} frame(s) where the detector does not find every marker");
        std::process::exit(1);
    }
}
