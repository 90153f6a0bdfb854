//! `touchdown detect`: find markers in image files (the contract's host CLI).
//!
//! One [`Detector`] and one [`HostWorkspace`] serve every image of a run, as on the camera
//! board, so the figures printed are those of a warm detector. With `--camera` the detector
//! is given the camera, as the board's per-frame path gives it its own: markers whose edges
//! the lens bends are fitted undistorted (touchdown's method only; the paper's stays as
//! published). `time_ms` is measured around
//! [`Detector::detect`] alone: decoding the file is not part of the detection time.

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Args, ValueEnum};
use serde::{Deserialize, Serialize};
use touchdown_core::camera::CameraModel;
use touchdown_core::detect::{DetectError, Detection, Detector, DetectorConfig, MAX_FAMILIES};
use touchdown_core::family::Family;
use touchdown_core::pose::{marker_pose, PoseMethod};

use super::{CliError, Outcome};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_formats::image_io::load_gray;

/// `touchdown detect --help`.
pub const LONG_HELP: &str = "\
Find fiducial markers in images and print their ids and corners.

IMAGE: PNG, PGM (P5) or JPEG; colour is converted to grey.

Families: without --family, tag36h11 and aruco_6x6_250 are searched. --family takes a
shipped family name (case does not matter):
  tag16h5 tag25h9 tag36h10 tag36h11 tagStandard41h12 aruco_original aruco_mip_36h12
  aruco_4x4_50 aruco_4x4_100 aruco_4x4_250 aruco_4x4_1000 aruco_5x5_50 aruco_5x5_100
  aruco_5x5_250 aruco_5x5_1000 aruco_6x6_50 aruco_6x6_100 aruco_6x6_250 aruco_6x6_1000
  aruco_7x7_50 aruco_7x7_100 aruco_7x7_250 aruco_7x7_1000
or the path of a family file: header lines `# key value`, then one code per line as the
full cell grid, row-major from the top-left, 1 = white, 0 = black. A custom 8x8 marker is
a one-line file. Repeat --family to search several families at once (at most 8).

Corners: the outer corners of the black border, ordered top-left, top-right, bottom-right,
bottom-left of the marker's canonical image (its code grid drawn with row 0 at the top;
OpenCV ArUco's order), in pixels with (0, 0) at the centre of the top-left pixel, x right,
y down. (AprilTag reports the same points starting bottom-left and going the other way,
with 0.5 added to x and y.)

Output: one line per marker and a summary. With --json, one JSON object per image, one
per line:
  {\"image\": \"a.png\", \"width\": 640, \"height\": 480, \"time_ms\": 1.23,
   \"detections\": [{\"family\": \"tag36h11\", \"id\": 7, \"hamming\": 0,
                   \"corners\": [[x,y],[x,y],[x,y],[x,y]],
                   \"pose\": {\"R\": [r00,r01,r02,r10,...,r22], \"t\": [x,y,z],
                            \"reprojection_px\": 0.12}}]}
time_ms is the detection (and pose) time only (not image decoding); hamming is the number
of bits the decoder corrected.

Camera and poses: with --camera CAMERA.toml the detector sees through the camera's lens:
it fits the outlines of large markers where their edges are straight again (undistorted),
which finds markers a wide-angle lens bends; the corners printed stay in the image's own
pixels either way. A marker whose size is known also gets \"pose\": with --tag-size M every
marker is taken to be M metres across its outer black border; with --pad pad.toml each
marker of the pad (same family and id) has its own size from the file, and without
--family the pad's families are searched (--tag-size then sizes the markers not on the
pad; the others get no pose). R (row-major) and t map marker-frame points into the camera
frame, X_cam = R X_marker + t (marker frame: x right, y up, z out of the printed face;
camera frame: x right, y down, z forward; metres), with the RMS reprojection error of the
corners in pixels. Corners are undistorted with the camera's Brown-Conrady coefficients;
the pose is IPPE's better planar solution refined by Levenberg-Marquardt.

Drawing: --draw OUT.png (one IMAGE) also writes the image as an RGB PNG with each marker
found outlined in green and a red dot on its first corner (top-left of its canonical
image): for looking at a detection, not for measuring it. --draw-scale N shrinks that
picture N times first (each pixel the mean of an NxN block), for a smaller file.

Exit status: 0 when every image was read (even with no marker found); 2 when an image could
not be read (one line per file on stderr; the other images are still processed) or an option
is wrong.";

