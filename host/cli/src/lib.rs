//! The `touchdown` command-line tool: argument parsing, the subcommands (`detect`, `simulate`,
//! `replay`, `pad`, `companion`, `calibrate`, `calibrate-lens`, `sitl`) and the figures of
//! `replay` ([`plot`]).
//!
//! Every failure the user can cause (a bad option, an unreadable file) is reported as one
//! line on stderr, prefixed `error: ` like clap's own messages, with exit status 2; nothing
//! here panics on user input. The binary (`src/bin/touchdown.rs`) only calls [`main`]; the
//! tests in `tests/` run that binary, as a user would.
//!
//! What this crate is not: the algorithms are the core's, the files `touchdown-formats`',
//! the simulator `touchdown-sim`'s and the scoring `touchdown-eval`'s; this crate turns
//! arguments into calls of those and their results into text, JSON, figures and exit codes.
//! It is a crate of its own so that the command line's dependencies (clap, plotters and its
//! embedded font, rustix for the serial port) stay here, out of the libraries the fuzz
//! harness, the tests and the examples build on.

pub mod board;
pub mod calibrate;
pub mod calibrate_lens;
pub mod companion;
pub mod detect;
pub mod effects;
pub mod lens_fit;
pub mod overlay;
pub mod pad;
pub mod pad_motion;
pub mod plot;
pub mod renderer;
pub mod replay;
pub mod signing_key;
pub mod simulate;
pub mod sitl;
pub mod view;

use std::fmt;
use std::io::{self, Write};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The exit status for a bad option or an unreadable input (the contract's "2").
pub const EXIT_FAILURE: u8 = 2;

/// touchdown: fiducial-marker landing aid (host tools).
#[derive(Debug, Parser)]
#[command(
    name = "touchdown",
    version,
    about = "touchdown: find landing-pad fiducial markers in images (host tools)",
    long_about = "touchdown: find landing-pad fiducial markers in images (host tools).\n\n\
                  The same detector runs on the drone's camera board; these tools run it on \
                  image files.\nSee `touchdown detect --help` for families, the corner \
                  convention and the JSON format."
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Find markers in images and print their ids and corners.
    #[command(long_about = detect::LONG_HELP)]
    Detect(detect::DetectArgs),
    /// Render a simulated flight over a landing pad into a recording.
    #[command(long_about = simulate::LONG_HELP)]
    Simulate(simulate::SimulateArgs),
    /// Replay a recording or a simulated scenario through both methods: tables and figures.
    #[command(long_about = replay::LONG_HELP)]
    Replay(replay::ReplayArgs),
    /// Write a printable landing pad (SVG at true size) and its pad.toml.
    #[command(long_about = pad::LONG_HELP)]
    Pad(pad::PadArgs),
    /// Run the board's MAVLink companion logic on a recording against a UDP endpoint (SITL)
    /// or a serial port.
    Companion(companion::CompanionArgs),
    /// Estimate the camera mount's roll and pitch (TD_CAM_ROLL, TD_CAM_PITCH) from a
    /// recording of a hover over the pad.
    #[command(long_about = calibrate::LONG_HELP)]
    Calibrate(calibrate::CalibrateArgs),
    /// Estimate a camera's intrinsics and lens distortion from views of the printed pad, and
    /// write its CAMERA.toml.
    #[command(name = "calibrate-lens", long_about = calibrate_lens::LONG_HELP)]
    CalibrateLens(calibrate_lens::CalibrateLensArgs),
    /// Closed-loop landings: the vehicle flies on the targets touchdown sends (against the
    /// autopilot model).
    #[command(long_about = sitl::LONG_HELP)]
    Sitl(sitl::SitlArgs),
    /// Set the board's lens or pad from a file over MAVLink, and read it back.
    #[command(long_about = board::LONG_HELP)]
    Board(board::BoardArgs),
    /// Show what the camera board sees (its frames, markers and pad fix, streamed over the
    /// debug probe) and record it.
    #[command(long_about = view::LONG_HELP)]
    View(view::ViewArgs),
}

/// `--board-params` of `replay` and `sitl`: `NAME=VALUE` pairs, comma-separated, in order
/// (names exactly as the parameter table has them; the caller checks them against it).
pub fn parse_board_params(list: Option<&str>) -> Result<Vec<(String, f32)>, CliError> {
    parse_param_list("--board-params", list)
}

