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
//! [`score_frame`] compares a detector's output with the truth: found markers, corner errors,
//! and every detection that is not a rendered marker (a wrong id is never acceptable).
//!
//! The landing simulator ([`crate::sim`]) renders whole flights with the same sampling
//! pattern, marker patterns ([`MarkerPattern`]), blur, noise and texture lattice, adding lens
//! distortion, a ground plane in metres, motion blur and a sensor model.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::detect::Detection;
use touchdown_core::family::Family;
use touchdown_core::geometry::Point;

use crate::image_io::GrayFrame;

/// A 3x3 matrix, row-major rows.
pub(crate) type Mat3 = [[f64; 3]; 3];

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
        mul3(&camera.matrix(), &extrinsic)
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
            rotation: mul3(&tilt, &mul3(&roll, &facing)),
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
        let (x, y) = apply(&self.grid_to_image, col, row)?;
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

/// A marker a frame was rendered with, for [`score_frame`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expected<'a> {
    /// Family name ([`Family::name`]).
    pub family: &'a str,
    /// Id within the family.
    pub id: u16,
    /// Where it is.
    pub truth: MarkerTruth,
}

/// How the detections of one frame compare with what was rendered.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameScore {
    /// Per expected marker, in order: the corner error of its detection (max over the four
    /// corners, pixels), `None` when it was missed.
    pub corner_errors: Vec<Option<f32>>,
    /// Detections that are no rendered marker (wrong family, wrong id, or nowhere near the
    /// marker with that id), described for the failure message.
    pub wrong: Vec<String>,
    /// Further detections of a marker that was already found.
    pub duplicates: usize,
}

impl FrameScore {
    /// Number of expected markers found.
    pub fn found(&self) -> usize {
        self.corner_errors.iter().filter(|e| e.is_some()).count()
    }
}

