//! The three errors of every frame and method of a replay in flight, and their statistics:
//! over all frames and near altitude checkpoints (each error near the altitude of its own
//! truth).

use super::{FlightOutcome, Scored};

/// Which of the three errors (see [`super`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// (a) what touchdown sends.
    Sent,
    /// (b) what the autopilot reconstructs from it.
    Reconstructed,
    /// (c) what it would reconstruct from an ideal sensor.
    Ideal,
}

impl ErrorKind {
    /// The three, in (a), (b), (c) order.
    pub const ALL: [ErrorKind; 3] = [ErrorKind::Sent, ErrorKind::Reconstructed, ErrorKind::Ideal];

    /// "a", "b" or "c".
    pub fn letter(self) -> &'static str {
        match self {
            ErrorKind::Sent => "a",
            ErrorKind::Reconstructed => "b",
            ErrorKind::Ideal => "c",
        }
    }

    /// The JSON key: `sent`, `reconstructed`, `ideal`.
    pub fn key(self) -> &'static str {
        match self {
            ErrorKind::Sent => "sent",
            ErrorKind::Reconstructed => "reconstructed",
            ErrorKind::Ideal => "ideal",
        }
    }
}

/// Statistics of one error over some frames, metres.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ErrorStats {
    /// Frames with this error.
    pub frames: usize,
    /// Mean of sqrt(ex^2 + ey^2).
    pub mean_horizontal: Option<f64>,
    /// Mean |error| per axis x, y, z.
    pub mean_abs: Option<[f64; 3]>,
    /// Mean error per axis.
    pub mean: Option<[f64; 3]>,
    /// RMS error per axis.
    pub rms: Option<[f64; 3]>,
}

impl ErrorStats {
    fn of<'a>(scored: impl Iterator<Item = &'a Scored>) -> ErrorStats {
        let mut n = 0usize;
        let (mut h, mut abs, mut sum, mut sq) = (0.0, [0.0; 3], [0.0; 3], [0.0; 3]);
        for s in scored {
            let e = s.error();
            n += 1;
            h += e.xy().norm();
            for k in 0..3 {
                abs[k] += e[k].abs();
                sum[k] += e[k];
                sq[k] += e[k] * e[k];
            }
        }
        if n == 0 {
            return ErrorStats::default();
        }
        let f = n as f64;
        ErrorStats {
            frames: n,
            mean_horizontal: Some(h / f),
            mean_abs: Some(abs.map(|v| v / f)),
            mean: Some(sum.map(|v| v / f)),
            rms: Some(sq.map(|v| (v / f).sqrt())),
        }
    }
}

/// Per frame (in replay order), per method, the three errors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FlightTrace {
    /// Method names, in outcome order.
    pub methods: Vec<String>,
    /// The frames.
    pub frames: Vec<Vec<FlightOutcome>>,
}

impl FlightTrace {
    /// An empty trace for `methods`.
    pub fn new(methods: Vec<String>) -> Self {
        FlightTrace {
            methods,
            frames: Vec::new(),
        }
    }

    fn scored(&self, m: usize, kind: ErrorKind) -> impl Iterator<Item = &Scored> {
        self.frames
            .iter()
            .filter_map(move |f| f.get(m).and_then(|o| o.get(kind)))
    }

    /// Error `kind` of method `m` over every frame that has it.
    pub fn summary(&self, m: usize, kind: ErrorKind) -> ErrorStats {
        ErrorStats::of(self.scored(m, kind))
    }

    /// Error `kind` of method `m` over the frames whose truth (that error's own) is within
    /// `tolerance * altitude_m` of `altitude_m`.
    pub fn at_altitude(
        &self,
        m: usize,
        kind: ErrorKind,
        altitude_m: f64,
        tolerance: f64,
    ) -> ErrorStats {
        ErrorStats::of(
            self.scored(m, kind)
                .filter(|s| (s.truth.z - altitude_m).abs() <= tolerance * altitude_m),
        )
    }

    /// The first frame (index into `frames`) after which method `m`'s board took the pad as
    /// moving; `None` if it never did.
    pub fn pad_moving_from(&self, m: usize) -> Option<usize> {
        self.frames
            .iter()
            .position(|f| f.get(m).is_some_and(|o| o.pad_moving))
    }

    /// Method `m`'s exposure-to-receipt time of its targets: (mean, max), milliseconds.
    pub fn latency_ms(&self, m: usize) -> Option<(f64, f64)> {
        let l: Vec<f64> = self
            .frames
            .iter()
            .filter_map(|f| f.get(m).and_then(|o| o.latency_us))
            .map(|us| us as f64 * 1e-3)
            .collect();
        if l.is_empty() {
            return None;
        }
        let mean = l.iter().sum::<f64>() / l.len() as f64;
        Some((mean, l.iter().copied().fold(0.0, f64::max)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn horizontal_mean_is_of_the_vector() {
        let scored = |z: f64, ex: f64, ey: f64| Scored {
            t_us: 0,
            truth: Vector3::new(0.0, 0.0, z),
            value: Vector3::new(-ex, -ey, z),
        };
        let mut t = FlightTrace::new(vec!["m".into()]);
        for (z, ex, ey) in [(10.0, 0.3, 0.4), (10.2, 0.0, 0.1), (2.0, 0.01, 0.0)] {
            t.frames.push(vec![FlightOutcome {
                reconstructed: Some(scored(z, ex, ey)),
                ..FlightOutcome::default()
            }]);
        }
        let s = t.at_altitude(0, ErrorKind::Reconstructed, 10.0, 0.1);
        assert_eq!(s.frames, 2);
        assert!((s.mean_horizontal.unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(t.summary(0, ErrorKind::Sent).frames, 0);
        assert_eq!(t.summary(0, ErrorKind::Reconstructed).frames, 3);
    }
}
