//! Test renderer: grey frames of printed markers as a camera sees them, with exact truth.
//!
//! A [`Scene`] is a ground plane (the [`Background`]) with printed markers lying on it. Each
//! marker is a square grid of cells ([`MarkerPattern`]) printed on white paper, placed in 3-D
//! by a [`PlanePose`] and seen through a [`PinholeCamera`]; its truth (corners, centre, the
//! whole grid-to-image homography) comes from the same projective mapping the pixels are
//! drawn with, in `f64`, so it is exact.
//!
//! Image formation, in order:
//! 1. **Area sampling.** Each output pixel integrates the scene over its footprint
//!    `[x - 0.5, x + 0.5] x [y - 0.5, y + 0.5]` (pixel (0, 0) is the centre of the top-left
//!    pixel, the project convention). A pixel whose footprint maps into a single uniform cell
//!    takes that cell's level; any other pixel averages `supersampling x supersampling`
//!    stratified sub-samples taken through the inverse homography (edge positions exact to
//!    1/128 px at the default 8 x 8). So a 12-pixel marker looks as it
//!    does on a real sensor (mixed pixels at every cell edge), not aliased.
//! 2. **Optics:** a Gaussian blur of `blur_sigma` pixels.
//! 3. **Sensor:** additive Gaussian noise of `noise_sigma` grey levels, then rounding to 8
//!    bits with clipping.
//!
//! Markers are composited over the background with their sub-sample coverage as alpha, so
//! later markers in a scene lie on top of earlier ones.
//!
//! Everything is deterministic: the texture is a pure function of position and seed, the
//! noise comes from a ChaCha stream seeded by [`FrameOptions::seed`].
//!
//! Scoring a detector's output against this truth is evaluation, not rendering: it is
//! `touchdown_eval::scoring`.
//!
//! The pieces: the private submodule `raster` turns a scene into pixels (area sampling,
//! compositing, blur, quantisation); the sensor noise and the ground texture come from
//! `crate::noise`, the 3x3 (homography and rotation) arithmetic from [`crate::math`], both
//! shared with the simulator.
//!
//! The landing simulator ([`crate`]) renders whole flights with the same sampling
//! pattern, marker patterns ([`MarkerPattern`]), blur, noise and texture lattice, adding lens
//! distortion, a ground plane in metres, motion blur and a sensor model.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use touchdown_core::family::Family;
use touchdown_core::geometry::Point;

use touchdown_formats::image_io::GrayFrame;

use crate::math::{apply_homography, mul, rotation_about, Mat3};
use crate::noise::NormalPairs;

mod raster;

pub(crate) use raster::gaussian_blur;
use raster::{composite_marker, grid_to_image, paint_background, quantise, truth_of};

/// An ideal pinhole camera (no distortion yet). Pixel coordinates follow the project
/// convention: (0, 0) is the centre of the top-left pixel, x right, y down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl PinholeCamera {
    /// A camera for a `width` x `height` frame: principal point at the frame centre and a
    /// focal length equal to the larger dimension (a 53-degree field of view across it), so
    /// tilted markers show real perspective, not just an affine squeeze.
    pub fn for_frame(width: usize, height: usize) -> Self {
        let focal = width.max(height).max(1) as f64;
        PinholeCamera {
            fx: focal,
            fy: focal,
            cx: (width as f64 - 1.0) * 0.5,
            cy: (height as f64 - 1.0) * 0.5,
        }
    }

    fn matrix(&self) -> Mat3 {
        [
            [self.fx, 0.0, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ]
    }
}

/// A rigid pose of a plane in the camera frame (project conventions): the plane's own frame
/// has x right, y up and z out of the printed face towards the viewer; the camera frame has
/// x right, y down, z forward. `X_cam = rotation * X_plane + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanePose {
    /// Rotation, row-major.
    pub rotation: Mat3,
    /// Translation, in the unit of the marker size.
    pub translation: [f64; 3],
}

impl PlanePose {
    /// The homography from plane coordinates (x, y on the z = 0 plane) to pixels.
    pub fn homography(&self, camera: &PinholeCamera) -> Mat3 {
        let r = &self.rotation;
        let t = &self.translation;
        let extrinsic = [
            [r[0][0], r[0][1], t[0]],
            [r[1][0], r[1][1], t[1]],
            [r[2][0], r[2][1], t[2]],
        ];
        mul(&camera.matrix(), &extrinsic)
    }
}

