//! A landing pad as printed: each layout marker's cell pattern at true size, and the white
//! sheet they are printed on.
//!
//! Shared by the simulator (which renders it on the ground) and `touchdown pad` (which
//! writes it as an SVG), so what is simulated is exactly what gets printed.
//!
//! Geometry (pad frame, contract): x right, y up, z up out of the pad. A marker's grid (quiet
//! rings included) is centred on its `(x, y)` and turned by `yaw_deg` counter-clockwise seen
//! from above; grid row 0 is at the marker's +y side (the top of its canonical image), so an
//! unturned marker reads upright for a camera whose image top points along pad +y. A marker
//! whose family has no quiet ring (ArUco) gets [`MARGIN_CELLS`] of white paper beyond its
//! grid, and the sheet is the bounding box of every marker's paper square. For the shipped
//! nested pad that is 1.5625 m x 2.78125 m, as `pads/nested.toml` says.

use std::fmt;

use touchdown_core::family::tables;
use touchdown_core::pad::PadLayout;

use crate::render::MarkerPattern;
use touchdown_formats::pad::{config_of_layout, PadConfig};

/// White paper beyond the grid of a marker whose family has no quiet ring of its own (ArUco,
/// tagStandard41h12), in that marker's cells. Families with a quiet ring (tag36h11) need none.
pub const MARGIN_CELLS: f64 = 1.0;

/// A marker that can be printed.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedMarker {
    /// Family name as in the layout.
    pub family: String,
    /// Id in the family.
    pub id: u16,
    /// Edge of the outer black border, metres.
    pub size: f64,
    /// Centre in the pad frame, metres.
    pub x: f64,
    /// Centre in the pad frame, metres.
    pub y: f64,
    /// Rotation about the pad z axis, degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
    /// The cells (quiet rings included).
    pub pattern: MarkerPattern,
    /// Edge of one cell, metres.
    pub cell: f64,
    /// White paper beyond the grid, cells (see [`MARGIN_CELLS`]).
    pub margin_cells: f64,
    /// `cos yaw`, `sin yaw`.
    rotation: (f64, f64),
    /// The grid's bounding box in the pad frame: the renderers skip a marker whose box a
    /// point or footprint misses without turning into its frame (a pad of many small markers
    /// would otherwise cost every sample a turn per marker).
    pub bounds: Rect,
}

impl PrintedMarker {
    /// Cells per side of the whole grid.
    pub fn grid(&self) -> usize {
        self.pattern.grid()
    }

    /// Edge of the whole grid (quiet rings included), metres.
    pub fn grid_size(&self) -> f64 {
        self.cell * self.grid() as f64
    }

    /// Grid coordinates (column, row in cells from the grid's top-left corner) of a pad
    /// point.
    #[inline]
    pub fn grid_coords(&self, px: f64, py: f64) -> (f64, f64) {
        let (c, s) = self.rotation;
        let (dx, dy) = (px - self.x, py - self.y);
        // Into the marker frame (inverse yaw), then x grows with the column, y shrinks with
        // the row.
        let lx = c * dx + s * dy;
        let ly = -s * dx + c * dy;
        let half = 0.5 * self.grid_size();
        ((lx + half) / self.cell, (half - ly) / self.cell)
    }

    /// A marker-frame point (metres) in the pad frame.
    pub fn to_pad(&self, lx: f64, ly: f64) -> [f64; 2] {
        let (c, s) = self.rotation;
        [self.x + c * lx - s * ly, self.y + s * lx + c * ly]
    }

    /// The outer corners of the black border in the pad frame (z = 0): top-left, top-right,
    /// bottom-right, bottom-left of the canonical image (the contract's order).
    pub fn corners(&self) -> [[f64; 3]; 4] {
        let h = 0.5 * self.size;
        [(-h, h), (h, h), (h, -h), (-h, -h)].map(|(lx, ly)| {
            let [x, y] = self.to_pad(lx, ly);
            [x, y, 0.0]
        })
    }

    /// Half the edge of the paper square (grid plus margin), metres.
    pub fn paper_half(&self) -> f64 {
        0.5 * self.grid_size() + self.margin_cells * self.cell
    }
}

