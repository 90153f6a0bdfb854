//! The simulated world: the ground plane z = 0 of the pad frame, carrying the printed pad, a
//! procedural ground texture, the sun and sky light, an optional shadow edge and an optional
//! occluding blob.
//!
//! Radiance is linear and relative: `albedo x illumination`, where daylight illumination is
//! `sky + direct` (1.0 in the default lighting) and a shadowed point keeps only the sky. The
//! sensor model ([`super::sensor`]) turns radiance into electrons and grey levels.
//!
//! The renderer asks two questions: the radiance at a ground point (per sub-sample) and
//! whether a pixel's footprint (the convex quad its four corners map to) is uniform, so one
//! sample can stand for the whole pixel. A footprint is uniform when all four corners fall in
//! the same cell of the same marker (cells are convex), or it misses every marker and lies
//! wholly on the sheet or wholly off it, and it crosses no shadow boundary and no occluder.

use super::pad::{PrintedPad, Rect};
use super::texture::GroundTexture;

/// Albedo of the printed white.
pub const PAPER_ALBEDO: f32 = 0.80;
/// Albedo of the printed black.
pub const INK_ALBEDO: f32 = 0.04;
/// Radiance of any ray that misses the ground (looking at or above the horizon).
pub const SKY_RADIANCE: f32 = 1.2;

/// A straight shadow edge on the ground (a building's or a person's shadow across the pad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowEdge {
    /// A point of the edge (pad frame, metres).
    pub point: [f64; 2],
    /// Unit normal of the edge, pointing into the shadow.
    pub normal: [f64; 2],
    /// Width of the penumbra, metres (the sun's 0.53 degree disc times the distance from the
    /// shadow-casting edge: about 1 cm per metre).
    pub penumbra_m: f64,
}

impl ShadowEdge {
    /// A shadow edge through `point` whose shadow lies toward `direction_deg` (degrees
    /// counter-clockwise from pad +x).
    pub fn new(point: [f64; 2], direction_deg: f64, penumbra_m: f64) -> Self {
        let a = direction_deg.to_radians();
        ShadowEdge {
            point,
            normal: [a.cos(), a.sin()],
            penumbra_m: penumbra_m.max(0.0),
        }
    }

    /// Signed distance into the shadow, metres.
    #[inline]
    fn depth(&self, x: f64, y: f64) -> f64 {
        (x - self.point[0]) * self.normal[0] + (y - self.point[1]) * self.normal[1]
    }

    /// Fraction of the sun seen at a depth (1 lit, 0 shadowed; linear across the penumbra,
    /// which is what a disc-shaped sun over a straight edge gives to first order).
    #[inline]
    fn sun_fraction(&self, depth: f64) -> f64 {
        if self.penumbra_m <= 0.0 {
            return if depth > 0.0 { 0.0 } else { 1.0 };
        }
        (0.5 - depth / self.penumbra_m).clamp(0.0, 1.0)
    }

    /// 0 fully lit, 1 penumbra, 2 fully shadowed.
    #[inline]
    fn zone(&self, depth: f64) -> u8 {
        let half = 0.5 * self.penumbra_m;
        if depth < -half || (half == 0.0 && depth <= 0.0) {
            0
        } else if depth > half {
            2
        } else {
            1
        }
    }
}

/// Light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    /// Direct sunlight on the ground plane (relative).
    pub direct: f64,
    /// Diffuse sky light (relative); what remains in shadow.
    pub sky: f64,
    /// A shadow edge, if any.
    pub shadow: Option<ShadowEdge>,
}

impl Lighting {
    /// Ordinary daylight: 0.8 direct + 0.2 sky.
    pub fn daylight() -> Self {
        Lighting {
            direct: 0.8,
            sky: 0.2,
            shadow: None,
        }
    }
}

/// Something dark lying on the pad (a leaf, a shoe, a bag): an ellipse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Occluder {
    /// Centre, pad frame, metres.
    pub center: [f64; 2],
    /// Semi-axes, metres.
    pub radii: [f64; 2],
    /// Direction of the first semi-axis, degrees counter-clockwise from pad +x.
    pub angle_deg: f64,
    /// Its albedo.
    pub albedo: f32,
}

impl Occluder {
    #[inline]
    fn contains(&self, x: f64, y: f64) -> bool {
        let (s, c) = self.angle_deg.to_radians().sin_cos();
        let (dx, dy) = (x - self.center[0], y - self.center[1]);
        let u = (c * dx + s * dy) / self.radii[0];
        let v = (-s * dx + c * dy) / self.radii[1];
        u * u + v * v <= 1.0
    }

    fn bounds(&self) -> Rect {
        let r = self.radii[0].max(self.radii[1]);
        Rect {
            x0: self.center[0] - r,
            x1: self.center[0] + r,
            y0: self.center[1] - r,
            y1: self.center[1] + r,
        }
    }
}

/// The ground plane and everything on it.
#[derive(Debug, Clone)]
pub struct World {
    /// The printed pad.
    pub pad: PrintedPad,
    /// The ground around it.
    pub ground: GroundTexture,
    /// Sun, sky and shadow.
    pub lighting: Lighting,
    /// An occluding blob, if any.
    pub occluder: Option<Occluder>,
}

