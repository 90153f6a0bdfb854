//! The paper's geometry, simulated: a 1.0 m `aruco_6x6_250` marker (id 0) flat on the
//! ground, seen by a 640x480 camera with a 60° horizontal field of view looking straight
//! down from a hovering vehicle, at the set points of the paper's Tables 2-4 (Z 5-25 m;
//! X and Y 1.2-6 m at 15 m altitude) and a few higher altitudes.
//!
//! Its set points are the simulator's tables ([`TABLE_ALTITUDES_M`], [`TABLE_OFFSETS_M`],
//! [`OFFSET_ROWS_ALTITUDE_M`], [`EXTRA_ALTITUDES_M`] of [`touchdown_sim::scenario`]), the one
//! definition of where the paper's experiment hovers, which the simulator's `paper` scenario
//! flies too.
//!
//! ## Axes and headings
//! The pad frame is the marker's frame (x right, y up on the print, z up). At heading 0
//! the image's right is pad +x and the image's top is pad +y, so an X offset moves the
//! marker along the 640-pixel image axis (visible out to 8.7 m at 15 m). A Y offset along
//! the 480-pixel axis would not fit: the half field of view across it reaches
//! 15 m x 240 / 554.3 = 6.49 m, and the far edge of the marker at Y = 6 m is at 6.5 m,
//! before any attitude jitter. The paper states its 6 m limit kept the tag in view, so
//! for the Y rows the vehicle is turned by 90° (image right = pad +y): both horizontal
//! offsets are then along the wide image axis, the Y rows with the marker turned by a
//! quarter turn in the image.
//!
//! ## Hover
//! At each set point the vehicle hovers with a slow wander (each position axis a sinusoid
//! of [`Config::position_jitter_m`] amplitude and 0.1-0.3 Hz, each attitude angle one of
//! [`Config::attitude_jitter_deg`] and 0.2-0.8 Hz, random phases; deterministic from
//! [`Config::seed`]). [`Config::settle_frames`] frames run through the filters before the
//! [`Config::frames_per_set_point`] scored ones (the vehicle arrives, then hovers, as in
//! the paper's tests); every set point is a new sequence (filters reset). The attitude
//! given to the methods is the true one: an ideal flight controller (see
//! [`super`] for why the attitude is used; a real attitude error of e degrees adds about
//! 15 m x e x 1.7 % to the X/Y rows for either method).
//!
//! ## Image formation
//! [`touchdown_sim::render`]: area-sampled ink on paper over a textured ground, Gaussian blur,
//! Gaussian sensor noise, 8 bits.

use std::f64::consts::TAU;

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::camera::CameraModel;
use touchdown_core::family::tables;
use touchdown_core::pad::designs::PAPER_SINGLE;

use touchdown_sim::render::{
    Background, FrameOptions, MarkerPattern, PinholeCamera, PlanePose, Scene, SceneMarker,
};
use touchdown_sim::scenario::{
    EXTRA_ALTITUDES_M, OFFSET_ROWS_ALTITUDE_M, TABLE_ALTITUDES_M, TABLE_OFFSETS_M,
};

use crate::{Axis, Experiment, ExperimentError, Frame, Method, Report, SetPoint};

/// Frame width, pixels.
pub const WIDTH: usize = 640;
/// Frame height, pixels.
pub const HEIGHT: usize = 480;
/// Horizontal field of view, degrees.
pub const HFOV_DEG: f64 = 60.0;
/// The marker's family (the paper's 8x8-cell markers).
pub const FAMILY: &str = "aruco_6x6_250";

/// Focal length in pixels for [`HFOV_DEG`] across [`WIDTH`]: 554.26.
pub fn focal_px() -> f64 {
    0.5 * WIDTH as f64 / (0.5 * HFOV_DEG).to_radians().tan()
}

/// The camera as the pose sees it.
pub fn camera_model() -> CameraModel {
    let f = focal_px() as f32;
    let (cx, cy) = (0.5 * (WIDTH as f32 - 1.0), 0.5 * (HEIGHT as f32 - 1.0));
    CameraModel::pinhole(WIDTH as u32, HEIGHT as u32, f, f, cx, cy)
}

fn render_camera() -> PinholeCamera {
    PinholeCamera {
        fx: focal_px(),
        fy: focal_px(),
        cx: 0.5 * (WIDTH as f64 - 1.0),
        cy: 0.5 * (HEIGHT as f64 - 1.0),
    }
}

