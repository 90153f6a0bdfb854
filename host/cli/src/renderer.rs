//! `--renderer raster|warp`, the image model `touchdown simulate`, `touchdown replay
//! --scenario` and `touchdown sitl` render with, `--psf`, the lens blur of either model, and
//! `--response`, the warp model's sensor response: one definition each, so that the commands
//! take the same values with the same help.

use touchdown_sim::warp::{Psf, Response};
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

/// `--psf`'s values: point-spread functions in place of the scenario's lens blur (either
/// model), so that one flight can be replayed through optics it was not tuned to.
#[derive(Debug, Clone, PartialEq)]
pub struct PsfArg(pub Vec<Psf>);

/// `--response`'s values: the warp model's sensor response, each one given in place of the
/// scenario's, so that one flight can be replayed through a camera's DSP it was not tuned to.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ResponseArg {
    /// `gamma:G`: the tone curve's gamma (1 linear; 2.2 about sRGB's).
    pub gamma: Option<f64>,
    /// `sharpen:S`: the 3x3 sharpening kernel's strength (0 none).
    pub sharpen: Option<f64>,
    /// `jpeg:Q`: block compression at this JPEG quality (1-100).
    pub jpeg: Option<u8>,
}

/// `--psf` and `--response`, shared by `touchdown simulate` and `touchdown replay`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LensArgs {
    /// The lens blur (either renderer; replay: with --scenario), in place of the scenario's:
    /// a comma-separated list of gaussian:SIGMA, disc:DIAMETER, motion:LENGTH
    /// or motion:LENGTH@DEGREES, field:CORNER_SIGMA (pixels)
    #[arg(
        long,
        value_name = "LIST",
        value_parser = PsfArg::parse,
        help_heading = "Advanced"
    )]
    pub psf: Option<PsfArg>,
    /// The warp model's sensor response (with --renderer warp; replay: with --scenario), each
    /// item in place of the scenario's: a comma-separated list of gamma:G (1 linear, 2.2
    /// about sRGB), sharpen:S (the 3x3 kernel's strength, 0 none), jpeg:Q (quality 1-100)
    #[arg(
        long,
        value_name = "LIST",
        value_parser = ResponseArg::parse,
        help_heading = "Advanced"
    )]
    pub response: Option<ResponseArg>,
}

impl LensArgs {
    /// Whether either option was given.
    pub fn any(&self) -> bool {
        self.psf.is_some() || self.response.is_some()
    }
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
        for (item, kind, value) in kind_values(text, EXPECTED)? {
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

impl ResponseArg {
    /// A comma-separated list of `gamma:G` (over 0, at most 5), `sharpen:S` (0 to 2) and
    /// `jpeg:Q` (1 to 100), each at most once; anything else is one line saying what is
    /// expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        const EXPECTED: &str = "expected gamma:G, sharpen:S or jpeg:QUALITY, comma-separated";
        let mut response = ResponseArg::default();
        for (item, kind, value) in kind_values(text, EXPECTED)? {
            let number: f64 = value
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| format!("`{item}`: `{value}` is not a number"))?;
            let kind = kind.trim().to_ascii_lowercase();
            let twice = || format!("`{item}`: {kind} is given twice");
            match kind.as_str() {
                "gamma" => {
                    if !(number > 0.0 && number <= 5.0) {
                        return Err(format!("`{item}`: gamma must be over 0 and at most 5"));
                    }
                    if response.gamma.replace(number).is_some() {
                        return Err(twice());
                    }
                }
                "sharpen" => {
                    if !(0.0..=2.0).contains(&number) {
                        return Err(format!("`{item}`: sharpen must be 0 to 2"));
                    }
                    if response.sharpen.replace(number).is_some() {
                        return Err(twice());
                    }
                }
                "jpeg" => {
                    if !(number.fract() == 0.0 && (1.0..=100.0).contains(&number)) {
                        return Err(format!("`{item}`: jpeg quality must be a whole 1 to 100"));
                    }
                    if response.jpeg.replace(number as u8).is_some() {
                        return Err(twice());
                    }
                }
                _ => return Err(format!("`{item}`: {EXPECTED}")),
            }
        }
        Ok(response)
    }

    /// `base` with the items given in place of its own.
    pub fn apply(&self, base: Response) -> Response {
        Response {
            gamma: self.gamma.unwrap_or(base.gamma),
            sharpen: self.sharpen.unwrap_or(base.sharpen),
            block_quality: self.jpeg.or(base.block_quality),
            ..base
        }
    }
}

/// The items of a comma-separated list of `KIND:VALUE`, each with its kind and value; an
/// item without a colon is one line naming it and what is `expected`.
fn kind_values<'a>(
    text: &'a str,
    expected: &str,
) -> Result<Vec<(&'a str, &'a str, &'a str)>, String> {
    text.split(',')
        .map(|item| {
            item.trim()
                .split_once(':')
                .map(|(kind, value)| (item, kind, value))
                .ok_or_else(|| format!("`{item}`: {expected}"))
        })
        .collect()
}

/// `simulator` rendering with `renderer`, with `lens`'s `--psf` in place of the scenario's
/// lens blur (either model; its defocus with distance, motion blur and vignetting kept) and
/// `--response`'s items of the warp model's sensor response (without the warp model a usage
/// error).
pub fn configure(
    simulator: Simulator,
    renderer: RendererArg,
    lens: &LensArgs,
) -> Result<Simulator, CliError> {
    // Refused before the warp model's world is rasterised.
    if lens.response.is_some() && renderer != RendererArg::Warp {
        return Err(CliError(
            "--response sets the warp model's sensor response: add --renderer warp".into(),
        ));
    }
    let mut simulator = simulator.with_renderer(renderer.renderer());
    if let Some(response) = &lens.response {
        let mut optics = WarpOptics::of_scenario(&simulator.scenario);
        optics.response = response.apply(optics.response);
        simulator = simulator.with_warp_optics(optics);
    }
    if let Some(PsfArg(psfs)) = &lens.psf {
        simulator = simulator.with_lens_psfs(psfs.clone());
    }
    Ok(simulator)
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

    #[test]
    fn response_lists_parse_replace_only_what_they_name_and_bad_ones_are_one_line() {
        let given = ResponseArg::parse("gamma:2.2, JPEG:80").unwrap();
        assert_eq!(
            given,
            ResponseArg {
                gamma: Some(2.2),
                sharpen: None,
                jpeg: Some(80)
            }
        );
        let applied = given.apply(Response::board_camera());
        assert_eq!(
            applied,
            Response {
                gamma: 2.2,
                block_quality: Some(80),
                ..Response::board_camera()
            }
        );
        assert_eq!(
            ResponseArg::parse("sharpen:0")
                .unwrap()
                .apply(Response::board_camera()),
            Response {
                sharpen: 0.0,
                ..Response::board_camera()
            }
        );
        for (bad, says) in [
            ("gamma", "expected gamma"),
            ("contrast:2", "expected gamma"),
            ("gamma:bright", "not a number"),
            ("gamma:0", "over 0"),
            ("gamma:inf", "not a number"),
            ("sharpen:-1", "0 to 2"),
            ("jpeg:80.5", "whole 1 to 100"),
            ("jpeg:0", "whole 1 to 100"),
            ("gamma:2,gamma:1", "twice"),
            ("gamma:2,", "expected gamma"),
        ] {
            let e = ResponseArg::parse(bad).unwrap_err();
            assert!(e.contains(says) && !e.contains('\n'), "{bad}: {e}");
        }
    }
}