/// Matches detections to the rendered markers: a detection matches when its family name and
/// id are those of a rendered marker whose true centre is within half the marker's shortest
/// side (at least 2 px) of the reported centre. Everything else is "wrong".
pub fn score_frame(
    detections: &[Detection],
    families: &[&Family<'_>],
    expected: &[Expected<'_>],
) -> FrameScore {
    let mut score = FrameScore {
        corner_errors: vec![None; expected.len()],
        ..FrameScore::default()
    };
    for d in detections {
        let name = families.get(d.family as usize).map_or("?", |f| f.name);
        let hit = expected.iter().position(|e| {
            e.family == name
                && e.id == d.id
                && e.truth.center.distance(d.center) <= (0.5 * e.truth.min_side_px()).max(2.0)
        });
        match hit {
            Some(k) => {
                let error = expected[k].truth.corner_error(&d.corners);
                match &mut score.corner_errors[k] {
                    Some(previous) => {
                        score.duplicates += 1;
                        *previous = previous.min(error);
                    }
                    slot => *slot = Some(error),
                }
            }
            None => score.wrong.push(format!(
                "{name} id {} at ({:.1}, {:.1}) hamming {} margin {:.2}",
                d.id, d.center.x, d.center.y, d.hamming, d.decision_margin
            )),
        }
    }
    score
}

/// Grid coordinates (col, row in cells from the grid's top-left corner) to pixels.
fn grid_to_image(marker: &SceneMarker, camera: &PinholeCamera) -> Mat3 {
    let n = marker.pattern.grid as f64;
    let cell = marker.size / marker.pattern.edge_cells() as f64;
    let half = 0.5 * n * cell;
    // Plane x grows with the column, plane y (up) shrinks with the row.
    let grid_to_plane = [[cell, 0.0, -half], [0.0, -cell, half], [0.0, 0.0, 1.0]];
    mul3(&marker.pose.homography(camera), &grid_to_plane)
}

fn truth_of(g: &Mat3, marker: &SceneMarker) -> MarkerTruth {
    let n = marker.pattern.grid as f64;
    let b = marker.pattern.border_ring as f64;
    let at = |col: f64, row: f64| {
        apply(g, col, row)
            .map(|(x, y)| Point::new(x as f32, y as f32))
            .unwrap_or(Point::new(f32::NAN, f32::NAN))
    };
    MarkerTruth {
        corners: [at(b, b), at(n - b, b), at(n - b, n - b), at(b, n - b)],
        center: at(0.5 * n, 0.5 * n),
        grid_to_image: *g,
    }
}

fn paint_background(buffer: &mut [f32], w: usize, h: usize, background: &Background, seed: u64) {
    match *background {
        Background::Flat(level) => buffer.fill(level),
        Background::Texture {
            mean,
            amplitude,
            scale_px,
        } => {
            let texture = ValueNoise::new(seed, scale_px);
            for y in 0..h {
                for x in 0..w {
                    let v = mean + amplitude * texture.at(x as f64, y as f64) as f32;
                    if let Some(p) = buffer.get_mut(y * w + x) {
                        *p = v;
                    }
                }
            }
        }
    }
}

/// Draws one marker over `buffer` with area sampling (see the module docs).
fn composite_marker(
    buffer: &mut [f32],
    w: usize,
    h: usize,
    marker: &SceneMarker,
    g: &Mat3,
    options: &FrameOptions,
) {
    let Some(inverse) = invert3(g) else {
        return;
    };
    let pattern = &marker.pattern;
    let n = pattern.grid as f64;
    let lo = -marker.margin_cells.max(0.0);
    let hi = n - lo;
    let level = |white: bool| if white { options.white } else { options.black };
    // Level of a grid point, or None off the paper.
    let sample = |col: f64, row: f64| -> Option<f32> {
        if !(col >= lo && col < hi && row >= lo && row < hi) {
            return None;
        }
        if col >= 0.0 && row >= 0.0 && col < n && row < n {
            Some(level(pattern.is_white(row as usize, col as usize)))
        } else {
            Some(options.white)
        }
    };
    // A whole integer cell is uniform when it lies entirely on or entirely off the paper.
    let uniform_cell = |i: f64, j: f64| -> Option<Option<f32>> {
        let off = i + 1.0 <= lo || i >= hi || j + 1.0 <= lo || j >= hi;
        let on = i >= lo && i + 1.0 <= hi && j >= lo && j + 1.0 <= hi;
        if off {
            Some(None)
        } else if on {
            Some(sample(i + 0.5, j + 0.5))
        } else {
            None
        }
    };

    let Some((x0, x1, y0, y1)) = paper_bbox(g, lo, hi, w, h) else {
        return;
    };
    let s = options.supersampling.max(1);
    // Sub-sample (i, j) sits in stratum (i, j) of an s x s grid, shifted inside it so that all
    // s^2 samples have distinct x and distinct y ("n-rooks"): an axis-aligned edge then sees
    // s^2 coverage levels instead of s, so its rendered position is off by at most 1/(2 s^2)
    // pixel (1/128 for s = 8) rather than 1/(2 s).
    let fine = 1.0 / (s * s) as f64;
    let mut top: Vec<Option<(f64, f64)>> = Vec::with_capacity(x1 - x0 + 2);
    let mut bottom: Vec<Option<(f64, f64)>> = Vec::with_capacity(x1 - x0 + 2);
    let map_row = |out: &mut Vec<Option<(f64, f64)>>, y: f64| {
        out.clear();
        for x in x0..=x1 + 1 {
            out.push(apply(&inverse, x as f64 - 0.5, y));
        }
    };
    map_row(&mut top, y0 as f64 - 0.5);
    for y in y0..=y1 {
        map_row(&mut bottom, y as f64 + 0.5);
        for x in x0..=x1 {
            let k = x - x0;
            let corners = [top[k], top[k + 1], bottom[k], bottom[k + 1]];
            let Some(pixel) = buffer.get_mut(y * w + x) else {
                continue;
            };
            // Fast path: the footprint's image is the convex hull of its mapped corners (all
            // in front of the camera), so four corners in one uniform cell mean a uniform pixel.
            if let [Some(a), Some(b), Some(c), Some(d)] = corners {
                let (i, j) = (a.0.floor(), a.1.floor());
                if [b, c, d]
                    .iter()
                    .all(|p| p.0.floor() == i && p.1.floor() == j)
                {
                    if let Some(value) = uniform_cell(i, j) {
                        if let Some(v) = value {
                            *pixel = v;
                        }
                        continue;
                    }
                }
            }
            let mut sum = 0.0f64;
            let mut covered = 0usize;
            for sy in 0..s {
                for sx in 0..s {
                    let px = x as f64 - 0.5 + ((sx * s + sy) as f64 + 0.5) * fine;
                    let py = y as f64 - 0.5 + ((sy * s + sx) as f64 + 0.5) * fine;
                    if let Some(v) = apply(&inverse, px, py).and_then(|(c, r)| sample(c, r)) {
                        sum += v as f64;
                        covered += 1;
                    }
                }
            }
            let total = (s * s) as f64;
            let alpha = covered as f64 / total;
            *pixel = (sum / total + (1.0 - alpha) * *pixel as f64) as f32;
        }
        std::mem::swap(&mut top, &mut bottom);
    }
}

/// Pixel bounds (inclusive) that may see the paper, or `None` when it is off the frame.
fn paper_bbox(
    g: &Mat3,
    lo: f64,
    hi: f64,
    w: usize,
    h: usize,
) -> Option<(usize, usize, usize, usize)> {
    if w == 0 || h == 0 {
        return None;
    }
    let mut bounds = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for (c, r) in [(lo, lo), (hi, lo), (hi, hi), (lo, hi)] {
        match apply(g, c, r) {
            Some((x, y)) => {
                bounds = [
                    bounds[0].min(x),
                    bounds[1].max(x),
                    bounds[2].min(y),
                    bounds[3].max(y),
                ];
            }
            // Part of the paper is behind the camera: search the whole frame, the per-sample
            // test sorts it out.
            None => return Some((0, w - 1, 0, h - 1)),
        }
    }
    let clamp = |v: f64, max: usize| v.max(0.0).min(max as f64) as usize;
    let (xmin, xmax) = ((bounds[0] - 1.0).floor(), (bounds[1] + 1.0).ceil());
    let (ymin, ymax) = ((bounds[2] - 1.0).floor(), (bounds[3] + 1.0).ceil());
    if xmax < 0.0 || ymax < 0.0 || xmin > (w - 1) as f64 || ymin > (h - 1) as f64 {
        return None;
    }
    Some((
        clamp(xmin, w - 1),
        clamp(xmax, w - 1),
        clamp(ymin, h - 1),
        clamp(ymax, h - 1),
    ))
}

/// Separable Gaussian blur, edges replicated.
pub(crate) fn gaussian_blur(buffer: &mut [f32], w: usize, h: usize, sigma: f64) {
    let radius = (4.0 * sigma).ceil().max(1.0) as isize;
    let mut kernel: Vec<f32> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    let mut scratch = vec![0.0f32; w * h];
    let clamp = |v: isize, len: usize| v.clamp(0, len as isize - 1) as usize;
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (k, weight) in kernel.iter().enumerate() {
                let sx = clamp(x as isize + k as isize - radius, w);
                acc += weight * buffer.get(y * w + sx).copied().unwrap_or(0.0);
            }
            if let Some(out) = scratch.get_mut(y * w + x) {
                *out = acc;
            }
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (k, weight) in kernel.iter().enumerate() {
                let sy = clamp(y as isize + k as isize - radius, h);
                acc += weight * scratch.get(sy * w + x).copied().unwrap_or(0.0);
            }
            if let Some(out) = buffer.get_mut(y * w + x) {
                *out = acc;
            }
        }
    }
}

