//! Landing pad layouts: which markers a pad carries, how large, and where.
//!
//! The pad frame (contract): origin at the landing point, x right, y up, z up out of the pad
//! (a marker-style frame, so a single-marker pad's frame is its marker's frame). Each
//! [`PadMarker`] places a marker's own frame in it: centre at `(x, y, 0)`, turned by
//! `yaw_deg` about the pad z axis. A marker-frame point `p` is at `Rz(yaw) p + (x, y, 0)`
//! on the pad.
//!
//! A layout is a fixed-capacity array ([`MAX_PAD_MARKERS`]) built by a `const fn`, so the
//! firmware holds its pad in a `const`/`static` ([`designs`]) while the host builds one from
//! a `pad.toml` file (markers borrow their family names from the caller). Markers refer to
//! their family by name, matched against [`Family::name`](crate::family::Family) of the
//! families the detector ran with.
//!
//! Why nested pads: one marker is only usable while its image is between about 14 pixels
//! (decodable) and most of the frame (fully visible). For a 70 degree lens that is a factor
//! of ~27 in altitude; a landing from 40 m to 0.3 m spans 130, so a pad needs markers of
//! several sizes. See [`designs`] and `pads/*.toml` for the arithmetic.

/// Most markers on a pad.
pub const MAX_PAD_MARKERS: usize = 80;

/// One marker on the pad.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PadMarker<'a> {
    /// Family name (`tag36h11`, `aruco_6x6_250`, or a user family's name).
    pub family: &'a str,
    /// Id within the family.
    pub id: u16,
    /// Edge of the outer black border, metres.
    pub size: f32,
    /// Marker centre in the pad frame, metres.
    pub x: f32,
    /// Marker centre in the pad frame, metres.
    pub y: f32,
    /// Rotation of the marker about the pad z axis, degrees (counter-clockwise seen from
    /// above).
    pub yaw_deg: f32,
}

impl PadMarker<'_> {
    /// A placeholder for unused slots.
    pub(crate) const EMPTY: PadMarker<'static> = PadMarker {
        family: "",
        id: 0,
        size: 0.0,
        x: 0.0,
        y: 0.0,
        yaw_deg: 0.0,
    };

    /// A marker-frame point in the pad frame.
    pub fn to_pad(&self, p: &nalgebra::Vector3<f32>) -> nalgebra::Vector3<f32> {
        let yaw = self.yaw_deg.to_radians();
        let (s, c) = (libm::sinf(yaw), libm::cosf(yaw));
        nalgebra::Vector3::new(c * p.x - s * p.y + self.x, s * p.x + c * p.y + self.y, p.z)
    }
}

/// Why a layout is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PadError {
    /// No marker.
    Empty,
    /// More than [`MAX_PAD_MARKERS`] markers.
    TooManyMarkers,
    /// Marker `index` has a size that is not finite and positive.
    BadSize {
        /// Position in the list.
        index: u8,
    },
    /// Marker `index` has a non-finite position or yaw.
    BadPlacement {
        /// Position in the list.
        index: u8,
    },
    /// Marker `index` has an empty family name.
    NoFamily {
        /// Position in the list.
        index: u8,
    },
    /// Marker `index` repeats the family and id of an earlier one (a detection could not be
    /// attributed).
    Duplicate {
        /// Position in the list.
        index: u8,
    },
}

/// A pad: a name and up to [`MAX_PAD_MARKERS`] markers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadLayout<'a> {
    name: &'a str,
    markers: [PadMarker<'a>; MAX_PAD_MARKERS],
    len: usize,
}

/// `a == b` for strings, ASCII case ignored, usable in `const fn`.
const fn same_name(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut rest = (a, b);
    while let ([x, xs @ ..], [y, ys @ ..]) = rest {
        if !x.eq_ignore_ascii_case(y) {
            return false;
        }
        rest = (xs, ys);
    }
    true
}

