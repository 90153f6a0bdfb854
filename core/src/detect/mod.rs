//! Marker detection: grey frame in, decoded markers with sub-pixel corners out.
//!
//! What this module offers: [`Detector`] (configured by [`DetectorConfig`], with the
//! [`Method`] it runs), whose [`Detector::detect`] takes a frame ([`crate::image::GrayImage`]),
//! the families to look for ([`crate::family`]) and the caller's work memory ([`Buffers`],
//! sized by [`buffer_sizes`] or owned by a [`Workspace`]), finds the candidates and returns
//! the decoded markers, [`Detection`]s (with the frame's [`DetectStats`]; or a
//! [`DetectError`]). The markers go on to the pad fix, [`crate::pose`]. The steps below are
//! private submodules.
//!
//! ## Pipeline (one function per step, see the submodules)
//! 1. `threshold`: binarise against a local (tile min/max) threshold, so shadows and
//!    brightness gradients across the frame do not matter; pixels without local contrast are
//!    never "dark".
//! 2. `contour`: scan the binary image for the tops of dark regions and follow each
//!    region's outer boundary (Moore neighbour tracing, iterative); holes only for
//!    white-on-black families.
//! 3. `quad`: screen each boundary (length, compactness, sampled convexity, diameter), then
//!    simplify the survivors with Douglas-Peucker and keep convex four-corner shapes with
//!    sane edges and angles. A boundary that is not a quad but holds three corners of one,
//!    a marker joined at its fourth by a shadow's band or a dark stroke, has that corner
//!    placed where its two sides meet (`quad::complete`). A quick look at the rough corners
//!    (`decode::precheck`: border ring, margin, flat interior) turns down most non-markers
//!    before step 4.
//! 4. `refine`: move each edge onto the image's intensity edge with sub-pixel precision
//!    (line fits to gradient peaks) and intersect neighbouring edges for the corners.
//! 5. `decode`: map the family's cell grid through the corner homography, sample each cell
//!    centre, threshold against black/white levels learnt from the marker's own border and
//!    margin, and look the code up in all four rotations with bounded error correction.
//!    Once a frame, at its end, the largest small candidate no code was found in is read
//!    again with the blur taken out (`deblur`): a far marker's cells run together.
//! 6. De-duplicate: the same marker found twice (two contours, two families) is kept once,
//!    with the fewest corrected bits and then the largest decision margin.
//! 7. `pattern_fit`: on a far frame, where every marker is small, fit the largest markers'
//!    corners with their decoded pattern, blurred, to the pixels: the edge search of step 4
//!    is biased in scale when a cell is as narrow as the blur, or the camera's tone curve
//!    bends the blurred edges.
//!
//! ## Through the lens
//! Given the camera ([`Detector::set_camera`]; the per-frame path,
//! [`crate::pipeline::FramePipeline`], gives it its own), steps 3 to 5 work on a large marker
//! as a distortion-free lens would show it (`lens`): the boundary is fitted undistorted, the
//! edges are refined where they are straight and the cell grid is laid on the undistorted
//! marker, every point taken back into the frame's pixels, in which the corners are reported.
//!
//! ## The paper's method
//! [`Method::Paper`] reproduces the reference paper's tables. What it does differently
//! (an edge map instead of step 1, every contour traced, no quick look, corners stepped back
//! from the edge band instead of step 4, cells read as area means and matched exactly) is
//! all in `paper`, as one implementation of the private `Strategy` trait that
//! [`Detector::detect`] picks once per frame; the steps above only ask the strategy, so the
//! production path has no branches for the paper.
//!
//! ## Time
//! Every step draws from one work budget per frame
//! ([`DetectorConfig::work_budget_per_pixel`]), so no image, however hostile, costs more than
//! the budget allows; the frame is then marked [`DetectStats::truncated`]. That includes what
//! an image adds before any boundary is followed: the blocks the binarisation compared with
//! their thresholds ([`WORK_THRESHOLD_BLOCK`]; a block of flat tiles is written without being
//! read) and the words the scan tested for starts ([`WORK_SCAN_WORD`]). The prices of the
//! steps (`WORK_*`) are set from the Cortex-M7 benchmark (`bench/m7`) so that one unit is
//! about one contour step there; what each step costs, with the command that counts it, is
//! in `docs/design/detection.md` ("Work budget").
//!
//! ## Memory
//! Frame-sized work memory is lent by the caller as [`Buffers`] (sized by
//! [`buffer_sizes`]), so firmware places it where it wants and the host sizes it per image.
//! Everything else is inside [`Detector`] with capacities set by the constants below.
//!
//! | buffer | size | QVGA (320x240) | VGA (640x480) |
//! |---|---|---|---|
//! | `bitmap`: 1 bit per pixel, dark/edge | ceil(w/32) * h words | 9,600 B | 38,400 B |
//! | `visited`: 1 bit per pixel, traced boundaries | same | 9,600 B | 38,400 B |
//! | `tiles`: min and max per 4x4 tile | 2 * ceil(w/4) * ceil(h/4) B | 9,600 B | 38,400 B |
//! | `Detector` (contour of [`MAX_CONTOUR_POINTS`], detections, candidates) | fixed | ~20 KiB | ~20 KiB |
//! | total | | ~49 KiB (budget 64 KiB) | ~135 KiB (budget 160 KiB) |