/// Everything about the simulated experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Scored frames per set point.
    pub frames_per_set_point: usize,
    /// Frames per set point that run through the filters before scoring starts.
    pub settle_frames: usize,
    /// Frame rate, Hz.
    pub frame_rate_hz: f64,
    /// Sensor noise, grey levels.
    pub noise_sigma: f64,
    /// Optical blur, pixels.
    pub blur_sigma: f64,
    /// Sub-samples per pixel side at ink edges ([`FrameOptions::supersampling`]).
    pub supersampling: usize,
    /// Textured ground (value noise) rather than flat grey. The marker's white margin
    /// keeps the ground away from its edges either way; the texture tests the detectors
    /// against clutter and costs about 50 ms per frame to render in the dev profile.
    pub textured_ground: bool,
    /// Hover wander amplitude per position axis, metres.
    pub position_jitter_m: f64,
    /// Hover wander amplitude per attitude angle, degrees.
    pub attitude_jitter_deg: f64,
    /// Altitudes beyond Table 2 to try (Z rows without a published value), metres.
    pub extra_altitudes_m: Vec<f64>,
    /// Seed of the hover and the sensor noise.
    pub seed: u64,
}

impl Default for Config {
    /// 15 scored frames after 10 settling frames per set point at 30 Hz, noise 2.5 grey
    /// levels, blur 0.5 px, 8x8 sub-samples, textured ground, wander 5 cm and 2°, extra
    /// altitudes 30, 40 and 50 m.
    fn default() -> Self {
        Config {
            frames_per_set_point: 15,
            settle_frames: 10,
            frame_rate_hz: 30.0,
            noise_sigma: 2.5,
            blur_sigma: 0.5,
            supersampling: 8,
            textured_ground: true,
            position_jitter_m: 0.05,
            attitude_jitter_deg: 2.0,
            extra_altitudes_m: EXTRA_ALTITUDES_M.to_vec(),
            seed: 3,
        }
    }
}

/// A set point with where the vehicle hovers.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSetPoint {
    /// The row.
    pub set_point: SetPoint,
    /// Nominal camera position in the pad frame, metres.
    pub position: Vector3<f64>,
    /// Vehicle heading: rotation of the image axes about the pad z axis, degrees (0:
    /// image right = pad +x).
    pub heading_deg: f64,
}

/// The paper's set points (Tables 2, 3, 4 in that order) plus `extra_altitudes_m` as
/// further Z rows.
pub fn set_points(extra_altitudes_m: &[f64]) -> Vec<SimSetPoint> {
    let mut out = Vec::new();
    let mut add = |axis: Axis, reference_m: f64, position: Vector3<f64>, heading_deg| {
        out.push(SimSetPoint {
            set_point: SetPoint {
                label: format!("{} {:.1} m", axis.name(), reference_m),
                axis,
                reference_m,
            },
            position,
            heading_deg,
        });
    };
    for z in TABLE_ALTITUDES_M.iter().chain(extra_altitudes_m) {
        add(Axis::Z, *z, Vector3::new(0.0, 0.0, *z), 0.0);
    }
    let h = OFFSET_ROWS_ALTITUDE_M;
    for y in TABLE_OFFSETS_M {
        add(Axis::Y, y, Vector3::new(0.0, y, h), 90.0);
    }
    for x in TABLE_OFFSETS_M {
        add(Axis::X, x, Vector3::new(x, 0.0, h), 0.0);
    }
    out
}

/// A slow hover wander: per component, amplitude * sin(2 pi f t + phase).
struct Wander {
    components: [(f64, f64); 6],
    position_amplitude: f64,
    attitude_amplitude: f64,
}

impl Wander {
    fn new(rng: &mut ChaCha8Rng, config: &Config) -> Self {
        let mut components = [(0.0, 0.0); 6];
        for (k, c) in components.iter_mut().enumerate() {
            // Positions wander slowly (0.1-0.3 Hz), attitude faster (0.2-0.8 Hz).
            let (lo, hi) = if k < 3 { (0.1, 0.3) } else { (0.2, 0.8) };
            *c = (
                lo + (hi - lo) * rng.random::<f64>(),
                TAU * rng.random::<f64>(),
            );
        }
        Wander {
            components,
            position_amplitude: config.position_jitter_m,
            attitude_amplitude: config.attitude_jitter_deg.to_radians(),
        }
    }

    fn at(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        let v = |k: usize| {
            let (f, phase) = self.components[k];
            (TAU * f * t + phase).sin()
        };
        let a = self.position_amplitude;
        let b = self.attitude_amplitude;
        (
            [a * v(0), a * v(1), a * v(2)],
            [b * v(3), b * v(4), b * v(5)],
        )
    }
}

/// Camera-to-pad rotation of a downward camera at `heading` with small roll, pitch and
/// yaw about the pad axes.
fn camera_to_pad(heading_deg: f64, angles: [f64; 3]) -> Matrix3<f64> {
    // Looking down, heading 0: camera x = pad x, camera y (image down) = pad -y,
    // camera z (optical axis) = pad -z.
    let down = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    let heading = Rotation3::from_axis_angle(&Vector3::z_axis(), heading_deg.to_radians());
    let wobble = Rotation3::from_euler_angles(angles[0], angles[1], angles[2]);
    wobble.matrix() * heading.matrix() * down
}

