//! `touchdown view`: what the camera board sees, live, over its debug probe.
//!
//! The firmware streams frames with its detections and pad fix over RTT while a host asks
//! for them (`touchdown_core::frame_stream`, the contract's "Frame stream"). A debugger
//! that serves an RTT channel on a TCP port (OpenOCD's `rtt server`) or the emulator's
//! firmware-in-the-loop is the source; a file of captured stream bytes is read too. Each
//! frame is drawn with its markers into a PNG that is replaced atomically (any image viewer
//! that reloads shows it live) and summarised on one line with a sharpness figure for
//! focusing the lens; `--record DIR` also writes the frames as a recording that `touchdown
//! detect`, `replay` and `calibrate-lens` read, with the board's own detections beside them
//! (`board.csv`, `board_markers.csv`) so that a replay can be compared with the board.
//!
//! The stream asks nothing of the board while nobody asks for it: the requests this tool
//! repeats every second are what keeps it on, and the board stops a few seconds after the
//! last one.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Args;
use touchdown_core::frame_stream::ViewRequest;
use touchdown_core::pad::designs;
use touchdown_formats::frame_stream::{StreamReader, StreamedFrame};
use touchdown_formats::image_io::GrayFrame;
use touchdown_formats::pad::{config_of_layout, load_pad, PadConfig};
use touchdown_formats::recording::RecordingWriter;

use super::{CliError, Outcome};

/// `--help`'s long text.
pub const LONG_HELP: &str = "\
Show what the camera board sees: frames streamed by the firmware over the debug probe's RTT, \
with the markers it found and its pad fix.

SOURCE is tcp:HOST:PORT, a TCP port that carries RTT channel 1 both ways (OpenOCD: `rtt \
server start PORT 1`; the emulator's firmware-in-the-loop), or a FILE of stream bytes \
captured earlier. Each frame is drawn, markers outlined, into --image (replaced whole each \
time, for an image viewer that reloads), and summarised on one line: size, exposure, markers, \
the pad fix, and a sharpness figure (the mean squared difference between neighbouring \
pixels over the frame's variance: turn the lens focus to make it largest).

--record DIR writes the frames as a recording (camera.toml and pad.toml from what the board \
uses, frames/, frames.csv) with the board's own results beside them: board.csv (one row a \
frame) and board_markers.csv (one row a marker, corners in the recorded frames' pixels). \
Ends after --frames N frames, after --seconds S, at the end of a FILE, or on Ctrl-C (the \
recording is complete up to the last whole frame). Errors (one line, exit status 2): a source \
that cannot be opened, no frame within --timeout seconds, a --record directory that is not \
empty (without --force), a pad the board names that is not a shipped design (give --pad).";

/// Options of `touchdown view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// tcp:HOST:PORT (an RTT server for channel 1) or a file of captured stream bytes.
    pub source: String,
    /// The picture of the newest frame, markers drawn (PNG, replaced each frame).
    #[arg(long, default_value = "touchdown-view.png")]
    pub image: PathBuf,
    /// Also write the frames as a recording into DIR.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// Write into a --record directory that is not empty.
    #[arg(long)]
    pub force: bool,
    /// The pad to write into the recording when the board's is not a shipped design.
    #[arg(long, value_name = "PAD.toml")]
    pub pad: Option<PathBuf>,
    /// Stop after this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Ask the board for every N-th frame (1 to 255).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..))]
    pub every: u8,
    /// Ask for frames halved (2x2 averaged): four times fewer bytes, for a slow probe.
    #[arg(long)]
    pub half: bool,
    /// Give up when no frame arrives for this many seconds.
    #[arg(long, default_value_t = 10.0)]
    pub timeout: f64,
    /// Print nothing per frame (the summary only).
    #[arg(long)]
    pub quiet: bool,
}

/// How often the request is repeated (well inside the board's lifetime of a request).
const REQUEST_PERIOD: Duration = Duration::from_secs(1);

/// Where the bytes come from.
enum Source {
    Tcp(TcpStream, String),
    File(File, PathBuf),
}