/// Where a marker appears in the image, in image terms; [`Placement::pose`] turns it into the
/// 3-D pose that produces it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Image of the marker centre, pixels.
    pub center: [f64; 2],
    /// Edge of the outer black border in pixels, as it would appear untilted at the same
    /// distance (a tilted marker is foreshortened below this).
    pub edge_px: f64,
    /// In-plane rotation, degrees, clockwise as seen in the image.
    pub rotation_deg: f64,
    /// Out-of-plane tilt, degrees: the marker plane turns by this angle about a line through
    /// its centre (right-hand rule in the camera frame), 0 = facing the camera.
    pub tilt_deg: f64,
    /// Direction of the tilt axis in the image, degrees clockwise from +x.
    pub tilt_axis_deg: f64,
    /// White paper beyond the pattern's grid (which already includes the family's quiet
    /// rings), in cells. Reversed families have no quiet ring; this is their only margin.
    pub margin_cells: f64,
}

impl Placement {
    /// Facing the camera, unrotated, with one cell of extra white paper.
    pub fn new(center_x: f64, center_y: f64, edge_px: f64) -> Self {
        Placement {
            center: [center_x, center_y],
            edge_px,
            rotation_deg: 0.0,
            tilt_deg: 0.0,
            tilt_axis_deg: 0.0,
            margin_cells: 1.0,
        }
    }

    /// The same placement rotated in the image plane (clockwise, degrees).
    pub fn rotated(mut self, degrees: f64) -> Self {
        self.rotation_deg = degrees;
        self
    }

    /// The same placement tilted by `degrees` about an image-plane axis at `axis_degrees`.
    pub fn tilted(mut self, degrees: f64, axis_degrees: f64) -> Self {
        self.tilt_deg = degrees;
        self.tilt_axis_deg = axis_degrees;
        self
    }

    /// The same placement with `cells` of white paper beyond the grid.
    pub fn with_margin(mut self, cells: f64) -> Self {
        self.margin_cells = cells;
        self
    }

    /// The pose of a marker of edge `size` that `camera` sees as described: the centre on the
    /// ray through [`Placement::center`] at the depth where the untilted edge spans
    /// [`Placement::edge_px`], then the in-plane rotation, then the tilt.
    pub fn pose(&self, camera: &PinholeCamera, size: f64) -> PlanePose {
        let depth = camera.fx * size / self.edge_px;
        let translation = [
            (self.center[0] - camera.cx) / camera.fx * depth,
            (self.center[1] - camera.cy) / camera.fy * depth,
            depth,
        ];
        // Facing the camera, upright: plane x = camera x, plane y = -camera y, z towards it.
        let facing = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        // About the optical axis: with y down, a positive angle is clockwise in the image.
        let roll = rotation_about(&[0.0, 0.0, 1.0], self.rotation_deg.to_radians());
        let axis_angle = self.tilt_axis_deg.to_radians();
        let axis = [axis_angle.cos(), axis_angle.sin(), 0.0];
        let tilt = rotation_about(&axis, self.tilt_deg.to_radians());
        PlanePose {
            rotation: mul(&tilt, &mul(&roll, &facing)),
            translation,
        }
    }
}

/// A printed square pattern of cells: a family code or any cell grid (negatives,
/// checkerboards). `true` = white.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MarkerPattern {
    grid: usize,
    border_ring: usize,
    cells: Vec<bool>,
}

impl MarkerPattern {
    /// The code `id` of `family`, drawn as its canonical image (row 0 at the top); `None` for
    /// an unknown id.
    pub fn from_code(family: &Family<'_>, id: usize) -> Option<Self> {
        let n = family.grid as usize;
        let mut cells = Vec::with_capacity(n * n);
        for row in 0..n {
            for col in 0..n {
                cells.push(family.cell_is_white(id, row, col)?);
            }
        }
        Some(MarkerPattern {
            grid: n,
            border_ring: family.border_ring as usize,
            cells,
        })
    }

    /// Any `grid` x `grid` cell pattern (row-major, `true` = white). `border_ring` says which
    /// ring's outer edge is the "marker edge" that sizes and corners refer to (0 = the whole
    /// grid). `None` when the sizes do not fit.
    pub fn from_cells(cells: &[bool], grid: usize, border_ring: usize) -> Option<Self> {
        if grid == 0 || cells.len() != grid * grid || 2 * border_ring >= grid {
            return None;
        }
        Some(MarkerPattern {
            grid,
            border_ring,
            cells: cells.to_vec(),
        })
    }

