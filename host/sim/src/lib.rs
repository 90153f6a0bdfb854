//! The landing simulator: a textured ground plane with the pad at true size, seen through
//! the calibrated camera of a flying vehicle, with the optics and sensor effects that make
//! real frames hard, and the exact truth of every frame.
//!
//! - [`world`]: the ground plane z = 0 of the pad frame: the printed pad ([`pad`]), a
//!   procedural texture ([`texture`]), sun and sky, a shadow edge, an occluding blob.
//! - [`camera`]: the core's camera model (intrinsics + Brown-Conrady distortion) in `f64`,
//!   its mount, the camera pose of a vehicle state, and the per-pixel rays.
//! - [`raster`]: area-sampled rendering of radiance (uniform footprints sampled once,
//!   everything else supersampled), averaged over sub-frame poses for motion blur.
//! - [`sensor`]: vignetting, lens blur and defocus, exposure (fixed or auto), flare,
//!   blooming, shot and read noise, 8-bit quantisation with clipping.
//! - [`trajectory`]: smooth seeded flights whose attitude follows their acceleration.
//! - [`effects`]: the error sources between the vehicle and its camera
//!   ([`effects::FlightEffects`]): rolling-shutter readout, vibration on the mount, mount
//!   misalignment.
//! - [`scenario`]: the named scenarios (`paper`, `lateral`, `descent`, `landing`, `sun`,
//!   `shadow`, `occlusion`).
//! - [`warp`]: a second image model ([`Renderer::Warp`], chosen per simulator with
//!   [`Simulator::with_renderer`]): a pre-rasterised world sampled through a homography per
//!   row with box-filtered footprints, motion blur as the footprint's sweep, its own PSFs and
//!   sensor response; fast enough for wall-clock frames, and differently made, for checking the
//!   detector on images it was not tuned on.
//! - [`render`]: the test renderer, single frames of printed markers on a plane through an
//!   ideal pinhole camera, for the detector's tests.
//! - [`math`]: the `f64` vectors, rotations and homographies both use; `noise` (private):
//!   their Gaussian sensor noise and value-noise textures.
//!
//! [`Simulator`] renders a scenario frame by frame; `touchdown simulate` writes the frames as
//! a recording ([`touchdown_formats::recording`]). Everything is a pure function of the
//! scenario and its seed: the same seed gives the same bytes, whatever the thread count.
//!
//! What this crate is not: it detects nothing and scores nothing (that is the core and
//! `touchdown-eval`), and it has no command line (`touchdown-cli`). A library of its own so
//! that the command line, the evaluation and the tests render the same frames from one
//! definition, and so that its random numbers (rand) stay out of the file parsers.
//!
//! Timing: a frame's time is the middle of its exposure, and its truth is the camera pose at
//! that instant. Motion blur averages poses spread evenly over the exposure; their number
//! follows how far the image moves during it (one sub-frame per half pixel, at most
//! [`MAX_SUBFRAMES`]), so a camera that does not move gets exactly one, the truth pose.
//!
//! Rolling shutter (the camera's `line_time_us` > 0, [`effects`]): row `v` is exposed
//! `(v - (height - 1) / 2) * line_time` after the frame's time, so the frame's time and truth
//! are the middle row's exposure middle. Every row is rendered over its own poses (its own
//! exposure window, shifted by its row time, with the vehicle moving and turning during the
//! readout and the camera vibrating), a homography per row and sub-frame; every row gets the
//! sub-frame count of the fastest-moving row. [`Simulator::marker_corners_rolling_shutter`]
//! gives where the marker corners land in such a frame. The camera pose is the vehicle's
//! through the true mount and the camera's vibration on it (camera-to-body =
//! `vibration(t) mount`); [`Simulator::vehicle_attitude`] is the body's attitude alone, what
//! an autopilot would measure.
//! An exposure never spans a jump of the trajectory ([`trajectory::Profile::Jump`]): the
//! part of it on the far side of the jump is cut off, so the frame sees only the side its
//! middle (its truth) is on, never a double exposure of two places.