impl Source {
    fn open(spec: &str) -> Result<Self, CliError> {
        if let Some(address) = spec.strip_prefix("tcp:") {
            let addrs: Vec<_> = address
                .to_socket_addrs()
                .map_err(|e| CliError(format!("{spec}: not a HOST:PORT ({e})")))?
                .collect();
            let mut last = None;
            for addr in addrs {
                match TcpStream::connect_timeout(&addr, Duration::from_secs(5)) {
                    Ok(stream) => {
                        stream
                            .set_read_timeout(Some(Duration::from_millis(100)))
                            .map_err(|e| CliError(format!("{spec}: {e}")))?;
                        return Ok(Source::Tcp(stream, spec.to_string()));
                    }
                    Err(e) => last = Some(e),
                }
            }
            return Err(CliError(format!(
                "{spec}: cannot connect ({}); is the debugger's RTT server running on it?",
                last.map_or_else(|| "no address".to_string(), |e| e.to_string())
            )));
        }
        let path = PathBuf::from(spec);
        let file = File::open(&path)
            .map_err(|e| CliError(format!("{}: cannot open: {e}", path.display())))?;
        Ok(Source::File(file, path))
    }

    /// Sends a request (TCP only: a file is only read).
    fn ask(&mut self, request: &ViewRequest) -> Result<(), CliError> {
        if let Source::Tcp(stream, spec) = self {
            stream
                .write_all(&request.encode())
                .map_err(|e| CliError(format!("{spec}: cannot send the request: {e}")))?;
        }
        Ok(())
    }

    /// Reads what is there: `Ok(None)` at the end of the source, `Ok(Some(0))` when nothing
    /// came within the read timeout.
    fn read(&mut self, buf: &mut [u8]) -> Result<Option<usize>, CliError> {
        let (result, name) = match self {
            Source::Tcp(stream, spec) => (stream.read(buf), spec.clone()),
            Source::File(file, path) => (file.read(buf), path.display().to_string()),
        };
        match result {
            Ok(0) => Ok(None),
            Ok(n) => Ok(Some(n)),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(Some(0))
            }
            Err(e) => Err(CliError(format!("{name}: read failed: {e}"))),
        }
    }
}

/// The sharpness figure: mean squared difference of horizontal and vertical neighbours over
/// the frame's variance (so that exposure and gain do not change it, only focus and motion).
pub fn sharpness(pixels: &[u8], width: usize, height: usize) -> f64 {
    if width < 2 || height < 2 || pixels.len() < width * height {
        return 0.0;
    }
    let n = (width * height) as f64;
    let mean = pixels[..width * height]
        .iter()
        .map(|&p| f64::from(p))
        .sum::<f64>()
        / n;
    let variance = pixels[..width * height]
        .iter()
        .map(|&p| (f64::from(p) - mean).powi(2))
        .sum::<f64>()
        / n;
    if variance < 1e-9 {
        return 0.0;
    }
    let mut energy = 0.0;
    let mut count = 0usize;
    for y in 0..height - 1 {
        for x in 0..width - 1 {
            let p = f64::from(pixels[y * width + x]);
            let dx = f64::from(pixels[y * width + x + 1]) - p;
            let dy = f64::from(pixels[(y + 1) * width + x]) - p;
            energy += dx * dx + dy * dy;
            count += 1;
        }
    }
    energy / count as f64 / variance
}

/// The recording and the board's results beside it.
struct Recorder {
    dir: PathBuf,
    writer: Option<RecordingWriter>,
    board: Option<BufWriter<File>>,
    markers: Option<BufWriter<File>>,
    pad: Option<PadConfig>,
    size: Option<(usize, usize)>,
    frames: usize,
}

fn csv_error(path: &Path, e: std::io::Error) -> CliError {
    CliError(format!("{}: cannot write: {e}", path.display()))
}