//!
//! ## Layout
//! This module is the detector's public surface (configuration, buffers, results, the entry
//! [`Detector::detect`] that runs the scan). The per-candidate steps 3 to 6 are in `candidates`,
//! the two methods' choices behind the private `Strategy` trait in `strategy` (touchdown's)
//! and `paper` (the paper's).
mod candidates;
mod contour;
mod deblur;
mod decode;
mod lens;
mod paper;
mod pattern_fit;
mod quad;
mod refine;
mod strategy;
mod threshold;

use crate::camera::CameraModel;
use crate::family::Family;
use crate::geometry::Point;
use crate::image::{GrayImage, ImageRegion};

use candidates::Candidates;
use strategy::{Look, Robust, Strategy, ThresholdLevel};

/// Most markers reported per frame.
pub const MAX_DETECTIONS: usize = 64;
/// Most families searched at once.
pub const MAX_FAMILIES: usize = 8;
/// Boundary points stored for the quad fit. A longer boundary is stored as evenly spaced
/// points (every second, fourth, ... pixel: see `contour`), so markers of any size are
/// candidates (a 2,000-pixel one, 8,000 boundary steps, is fitted on every second pixel);
/// 4096 holds every pixel of a marker filling a VGA frame.
pub const MAX_CONTOUR_POINTS: usize = 4096;
/// Side of the square tiles of the local threshold, in pixels.
pub const TILE: usize = 4;

/// Boundary pixels per work unit of the screening before the quad fit
/// ([`DetectorConfig::work_budget_per_pixel`]): the area, compactness, convexity and
/// diameter tests cost about 15 Cortex-M7 instructions per boundary pixel.
pub const WORK_SCREEN_PIXELS: u32 = 4;
/// Work units of the Douglas-Peucker quad fit of a boundary that passed the screening: this
/// many, plus one per boundary pixel (its cost on the Cortex-M7: `docs/design/detection.md`,
/// "Work budget").
pub const WORK_FIT: u32 = 20;
/// Work units per boundary pixel of the search for a marker with a hidden corner
/// (`quad::complete`), on top of [`WORK_FIT`]: the diameter's two passes and a
/// simplification that follows every turn of the boundary.
pub const WORK_COMPLETION_PER_PIXEL: u32 = 2;
/// [`DetectorConfig::work_budget_per_pixel`] of [`DetectorConfig::default`], for the camera:
/// the bound on the time per frame (see [`DetectorConfig::work_budget_per_pixel`]).
///
/// Why 0.28: it is about the least that legitimate frames do not reach. None of the
/// camera-configured test frames (distortion, rendered, families, rolling shutter) is
/// truncated; the replayed scenarios stay below it but for `shadow`'s far frames (a hard
/// shadow edge across the pad on concrete, and the far marker's pattern fit), whose busiest
/// are cut after their markers were found; and the worst frames stay within twice a landing
/// frame on the Cortex-M7. The figures, with their commands: `docs/design/detection.md`
/// ("Work budget") and `docs/performance.md`. A QVGA frame (21,504 units at 0.28) gets the
/// floor, [`MIN_WORK_BUDGET`].
pub const CAMERA_WORK_BUDGET: f32 = 0.28;
/// [`DetectorConfig::work_budget_per_pixel`] of [`DetectorConfig::offline`]: fourteen times
/// the camera's, and several times what the most cluttered photo of the test data needs
/// (`docs/design/detection.md`, "Work budget").
pub const OFFLINE_WORK_BUDGET: f32 = 4.0;
/// Work units charged for starting a boundary (the call, the first neighbour search, the
/// bookkeeping): a frame of thousands of two-pixel specks costs that much more than its steps.
pub const WORK_TRACE_START: u32 = 2;
/// Work units of a block of 32 x 4 pixels that the binarisation compared with its
/// thresholds (a block with a tile of contrast; one of flat tiles is written without
/// reading its pixels): a compared block costs about six contour steps more in the
/// binarisation than a flat one on the Cortex-M7 (`docs/design/detection.md`, "Work
/// budget").
pub const WORK_THRESHOLD_BLOCK: u32 = 6;
/// Work units of a bitmap word the scan looks at for boundary starts (one with a dark pixel
/// whose west neighbour is light and not on a followed boundary): its neighbourhood's six
/// words and the start test, about one contour step on the Cortex-M7.
pub const WORK_SCAN_WORD: u32 = 1;