/// An axis-aligned rectangle in the pad frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Smallest x.
    pub x0: f64,
    /// Largest x.
    pub x1: f64,
    /// Smallest y.
    pub y0: f64,
    /// Largest y.
    pub y1: f64,
}

impl Rect {
    /// Width, metres.
    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    /// Height, metres.
    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    /// Whether a point lies inside (edges included).
    #[inline]
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x0 && x <= self.x1 && y >= self.y0 && y <= self.y1
    }
}

/// Why a layout cannot be printed or rendered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PadBuildError(pub String);

impl fmt::Display for PadBuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PadBuildError {}

/// A pad layout with its cells and sheet.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedPad {
    /// The pad's name.
    pub name: String,
    /// The markers, in layout order (later ones print over earlier ones).
    pub markers: Vec<PrintedMarker>,
    /// The white sheet: the bounding box of every marker's paper square.
    pub sheet: Rect,
    /// The layout as a `pad.toml` would hold it.
    pub config: PadConfig,
}

impl PrintedPad {
    /// From a `pad.toml`'s contents. Families must be shipped ones (their cells are needed).
    pub fn from_config(config: &PadConfig) -> Result<Self, PadBuildError> {
        config
            .layout()
            .map_err(|e| PadBuildError(format!("invalid pad layout: {e:?}")))?;
        let mut markers = Vec::with_capacity(config.markers.len());
        for (index, m) in config.markers.iter().enumerate() {
            let family = tables::by_name(&m.family).ok_or_else(|| {
                PadBuildError(format!(
                    "marker[{index}]: family `{}` is not a shipped family (shipped: {})",
                    m.family,
                    tables::names().collect::<Vec<_>>().join(", ")
                ))
            })?;
            let pattern = MarkerPattern::from_code(family, usize::from(m.id)).ok_or_else(|| {
                PadBuildError(format!(
                    "marker[{index}]: {} has no id {} (it has {} codes)",
                    family.name,
                    m.id,
                    family.codes.len()
                ))
            })?;
            let cell = m.size / pattern.edge_cells() as f64;
            let yaw = m.yaw_deg.to_radians();
            let (cos, sin) = (yaw.cos(), yaw.sin());
            // Half the grid's extent along x and y once turned.
            let reach = 0.5 * cell * pattern.grid() as f64 * (cos.abs() + sin.abs());
            markers.push(PrintedMarker {
                family: m.family.clone(),
                id: m.id,
                size: m.size,
                x: m.x,
                y: m.y,
                yaw_deg: m.yaw_deg,
                pattern,
                cell,
                margin_cells: if family.quiet_rings == 0 {
                    MARGIN_CELLS
                } else {
                    0.0
                },
                rotation: (cos, sin),
                bounds: Rect {
                    x0: m.x - reach,
                    x1: m.x + reach,
                    y0: m.y - reach,
                    y1: m.y + reach,
                },
            });
        }
        check_clearance(&markers)?;
        Ok(PrintedPad {
            name: config.name.clone(),
            sheet: sheet_of(&markers),
            markers,
            config: config.clone(),
        })
    }

    /// The pad with `cells` more white paper printed around every marker (in that marker's
    /// cells) and its sheet grown to hold it: a marker on a wider margin than the detector
    /// knows of, with the ground further from its border.
    pub fn with_wider_margins(mut self, cells: f64) -> Result<Self, PadBuildError> {
        for m in &mut self.markers {
            m.margin_cells += cells.max(0.0);
        }
        check_clearance(&self.markers)?;
        self.sheet = sheet_of(&self.markers);
        Ok(self)
    }

    /// From a core layout (a shipped design).
    pub fn from_layout(layout: &PadLayout<'_>) -> Result<Self, PadBuildError> {
        Self::from_config(&config_of_layout(layout))
    }

    /// A shipped design by name (`paper-single`, `nested`), ASCII case ignored.
    pub fn design(name: &str) -> Option<Self> {
        let layout = touchdown_core::pad::designs::ALL
            .iter()
            .find(|l| l.name().eq_ignore_ascii_case(name))?;
        Self::from_layout(layout).ok()
    }
}

