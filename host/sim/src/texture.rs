//! Procedural ground textures (grass, concrete, asphalt): albedo as a pure function of the
//! ground position, the seed and the pixel's footprint.
//!
//! Each texture is value noise summed over octaves (the test renderer's lattice hash),
//! defined in metres on the ground so that the same patch of grass looks the same in every
//! frame and grows with the descent. Area sampling needs a texture averaged over the pixel's
//! footprint, not point-sampled (a 1 cm grass blade seen from 40 m, where a pixel covers
//! 7 cm, must average out, not alias into speckle): an octave whose wavelength is below
//! twice the footprint fades to its mean (zero), and octaves below the footprint are not
//! evaluated at all, which also keeps high altitudes cheap. Concrete joints are averaged
//! exactly over the footprint (box filter of a periodic line).

use crate::noise::lattice_hash;

/// What the ground is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GroundKind {
    /// Mown grass: dark, with metre-scale patches and strong centimetre-scale blade contrast.
    Grass,
    /// Concrete: bright, mottled, fine grain, dark expansion joints every 3 m.
    Concrete,
    /// Asphalt: dark and fine-grained with light aggregate speckle.
    Asphalt,
    /// One albedo everywhere (tests).
    Flat(f32),
}

/// One band of value noise: octaves from `coarsest` down to `finest` metres, each half the
/// wavelength and `persistence` times the amplitude of the previous.
#[derive(Debug, Clone, Copy)]
struct Band {
    amplitude: f64,
    coarsest: f64,
    finest: f64,
    persistence: f64,
    salt: u64,
}

/// Expansion joints of concrete slabs.
const JOINT_PERIOD_M: f64 = 3.0;
const JOINT_WIDTH_M: f64 = 0.012;
const JOINT_ALBEDO: f64 = 0.18;

/// Points per batch of [`GroundTexture::albedo_batch`]: enough to keep the look-ups of
/// several points in flight, few enough for the sums to stay in the L1 cache.
const BATCH: usize = 64;

/// Lattice cells per side of the value table (a power of two).
const LATTICE: usize = 256;

/// A ground texture.
#[derive(Clone)]
pub struct GroundTexture {
    /// The material.
    pub kind: GroundKind,
    /// Seed of the noise.
    pub seed: u64,
    /// `LATTICE x LATTICE` hashed lattice values, shared by all octaves (each reads it at
    /// its own offset). A table look-up is several times cheaper than hashing, and the
    /// texture is most of a frame's rendering time; the period (256 cells of the octave)
    /// is hidden by the coarser octaves.
    lattice: std::sync::Arc<[f32; LATTICE * LATTICE]>,
}

impl std::fmt::Debug for GroundTexture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GroundTexture")
            .field("kind", &self.kind)
            .field("seed", &self.seed)
            .finish()
    }
}

impl PartialEq for GroundTexture {
    fn eq(&self, other: &Self) -> bool {
        // The table is a function of the seed.
        self.kind == other.kind && self.seed == other.seed
    }
}

impl GroundTexture {
    /// A texture of `kind`.
    pub fn new(kind: GroundKind, seed: u64) -> Self {
        let mut lattice = std::sync::Arc::new([0.0f32; LATTICE * LATTICE]);
        if let Some(table) = std::sync::Arc::get_mut(&mut lattice) {
            for (k, v) in table.iter_mut().enumerate() {
                let (a, b) = ((k % LATTICE) as i64, (k / LATTICE) as i64);
                *v = lattice_hash(seed, 0, a, b) as f32;
            }
        }
        GroundTexture {
            kind,
            seed,
            lattice,
        }
    }

