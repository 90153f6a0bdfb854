//! Recordings: written and read back identical (truth bit for bit), read lazily, and every
//! damaged file reported in one line naming the file (and the line, for CSV files).

use std::path::{Path, PathBuf};

use touchdown_core::camera::CameraModel;
use touchdown_formats::image_io::GrayFrame;
use touchdown_formats::pad::{config_of_layout, PadConfig};
use touchdown_formats::recording::{
    frame_path, CameraTruth, RecordedFrame, Recording, RecordingError, RecordingReader,
};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("touchdown-rec-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn pad() -> PadConfig {
    config_of_layout(&touchdown_core::pad::designs::NESTED)
}

/// A small recording whose numbers are awkward to print: thirds, tiny and huge magnitudes,
/// negative zero, and floats that are not short decimals.
fn sample(has_truth: bool) -> Recording {
    let camera = CameraModel {
        distortion: [-0.123_456_79, 0.03, 0.000_5, -0.000_3, 1.0e-7],
        ..CameraModel::pinhole(48, 32, 554.256_3, 554.1, 23.5, 15.5)
    };
    let frames = (0..5)
        .map(|k| {
            let pixels = (0..48 * 32)
                .map(|i| ((i * 7 + k * 31) % 256) as u8)
                .collect();
            let third = 1.0 / 3.0 + k as f64;
            let q = [0.1f64, -0.7, 0.3 + k as f64 * 0.01, 0.2];
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            RecordedFrame {
                index: k,
                t_us: 1_000_000 + k as u64 * 33_333,
                truth: (has_truth && k != 2).then(|| CameraTruth {
                    position: [third, -1e-300 * k as f64, 0.1 + 0.2 + k as f64 * 1e17],
                    orientation: q.map(|v| v / n),
                }),
                vehicle_attitude: None,
                label: (k % 2 == 0).then(|| format!("z={}", k * 5)),
                image: GrayFrame {
                    width: 48,
                    height: 32,
                    pixels,
                },
            }
        })
        .collect();
    Recording {
        camera,
        pad: pad(),
        has_truth,
        frames,
    }
}

