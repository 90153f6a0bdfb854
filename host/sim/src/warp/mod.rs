//! The warp renderer: a second image model, built differently from [`crate::raster`] and
//! [`crate::sensor`], fast enough for `touchdown sitl`'s wall-clock frames, and a second
//! opinion for the detector's accuracy tests (tuned on one model, checked on two).
//!
//! Where the two differ:
//! - **World**: pre-rasterised once per [`crate::Simulator`] (`texture`): the pad as
//!   summed-area tables of its cells (exact box averages of any size), the ground as a
//!   mirrored texture pyramid of [`crate::texture::GroundTexture`]'s albedo, instead of the
//!   procedural texture evaluated per pixel and sub-frame.
//! - **Pixels** (`sample`): one ground point per pixel through its row's homography, the
//!   world box-filtered over the footprint the homography's derivative gives (no
//!   sub-samples), the light in closed form over the same footprint.
//! - **Motion blur**: the footprint swept along the image's path over the exposure (its
//!   spread added to the box, its mean to the centre), measured at a sparse grid of knots;
//!   no sub-frames. A rolling shutter stays a pose per row.
//! - **Optics** ([`WarpOptics`]): the scenario's lens as a Gaussian whose corners are
//!   softer ([`Psf::Field`]) and its defocus as the blur circle itself ([`Psf::Disc`]),
//!   where the raster model has one Gaussian for both; either model takes other
//!   point-spread functions in place of the lens's ([`crate::psf`]).
//! - **Sensor** (`response`): the scenario's exposure and photometry, its own noise
//!   (SplitMix64, sum of uniforms, seeded per row), gamma, a 3x3 sharpening kernel,
//!   rounding, optional 8x8 block compression. No blooming.
//!
//! The truth of a frame ([`crate::SimFrame::truth`], the marker corners) is the same
//! function of the pose as with the raster renderer; only the image differs. A frame is a
//! pure function of the scenario, the optics and the seed, whatever the thread count.

mod response;
mod sample;
mod texture;

use std::fmt;

pub use crate::psf::Psf;
pub use response::Response;

use crate::camera::RayMap;
use crate::scenario::Scenario;
use crate::sensor::Sensor;
use crate::world::World;

/// Which image model renders a [`crate::Simulator`]'s frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Renderer {
    /// Area-sampled ray casting averaged over sub-frames ([`crate::raster`], [`crate::sensor`]).
    #[default]
    Raster,
    /// This module's pre-rasterised world, per-row homographies and swept footprints.
    Warp,
}

impl Renderer {
    /// `raster` or `warp`.
    pub fn name(self) -> &'static str {
        match self {
            Renderer::Raster => "raster",
            Renderer::Warp => "warp",
        }
    }
}

impl fmt::Display for Renderer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The warp renderer's optics and sensor response.
#[derive(Debug, Clone, PartialEq)]
pub struct WarpOptics {
    /// Point-spread functions applied in turn to the radiance.
    pub psfs: Vec<Psf>,
    /// Also a defocus disc of the scenario's lens
    /// ([`crate::sensor::Optics::defocus_diameter_px`]) at the frame's distance along the
    /// optical axis (a narrow one merged into the first Gaussian of `psfs`).
    pub defocus: bool,
    /// The footprint swept along the image's path over the exposure.
    pub motion_blur: bool,
    /// Vignetting strength: 0 none, 1 the natural cos^4 fall-off.
    pub vignetting: f64,
    /// The DSP's response.
    pub response: Response,
}

impl WarpOptics {
    /// Sharp: no PSF, no vignetting, no motion blur, a linear noiseless response.
    pub fn ideal() -> Self {
        WarpOptics {
            psfs: Vec::new(),
            defocus: false,
            motion_blur: false,
            vignetting: 0.0,
            response: Response::linear(),
        }
    }

    /// The warp model of a scenario's lens and sensor: its lens blur as a Gaussian, its
    /// defocus as a disc, corners softer by half the lens blur again, its vignetting, motion
    /// blur, and a board camera's DSP (mild sharpening, noise) unless the sensor is ideal.
    pub fn of_scenario(scenario: &Scenario) -> Self {
        let o = &scenario.optics;
        let mut psfs = Vec::new();
        if o.blur_sigma_px > 0.0 {
            psfs.push(Psf::Gaussian {
                sigma_px: o.blur_sigma_px,
            });
            psfs.push(Psf::Field {
                corner_sigma_px: 0.5 * o.blur_sigma_px,
            });
        }
        WarpOptics {
            psfs,
            defocus: o.aperture_m > 0.0,
            motion_blur: true,
            vignetting: o.vignetting,
            response: if scenario.sensor == Sensor::ideal() {
                Response::linear()
            } else {
                Response::board_camera()
            },
        }
    }
}