/// Work units of the quick look at a candidate before its refinement (border ring, margin
/// and interior at the rough corners: about 80 nearest-pixel samples).
pub const WORK_PRECHECK: u32 = 30;
/// Work units of a refined and read candidate besides its image reads (the cell grid's
/// homography, the black and white level fits, the code look-up: about 20,000 Cortex-M7
/// instructions).
pub const WORK_CANDIDATE: u32 = 300;
/// Twice the work units per image read of a refined candidate: a bilinear sample on an edge
/// profile or in a cell, or a point mapped through the cell grid's homography, costs about
/// two contour steps with its share of the bookkeeping on the Cortex-M7
/// (`docs/design/detection.md`, "Work budget").
pub const WORK_PER_SAMPLE_X2: u32 = 3;
/// Smallest work budget of a frame, whatever its size: the budget of a QVGA frame, just
/// above what the benchmark's QVGA frame of the nested pad with all six markers in view
/// (`qvga-multi-6`, textured ground) uses, and within twice the QVGA landing frame on the
/// Cortex-M7 for a frame that spends all of it on noise or look-alikes (the figures:
/// `docs/design/detection.md`, "Work budget", and `docs/performance.md`).
pub const MIN_WORK_BUDGET: u32 = 25_000;

/// Sizes of the caller-provided buffers for a frame size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferSizes {
    /// `u32` words of `bitmap` and of `visited` each.
    pub bitmap_words: usize,
    /// Bytes of `tiles`.
    pub tile_bytes: usize,
}

/// Buffer sizes for a `width` x `height` frame.
pub const fn buffer_sizes(width: usize, height: usize) -> BufferSizes {
    BufferSizes {
        bitmap_words: width.div_ceil(32) * height,
        tile_bytes: 2 * width.div_ceil(TILE) * height.div_ceil(TILE),
    }
}

/// Frame-sized work memory lent to [`Detector::detect`].
#[derive(Debug)]
pub struct Buffers<'a> {
    /// One bit per pixel: dark (or edge) pixels.
    pub bitmap: &'a mut [u32],
    /// One bit per pixel: boundary pixels already followed.
    pub visited: &'a mut [u32],
    /// Per-tile statistics and scratch rows.
    pub tiles: &'a mut [u8],
}

/// Owned work memory for frames up to a fixed size; see [`QvgaWorkspace`], [`VgaWorkspace`].
#[derive(Debug)]
pub struct Workspace<const BITMAP_WORDS: usize, const TILE_BYTES: usize> {
    bitmap: [u32; BITMAP_WORDS],
    visited: [u32; BITMAP_WORDS],
    tiles: [u8; TILE_BYTES],
}

impl<const BITMAP_WORDS: usize, const TILE_BYTES: usize> Workspace<BITMAP_WORDS, TILE_BYTES> {
    /// Zeroed work memory (a `const fn`, so it can initialise a `static`).
    pub const fn new() -> Self {
        Workspace {
            bitmap: [0; BITMAP_WORDS],
            visited: [0; BITMAP_WORDS],
            tiles: [0; TILE_BYTES],
        }
    }

    /// Lends the memory to the detector.
    pub fn buffers(&mut self) -> Buffers<'_> {
        Buffers {
            bitmap: &mut self.bitmap,
            visited: &mut self.visited,
            tiles: &mut self.tiles,
        }
    }
}

impl<const BITMAP_WORDS: usize, const TILE_BYTES: usize> Default
    for Workspace<BITMAP_WORDS, TILE_BYTES>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Work memory for frames up to 320x240.
pub type QvgaWorkspace =
    Workspace<{ buffer_sizes(320, 240).bitmap_words }, { buffer_sizes(320, 240).tile_bytes }>;