pub mod camera;
pub mod effects;
pub mod math;
mod noise;
pub mod pad;
pub mod pad_motion;
pub mod psf;
pub mod raster;
pub mod render;
pub mod scenario;
pub mod sensor;
pub mod texture;
pub mod trajectory;
pub mod warp;
pub mod world;

use camera::{CameraMount, CameraPose, RayMap};
use math::{matrix_to_quat, mul, Quat};
use raster::RowPoses;
use scenario::Scenario;
use touchdown_formats::image_io::GrayFrame;
use world::World;

pub use warp::{Renderer, WarpOptics};

/// Most sub-frames averaged for motion blur.
pub const MAX_SUBFRAMES: usize = 24;
/// Image motion per sub-frame, pixels.
pub const SUBFRAME_STEP_PX: f64 = 0.5;
/// Length of the pieces of an exposure whose image motion is summed when the camera
/// vibrates, seconds: ten per cycle of the fastest (200 Hz) vibration, eight per 4 ms.
pub const VIBRATION_MOTION_STEP_S: f64 = 0.0005;
/// Rows, top to bottom, whose exposure's motion sets the sub-frame count with a rolling
/// shutter.
pub const MOTION_ROWS: usize = 9;
/// Fixed-point steps of [`Simulator::marker_corners_rolling_shutter`].
pub const ROLLING_SHUTTER_ITERATIONS: usize = 6;

pub use touchdown_formats::recording::CameraTruth;

/// The truth (`frames.csv` columns) of a camera pose: quaternion with `w >= 0`.
pub fn truth_of_pose(pose: &CameraPose) -> CameraTruth {
    CameraTruth {
        position: pose.position,
        orientation: matrix_to_quat(&pose.rotation),
    }
}

/// The camera pose of a truth record.
pub fn pose_of_truth(truth: &CameraTruth) -> CameraPose {
    CameraPose {
        rotation: math::quat_to_matrix(truth.orientation),
        position: truth.position,
    }
}

/// One rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFrame {
    /// Position in the recording.
    pub index: usize,
    /// Middle of the exposure, microseconds.
    pub t_us: u64,
    /// The image.
    pub image: GrayFrame,
    /// The camera pose at `t_us` (with a rolling shutter: the middle row's exposure middle).
    pub truth: CameraTruth,
    /// The vehicle's true attitude at `t_us`, body FRD to NED, without the camera's
    /// vibration ([`Simulator::vehicle_attitude`]).
    pub vehicle_attitude: Quat,
    /// Set-point label, if any.
    pub label: Option<String>,
    /// Sub-frames averaged for motion blur (1 = none; always 1 with [`Renderer::Warp`], which
    /// blurs by sweeping each pixel's footprint instead).
    pub subframes: usize,
}

/// Renders the frames of a scenario.
#[derive(Debug, Clone)]
pub struct Simulator {
    /// What is rendered.
    pub scenario: Scenario,
    /// The world built from it.
    pub world: World,
    rays: RayMap,
    threads: usize,
    /// The warp renderer's pre-rasterised world, built by [`Simulator::with_renderer`]; `None`:
    /// the raster renderer.
    warp: Option<std::sync::Arc<warp::WarpScene>>,
    warp_optics: WarpOptics,
    /// The raster renderer's lens blur in place of the scenario's Gaussian
    /// ([`Simulator::with_lens_psfs`]); `None`: the scenario's.
    raster_psfs: Option<Vec<psf::Psf>>,
}

