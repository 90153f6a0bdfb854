//! Recordings, the contract's format (`docs/interfaces.md`): a directory with `camera.toml`
//! ([`crate::camera`]), `pad.toml` ([`crate::pad`]), `frames/NNNNNN.pgm` ([`crate::pgm`])
//! and `frames.csv`, written by the simulator and, later, by the camera board; read back by
//! `replay` and the tests. [`RecordingWriter`] and [`RecordingReader`] are the two sides.
//!
//! `frames.csv` has the header `index,t_us` or `index,t_us,cam_x,cam_y,cam_z,cam_qw,cam_qx,
//! cam_qy,cam_qz` (the camera's true position in the pad frame, metres, and its camera-to-pad
//! rotation as a unit quaternion), optionally followed by `veh_qw,veh_qx,veh_qy,veh_qz`: the
//! vehicle's true attitude at the frame's time, body FRD to NED, as a unit quaternion (NED
//! is the simulator's: north = pad +y, east = pad +x, down = pad -z, so that camera-to-pad =
//! NED-to-pad x body-to-NED x mount), without the camera's vibration on its mount: what an
//! ideal autopilot would measure. A row may leave all seven truth fields empty (truth lost
//! for that frame), and all four attitude fields; leaving some of a group empty is an error. Indices count up from 0 without gaps (frame `k` is `frames/` + `k`
//! zero-padded to 6 digits + `.pgm`); a dropped camera frame shows as a larger step in `t_us`,
//! which must increase strictly.
//!
//! Set-point labels (the paper's tables group frames by them) are an extension in a separate
//! `setpoints.csv` (`index,label`), so `frames.csv` keeps exactly the contract's columns.
//! Readers that do not know it ignore it.
//!
//! Exactness: truth values are written in Rust's shortest round-trip form, and the camera's
//! `f32` numbers in the shortest form that reads back to the same `f32`, so a recording
//! written and read back is identical, bit for bit.
//!
//! Reading is strict and every error is one line naming the file and, for CSV files, the
//! line: `rec/frames.csv: line 7: t_us 200000 is not after the previous frame's 233333`.
//! [`RecordingReader`] checks the CSV files and that every listed frame file exists up
//! front, then decodes frames one at a time ([`RecordingReader::frames`]) so a long recording
//! never has to fit in memory.

use std::fmt;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use touchdown_core::camera::CameraModel;

use crate::camera::{camera_toml, load_camera};
use crate::image_io::GrayFrame;
use crate::pad::{load_pad, pad_toml, PadConfig};
use crate::pgm::{parse_pgm, save_pgm};
use crate::ConfigError;

/// The truth columns of `frames.csv`, in order.
pub const TRUTH_COLUMNS: [&str; 7] = [
    "cam_x", "cam_y", "cam_z", "cam_qw", "cam_qx", "cam_qy", "cam_qz",
];
/// The optional vehicle-attitude columns of `frames.csv`, in order, after the truth.
pub const VEHICLE_ATTITUDE_COLUMNS: [&str; 4] = ["veh_qw", "veh_qx", "veh_qy", "veh_qz"];
/// How far from 1 a truth quaternion's norm may be.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// The camera's true pose for a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraTruth {
    /// Camera centre in the pad frame, metres.
    pub position: [f64; 3],
    /// Camera-to-pad rotation, unit quaternion `[w, x, y, z]`.
    pub orientation: [f64; 4],
}

/// A recording that cannot be read or written: one line naming the file (and line).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, for text files.
    pub line: Option<usize>,
    /// What is wrong.
    pub reason: String,
}

impl fmt::Display for RecordingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ": line {line}")?;
        }
        write!(f, ": {}", self.reason.replace(['\n', '\r'], " "))
    }
}

impl std::error::Error for RecordingError {}

impl From<ConfigError> for RecordingError {
    fn from(e: ConfigError) -> Self {
        RecordingError {
            path: e.path,
            line: e.line,
            reason: match e.key {
                Some(key) => format!("{key}: {}", e.reason),
                None => e.reason,
            },
        }
    }
}

