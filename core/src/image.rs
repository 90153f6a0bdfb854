//! Borrowed 8-bit grey frames.
//!
//! The camera delivers luminance bytes into a buffer the firmware owns; the host decodes files
//! into a `Vec`. Both hand the detector a [`GrayImage`], a checked view that never copies.
//! Rows may be padded (`stride >= width`) so a DCMI buffer with line padding or a crop of a
//! larger frame can be used in place.

/// Largest accepted width or height, in pixels. Coordinates are kept in `u16` inside the
/// detector; 8192 leaves room for the 2x up-sampled corner lattice.
pub const MAX_DIMENSION: usize = 8192;

/// Why a byte slice cannot be viewed as an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    /// Width or height is zero or above [`MAX_DIMENSION`].
    BadDimensions,
    /// `stride` is smaller than `width`.
    BadStride,
    /// The slice is shorter than `stride * (height - 1) + width` bytes.
    TooShort,
}

/// A rectangle of pixels: the top-left pixel (`x`, `y`) and the size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImageRegion {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

/// A read-only grey image: `height` rows of `width` bytes, `stride` bytes apart.
#[derive(Debug, Clone, Copy)]
pub struct GrayImage<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> GrayImage<'a> {
    /// A tightly packed image (`stride == width`).
    pub fn new(data: &'a [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::with_stride(data, width, height, width)
    }

    /// An image whose rows start `stride` bytes apart.
    pub fn with_stride(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        if width == 0 || height == 0 || width > MAX_DIMENSION || height > MAX_DIMENSION {
            return Err(ImageError::BadDimensions);
        }
        if stride < width {
            return Err(ImageError::BadStride);
        }
        let needed = stride
            .checked_mul(height - 1)
            .and_then(|n| n.checked_add(width))
            .ok_or(ImageError::TooShort)?;
        if data.len() < needed {
            return Err(ImageError::TooShort);
        }
        Ok(GrayImage {
            data,
            width,
            height,
            stride,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Bytes between the starts of two rows.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The part of the image inside `region`, in place (same rows, no copy); `None` when the
    /// region is empty or reaches outside the image.
    pub fn view(&self, region: &ImageRegion) -> Option<GrayImage<'a>> {
        let x_end = region.x.checked_add(region.width)?;
        let y_end = region.y.checked_add(region.height)?;
        if region.width == 0 || region.height == 0 || x_end > self.width || y_end > self.height {
            return None;
        }
        let start = region.y * self.stride + region.x;
        let data = self.data.get(start..)?;
        GrayImage::with_stride(data, region.width, region.height, self.stride).ok()
    }

    /// Row `y` (exactly `width` bytes), or an empty slice outside the image.
    pub fn row(&self, y: usize) -> &'a [u8] {
        if y >= self.height {
            return &[];
        }
        let start = y * self.stride;
        self.data.get(start..start + self.width).unwrap_or(&[])
    }

    /// The pixel at (x, y), clamped to the nearest pixel inside the image.
    #[inline]
    pub fn pixel_clamped(&self, x: isize, y: isize) -> u8 {
        // min-then-max rather than `clamp`, whose "min > max" panic the optimiser cannot rule
        // out (it does not know the image is never empty); same result for any real image.
        let xc = x.min(self.width as isize - 1).max(0) as usize;
        let yc = y.min(self.height as isize - 1).max(0) as usize;
        self.data.get(yc * self.stride + xc).copied().unwrap_or(0)
    }

    /// The pixel nearest (x, y) (`(x + 0.5)` truncated), for a caller that knows it lies
    /// inside the image: none of [`GrayImage::pixel_clamped`]'s clamping, which was most of
    /// the cost of a nearest-pixel read. Elsewhere it never panics, but reads another pixel
    /// or 0.
    #[inline]
    pub(crate) fn nearest_inside(&self, x: f32, y: f32) -> u8 {
        let (xi, yi) = ((x + 0.5) as usize, (y + 0.5) as usize);
        self.data
            .get(yi.wrapping_mul(self.stride).wrapping_add(xi))
            .copied()
            .unwrap_or(0)
    }

    /// Bilinear interpolation at a sub-pixel position (pixel centres at integers); positions
    /// outside the image read the nearest edge pixel.
    #[inline]
    pub fn sample(&self, x: f32, y: f32) -> f32 {
        if self.bilinear_inside(x, y) {
            self.sample_inside(x, y)
        } else {
            self.sample_clamped(x, y)
        }
    }

    /// Whether [`GrayImage::sample`] at (x, y) reads a 2x2 neighbourhood inside the image
    /// (false for NaN). A caller sampling along a segment whose two ends pass needs no test
    /// per sample: the box is convex and `a + t * d` rounds monotonically in `t`.
    #[inline]
    pub(crate) fn bilinear_inside(&self, x: f32, y: f32) -> bool {
        x >= 0.0 && y >= 0.0 && x < (self.width - 1) as f32 && y < (self.height - 1) as f32
    }

    /// [`GrayImage::sample`] at a position that is [`GrayImage::bilinear_inside`], without
    /// that test (the same value there). Elsewhere it never panics, but reads the clamped
    /// value only when the neighbourhood's bytes are missing.
    #[inline]
    pub(crate) fn sample_inside(&self, x: f32, y: f32) -> f32 {
        let (xi, yi) = (x as usize, y as usize); // truncation is floor for x, y >= 0
        let (fx, fy) = (x - xi as f32, y - yi as f32);
        // Wrapping: a position far outside (a caller's mistake) then misses the data below.
        // One slice from the top-left to the bottom-right pixel: one bounds check.
        let top = yi.wrapping_mul(self.stride).wrapping_add(xi);
        let window = self
            .data
            .get(top..)
            .and_then(|rest| rest.get(..self.stride.wrapping_add(2)))
            .unwrap_or(&[]);
        if let (Some(&[p00, p10]), Some(&[p01, p11])) =
            (window.first_chunk::<2>(), window.last_chunk::<2>())
        {
            let upper = p00 as f32 + (p10 as f32 - p00 as f32) * fx;
            let lower = p01 as f32 + (p11 as f32 - p01 as f32) * fx;
            return upper + (lower - upper) * fy;
        }
        self.sample_clamped(x, y)
    }

    /// Walks `count` bilinear samples from `start` in steps of `step`, in fixed point:
    /// `None` unless every sample's 2x2 neighbourhood lies inside the image (checked at both
    /// ends: the positions are linear in the step's index, and the box convex), or when
    /// `start` is not finite.
    #[inline]
    pub(crate) fn bilinear_walk(
        &self,
        start: (f32, f32),
        step: &WalkStep,
        count: usize,
    ) -> Option<BilinearWalk<'a>> {
        // The float test first: a position inside (0 <= x < 8191) converts without
        // saturating, and steps of at most a pixel keep the far end within an i32.
        if count == 0 || count > MAX_WALK || !self.bilinear_inside(start.0, start.1) {
            return None;
        }
        let (x, y) = (fixed_position(start.0), fixed_position(start.1));
        let last = count as i32 - 1;
        let (x_end, y_end) = (x + last * step.dx, y + last * step.dy);
        let inside = |x: i32, y: i32| {
            x >= 0
                && y >= 0
                && (x >> WALK_POSITION_BITS) < self.width as i32 - 1
                && (y >> WALK_POSITION_BITS) < self.height as i32 - 1
        };
        (inside(x, y) && inside(x_end, y_end)).then_some(BilinearWalk {
            data: self.data,
            stride: self.stride,
            x,
            y,
            dx: step.dx,
            dy: step.dy,
        })
    }

    /// [`GrayImage::sample`] near or beyond the border: reads the nearest edge pixels.
    fn sample_clamped(&self, x: f32, y: f32) -> f32 {
        if !(x.is_finite() && y.is_finite()) {
            return 0.0;
        }
        let xf = floor(x);
        let yf = floor(y);
        let fx = x - xf;
        let fy = y - yf;
        // Clamp before converting so huge values cannot overflow the cast (max/min: `clamp`
        // keeps a panic path for bounds the optimiser cannot order; x, y are finite here).
        let xi = xf.max(-2.0).min(self.width as f32 + 1.0) as isize;
        let yi = yf.max(-2.0).min(self.height as f32 + 1.0) as isize;
        let p00 = self.pixel_clamped(xi, yi) as f32;
        let p10 = self.pixel_clamped(xi + 1, yi) as f32;
        let p01 = self.pixel_clamped(xi, yi + 1) as f32;
        let p11 = self.pixel_clamped(xi + 1, yi + 1) as f32;
        let top = p00 + (p10 - p00) * fx;
        let bottom = p01 + (p11 - p01) * fx;
        top + (bottom - top) * fy
    }
}

