//! `touchdown calibrate-lens`: a camera's intrinsics and distortion from views of the printed
//! pad, written as a CAMERA.toml.
//!
//! Why it exists: a builder who screws an M12 lens onto the camera board needs that lens's
//! focal length (a 3 % focal error is a 3 % range error) and its distortion (the detector's
//! lens-aware mode and every pose use it). The pad the vehicle lands on is already a known
//! planar target: every decoded marker gives four corners whose pad positions `pad.toml`
//! states, so no chessboard is needed.
//!
//! The method: the project's detector finds the markers; each id is matched to its layout
//! marker (corners in the detector's order, top-left, top-right, bottom-right, bottom-left of
//! the canonical image, which are the marker-frame points (-s/2, s/2), (s/2, s/2),
//! (s/2, -s/2), (-s/2, -s/2) placed by `PadMarker::to_pad`); [`crate::lens_fit`] does the
//! homographies, Zhang's start and the least-squares fit. Markers whose corners stay far off
//! the fitted model (a misread corner, a marker half in shadow) are dropped and the fit
//! repeated. With a distorting lens found, every used frame is searched again with the
//! detector given that lens (its lens-aware mode fits bent marker edges where they are
//! straight), which moves the corners of wide lenses' border markers by up to a pixel, and the
//! fit is repeated from the first one.
//!
//! A recording's camera.toml, when it has one, gives the line time only: its intrinsics are
//! what is being measured, so they are never used. Nothing the user gave is written to: `--out` must be new
//! unless `--force`.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use nalgebra::Vector3;
use serde::Serialize;
use touchdown_core::camera::CameraModel;
use touchdown_core::detect::{Detector, DetectorConfig, MAX_FAMILIES};
use touchdown_core::family::Family;
use touchdown_core::geometry::Point;
use touchdown_core::pad::PadLayout;

use super::lens_fit::{self, FreeTerms, Intrinsics, Pose, View};
use super::{CliError, Outcome};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_formats::image_io::{load_gray, GrayFrame};
use touchdown_formats::pad::PadConfig;
use touchdown_formats::recording::{frame_path, parse_frames_csv_columns};

/// A view is usable with at least this many of the pad's markers (8 corners: a homography
/// from 4 would fit any four points exactly and say nothing about the lens).
pub const MIN_VIEW_MARKERS: usize = 2;
/// Fewest usable views the fit runs on.
pub const MIN_VIEWS: usize = 3;
/// Views the advice asks for: with fewer, k1 and the focal length are not pinned down to the
/// 0.3 % the pose needs.
pub const ADVISED_VIEWS: usize = 15;
/// Largest angle between the pad's normals in two views the advice asks for, degrees: the
/// focal length is measured through perspective, which a pad seen head-on hardly shows.
pub const ADVISED_TILT_SPAN_DEG: f64 = 40.0;
/// A ninth of the image with fewer than this share of the corners counts as not covered.
pub const ADVISED_NINTH_SHARE: f64 = 0.01;
/// A marker is dropped when its corners' RMS residual exceeds this many times the median
/// marker's...
pub const OUTLIER_FACTOR: f64 = 5.0;
/// ...and this many pixels.
pub const OUTLIER_FLOOR_PX: f64 = 1.0;
/// Rounds of dropping outliers and fitting again.
pub const OUTLIER_ROUNDS: usize = 5;

/// `--help`'s long text.
pub const LONG_HELP: &str = "\
Estimate a camera's intrinsics (fx, fy, cx, cy) and Brown-Conrady distortion [k1, k2, p1, \
p2, k3] (OpenCV's order) from views of the printed pad, and write them as a CAMERA.toml.

Inputs: recording directories (frames.csv and frames/; pad.toml and camera.toml if \
present, of which only the line time is used, never the intrinsics) and/or image files (PNG, \
PGM, JPEG; colour is converted to grey), all of one size. The pad layout is --pad, else the \
first recording's pad.toml. \
Every pad marker found gives its four corners; a view is usable with at least 2 of the \
pad's markers, and at most --max-views usable views are used (evenly spaced).

How to take the views: 15 to 30 sharp pictures of the pad, flat, filling a good part of the \
frame, tilted 20 to 45 degrees in different directions, and moved so that over all pictures \
markers reach every corner and edge of the image (the distortion is largest there).