fn error(path: &Path, line: Option<usize>, reason: impl Into<String>) -> RecordingError {
    RecordingError {
        path: path.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// One frame of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// Position in the recording (0, 1, ...).
    pub index: usize,
    /// Time, microseconds (middle of the exposure for simulated frames).
    pub t_us: u64,
    /// The camera's true pose, when known.
    pub truth: Option<CameraTruth>,
    /// The vehicle's true attitude (body FRD to NED, unit quaternion `[w, x, y, z]`), when
    /// known (the `veh_` columns).
    pub vehicle_attitude: Option<[f64; 4]>,
    /// Set-point label, when the recording has one for this frame.
    pub label: Option<String>,
    /// The image.
    pub image: GrayFrame,
}

/// A whole recording in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The camera (`camera.toml`).
    pub camera: CameraModel,
    /// The pad (`pad.toml`).
    pub pad: PadConfig,
    /// Whether `frames.csv` has the truth columns.
    pub has_truth: bool,
    /// The frames.
    pub frames: Vec<RecordedFrame>,
}

impl Recording {
    /// Writes the recording into `dir` (created if needed), with the vehicle-attitude
    /// columns when some frame has an attitude.
    pub fn write(&self, dir: &Path) -> Result<(), RecordingError> {
        let has_vehicle_attitude = self.frames.iter().any(|f| f.vehicle_attitude.is_some());
        let mut writer = RecordingWriter::create_with_vehicle_attitude(
            dir,
            &self.camera,
            &self.pad,
            self.has_truth,
            has_vehicle_attitude,
        )?;
        for frame in &self.frames {
            writer.push_with_vehicle_attitude(
                frame.t_us,
                frame.truth.as_ref(),
                frame.vehicle_attitude.as_ref(),
                frame.label.as_deref(),
                &frame.image,
            )?;
        }
        writer.finish()?;
        Ok(())
    }

    /// Reads a whole recording.
    pub fn read(dir: &Path) -> Result<Recording, RecordingError> {
        let reader = RecordingReader::open(dir)?;
        let frames = reader.frames().collect::<Result<Vec<_>, _>>()?;
        Ok(Recording {
            camera: reader.camera,
            pad: reader.pad,
            has_truth: reader.has_truth,
            frames,
        })
    }
}

/// Writes a recording frame by frame (the simulator never holds more than one frame).
#[derive(Debug)]
pub struct RecordingWriter {
    dir: PathBuf,
    csv: BufWriter<File>,
    setpoints: Option<BufWriter<File>>,
    has_truth: bool,
    has_vehicle_attitude: bool,
    size: (usize, usize),
    next_index: usize,
    last_t_us: Option<u64>,
}

fn io_error(path: &Path, what: &str, e: std::io::Error) -> RecordingError {
    error(path, None, format!("cannot {what}: {e}"))
}

/// Path of frame `index` inside a recording directory.
pub fn frame_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("frames").join(format!("{index:06}.pgm"))
}

impl RecordingWriter {
    /// Creates `dir` (and `dir/frames`), writes `camera.toml` and `pad.toml`, and starts
    /// `frames.csv` (with the truth columns when `has_truth`).
    pub fn create(
        dir: &Path,
        camera: &CameraModel,
        pad: &PadConfig,
        has_truth: bool,
    ) -> Result<Self, RecordingError> {
        Self::create_with_vehicle_attitude(dir, camera, pad, has_truth, false)
    }