/// Arguments of `touchdown detect`.
#[derive(Debug, Clone, Args)]
pub struct DetectArgs {
    /// Marker family to search: a shipped name or a family file; repeatable
    /// [default: tag36h11 and aruco_6x6_250]
    #[arg(long = "family", value_name = "NAME|FILE")]
    pub families: Vec<String>,

    /// Camera intrinsics (CAMERA.toml): the detector sees through its lens; poses with
    /// --tag-size or --pad
    #[arg(long, value_name = "CAMERA.toml")]
    pub camera: Option<PathBuf>,

    /// Marker size for poses: edge of the outer black border, metres; needs --camera
    #[arg(long, allow_negative_numbers = true, value_name = "M", value_parser = parse_tag_size)]
    pub tag_size: Option<f64>,

    /// Pad layout (pad.toml): each of its markers gets a pose at its own size, and without
    /// --family its families are searched; needs --camera
    #[arg(long, value_name = "pad.toml")]
    pub pad: Option<PathBuf>,

    /// Print one JSON object per image per line instead of text
    #[arg(long)]
    pub json: bool,

    /// Also write the image with the markers found outlined (green; a red dot on each
    /// marker's first corner) to OUT.png; needs exactly one IMAGE
    #[arg(long, value_name = "OUT.png")]
    pub draw: Option<PathBuf>,

    /// Shrink the --draw picture N times in each direction (each pixel the mean of an NxN
    /// block) before outlining: a smaller file for a web page
    #[arg(long, value_name = "N", default_value_t = 1, requires = "draw",
          value_parser = clap::value_parser!(u8).range(1..=8))]
    pub draw_scale: u8,

    /// Detection pipeline: touchdown's own (robust) or the paper's method (paper), kept to
    /// reproduce the paper's tables
    #[arg(long, value_enum, default_value_t = MethodArg::Robust, help_heading = "Advanced")]
    pub method: MethodArg,

    /// Image files (PNG, PGM, JPEG)
    #[arg(value_name = "IMAGE", required = true)]
    pub images: Vec<PathBuf>,
}

/// `--method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// touchdown's detector (local threshold, sub-pixel edges, error correction).
    Robust,
    /// The paper's pipeline with its fixed choices (exact template match, no refinement).
    Paper,
    /// touchdown's detector with the camera board's bound on the work per frame (what the
    /// board finds in the frame; `robust` searches a cluttered photo to the end).
    Board,
}

impl MethodArg {
    /// The detector settings this method stands for.
    pub fn config(self) -> DetectorConfig {
        match self {
            MethodArg::Robust => DetectorConfig::offline(),
            MethodArg::Paper => DetectorConfig::paper(),
            MethodArg::Board => DetectorConfig::default(),
        }
    }
}

fn parse_tag_size(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(size) if size.is_finite() && size > 0.0 => Ok(size),
        _ => Err("expected a positive length in metres, such as 0.16".to_string()),
    }
}

/// One image of `--json` output (the contract's keys, in its order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageReport {
    /// The path as given on the command line.
    pub image: String,
    /// Pixels.
    pub width: usize,
    /// Pixels.
    pub height: usize,
    /// Detection time, milliseconds (image decoding excluded).
    pub time_ms: f64,
    /// The markers found.
    pub detections: Vec<DetectionReport>,
}

/// One marker of `--json` output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectionReport {
    /// The family's name (a shipped name, or a family file's `# family` / file stem).
    pub family: String,
    /// The marker id within the family.
    pub id: u16,
    /// Bits corrected by the decoder.
    pub hamming: u8,
    /// Outer black-border corners: top-left, top-right, bottom-right, bottom-left of the
    /// canonical image, pixels, (0, 0) = centre of the top-left pixel.
    pub corners: [[f32; 2]; 4],
    /// The marker's pose: with `--camera`, for a marker whose size `--tag-size` or `--pad`
    /// gives.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<PoseReport>,
}

/// The `"pose"` of a detection (the contract's keys).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseReport {
    /// Rotation marker frame -> camera frame, row-major.
    #[serde(rename = "R")]
    pub rotation: [f32; 9],
    /// Marker centre in the camera frame, metres.
    pub t: [f32; 3],
    /// RMS reprojection error of the four corners, pixels.
    pub reprojection_px: f32,
}

