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
//! - [`scenario`]: the named scenarios (`paper`, `lateral`, `descent`, `landing`, `sun`,
//!   `shadow`, `occlusion`).
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
//! An exposure never spans a jump of the trajectory ([`trajectory::Profile::Jump`]): the
//! part of it on the far side of the jump is cut off, so the frame sees only the side its
//! middle (its truth) is on, never a double exposure of two places.

pub mod camera;
pub mod math;
mod noise;
pub mod pad;
pub mod raster;
pub mod render;
pub mod scenario;
pub mod sensor;
pub mod texture;
pub mod trajectory;
pub mod world;

use camera::{CameraPose, RayMap};
use math::matrix_to_quat;
use scenario::Scenario;
use touchdown_formats::image_io::GrayFrame;
use world::World;

/// Most sub-frames averaged for motion blur.
pub const MAX_SUBFRAMES: usize = 24;
/// Image motion per sub-frame, pixels.
pub const SUBFRAME_STEP_PX: f64 = 0.5;

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
    /// The camera pose at `t_us`.
    pub truth: CameraTruth,
    /// Set-point label, if any.
    pub label: Option<String>,
    /// Sub-frames averaged for motion blur (1 = none).
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
        Simulator {
            scenario,
            world,
            rays,
            threads,
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

    /// The camera pose at `t` seconds.
    pub fn camera_pose(&self, t: f64) -> CameraPose {
        let state = self.scenario.trajectory.state(t);
        CameraPose::of_vehicle(state.position, &state.attitude, &self.scenario.mount)
    }

    /// How far (pixels) the image moves between two poses: the ground points seen at a 3x3
    /// grid of image points from `a`, projected through `b`.
    fn image_motion(&self, a: &CameraPose, b: &CameraPose) -> f64 {
        let cam = &self.scenario.camera;
        let (w, h) = (cam.width() as f64, cam.height() as f64);
        let ha = a.ground_homography();
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
                if let Some(p) = cam.project(b.to_camera([gx, gy, 0.0])) {
                    worst = worst.max(((p[0] - u).powi(2) + (p[1] - v).powi(2)).sqrt());
                }
            }
        }
        worst
    }

    /// The exposure of the frame at `t`, seconds: `exposure_time_s` centred on `t`, cut at
    /// the trajectory's jumps on either side (see the crate docs).
    pub fn exposure_window(&self, t: f64) -> (f64, f64) {
        let e = self.scenario.exposure_time_s.max(0.0);
        let (start, end) = self.scenario.trajectory.continuous_span(t);
        let last_before_end = end - trajectory::JUMP_GUARD_S;
        (
            (t - 0.5 * e).max(start),
            (t + 0.5 * e).min(last_before_end).max(t),
        )
    }

    /// The poses averaged for the frame at `t` (one when the image does not move).
    pub fn exposure_poses(&self, t: f64) -> Vec<CameraPose> {
        let (open, close) = self.exposure_window(t);
        let e = close - open;
        let middle = self.camera_pose(t);
        if e <= 0.0 {
            return vec![middle];
        }
        let start = self.camera_pose(open);
        let end = self.camera_pose(close);
        let motion = self.image_motion(&start, &end);
        let n = ((motion / SUBFRAME_STEP_PX).ceil() as usize).clamp(1, MAX_SUBFRAMES);
        if n == 1 {
            return vec![middle];
        }
        (0..n)
            .map(|k| self.camera_pose(open + (k as f64 + 0.5) / n as f64 * e))
            .collect()
    }

    /// Renders frame `index`; `None` past the end.
    pub fn render(&self, index: usize) -> Option<SimFrame> {
        let plan = self.scenario.frames.get(index)?;
        let t = plan.t_us as f64 * 1e-6;
        let poses = self.exposure_poses(t);
        let middle = self.camera_pose(t);
        let s = &self.scenario;
        let (w, h) = (s.camera.width(), s.camera.height());
        // The sub-frames already average over the footprint's motion: fewer sub-samples each.
        let supersampling = if poses.len() > 1 {
            ((s.supersampling as f64 / (poses.len() as f64).sqrt()).round() as usize).max(2)
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
        let blur = s
            .optics
            .blur_sigma(s.camera.fx(), middle.axis_distance_to_ground());
        let pixels = sensor::expose(
            radiance,
            w,
            h,
            &self.rays.cos_off_axis,
            &s.optics,
            &s.sensor,
            blur,
            mix(s.seed, index as u64 + 1),
        );
        Some(SimFrame {
            index,
            t_us: plan.t_us,
            image: GrayFrame {
                width: w,
                height: h,
                pixels,
            },
            truth: truth_of_pose(&middle),
            label: plan.label.clone(),
            subframes: poses.len(),
        })
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
            for pose in simulator.exposure_poses(t) {
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
        for pose in simulator.exposure_poses(t) {
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
}