    /// [`RecordingWriter::create`], with the vehicle-attitude columns
    /// ([`VEHICLE_ATTITUDE_COLUMNS`]) after the truth when `has_vehicle_attitude`.
    pub fn create_with_vehicle_attitude(
        dir: &Path,
        camera: &CameraModel,
        pad: &PadConfig,
        has_truth: bool,
        has_vehicle_attitude: bool,
    ) -> Result<Self, RecordingError> {
        camera.validate().map_err(|e| {
            error(
                &dir.join("camera.toml"),
                None,
                format!("invalid camera: {e:?}"),
            )
        })?;
        let frames_dir = dir.join("frames");
        std::fs::create_dir_all(&frames_dir)
            .map_err(|e| io_error(&frames_dir, "create directory", e))?;
        let write = |name: &str, text: String| {
            let path = dir.join(name);
            std::fs::write(&path, text).map_err(|e| io_error(&path, "write", e))
        };
        write("camera.toml", camera_toml(camera))?;
        write("pad.toml", pad_toml(pad))?;
        let csv_path = dir.join("frames.csv");
        let file = File::create(&csv_path).map_err(|e| io_error(&csv_path, "create", e))?;
        let mut csv = BufWriter::new(file);
        let mut header = String::from("index,t_us");
        if has_truth {
            for column in TRUTH_COLUMNS {
                header.push(',');
                header.push_str(column);
            }
        }
        if has_vehicle_attitude {
            for column in VEHICLE_ATTITUDE_COLUMNS {
                header.push(',');
                header.push_str(column);
            }
        }
        writeln!(csv, "{header}").map_err(|e| io_error(&csv_path, "write", e))?;
        // A previous recording's labels must not survive into this one.
        let setpoints_path = dir.join("setpoints.csv");
        if setpoints_path.exists() {
            std::fs::remove_file(&setpoints_path)
                .map_err(|e| io_error(&setpoints_path, "remove", e))?;
        }
        Ok(RecordingWriter {
            dir: dir.to_path_buf(),
            csv,
            setpoints: None,
            has_truth,
            has_vehicle_attitude,
            size: (camera.width as usize, camera.height as usize),
            next_index: 0,
            last_t_us: None,
        })
    }

    /// Appends a frame (without a vehicle attitude: empty `veh_` fields, when the recording
    /// has them).
    pub fn push(
        &mut self,
        t_us: u64,
        truth: Option<&CameraTruth>,
        label: Option<&str>,
        image: &GrayFrame,
    ) -> Result<(), RecordingError> {
        self.push_with_vehicle_attitude(t_us, truth, None, label, image)
    }

    /// Appends a frame with the vehicle's attitude (body FRD to NED, `[w, x, y, z]`); the
    /// recording must have been created with the attitude columns to be given one.
    pub fn push_with_vehicle_attitude(
        &mut self,
        t_us: u64,
        truth: Option<&CameraTruth>,
        vehicle_attitude: Option<&[f64; 4]>,
        label: Option<&str>,
        image: &GrayFrame,
    ) -> Result<(), RecordingError> {
        let index = self.next_index;
        let path = frame_path(&self.dir, index);
        if (image.width, image.height) != self.size
            || image.pixels.len() != image.width * image.height
        {
            return Err(error(
                &path,
                None,
                format!(
                    "frame is {}x{} but the camera is {}x{}",
                    image.width, image.height, self.size.0, self.size.1
                ),
            ));
        }
        if self.last_t_us.is_some_and(|last| t_us <= last) {
            return Err(error(
                &self.dir.join("frames.csv"),
                None,
                format!("frame {index}: time {t_us} us does not increase"),
            ));
        }
        if truth.is_some() && !self.has_truth {
            return Err(error(
                &self.dir.join("frames.csv"),
                None,
                "truth given for a recording created without truth columns",
            ));
        }
        if vehicle_attitude.is_some() && !self.has_vehicle_attitude {
            return Err(error(
                &self.dir.join("frames.csv"),
                None,
                "vehicle attitude given for a recording created without veh_ columns",
            ));
        }
        if let Some(v) = vehicle_attitude
            .into_iter()
            .flatten()
            .find(|v| !v.is_finite())
        {
            return Err(error(
                &self.dir.join("frames.csv"),
                None,
                format!("frame {index}: vehicle attitude value {v} is not finite"),
            ));
        }
        save_pgm(&path, image).map_err(|e| io_error(&path, "write", e))?;
        let mut row = format!("{index},{t_us}");
        if self.has_truth {
            match truth {
                Some(t) => {
                    for v in t.position.iter().chain(&t.orientation) {
                        if !v.is_finite() {
                            return Err(error(
                                &self.dir.join("frames.csv"),
                                None,
                                format!("frame {index}: truth value {v} is not finite"),
                            ));
                        }
                        row.push_str(&format!(",{v:?}"));
                    }
                }
                None => row.push_str(",,,,,,,"),
            }
        }
        if self.has_vehicle_attitude {
            match vehicle_attitude {
                Some(q) => {
                    for v in q {
                        row.push_str(&format!(",{v:?}"));
                    }
                }
                None => row.push_str(",,,,"),
            }
        }
        let csv_path = self.dir.join("frames.csv");
        writeln!(self.csv, "{row}").map_err(|e| io_error(&csv_path, "write", e))?;
        if let Some(label) = label {
            let sp_path = self.dir.join("setpoints.csv");
            if label.is_empty() || label.contains([',', '\n', '\r']) {
                return Err(error(
                    &sp_path,
                    None,
                    format!("label `{label}` must be non-empty without commas or line breaks"),
                ));
            }
            if self.setpoints.is_none() {
                let file = File::create(&sp_path).map_err(|e| io_error(&sp_path, "create", e))?;
                let mut w = BufWriter::new(file);
                writeln!(w, "index,label").map_err(|e| io_error(&sp_path, "write", e))?;
                self.setpoints = Some(w);
            }
            if let Some(w) = &mut self.setpoints {
                writeln!(w, "{index},{label}").map_err(|e| io_error(&sp_path, "write", e))?;
            }
        }
        self.next_index += 1;
        self.last_t_us = Some(t_us);
        Ok(())
    }

