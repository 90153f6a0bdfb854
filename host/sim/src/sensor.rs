//! From radiance to 8-bit grey levels: lens (vignetting, blur, defocus) and sensor
//! (exposure, gain, blooming, flare, shot and read noise, quantisation with clipping).
//!
//! Order, as light goes:
//! 1. **Vignetting**: `1 - strength (1 - cos^4 theta)` with `theta` the ray's angle off the
//!    optical axis (the natural cos^4 fall-off at strength 1).
//! 2. **Blur**: one Gaussian for the lens's own spread and the defocus. Defocus is
//!    geometric: a lens of aperture `A` focused at `d_f` spreads a point at distance `d` over
//!    a disc of `f_px A |1/d - 1/d_f|` pixels; the Gaussian with the disc's standard deviation
//!    (a quarter of its diameter) stands in for it. Fixed-focus board cameras are focused far
//!    away, so the pad blurs in the last metre of a landing. Other point-spread functions
//!    ([`crate::psf`], [`crate::Simulator::with_lens_psfs`]) may replace the lens's spread:
//!    applied in turn after the defocus's Gaussian.
//! 3. **Exposure**: electrons = radiance x `electrons_per_radiance`, either fixed, or set per
//!    frame by the sensor's own auto-exposure, which meters the mean of the frame (as
//!    OpenMV's and most sensors' AE do: metering on dark grass makes a white pad clip, the
//!    outdoor failure), or set manually by a controller (the board's auto-exposure, as a
//!    replay that closes its loop runs it: [`Exposure::Manual`]): electrons =
//!    radiance x [`Sensor::sensitivity`] x exposure time, and the analog gain multiplies the
//!    grey levels per electron (noise and all), so the ADC clips at 255 before the full well
//!    does.
//! 4. **Flare** (veiling glare): a fraction of the mean signal added everywhere, lifting the
//!    blacks in bright scenes.
//! 5. **Blooming**: charge beyond the full well spills into the neighbourhood (a Gaussian
//!    spread of the excess), so clipped white eats into thin black lines.
//! 6. **Noise**: shot noise (Gaussian with variance = electrons, the Poisson limit that holds
//!    from a few tens of electrons on) and read noise, then gain to grey levels, rounding and
//!    clipping to 0..255.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::noise::NormalPairs;
use crate::psf::Psf;
use crate::render::gaussian_blur;

/// The lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Optics {
    /// Standard deviation of the lens's own blur, pixels.
    pub blur_sigma_px: f64,
    /// Aperture diameter, metres (focal length / f-number); 0 = pinhole, no defocus.
    pub aperture_m: f64,
    /// Distance the lens is focused at, metres (`f64::INFINITY` for infinity).
    pub focus_distance_m: f64,
    /// Vignetting strength: 0 none, 1 the natural cos^4 fall-off.
    pub vignetting: f64,
}

impl Optics {
    /// A sharp pinhole: no blur, no defocus, no vignetting.
    pub fn ideal() -> Self {
        Optics {
            blur_sigma_px: 0.0,
            aperture_m: 0.0,
            focus_distance_m: f64::INFINITY,
            vignetting: 0.0,
        }
    }

    /// A small board camera: 0.6 px lens blur, 3.6 mm f/2.0 (1.8 mm aperture) focused at
    /// 5 m, natural vignetting.
    pub fn board_camera() -> Self {
        Optics {
            blur_sigma_px: 0.6,
            aperture_m: 0.0018,
            focus_distance_m: 5.0,
            vignetting: 1.0,
        }
    }

    /// Diameter of the defocus disc of a point `distance_m` away, pixels.
    pub fn defocus_diameter_px(&self, focal_px: f64, distance_m: f64) -> f64 {
        if self.aperture_m <= 0.0 || distance_m.is_nan() || distance_m <= 0.0 {
            return 0.0;
        }
        let inv_focus = if self.focus_distance_m.is_finite() && self.focus_distance_m > 0.0 {
            1.0 / self.focus_distance_m
        } else {
            0.0
        };
        focal_px * self.aperture_m * (1.0 / distance_m - inv_focus).abs()
    }

    /// The defocus as a Gaussian of the blur circle's variance (a uniform disc of diameter d
    /// has d^2 / 16 along each axis) for a scene `distance_m` away, pixels.
    pub fn defocus_sigma(&self, focal_px: f64, distance_m: f64) -> f64 {
        0.25 * self.defocus_diameter_px(focal_px, distance_m)
    }

    /// The total blur's standard deviation for a scene `distance_m` away, pixels.
    pub fn blur_sigma(&self, focal_px: f64, distance_m: f64) -> f64 {
        self.blur_sigma_px
            .hypot(self.defocus_sigma(focal_px, distance_m))
    }
}