impl Recorder {
    fn new(dir: &Path, force: bool, pad: Option<PadConfig>) -> Result<Self, CliError> {
        if dir.exists() && !dir.is_dir() {
            return Err(CliError(format!(
                "{}: exists and is not a directory",
                dir.display()
            )));
        }
        if !force && dir.is_dir() {
            let mut entries = std::fs::read_dir(dir)
                .map_err(|e| CliError(format!("{}: cannot read directory: {e}", dir.display())))?;
            if entries.next().is_some() {
                return Err(CliError(format!(
                    "{}: directory is not empty (use --force to write into it anyway)",
                    dir.display()
                )));
            }
        }
        Ok(Recorder {
            dir: dir.to_path_buf(),
            writer: None,
            board: None,
            markers: None,
            pad,
            size: None,
            frames: 0,
        })
    }

    /// The pad the board uses, as a pad.toml: a shipped design scaled as the board scales it.
    fn board_pad(frame: &StreamedFrame) -> Option<PadConfig> {
        let layout = designs::ALL.iter().find(|d| d.name() == frame.pad_name)?;
        let mut config = config_of_layout(layout);
        let s = f64::from(frame.pad_scale);
        if !(s.is_finite() && s > 0.0) {
            return None;
        }
        for marker in &mut config.markers {
            marker.size *= s;
            marker.x *= s;
            marker.y *= s;
        }
        Some(config)
    }

    fn push(&mut self, frame: &StreamedFrame, image: &GrayFrame) -> Result<(), CliError> {
        let size = (frame.width, frame.height);
        if let Some(first) = self.size {
            if first != size {
                // A recording has one frame size; the board changed its scale.
                return Err(CliError(format!(
                    "{}: the board's frames changed size from {}x{} to {}x{}; record again",
                    self.dir.display(),
                    first.0,
                    first.1,
                    size.0,
                    size.1
                )));
            }
        }
        if self.writer.is_none() {
            let pad = match self.pad.clone().or_else(|| Self::board_pad(frame)) {
                Some(pad) => pad,
                None => {
                    return Err(CliError(format!(
                    "the board's pad '{}' is not a shipped design: give its pad.toml with --pad",
                    frame.pad_name
                )))
                }
            };
            let camera = frame.sent_camera();
            let writer =
                RecordingWriter::create(&self.dir, &camera, &pad, false).map_err(CliError::new)?;
            let open = |name: &str, header: &str| -> Result<BufWriter<File>, CliError> {
                let path = self.dir.join(name);
                let file = File::create(&path)
                    .map_err(|e| CliError(format!("{}: cannot create: {e}", path.display())))?;
                let mut w = BufWriter::new(file);
                writeln!(w, "{header}").map_err(|e| csv_error(&path, e))?;
                Ok(w)
            };
            self.board = Some(open(
                "board.csv",
                "index,board_index,t_us,scale,exposure_us,gain,process_us,markers,\
                 fix_x,fix_y,fix_z,fix_markers,fix_rms_px",
            )?);
            self.markers = Some(open(
                "board_markers.csv",
                "index,family,id,hamming,c0x,c0y,c1x,c1y,c2x,c2y,c3x,c3y",
            )?);
            self.writer = Some(writer);
            self.size = Some(size);
        }
        let index = self.frames;
        if let Some(writer) = &mut self.writer {
            writer
                .push(frame.t_us, None, None, image)
                .map_err(CliError::new)?;
        }
        let board_path = self.dir.join("board.csv");
        if let Some(w) = &mut self.board {
            let fix = frame.fix.map_or_else(
                || ",,,,".to_string(),
                |f| {
                    format!(
                        "{},{},{},{},{}",
                        f.camera_position[0],
                        f.camera_position[1],
                        f.camera_position[2],
                        f.markers_used,
                        f.reprojection_rms_px
                    )
                },
            );
            writeln!(
                w,
                "{index},{},{},{},{},{},{},{},{fix}",
                frame.index,
                frame.t_us,
                frame.scale,
                frame.exposure_us,
                f64::from(frame.gain_x16) / 16.0,
                frame.process_us,
                frame.markers.len()
            )
            .and_then(|()| w.flush())
            .map_err(|e| csv_error(&board_path, e))?;
        }
        let markers_path = self.dir.join("board_markers.csv");
        if let Some(w) = &mut self.markers {
            for m in &frame.markers {
                let mut row = format!("{index},{},{},{}", m.family, m.id, m.hamming);
                // In the recorded (possibly halved) frame's pixels.
                for [x, y] in frame.sent_corners(m) {
                    row.push_str(&format!(",{x},{y}"));
                }
                writeln!(w, "{row}").map_err(|e| csv_error(&markers_path, e))?;
            }
            w.flush().map_err(|e| csv_error(&markers_path, e))?;
        }
        self.frames += 1;
        Ok(())
    }