    /// Flushes the CSV files; returns the number of frames written.
    pub fn finish(mut self) -> Result<usize, RecordingError> {
        let csv_path = self.dir.join("frames.csv");
        self.csv
            .flush()
            .map_err(|e| io_error(&csv_path, "write", e))?;
        if let Some(w) = &mut self.setpoints {
            let sp_path = self.dir.join("setpoints.csv");
            w.flush().map_err(|e| io_error(&sp_path, "write", e))?;
        }
        Ok(self.next_index)
    }
}

/// A row of `frames.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameEntry {
    /// Frame index.
    pub index: usize,
    /// Time, microseconds.
    pub t_us: u64,
    /// Truth, when present.
    pub truth: Option<CameraTruth>,
    /// The vehicle's attitude, when present.
    pub vehicle_attitude: Option<[f64; 4]>,
    /// Line in `frames.csv`.
    pub line: usize,
}

/// An opened recording: configuration and frame list read and checked; images decoded on
/// demand.
#[derive(Debug, Clone)]
pub struct RecordingReader {
    /// The directory.
    pub dir: PathBuf,
    /// The camera (`camera.toml`).
    pub camera: CameraModel,
    /// The pad (`pad.toml`).
    pub pad: PadConfig,
    /// Whether `frames.csv` has the truth columns.
    pub has_truth: bool,
    /// Whether `frames.csv` has the vehicle-attitude columns.
    pub has_vehicle_attitude: bool,
    /// The rows of `frames.csv`.
    pub entries: Vec<FrameEntry>,
    /// Set-point label per frame (from `setpoints.csv`, when present).
    pub labels: Vec<Option<String>>,
}