impl<'a> PadLayout<'a> {
    /// A checked layout (a `const fn`: a firmware pad is checked at compile time by
    /// matching on the result in a `const`).
    pub const fn new(name: &'a str, markers: &[PadMarker<'a>]) -> Result<Self, PadError> {
        if markers.is_empty() {
            return Err(PadError::Empty);
        }
        if markers.len() > MAX_PAD_MARKERS {
            return Err(PadError::TooManyMarkers);
        }
        let mut out = [PadMarker::EMPTY; MAX_PAD_MARKERS];
        let mut len = 0;
        let mut rest = markers;
        while let [m, tail @ ..] = rest {
            let index = len as u8;
            if !(m.size.is_finite() && m.size > 0.0) {
                return Err(PadError::BadSize { index });
            }
            if !(m.x.is_finite() && m.y.is_finite() && m.yaw_deg.is_finite()) {
                return Err(PadError::BadPlacement { index });
            }
            if m.family.is_empty() {
                return Err(PadError::NoFamily { index });
            }
            let mut earlier = markers;
            let mut k = 0;
            while let [e, etail @ ..] = earlier {
                if k >= len {
                    break;
                }
                if e.id == m.id && same_name(e.family, m.family) {
                    return Err(PadError::Duplicate { index });
                }
                earlier = etail;
                k += 1;
            }
            out = place(out, len, *m);
            len += 1;
            rest = tail;
        }
        Ok(PadLayout {
            name,
            markers: out,
            len,
        })
    }

    /// The pad's name.
    pub fn name(&self) -> &'a str {
        self.name
    }

    /// The markers.
    pub fn markers(&self) -> &[PadMarker<'a>] {
        self.markers.get(..self.len).unwrap_or(&[])
    }

    /// The layout marker of a family name and id.
    pub fn find(&self, family: &str, id: u16) -> Option<&PadMarker<'a>> {
        self.markers()
            .iter()
            .find(|m| m.id == id && same_name(m.family, family))
    }
}

