//! The wind the closed loop's vehicle flies in: a steady mean wind plus discrete gusts.
//!
//! Gusts are the "1 - cos" shape of the discrete gust models (MIL-F-8785C, CS-25): a gust of
//! peak `gust_mps` rises from nothing to its peak and falls back over its length,
//! `v(t) = peak / 2 * (1 - cos(2 pi (t - start) / length))`. They arrive at seeded random
//! times (exponential intervals, mean [`GUST_MEAN_INTERVAL_S`]), each from its own seeded
//! horizontal direction and with its own length ([`GUST_LENGTH_S`]); two may overlap. The
//! mean wind blows from a seeded direction. Everything is a pure function of the seed, so
//! the same seed flies the same air.
//!
//! Why discrete gusts rather than a filtered noise: "3 m/s gusts" (issue 15) names a peak, and
//! a gust's rise over seconds is what a position controller must reject; a Dryden-like noise
//! of that RMS would put twice the peak into the air now and then.
//!
//! Over height ([`WindProfile`]): the same air at every height by default (the gusts at
//! their full peak down to the ground, the hard case), or ArduPilot SITL's default profile
//! (`SIM_WIND_T` 0, `SITL_State.cpp`): below `SIM_WIND_T_ALT` (60 m) the wind speed is
//! scaled by `sqrt(height / 60 m)`, so 0.58 of it at 20 m and 0.09 at 0.5 m. SITL scales its
//! set wind speed that way and adds its turbulence (`SIM_WIND_TURB`) unscaled; SITL has no
//! discrete gusts, so here the whole wind, mean and gusts, is scaled.

use nalgebra::{Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Mean time between gust starts, seconds.
pub const GUST_MEAN_INTERVAL_S: f64 = 6.0;
/// Shortest and longest gust, seconds.
pub const GUST_LENGTH_S: (f64, f64) = (2.0, 6.0);

/// How the wind changes with the height over the ground (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum WindProfile {
    /// The same wind at every height.
    #[default]
    Uniform,
    /// ArduPilot SITL's default: scaled by `sqrt(height / reference_m)` below `reference_m`.
    SquareRoot {
        /// SIM_WIND_T_ALT, metres (SITL's default 60).
        reference_m: f64,
    },
}

impl WindProfile {
    /// ArduPilot SITL's default profile (SIM_WIND_T 0, SIM_WIND_T_ALT 60 m).
    pub fn sitl() -> Self {
        WindProfile::SquareRoot { reference_m: 60.0 }
    }

    /// The factor on the wind at `height_m` over the ground.
    pub fn scale(&self, height_m: f64) -> f64 {
        match *self {
            WindProfile::Uniform => 1.0,
            WindProfile::SquareRoot { reference_m } if reference_m > 0.0 => {
                (height_m / reference_m).clamp(0.0, 1.0).sqrt()
            }
            WindProfile::SquareRoot { .. } => 1.0,
        }
    }
}

/// One 1-cos gust.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gust {
    /// When it starts, seconds.
    pub start_s: f64,
    /// How long it lasts, seconds.
    pub length_s: f64,
    /// Its peak, north and east, m/s.
    pub peak_ne: Vector2<f64>,
}

impl Gust {
    /// Its wind at `t_s`, north and east, m/s.
    pub fn at(&self, t_s: f64) -> Vector2<f64> {
        let u = (t_s - self.start_s) / self.length_s;
        if !(0.0..=1.0).contains(&u) {
            return Vector2::zeros();
        }
        self.peak_ne * (0.5 * (1.0 - (std::f64::consts::TAU * u).cos()))
    }
}

/// The air over a flight (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Wind {
    /// The steady wind, north and east, m/s.
    pub mean_ne: Vector2<f64>,
    /// The gusts, in start order.
    pub gusts: Vec<Gust>,
}

impl Wind {
    /// Still air.
    pub fn calm() -> Self {
        Wind {
            mean_ne: Vector2::zeros(),
            gusts: Vec::new(),
        }
    }

    /// A mean wind of `mean_mps` and gusts of peak `gust_mps` over `duration_s`, from `seed`.
    pub fn new(mean_mps: f64, gust_mps: f64, duration_s: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7769_6e64); // "wind"
        let heading = |rng: &mut ChaCha8Rng| {
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(a.cos(), a.sin())
        };
        let mean_ne = heading(&mut rng) * mean_mps.max(0.0);
        let mut gusts = Vec::new();
        if gust_mps > 0.0 {
            // The first gust may already be blowing at the start.
            let mut t = -GUST_LENGTH_S.1 * rng.random_range(0.0..1.0);
            while t < duration_s {
                let length_s = rng.random_range(GUST_LENGTH_S.0..GUST_LENGTH_S.1);
                gusts.push(Gust {
                    start_s: t,
                    length_s,
                    peak_ne: heading(&mut rng) * gust_mps,
                });
                let u: f64 = rng.random_range(1e-9..1.0);
                t += -GUST_MEAN_INTERVAL_S * u.ln();
            }
        }
        Wind { mean_ne, gusts }
    }

    /// The wind at `t_s`, NED (no vertical part), m/s.
    pub fn at(&self, t_s: f64) -> Vector3<f64> {
        let ne = self.gusts.iter().fold(self.mean_ne, |w, g| w + g.at(t_s));
        Vector3::new(ne.x, ne.y, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gust_rises_to_its_peak_and_falls_back() {
        let g = Gust {
            start_s: 1.0,
            length_s: 4.0,
            peak_ne: Vector2::new(3.0, 0.0),
        };
        assert_eq!(g.at(0.5), Vector2::zeros());
        assert!((g.at(3.0).x - 3.0).abs() < 1e-12);
        assert!(g.at(5.0).norm() < 1e-12);
        assert!((g.at(2.0).x - 1.5).abs() < 1e-12);
    }

    #[test]
    fn the_wind_is_seeded_and_bounded() {
        let a = Wind::new(2.0, 3.0, 60.0, 7);
        assert_eq!(a, Wind::new(2.0, 3.0, 60.0, 7));
        assert_ne!(a, Wind::new(2.0, 3.0, 60.0, 8));
        assert!((a.mean_ne.norm() - 2.0).abs() < 1e-12);
        assert!(a.gusts.len() >= 3, "{}", a.gusts.len());
        let strongest = (0..6000)
            .map(|k| (a.at(k as f64 * 0.01) - a.at(-1e9)).norm())
            .fold(0.0, f64::max);
        assert!(strongest > 1.0 && strongest < 6.0 + 1e-9, "{strongest}");
        assert_eq!(Wind::calm().at(3.0), Vector3::zeros());
    }

    #[test]
    fn sitl_s_profile_thins_the_wind_toward_the_ground() {
        let sitl = WindProfile::sitl();
        assert_eq!(sitl.scale(60.0), 1.0);
        assert_eq!(sitl.scale(100.0), 1.0);
        assert!((sitl.scale(15.0) - 0.5).abs() < 1e-12);
        assert!((sitl.scale(0.6) - 0.1).abs() < 1e-12);
        assert_eq!(sitl.scale(-1.0), 0.0);
        assert_eq!(WindProfile::Uniform.scale(0.5), 1.0);
    }
}