Method: a homography per view, Zhang's closed-form start (zero skew), then \
Levenberg-Marquardt over the intrinsics, the distortion and every view's pose, minimising \
the corners' pixel reprojection error; markers whose corners stay far off the fit (over 5 \
times the median marker's RMS and 1 px) are dropped and the fit repeated. With a distorting \
lens found, the frames are searched again with the detector looking through that lens, and \
the fit repeated. k3 is held at 0 unless --k3: with a few views it trades against k1.

Coverage advice, printed after the result (it does not change the exit status):
  more views: N of at least 15
  tilt the pad more: views span N degrees, want at least 40 (the largest angle between the \
pad's normals in two views; the focal length is measured through perspective)
  fill the corners: no corners in the top-left ninth of the image (the image cut in 3 x 3; \
a ninth with under 1 % of the corners counts as empty)

Output: the camera, one-sigma uncertainties, the horizontal field of view (of the distorted \
image: between the outer edges of the middle row's first and last pixels), the RMS \
reprojection error and the worst view's, the coverage and the advice; then the camera file, \
which --out FILE writes instead (a file that exists needs --force). With --json one object: \
camera {width, height, fx, fy, cx, cy, distortion, line_time_us}, sigma {fx, fy, cx, cy, \
distortion}, hfov_deg, rms_px, worst_view {source, rms_px}, frames, usable_views, views \
(each: source, markers, rms_px, worst_px, tilt_deg), corners, rejected_markers, passes, \
coverage {views, tilt_span_deg, max_tilt_deg, ninths (corner counts, rows top to bottom)}, \
advice, out, camera_toml.

Exit status: 0 with a camera; 2 with one line on stderr for a bad option, an unreadable \
image or recording, no pad layout, images of different sizes, too few usable views, an \
existing --out without --force, or a fit that does not converge or folds over inside the \
image.";

/// Arguments of `touchdown calibrate-lens`.
#[derive(Debug, Clone, Args)]
pub struct CalibrateLensArgs {
    /// Recording directories and/or image files (PNG, PGM, JPEG), all of one size
    #[arg(value_name = "RECORDING|IMAGE", required = true)]
    pub inputs: Vec<PathBuf>,

    /// Pad layout (pad.toml) [default: the first recording's pad.toml]
    #[arg(long, value_name = "pad.toml")]
    pub pad: Option<PathBuf>,

    /// Write the camera file here instead of printing it
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,

    /// Replace an existing --out
    #[arg(long, requires = "out")]
    pub force: bool,

    /// Print one JSON object instead of text
    #[arg(long)]
    pub json: bool,

    /// Rolling-shutter line time for the camera file, microseconds [default: the first
    /// recording's camera.toml's, else 0]
    #[arg(long, value_name = "US", allow_negative_numbers = true)]
    pub line_time_us: Option<f32>,

    /// Also fit k3 (only with many views reaching the image's corners)
    #[arg(long)]
    pub k3: bool,

    /// Most usable views fitted (evenly spaced over the inputs)
    #[arg(long, value_name = "N", default_value_t = 60,
          value_parser = clap::value_parser!(u16).range(3..=400))]
    pub max_views: u16,
}

/// One frame's pad markers: layout index and the four corners, pixels.
#[derive(Debug, Clone)]
struct Observation {
    frame: usize,
    markers: Vec<(usize, [[f64; 2]; 4])>,
}

/// A recording's files besides its frames, each optional here: a recording made to calibrate
/// a new lens may have no camera.toml yet, and `--pad` may stand in for its pad.toml.
struct RecordingFiles {
    pad: Option<PadConfig>,
    line_time_us: Option<f32>,
    /// Sensor pixels per recorded pixel, when the recording is `touchdown view --record`'s
    /// (board.csv's `scale`): the board's parameters are in its own frames' pixels.
    board_scale: Option<u8>,
}

/// The scale of a `touchdown view` recording's frames (board.csv's `scale`, one for all its
/// rows); `None` for a recording without board.csv.
fn board_scale(dir: &Path) -> Result<Option<u8>, CliError> {
    let path = dir.join("board.csv");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(None);
    };
    let bad = |why: &str| CliError(format!("{}: {why}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let column = header
        .iter()
        .position(|&c| c == "scale")
        .ok_or_else(|| bad("no `scale` column"))?;
    let mut scale = None;
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let value: u8 = line
            .split(',')
            .nth(column)
            .and_then(|v| v.trim().parse().ok())
            .filter(|v| matches!(v, 1 | 2))
            .ok_or_else(|| bad("a `scale` that is not 1 or 2"))?;
        if scale.is_some_and(|s| s != value) {
            return Err(bad("frames of two scales: record again at one"));
        }
        scale = Some(value);
    }
    Ok(scale)
}