    fn finish(self) -> Result<usize, CliError> {
        if let Some(writer) = self.writer {
            writer.finish().map_err(CliError::new)?;
        }
        Ok(self.frames)
    }
}

/// Writes the frame, markers drawn, to `path` through a temporary file and a rename, so a
/// viewer never reads half a picture.
fn write_picture(path: &Path, frame: &StreamedFrame, image: &GrayFrame) -> Result<(), CliError> {
    let quads: Vec<[[f32; 2]; 4]> = frame
        .markers
        .iter()
        .map(|m| frame.sent_corners(m))
        .collect();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "view.png".to_string());
    let tmp = path.with_file_name(format!(".{name}.tmp.png"));
    super::overlay::write_png(&tmp, image, &quads, 1).map_err(CliError)?;
    std::fs::rename(&tmp, path)
        .map_err(|e| CliError(format!("{}: cannot replace: {e}", path.display())))
}

/// One frame's line.
fn frame_line(frame: &StreamedFrame, sharp: f64, best: f64, fps: f64) -> String {
    let fix = frame.fix.map_or_else(
        || "no fix".to_string(),
        |f| {
            format!(
                "fix x {:.2} y {:.2} z {:.2} m ({} markers, {:.2} px)",
                f.camera_position[0],
                f.camera_position[1],
                f.camera_position[2],
                f.markers_used,
                f.reprojection_rms_px
            )
        },
    );
    format!(
        "frame {:>6}  {}x{}  exposure {:.1} ms gain x{:.1}  {} markers  {fix}  sharpness {:.3} (best {:.3})  {:.1} fps",
        frame.index,
        frame.width,
        frame.height,
        f64::from(frame.exposure_us) / 1000.0,
        f64::from(frame.gain_x16) / 16.0,
        frame.markers.len(),
        sharp,
        best,
        fps
    )
}