/// A `NAME=VALUE,...` list of option `flag` (the flag names the option in the errors).
pub fn parse_param_list(flag: &str, list: Option<&str>) -> Result<Vec<(String, f32)>, CliError> {
    let Some(list) = list else {
        return Ok(Vec::new());
    };
    list.split(',')
        .map(|pair| {
            let (name, value) = pair
                .split_once('=')
                .ok_or_else(|| CliError(format!("{flag}: `{pair}` is not NAME=VALUE")))?;
            let value: f32 = value
                .trim()
                .parse()
                .map_err(|_| CliError(format!("{flag}: `{pair}`: the value is not a number")))?;
            Ok((name.trim().to_string(), value))
        })
        .collect()
}

/// A failure reported as one line on stderr with exit status 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CliError(pub String);

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Messages are built from file names and library errors that might carry newlines;
        // the contract promises one line.
        f.write_str(&self.0.replace(['\n', '\r'], " "))
    }
}

impl std::error::Error for CliError {}

impl CliError {
    /// An error from anything displayable.
    pub fn new(message: impl fmt::Display) -> Self {
        CliError(message.to_string())
    }
}

/// How a run ended, when it got to run at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything was processed.
    Success,
    /// Some inputs failed; each was already reported on stderr.
    PartialFailure,
    /// A signal stopped the run after its output was written (`touchdown companion`'s
    /// summary on SIGINT or SIGTERM): exit with `status`, the shell's for that signal
    /// (128 + its number), once everything is dropped and flushed.
    Stopped {
        /// The exit status.
        status: u8,
    },
}

/// Runs a parsed command line, writing results to `out` and per-file problems to `err`.
pub fn run(cli: Cli, out: &mut dyn Write, err: &mut dyn Write) -> Result<Outcome, CliError> {
    match cli.command {
        Command::Detect(args) => detect::run(&args, out, err),
        Command::Simulate(args) => simulate::run(&args, out, err),
        Command::Replay(args) => replay::run(&args, out, err),
        Command::Pad(args) => pad::run(&args, out, err),
        Command::Companion(args) => companion::run(&args, out, err),
        Command::Calibrate(args) => calibrate::run(&args, out, err),
        Command::CalibrateLens(args) => calibrate_lens::run(&args, out, err),
        Command::Sitl(args) => sitl::run(&args, out, err),
        Command::View(args) => view::run(&args, out, err),
        Command::Board(args) => board::run(&args, out, err),
    }
}

/// The binary's entry point: parse (`--help` and `--version` print and exit 0; a usage
/// error is one line and exit 2), run, and turn the result into the exit status.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            let _ = writeln!(io::stderr(), "{}", usage_error_line(&e));
            return ExitCode::from(EXIT_FAILURE);
        }
    };
    let stdout = io::stdout();
    let stderr = io::stderr();
    let mut out = stdout.lock();
    let mut err = stderr.lock();
    match run(cli, &mut out, &mut err) {
        Ok(Outcome::Success) => ExitCode::SUCCESS,
        Ok(Outcome::PartialFailure) => ExitCode::from(EXIT_FAILURE),
        Ok(Outcome::Stopped { status }) => ExitCode::from(status),
        Err(error) => {
            // Nothing more can be done if stderr itself is gone.
            let _ = writeln!(err, "error: {error}");
            ExitCode::from(EXIT_FAILURE)
        }
    }
}

/// A clap usage error as the contract's one line: clap's message and its tips, without the
/// usage block (`--help` shows that).
pub fn usage_error_line(error: &clap::Error) -> String {
    let rendered = error.render().to_string();
    let mut lines = rendered.lines().map(str::trim).filter(|l| !l.is_empty());
    let mut line = lines
        .next()
        .unwrap_or("error: bad command line")
        .to_string();
    for tip in lines.filter_map(|l| l.strip_prefix("tip:")) {
        line.push_str("; ");
        line.push_str(tip.trim());
    }
    if !line.starts_with("error:") {
        line.insert_str(0, "error: ");
    }
    line.push_str(" (see --help)");
    line
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn usage_errors_are_one_line_with_their_tips() {
        let error = Cli::try_parse_from(["touchdown", "detect", "--fmaily", "x", "a.png"])
            .expect_err("misspelt option");
        let line = usage_error_line(&error);
        assert!(!line.contains('\n'), "{line}");
        assert!(
            line.starts_with("error: unexpected argument '--fmaily'"),
            "{line}"
        );
        assert!(line.contains("--family"), "the tip is kept: {line}");
        assert!(!line.contains("Usage"), "{line}");
    }

    #[test]
    fn errors_are_one_line() {
        assert_eq!(CliError::new("a\nb").to_string(), "a b");
    }
}