/// Work memory for frames up to 640x480.
pub type VgaWorkspace =
    Workspace<{ buffer_sizes(640, 480).bitmap_words }, { buffer_sizes(640, 480).tile_bytes }>;

/// Which pipeline to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Method {
    /// touchdown's detector: local threshold, sub-pixel edges, learnt cell threshold,
    /// error-correcting decode.
    Robust,
    /// The paper's pipeline (section 2.2), kept to reproduce its tables: normalise, Gaussian
    /// blur, 3x3 gradients, contours, Douglas-Peucker, perspective sampling of the cells,
    /// binarisation at the patch mean, exact template comparison.
    Paper,
}

/// Detector settings. [`DetectorConfig::default`] is what the firmware and CLI use.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DetectorConfig {
    /// Pipeline variant.
    pub method: Method,
    /// Smallest local contrast (max - min grey level in a 12x12 neighbourhood) for a pixel
    /// to be classified; flat regions are never dark. A neighbourhood whose darkest level is
    /// at most a quarter of its lightest (ink on paper in a deep shadow) needs only 12.
    pub min_contrast: u8,
    /// Smallest accepted marker edge, in pixels.
    pub min_edge_px: f32,
    /// Upper bound on corrected bits (each family's own bound applies too).
    pub max_hamming: u8,
    /// Refine edges to sub-pixel precision.
    pub refine_edges: bool,
    /// Step 7: when every marker of a frame is small (at most 40 pixels across: a far pad),
    /// fit the corners of the largest one with its decoded pattern, blurred, to the
    /// pixels. It removes the edge search's scale bias on small markers (in a direction set
    /// by the blur; its size: `docs/design/detection.md`, step 7), which is the pose's largest
    /// error far from the pad. Needs `refine_edges`.
    pub fit_small_markers: bool,
    /// Smallest decision margin (0..1: mean distance of the data cells from the threshold,
    /// relative to half the black/white contrast) for a detection to be reported.
    pub min_decision_margin: f32,
    /// Work allowed per frame, per pixel of the frame, in **work units**: bounds the time per
    /// frame on any image. One unit is one contour-following step (about 55 Cortex-M7
    /// instructions); the binarisation's blocks with contrast cost [`WORK_THRESHOLD_BLOCK`]
    /// each and the scan's words with a start to test [`WORK_SCAN_WORD`]; screening a
    /// boundary for the quad fit costs one unit per [`WORK_SCREEN_PIXELS`] of it (and
    /// [`WORK_FIT`] plus one per pixel for the fit itself), a quick look at a candidate
    /// [`WORK_PRECHECK`] and refining and reading a candidate [`WORK_CANDIDATE`] plus its image
    /// reads ([`WORK_PER_SAMPLE_X2`]; see their docs for the measurements). When the budget
    /// runs out, detection stops and [`DetectStats::truncated`] is set. A frame gets at least
    /// [`MIN_WORK_BUDGET`].
    ///
    /// The default, [`CAMERA_WORK_BUDGET`], is for the camera board: it holds the worst
    /// frames of the Cortex-M7 benchmark (uniform noise, hundreds of small squares, a sheet of
    /// marker look-alikes) within twice the cost of a typical landing frame
    /// (`scripts/m7_check.sh`). Replayed scenarios stay below it, the `shadow` scenario's
    /// busiest frames reach it (see [`CAMERA_WORK_BUDGET`]). Cluttered photos with dozens of
    /// markers use more (AprilTag 3's photo of 25 tags on cubes): [`DetectorConfig::offline`]
    /// is the setting for photos on a host. Not a number, or below 0, counts as 0.
    pub work_budget_per_pixel: f32,
    /// Candidate quads refined and read per frame. A quad costs far more than a traced
    /// pixel (sub-pixel edges, the cell grid, the look-up: ~80,000 Cortex-M7 instructions
    /// for a small one). When reached, detection stops and [`DetectStats::truncated`] is set.
    /// A landing frame has a few (each marker, a few look-alikes in the clutter): the default
    /// leaves a wide margin, but on a frame with more candidates than this, markers after
    /// the budget (in raster order of their top edge) are not searched. Quads without a dark
    /// border in a light margin, or whose interior is one flat tone (tiles, windows, dark
    /// squares; for families without a uniform code), are turned down before they count.
    pub max_candidates: u16,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig {
            method: Method::Robust,
            min_contrast: 20,
            min_edge_px: 7.0,
            max_hamming: u8::MAX,
            refine_edges: true,
            fit_small_markers: true,
            min_decision_margin: 0.25,
            work_budget_per_pixel: CAMERA_WORK_BUDGET,
            max_candidates: 48,
        }
    }
}