impl RecordingReader {
    /// Reads `camera.toml`, `pad.toml`, `frames.csv` (and `setpoints.csv` when present), and
    /// checks that every listed frame file exists.
    pub fn open(dir: &Path) -> Result<Self, RecordingError> {
        if !dir.is_dir() {
            return Err(error(
                dir,
                None,
                "not a recording directory (no such directory)",
            ));
        }
        let camera = load_camera(&dir.join("camera.toml"))?;
        let pad = load_pad(&dir.join("pad.toml"))?;
        let csv_path = dir.join("frames.csv");
        let text =
            std::fs::read_to_string(&csv_path).map_err(|e| io_error(&csv_path, "read", e))?;
        let (columns, entries) = parse_frames_csv_columns(&text)
            .map_err(|(line, reason)| error(&csv_path, Some(line), reason))?;
        for entry in &entries {
            let path = frame_path(dir, entry.index);
            if !path.is_file() {
                return Err(error(
                    &path,
                    None,
                    format!(
                        "missing frame file (frames.csv line {} lists frame {})",
                        entry.line, entry.index
                    ),
                ));
            }
        }
        let mut labels = vec![None; entries.len()];
        let sp_path = dir.join("setpoints.csv");
        if sp_path.exists() {
            let text =
                std::fs::read_to_string(&sp_path).map_err(|e| io_error(&sp_path, "read", e))?;
            parse_setpoints_csv(&text, &mut labels)
                .map_err(|(line, reason)| error(&sp_path, Some(line), reason))?;
        }
        Ok(RecordingReader {
            dir: dir.to_path_buf(),
            camera,
            pad,
            has_truth: columns.truth,
            has_vehicle_attitude: columns.vehicle_attitude,
            entries,
            labels,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the recording has no frame.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Reads frame `k` (of [`RecordingReader::entries`]).
    pub fn frame(&self, k: usize) -> Result<RecordedFrame, RecordingError> {
        let entry = self.entries.get(k).ok_or_else(|| {
            error(
                &self.dir.join("frames.csv"),
                None,
                format!("no frame {k} (the recording has {})", self.entries.len()),
            )
        })?;
        let path = frame_path(&self.dir, entry.index);
        let image = read_pgm(
            &path,
            Some((self.camera.width as usize, self.camera.height as usize)),
        )?;
        Ok(RecordedFrame {
            index: entry.index,
            t_us: entry.t_us,
            truth: entry.truth,
            vehicle_attitude: entry.vehicle_attitude,
            label: self.labels.get(k).cloned().flatten(),
            image,
        })
    }

    /// The frames in order, decoded one at a time.
    pub fn frames(&self) -> impl Iterator<Item = Result<RecordedFrame, RecordingError>> + '_ {
        (0..self.entries.len()).map(|k| self.frame(k))
    }
}

/// Lines of a text file with their 1-based numbers, line breaks (`\n` or `\r\n`) removed,
/// blank lines skipped.
fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.split('\n')
        .enumerate()
        .map(|(k, l)| (k + 1, l.strip_suffix('\r').unwrap_or(l)))
        .filter(|(_, l)| !l.trim().is_empty())
}

/// Which optional column groups a `frames.csv` has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FramesCsvColumns {
    /// The truth ([`TRUTH_COLUMNS`]).
    pub truth: bool,
    /// The vehicle's attitude ([`VEHICLE_ATTITUDE_COLUMNS`]).
    pub vehicle_attitude: bool,
}

/// Parses `frames.csv`: whether it has truth, and its rows. Errors are (line, reason).
pub fn parse_frames_csv(text: &str) -> Result<(bool, Vec<FrameEntry>), (usize, String)> {
    parse_frames_csv_columns(text).map(|(columns, entries)| (columns.truth, entries))
}

/// The numbers of a group of columns: `None` when all are empty, an error naming the first
/// bad one, or naming the group when only some are empty.
fn parse_group<const N: usize>(
    line: usize,
    values: &[&str],
    names: [&str; N],
) -> Result<Option<[f64; N]>, (usize, String)> {
    if values.iter().all(|v| v.is_empty()) {
        return Ok(None);
    }
    if values.iter().any(|v| v.is_empty()) {
        let empty: Vec<&str> = values
            .iter()
            .zip(names)
            .filter(|(v, _)| v.is_empty())
            .map(|(_, name)| name)
            .collect();
        return Err((
            line,
            format!(
                "{}..{}: {} empty; give all {N} or leave all empty",
                names[0],
                names[N - 1],
                empty.join(", ")
            ),
        ));
    }
    let mut parsed = [0.0f64; N];
    for ((slot, text), name) in parsed.iter_mut().zip(values).zip(names) {
        *slot = text
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| (line, format!("{name}: `{text}` is not a finite number")))?;
    }
    Ok(Some(parsed))
}