/// A 64-bit mix of two numbers (splitmix64 finaliser), for per-frame seeds.
fn mix(a: u64, b: u64) -> u64 {
    let mut z = a ^ b.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Simulator {
    /// Prepares a scenario (undistorts every pixel corner once).
    pub fn new(scenario: Scenario) -> Self {
        let mut world = World::new(
            scenario.pad.clone(),
            texture::GroundTexture::new(scenario.ground, mix(scenario.seed, 0x67726f756e64)),
        );
        world.lighting = scenario.lighting;
        world.occluder = scenario.occluder;
        let rays = RayMap::new(&scenario.camera);
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let warp_optics = WarpOptics::of_scenario(&scenario);
        Simulator {
            scenario,
            world,
            rays,
            threads,
            warp: None,
            warp_optics,
            raster_psfs: None,
        }
    }

    /// Renders with `renderer` ([`Renderer::Raster`] unless told). Choosing
    /// [`Renderer::Warp`] rasterises the world once, here, on the simulator's threads (the
    /// ground's texture is most of it): set [`Simulator::with_threads`] first.
    pub fn with_renderer(mut self, renderer: Renderer) -> Self {
        if renderer == Renderer::Raster {
            self.warp = None;
        } else if self.warp.is_none() {
            let (w, h) = (self.scenario.camera.width(), self.scenario.camera.height());
            self.warp = Some(std::sync::Arc::new(warp::WarpScene::new(
                &self.world,
                &self.rays,
                w,
                h,
                self.threads,
            )));
        }
        self
    }

    /// The warp renderer's optics and response ([`WarpOptics::of_scenario`] unless told);
    /// the raster renderer ignores them.
    pub fn with_warp_optics(mut self, optics: WarpOptics) -> Self {
        self.warp_optics = optics;
        self
    }

    /// The lens's blur as `psfs`, applied in turn to the radiance, in place of the scenario's
    /// lens blur ([`sensor::Optics::blur_sigma_px`]) with either renderer: the defocus with
    /// distance, motion blur, vignetting and sensor stay the scenario's (so a flight can be
    /// replayed through a lens it was not tuned to on both image models). Sets the warp
    /// model's [`WarpOptics::psfs`]: give [`Simulator::with_warp_optics`] first.
    pub fn with_lens_psfs(mut self, psfs: Vec<psf::Psf>) -> Self {
        self.warp_optics.psfs = psfs.clone();
        self.raster_psfs = Some(psfs);
        self
    }

    /// The image model in use.
    pub fn renderer(&self) -> Renderer {
        if self.warp.is_some() {
            Renderer::Warp
        } else {
            Renderer::Raster
        }
    }

    /// Uses `threads` threads per frame (the result does not depend on it).
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.scenario.frames.len()
    }

    /// The camera pose at `t` seconds in the pad's frame: the vehicle's, relative to the pad
    /// where it is at `t` ([`pad_motion::PadMotion::relative`]), through the (true) mount,
    /// turned by the camera's vibration on it at `t`.
    pub fn camera_pose(&self, t: f64) -> CameraPose {
        let state = self.scenario.pad_motion.relative(t, &self.vehicle_state(t));
        let vibration = &self.scenario.vibration;
        if vibration.is_none() {
            return CameraPose::of_vehicle(state.position, &state.attitude, &self.scenario.mount);
        }
        let mount = CameraMount {
            rotation: mul(&vibration.rotation(t), &self.scenario.mount.rotation),
        };
        CameraPose::of_vehicle(state.position, &state.attitude, &mount)
    }

    /// The vehicle in the world at `t` seconds: the trajectory's state, carried along the
    /// pad's drive when the scenario's flight follows a moving pad
    /// ([`Scenario::flight_follows_pad`], [`pad_motion::PadMotion::carry`]).
    pub fn vehicle_state(&self, t: f64) -> trajectory::VehicleState {
        let state = self.scenario.trajectory.state(t);
        if self.scenario.flight_follows_pad {
            self.scenario.pad_motion.carry(t, &state)
        } else {
            state
        }
    }

    /// The vehicle's true attitude at `t` seconds: body FRD to NED (the simulator's NED:
    /// north = pad +y, east = pad +x, down = pad -z), without the camera's vibration, as a
    /// unit quaternion `[w, x, y, z]` with `w >= 0`.
    pub fn vehicle_attitude(&self, t: f64) -> Quat {
        matrix_to_quat(&self.vehicle_state(t).attitude)
    }

    /// Rolling shutter: the time from one row's exposure to the next row's, seconds (0 for
    /// a global shutter), from the camera's `line_time_us`.
    pub fn line_time_s(&self) -> f64 {
        let line_us = f64::from(self.scenario.camera.model.line_time_us);
        if line_us.is_finite() && line_us > 0.0 {
            line_us * 1e-6
        } else {
            0.0
        }
    }

    /// When row `row` (pixels from the top, fractional rows allowed) of the frame at `t` is
    /// exposed: `t + (row - (height - 1) / 2) * line_time`, the middle of its exposure, held
    /// on this side of the trajectory's jumps (the crate docs: no frame spans one).
    pub fn row_time(&self, t: f64, row: f64) -> f64 {
        let line = self.line_time_s();
        if line == 0.0 {
            return t;
        }
        let middle = 0.5 * (self.scenario.camera.height() as f64 - 1.0);
        let (start, end) = self.scenario.trajectory.continuous_span(t);
        let last_before_end = (end - trajectory::JUMP_GUARD_S).max(t);
        (t + (row - middle) * line).min(last_before_end).max(start)
    }

    /// How far the image moves during an exposure from `open` to `close`. A smooth flight
    /// moves along a straight line over a few milliseconds, so the motion from the first
    /// pose to the last is the motion; a vibrating camera swings back and forth within an
    /// exposure (a 100 Hz jitter turns around in 5 ms), so its motion is the path through
    /// poses [`VIBRATION_MOTION_STEP_S`] apart.
    fn exposure_motion(&self, open: f64, close: f64) -> f64 {
        if self.scenario.vibration.is_none() {
            return self.image_path(&[self.camera_pose(open), self.camera_pose(close)]);
        }
        let steps = ((close - open) / VIBRATION_MOTION_STEP_S)
            .ceil()
            .clamp(1.0, 256.0) as usize;
        let poses: Vec<CameraPose> = (0..=steps)
            .map(|k| self.camera_pose(open + (close - open) * k as f64 / steps as f64))
            .collect();
        self.image_path(&poses)
    }

    /// How far (pixels) the image travels through `poses`: the ground points seen at a 3x3
    /// grid of image points from the first pose, followed through the others; the longest
    /// of their paths.
    fn image_path(&self, poses: &[CameraPose]) -> f64 {
        let cam = &self.scenario.camera;
        let (w, h) = (cam.width() as f64, cam.height() as f64);
        let Some(first) = poses.first() else {
            return 0.0;
        };
        let ha = first.ground_homography();
        let mut worst = 0.0f64;
        for fy in [0.0, 0.5, 1.0] {
            for fx in [0.0, 0.5, 1.0] {
                let (u, v) = (fx * (w - 1.0), fy * (h - 1.0));
                let Some((x, y)) = cam.undistort(u, v) else {
                    continue;
                };
                let Some((gx, gy)) = crate::math::apply_homography(&ha, x, y) else {
                    continue;
                };
                let mut previous = [u, v];
                let mut path = 0.0;
                for pose in poses.iter().skip(1) {
                    if let Some(p) = cam.project(pose.to_camera([gx, gy, 0.0])) {
                        path +=
                            ((p[0] - previous[0]).powi(2) + (p[1] - previous[1]).powi(2)).sqrt();
                        previous = p;
                    }
                }
                worst = worst.max(path);
            }
        }
        worst
    }

    /// The exposure of the frame at `t`, seconds: `exposure_time_s` centred on `t`, cut at
    /// the trajectory's jumps on either side (see the crate docs). With a rolling shutter
    /// this is the middle row's; [`Simulator::row_exposure_window`] gives any row's.
    pub fn exposure_window(&self, t: f64) -> (f64, f64) {
        self.exposure_window_at(t, t, self.scenario.exposure_time_s)
    }

    /// The exposure of row `row` of the frame at `t` exposed for `exposure_s` seconds:
    /// centred on [`Simulator::row_time`], cut at the jumps around the frame's time.
    pub fn row_exposure_window(&self, t: f64, row: f64, exposure_s: f64) -> (f64, f64) {
        self.exposure_window_at(t, self.row_time(t, row), exposure_s)
    }

    fn exposure_window_at(&self, t: f64, middle: f64, exposure_s: f64) -> (f64, f64) {
        let e = exposure_s.max(0.0);
        let (start, end) = self.scenario.trajectory.continuous_span(t);
        let last_before_end = end - trajectory::JUMP_GUARD_S;
        (
            (middle - 0.5 * e).max(start),
            (middle + 0.5 * e).min(last_before_end).max(middle),
        )
    }

    /// Sub-frames averaged for the frame at `t` exposed for `exposure_s` seconds (the
    /// scenario's own is [`Scenario::exposure_time_s`]): one per [`SUBFRAME_STEP_PX`] of image
    /// motion during the exposure (at most [`MAX_SUBFRAMES`]), the worst of the rows
    /// [`MOTION_ROWS`] evenly spread from top to bottom with a rolling shutter (every row
    /// gets as many, so the blur is sampled alike over the frame).
    pub fn subframe_count(&self, t: f64, exposure_s: f64) -> usize {
        let h = self.scenario.camera.height();
        let middle = 0.5 * (h as f64 - 1.0);
        let rows: Vec<f64> = if self.line_time_s() == 0.0 || h < 2 {
            vec![middle]
        } else {
            (0..MOTION_ROWS)
                .map(|k| k as f64 / (MOTION_ROWS - 1) as f64 * (h - 1) as f64)
                .collect()
        };
        let mut motion = 0.0f64;
        for row in rows {
            let (open, close) = self.row_exposure_window(t, row, exposure_s);
            if close - open > 0.0 {
                motion = motion.max(self.exposure_motion(open, close));
            }
        }
        ((motion / SUBFRAME_STEP_PX).ceil() as usize).clamp(1, MAX_SUBFRAMES)
    }

    /// The `n` poses averaged for row `row` of the frame at `t` exposed for `exposure_s`
    /// seconds: evenly spread over its exposure, or the pose at its time alone for `n = 1`.
    pub fn row_exposure_poses(
        &self,
        t: f64,
        row: f64,
        n: usize,
        exposure_s: f64,
    ) -> Vec<CameraPose> {
        let (open, close) = self.row_exposure_window(t, row, exposure_s);
        let e = close - open;
        if n <= 1 || e <= 0.0 {
            return vec![self.camera_pose(self.row_time(t, row)); n.max(1)];
        }
        (0..n)
            .map(|k| self.camera_pose(open + (k as f64 + 0.5) / n as f64 * e))
            .collect()
    }

    /// The poses averaged for the frame at `t` exposed for `exposure_s` seconds (one when the
    /// image does not move); with a rolling shutter, the middle row's.
    pub fn exposure_poses(&self, t: f64, exposure_s: f64) -> Vec<CameraPose> {
        let middle = 0.5 * (self.scenario.camera.height() as f64 - 1.0);
        let n = self.subframe_count(t, exposure_s);
        self.row_exposure_poses(t, middle, n, exposure_s)
    }

    /// The poses every row of the frame at `t` exposed for `exposure_s` seconds is averaged
    /// over.
    pub fn row_poses(&self, t: f64, exposure_s: f64) -> RowPoses {
        let n = self.subframe_count(t, exposure_s);
        if self.line_time_s() == 0.0 {
            return RowPoses::global(self.exposure_poses(t, exposure_s));
        }
        let h = self.scenario.camera.height();
        let mut poses = Vec::with_capacity(h * n);
        for y in 0..h {
            poses.extend(self.row_exposure_poses(t, y as f64, n, exposure_s));
        }
        RowPoses::per_row(n, poses)
    }

    /// Renders frame `index`; `None` past the end.
    pub fn render(&self, index: usize) -> Option<SimFrame> {
        self.render_exposed(index, None)
    }

    /// Renders frame `index` with the exposure a controller set for it (`None`: the
    /// scenario's own, [`Scenario::exposure_time_s`] and its sensor's [`sensor::Exposure`]):
    /// the exposure time is what motion blurs over and, with the sensor's sensitivity and the
    /// analog gain, what sets the grey levels ([`sensor::Exposure::Manual`]). `None` past the
    /// end.
    pub fn render_exposed(
        &self,
        index: usize,
        manual: Option<sensor::ManualExposure>,
    ) -> Option<SimFrame> {
        let plan = self.scenario.frames.get(index)?;
        Some(self.render_frame(index, plan.t_us, plan.label.clone(), manual))
    }

    /// Renders the view at `t_us` on the scenario's trajectory, planned frame or not, with the
    /// scenario's exposure; `index` numbers the frame and seeds its sensor noise (each index
    /// its own draw). For a caller that decides its frame times as it goes (`touchdown sitl`
    /// against a running SITL): nothing is added to [`Scenario::frames`].
    pub fn render_at(&self, t_us: u64, index: usize) -> SimFrame {
        self.render_frame(index, t_us, None, None)
    }

    fn render_frame(
        &self,
        index: usize,
        t_us: u64,
        label: Option<String>,
        manual: Option<sensor::ManualExposure>,
    ) -> SimFrame {
        let t = t_us as f64 * 1e-6;
        let (exposure_s, sensor) = match manual {
            Some(m) => (
                m.exposure_s,
                sensor::Sensor {
                    exposure: sensor::Exposure::Manual(m),
                    ..self.scenario.sensor
                },
            ),
            None => (self.scenario.exposure_time_s, self.scenario.sensor),
        };
        let middle = self.camera_pose(t);
        let s = &self.scenario;
        let (w, h) = (s.camera.width(), s.camera.height());
        let (pixels, subframes) = match &self.warp {
            // The warp model blurs the motion within its one pass: no sub-frames.
            Some(scene) => (
                warp::render(
                    self,
                    scene,
                    &self.rays,
                    &self.warp_optics,
                    &warp::Exposure {
                        t,
                        exposure_s,
                        sensor: &sensor,
                        noise_seed: mix(s.seed, index as u64 + 1),
                    },
                    self.threads,
                ),
                1,
            ),
            None => self.render_raster(t, exposure_s, &sensor, &middle, index),
        };
        SimFrame {
            index,
            t_us,
            image: GrayFrame {
                width: w,
                height: h,
                pixels,
            },
            truth: truth_of_pose(&middle),
            vehicle_attitude: self.vehicle_attitude(t),
            label,
            subframes,
        }
    }

    /// The raster model's pixels of the frame at `t` (s) and its motion-blur sub-frame count.
    fn render_raster(
        &self,
        t: f64,
        exposure_s: f64,
        sensor: &sensor::Sensor,
        middle: &CameraPose,
        index: usize,
    ) -> (Vec<u8>, usize) {
        let s = &self.scenario;
        let (w, h) = (s.camera.width(), s.camera.height());
        let poses = self.row_poses(t, exposure_s);
        let subframes = poses.subframes();
        // The sub-frames already average over the footprint's motion: fewer sub-samples each.
        let supersampling = if subframes > 1 {
            ((s.supersampling as f64 / (subframes as f64).sqrt()).round() as usize).max(2)
        } else {
            s.supersampling
        };
        let radiance = raster::render_radiance(
            &self.world,
            &self.rays,
            w,
            h,
            &poses,
            supersampling,
            self.threads,
        );
        let distance = middle.axis_distance_to_ground();
        let (blur, psfs) = match &self.raster_psfs {
            Some(psfs) => (
                s.optics.defocus_sigma(s.camera.fx(), distance),
                psfs.as_slice(),
            ),
            None => (s.optics.blur_sigma(s.camera.fx(), distance), &[][..]),
        };
        let pixels = sensor::expose(
            radiance,
            w,
            h,
            &self.rays.cos_off_axis,
            &s.optics,
            sensor,
            blur,
            psfs,
            mix(s.seed, index as u64 + 1),
        );
        (pixels, subframes)
    }

    /// Where each pad marker's outer corners (top-left, top-right, bottom-right, bottom-left)
    /// appear for a camera pose, pixels (distortion included); `None` for a marker with a
    /// corner behind the camera.
    pub fn marker_corners(&self, pose: &CameraPose) -> Vec<Option<[[f64; 2]; 4]>> {
        self.world
            .pad
            .markers
            .iter()
            .map(|m| {
                let c = m.corners();
                let p0 = self.scenario.camera.project(pose.to_camera(c[0]))?;
                let p1 = self.scenario.camera.project(pose.to_camera(c[1]))?;
                let p2 = self.scenario.camera.project(pose.to_camera(c[2]))?;
                let p3 = self.scenario.camera.project(pose.to_camera(c[3]))?;
                Some([p0, p1, p2, p3])
            })
            .collect()
    }
}