    fn recipe(&self) -> (f64, &'static [Band]) {
        const GRASS: &[Band] = &[
            Band {
                amplitude: 0.05,
                coarsest: 6.0,
                finest: 0.7,
                persistence: 0.6,
                salt: 1,
            },
            Band {
                amplitude: 0.07,
                coarsest: 0.12,
                finest: 0.008,
                persistence: 0.8,
                salt: 2,
            },
        ];
        const CONCRETE: &[Band] = &[
            Band {
                amplitude: 0.05,
                coarsest: 4.0,
                finest: 0.25,
                persistence: 0.6,
                salt: 3,
            },
            Band {
                amplitude: 0.05,
                coarsest: 0.03,
                finest: 0.003,
                persistence: 0.8,
                salt: 4,
            },
        ];
        const ASPHALT: &[Band] = &[
            Band {
                amplitude: 0.015,
                coarsest: 3.0,
                finest: 0.4,
                persistence: 0.6,
                salt: 5,
            },
            Band {
                amplitude: 0.06,
                coarsest: 0.016,
                finest: 0.002,
                persistence: 0.7,
                salt: 6,
            },
        ];
        match self.kind {
            GroundKind::Grass => (0.17, GRASS),
            GroundKind::Concrete => (0.40, CONCRETE),
            GroundKind::Asphalt => (0.09, ASPHALT),
            GroundKind::Flat(a) => (f64::from(a), &[]),
        }
    }

    /// Mean albedo over a footprint of about `footprint_m` metres around `(x, y)`.
    pub fn albedo(&self, x: f64, y: f64, footprint_m: f64) -> f32 {
        let (mean, bands) = self.recipe();
        let footprint = footprint_m.max(1e-6);
        let inv_footprint = 1.0 / footprint;
        let mut value = mean;
        for band in bands {
            value += band.amplitude * self.band(band, x, y, inv_footprint);
        }
        self.finish(value, x, y, footprint)
    }

    /// [`GroundTexture::albedo`] of many footprints at once, the same values to the bit:
    /// `out[i]` for `points[i] = [x, y, footprint_m]`. An octave at a time over a batch of
    /// points, so that the table look-ups of different points overlap instead of each point
    /// waiting on its own, octave after octave.
    pub fn albedo_batch(&self, points: &[[f64; 3]], out: &mut [f32]) {
        for (points, out) in points.chunks(BATCH).zip(out.chunks_mut(BATCH)) {
            self.albedo_chunk(points, out);
        }
    }

    fn albedo_chunk(&self, points: &[[f64; 3]], out: &mut [f32]) {
        let (mean, bands) = self.recipe();
        let n = points.len().min(out.len()).min(BATCH);
        let mut value = [mean; BATCH];
        let mut total = [0.0f64; BATCH];
        let mut inv_footprint = [0.0f64; BATCH];
        for (inv, p) in inv_footprint.iter_mut().zip(points).take(n) {
            *inv = 1.0 / p[2].max(1e-6);
        }
        for band in bands {
            total.fill(0.0);
            // The loop of `band`, turned inside out: the octaves outside, the points inside.
            let mut weight_sum = 0.0;
            let mut scale = band.coarsest;
            let mut inv_scale = 1.0 / band.coarsest;
            let mut amplitude = 1.0;
            let mut octave = band.salt << 8;
            while scale >= band.finest * 0.999 {
                weight_sum += amplitude;
                for ((t, p), inv) in total.iter_mut().zip(points).zip(&inv_footprint).take(n) {
                    // `keep` only falls with the octave: once it is 0 for a point, `band`
                    // would stop adding to it, as this does.
                    let keep = (scale * inv - 1.0).clamp(0.0, 1.0);
                    if keep > 0.0 {
                        *t += amplitude
                            * keep
                            * self.octave(octave, p[0] * inv_scale, p[1] * inv_scale);
                    }
                }
                scale *= 0.5;
                inv_scale *= 2.0;
                amplitude *= band.persistence;
                octave += 1;
            }
            for (v, t) in value.iter_mut().zip(&total).take(n) {
                *v += band.amplitude
                    * if weight_sum > 0.0 {
                        t / weight_sum
                    } else {
                        0.0
                    };
            }
        }
        for ((o, &v), p) in out.iter_mut().zip(&value).zip(points).take(n) {
            *o = self.finish(v, p[0], p[1], p[2].max(1e-6));
        }
    }

    /// The joints (concrete) over the band sum `value`, clamped to an albedo.
    #[inline]
    fn finish(&self, mut value: f64, x: f64, y: f64, footprint: f64) -> f32 {
        if self.kind == GroundKind::Concrete {
            let coverage = joint_coverage(x, footprint).max(joint_coverage(y, footprint));
            value += coverage * (JOINT_ALBEDO - value);
        }
        value.clamp(0.0, 1.0) as f32
    }