/// Everything the frames are read with: each frame is an image file (a recording's frames
/// are its `frames/NNNNNN.pgm` in frames.csv's order).
struct Inputs {
    names: Vec<String>,
    paths: Vec<PathBuf>,
    recordings: Vec<RecordingFiles>,
    size: Option<(usize, usize)>,
}

impl Inputs {
    /// Adds a recording's frames; its pad.toml and camera.toml's line time when present.
    fn add_recording(&mut self, dir: &Path) -> Result<(), CliError> {
        let csv = dir.join("frames.csv");
        let text = std::fs::read_to_string(&csv).map_err(|e| {
            CliError(format!(
                "{}: not a recording (frames.csv: {e})",
                dir.display()
            ))
        })?;
        let (_, entries) = parse_frames_csv_columns(&text).map_err(|(line, reason)| {
            CliError(format!("{}: line {line}: {reason}", csv.display()))
        })?;
        let camera = dir.join("camera.toml");
        let line_time_us = if camera.exists() {
            Some(
                touchdown_formats::camera::load_camera(&camera)
                    .map_err(CliError::new)?
                    .line_time_us,
            )
        } else {
            None
        };
        let pad_path = dir.join("pad.toml");
        let pad = if pad_path.exists() {
            Some(touchdown_formats::pad::load_pad(&pad_path).map_err(CliError::new)?)
        } else {
            None
        };
        for entry in &entries {
            let path = frame_path(dir, entry.index);
            self.names.push(path.display().to_string());
            self.paths.push(path);
        }
        let board_scale = board_scale(dir)?;
        self.recordings.push(RecordingFiles {
            pad,
            line_time_us,
            board_scale,
        });
        Ok(())
    }

    fn load(&mut self, frame: usize) -> Result<GrayFrame, CliError> {
        let image = load_gray(&self.paths[frame]).map_err(CliError::new)?;
        match self.size {
            None => self.size = Some((image.width, image.height)),
            Some((w, h)) if (w, h) != (image.width, image.height) => {
                return Err(CliError(format!(
                    "{}: the image is {}x{}, the first one {w}x{h}: a calibration is for one \
                     image size",
                    self.names[frame], image.width, image.height
                )));
            }
            Some(_) => {}
        }
        Ok(image)
    }
}

/// The detector and what it searches for.
struct Search<'a> {
    detector: Detector,
    workspace: HostWorkspace,
    selected: &'a [SelectedFamily],
    layout: &'a PadLayout<'a>,
}

impl Search<'_> {
    /// The pad markers of one frame (a marker found twice in one frame is dropped: which one
    /// is the pad's cannot be told).
    fn observe(
        &mut self,
        frame: usize,
        image: &GrayFrame,
        name: &str,
    ) -> Result<Observation, CliError> {
        let views: Vec<Family<'_>> = self.selected.iter().map(SelectedFamily::family).collect();
        let refs: Vec<&Family<'_>> = views.iter().collect();
        let view = image.view();
        let mut buffers = self.workspace.buffers(image.width, image.height);
        let detections = self
            .detector
            .detect(&view, &refs, &mut buffers)
            .map_err(|e| CliError(format!("{name}: the detector refused the image: {e:?}")))?;
        let mut markers: Vec<(usize, [[f64; 2]; 4])> = Vec::new();
        let mut twice: Vec<usize> = Vec::new();
        for d in detections {
            let Some(family) = self.selected.get(usize::from(d.family)) else {
                continue;
            };
            let Some(index) = self
                .layout
                .markers()
                .iter()
                .position(|m| m.id == d.id && m.family.eq_ignore_ascii_case(family.name()))
            else {
                continue;
            };
            if markers.iter().any(|(k, _)| *k == index) {
                twice.push(index);
            }
            markers.push((index, d.corners.map(|p| [f64::from(p.x), f64::from(p.y)])));
        }
        markers.retain(|(k, _)| !twice.contains(k));
        Ok(Observation { frame, markers })
    }
}