impl Simulator {
    /// Where each pad marker's outer corners appear in the frame at `t` with the rolling
    /// shutter: each corner at the camera pose of the row it lands on (the row's exposure
    /// middle, [`Simulator::row_time`]), found by [`ROLLING_SHUTTER_ITERATIONS`] fixed-point
    /// steps from the frame-time pose (the row moves by the image's row speed times the line
    /// time per step, a few hundredths of a pixel per pixel: the steps converge to far below
    /// a thousandth of a pixel). Equal to [`Simulator::marker_corners`] of
    /// [`Simulator::camera_pose`]`(t)` for a global shutter. `None` for a marker with a
    /// corner behind the camera.
    pub fn marker_corners_rolling_shutter(&self, t: f64) -> Vec<Option<[[f64; 2]; 4]>> {
        let frame_pose = self.camera_pose(t);
        let rolling = self.line_time_s() > 0.0;
        let camera = &self.scenario.camera;
        let see = |corner: math::Vec3| -> Option<[f64; 2]> {
            let mut p = camera.project(frame_pose.to_camera(corner))?;
            if rolling {
                for _ in 0..ROLLING_SHUTTER_ITERATIONS {
                    let pose = self.camera_pose(self.row_time(t, p[1]));
                    p = camera.project(pose.to_camera(corner))?;
                }
            }
            Some(p)
        };
        self.world
            .pad
            .markers
            .iter()
            .map(|m| {
                let c = m.corners();
                Some([see(c[0])?, see(c[1])?, see(c[2])?, see(c[3])?])
            })
            .collect()
    }
}