/// Fractional bits of a [`BilinearWalk`]'s positions (16.16 fixed point: positions below
/// [`MAX_DIMENSION`] fit an i32 with room for a step). A step rounded to them is off by at
/// most 2^-17 px, so a walk of [`MAX_WALK`] samples drifts by less than 3e-4 px.
const WALK_POSITION_BITS: u32 = 16;
/// Fractional bits of the interpolation weights of a [`BilinearWalk`] (the position rounded
/// to 1/2048 px, 2.4e-4 px at most): eleven keep both interpolations within an i32 (a grey
/// level of 8 bits times two weights of 11 bits is below 2^30, and so is a difference).
const WALK_WEIGHT_BITS: u32 = 11;
/// Most samples of a [`BilinearWalk`].
const MAX_WALK: usize = 64;
/// A [`BilinearWalk`] sample per grey level (2^22).
pub(crate) const WALK_SAMPLE_SCALE: f32 = (1u32 << (2 * WALK_WEIGHT_BITS)) as f32;

/// The walk's fixed-point position of a coordinate `0 <= v < MAX_DIMENSION`: truncated to
/// 2^-16 px (the product is exact: a power of two), plus half a weight step, so that
/// truncating the weights rounds the position to the nearest 1/2048 px.
#[inline]
fn fixed_position(v: f32) -> i32 {
    (v * (1u32 << WALK_POSITION_BITS) as f32) as i32
        + (1 << (WALK_POSITION_BITS - WALK_WEIGHT_BITS - 1))
}