/// The pad-frame corners (x, y) of layout marker `index`, in the detector's order.
pub fn marker_corners(layout: &PadLayout<'_>, index: usize) -> Option<[[f64; 2]; 4]> {
    let m = layout.markers().get(index)?;
    let h = 0.5 * m.size;
    Some([(-h, h), (h, h), (h, -h), (-h, -h)].map(|(x, y)| {
        let p = m.to_pad(&Vector3::new(x, y, 0.0));
        [f64::from(p.x), f64::from(p.y)]
    }))
}

/// A fit and the observations it kept.
struct Solved {
    fit: lens_fit::Fit,
    kept: Vec<Observation>,
    rejected: usize,
}

fn views_of(layout: &PadLayout<'_>, observations: &[Observation]) -> Vec<View> {
    observations
        .iter()
        .map(|o| {
            let mut view = View::default();
            for (index, corners) in &o.markers {
                if let Some(object) = marker_corners(layout, *index) {
                    view.object.extend_from_slice(&object);
                    view.image.extend_from_slice(corners);
                }
            }
            view
        })
        .collect()
}

/// Fits, drops the markers far off the fit, fits again (from the last fit) until none is.
/// `start`: the camera and the poses of earlier views (by frame) to start from; without one,
/// Zhang's start.
fn solve(
    layout: &PadLayout<'_>,
    mut observations: Vec<Observation>,
    start: Option<(Intrinsics, &[(usize, Pose)])>,
    free: FreeTerms,
    size: (usize, usize),
) -> Result<Solved, CliError> {
    let (width, height) = (size.0 as f64, size.1 as f64);
    let not_converged = |why: &str| {
        CliError(format!(
            "the lens fit did not converge ({why}): take more views, tilted more, with the pad \
             sharp and flat"
        ))
    };
    let mut views = views_of(layout, &observations);
    let homographies: Vec<_> = views
        .iter()
        .map(|v| lens_fit::homography(&v.object, &v.image))
        .collect();
    let camera = match start {
        Some((camera, _)) => camera,
        None => {
            let hs: Vec<_> = homographies.iter().flatten().copied().collect();
            lens_fit::initial_intrinsics(&hs, width, height)
                .ok_or_else(|| not_converged("no focal length fits the views' perspective"))?
        }
    };
    let mut poses = Vec::new();
    for (o, h) in observations.iter().zip(&homographies) {
        let earlier = start.and_then(|(_, poses)| {
            poses
                .iter()
                .find(|(frame, _)| *frame == o.frame)
                .map(|p| p.1)
        });
        let pose = earlier
            .or_else(|| h.as_ref().and_then(|h| lens_fit::initial_pose(h, &camera)))
            .ok_or_else(|| not_converged("a view's markers are degenerate"))?;
        poses.push(pose);
    }
    let mut rejected = 0;
    let mut fit =
        lens_fit::fit(&views, camera, poses, free).map_err(|e| not_converged(&format!("{e:?}")))?;
    for _ in 0..OUTLIER_ROUNDS {
        // Per marker: RMS of its four corners' residuals.
        let mut marker_rms: Vec<Vec<f64>> = Vec::new();
        for residuals in &fit.residuals {
            marker_rms.push(
                residuals
                    .chunks(4)
                    .map(|c| {
                        (c.iter().map(|r| r[0] * r[0] + r[1] * r[1]).sum::<f64>() / 4.0).sqrt()
                    })
                    .collect(),
            );
        }
        let mut all: Vec<f64> = marker_rms.iter().flatten().copied().collect();
        all.sort_by(f64::total_cmp);
        let median = all.get(all.len() / 2).copied().unwrap_or(0.0);
        let threshold = (OUTLIER_FACTOR * median).max(OUTLIER_FLOOR_PX);
        let mut dropped = 0;
        let mut next_obs = Vec::new();
        let mut next_poses = Vec::new();
        for ((o, rms), pose) in observations.iter().zip(&marker_rms).zip(&fit.poses) {
            let markers: Vec<_> = o
                .markers
                .iter()
                .zip(rms)
                .filter(|(_, &r)| r <= threshold)
                .map(|(m, _)| *m)
                .collect();
            dropped += o.markers.len() - markers.len();
            if markers.len() >= MIN_VIEW_MARKERS {
                next_obs.push(Observation {
                    frame: o.frame,
                    markers,
                });
                next_poses.push(*pose);
            } else {
                dropped += markers.len();
            }
        }
        if dropped == 0 {
            break;
        }
        rejected += dropped;
        if next_obs.len() < MIN_VIEWS {
            return Err(CliError(format!(
                "too few usable views: {} keep at least {MIN_VIEW_MARKERS} pad markers that \
                 agree with the fit; need at least {MIN_VIEWS}",
                next_obs.len()
            )));
        }
        observations = next_obs;
        views = views_of(layout, &observations);
        fit = lens_fit::fit(&views, fit.intrinsics, next_poses, free)
            .map_err(|e| not_converged(&format!("{e:?}")))?;
    }
    Ok(Solved {
        fit,
        kept: observations,
        rejected,
    })
}