/// The pose of one detection, or `None` when no pose explains its corners.
fn pose_report(detection: &Detection, camera: &CameraModel, size: f32) -> Option<PoseReport> {
    let found = marker_pose(&detection.corners, size, camera, PoseMethod::Ippe).ok()?;
    let pose = found.best.pose;
    Some(PoseReport {
        rotation: pose.rotation_row_major(),
        t: [pose.translation.x, pose.translation.y, pose.translation.z],
        reprojection_px: found.best.reprojection_rms_px,
    })
}

/// Counts for the closing summary line.
#[derive(Debug, Default)]
struct Totals {
    images: usize,
    markers: usize,
    unreadable: usize,
    detect_seconds: f64,
}

/// Runs `touchdown detect`.
pub fn run(
    args: &DetectArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    if args.draw.is_some() && args.images.len() != 1 {
        return Err(CliError::new("--draw needs exactly one IMAGE"));
    }
    let pose_setup = check_pose_options(args)?;
    let selected = searched_families(args)?;
    if selected.len() > MAX_FAMILIES {
        return Err(CliError(format!(
            "at most {MAX_FAMILIES} families can be searched at once ({} given)",
            selected.len()
        )));
    }

    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();
    let mut detector = Detector::new(args.method.config());
    // With --camera, touchdown's detector fits long boundaries through the lens, as the
    // board's per-frame path does (`FramePipeline`); the paper's method stays as published.
    if args.method == MethodArg::Robust {
        detector.set_camera(pose_setup.as_ref().map(|setup| setup.camera));
    }
    let mut workspace = HostWorkspace::new();
    let mut totals = Totals::default();

    for path in &args.images {
        let frame = match load_gray(path) {
            Ok(frame) => frame,
            Err(error) => {
                // Report and go on: the other images are still worth detecting.
                let _ = writeln!(err, "error: {}", CliError::new(error));
                totals.unreadable += 1;
                continue;
            }
        };
        let view = frame.view();
        let mut buffers = workspace.buffers(frame.width, frame.height);
        let started = Instant::now();
        let searched = detector
            .detect(&view, &family_refs, &mut buffers)
            .map(|_| ());
        let poses: Vec<Option<PoseReport>> = match &pose_setup {
            Some(setup) if searched.is_ok() => detector
                .detections()
                .iter()
                .map(|d| {
                    let size = setup.size_of(family_name(&selected, d), d.id)?;
                    pose_report(d, &setup.camera, size)
                })
                .collect(),
            _ => Vec::new(),
        };
        let elapsed = started.elapsed().as_secs_f64();
        searched.map_err(|e| CliError(format!("{}: {}", path.display(), describe(e))))?;
        let detections = detector.detections();
        if let Some(setup) = &pose_setup {
            let camera = &setup.camera;
            if (camera.width as usize, camera.height as usize) != (frame.width, frame.height) {
                let _ = writeln!(
                    err,
                    "warning: {}: image is {}x{} but the camera file is for {}x{}; the detection's lens model and the poses use the camera file as given",
                    path.display(),
                    frame.width,
                    frame.height,
                    camera.width,
                    camera.height
                );
            }
            // A marker of no known size has no pose by design; only a sized one is a failure.
            let sized = detections
                .iter()
                .filter(|d| setup.size_of(family_name(&selected, d), d.id).is_some())
                .count();
            let failed = sized.saturating_sub(poses.iter().flatten().count());
            if failed > 0 {
                let _ = writeln!(
                    err,
                    "warning: {}: no pose for {failed} marker(s) (degenerate corners or outside the lens model)",
                    path.display()
                );
            }
        }
        if let Some(draw) = &args.draw {
            let quads: Vec<[[f32; 2]; 4]> = detections
                .iter()
                .map(|d| d.corners.map(|p| [p.x, p.y]))
                .collect();
            crate::overlay::write_png(draw, &frame, &quads, usize::from(args.draw_scale))
                .map_err(|e| CliError(format!("cannot write the drawing: {e}")))?;
        }
        totals.images += 1;
        totals.markers += detections.len();
        totals.detect_seconds += elapsed;
        if detector.stats().truncated {
            let _ = writeln!(
                err,
                "warning: {}: search stopped early (step budget or capacity reached); markers may be missing",
                path.display()
            );
        }
        let written = if args.json {
            let report = image_report(
                path,
                frame.width,
                frame.height,
                elapsed,
                detections,
                &selected,
                &poses,
            );
            write_json_line(out, &report)
        } else {
            write_text(
                out,
                path,
                frame.width,
                frame.height,
                elapsed,
                detections,
                &selected,
                &poses,
            )
        };
        match written {
            Ok(()) => {}
            // The reader went away (`touchdown detect ... | head`): stop quietly.
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe => return Ok(Outcome::Success),
            Err(e) => return Err(CliError(format!("cannot write the output: {e}"))),
        }
    }

    if !args.json {
        let written = write_summary(out, &totals);
        if let Err(e) = written {
            if e.kind() != io::ErrorKind::BrokenPipe {
                return Err(CliError(format!("cannot write the output: {e}")));
            }
        }
    }
    Ok(if totals.unreadable == 0 {
        Outcome::Success
    } else {
        Outcome::PartialFailure
    })
}