impl Simulator {
    /// How many pad markers frame `index` shows whole: all four outer corners (where the
    /// rolling shutter puts them, [`Simulator::marker_corners_rolling_shutter`]) at least
    /// `margin_px` inside the image and every side at least `min_side_px` long. `None` past
    /// the end. For scoring a detector over the frames it could have decoded: a marker cut
    /// by the image's edge, or too small to find, is no miss of the detector's.
    pub fn markers_in_view(&self, index: usize, margin_px: f64, min_side_px: f64) -> Option<usize> {
        let plan = self.scenario.frames.get(index)?;
        let (w, h) = (
            self.scenario.camera.width() as f64,
            self.scenario.camera.height() as f64,
        );
        let inside = |p: &[f64; 2]| {
            p[0] >= margin_px
                && p[1] >= margin_px
                && p[0] <= w - 1.0 - margin_px
                && p[1] <= h - 1.0 - margin_px
        };
        let side = |a: &[f64; 2], b: &[f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
        let whole = self
            .marker_corners_rolling_shutter(plan.t_us as f64 * 1e-6)
            .into_iter()
            .flatten()
            .filter(|c| {
                c.iter().all(inside) && (0..4).all(|i| side(&c[i], &c[(i + 1) % 4]) >= min_side_px)
            })
            .count();
        Some(whole)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames of the paper scenario whose exposure reached into the previous set point
    /// before the jumps were explicit: the first frame of each hover but the first.
    fn first_frames_of_hovers(scenario: &Scenario) -> Vec<usize> {
        (1..scenario.frames.len())
            .filter(|&k| scenario.frames[k].label != scenario.frames[k - 1].label)
            .collect()
    }

    #[test]
    fn no_paper_frame_is_exposed_at_two_set_points() {
        let simulator = Simulator::new(Scenario::named("paper", 1).expect("paper scenario"));
        let firsts = first_frames_of_hovers(&simulator.scenario);
        assert_eq!(firsts.len(), 17, "18 hovers");
        for (k, plan) in simulator.scenario.frames.iter().enumerate() {
            let t = plan.t_us as f64 * 1e-6;
            let truth = simulator.camera_pose(t).position;
            // The hover wobbles by centimetres; the set points are metres apart.
            for pose in simulator.exposure_poses(t, simulator.scenario.exposure_time_s) {
                let distance = math::norm(math::sub(pose.position, truth));
                assert!(
                    distance < 0.05,
                    "frame {k}: a sub-frame {distance:.2} m from its truth"
                );
            }
        }
    }

    #[test]
    fn a_frame_next_to_a_jump_sees_its_own_side_only() {
        let mut scenario = Scenario::named("paper", 1).expect("paper scenario");
        // The first frame of the 10 m hover, with the jump moved onto its middle: its
        // exposure is cut at the jump, so it sees the 10 m set point alone.
        let k = first_frames_of_hovers(&scenario)[0];
        let t = scenario.frames[k].t_us as f64 * 1e-6;
        for segment in &mut scenario.trajectory.segments {
            if segment.profile == trajectory::Profile::Jump && segment.t0 < t {
                segment.t0 = t;
                segment.t1 = t;
            }
        }
        let simulator = Simulator::new(scenario);
        let (open, close) = simulator.exposure_window(t);
        assert_eq!(open, t);
        assert!((close - t - 0.5 * simulator.scenario.exposure_time_s).abs() < 1e-9);
        for pose in simulator.exposure_poses(t, simulator.scenario.exposure_time_s) {
            assert!((pose.position[2] - 10.0).abs() < 0.1, "{:?}", pose.position);
        }
    }

    #[test]
    fn a_hover_frame_is_the_render_of_its_own_pose() {
        // Frame 32, the first at 15 m, used to be the 10 m and 15 m markers superimposed.
        let scenario = Scenario::named("paper", 1).expect("paper scenario");
        let still = Scenario {
            exposure_time_s: 0.0,
            ..scenario.clone()
        };
        let index = 32;
        let frame = Simulator::new(scenario).render(index).expect("frame 32");
        let alone = Simulator::new(still).render(index).expect("frame 32");
        assert_eq!(frame.truth, alone.truth);
        let (a, b) = (&frame.image.pixels, &alone.image.pixels);
        let mean_difference = a
            .iter()
            .zip(b)
            .map(|(&p, &q)| (i32::from(p) - i32::from(q)).abs() as f64)
            .sum::<f64>()
            / a.len() as f64;
        // The same noise (seeded per frame) on both: only the blur of the hover's wobble
        // during 4 ms could differ, well below a grey level.
        assert!(
            mean_difference < 0.5,
            "mean |difference| {mean_difference:.2} grey levels, {} sub-frames",
            frame.subframes
        );
    }

    #[test]
    fn markers_in_view_counts_whole_markers_only() {
        // The paper's hover shows its pad whole at the first set point.
        let paper = Simulator::new(Scenario::named("paper", 1).unwrap());
        assert!(paper.markers_in_view(0, 1.0, 8.0).unwrap() >= 1);
        // Nothing is in view if it must be larger than the image.
        assert_eq!(paper.markers_in_view(0, 1.0, 1.0e4), Some(0));
        assert_eq!(paper.markers_in_view(paper.frame_count(), 1.0, 8.0), None);
        // lateral's tilts swing the pad out of the frame for some frames, not all.
        let lateral = Simulator::new(Scenario::named("lateral", 1).unwrap());
        let seen = (0..lateral.frame_count())
            .filter(|&k| lateral.markers_in_view(k, 1.0, 8.0).unwrap() > 0)
            .count();
        assert!(seen > 0 && seen < lateral.frame_count(), "{seen}");
    }
}