    fn band(&self, band: &Band, x: f64, y: f64, inv_footprint: f64) -> f64 {
        // Multiplications only in the loop: three divisions per octave cost more than the
        // look-ups.
        let mut total = 0.0;
        let mut weight_sum = 0.0;
        let mut scale = band.coarsest;
        let mut inv_scale = 1.0 / band.coarsest;
        let mut amplitude = 1.0;
        let mut octave = band.salt << 8;
        let mut resolved = true;
        while scale >= band.finest * 0.999 {
            weight_sum += amplitude;
            if resolved {
                // Fades from 1 at a wavelength of two footprints to 0 at one footprint.
                let keep = (scale * inv_footprint - 1.0).clamp(0.0, 1.0);
                if keep > 0.0 {
                    total += amplitude * keep * self.octave(octave, x * inv_scale, y * inv_scale);
                } else {
                    // Finer octaves are finer still: nothing more to add, only to weigh.
                    resolved = false;
                }
            }
            scale *= 0.5;
            inv_scale *= 2.0;
            amplitude *= band.persistence;
            octave += 1;
        }
        // Normalised by the weights of all the octaves the band has at full resolution.
        if weight_sum > 0.0 {
            total / weight_sum
        } else {
            0.0
        }
    }

    /// Smoothstep-interpolated lattice values, roughly in [-1, 1].
    #[inline]
    fn octave(&self, octave: u64, u: f64, v: f64) -> f64 {
        let (iu, iv) = (fast_floor(u), fast_floor(v));
        let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
        let (fu, fv) = (smooth(u - iu as f64), smooth(v - iv as f64));
        // Each octave reads the table at its own offset, so octaves are not correlated.
        let offset = octave.wrapping_mul(0x9e37_79b9) as i64;
        let mask = LATTICE - 1;
        let (a0, b0) = (
            (iu.wrapping_add(offset) as usize) & mask,
            (iv.wrapping_add(offset >> 8) as usize) & mask,
        );
        let (a1, b1) = ((a0 + 1) & mask, (b0 + 1) & mask);
        // Masked indices into a fixed-size table: no bounds check survives.
        let table: &[f32; LATTICE * LATTICE] = &self.lattice;
        let l = |a: usize, b: usize| f64::from(table[(b * LATTICE + a) & (LATTICE * LATTICE - 1)]);
        let top = l(a0, b0) + (l(a1, b0) - l(a0, b0)) * fu;
        let bottom = l(a0, b1) + (l(a1, b1) - l(a0, b1)) * fu;
        top + (bottom - top) * fv
    }
}

/// `floor` as an integer without a libm call (the baseline x86-64 target has no rounding
/// instruction). Values beyond the `i64` range saturate, which only moves far-away texture.
#[inline]
fn fast_floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// Fraction of a box of width `footprint` centred on `u` covered by joints of width
/// [`JOINT_WIDTH_M`] repeating every [`JOINT_PERIOD_M`] (exact: the integral of the periodic
/// indicator over the box).
fn joint_coverage(u: f64, footprint: f64) -> f64 {
    let integral = |t: f64| {
        let periods = (t / JOINT_PERIOD_M).floor();
        periods * JOINT_WIDTH_M + (t - periods * JOINT_PERIOD_M).min(JOINT_WIDTH_M)
    };
    let half = 0.5 * footprint;
    ((integral(u + half) - integral(u - half)) / footprint).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joints_are_area_averaged() {
        // A 1.2 cm joint seen through a 12 cm footprint covers a tenth of it.
        assert!((joint_coverage(0.006, 0.12) - 0.1).abs() < 1e-9);
        assert!((joint_coverage(0.006, 0.001) - 1.0).abs() < 1e-9);
        assert!(joint_coverage(1.5, 0.1) == 0.0);
    }

    #[test]
    fn coarse_footprints_average_the_fine_detail_out() {
        let grass = GroundTexture::new(GroundKind::Grass, 3);
        let spread = |footprint: f64| {
            let values: Vec<f64> = (0..400)
                .map(|k| f64::from(grass.albedo(k as f64 * 0.0037, 0.5, footprint)))
                .collect();
            let mean = values.iter().sum::<f64>() / 400.0;
            (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 400.0).sqrt()
        };
        // Over a 1.5 m strip: centimetre blades at 2 mm footprints, smooth at 20 cm.
        assert!(
            spread(0.002) > 2.0 * spread(0.2),
            "{} {}",
            spread(0.002),
            spread(0.2)
        );
    }
}
