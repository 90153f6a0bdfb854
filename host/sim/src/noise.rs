//! The noise generators of the test renderer ([`crate::render`]) and the simulator: Gaussian
//! sensor noise (Box-Muller over a ChaCha stream) and the smooth value-noise texture of the
//! ground, both deterministic. One module for both, so the simulator's sensor noise and
//! ground textures are the renderer's generators, not copies.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

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
pub(super) struct ValueNoise {
    seed: u64,
    scales: Vec<(f64, f64)>,
}

impl ValueNoise {
    pub(super) fn new(seed: u64, coarsest_px: f64) -> Self {
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
    pub(super) fn at(&self, x: f64, y: f64) -> f64 {
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