/// What one sample can say about a pixel footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Footprint {
    /// Uniform: this albedo everywhere (ground: `None`, to be textured).
    Uniform(Option<f32>),
    /// Needs sub-samples.
    Mixed,
}

impl World {
    /// Plain daylight over `ground`, nothing else.
    pub fn new(pad: PrintedPad, ground: GroundTexture) -> Self {
        World {
            pad,
            ground,
            lighting: Lighting::daylight(),
            occluder: None,
        }
    }

    /// Albedo of the printed or lying things at a ground point; `None` on bare ground.
    #[inline]
    pub(crate) fn object_albedo(&self, x: f64, y: f64) -> Option<f32> {
        if let Some(o) = &self.occluder {
            if o.contains(x, y) {
                return Some(o.albedo);
            }
        }
        // Later markers lie on top of earlier ones.
        for m in self.pad.markers.iter().rev() {
            if !m.bounds.contains(x, y) {
                continue;
            }
            let (col, row) = m.grid_coords(x, y);
            let n = m.grid() as f64;
            if col >= 0.0 && row >= 0.0 && col < n && row < n {
                let white = m.pattern.is_white(row as usize, col as usize);
                return Some(if white { PAPER_ALBEDO } else { INK_ALBEDO });
            }
        }
        self.pad.sheet.contains(x, y).then_some(PAPER_ALBEDO)
    }

    /// Illumination at a ground point.
    #[inline]
    pub(crate) fn illumination(&self, x: f64, y: f64) -> f64 {
        let l = &self.lighting;
        match &l.shadow {
            None => l.sky + l.direct,
            Some(s) => l.sky + l.direct * s.sun_fraction(s.depth(x, y)),
        }
    }

    /// Whether the shadow is the same over a convex footprint given its corners: `Some(mean
    /// illumination)` when all corners are in the same zone (lit, penumbra, shadowed; the
    /// illumination is affine inside each zone).
    #[inline]
    pub(crate) fn footprint_illumination(&self, corners: &[(f64, f64); 4]) -> Option<f64> {
        let l = &self.lighting;
        let Some(s) = &l.shadow else {
            return Some(l.sky + l.direct);
        };
        let depths = corners.map(|(x, y)| s.depth(x, y));
        let zone = s.zone(depths[0]);
        if depths.iter().any(|&d| s.zone(d) != zone) {
            return None;
        }
        let sun = depths.iter().map(|&d| s.sun_fraction(d)).sum::<f64>() * 0.25;
        Some(l.sky + l.direct * sun)
    }

    /// Whether one albedo describes a convex footprint with these corners (see the module
    /// docs).
    #[inline]
    pub(crate) fn footprint(&self, corners: &[(f64, f64); 4]) -> Footprint {
        let mut bounds = Rect {
            x0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y0: f64::INFINITY,
            y1: f64::NEG_INFINITY,
        };
        for &(x, y) in corners {
            bounds.x0 = bounds.x0.min(x);
            bounds.x1 = bounds.x1.max(x);
            bounds.y0 = bounds.y0.min(y);
            bounds.y1 = bounds.y1.max(y);
        }
        let overlaps = |r: &Rect| {
            bounds.x1 >= r.x0 && bounds.x0 <= r.x1 && bounds.y1 >= r.y0 && bounds.y0 <= r.y1
        };
        if let Some(o) = &self.occluder {
            if overlaps(&o.bounds()) {
                return if corners.iter().all(|&(x, y)| o.contains(x, y)) {
                    Footprint::Uniform(Some(o.albedo))
                } else {
                    Footprint::Mixed
                };
            }
        }
        let sheet = &self.pad.sheet;
        if !overlaps(sheet) {
            return Footprint::Uniform(None);
        }
        let mut hit = None;
        for m in &self.pad.markers {
            if !overlaps(&m.bounds) {
                continue;
            }
            let n = m.grid() as f64;
            let g = corners.map(|(x, y)| m.grid_coords(x, y));
            let (c0, c1) = g
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.0), b.max(p.0))
                });
            let (r0, r1) = g
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.1), b.max(p.1))
                });
            if c1 < 0.0 || r1 < 0.0 || c0 >= n || r0 >= n {
                continue;
            }
            if hit.is_some() {
                return Footprint::Mixed;
            }
            let (col, row) = (c0.floor(), r0.floor());
            let same_cell = col >= 0.0
                && row >= 0.0
                && col < n
                && row < n
                && c1.floor() == col
                && r1.floor() == row;
            if !same_cell {
                return Footprint::Mixed;
            }
            let white = m.pattern.is_white(row as usize, col as usize);
            hit = Some(if white { PAPER_ALBEDO } else { INK_ALBEDO });
        }
        if hit.is_some() {
            return Footprint::Uniform(hit);
        }
        if corners.iter().all(|&(x, y)| sheet.contains(x, y)) {
            Footprint::Uniform(Some(PAPER_ALBEDO))
        } else {
            Footprint::Mixed
        }
    }
}
