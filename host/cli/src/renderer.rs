//! `--renderer raster|warp`, the image model `touchdown simulate`, `touchdown replay
//! --scenario` and `touchdown sitl` render with, and `--psf`, the warp model's lens blur:
//! one definition each, so that the commands take the same values with the same help.

use touchdown_sim::warp::Psf;
use touchdown_sim::{Renderer, Simulator, WarpOptics};

use crate::CliError;

/// `--renderer`'s values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RendererArg {
    /// Ray casting per pixel averaged over motion-blur sub-frames (the simulator's first model)
    #[default]
    Raster,
    /// The pre-rasterised world through a homography per row, motion blur as each pixel's
    /// footprint swept, its own PSFs and sensor response (much faster)
    Warp,
}

impl RendererArg {
    /// `raster` or `warp` (ASCII case ignored); anything else is one line naming both, for
    /// clap's one-line usage error.
    pub fn parse(text: &str) -> Result<Self, String> {
        if text.eq_ignore_ascii_case("raster") {
            Ok(RendererArg::Raster)
        } else if text.eq_ignore_ascii_case("warp") {
            Ok(RendererArg::Warp)
        } else {
            Err(format!("`{text}` is not a renderer: raster or warp"))
        }
    }

    /// The simulator's renderer.
    pub fn renderer(self) -> Renderer {
        match self {
            RendererArg::Raster => Renderer::Raster,
            RendererArg::Warp => Renderer::Warp,
        }
    }
}

/// `--psf`'s values: the warp model's point-spread functions, in place of the scenario's lens
/// blur, so that one flight can be replayed through optics it was not tuned to.
#[derive(Debug, Clone, PartialEq)]
pub struct PsfArg(pub Vec<Psf>);

/// `--psf`, shared by `touchdown simulate` and `touchdown replay`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LensArgs {
    /// The warp model's lens blur (with --renderer warp; replay: with --scenario), in place of
    /// the scenario's: a comma-separated list of gaussian:SIGMA, disc:DIAMETER, motion:LENGTH
    /// or motion:LENGTH@DEGREES, field:CORNER_SIGMA (pixels)
    #[arg(
        long,
        value_name = "LIST",
        value_parser = PsfArg::parse,
        help_heading = "Advanced"
    )]
    pub psf: Option<PsfArg>,
}

/// The widest PSF `--psf` takes, pixels (sigma, diameter or length): the renderer cuts
/// kernels at 32 px either side, and a blur this wide leaves no marker to read anyway.
const MAX_PSF_PX: f64 = 20.0;

impl PsfArg {
    /// A comma-separated list of `gaussian:SIGMA`, `disc:DIAMETER`, `motion:LENGTH[@DEGREES]`
    /// and `field:CORNER_SIGMA` (pixels; the motion line's angle from the image's +x toward
    /// +y, 0 unless given); anything else is one line saying what is expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        const EXPECTED: &str = "expected gaussian:SIGMA, disc:DIAMETER, motion:LENGTH[@DEGREES] \
                                or field:SIGMA (pixels), comma-separated";
        let mut psfs = Vec::new();
        for item in text.split(',') {
            let (kind, value) = item
                .trim()
                .split_once(':')
                .ok_or_else(|| format!("`{item}`: {EXPECTED}"))?;
            let (size, angle) = match value.split_once('@') {
                Some((size, angle)) if kind.eq_ignore_ascii_case("motion") => (size, Some(angle)),
                _ => (value, None),
            };
            let px: f64 = size
                .trim()
                .parse()
                .map_err(|_| format!("`{item}`: `{size}` is not a number of pixels"))?;
            if !(px > 0.0 && px <= MAX_PSF_PX) {
                return Err(format!(
                    "`{item}`: the size must be over 0 and at most {MAX_PSF_PX} px"
                ));
            }
            let angle_deg = match angle {
                Some(a) => a
                    .trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|a| a.is_finite())
                    .ok_or_else(|| format!("`{item}`: `{a}` is not an angle in degrees"))?,
                None => 0.0,
            };
            psfs.push(match kind.to_ascii_lowercase().as_str() {
                "gaussian" => Psf::Gaussian { sigma_px: px },
                "disc" => Psf::Disc { diameter_px: px },
                "motion" => Psf::MotionLine {
                    length_px: px,
                    angle_deg,
                },
                "field" => Psf::Field {
                    corner_sigma_px: px,
                },
                _ => return Err(format!("`{item}`: {EXPECTED}")),
            });
        }
        Ok(PsfArg(psfs))
    }
}

/// `simulator` rendering with `renderer` and, with `psf`, the warp model's lens blur replaced
/// by it (its defocus with distance, motion blur, vignetting and sensor response kept);
/// `--psf` without the warp model is a usage error.
pub fn configure(
    simulator: Simulator,
    renderer: RendererArg,
    psf: Option<&PsfArg>,
) -> Result<Simulator, CliError> {
    // Refused before the warp model's world is rasterised.
    if psf.is_some() && renderer != RendererArg::Warp {
        return Err(CliError(
            "--psf sets the warp model's optics: add --renderer warp".into(),
        ));
    }
    let simulator = simulator.with_renderer(renderer.renderer());
    let Some(PsfArg(psfs)) = psf else {
        return Ok(simulator);
    };
    let optics = WarpOptics {
        psfs: psfs.clone(),
        ..WarpOptics::of_scenario(&simulator.scenario)
    };
    Ok(simulator.with_warp_optics(optics))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_names_parse_and_anything_else_is_one_line() {
        assert_eq!(RendererArg::parse("raster"), Ok(RendererArg::Raster));
        assert_eq!(RendererArg::parse("Warp"), Ok(RendererArg::Warp));
        assert_eq!(RendererArg::default(), RendererArg::Raster);
        let e = RendererArg::parse("gpu").unwrap_err();
        assert!(e.contains("raster or warp") && !e.contains('\n'), "{e}");
    }

    #[test]
    fn psf_lists_parse_and_bad_ones_are_one_line() {
        assert_eq!(
            PsfArg::parse("gaussian:0.8, disc:2.5,motion:3@45,Field:0.4"),
            Ok(PsfArg(vec![
                Psf::Gaussian { sigma_px: 0.8 },
                Psf::Disc { diameter_px: 2.5 },
                Psf::MotionLine {
                    length_px: 3.0,
                    angle_deg: 45.0
                },
                Psf::Field {
                    corner_sigma_px: 0.4
                },
            ]))
        );
        assert_eq!(
            PsfArg::parse("motion:2"),
            Ok(PsfArg(vec![Psf::MotionLine {
                length_px: 2.0,
                angle_deg: 0.0
            }]))
        );
        for (bad, says) in [
            ("box:2", "expected gaussian"),
            ("gaussian", "expected gaussian"),
            ("disc:wide", "not a number"),
            ("disc:0", "over 0"),
            ("gaussian:NaN", "over 0"),
            ("gaussian:25", "at most 20"),
            ("motion:3@left", "not an angle"),
            ("disc:2@45", "not a number"),
            ("gaussian:1,", "expected gaussian"),
        ] {
            let e = PsfArg::parse(bad).unwrap_err();
            assert!(e.contains(says) && !e.contains('\n'), "{bad}: {e}");
        }
    }
}