/// Runs `methods` on the simulated paper geometry.
pub fn run(config: &Config, methods: &[Method]) -> Result<Report, ExperimentError> {
    let family = tables::by_name(FAMILY).ok_or(ExperimentError::MissingFamily)?;
    let marker = PAPER_SINGLE
        .markers()
        .first()
        .ok_or(ExperimentError::MissingFamily)?;
    let pattern = MarkerPattern::from_code(family, marker.id as usize)
        .ok_or(ExperimentError::MissingFamily)?;
    let families = [family];
    let mut experiment = Experiment::new(camera_model(), &families, PAPER_SINGLE, methods)?;
    let dt = 1.0 / config.frame_rate_hz;
    for (index, sp) in set_points(&config.extra_altitudes_m).iter().enumerate() {
        experiment.start_sequence()?;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ ((index as u64) << 32));
        let wander = Wander::new(&mut rng, config);
        let total = config.settle_frames + config.frames_per_set_point;
        // Where each frame is seen from, and its noise seed, drawn in frame order (so the
        // frames do not depend on how many threads render them).
        let views: Vec<(f64, Vector3<f64>, Matrix3<f64>, u64)> = (0..total)
            .map(|k| {
                let t = k as f64 * dt;
                let (offset, angles) = wander.at(t);
                let position = sp.position + Vector3::from(offset);
                (
                    t,
                    position,
                    camera_to_pad(sp.heading_deg, angles),
                    rng.random(),
                )
            })
            .collect();
        // Rendering is most of the run's time and each frame is independent: it is spread
        // over the machine's cores; the methods then see the frames in order.
        let rendered = render_all(config, &pattern, f64::from(marker.size), &views);
        for (k, ((t, position, rotation, _), image)) in views.iter().zip(&rendered).enumerate() {
            let frame = Frame {
                set_point: (k >= config.settle_frames).then_some(&sp.set_point),
                t_us: (t * 1e6).round() as u64,
                truth: *position,
                attitude: Some(rotation.cast::<f32>()),
                image: image.view(),
            };
            experiment.process(&frame)?;
        }
    }
    Ok(experiment.report())
}

/// [`render`] of every view, in order, on as many threads as the machine has cores.
fn render_all(
    config: &Config,
    pattern: &MarkerPattern,
    size: f64,
    views: &[(f64, Vector3<f64>, Matrix3<f64>, u64)],
) -> Vec<touchdown_formats::image_io::GrayFrame> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = views.len().div_ceil(threads.max(1)).max(1);
    std::thread::scope(|scope| {
        let workers: Vec<_> = views
            .chunks(chunk)
            .map(|part| {
                scope.spawn(move || {
                    part.iter()
                        .map(|(_, position, rotation, seed)| {
                            render(config, pattern, size, position, rotation, *seed)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|worker| {
                worker
                    .join()
                    .unwrap_or_else(|e| std::panic::resume_unwind(e))
            })
            .collect()
    })
}

/// One frame of the marker seen from `position` with camera-to-pad `rotation`.
fn render(
    config: &Config,
    pattern: &MarkerPattern,
    size: f64,
    position: &Vector3<f64>,
    rotation: &Matrix3<f64>,
    seed: u64,
) -> touchdown_formats::image_io::GrayFrame {
    let options = FrameOptions {
        width: WIDTH,
        height: HEIGHT,
        background: if config.textured_ground {
            Background::Texture {
                mean: 110.0,
                amplitude: 40.0,
                scale_px: 48.0,
            }
        } else {
            Background::Flat(110.0)
        },
        blur_sigma: config.blur_sigma,
        noise_sigma: config.noise_sigma,
        seed,
        supersampling: config.supersampling,
        ..FrameOptions::default()
    };
    // X_cam = R^T (X_pad - c).
    let pad_to_camera = rotation.transpose();
    let translation = -(pad_to_camera * position);
    let r = |i: usize, j: usize| pad_to_camera[(i, j)];
    let mut scene = Scene::new(options);
    scene.camera = render_camera();
    scene.markers.push(SceneMarker {
        pattern: pattern.clone(),
        pose: PlanePose {
            rotation: [
                [r(0, 0), r(0, 1), r(0, 2)],
                [r(1, 0), r(1, 1), r(1, 2)],
                [r(2, 0), r(2, 1), r(2, 2)],
            ],
            translation: [translation.x, translation.y, translation.z],
        },
        size,
        margin_cells: 1.0,
    });
    scene.render().frame
}