/// The bounding box of every marker's paper square (grid and margin).
fn sheet_of(markers: &[PrintedMarker]) -> Rect {
    let mut sheet = Rect {
        x0: f64::INFINITY,
        x1: f64::NEG_INFINITY,
        y0: f64::INFINITY,
        y1: f64::NEG_INFINITY,
    };
    for m in markers {
        let h = m.paper_half();
        for (lx, ly) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
            let [x, y] = m.to_pad(lx, ly);
            sheet = Rect {
                x0: sheet.x0.min(x),
                x1: sheet.x1.max(x),
                y0: sheet.y0.min(y),
                y1: sheet.y1.max(y),
            };
        }
    }
    sheet
}

/// Refuses a layout in which a marker's black border reaches into another marker's paper
/// square (its grid, quiet rings included, plus its white margin): printed over each other,
/// neither decodes, since a marker needs its cells and the white around its border intact.
/// Squares touching along an edge are fine.
fn check_clearance(markers: &[PrintedMarker]) -> Result<(), PadBuildError> {
    for (j, black) in markers.iter().enumerate() {
        for (k, paper) in markers.iter().enumerate() {
            if j != k && squares_overlap(black, 0.5 * black.size, paper, paper.paper_half()) {
                let (first, second) = if j < k { (j, k) } else { (k, j) };
                let name = |i: usize| {
                    let m = &markers[i];
                    format!("marker[{i}] ({} #{})", m.family, m.id)
                };
                return Err(PadBuildError(format!(
                    "{} and {} overlap (each needs its cells and the white around its border \
                     clear of the other): move them apart or make them smaller",
                    name(first),
                    name(second)
                )));
            }
        }
    }
    Ok(())
}

/// Whether the square of half-edge `ha` centred and turned like `a` overlaps the one of
/// half-edge `hb` placed like `b` by more than a micrometre (separating-axis test: two convex
/// shapes are apart exactly when their projections are apart on one of their edge normals).
fn squares_overlap(a: &PrintedMarker, ha: f64, b: &PrintedMarker, hb: f64) -> bool {
    const TOUCH: f64 = 1e-6;
    let axes = |m: &PrintedMarker| {
        let (c, s) = m.rotation;
        [(c, s), (-s, c)]
    };
    let (axes_a, axes_b) = (axes(a), axes(b));
    let radius = |axes: &[(f64, f64); 2], half: f64, (nx, ny): (f64, f64)| {
        half * axes
            .iter()
            .map(|(ux, uy)| (ux * nx + uy * ny).abs())
            .sum::<f64>()
    };
    axes_a.iter().chain(axes_b.iter()).all(|&axis| {
        let gap = ((b.x - a.x) * axis.0 + (b.y - a.y) * axis.1).abs();
        gap < radius(&axes_a, ha, axis) + radius(&axes_b, hb, axis) - TOUCH
    })
}

/// A shipped design by name, as [`PrintedPad::design`], or the one-line error the tools print
/// for a name that is none of them: "no design `NAME` (shipped: ...)".
pub fn shipped_design(name: &str) -> Result<PrintedPad, String> {
    PrintedPad::design(name).ok_or_else(|| {
        format!(
            "no design `{name}` (shipped: {})",
            design_names().join(", ")
        )
    })
}