    /// Cells per side.
    pub fn grid(&self) -> usize {
        self.grid
    }

    /// Index (from the outside) of the ring whose outer edge is the marker edge.
    pub fn border_ring(&self) -> usize {
        self.border_ring
    }

    /// Cells per side of the square the size and corners refer to.
    pub fn edge_cells(&self) -> usize {
        self.grid - 2 * self.border_ring
    }

    /// Whether cell (row, col) is white.
    pub fn is_white(&self, row: usize, col: usize) -> bool {
        self.cells
            .get(row * self.grid + col)
            .copied()
            .unwrap_or(true)
    }
}

/// One printed marker in a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneMarker {
    /// What is printed.
    pub pattern: MarkerPattern,
    /// Where the marker plane is.
    pub pose: PlanePose,
    /// Edge of the marker (outer edge of [`MarkerPattern::edge_cells`]), in the unit of
    /// the pose's translation.
    pub size: f64,
    /// White paper beyond the grid, cells.
    pub margin_cells: f64,
}

/// The ground the markers lie on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    /// One grey level everywhere.
    Flat(f32),
    /// Smooth random value noise (octaves from `scale_px` down to 2 px, each half the
    /// amplitude of the previous) around `mean`, peak deviation about `amplitude`. Defined in
    /// image coordinates and smooth at the pixel scale, so it is point-sampled at pixel
    /// centres.
    Texture {
        /// Mean grey level.
        mean: f32,
        /// Largest deviation from the mean, grey levels.
        amplitude: f32,
        /// Feature size of the coarsest octave, pixels.
        scale_px: f64,
    },
}

/// Everything about a frame that is not a marker: size, illumination, optics, sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOptions {
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// The ground around the markers.
    pub background: Background,
    /// Grey level of the black ink (before blur and noise).
    pub black: f32,
    /// Grey level of the white paper.
    pub white: f32,
    /// Standard deviation of the optical Gaussian blur, pixels (0 = none).
    pub blur_sigma: f64,
    /// Standard deviation of the additive sensor noise, grey levels (0 = none).
    pub noise_sigma: f64,
    /// Seed of the noise and the background texture.
    pub seed: u64,
    /// Sub-samples per pixel side where a pixel is not uniform.
    pub supersampling: usize,
}

impl Default for FrameOptions {
    /// 320x240, flat grey 128 ground, ink 20 on paper 235, no blur, no noise, 8x8 sub-samples.
    fn default() -> Self {
        FrameOptions {
            width: 320,
            height: 240,
            background: Background::Flat(128.0),
            black: 20.0,
            white: 235.0,
            blur_sigma: 0.0,
            noise_sigma: 0.0,
            seed: 0,
            supersampling: 8,
        }
    }
}

impl FrameOptions {
    /// Default options for a `width` x `height` frame.
    pub fn sized(width: usize, height: usize) -> Self {
        FrameOptions {
            width,
            height,
            ..FrameOptions::default()
        }
    }
}

/// Where a rendered marker is in the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerTruth {
    /// Outer corners of the marker edge (the black border for family codes): top-left,
    /// top-right, bottom-right, bottom-left of the canonical image, pixels.
    pub corners: [Point; 4],
    /// Image of the marker centre (not the mean of the corners under perspective).
    pub center: Point,
    /// Grid coordinates (col, row in cells; (0, 0) = top-left corner of the whole grid) to
    /// pixels.
    grid_to_image: Mat3,
}

impl MarkerTruth {
    /// Image of a point given in grid coordinates: `col`, `row` in cells from the top-left
    /// corner of the whole grid (quiet rings included). `None` behind the camera.
    pub fn grid_point(&self, col: f64, row: f64) -> Option<Point> {
        let (x, y) = apply_homography(&self.grid_to_image, col, row)?;
        Some(Point::new(x as f32, y as f32))
    }

    /// Shortest side of the corner quad, pixels.
    pub fn min_side_px(&self) -> f32 {
        (0..4)
            .map(|k| self.corners[k].distance(self.corners[(k + 1) % 4]))
            .fold(f32::INFINITY, f32::min)
    }

    /// Largest distance between a reported corner and the true one of the same index.
    pub fn corner_error(&self, corners: &[Point; 4]) -> f32 {
        self.corners
            .iter()
            .zip(corners)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f32::max)
    }
}