/// Runs `touchdown view`.
pub fn run(args: &ViewArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<Outcome, CliError> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(CliError(
            "--timeout: must be a number of seconds over 0".into(),
        ));
    }
    if let Some(s) = args.seconds {
        if !(s.is_finite() && s > 0.0) {
            return Err(CliError(
                "--seconds: must be a number of seconds over 0".into(),
            ));
        }
    }
    let pad = match &args.pad {
        Some(path) => Some(load_pad(path).map_err(CliError::new)?),
        None => None,
    };
    let mut recorder = match &args.record {
        Some(dir) => Some(Recorder::new(dir, args.force, pad)?),
        None => None,
    };
    let mut source = Source::open(&args.source)?;
    // Ctrl-C ends the run with the recording whole (best effort: without the handler, the
    // default action still leaves every frame written so far, each row flushed).
    let _ = super::companion::interrupt::install();
    let request = ViewRequest {
        every: args.every,
        scale: if args.half { 2 } else { 1 },
    };
    let started = Instant::now();
    let mut asked_at: Option<Instant> = None;
    let mut last_frame_at = Instant::now();
    let mut reader = StreamReader::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut frames = 0usize;
    let mut best = 0.0f64;
    let mut rate_window: Vec<Instant> = Vec::new();
    let timeout = Duration::from_secs_f64(args.timeout);
    let mut ended = "end of the source";
    'outer: loop {
        if super::companion::interrupt::received().is_some() {
            ended = "stopped";
            break;
        }
        if asked_at.is_none_or(|t| t.elapsed() >= REQUEST_PERIOD) {
            source.ask(&request)?;
            asked_at = Some(Instant::now());
        }
        let Some(n) = source.read(&mut buf)? else {
            break;
        };
        reader.push(&buf[..n]);
        while let Some(mut frame) = reader.next_frame() {
            frames += 1;
            last_frame_at = Instant::now();
            rate_window.push(last_frame_at);
            rate_window.retain(|t| last_frame_at.duration_since(*t) <= Duration::from_secs(2));
            let fps = match (rate_window.first(), rate_window.len()) {
                (Some(first), n) if n > 1 => {
                    (n - 1) as f64 / last_frame_at.duration_since(*first).as_secs_f64().max(1e-6)
                }
                _ => 0.0,
            };
            let sharp = sharpness(&frame.pixels, frame.width, frame.height);
            best = best.max(sharp);
            let image = GrayFrame {
                width: frame.width,
                height: frame.height,
                pixels: std::mem::take(&mut frame.pixels),
            };
            write_picture(&args.image, &frame, &image)?;
            if let Some(recorder) = &mut recorder {
                recorder.push(&frame, &image)?;
            }
            if !args.quiet {
                writeln!(out, "{}", frame_line(&frame, sharp, best, fps))
                    .map_err(|e| CliError(format!("stdout: {e}")))?;
            }
            if args.frames.is_some_and(|n| frames >= n) {
                ended = "frames done";
                break 'outer;
            }
        }
        if args
            .seconds
            .is_some_and(|s| started.elapsed().as_secs_f64() >= s)
        {
            ended = "time up";
            break;
        }
        if last_frame_at.elapsed() > timeout {
            return Err(CliError(format!(
                "{}: no frame for {} s (is the firmware running, and the RTT channel 1 served there?)",
                args.source, args.timeout
            )));
        }
    }
    let stats = reader.stats();
    let recorded = match recorder {
        Some(recorder) => Some(recorder.finish()?),
        None => None,
    };
    if frames == 0 {
        return Err(CliError(format!("{}: no frame in the stream", args.source)));
    }
    let mut summary = format!(
        "{frames} frames ({ended}); {} bad records, {} bytes skipped; best sharpness {best:.3}",
        stats.bad_checksums, stats.skipped_bytes
    );
    if let (Some(n), Some(dir)) = (recorded, &args.record) {
        summary.push_str(&format!("; {n} frames recorded in {}", dir.display()));
    }
    writeln!(err, "{summary}").map_err(|e| CliError(format!("stderr: {e}")))?;
    Ok(match super::companion::interrupt::received() {
        Some(signal) => Outcome::Stopped {
            status: signal.exit_status(),
        },
        None => Outcome::Success,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sharpness_rises_with_focus_and_ignores_contrast() {
        let (w, h) = (64, 48);
        let sharp: Vec<u8> = (0..w * h)
            .map(|i| {
                if (i % w / 4 + i / w / 4) % 2 == 0 {
                    40
                } else {
                    200
                }
            })
            .collect();
        // The same checker blurred by a 3x3 box.
        let mut blurred = sharp.clone();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let mut s = 0u32;
                for dy in 0..3 {
                    for dx in 0..3 {
                        s += u32::from(sharp[(y + dy - 1) * w + x + dx - 1]);
                    }
                }
                blurred[y * w + x] = (s / 9) as u8;
            }
        }
        let dim: Vec<u8> = sharp.iter().map(|&p| p / 2).collect();
        let (a, b, c) = (
            sharpness(&sharp, w, h),
            sharpness(&blurred, w, h),
            sharpness(&dim, w, h),
        );
        assert!(a > 1.5 * b, "{a} vs {b}");
        assert!((a - c).abs() < 0.01 * a, "{a} vs {c}");
        assert_eq!(sharpness(&[7; 12], 4, 3), 0.0);
    }
}