/// What `--camera`, `--tag-size` and `--pad` ask for.
struct PoseSetup {
    camera: CameraModel,
    /// `--tag-size`: the size of every marker `--pad` does not size.
    tag_size: Option<f32>,
    /// `--pad`: (family name, id, size) of each of the pad's markers.
    pad_markers: Vec<(String, u16, f32)>,
}

impl PoseSetup {
    /// The size of a detected marker, if it is known.
    fn size_of(&self, family: &str, id: u16) -> Option<f32> {
        self.pad_markers
            .iter()
            .find(|(name, marker, _)| *marker == id && name.eq_ignore_ascii_case(family))
            .map(|&(_, _, size)| size)
            .or(self.tag_size)
    }
}

/// Checks `--camera`, `--tag-size` and `--pad` (the files in full, so a bad one is reported
/// as such): the sizes need the camera; the camera alone gives the detector its lens.
fn check_pose_options(args: &DetectArgs) -> Result<Option<PoseSetup>, CliError> {
    let Some(path) = &args.camera else {
        return match (args.tag_size, &args.pad) {
            (None, None) => Ok(None),
            (Some(_), _) => Err(CliError::new(
                "--tag-size needs --camera CAMERA.toml for poses",
            )),
            (None, Some(_)) => Err(CliError::new("--pad needs --camera CAMERA.toml for poses")),
        };
    };
    let camera = touchdown_formats::camera::load_camera(path).map_err(CliError::new)?;
    let pad_markers = match &args.pad {
        Some(pad) => touchdown_formats::pad::load_pad(pad)
            .map_err(CliError::new)?
            .markers
            .iter()
            .map(|m| (m.family.clone(), m.id, m.size as f32))
            .collect(),
        None => Vec::new(),
    };
    Ok(Some(PoseSetup {
        camera,
        tag_size: args.tag_size.map(|size| size as f32),
        pad_markers,
    }))
}

/// The families to search: `--family`, else the pad's (in its order), else the defaults.
fn searched_families(args: &DetectArgs) -> Result<Vec<SelectedFamily>, CliError> {
    let mut names = args.families.clone();
    if names.is_empty() && args.camera.is_some() {
        if let Some(pad) = &args.pad {
            for marker in touchdown_formats::pad::load_pad(pad)
                .map_err(CliError::new)?
                .markers
            {
                if !names.iter().any(|n| n.eq_ignore_ascii_case(&marker.family)) {
                    names.push(marker.family);
                }
            }
        }
    }
    families::resolve_all(&names).map_err(CliError::new)
}

fn describe(error: DetectError) -> &'static str {
    match error {
        DetectError::BuffersTooSmall => {
            "internal error: detector work memory too small for the image"
        }
        DetectError::BadFamilyCount => "between 1 and 8 families must be searched",
        DetectError::BadFamily => "a family's tables are inconsistent",
        DetectError::RegionOutsideImage => "the region searched lies outside the image",
    }
}

fn family_name<'a>(selected: &'a [SelectedFamily], detection: &Detection) -> &'a str {
    selected
        .get(usize::from(detection.family))
        .map(SelectedFamily::name)
        .unwrap_or("?")
}