/// A rendered frame with the truth of each marker, in scene order.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// The frame.
    pub frame: GrayFrame,
    /// One entry per scene marker.
    pub truths: Vec<MarkerTruth>,
}

/// Markers on a ground plane, seen by a camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The camera.
    pub camera: PinholeCamera,
    /// Frame size, illumination, optics, sensor.
    pub options: FrameOptions,
    /// The markers, bottom first.
    pub markers: Vec<SceneMarker>,
}

impl Scene {
    /// An empty scene seen by [`PinholeCamera::for_frame`].
    pub fn new(options: FrameOptions) -> Self {
        Scene {
            camera: PinholeCamera::for_frame(options.width, options.height),
            options,
            markers: Vec::new(),
        }
    }

    /// Adds a marker (of unit size) where `placement` says it appears.
    pub fn place(&mut self, pattern: MarkerPattern, placement: &Placement) -> &mut Self {
        let size = 1.0;
        self.markers.push(SceneMarker {
            pattern,
            pose: placement.pose(&self.camera, size),
            size,
            margin_cells: placement.margin_cells,
        });
        self
    }

    /// Where each marker's grid lands in the image.
    pub fn truths(&self) -> Vec<MarkerTruth> {
        self.markers
            .iter()
            .map(|m| truth_of(&grid_to_image(m, &self.camera), m))
            .collect()
    }

    /// Renders the frame (see the module docs for the steps).
    pub fn render(&self) -> Rendered {
        let o = &self.options;
        let (w, h) = (o.width, o.height);
        let mut buffer = vec![0.0f32; w * h];
        paint_background(&mut buffer, w, h, &o.background, o.seed);
        for marker in &self.markers {
            let g = grid_to_image(marker, &self.camera);
            composite_marker(&mut buffer, w, h, marker, &g, o);
        }
        if o.blur_sigma > 0.0 {
            gaussian_blur(&mut buffer, w, h, o.blur_sigma);
        }
        let mut pixels = Vec::with_capacity(w * h);
        if o.noise_sigma > 0.0 {
            let mut rng = ChaCha8Rng::seed_from_u64(o.seed ^ 0x6e6f_6973_655f_7365); // "noise_se"
            let mut normals = NormalPairs::default();
            for &v in &buffer {
                let noisy = v as f64 + o.noise_sigma * normals.next(&mut rng);
                pixels.push(quantise(noisy as f32));
            }
        } else {
            pixels.extend(buffer.iter().map(|&v| quantise(v)));
        }
        Rendered {
            frame: GrayFrame {
                width: w,
                height: h,
                pixels,
            },
            truths: self.truths(),
        }
    }
}

/// Renders code `id` of `family` alone in a frame; `None` for an unknown id.
pub fn render_marker(
    family: &Family<'_>,
    id: usize,
    placement: &Placement,
    options: &FrameOptions,
) -> Option<(GrayFrame, MarkerTruth)> {
    let pattern = MarkerPattern::from_code(family, id)?;
    render_one(pattern, placement, options)
}

/// Renders an arbitrary `grid` x `grid` cell pattern (row-major, `true` = white) whose edge
/// is the outer edge of ring `border_ring`; `None` when the sizes do not fit.
pub fn render_cells(
    cells: &[bool],
    grid: usize,
    border_ring: usize,
    placement: &Placement,
    options: &FrameOptions,
) -> Option<(GrayFrame, MarkerTruth)> {
    let pattern = MarkerPattern::from_cells(cells, grid, border_ring)?;
    render_one(pattern, placement, options)
}

/// Renders several markers into one frame (later ones on top).
pub fn render_markers(markers: &[(MarkerPattern, Placement)], options: &FrameOptions) -> Rendered {
    let mut scene = Scene::new(*options);
    for (pattern, placement) in markers {
        scene.place(pattern.clone(), placement);
    }
    scene.render()
}

fn render_one(
    pattern: MarkerPattern,
    placement: &Placement,
    options: &FrameOptions,
) -> Option<(GrayFrame, MarkerTruth)> {
    let mut scene = Scene::new(*options);
    scene.place(pattern, placement);
    let rendered = scene.render();
    let truth = *rendered.truths.first()?;
    Some((rendered.frame, truth))
}

#[cfg(test)]
mod tests;