/// `array` with element `index` replaced (`const fn`; out-of-range indices change nothing).
const fn place<'a, const N: usize>(
    mut array: [PadMarker<'a>; N],
    index: usize,
    marker: PadMarker<'a>,
) -> [PadMarker<'a>; N] {
    let mut k = 0;
    let mut slots: &mut [PadMarker<'a>] = &mut array;
    while let [slot, rest @ ..] = slots {
        if k == index {
            *slot = marker;
        }
        slots = rest;
        k += 1;
    }
    array
}

/// Unwraps a layout in a `const` context: an invalid layout becomes the empty one (which a
/// test then catches), so no panic path exists.
const fn or_empty(layout: Result<PadLayout<'static>, PadError>) -> PadLayout<'static> {
    match layout {
        Ok(l) => l,
        Err(_) => PadLayout {
            name: "",
            markers: [PadMarker::EMPTY; MAX_PAD_MARKERS],
            len: 0,
        },
    }
}

/// The shipped pad designs; identical to `pads/*.toml` (a host test compares them).
///
/// A public module because it is a namespace of data, not a stage: the designs by name
/// (`designs::NESTED`, `designs::PAPER_SINGLE`) and all of them (`designs::ALL`).
///
/// Coverage arithmetic, for a 640x480 camera with a 70 degree horizontal field of view
/// (`f = 320 / tan 35deg = 457 px`), looking straight down from altitude `h` above the
/// landing point: a marker of edge `s` is `457 s / h` pixels wide. It is decodable down to
/// about 14 px, so up to `h = 32.6 s`; it must stay within 80 % of the frame height
/// (384 px), so down to `h = 1.19 s`; and an off-centre marker must lie entirely in view,
/// `|offset| + s/2 <= 0.525 h` along the frame's short (vertical) side.
pub mod designs {
    use super::{or_empty, place, PadLayout, PadMarker};

    const fn m(family: &'static str, id: u16, size: f32, x: f32, y: f32) -> PadMarker<'static> {
        PadMarker {
            family,
            id,
            size,
            x,
            y,
            yaw_deg: 0.0,
        }
    }

    /// The paper's setup: one aruco_6x6_250 marker (the paper's 8x8-cell markers), 1 m,
    /// centred on the landing point. Usable from 32.6 m down to 1.2 m.
    pub const PAPER_SINGLE: PadLayout<'static> = or_empty(PadLayout::new(
        "paper-single",
        &[m("aruco_6x6_250", 0, 1.0, 0.0, 0.0)],
    ));

    /// touchdown's nested pad (tag36h11): a 1.25 m marker for altitude, four 0.40 m markers
    /// around the landing point for the middle range, a 0.16 m marker on the landing point
    /// for the last metre. At least one marker is fully in view and at least 14 px wide from
    /// 40.8 m down to 0.19 m:
    ///
    /// | marker | size | centre | decodable up to | fully in view down to |
    /// |---|---|---|---|---|
    /// | id 0 | 1.25 m | (0, 1.40) | 40.8 m | 3.9 m (offset) |
    /// | ids 1-4 | 0.40 m | (+-0.35, +-0.35) | 13.0 m | 1.05 m (offset) |
    /// | id 5 | 0.16 m | (0, 0) | 5.2 m | 0.19 m (80 % of frame) |
    pub const NESTED: PadLayout<'static> = or_empty(PadLayout::new("nested", &{
        let [a, b, c, d, e] = LARGE_AND_MIDDLE;
        [a, b, c, d, e, m("tag36h11", 5, 0.16, 0.0, 0.0)]
    }));

    /// The large and middle markers of [`NESTED`] and [`NESTED_REST`] alike: same ids, same
    /// places, so either pad's firmware finds the other's down to about a metre.
    const LARGE_AND_MIDDLE: [PadMarker<'static>; 5] = [
        m("tag36h11", 0, 1.25, 0.0, 1.4),
        m("tag36h11", 1, 0.40, -0.35, 0.35),
        m("tag36h11", 2, 0.40, 0.35, 0.35),
        m("tag36h11", 3, 0.40, 0.35, -0.35),
        m("tag36h11", 4, 0.40, -0.35, -0.35),
    ];

    /// The rest field of [`NESTED_REST`]: markers per side.
    const REST_SIDE: usize = 5;
    /// Edge of a rest-field marker, metres.
    const REST_SIZE: f32 = 0.027;
    /// Centre-to-centre spacing of the rest field, metres: one marker plus both quiet rings
    /// (a cell each, `size / 8`), rounded up to the millimetre.
    const REST_PITCH: f32 = 0.034;
    /// Id of the rest field's first marker (top left; then row by row, left to right).
    const REST_FIRST_ID: u16 = 10;
    /// The markers of [`NESTED_REST`] besides its rest field.
    const NESTED_REST_FRAME: [PadMarker<'static>; 9] = {
        let [a, b, c, d, e] = LARGE_AND_MIDDLE;
        [
            a,
            b,
            c,
            d,
            e,
            m("tag36h11", 6, 0.12, 0.0, 0.16),
            m("tag36h11", 7, 0.12, 0.16, 0.0),
            m("tag36h11", 8, 0.12, 0.0, -0.16),
            m("tag36h11", 9, 0.12, -0.16, 0.0),
        ]
    };
    /// Markers of [`NESTED_REST`].
    const NESTED_REST_LEN: usize = NESTED_REST_FRAME.len() + REST_SIDE * REST_SIDE;

    /// `markers` placed in `out` from slot `k` on; the array and the next free slot.
    const fn place_all<const N: usize>(
        mut out: [PadMarker<'static>; N],
        mut k: usize,
        mut markers: &[PadMarker<'static>],
    ) -> ([PadMarker<'static>; N], usize) {
        while let [marker, rest @ ..] = markers {
            out = place(out, k, *marker);
            (k, markers) = (k + 1, rest);
        }
        (out, k)
    }

    /// The rest field's marker `cell` (row by row from the top, left to right), for
    /// [`NESTED_REST`] and [`NESTED_FIELD`] alike.
    const fn rest_marker(cell: usize) -> PadMarker<'static> {
        let half = (REST_SIDE - 1) as f32 / 2.0;
        let (row, col) = ((cell / REST_SIDE) as f32, (cell % REST_SIDE) as f32);
        m(
            "tag36h11",
            REST_FIRST_ID + cell as u16,
            REST_SIZE,
            (col - half) * REST_PITCH,
            (half - row) * REST_PITCH,
        )
    }

    /// The rest field placed in `out` from slot `k` on; the array and the next free slot.
    const fn place_rest_field<const N: usize>(
        mut out: [PadMarker<'static>; N],
        mut k: usize,
    ) -> ([PadMarker<'static>; N], usize) {
        let mut cell = 0;
        while cell < REST_SIDE * REST_SIDE {
            out = place(out, k, rest_marker(cell));
            (k, cell) = (k + 1, cell + 1);
        }
        (out, k)
    }

    /// [`NESTED_REST`]'s markers: its frame, then the rest field.
    const fn nested_rest_markers() -> [PadMarker<'static>; NESTED_REST_LEN] {
        let (out, k) = place_all([PadMarker::EMPTY; NESTED_REST_LEN], 0, &NESTED_REST_FRAME);
        place_rest_field(out, k).0
    }

    /// The recommended pad: [`NESTED`]'s large and middle markers (same ids, same places), with
    /// the landing point under a field of small markers so that the camera of a vehicle
    /// *resting* on the pad still has whole markers in view, and four markers between the
    /// two for the last metre. A vehicle gets its position on the ground, so it can arm, take
    /// off and land in a position mode without GPS, and its mount can be calibrated before
    /// take-off. Marker 5 of [`NESTED`] is not used, so neither pad's markers are mistaken
    /// for the other's.
    ///
    /// | marker | size | centre | decodable up to | fully in view down to |
    /// |---|---|---|---|---|
    /// | id 0 | 1.25 m | (0, 1.40) | 40.8 m | 3.9 m (offset) |
    /// | ids 1-4 | 0.40 m | (+-0.35, +-0.35) | 13.0 m | 1.05 m (offset) |
    /// | ids 6-9 | 0.12 m | (0, +-0.16), (+-0.16, 0) | 3.9 m | 0.42 m (offset) |
    /// | ids 10-34 | 0.027 m | 5 x 5 at 0.034 m, within +-0.068 m | 0.88 m | the ground |
    ///
    /// On the ground the rest field keeps a whole marker in view, whatever the heading, with
    /// the camera 0.08 m or more above the pad and within about 8 cm of the landing point
    /// (both lenses above; `the_rest_pad_has_a_marker_in_view_from_the_ground_up` checks it).
    pub const NESTED_REST: PadLayout<'static> =
        or_empty(PadLayout::new("nested-rest", &nested_rest_markers()));

    /// The markers of [`NESTED_FIELD`] besides its rest field and its small markers: the
    /// altitude marker where the other nested pads have it, three 0.40 m markers beside the
    /// field (left, right, below) and four 0.10 m markers on its diagonals (reading order).
    const FIELD_FRAME: [PadMarker<'static>; 8] = [
        LARGE_AND_MIDDLE[0],
        m("tag36h11", 35, 0.40, -0.6, 0.0),
        m("tag36h11", 36, 0.40, 0.6, 0.0),
        m("tag36h11", 37, 0.40, 0.0, -0.6),
        m("tag36h11", 38, 0.10, -0.3, 0.3),
        m("tag36h11", 39, 0.10, 0.3, 0.3),
        m("tag36h11", 40, 0.10, 0.3, -0.3),
        m("tag36h11", 41, 0.10, -0.3, -0.3),
    ];
    /// Edge of [`NESTED_FIELD`]'s small markers, metres.
    const FIELD_SMALL_SIZE: f32 = 0.04;
    /// Their lattice's pitch, metres.
    const FIELD_PITCH: f32 = 0.1;
    /// The eight lattice points around the rest field are pushed out to this pitch, so that
    /// their quiet rings clear the rest field's.
    const FIELD_INNER_PITCH: f32 = 0.11;
    /// Lattice steps from the landing point, each way.
    const FIELD_STEPS: i32 = 4;
    /// Id of the first small marker (top row, left; then row by row, left to right).
    const FIELD_FIRST_ID: u16 = 42;

    /// Where the small marker at lattice step `(i, j)` lies, if there is one: every point
    /// within 0.42 m of the landing point (17 squared steps), except the rest field's centre
    /// and where a 0.40 m marker's quiet ring begins.
    const fn field_small_at(i: i32, j: i32) -> Option<(f32, f32)> {
        let (ai, aj) = (i.abs(), j.abs());
        let outside = i * i + j * j > 17;
        let taken = (ai == 0 && aj == 0) || ai >= 4 || j <= -4;
        if outside || taken {
            return None;
        }
        let pitch = if ai <= 1 && aj <= 1 {
            FIELD_INNER_PITCH
        } else {
            FIELD_PITCH
        };
        Some((i as f32 * pitch, j as f32 * pitch))
    }

    /// How many small markers [`field_small_at`] places.
    const fn field_small_count() -> usize {
        let (mut count, mut j) = (0, FIELD_STEPS);
        while j >= -FIELD_STEPS {
            let mut i = -FIELD_STEPS;
            while i <= FIELD_STEPS {
                if field_small_at(i, j).is_some() {
                    count += 1;
                }
                i += 1;
            }
            j -= 1;
        }
        count
    }

    /// Markers of [`NESTED_FIELD`].
    const NESTED_FIELD_LEN: usize = FIELD_FRAME.len() + REST_SIDE * REST_SIDE + field_small_count();

    /// [`NESTED_FIELD`]'s markers: its frame, the rest field (as [`NESTED_REST`]'s), then the
    /// small markers.
    const fn nested_field_markers() -> [PadMarker<'static>; NESTED_FIELD_LEN] {
        let (out, k) = place_all([PadMarker::EMPTY; NESTED_FIELD_LEN], 0, &FIELD_FRAME);
        let (mut out, mut k) = place_rest_field(out, k);
        let (mut id, mut j) = (FIELD_FIRST_ID, FIELD_STEPS);
        while j >= -FIELD_STEPS {
            let mut i = -FIELD_STEPS;
            while i <= FIELD_STEPS {
                if let Some((x, y)) = field_small_at(i, j) {
                    out = place(out, k, m("tag36h11", id, FIELD_SMALL_SIZE, x, y));
                    (k, id) = (k + 1, id + 1);
                }
                i += 1;
            }
            j -= 1;
        }
        out
    }

    /// The recommended pad, for landings in gusts: some marker stays whole in view with the
    /// camera up to 30 cm off the landing point and tilted up to 10 degrees, facing anywhere,
    /// from 8 m down to 0.2 m, and on the ground the rest field of [`NESTED_REST`] (same ids,
    /// same places) keeps one in view from 0.1 m up. Around the rest field, a lattice of
    /// 0.04 m markers at 0.1 m within 0.42 m of the landing point, four 0.10 m markers and
    /// three 0.40 m markers beyond it; the altitude marker is [`NESTED`]'s id 0, in its place.
    /// Its other ids (35-88) are on neither other nested pad, so no pad's markers are
    /// mistaken for another's.
    ///
    /// | marker | size | centre | decodable up to |
    /// |---|---|---|---|
    /// | id 0 | 1.25 m | (0, 1.40) | 40.8 m |
    /// | ids 35-37 | 0.40 m | (-0.6, 0), (0.6, 0), (0, -0.6) | 13.0 m |
    /// | ids 38-41 | 0.10 m | (-+0.3, +-0.3) | 3.3 m |
    /// | ids 42-88 | 0.04 m | a 0.1 m lattice within 0.42 m | 1.3 m |
    /// | ids 10-34 | 0.027 m | the rest field | 0.88 m |
    ///
    /// `the_field_pad_keeps_a_marker_in_view_30_cm_off_and_tilted` checks the coverage for
    /// the 60 degree 320x240 lens, the 70 degree 640x480 lens and a 100 degree 640x480 lens
    /// with barrel distortion.
    pub const NESTED_FIELD: PadLayout<'static> =
        or_empty(PadLayout::new("nested-field", &nested_field_markers()));

    /// The design the docs recommend, which `touchdown sitl` and the rehearsals draw unless
    /// told otherwise.
    pub const RECOMMENDED: &PadLayout<'static> = &NESTED_FIELD;

    /// Every shipped design.
    pub const ALL: [&PadLayout<'static>; 4] = [&PAPER_SINGLE, &NESTED, &NESTED_REST, &NESTED_FIELD];
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_designs_are_valid() {
        assert_eq!(designs::PAPER_SINGLE.markers().len(), 1);
        assert_eq!(designs::NESTED.markers().len(), 6);
        assert_eq!(designs::NESTED.name(), "nested");
        assert!(designs::NESTED.find("TAG36H11", 5).is_some());
        assert!(designs::NESTED.find("tag36h11", 6).is_none());
    }

    #[test]
    fn bad_layouts_are_refused() {
        let ok = PadMarker {
            family: "tag36h11",
            id: 1,
            size: 0.2,
            x: 0.0,
            y: 0.0,
            yaw_deg: 0.0,
        };
        assert_eq!(PadLayout::new("x", &[]), Err(PadError::Empty));
        assert_eq!(
            PadLayout::new("x", &[ok; MAX_PAD_MARKERS + 1]),
            Err(PadError::TooManyMarkers)
        );
        assert_eq!(
            PadLayout::new("x", &[ok, ok]),
            Err(PadError::Duplicate { index: 1 })
        );
        let bad = PadMarker { size: -1.0, ..ok };
        assert_eq!(
            PadLayout::new("x", &[bad]),
            Err(PadError::BadSize { index: 0 })
        );
        let bad = PadMarker { x: f32::NAN, ..ok };
        assert_eq!(
            PadLayout::new("x", &[bad]),
            Err(PadError::BadPlacement { index: 0 })
        );
    }

    #[test]
    fn yaw_places_marker_points() {
        let m = PadMarker {
            family: "f",
            id: 0,
            size: 1.0,
            x: 1.0,
            y: 2.0,
            yaw_deg: 90.0,
        };
        let p = m.to_pad(&nalgebra::Vector3::new(1.0, 0.0, 0.0));
        assert!((p.x - 1.0).abs() < 1e-6 && (p.y - 3.0).abs() < 1e-6);
    }
}