fn quantise(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// Standard normal deviates by the Box-Muller transform, two per pair of uniforms.
#[derive(Default)]
pub(crate) struct NormalPairs {
    spare: Option<f64>,
}

impl NormalPairs {
    pub(crate) fn next(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        // 1 - u keeps the logarithm's argument in (0, 1].
        let u1 = 1.0 - rng.random::<f64>();
        let u2 = rng.random::<f64>();
        let radius = (-2.0 * u1.ln()).sqrt();
        let angle = std::f64::consts::TAU * u2;
        self.spare = Some(radius * angle.sin());
        radius * angle.cos()
    }
}

/// Smooth deterministic noise: bilinear-smoothstep interpolation of hashed lattice values,
/// summed over octaves. A pure function of position and seed, so the same ground looks the
/// same in every frame that shows it.
struct ValueNoise {
    seed: u64,
    scales: Vec<(f64, f64)>,
}

impl ValueNoise {
    fn new(seed: u64, coarsest_px: f64) -> Self {
        let mut scales = Vec::new();
        let mut scale = coarsest_px.max(2.0);
        let mut amplitude = 1.0;
        while scale >= 2.0 && scales.len() < 8 {
            scales.push((scale, amplitude));
            scale *= 0.5;
            amplitude *= 0.5;
        }
        let total: f64 = scales.iter().map(|s| s.1).sum();
        scales.iter_mut().for_each(|s| s.1 /= total);
        ValueNoise { seed, scales }
    }

    /// Roughly in [-1, 1].
    fn at(&self, x: f64, y: f64) -> f64 {
        let mut v = 0.0;
        for (octave, &(scale, amplitude)) in self.scales.iter().enumerate() {
            let (u, w) = (x / scale, y / scale);
            let (iu, iw) = (u.floor(), w.floor());
            let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
            let (fu, fw) = (smooth(u - iu), smooth(w - iw));
            let lattice = |a: f64, b: f64| self.lattice(octave as u64, a as i64, b as i64);
            let top = lattice(iu, iw) * (1.0 - fu) + lattice(iu + 1.0, iw) * fu;
            let bottom = lattice(iu, iw + 1.0) * (1.0 - fu) + lattice(iu + 1.0, iw + 1.0) * fu;
            v += amplitude * (top * (1.0 - fw) + bottom * fw);
        }
        v
    }

    fn lattice(&self, octave: u64, a: i64, b: i64) -> f64 {
        lattice_hash(self.seed, octave, a, b)
    }
}

/// A hash of (seed, octave, lattice point) mapped to [-1, 1] (splitmix64 finaliser); the
/// simulator's ground textures use the same lattice.
pub(crate) fn lattice_hash(seed: u64, octave: u64, a: i64, b: i64) -> f64 {
    let mut z = seed
        .wrapping_add(octave.wrapping_mul(0x9e37_79b9_7f4a_7c15))
        .wrapping_add((a as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9))
        .wrapping_add((b as u64).wrapping_mul(0x94d0_49bb_1331_11eb));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

pub(crate) fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for (r, row) in c.iter_mut().enumerate() {
        for (k, out) in row.iter_mut().enumerate() {
            *out = (0..3).map(|j| a[r][j] * b[j][k]).sum();
        }
    }
    c
}

pub(crate) fn invert3(m: &Mat3) -> Option<Mat3> {
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    if !det.is_finite() || det.abs() <= 1e-300 {
        return None;
    }
    Some(adj.map(|row| row.map(|v| v / det)))
}

/// Applies a homography; `None` at or behind the horizon (w <= 0: the plane point is not in
/// front of the camera, or the pixel's ray misses the plane's front side).
pub(crate) fn apply(m: &Mat3, x: f64, y: f64) -> Option<(f64, f64)> {
    let w = m[2][0] * x + m[2][1] * y + m[2][2];
    if w.is_nan() || w <= 1e-12 {
        return None;
    }
    Some((
        (m[0][0] * x + m[0][1] * y + m[0][2]) / w,
        (m[1][0] * x + m[1][1] * y + m[1][2]) / w,
    ))
}

/// Rotation by `angle` radians about the unit `axis` (Rodrigues).
fn rotation_about(axis: &[f64; 3], angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = *axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(grid: usize) -> MarkerPattern {
        MarkerPattern::from_cells(&vec![false; grid * grid], grid, 0).unwrap()
    }

    fn white_ground(width: usize, height: usize) -> FrameOptions {
        FrameOptions {
            background: Background::Flat(255.0),
            black: 0.0,
            white: 255.0,
            ..FrameOptions::sized(width, height)
        }
    }

    fn close(a: Point, x: f32, y: f32, tol: f32) -> bool {
        (a.x - x).abs() <= tol && (a.y - y).abs() <= tol
    }

    #[test]
    fn facing_marker_truth_is_the_placed_square() {
        let p = Placement::new(40.3, 31.7, 20.0);
        let (_, t) = render_cells(&[false; 16], 4, 0, &p, &white_ground(80, 60)).unwrap();
        let e = 10.0;
        assert!(
            close(t.corners[0], 40.3 - e, 31.7 - e, 1e-4),
            "{:?}",
            t.corners
        );
        assert!(close(t.corners[1], 40.3 + e, 31.7 - e, 1e-4));
        assert!(close(t.corners[2], 40.3 + e, 31.7 + e, 1e-4));
        assert!(close(t.corners[3], 40.3 - e, 31.7 + e, 1e-4));
        assert!(close(t.center, 40.3, 31.7, 1e-4));
    }

    #[test]
    fn rotation_is_clockwise_in_the_image() {
        let p = Placement::new(40.0, 30.0, 20.0).rotated(90.0);
        let (_, t) = render_cells(&[false; 16], 4, 0, &p, &white_ground(80, 60)).unwrap();
        // The canonical top-left corner moves to the top-right of the image.
        assert!(close(t.corners[0], 50.0, 20.0, 1e-4), "{:?}", t.corners);
        assert!(close(t.corners[1], 50.0, 40.0, 1e-4), "{:?}", t.corners);
    }

    #[test]
    fn border_ring_sets_the_edge_and_the_margin_is_paper() {
        // 4x4 grid, ring 1 is the edge: 2 cells span 20 px, so cells are 10 px; the white
        // quiet ring and one cell of margin extend 20 px beyond the edge.
        let mut cells = [true; 16];
        for k in [5, 6, 9, 10] {
            cells[k] = false;
        }
        let p = Placement::new(50.0, 50.0, 20.0);
        let (frame, t) = render_cells(&cells, 4, 1, &p, &FrameOptions::sized(101, 101)).unwrap();
        assert!(close(t.corners[0], 40.0, 40.0, 1e-4));
        assert_eq!(
            t.grid_point(0.0, 0.0).map(|q| close(q, 30.0, 30.0, 1e-4)),
            Some(true)
        );
        let at = |x: usize, y: usize| frame.pixels[y * 101 + x];
        assert_eq!(at(50, 50), 20); // black square
        assert_eq!(at(35, 50), 235); // quiet ring
        assert_eq!(at(22, 50), 235); // extra paper
        assert_eq!(at(15, 50), 128); // ground
    }

    #[test]
    fn edge_pixels_are_area_weighted() {
        // Edges at x = 15.0 and 25.0 fall on pixel centres: those pixels are half covered.
        let p = Placement::new(20.0, 20.0, 10.0).with_margin(0.0);
        let (frame, _) = render_cells(&[false; 4], 2, 0, &p, &white_ground(41, 41)).unwrap();
        let at = |x: usize, y: usize| frame.pixels[y * 41 + x];
        assert_eq!(at(20, 20), 0);
        assert_eq!(at(14, 20), 255);
        assert_eq!(at(15, 20), 128);
        assert_eq!(at(25, 20), 128);
        assert_eq!(at(15, 15), 191); // a quarter covered: 255 * 3 / 4 = 191.25
                                     // Edge at x = 15.25: pixel 15 is 25 % covered.
        let p = Placement::new(20.25, 20.0, 10.0).with_margin(0.0);
        let (frame, _) = render_cells(&[false; 4], 2, 0, &p, &white_ground(41, 41)).unwrap();
        assert_eq!(frame.pixels[20 * 41 + 15], 191);
    }

    /// Total darkness and its centroid equal the area and centroid of the truth quad at any
    /// rotation and tilt: the pixels and the truth come from the same mapping, and pixel
    /// (0, 0) is the centre of the top-left pixel.
    #[test]
    fn darkness_matches_the_truth_quad_area_and_centroid() {
        for (rotation, tilt, axis) in [
            (0.0, 0.0, 0.0),
            (31.0, 0.0, 0.0),
            (12.0, 55.0, 70.0),
            (200.0, 40.0, -20.0),
        ] {
            let p = Placement::new(60.4, 55.9, 40.0)
                .rotated(rotation)
                .tilted(tilt, axis)
                .with_margin(0.0);
            let (frame, t) = render_cells(&[false; 9], 3, 0, &p, &white_ground(121, 111)).unwrap();
            let (mut dark, mut mx, mut my) = (0.0f64, 0.0f64, 0.0f64);
            for (k, &v) in frame.pixels.iter().enumerate() {
                let d = (255 - v) as f64 / 255.0;
                dark += d;
                mx += d * (k % 121) as f64;
                my += d * (k / 121) as f64;
            }
            // Shoelace area and centroid of the corner polygon.
            let c = t.corners.map(|q| (q.x as f64, q.y as f64));
            let (mut area, mut cx, mut cy) = (0.0, 0.0, 0.0);
            for k in 0..4 {
                let (a, b) = (c[k], c[(k + 1) % 4]);
                let cross = a.0 * b.1 - b.0 * a.1;
                area += 0.5 * cross;
                cx += (a.0 + b.0) * cross;
                cy += (a.1 + b.1) * cross;
            }
            let (cx, cy) = (cx / (6.0 * area), cy / (6.0 * area));
            let area = area.abs();
            assert!(
                (dark - area).abs() < 0.002 * area + 1.0,
                "rotation {rotation} tilt {tilt}: {dark} vs {area}"
            );
            let (ex, ey) = (mx / dark - cx, my / dark - cy);
            assert!(
                ex.abs() < 0.01 && ey.abs() < 0.01,
                "rotation {rotation} tilt {tilt}: centroid off by ({ex}, {ey})"
            );
        }
    }

    #[test]
    fn tilt_foreshortens_and_keeps_the_centre() {
        let p = Placement::new(80.0, 60.0, 40.0).tilted(60.0, 0.0);
        let (_, t) = render_cells(&[false; 9], 3, 0, &p, &white_ground(160, 120)).unwrap();
        assert!(close(t.center, 80.0, 60.0, 1e-4));
        // Axis along x: the vertical extent shrinks to about cos(60) = half.
        let height = (t.corners[3].y + t.corners[2].y - t.corners[0].y - t.corners[1].y) * 0.5;
        assert!((height - 20.0).abs() < 2.0, "{height}");
        assert!(t.min_side_px() < 21.0);
    }

    #[test]
    fn code_pattern_is_the_canonical_grid() {
        use touchdown_core::family::parse_family;
        const TWO: &str = "# family mini\n# cells 8\n\
            1111111110000001101011011001010110001101100010011000000111111111\n\
            1111111110000001101001011011010110101101101010011000000111111111\n";
        let mut codes = [0u64; 2];
        let mut ids = [0u16; 2];
        let family = parse_family(TWO, "mini", &mut codes)
            .unwrap()
            .into_family(&codes, &mut ids)
            .unwrap();
        let pattern = MarkerPattern::from_code(&family, 1).unwrap();
        let line = TWO.lines().nth(3).unwrap();
        for (k, ch) in line.chars().enumerate() {
            assert_eq!(pattern.is_white(k / 8, k % 8), ch == '1', "cell {k}");
        }
        assert_eq!(pattern.edge_cells(), 6);
        assert!(MarkerPattern::from_code(&family, 2).is_none());
    }

    #[test]
    fn rendering_is_deterministic_and_seeded() {
        let mut options = FrameOptions {
            noise_sigma: 5.0,
            blur_sigma: 1.0,
            background: Background::Texture {
                mean: 120.0,
                amplitude: 60.0,
                scale_px: 32.0,
            },
            seed: 7,
            ..FrameOptions::sized(64, 48)
        };
        let p = Placement::new(30.0, 20.0, 16.0).rotated(10.0);
        let a = render_markers(&[(square(3), p)], &options);
        let b = render_markers(&[(square(3), p)], &options);
        assert_eq!(a, b);
        options.seed = 8;
        let c = render_markers(&[(square(3), p)], &options);
        assert_ne!(a.frame, c.frame);
    }

    #[test]
    fn noise_has_the_requested_spread() {
        let options = FrameOptions {
            noise_sigma: 8.0,
            ..FrameOptions::sized(200, 200)
        };
        let frame = Scene::new(options).render().frame;
        let n = frame.pixels.len() as f64;
        let mean = frame.pixels.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = frame
            .pixels
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        assert!((mean - 128.0).abs() < 0.2, "{mean}");
        // Rounding adds 1/12 of a level squared.
        assert!((var.sqrt() - 8.0).abs() < 0.15, "{}", var.sqrt());
    }

    #[test]
    fn blur_keeps_the_total_light() {
        let p = Placement::new(40.0, 40.0, 20.0).rotated(20.0);
        let sharp = render_markers(&[(square(3), p)], &white_ground(81, 81));
        let blurred = render_markers(
            &[(square(3), p)],
            &FrameOptions {
                blur_sigma: 1.5,
                ..white_ground(81, 81)
            },
        );
        let total = |f: &GrayFrame| f.pixels.iter().map(|&v| v as f64).sum::<f64>();
        let (a, b) = (total(&sharp.frame), total(&blurred.frame));
        assert!((a - b).abs() < 0.001 * a, "{a} vs {b}");
        assert_ne!(sharp.frame, blurred.frame);
    }
}