/// The names of the shipped designs.
pub fn design_names() -> Vec<&'static str> {
    touchdown_core::pad::designs::ALL
        .iter()
        .map(|l| l.name())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_formats::pad::MarkerConfig;

    #[test]
    fn nested_sheet_and_corners() {
        let pad = PrintedPad::design("nested").unwrap();
        assert_eq!(pad.markers.len(), 6);
        // tag36h11: 10-cell grid, 8-cell border square; id 0 is 1.25 m.
        let m = &pad.markers[0];
        assert!((m.cell - 1.25 / 8.0).abs() < 1e-12);
        let c = m.corners();
        assert!((c[0][0] + 0.625).abs() < 1e-12 && (c[0][1] - (1.4 + 0.625)).abs() < 1e-6);
        // Sheet: id 0's grid (quiet ring included) reaches y = 1.4 + 0.78125; tag36h11 has a
        // quiet ring, so no extra margin.
        assert!((pad.sheet.y1 - (1.4 + 0.78125)).abs() < 1e-6);
        assert!((pad.sheet.width() - 1.5625).abs() < 1e-6);
        assert!((pad.sheet.y0 + 0.6).abs() < 1e-6);
        // ArUco has no quiet ring: one cell of paper around the paper's marker.
        let single = PrintedPad::design("paper-single").unwrap();
        assert!((single.sheet.width() - 1.25).abs() < 1e-12);
        // The canonical top-left cell of the grid is at the marker's top-left.
        let (col, row) = m.grid_coords(c[0][0], c[0][1]);
        assert!((col - 1.0).abs() < 1e-9 && (row - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_wider_margin_grows_the_paper_and_the_sheet_by_whole_cells() {
        let single = PrintedPad::design("paper-single").unwrap();
        let wider = single.clone().with_wider_margins(1.0).unwrap();
        // The paper's 1 m aruco_6x6_250: 8-cell border square, cells of 0.125 m.
        let cell = single.markers[0].cell;
        assert!((cell - 0.125).abs() < 1e-12);
        let grown = wider.markers[0].paper_half() - single.markers[0].paper_half();
        assert!((grown - cell).abs() < 1e-12, "{grown}");
        assert!((wider.sheet.width() - single.sheet.width() - 2.0 * cell).abs() < 1e-12);
        // Markers stay where they were; a negative width widens nothing.
        assert_eq!(wider.markers[0].corners(), single.markers[0].corners());
        let same = single.clone().with_wider_margins(-2.0).unwrap();
        assert!((same.sheet.width() - single.sheet.width()).abs() < 1e-12);
        // A margin that reaches another marker's border is refused, as in a layout.
        let nested = PrintedPad::design("nested").unwrap();
        assert!(nested.with_wider_margins(3.0).is_err());
    }

    #[test]
    fn yaw_turns_counter_clockwise() {
        let mut config = config_of_layout(&touchdown_core::pad::designs::PAPER_SINGLE);
        config.markers[0].yaw_deg = 90.0;
        let pad = PrintedPad::from_config(&config).unwrap();
        // Top-left corner of the canonical image: (-0.5, 0.5) turned by 90 degrees.
        let c = pad.markers[0].corners()[0];
        assert!(
            (c[0] + 0.5).abs() < 1e-12 && (c[1] + 0.5).abs() < 1e-12,
            "{c:?}"
        );
    }

    #[test]
    fn overlapping_markers_are_refused_and_clear_ones_accepted() {
        let mut config = config_of_layout(&touchdown_core::pad::designs::NESTED);
        // Every shipped design keeps its markers apart.
        for layout in touchdown_core::pad::designs::ALL {
            assert!(PrintedPad::from_layout(layout).is_ok(), "{}", layout.name());
        }
        // The small centre marker (id 5, 0.16 m) moved onto a medium one's corner.
        config.markers[5].x = 0.2;
        config.markers[5].y = 0.2;
        let e = PrintedPad::from_config(&config).unwrap_err();
        assert!(e.0.contains("overlap") && e.0.contains("#5"), "{e}");
        // Inside the large marker (a marker printed in another's cells).
        config.markers[5].x = 0.0;
        config.markers[5].y = 1.4;
        assert!(PrintedPad::from_config(&config).is_err());
        // Turned by 45 degrees, a square reaches further along its diagonal: two 0.4 m markers
        // 0.5 m apart (their 0.5 m grids touch) stop being clear.
        let two = |yaw_deg: f64| PadConfig {
            name: "two".into(),
            markers: vec![
                MarkerConfig {
                    family: "tag36h11".into(),
                    id: 1,
                    size: 0.4,
                    x: 0.0,
                    y: 0.0,
                    yaw_deg: 0.0,
                },
                MarkerConfig {
                    family: "tag36h11".into(),
                    id: 2,
                    size: 0.4,
                    x: 0.5,
                    y: 0.0,
                    yaw_deg,
                },
            ],
        };
        assert!(PrintedPad::from_config(&two(0.0)).is_ok());
        assert!(PrintedPad::from_config(&two(45.0)).is_err());
    }
}