/// `--json`'s uncertainties.
#[derive(Debug, Serialize)]
struct Sigma {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    distortion: [f64; 5],
}

/// `--json`'s camera.
#[derive(Debug, Serialize)]
struct CameraReport {
    width: u32,
    height: u32,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    distortion: [f32; 5],
    line_time_us: f32,
}

/// One used view.
#[derive(Debug, Serialize)]
struct ViewReport {
    source: String,
    markers: usize,
    rms_px: f64,
    worst_px: f64,
    tilt_deg: f64,
}

/// The worst view.
#[derive(Debug, Serialize)]
struct WorstView {
    source: String,
    rms_px: f64,
}

/// What the views cover.
#[derive(Debug, Serialize)]
struct Coverage {
    views: usize,
    tilt_span_deg: f64,
    max_tilt_deg: f64,
    ninths: [[usize; 3]; 3],
}

/// `--json`'s object (see [`LONG_HELP`]).
#[derive(Debug, Serialize)]
struct Report {
    camera: CameraReport,
    sigma: Sigma,
    hfov_deg: f64,
    rms_px: f64,
    worst_view: WorstView,
    frames: usize,
    usable_views: usize,
    views: Vec<ViewReport>,
    corners: usize,
    rejected_markers: usize,
    passes: usize,
    coverage: Coverage,
    advice: Vec<String>,
    out: Option<String>,
    camera_toml: String,
    board: Option<BoardParameters>,
}

/// The lens as the board's parameters (TD_CAM_*), in the pixels of its own frames: the
/// calibration scaled back by the recording's scale when it came from `touchdown view
/// --record` of halved frames.
#[derive(Debug, Serialize)]
struct BoardParameters {
    /// The board's frame size the values are for.
    width: u32,
    height: u32,
    /// `(name, value)` in the parameter table's order.
    parameters: Vec<(String, f64)>,
}

impl BoardParameters {
    fn new(camera: &CameraModel, scale: u8) -> Self {
        let (width, height) = (
            camera.width * u32::from(scale),
            camera.height * u32::from(scale),
        );
        let board = camera.resampled(f32::from(scale), width, height);
        BoardParameters {
            width,
            height,
            parameters: crate::board::lens_parameters(&board)
                .iter()
                .map(|&(id, value)| (id.def().name.to_string(), f64::from(value)))
                .collect(),
        }
    }
}

/// The names of the image's ninths, rows top to bottom.
const NINTHS: [[&str; 3]; 3] = [
    ["top-left", "top", "top-right"],
    ["left", "centre", "right"],
    ["bottom-left", "bottom", "bottom-right"],
];