impl DetectorConfig {
    /// The default detector with the [`OFFLINE_WORK_BUDGET`]: for photos on a host (the
    /// `touchdown detect` command), where searching a cluttered frame to the end matters
    /// more than a bound on the time per frame.
    pub fn offline() -> Self {
        DetectorConfig {
            work_budget_per_pixel: OFFLINE_WORK_BUDGET,
            ..DetectorConfig::default()
        }
    }

    /// The paper's method with its fixed choices. It follows every contour of its edge map
    /// (holes and the edge bands' both sides), several times the work of ours, and keeps the
    /// [`OFFLINE_WORK_BUDGET`] so its tables reproduce.
    pub fn paper() -> Self {
        DetectorConfig {
            method: Method::Paper,
            work_budget_per_pixel: OFFLINE_WORK_BUDGET,
            max_hamming: 0,
            refine_edges: true,
            min_decision_margin: 0.0,
            ..DetectorConfig::default()
        }
    }
}

/// One decoded marker.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Detection {
    /// Index of the family in the slice given to [`Detector::detect`].
    pub family: u8,
    /// Marker id within the family.
    pub id: u16,
    /// Number of bits the decode corrected.
    pub hamming: u8,
    /// Outer corners of the black border: top-left, top-right, bottom-right, bottom-left of
    /// the marker's canonical image, in pixels ((0, 0) = centre of the top-left pixel).
    pub corners: [Point; 4],
    /// Image of the marker centre.
    pub center: Point,
    /// 0..1: how clearly the data cells were black or white (1 = at the learnt levels).
    pub decision_margin: f32,
    /// Black-to-white contrast of the marker, grey levels.
    pub contrast: f32,
}

/// Counters of the last frame, for logs and benchmarks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DetectStats {
    /// Boundaries followed.
    pub contours: u32,
    /// Boundaries that simplified to a convex quad of a polarity some family is printed in
    /// (dark outline, or a light hole for white-on-black families): the candidates.
    pub quads: u32,
    /// Quads whose cells read as a valid marker grid (black border, white margin, clear
    /// cells) for some family's layout, before the code look-up.
    pub bordered: u32,
    /// Quads decoded to an id (before de-duplication).
    pub decoded: u32,
    /// Candidates refined and read: the quads that the quick look at their rough corners
    /// (border ring, margin, flat interior) did not turn down; at most
    /// [`DetectorConfig::max_candidates`].
    pub refined: u32,
    /// Detections whose corners came from the pattern fit (step 7).
    pub fitted: u32,
    /// Small candidates read a second time with the blur taken out (step 5, `deblur`): the
    /// largest one whose first read found no code, at most one a frame.
    pub deblurred: u32,
    /// Contour-following steps spent.
    pub trace_steps: u32,
    /// Work units spent ([`DetectorConfig::work_budget_per_pixel`]): the binarisation's
    /// compared blocks, the scan's words, the steps and everything after.
    pub work: u32,
    /// The work or candidate budget ran out, or a fixed capacity filled: some of the frame was
    /// not searched.
    pub truncated: bool,
}

/// Why a frame could not be searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DetectError {
    /// The buffers are smaller than [`buffer_sizes`] of the frame.
    BuffersTooSmall,
    /// No family, or more than [`MAX_FAMILIES`].
    BadFamilyCount,
    /// A family's layout is inconsistent ([`Family::check_layout`]).
    BadFamily,
    /// The region of [`Detector::detect_region`] is empty or reaches outside the image.
    RegionOutsideImage,
}

/// The marker detector. Holds the settings, the fixed-capacity candidate storage and the
/// results of the last frame.
#[derive(Debug)]
pub struct Detector {
    config: DetectorConfig,
    contour: [contour::Pixel; MAX_CONTOUR_POINTS],
    detections: heapless::Vec<Detection, MAX_DETECTIONS>,
    stats: DetectStats,
    /// The lens the frames come through, if known ([`Detector::set_camera`]).
    camera: Option<CameraModel>,
}

impl Detector {
    /// A detector with the given settings.
    pub fn new(config: DetectorConfig) -> Self {
        Detector {
            config,
            contour: [contour::Pixel::default(); MAX_CONTOUR_POINTS],
            detections: heapless::Vec::new(),
            stats: DetectStats::default(),
            camera: None,
        }
    }