/// What a [`crate::Simulator`] prepares once for the warp renderer.
#[derive(Clone)]
pub(crate) struct WarpScene {
    pad: texture::PadTables,
    ground: texture::GroundPyramid,
    light: sample::Light,
    rays: Vec<[f32; 6]>,
}

impl fmt::Debug for WarpScene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WarpScene").finish_non_exhaustive()
    }
}

impl WarpScene {
    /// Rasterises the world and the pixels' rays (`threads` for the ground).
    pub(crate) fn new(
        world: &World,
        rays: &RayMap,
        width: usize,
        height: usize,
        threads: usize,
    ) -> Self {
        WarpScene {
            pad: texture::PadTables::new(&world.pad),
            ground: texture::GroundPyramid::new(&world.ground, threads),
            light: sample::Light::new(world),
            rays: sample::pixel_rays(rays, width, height),
        }
    }
}

/// One frame's exposure, as [`crate::Simulator`] decided it.
pub(crate) struct Exposure<'a> {
    pub t: f64,
    pub exposure_s: f64,
    pub sensor: &'a Sensor,
    pub noise_seed: u64,
}

/// Renders the frame at `e.t` (grey levels, row-major).
pub(crate) fn render(
    sim: &crate::Simulator,
    scene: &WarpScene,
    rays: &RayMap,
    optics: &WarpOptics,
    e: &Exposure<'_>,
    threads: usize,
) -> Vec<u8> {
    let s = &sim.scenario;
    let (w, h) = (s.camera.width(), s.camera.height());
    let homographies: Vec<_> = if sim.line_time_s() == 0.0 {
        vec![sim.camera_pose(e.t).ground_homography()]
    } else {
        (0..h)
            .map(|y| {
                sim.camera_pose(sim.row_time(e.t, y as f64))
                    .ground_homography()
            })
            .collect()
    };
    let knots = if optics.motion_blur {
        sample::Knots::new(sim, &scene.rays, e.t, e.exposure_s)
    } else {
        None
    };
    let sources = sample::Sources {
        pad: &scene.pad,
        ground: &scene.ground,
        light: scene.light,
        rays: &scene.rays,
        cos_off_axis: &rays.cos_off_axis,
        vignetting: optics.vignetting.clamp(0.0, 1.0) as f32,
    };
    let mut radiance =
        sample::render_radiance(&sources, w, h, &homographies, knots.as_ref(), threads);
    for psf in frame_psfs(sim, optics, e.t) {
        psf.apply(&mut radiance, w, h);
    }
    response::develop(&radiance, w, h, e.sensor, &optics.response, e.noise_seed)
}

/// Defocus discs narrower than this are a Gaussian of the same variance, merged with the
/// lens's: a disc of a pixel or so is not told from a Gaussian, and one pass costs less
/// than two.
const SMALL_DISC_PX: f64 = 1.5;

/// The PSFs of the frame at `t`: the optics' own, and the defocus at the frame's distance.
fn frame_psfs(sim: &crate::Simulator, optics: &WarpOptics, t: f64) -> Vec<Psf> {
    let mut psfs = optics.psfs.clone();
    if !optics.defocus {
        return psfs;
    }
    let s = &sim.scenario;
    let distance = sim.camera_pose(t).axis_distance_to_ground();
    let diameter_px = s.optics.defocus_diameter_px(s.camera.fx(), distance);
    if diameter_px >= SMALL_DISC_PX {
        psfs.insert(0, Psf::Disc { diameter_px });
        return psfs;
    }
    // A uniform disc of diameter d has the variance d^2 / 16 along each axis.
    let disc_sigma = 0.25 * diameter_px;
    match psfs.iter_mut().find(|p| matches!(p, Psf::Gaussian { .. })) {
        Some(Psf::Gaussian { sigma_px }) => *sigma_px = sigma_px.hypot(disc_sigma),
        _ => psfs.insert(
            0,
            Psf::Gaussian {
                sigma_px: disc_sigma,
            },
        ),
    }
    psfs
}