/// Checks that `q` is a unit quaternion; the error names its columns.
fn check_unit(line: usize, q: &[f64; 4], first: &str, last: &str) -> Result<(), (usize, String)> {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err((
            line,
            format!("{first}..{last} has norm {norm:.6}; it must be a unit quaternion"),
        ));
    }
    Ok(())
}

/// Parses `frames.csv`: which optional columns it has, and its rows. Errors are (line,
/// reason).
pub fn parse_frames_csv_columns(
    text: &str,
) -> Result<(FramesCsvColumns, Vec<FrameEntry>), (usize, String)> {
    let mut lines = numbered_lines(text);
    let Some((header_line, header)) = lines.next() else {
        return Err((
            1,
            "empty file: expected the header `index,t_us[,cam_x,...][,veh_qw,...]`".into(),
        ));
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let basic = ["index", "t_us"];
    let mut rest = columns.get(2..).unwrap_or(&[]);
    let mut found = FramesCsvColumns::default();
    if rest.starts_with(&TRUTH_COLUMNS) {
        found.truth = true;
        rest = &rest[TRUTH_COLUMNS.len()..];
    }
    if rest.starts_with(&VEHICLE_ATTITUDE_COLUMNS) {
        found.vehicle_attitude = true;
        rest = &rest[VEHICLE_ATTITUDE_COLUMNS.len()..];
    }
    if columns.get(..2) != Some(&basic[..]) || !rest.is_empty() {
        return Err((
            header_line,
            format!(
                "header `{header}`: expected `index,t_us`, then optionally `{}`, then \
                 optionally `{}`",
                TRUTH_COLUMNS.join(","),
                VEHICLE_ATTITUDE_COLUMNS.join(",")
            ),
        ));
    }
    let truth_width = if found.truth { TRUTH_COLUMNS.len() } else { 0 };
    let width = 2
        + truth_width
        + if found.vehicle_attitude {
            VEHICLE_ATTITUDE_COLUMNS.len()
        } else {
            0
        };
    let mut entries = Vec::new();
    let mut previous_t: Option<u64> = None;
    for (line, row) in lines {
        let fields: Vec<&str> = row.split(',').map(str::trim).collect();
        if fields.len() != width {
            return Err((
                line,
                format!(
                    "expected {width} comma-separated columns, found {} (truncated or corrupt row?)",
                    fields.len()
                ),
            ));
        }
        let index: usize = fields[0].parse().map_err(|_| {
            (
                line,
                format!("index: `{}` is not a whole number", fields[0]),
            )
        })?;
        let expected = entries.len();
        if index != expected {
            return Err((
                line,
                format!(
                    "index {index} where {expected} was expected (indices count up from 0 \
                     without gaps; dropped frames show in t_us)"
                ),
            ));
        }
        let t_us: u64 = fields[1].parse().map_err(|_| {
            (
                line,
                format!(
                    "t_us: `{}` is not a whole number of microseconds",
                    fields[1]
                ),
            )
        })?;
        if let Some(previous) = previous_t {
            if t_us <= previous {
                return Err((
                    line,
                    format!(
                        "t_us {t_us} is not after the previous frame's {previous} (times must increase)"
                    ),
                ));
            }
        }
        let truth = if found.truth {
            parse_group(line, &fields[2..2 + truth_width], TRUTH_COLUMNS)?
                .map(|parsed| {
                    let q = [parsed[3], parsed[4], parsed[5], parsed[6]];
                    check_unit(line, &q, "cam_qw", "cam_qz")?;
                    Ok(CameraTruth {
                        position: [parsed[0], parsed[1], parsed[2]],
                        orientation: q,
                    })
                })
                .transpose()?
        } else {
            None
        };
        let vehicle_attitude = if found.vehicle_attitude {
            let q = parse_group(line, &fields[2 + truth_width..], VEHICLE_ATTITUDE_COLUMNS)?;
            if let Some(q) = &q {
                check_unit(line, q, "veh_qw", "veh_qz")?;
            }
            q
        } else {
            None
        };
        entries.push(FrameEntry {
            index,
            t_us,
            truth,
            vehicle_attitude,
            line,
        });
        previous_t = Some(t_us);
    }
    Ok((found, entries))
}

/// Parses `setpoints.csv` into `labels` (one slot per frame). Errors are (line, reason).
fn parse_setpoints_csv(text: &str, labels: &mut [Option<String>]) -> Result<(), (usize, String)> {
    let mut lines = numbered_lines(text);
    match lines.next() {
        Some((_, header)) if header.trim() == "index,label" => {}
        Some((line, header)) => {
            return Err((line, format!("header `{header}`: expected `index,label`")));
        }
        None => return Ok(()),
    }
    for (line, row) in lines {
        let Some((index, label)) = row.split_once(',') else {
            return Err((line, "expected `index,label`".into()));
        };
        let index: usize = index.trim().parse().map_err(|_| {
            (
                line,
                format!("index: `{}` is not a whole number", index.trim()),
            )
        })?;
        let count = labels.len();
        let slot = labels.get_mut(index).ok_or_else(|| {
            (
                line,
                format!("frame {index} is not in frames.csv (it has {count} frames)"),
            )
        })?;
        let label = label.trim();
        if label.is_empty() {
            return Err((line, "empty label".into()));
        }
        *slot = Some(label.to_string());
    }
    Ok(())
}

/// Reads an 8-bit binary PGM (P5) strictly ([`parse_pgm`]), with the size `expected` when
/// given; the error names the file.
pub fn read_pgm(
    path: &Path,
    expected: Option<(usize, usize)>,
) -> Result<GrayFrame, RecordingError> {
    let bytes = std::fs::read(path).map_err(|e| io_error(path, "read", e))?;
    parse_pgm(&bytes, expected).map_err(|reason| error(path, None, reason))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_errors_name_the_line() {
        let head = "index,t_us\n";
        assert_eq!(
            parse_frames_csv(&format!("{head}0,10\n1,20\n"))
                .unwrap()
                .1
                .len(),
            2
        );
        let e = parse_frames_csv(&format!("{head}0,10\n2,20\n")).unwrap_err();
        assert_eq!(e.0, 3);
        let e = parse_frames_csv(&format!("{head}0,10\n1,10\n")).unwrap_err();
        assert!(e.0 == 3 && e.1.contains("after"), "{e:?}");
        let e = parse_frames_csv(&format!("{head}0,1x\n")).unwrap_err();
        assert!(e.0 == 2 && e.1.contains("t_us"));
        let e = parse_frames_csv("index,time\n").unwrap_err();
        assert_eq!(e.0, 1);
        let truth = format!("index,t_us,{}\n", TRUTH_COLUMNS.join(","));
        let (has, rows) =
            parse_frames_csv(&format!("{truth}0,5,1,2,3,1,0,0,0\n1,6,,,,,,,\n")).unwrap();
        assert!(has && rows[0].truth.is_some() && rows[1].truth.is_none());
        let e = parse_frames_csv(&format!("{truth}0,5,1,2,3,2,0,0,0\n")).unwrap_err();
        assert!(e.1.contains("unit quaternion"), "{e:?}");
        let e = parse_frames_csv(&format!("{truth}0,5,1,2,3,1,0,0\n")).unwrap_err();
        assert!(e.1.contains("columns"), "{e:?}");
    }

    #[test]
    fn vehicle_attitude_columns_are_optional_and_whole() {
        let truth = TRUTH_COLUMNS.join(",");
        let veh = VEHICLE_ATTITUDE_COLUMNS.join(",");
        let text =
            format!("index,t_us,{truth},{veh}\n0,5,1,2,3,1,0,0,0,0.6,0,0,0.8\n1,6,,,,,,,,,,,\n");
        let (columns, rows) = parse_frames_csv_columns(&text).unwrap();
        assert!(columns.truth && columns.vehicle_attitude);
        assert_eq!(rows[0].vehicle_attitude, Some([0.6, 0.0, 0.0, 0.8]));
        assert!(rows[1].vehicle_attitude.is_none() && rows[1].truth.is_none());
        // The attitude without the truth.
        let (columns, rows) =
            parse_frames_csv_columns(&format!("index,t_us,{veh}\n0,5,1,0,0,0\n")).unwrap();
        assert!(!columns.truth && columns.vehicle_attitude);
        assert_eq!(rows[0].vehicle_attitude, Some([1.0, 0.0, 0.0, 0.0]));
        // Without them, as before.
        let (columns, rows) =
            parse_frames_csv_columns(&format!("index,t_us,{truth}\n0,5,1,2,3,1,0,0,0\n")).unwrap();
        assert!(columns.truth && !columns.vehicle_attitude);
        assert!(rows[0].vehicle_attitude.is_none());
        // Some but not all: refused on its line, naming the empty columns.
        let e = parse_frames_csv_columns(&format!(
            "index,t_us,{truth},{veh}\n0,5,1,2,3,1,0,0,0,1,0,0,0\n1,6,1,2,3,1,0,0,0,1,0,,\n"
        ))
        .unwrap_err();
        assert_eq!(e.0, 3, "{e:?}");
        assert!(e.1.contains("veh_qy, veh_qz empty"), "{e:?}");
        let e = parse_frames_csv_columns(&format!("index,t_us,{veh}\n0,5,2,0,0,0\n")).unwrap_err();
        assert!(e.0 == 2 && e.1.contains("veh_qw..veh_qz"), "{e:?}");
        // In the wrong order, or the truth after the attitude: a header error.
        let e = parse_frames_csv_columns(&format!("index,t_us,{veh},{truth}\n")).unwrap_err();
        assert_eq!(e.0, 1);
        let e = parse_frames_csv_columns("index,t_us,veh_qw,veh_qx,veh_qz,veh_qy\n").unwrap_err();
        assert_eq!(e.0, 1);
    }

    #[test]
    fn vehicle_attitude_round_trips_through_a_written_recording() {
        let dir = std::env::temp_dir().join(format!("touchdown-veh-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let camera = CameraModel::pinhole(4, 3, 10.0, 10.0, 1.5, 1.0);
        let pad = crate::pad::PadConfig {
            name: "one".into(),
            markers: vec![crate::pad::MarkerConfig {
                family: "tag36h11".into(),
                id: 0,
                size: 0.5,
                x: 0.0,
                y: 0.0,
                yaw_deg: 0.0,
            }],
        };
        let image = GrayFrame {
            width: 4,
            height: 3,
            pixels: vec![7; 12],
        };
        let q = [0.9887710779360422, 0.1, -0.05, 0.1];
        let frame = |index: usize, attitude| RecordedFrame {
            index,
            t_us: 1000 * index as u64 + 1,
            truth: Some(CameraTruth {
                position: [0.1, 0.2, 3.0],
                orientation: [1.0, 0.0, 0.0, 0.0],
            }),
            vehicle_attitude: attitude,
            label: None,
            image: image.clone(),
        };
        let recording = Recording {
            camera,
            pad,
            has_truth: true,
            frames: vec![frame(0, Some(q)), frame(1, None)],
        };
        recording.write(&dir).unwrap();
        let csv = std::fs::read_to_string(dir.join("frames.csv")).unwrap();
        assert!(csv.starts_with(&format!(
            "index,t_us,{},{}\n",
            TRUTH_COLUMNS.join(","),
            VEHICLE_ATTITUDE_COLUMNS.join(",")
        )));
        let back = Recording::read(&dir).unwrap();
        assert_eq!(back, recording, "bit for bit");
        assert!(RecordingReader::open(&dir).unwrap().has_vehicle_attitude);
        // A writer without the columns refuses an attitude.
        let mut writer = RecordingWriter::create(&dir, &camera, &recording.pad, true).unwrap();
        let e = writer
            .push_with_vehicle_attitude(1, None, Some(&q), None, &image)
            .unwrap_err();
        assert!(e.reason.contains("veh_"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