    /// The camera the frames come from, or `None` (the default). With a camera whose lens
    /// distorts, each long boundary is undistorted before the quad fit, so markers whose
    /// edges the lens bends are found (see `lens`), and the edges of markers of about 30
    /// pixels and more are refined and their cells read through the lens (`refine`,
    /// `decode`); the corners reported stay in the frame's own (distorted) pixels either way.
    /// A model that does not validate counts as none.
    pub fn set_camera(&mut self, camera: Option<CameraModel>) {
        self.camera = camera.filter(|c| c.validate().is_ok() && c.has_distortion());
    }

    /// The camera set with [`Detector::set_camera`] (`None` also for a distortion-free one,
    /// which changes nothing).
    pub fn camera(&self) -> Option<&CameraModel> {
        self.camera.as_ref()
    }

    /// The settings.
    pub fn config(&self) -> &DetectorConfig {
        &self.config
    }

    /// Changes the settings (takes effect on the next frame).
    pub fn set_config(&mut self, config: DetectorConfig) {
        self.config = config;
    }

    /// Counters of the last frame.
    pub fn stats(&self) -> &DetectStats {
        &self.stats
    }

    /// The detections of the last frame.
    pub fn detections(&self) -> &[Detection] {
        &self.detections
    }

    /// Searches `image` for markers of `families`; the result stays readable through
    /// [`Detector::detections`] until the next call. The last search's markers choose this
    /// one's row order (none or one small marker: the frame's middle quarter first), which
    /// matters only where the work budget cuts the search short: a frame's result depends on
    /// the frame before it only then.
    pub fn detect(
        &mut self,
        image: &GrayImage<'_>,
        families: &[&Family<'_>],
        buffers: &mut Buffers<'_>,
    ) -> Result<&[Detection], DetectError> {
        let camera = self.camera;
        self.search(
            image,
            camera.as_ref(),
            ThresholdLevel::MidLevel,
            families,
            buffers,
        )?;
        Ok(&self.detections)
    }

    /// Searches `region` of `image` again, binarised at the ratio of the levels instead of
    /// the mid-level (see `threshold`: across a hard shadow), and returns what it finds there
    /// in the frame's pixels. This is the per-frame path's second look where it lost a pad it
    /// was tracking ([`crate::pipeline::FramePipeline::process`]); the work budget and every
    /// step are those of [`Detector::detect`], scaled to the region. The detections and
    /// statistics of the frame's own search are replaced.
    pub fn detect_region(
        &mut self,
        image: &GrayImage<'_>,
        region: &ImageRegion,
        families: &[&Family<'_>],
        buffers: &mut Buffers<'_>,
    ) -> Result<&[Detection], DetectError> {
        let Some(view) = image.view(region) else {
            self.detections.clear();
            self.stats = DetectStats::default();
            return Err(DetectError::RegionOutsideImage);
        };
        let (dx, dy) = (region.x as f32, region.y as f32);
        // The lens seen from the region: the same camera with its centre moved.
        let camera = self.camera.map(|c| CameraModel {
            cx: c.cx - dx,
            cy: c.cy - dy,
            ..c
        });
        self.search(
            &view,
            camera.as_ref(),
            ThresholdLevel::Ratio,
            families,
            buffers,
        )?;
        for detection in self.detections.iter_mut() {
            for corner in detection.corners.iter_mut().chain([&mut detection.center]) {
                corner.x += dx;
                corner.y += dy;
            }
        }
        Ok(&self.detections)
    }

    /// Steps 1 to 7 on `image` through `camera`, binarising at `level`, into
    /// `self.detections` and `self.stats`.
    fn search(
        &mut self,
        image: &GrayImage<'_>,
        camera: Option<&CameraModel>,
        level: ThresholdLevel,
        families: &[&Family<'_>],
        buffers: &mut Buffers<'_>,
    ) -> Result<(), DetectError> {
        // Far from the pad or before it is found (the last search found one marker small
        // enough to be fitted, or none) the scan takes the frame's middle first
        // (`scan_rows`); nearer, where several markers or large ones fill the frame and the
        // middle band would cut through them, every row in turn.
        let far = match self.detections.as_slice() {
            [] => true,
            [one] => pattern_fit::fits(&one.corners),
            _ => false,
        };
        self.detections.clear();
        self.stats = DetectStats::default();
        if families.is_empty() || families.len() > MAX_FAMILIES {
            return Err(DetectError::BadFamilyCount);
        }
        if families.iter().any(|f| f.check_layout().is_err()) {
            return Err(DetectError::BadFamily);
        }
        let (width, height) = (image.width(), image.height());
        let sizes = buffer_sizes(width, height);
        let wpr = threshold::words_per_row(width);
        let words = wpr * height;
        let (Some(bitmap), Some(visited), Some(tiles)) = (
            buffers.bitmap.get_mut(..words),
            buffers.visited.get_mut(..words),
            buffers.tiles.get_mut(..sizes.tile_bytes),
        ) else {
            return Err(DetectError::BuffersTooSmall);
        };
        let Detector {
            config,
            contour,
            detections,
            stats,
            camera: _,
        } = self;
        // The one place the method is looked at: everything after asks the strategy.
        let robust = Robust { level };
        let strategy: &dyn Strategy = match config.method {
            Method::Robust => &robust,
            Method::Paper => &paper::Paper,
        };
        let binarise_work = strategy.binarise(image, config, bitmap, tiles);
        contour::clear_border(bitmap, wpr, width);
        visited.fill(0);
        let candidates = Candidates {
            strategy,
            image,
            families,
            config,
            max_quad_cells: families
                .iter()
                .map(|f| f.quad_cells())
                .max()
                .unwrap_or(1)
                .max(1),
            uniform_decodes: families.iter().any(|f| decode::uniform_grid_decodes(f)),
            quiet_margins: families.iter().all(|f| f.quiet_rings >= f.border_ring),
            camera,
            unread: core::cell::Cell::new(None),
        };
        let rule = strategy.start_rule(families);
        let bitmap: &[u32] = bitmap;
        let budget = work_budget(config.work_budget_per_pixel, width * height);
        let mut tracer = contour::Tracer::new(bitmap, visited, wpr, budget);
        let row_words = |y: usize| bitmap.get(y * wpr..(y + 1) * wpr).unwrap_or(&[]);
        let word = |row: &[u32], k: usize| row.get(k).copied().unwrap_or(0);
        // The binarisation's share that depends on the image comes out of the same budget,
        // so that the budget bounds all the work an image can add, not only the later steps'.
        let binarised = tracer.charge(binarise_work);
        'scan: for y in
            scan_rows(height, far && strategy.scans_middle_first()).take_while(|_| binarised)
        {
            let row = row_words(y);
            // Most rows of a frame have no dark pixel: a tight test of the row is a few
            // instructions a word. The search for starts goes on from its first dark word.
            let Some(first_dark) = row.iter().position(|&dark| dark != 0) else {
                continue;
            };
            let above = y.checked_sub(1).map_or(&[][..], row_words);
            let below = row_words(y + 1);
            // Every start has a light west neighbour and is not on a followed boundary: most
            // dark words (the insides of runs, edges already followed) have none, and are
            // passed by a tight loop of their own (`Tracer::next_start_word`); the six words
            // above and below are read only for the others.
            let mut from = first_dark;
            while let Some((k, left, dark)) = tracer.next_start_word(row, y * wpr, from) {
                from = k + 1;
                if !tracer.charge(WORK_SCAN_WORD) {
                    stats.truncated = true;
                    break 'scan;
                }
                let three = |r: &[u32]| [word(r, k.wrapping_sub(1)), word(r, k), word(r, k + 1)];
                let neighbourhood = contour::Neighbourhood {
                    left,
                    dark,
                    right: word(row, k + 1),
                    above: three(above),
                    below: three(below),
                };
                loop {
                    let seen = tracer.visited_word(y * wpr + k);
                    let starts = contour::start_bits(&neighbourhood, seen, rule);
                    if starts == 0 {
                        break;
                    }
                    let x = k * 32 + starts.trailing_zeros() as usize;
                    stats.contours += 1;
                    if !tracer.charge(WORK_TRACE_START) {
                        stats.truncated = true;
                        break 'scan;
                    }
                    match tracer.trace(x, y, contour) {
                        contour::Trace::Closed { points, length } => {
                            let fit_work = points as u32 / WORK_SCREEN_PIXELS;
                            let go_on = tracer.charge(fit_work)
                                && contour.get(..points).is_none_or(|boundary| {
                                    let boundary = contour::Boundary {
                                        points: boundary,
                                        length,
                                    };
                                    candidates.process(boundary, detections, stats, &mut tracer)
                                });
                            if !go_on {
                                stats.truncated = true;
                                break 'scan;
                            }
                        }
                        contour::Trace::TooLong => {}
                        contour::Trace::OutOfBudget => {
                            stats.truncated = true;
                            break 'scan;
                        }
                    }
                }
            }
        }
        stats.truncated |= !binarised;
        candidates.read_the_largest_unread(detections, stats, &mut tracer);
        tracer.release();
        if strategy.fits_patterns(config) {
            stats.fitted = u32::from(pattern_fit::fit_small_markers(
                image,
                families,
                detections,
                &mut tracer,
            ));
        }
        stats.trace_steps = tracer.steps();
        stats.work = budget - tracer.remaining();
        Ok(())
    }
}

/// The rows of a frame `height` rows high in the scan's order: with `middle_first`, its
/// middle quarter first, then the rows above it and those below, each part top to bottom;
/// otherwise every row in turn. Where the work budget stops a cluttered frame's search, the
/// middle of the frame, where a descent keeps its pad, has been searched: in row order the
/// budget ran out above the middle of frames of cluttered ground, and a far pad in the middle
/// was never reached. Three parts rather than rows from the middle out, so that most markers
/// are met from their top, as in row order: one met from below has its inner boundaries
/// looked at before its outline (on the Cortex-M7 frames rows from the middle out cost 2-3 %
/// more, and near the pad, markers cut by the middle band cost frames of the rest field some
/// of the markers they found in row order: hence row order there, see `Detector::search`).
fn scan_rows(height: usize, middle_first: bool) -> impl Iterator<Item = usize> {
    let (top, bottom) = if middle_first {
        (height * 3 / 8, height * 5 / 8)
    } else {
        (0, 0)
    };
    (top..bottom).chain(0..top).chain(bottom..height)
}

/// Work units of a frame of `pixels` at `per_pixel` units each, at least [`MIN_WORK_BUDGET`]
/// (0 for a negative, zero or not-a-number setting), saturating.
fn work_budget(per_pixel: f32, pixels: usize) -> u32 {
    let units = per_pixel * pixels as f32;
    if units >= u32::MAX as f32 {
        u32::MAX
    } else if units > 0.0 {
        (units as u32).max(MIN_WORK_BUDGET)
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The memory budget: work memory beyond the frame, 64 KiB at QVGA and 160 KiB at VGA.
    #[test]
    fn working_memory_fits_the_budget() {
        let detector = core::mem::size_of::<Detector>();
        let qvga = core::mem::size_of::<QvgaWorkspace>() + detector;
        let vga = core::mem::size_of::<VgaWorkspace>() + detector;
        assert!(qvga <= 64 * 1024, "QVGA work memory {qvga} B");
        assert!(vga <= 160 * 1024, "VGA work memory {vga} B");
    }

    #[test]
    fn the_scan_visits_every_row_once_the_middle_quarter_first() {
        for middle_first in [true, false] {
            for height in [0usize, 1, 2, 7, 8, 240, 241, 480, 1080] {
                let order: heapless::Vec<usize, 1080> = scan_rows(height, middle_first).collect();
                let mut seen = [false; 1080];
                for &y in &order {
                    assert!(y < height && !seen[y], "height {height}: row {y}");
                    seen[y] = true;
                }
                assert_eq!(order.len(), height);
                let first = if middle_first { height * 3 / 8 } else { 0 };
                assert_eq!(order.first().copied(), (height > 0).then_some(first));
            }
        }
    }

    #[test]
    fn bad_calls_are_errors() {
        let pixels = [0u8; 64 * 48];
        let image = GrayImage::new(&pixels, 64, 48).unwrap();
        let mut ws = QvgaWorkspace::new();
        let mut detector = Detector::new(DetectorConfig::default());
        let family = crate::family::tables::by_name("tag36h11").unwrap();
        assert_eq!(
            detector.detect(&image, &[], &mut ws.buffers()).err(),
            Some(DetectError::BadFamilyCount)
        );
        let mut small = Buffers {
            bitmap: &mut [0u32; 4],
            visited: &mut [0u32; 4],
            tiles: &mut [0u8; 4],
        };
        assert_eq!(
            detector.detect(&image, &[family], &mut small).err(),
            Some(DetectError::BuffersTooSmall)
        );
        let mut broken = *family;
        broken.max_correction = 9;
        assert_eq!(
            detector.detect(&image, &[&broken], &mut ws.buffers()).err(),
            Some(DetectError::BadFamily)
        );
        assert_eq!(
            detector
                .detect(&image, &[family], &mut ws.buffers())
                .map(|d| d.len()),
            Ok(0)
        );
    }
}