/// The step between the samples of a [`BilinearWalk`], in its fixed point: converted once
/// for the walks that share it (the profiles across one edge).
#[derive(Debug, Clone, Copy)]
pub(crate) struct WalkStep {
    dx: i32,
    dy: i32,
}

impl WalkStep {
    /// The step (dx, dy), rounded to the nearest 2^-16 px; `None` unless it is at most a
    /// pixel each way.
    #[inline]
    pub(crate) fn new(dx: f32, dy: f32) -> Option<Self> {
        if !(dx.abs() <= 1.0 && dy.abs() <= 1.0) {
            return None;
        }
        let fixed = |d: f32| {
            let scaled = d * (1u32 << WALK_POSITION_BITS) as f32;
            (scaled + 0.5f32.copysign(scaled)) as i32
        };
        Some(WalkStep {
            dx: fixed(dx),
            dy: fixed(dy),
        })
    }
}

/// Evenly spaced bilinear samples along a segment inside an image
/// ([`GrayImage::bilinear_walk`]), as integers ([`WALK_SAMPLE_SCALE`] per grey level).
///
/// An edge profile reads a dozen samples per edge point, thousands per candidate; the float
/// sample ([`GrayImage::sample_inside`]) pays, per sample on the Cortex-M7, the position's
/// multiply-adds, two float-to-integer conversions and back for the weights and four
/// byte-to-float conversions. Here the position steps by integer additions and the
/// interpolation is integer multiply-adds on the bytes, and the extremes are kept in a loop
/// of their own (the walk's registers are spilled, the loop being inlined into the edge's;
/// `bench/m7`'s `qvga-adv-tags` frame counts it). The value is exact at the position
/// rounded to 1/2048 px (the float's position was closer, within a few 1e-5 px, but its
/// interpolation rounded to 24 bits).
#[derive(Debug, Clone)]
pub(crate) struct BilinearWalk<'a> {
    data: &'a [u8],
    stride: usize,
    x: i32,
    y: i32,
    dx: i32,
    dy: i32,
}

impl BilinearWalk<'_> {
    /// The sample at the current position (times [`WALK_SAMPLE_SCALE`]), then one step on;
    /// `None` only past the walk's `count` samples, where the position may leave the image
    /// (and the values mean nothing until then: the 2x2 neighbourhood wraps onto the next
    /// row, never out of the slice).
    #[inline(always)]
    pub(crate) fn next_sample(&mut self) -> Option<i32> {
        const WEIGHT_MASK: i32 = (1 << WALK_WEIGHT_BITS) - 1;
        const WEIGHT_SHIFT: u32 = WALK_POSITION_BITS - WALK_WEIGHT_BITS;
        let (x, y) = (self.x, self.y);
        self.x = x.wrapping_add(self.dx);
        self.y = y.wrapping_add(self.dy);
        // Non-negative inside the walk, so the shifts are floor and fraction.
        let (xi, yi) = (
            (x >> WALK_POSITION_BITS) as usize,
            (y >> WALK_POSITION_BITS) as usize,
        );
        let (fx, fy) = (
            (x >> WEIGHT_SHIFT) & WEIGHT_MASK,
            (y >> WEIGHT_SHIFT) & WEIGHT_MASK,
        );
        // One slice from the top-left to the bottom-right pixel: one bounds check.
        let top = yi.wrapping_mul(self.stride).wrapping_add(xi);
        let window = self.data.get(top..)?.get(..self.stride.wrapping_add(2))?;
        let (&[p00, p10], &[p01, p11]) = (window.first_chunk::<2>()?, window.last_chunk::<2>()?);
        let (p00, p10, p01, p11) = (p00 as i32, p10 as i32, p01 as i32, p11 as i32);
        let upper = (p00 << WALK_WEIGHT_BITS) + (p10 - p00) * fx;
        let lower = (p01 << WALK_WEIGHT_BITS) + (p11 - p01) * fx;
        Some((upper << WALK_WEIGHT_BITS) + (lower - upper) * fy)
    }
}