/// Runs `touchdown calibrate-lens`.
pub fn run(
    args: &CalibrateLensArgs,
    out: &mut dyn Write,
    _err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    if let Some(t) = args.line_time_us {
        if !(t.is_finite() && t >= 0.0) {
            return Err(CliError::new("--line-time-us must be a number >= 0"));
        }
    }
    if let Some(path) = &args.out {
        if path.exists() && !args.force {
            return Err(CliError(format!(
                "{}: exists; give --force to replace it",
                path.display()
            )));
        }
        if path.is_dir() {
            return Err(CliError(format!("{}: is a directory", path.display())));
        }
    }
    let mut inputs = Inputs {
        names: Vec::new(),
        paths: Vec::new(),
        recordings: Vec::new(),
        size: None,
    };
    for path in &args.inputs {
        if path.is_dir() {
            inputs.add_recording(path)?;
        } else {
            inputs.names.push(path.display().to_string());
            inputs.paths.push(path.clone());
        }
    }
    let recorded_pad = inputs.recordings.iter().find_map(|r| r.pad.clone());
    let pad: PadConfig =
        match (&args.pad, recorded_pad) {
            (Some(path), _) => touchdown_formats::pad::load_pad(path).map_err(CliError::new)?,
            (None, Some(pad)) => pad,
            (None, None) => return Err(CliError::new(
                "no pad layout: give --pad pad.toml (images carry none; a recording's pad.toml \
                 is used when one is given)",
            )),
        };
    let layout = pad
        .layout()
        .map_err(|e| CliError(format!("pad layout: {e:?}")))?;
    let selected = families::resolve_pad(&pad).map_err(CliError::new)?;
    if selected.is_empty() || selected.len() > MAX_FAMILIES {
        return Err(CliError(format!(
            "the pad names {} marker families; 1 to {MAX_FAMILIES} can be searched",
            selected.len()
        )));
    }
    let line_time_us = args
        .line_time_us
        .or_else(|| inputs.recordings.iter().find_map(|r| r.line_time_us))
        .unwrap_or(0.0);
    let free = FreeTerms {
        radial: true,
        tangential: true,
        k3: args.k3,
    };

    // Pass 1: every frame, the detector without a lens.
    let mut search = Search {
        detector: Detector::new(DetectorConfig::offline()),
        workspace: HostWorkspace::new(),
        selected: &selected,
        layout: &layout,
    };
    let mut usable = Vec::new();
    for frame in 0..inputs.paths.len() {
        let image = inputs.load(frame)?;
        let o = search.observe(frame, &image, &inputs.names[frame])?;
        if o.markers.len() >= MIN_VIEW_MARKERS {
            usable.push(o);
        }
    }
    let frames = inputs.paths.len();
    let usable_views = usable.len();
    if usable_views < MIN_VIEWS {
        return Err(CliError(format!(
            "too few usable views: {usable_views} of {frames} frames show at least \
             {MIN_VIEW_MARKERS} of the pad's markers; need at least {MIN_VIEWS} (advised: \
             {ADVISED_VIEWS} or more, tilted, the pad filling much of the frame)"
        )));
    }
    let cap = usize::from(args.max_views);
    let chosen: Vec<Observation> = if usable.len() > cap {
        (0..cap)
            .map(|i| usable[i * usable.len() / cap].clone())
            .collect()
    } else {
        usable
    };
    let Some(size) = inputs.size else {
        return Err(CliError::new("no image was read"));
    };
    let mut solved = solve(&layout, chosen.clone(), None, free, size)?;
    let mut passes = 1;

    // Pass 2: the same frames through the lens just found.
    let first = camera_model(&solved.fit.intrinsics, size, line_time_us);
    if first.validate().is_ok() && first.has_distortion() {
        search.detector.set_camera(Some(first));
        let mut again = Vec::new();
        for o in &chosen {
            let image = inputs.load(o.frame)?;
            let seen = search.observe(o.frame, &image, &inputs.names[o.frame])?;
            if seen.markers.len() >= MIN_VIEW_MARKERS {
                again.push(seen);
            }
        }
        let poses: Vec<(usize, Pose)> = solved
            .kept
            .iter()
            .zip(&solved.fit.poses)
            .map(|(o, p)| (o.frame, *p))
            .collect();
        if again.len() >= MIN_VIEWS {
            if let Ok(second) = solve(
                &layout,
                again,
                Some((solved.fit.intrinsics, &poses)),
                free,
                size,
            ) {
                solved = second;
                passes = 2;
            }
        }
    }

    let fit = &solved.fit;
    let camera = camera_model(&fit.intrinsics, size, line_time_us);
    camera.validate().map_err(|e| {
        CliError(format!(
            "the lens fit did not converge to a usable camera ({e:?}): take more views, tilted \
             more"
        ))
    })?;
    if !fit.intrinsics.monotonic_over(size.0 as f64, size.1 as f64) {
        let [k1, k2, _, _, k3] = fit.intrinsics.k;
        return Err(CliError(format!(
            "the fitted lens folds over inside the image (k1 {k1:.4}, k2 {k2:.4}, k3 {k3:.4}): \
             the views do not reach far enough into the image's corners to pin the distortion \
             down there; add views with markers in the corners"
        )));
    }

    let mut report = build_report(
        &solved,
        &inputs.names,
        size,
        camera,
        frames,
        usable_views,
        passes,
        args,
    );
    // The board's parameters when the frames are one board's: recordings of `touchdown view`
    // at one scale, or images (taken to be the board's frames at full size).
    let scales: Vec<Option<u8>> = inputs.recordings.iter().map(|r| r.board_scale).collect();
    let scale = match scales.first() {
        None => Some(1),
        Some(first) if scales.iter().all(|s| s == first) => Some(first.unwrap_or(1)),
        Some(_) => None,
    };
    report.board = scale.map(|s| BoardParameters::new(&camera, s));
    if let Some(path) = &args.out {
        std::fs::write(path, &report.camera_toml)
            .map_err(|e| CliError(format!("{}: cannot write: {e}", path.display())))?;
    }
    let written = if args.json {
        let text = serde_json::to_string_pretty(&report).map_err(CliError::new)?;
        writeln!(out, "{text}")
    } else {
        write_text(out, &report, args.out.is_none())
    };
    written.map_err(|e| CliError(format!("cannot write the output: {e}")))?;
    Ok(Outcome::Success)
}