/// Builds the JSON record of one image.
pub fn image_report(
    path: &Path,
    width: usize,
    height: usize,
    seconds: f64,
    detections: &[Detection],
    selected: &[SelectedFamily],
    poses: &[Option<PoseReport>],
) -> ImageReport {
    ImageReport {
        image: path.to_string_lossy().into_owned(),
        width,
        height,
        // Microsecond resolution is all Instant offers reliably; more digits are noise.
        time_ms: (seconds * 1e6).round() / 1e3,
        detections: detections
            .iter()
            .enumerate()
            .map(|(k, d)| DetectionReport {
                family: family_name(selected, d).to_string(),
                id: d.id,
                hamming: d.hamming,
                corners: d.corners.map(|p| [p.x, p.y]),
                pose: poses.get(k).copied().flatten(),
            })
            .collect(),
    }
}

fn write_json_line(out: &mut dyn Write, report: &ImageReport) -> io::Result<()> {
    serde_json::to_writer(&mut *out, report).map_err(io::Error::from)?;
    writeln!(out)?;
    // Flush per image so a consumer reading line by line sees each image as it is done.
    out.flush()
}

// One line per marker needs the image facts, the markers and their poses side by side.
#[allow(clippy::too_many_arguments)]
fn write_text(
    out: &mut dyn Write,
    path: &Path,
    width: usize,
    height: usize,
    seconds: f64,
    detections: &[Detection],
    selected: &[SelectedFamily],
    poses: &[Option<PoseReport>],
) -> io::Result<()> {
    let image = path.display();
    if detections.is_empty() {
        writeln!(
            out,
            "{image}: no markers ({width}x{height}, {:.2} ms)",
            seconds * 1e3
        )?;
    }
    for (k, d) in detections.iter().enumerate() {
        let [a, b, c, e] = d.corners;
        write!(
            out,
            "{image}: {} id {} hamming {} corners ({:.2}, {:.2}) ({:.2}, {:.2}) ({:.2}, {:.2}) ({:.2}, {:.2}) margin {:.2}",
            family_name(selected, d),
            d.id,
            d.hamming,
            a.x, a.y, b.x, b.y, c.x, c.y, e.x, e.y,
            d.decision_margin,
        )?;
        if let Some(pose) = poses.get(k).copied().flatten() {
            let [x, y, z] = pose.t;
            write!(
                out,
                " t ({x:.4}, {y:.4}, {z:.4}) m reprojection {:.2} px",
                pose.reprojection_px
            )?;
        }
        writeln!(out)?;
    }
    out.flush()
}

fn write_summary(out: &mut dyn Write, totals: &Totals) -> io::Result<()> {
    let plural = |n: usize, word: &str| format!("{n} {word}{}", if n == 1 { "" } else { "s" });
    let mut line = format!(
        "{}, {} found",
        plural(totals.images, "image"),
        plural(totals.markers, "marker")
    );
    if totals.images > 0 {
        line.push_str(&format!(
            ", detection {:.2} ms per image",
            totals.detect_seconds * 1e3 / totals.images as f64
        ));
    }
    if totals.unreadable > 0 {
        line.push_str(&format!(
            "; {} could not be read",
            plural(totals.unreadable, "image")
        ));
    }
    writeln!(out, "{line}")?;
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Cli;
    use clap::{CommandFactory, Parser};

    #[test]
    fn help_lists_every_shipped_family_and_the_defaults() {
        let mut command = Cli::command();
        let detect = command.find_subcommand_mut("detect").unwrap();
        let help = detect.render_long_help().to_string();
        for name in touchdown_core::family::tables::names() {
            assert!(help.contains(name), "help does not mention {name}");
        }
        assert!(help.contains("without --family, tag36h11 and aruco_6x6_250 are searched"));
    }

    #[test]
    fn parses_the_contract_command_line() {
        let cli = Cli::try_parse_from([
            "touchdown",
            "detect",
            "--family",
            "tag36h11",
            "--family",
            "x.txt",
            "--json",
            "a.png",
            "b.pgm",
        ])
        .unwrap();
        let crate::Command::Detect(args) = cli.command else {
            panic!("parsed as another subcommand");
        };
        assert_eq!(args.families, ["tag36h11", "x.txt"]);
        assert!(args.json);
        assert_eq!(args.images.len(), 2);
        assert_eq!(args.method, MethodArg::Robust);
        assert!(Cli::try_parse_from(["touchdown", "detect", "--tag-size", "-1", "a.png"]).is_err());
        assert!(Cli::try_parse_from(["touchdown", "detect", "--method", "paper", "a.png"]).is_ok());
        assert!(Cli::try_parse_from(["touchdown", "detect"]).is_err());
    }
}