/// `floor` for f32 without std (exact for |x| < 2^23, the range pixels live in).
#[inline]
pub(crate) fn floor(x: f32) -> f32 {
    if !(x.abs() < 8_388_608.0) {
        return x;
    }
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_view_reads_its_region_of_the_rows_and_refuses_what_reaches_outside() {
        // 5 x 4 with stride 6: pixel (x, y) = 10 y + x.
        let data: [u8; 24] = core::array::from_fn(|i| (10 * (i / 6) + i % 6) as u8);
        let image = GrayImage::with_stride(&data, 5, 4, 6).unwrap();
        let region = |x, y, width, height| ImageRegion {
            x,
            y,
            width,
            height,
        };
        let view = image.view(&region(1, 2, 4, 2)).unwrap();
        assert_eq!((view.width(), view.height()), (4, 2));
        assert_eq!(view.row(0), &[21, 22, 23, 24]);
        assert_eq!(view.row(1), &[31, 32, 33, 34]);
        assert_eq!(view.pixel_clamped(9, 9), 34);
        assert!(image.view(&region(2, 2, 4, 2)).is_none());
        assert!(image.view(&region(0, 3, 5, 2)).is_none());
        assert!(image.view(&region(1, 1, 0, 2)).is_none());
        assert!(image.view(&region(usize::MAX, 0, 2, 2)).is_none());
    }

    #[test]
    fn rejects_bad_shapes() {
        let data = [0u8; 12];
        assert_eq!(
            GrayImage::new(&data, 0, 3).err(),
            Some(ImageError::BadDimensions)
        );
        assert_eq!(
            GrayImage::new(&data, 4, 4).err(),
            Some(ImageError::TooShort)
        );
        assert_eq!(
            GrayImage::with_stride(&data, 4, 2, 3).err(),
            Some(ImageError::BadStride)
        );
        // stride 5, 3 rows: needs 5 * 2 + 4 = 14 bytes.
        assert_eq!(
            GrayImage::with_stride(&data, 4, 3, 5).err(),
            Some(ImageError::TooShort)
        );
        assert!(GrayImage::with_stride(&data, 4, 2, 6).is_ok());
    }

    #[test]
    fn bilinear_sampling_and_clamping() {
        let data = [0u8, 100, 200, 50];
        let img = GrayImage::new(&data, 2, 2).unwrap();
        assert_eq!(img.sample(0.0, 0.0), 0.0);
        assert_eq!(img.sample(0.5, 0.0), 50.0);
        assert_eq!(img.sample(0.5, 0.5), 87.5);
        assert_eq!(img.sample(-10.0, 1.0), 200.0);
        assert_eq!(img.sample(f32::NAN, 0.0), 0.0);
        assert_eq!(img.sample(1e30, -1e30), 100.0);
    }

    #[test]
    fn fast_and_clamped_sampling_agree_inside() {
        let data: [u8; 20] = core::array::from_fn(|k| (k * 37 % 251) as u8);
        let img = GrayImage::with_stride(&data, 4, 4, 5).unwrap();
        for i in 0..=30 {
            for j in 0..=30 {
                let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
                let fast = img.sample(x, y);
                let slow = img.sample_clamped(x, y);
                assert!((fast - slow).abs() < 1e-3, "({x}, {y}): {fast} vs {slow}");
            }
        }
    }

    #[test]
    fn floor_matches_definition() {
        for &(x, f) in &[
            (1.5f32, 1.0f32),
            (-1.5, -2.0),
            (-0.0, 0.0),
            (3.0, 3.0),
            (-3.0, -3.0),
        ] {
            assert_eq!(floor(x), f);
        }
    }
}