#[test]
fn written_and_read_back_identical() {
    for has_truth in [true, false] {
        let dir = scratch(&format!("identical-{has_truth}"));
        let original = sample(has_truth);
        original.write(&dir).unwrap();
        let back = Recording::read(&dir).unwrap();
        assert_eq!(back, original);
        // Bit for bit, not just ==: -0.0 == 0.0, so compare the bits of the truth too.
        for (a, b) in back.frames.iter().zip(&original.frames) {
            if let (Some(a), Some(b)) = (a.truth, b.truth) {
                for (x, y) in a
                    .position
                    .iter()
                    .chain(&a.orientation)
                    .zip(b.position.iter().chain(&b.orientation))
                {
                    assert_eq!(x.to_bits(), y.to_bits());
                }
            }
        }
        // Writing it again gives the same files.
        let again = scratch(&format!("identical-again-{has_truth}"));
        back.write(&again).unwrap();
        for name in ["camera.toml", "pad.toml", "frames.csv"] {
            assert_eq!(
                std::fs::read(dir.join(name)).unwrap(),
                std::fs::read(again.join(name)).unwrap(),
                "{name}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&again);
    }
}

#[test]
fn reader_is_lazy_and_in_order() {
    let dir = scratch("lazy");
    sample(true).write(&dir).unwrap();
    let reader = RecordingReader::open(&dir).unwrap();
    assert_eq!(reader.len(), 5);
    // Damage a frame after opening: only reading that frame fails.
    std::fs::write(frame_path(&dir, 3), b"P5\n48 32\n255\n").unwrap();
    let results: Vec<_> = reader.frames().collect();
    assert!(results[..3].iter().all(Result::is_ok));
    assert!(results[3].is_err());
    assert_eq!(results[4].as_ref().unwrap().index, 4);
    assert_eq!(results[2].as_ref().unwrap().truth, None);
    assert_eq!(results[4].as_ref().unwrap().label.as_deref(), Some("z=20"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Writes the sample, damages it with `damage`, and returns the error of reading it all.
fn broken(name: &str, damage: impl Fn(&Path)) -> (PathBuf, RecordingError) {
    let dir = scratch(name);
    sample(true).write(&dir).unwrap();
    damage(&dir);
    let e = Recording::read(&dir).unwrap_err();
    let text = e.to_string();
    assert!(!text.contains('\n'), "{text}");
    (dir, e)
}

fn rewrite_line(path: &Path, line: usize, text: &str) {
    let csv = std::fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    lines[line - 1] = text.to_string();
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

#[test]
fn truncated_frame_names_the_file() {
    let (dir, e) = broken("truncated", |dir| {
        let path = frame_path(dir, 1);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    });
    assert_eq!(e.path, frame_path(&dir, 1));
    let text = e.to_string();
    assert!(
        text.contains("000001.pgm") && text.contains("truncated"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_frame_header_and_size_name_the_file() {
    let (dir, e) = broken("header", |dir| {
        std::fs::write(frame_path(dir, 0), b"P2\n48 32\n255\n").unwrap();
    });
    assert!(
        e.to_string().contains("000000.pgm: not a binary PGM"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
    let (dir, e) = broken("size", |dir| {
        let mut bytes = b"P5\n32 48\n255\n".to_vec();
        bytes.extend(std::iter::repeat_n(0u8, 48 * 32));
        std::fs::write(frame_path(dir, 4), bytes).unwrap();
    });
    assert!(
        e.to_string()
            .contains("000004.pgm: frame is 32x48 but camera.toml says 48x32"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn corrupt_csv_names_file_and_line() {
    let cases: &[(&str, usize, &str, &str)] = &[
        (
            "number",
            3,
            "1,1033333,0.5,x,1,1,0,0,0",
            "cam_y: `x` is not a finite number",
        ),
        (
            "columns",
            4,
            "2,1066666,0.5",
            "expected 9 comma-separated columns, found 3",
        ),
        (
            "time",
            5,
            "3,1000000,,,,,,,",
            "is not after the previous frame",
        ),
        ("gap", 5, "4,1099999,,,,,,,", "index 4 where 3 was expected"),
        (
            "quaternion",
            2,
            "0,1000000,0,0,1,0.5,0,0,0",
            "unit quaternion",
        ),
        ("header", 1, "index,time", "header `index,time`"),
    ];
    for &(name, line, text, reason) in cases {
        let (dir, e) = broken(name, |dir| {
            rewrite_line(&dir.join("frames.csv"), line, text)
        });
        assert_eq!(e.path, dir.join("frames.csv"), "{name}");
        assert_eq!(e.line, Some(line), "{name}: {e}");
        assert!(e.to_string().contains(reason), "{name}: {e}");
        assert!(
            e.to_string()
                .contains(&format!("frames.csv: line {line}: ")),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn truncated_csv_names_the_last_line() {
    let (dir, e) = broken("truncated-csv", |dir| {
        let path = dir.join("frames.csv");
        let csv = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, &csv[..csv.len() - 60]).unwrap();
    });
    assert_eq!(e.line, Some(6), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_frame_file_names_file_and_csv_line() {
    let (dir, e) = broken("missing", |dir| {
        std::fs::remove_file(frame_path(dir, 2)).unwrap()
    });
    assert_eq!(e.path, frame_path(&dir, 2));
    assert!(
        e.to_string().contains("frames.csv line 4 lists frame 2"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_configuration_and_labels_name_the_file() {
    let (dir, e) = broken("camera", |dir| {
        std::fs::write(
            dir.join("camera.toml"),
            "width = 48\nheight = 32\nfx = -1\nfy = 1\ncx = 1\ncy = 1\n",
        )
        .unwrap()
    });
    assert!(e.to_string().contains("camera.toml: line 3: fx"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
    let (dir, e) = broken("pad", |dir| {
        std::fs::remove_file(dir.join("pad.toml")).unwrap()
    });
    assert!(e.to_string().contains("pad.toml"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
    let (dir, e) = broken("labels", |dir| {
        std::fs::write(dir.join("setpoints.csv"), "index,label\n0,z=0\n9,z=9\n").unwrap()
    });
    assert!(
        e.to_string()
            .contains("setpoints.csv: line 3: frame 9 is not in frames.csv"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
    let e = Recording::read(Path::new("/nonexistent/recording")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/recording"), "{e}");
}