/// How the exposure is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Exposure {
    /// Electrons per unit of radiance, fixed.
    Fixed {
        /// Electrons collected from radiance 1.0 at the image centre.
        electrons_per_radiance: f64,
    },
    /// Auto-exposure: the mean grey level of the frame is brought to `target_mean` within
    /// the exposure's limits.
    Auto {
        /// Wanted mean grey level.
        target_mean: f64,
        /// Smallest and largest electrons per unit radiance (shortest and longest exposure
        /// times at the set gain).
        limits: (f64, f64),
    },
    /// Set from outside, frame by frame.
    Manual(ManualExposure),
}

/// An exposure time and an analog gain, as a controller writes them to a sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManualExposure {
    /// Exposure time, seconds (also what motion blurs over).
    pub exposure_s: f64,
    /// Analog gain, 1.0 = unity: grey levels per electron are [`Sensor::gain`] times this.
    pub analog_gain: f64,
}

/// The image sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Full-well capacity, electrons.
    pub full_well_e: f64,
    /// Read noise, electrons RMS.
    pub read_noise_e: f64,
    /// Grey levels per electron (analog gain included).
    pub gain: f64,
    /// Grey level of no light.
    pub black_level: f64,
    /// Fraction of the charge beyond the full well that spills into neighbours.
    pub bloom: f64,
    /// Spread of the spill, pixels.
    pub bloom_sigma_px: f64,
    /// Veiling glare: fraction of the mean signal added to every pixel.
    pub flare: f64,
    /// How the exposure is set.
    pub exposure: Exposure,
    /// Electrons collected per unit radiance (at the image centre) per second of exposure:
    /// what a [`Exposure::Manual`] exposure time is turned into electrons with.
    pub sensitivity: f64,
}

impl Sensor {
    /// A small CMOS sensor (OV-class): 6000 e- full well, 4 e- read noise, unity gain at
    /// full well, a little blooming and flare, fixed exposure putting paper white (albedo
    /// 0.8) in daylight at about 200; a sensitivity that does the same in a 4 ms exposure at
    /// unity gain.
    pub fn board_camera() -> Self {
        let full_well = 6000.0;
        let electrons_per_radiance = 200.0 / 0.8 / (255.0 / full_well);
        Sensor {
            full_well_e: full_well,
            read_noise_e: 4.0,
            gain: 255.0 / full_well,
            black_level: 2.0,
            bloom: 0.3,
            bloom_sigma_px: 1.5,
            flare: 0.01,
            exposure: Exposure::Fixed {
                electrons_per_radiance,
            },
            sensitivity: electrons_per_radiance / 0.004,
        }
    }

    /// A noiseless, linear sensor: radiance 1.0 = grey level 250, no clipping effects
    /// beyond 8 bits (tests).
    pub fn ideal() -> Self {
        Sensor {
            full_well_e: f64::INFINITY,
            read_noise_e: 0.0,
            gain: 1.0,
            black_level: 0.0,
            bloom: 0.0,
            bloom_sigma_px: 0.0,
            flare: 0.0,
            exposure: Exposure::Fixed {
                electrons_per_radiance: 250.0,
            },
            sensitivity: 250.0 / 0.004,
        }
    }

    /// Electrons per unit radiance for a frame of this radiance (after vignetting).
    pub fn electrons_per_radiance(&self, radiance: &[f32]) -> f64 {
        match self.exposure {
            Exposure::Fixed {
                electrons_per_radiance,
            } => electrons_per_radiance,
            Exposure::Auto {
                target_mean,
                limits,
            } => {
                let mean = radiance.iter().map(|&v| f64::from(v)).sum::<f64>()
                    / radiance.len().max(1) as f64;
                let wanted = (target_mean - self.black_level).max(1.0) / self.gain / mean.max(1e-9);
                wanted.clamp(limits.0, limits.1.max(limits.0))
            }
            Exposure::Manual(m) => self.sensitivity * m.exposure_s.max(0.0),
        }
    }

    /// Grey levels per electron: [`Sensor::gain`] times a manual exposure's analog gain.
    pub fn grey_per_electron(&self) -> f64 {
        match self.exposure {
            Exposure::Manual(m) => self.gain * m.analog_gain.max(0.0),
            _ => self.gain,
        }
    }
}