fn camera_model(c: &Intrinsics, size: (usize, usize), line_time_us: f32) -> CameraModel {
    CameraModel {
        width: size.0 as u32,
        height: size.1 as u32,
        fx: c.fx as f32,
        fy: c.fy as f32,
        cx: c.cx as f32,
        cy: c.cy as f32,
        distortion: c.k.map(|k| k as f32),
        line_time_us,
    }
}

/// Horizontal field of view of the distorted image: between the rays through the outer
/// edges of the middle row's first and last pixels, degrees (`None` where the lens model
/// cannot be inverted).
pub fn hfov_deg(camera: &CameraModel) -> Option<f64> {
    let v = camera.cy;
    let left = camera.undistort(Point::new(-0.5, v))?;
    let right = camera.undistort(Point::new(camera.width as f32 - 0.5, v))?;
    Some((f64::from(right.x).atan() - f64::from(left.x).atan()).to_degrees())
}

#[allow(clippy::too_many_arguments)]
fn build_report(
    solved: &Solved,
    names: &[String],
    size: (usize, usize),
    camera: CameraModel,
    frames: usize,
    usable_views: usize,
    passes: usize,
    args: &CalibrateLensArgs,
) -> Report {
    let fit = &solved.fit;
    let mut views = Vec::new();
    let mut ninths = [[0usize; 3]; 3];
    let mut corners = 0;
    for ((o, residuals), pose) in solved.kept.iter().zip(&fit.residuals).zip(&fit.poses) {
        let squares: Vec<f64> = residuals
            .iter()
            .map(|r| r[0] * r[0] + r[1] * r[1])
            .collect();
        let rms = (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt();
        views.push(ViewReport {
            source: names.get(o.frame).cloned().unwrap_or_default(),
            markers: o.markers.len(),
            rms_px: rms,
            worst_px: squares.iter().copied().fold(0.0, f64::max).sqrt(),
            tilt_deg: pose.tilt_deg(),
        });
        for (_, quad) in &o.markers {
            for [u, v] in quad {
                let col = ((u + 0.5) * 3.0 / size.0 as f64).clamp(0.0, 2.0) as usize;
                let row = ((v + 0.5) * 3.0 / size.1 as f64).clamp(0.0, 2.0) as usize;
                ninths[row][col] += 1;
                corners += 1;
            }
        }
    }
    let normals: Vec<Vector3<f64>> = fit.poses.iter().map(Pose::normal).collect();
    let mut span: f64 = 0.0;
    for (i, a) in normals.iter().enumerate() {
        for b in &normals[i + 1..] {
            span = span.max(a.dot(b).clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    let max_tilt = views.iter().map(|v| v.tilt_deg).fold(0.0, f64::max);
    let mut advice = Vec::new();
    if views.len() < ADVISED_VIEWS {
        advice.push(format!(
            "more views: {} of at least {ADVISED_VIEWS}",
            views.len()
        ));
    }
    if span < ADVISED_TILT_SPAN_DEG {
        advice.push(format!(
            "tilt the pad more: views span {span:.0} degrees, want at least \
             {ADVISED_TILT_SPAN_DEG:.0}"
        ));
    }
    let few = (ADVISED_NINTH_SHARE * corners as f64).ceil() as usize;
    for (row, names) in ninths.iter().zip(NINTHS) {
        for (&count, name) in row.iter().zip(names) {
            if count == 0 {
                advice.push(format!(
                    "fill the corners: no corners in the {name} ninth of the image"
                ));
            } else if count < few {
                advice.push(format!(
                    "fill the corners: only {count} corners in the {name} ninth of the image"
                ));
            }
        }
    }
    let worst = views
        .iter()
        .max_by(|a, b| a.rms_px.total_cmp(&b.rms_px))
        .map(|v| WorstView {
            source: v.source.clone(),
            rms_px: v.rms_px,
        })
        .unwrap_or(WorstView {
            source: String::new(),
            rms_px: 0.0,
        });
    let s = fit.sigma;
    Report {
        camera: CameraReport {
            width: camera.width,
            height: camera.height,
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            distortion: camera.distortion,
            line_time_us: camera.line_time_us,
        },
        sigma: Sigma {
            fx: s[0],
            fy: s[1],
            cx: s[2],
            cy: s[3],
            distortion: [s[4], s[5], s[6], s[7], s[8]],
        },
        hfov_deg: hfov_deg(&camera).unwrap_or(f64::NAN),
        rms_px: fit.rms_px,
        worst_view: worst,
        frames,
        usable_views,
        corners,
        rejected_markers: solved.rejected,
        passes,
        coverage: Coverage {
            views: views.len(),
            tilt_span_deg: span,
            max_tilt_deg: max_tilt,
            ninths,
        },
        views,
        advice,
        out: args.out.as_deref().map(|p: &Path| p.display().to_string()),
        camera_toml: touchdown_formats::camera::camera_toml(&camera),
        board: None,
    }
}

/// `n` and the word in its number.
fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

fn write_text(out: &mut dyn Write, r: &Report, with_file: bool) -> std::io::Result<()> {
    let c = &r.camera;
    let s = &r.sigma;
    writeln!(
        out,
        "touchdown calibrate-lens: {} frames, {} usable views, {} used ({} corners), {} dropped \
         as outliers, {}",
        r.frames,
        r.usable_views,
        r.coverage.views,
        r.corners,
        plural(r.rejected_markers, "marker", "markers"),
        plural(r.passes, "detection pass", "detection passes"),
    )?;
    writeln!(
        out,
        "fx {:.3} +-{:.3}  fy {:.3} +-{:.3}  cx {:.3} +-{:.3}  cy {:.3} +-{:.3} px ({}x{})",
        c.fx, s.fx, c.fy, s.fy, c.cx, s.cx, c.cy, s.cy, c.width, c.height
    )?;
    let d = c.distortion;
    let e = s.distortion;
    writeln!(
        out,
        "distortion k1 {:+.5} +-{:.5}  k2 {:+.5} +-{:.5}  p1 {:+.6} +-{:.6}  p2 {:+.6} +-{:.6}  \
         k3 {:+.5} +-{:.5}",
        d[0], e[0], d[1], e[1], d[2], e[2], d[3], e[3], d[4], e[4]
    )?;
    writeln!(
        out,
        "horizontal field of view {:.2} deg (distorted image); RMS reprojection error {:.3} px, \
         worst view {} ({:.3} px)",
        r.hfov_deg, r.rms_px, r.worst_view.source, r.worst_view.rms_px
    )?;
    let n = &r.coverage.ninths;
    writeln!(
        out,
        "coverage: {} views, tilts up to {:.0} deg, spanning {:.0} deg; corners per ninth {} {} {} / {} {} {} / {} {} {}",
        r.coverage.views,
        r.coverage.max_tilt_deg,
        r.coverage.tilt_span_deg,
        n[0][0], n[0][1], n[0][2], n[1][0], n[1][1], n[1][2], n[2][0], n[2][1], n[2][2]
    )?;
    if r.advice.is_empty() {
        writeln!(out, "advice: none, the views cover the lens")?;
    }
    for line in &r.advice {
        writeln!(out, "advice: {line}")?;
    }
    if let Some(b) = &r.board {
        let values: Vec<String> = b
            .parameters
            .iter()
            .map(|(name, value)| format!("{name} {value:.6}"))
            .collect();
        writeln!(
            out,
            "board parameters, for a board whose frames are {}x{} (set them from the ground \
             station; docs/first-light.md): {}",
            b.width,
            b.height,
            values.join("  ")
        )?;
    }
    match &r.out {
        Some(path) => writeln!(out, "wrote {path}")?,
        None if with_file => {
            writeln!(out, "camera file (CAMERA.toml; --out FILE writes it):")?;
            write!(out, "{}", r.camera_toml)?;
        }
        None => {}
    }
    out.flush()
}