/// Turns a radiance image into grey levels (the steps of the module docs).
#[allow(clippy::too_many_arguments)]
pub fn expose(
    mut radiance: Vec<f32>,
    width: usize,
    height: usize,
    cos_off_axis: &[f32],
    optics: &Optics,
    sensor: &Sensor,
    blur_sigma_px: f64,
    psfs: &[Psf],
    noise_seed: u64,
) -> Vec<u8> {
    if optics.vignetting > 0.0 {
        let strength = optics.vignetting as f32;
        for (v, &c) in radiance.iter_mut().zip(cos_off_axis) {
            let c2 = c * c;
            *v *= 1.0 - strength * (1.0 - c2 * c2);
        }
    }
    if blur_sigma_px > 0.05 {
        gaussian_blur(&mut radiance, width, height, blur_sigma_px);
    }
    for psf in psfs {
        psf.apply(&mut radiance, width, height);
    }
    let scale = sensor.electrons_per_radiance(&radiance) as f32;
    let mut electrons: Vec<f32> = radiance.iter().map(|&v| v * scale).collect();
    if sensor.flare > 0.0 {
        let mean =
            electrons.iter().map(|&v| f64::from(v)).sum::<f64>() / electrons.len().max(1) as f64;
        let lift = (sensor.flare * mean) as f32;
        electrons.iter_mut().for_each(|v| *v += lift);
    }
    let full = sensor.full_well_e as f32;
    if sensor.bloom > 0.0 && sensor.full_well_e.is_finite() {
        let mut excess: Vec<f32> = electrons.iter().map(|&v| (v - full).max(0.0)).collect();
        if excess.iter().any(|&v| v > 0.0) {
            if sensor.bloom_sigma_px > 0.05 {
                gaussian_blur(&mut excess, width, height, sensor.bloom_sigma_px);
            }
            let k = sensor.bloom as f32;
            for (v, e) in electrons.iter_mut().zip(&excess) {
                *v += k * e;
            }
        }
    }
    let grey_per_electron = sensor.grey_per_electron();
    let mut rng = ChaCha8Rng::seed_from_u64(noise_seed);
    let mut normals = NormalPairs::default();
    let noisy = sensor.read_noise_e > 0.0 || sensor.full_well_e.is_finite();
    electrons
        .iter()
        .map(|&e| {
            let e = f64::from(e.clamp(0.0, full));
            let e = if noisy {
                let shot = e.sqrt() * normals.next(&mut rng);
                let read = sensor.read_noise_e * normals.next(&mut rng);
                e + shot + read
            } else {
                e
            };
            quantise(sensor.black_level + e * grey_per_electron)
        })
        .collect()
}

/// `v.round().clamp(0.0, 255.0) as u8` without the library call `round` is on the baseline
/// x86-64 target (it has no rounding instruction), the same value for every `v`: halves
/// away from zero, NaN to 0.
#[inline]
fn quantise(v: f64) -> u8 {
    // Clamped first to a range where the truncation is exact; the rounding of a value
    // beyond 0..255 lands beyond it too, so the final clamp is unchanged. NaN stays NaN.
    let c = v.clamp(-1.0, 256.0);
    let t = c as i64 as f64;
    let rounded = if c - t >= 0.5 {
        t + 1.0
    } else if t - c >= 0.5 {
        t - 1.0
    } else {
        t
    };
    rounded.clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantise_rounds_as_round_does() {
        let mut values = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.5,
            -0.49999999999999994,
            0.49999999999999994,
            0.5,
            1.5,
            2.5,
            254.5,
            254.49999999999997,
            255.5,
            1e300,
            -1e300,
        ];
        values.extend((-4000..300_000).map(|k| f64::from(k) * 0.000_913_7));
        for v in values {
            assert_eq!(quantise(v), v.round().clamp(0.0, 255.0) as u8, "{v}");
        }
    }

    #[test]
    fn defocus_grows_near_the_camera() {
        let o = Optics::board_camera();
        // 554 px x 1.8 mm x |1/0.3 - 1/5| = 3.1 px.
        let d = o.defocus_diameter_px(554.0, 0.3);
        assert!((d - 3.12).abs() < 0.02, "{d}");
        assert_eq!(o.defocus_diameter_px(554.0, 5.0), 0.0);
    }

    #[test]
    fn ideal_sensor_is_linear_and_exact() {
        let g = expose(
            vec![0.0, 0.5, 1.0, 2.0],
            2,
            2,
            &[1.0; 4],
            &Optics::ideal(),
            &Sensor::ideal(),
            0.0,
            &[],
            1,
        );
        assert_eq!(g, vec![0, 125, 250, 255]);
    }

    #[test]
    fn shot_noise_follows_the_signal() {
        let sensor = Sensor {
            bloom: 0.0,
            flare: 0.0,
            read_noise_e: 0.0,
            black_level: 0.0,
            ..Sensor::board_camera()
        };
        let n = 20000;
        let level = 0.4f32;
        let g = expose(
            vec![level; n],
            200,
            100,
            &vec![1.0; n],
            &Optics::ideal(),
            &sensor,
            0.0,
            &[],
            9,
        );
        let mean = g.iter().map(|&v| f64::from(v)).sum::<f64>() / n as f64;
        let var = g
            .iter()
            .map(|&v| (f64::from(v) - mean).powi(2))
            .sum::<f64>()
            / n as f64;
        let e = f64::from(level)
            * match sensor.exposure {
                Exposure::Fixed {
                    electrons_per_radiance,
                } => electrons_per_radiance,
                Exposure::Auto { .. } | Exposure::Manual(_) => unreachable!(),
            };
        // Variance in grey levels: gain^2 e (plus 1/12 from rounding).
        let expected = sensor.gain * sensor.gain * e + 1.0 / 12.0;
        assert!(
            (var - expected).abs() < 0.1 * expected,
            "{var} vs {expected}"
        );
    }
}
