//! Marker families: cell layouts, code tables and decoding.
//!
//! What this module offers: [`Family`] (a family's layout and codes, and [`Family::decode`],
//! which the detector, [`crate::detect`], uses to turn a sampled cell grid into a marker id),
//! the shipped families in [`tables`] and user families read by [`parse_family`]. [`tables`]
//! stays a public module because it is a namespace of data, not a stage: one generated table
//! per family (`tables::TAG36H11`, ...) and the look-ups by name. The look-up index,
//! [`MultiIndex`], is in the private submodule `index`, the parser in `parse`.
//!
//! A family is a set of square cell grids (the codes), each drawn with row 0 at the top,
//! white = 1, black = 0, exactly as in the text files of `shared/data/families`. Any grid
//! with one all-black ring works, which is what lets users bring ArUco, AprilTag or their
//! own 8x8 designs ("the 8x8 cells and the edge length are enough", the paper's promise).
//!
//! ## Layout
//! Rings are counted from the outside (ring 0 is the outermost row/column of cells).
//! - quiet rings: leading rings that are white in every code (the printed margin);
//! - the border ring: the first ring that is black in every code; its outer edge is the
//!   marker edge the size refers to and the corners are reported on;
//! - *reversed* families (AprilTag's tagStandard41h12) carry data outside the border ring.
//!   Their clean edge is the border ring's inner edge against a white ring, which is then a
//!   fixed part of the layout rather than data;
//! - every other cell is a data bit. Bits are numbered in row-major order and packed into a
//!   `u64` with the first data cell as the most significant of the `bits` used bits.
//!
//! ## Error correction
//! [`max_correction_for`] picks how many wrong bits a decode may repair: the largest `k` not
//! above half the family's minimum distance (so a decode is unique) for which a random bit
//! pattern inside a valid border would be accepted with probability at most
//! [`MAX_FALSE_ACCEPT`]. That gives tag36h11 and aruco_6x6_250 two bits, tagStandard41h12
//! three, aruco_7x7_250 six, and none to the 4x4 and 16h5 families whose codes are too short
//! to correct anything safely.
//!
//! ## Look-up
//! [`Family::decode`] finds exact matches by binary search in `sorted_ids`. Corrected matches
//! go through the family's [`MultiIndex`] (multi-index hashing), which verifies
//! only the few codes that share a chunk of bits with a reading; a family without one (a user
//! family parsed at run time) compares the readings with every code. Both give the same
//! answer: the nearest code, ties broken by the smallest id, then the smallest rotation.

mod index;
mod parse;
pub mod tables;

pub use index::MultiIndex;
pub use parse::{parse_family, FamilyError, FamilyErrorKind, FamilyHeader};

/// Largest grid (cells per side) a family may have.
pub const MAX_GRID: usize = 16;

/// The data cells of a grid, (row, column) in row-major order: the order of a code's bits
/// ([`Family::data_cells`]).
pub(crate) type DataCells = heapless::Vec<(u8, u8), { MAX_GRID * MAX_GRID }>;

/// Largest number of data bits per code.
pub const MAX_BITS: usize = 64;

/// Acceptable chance that a random pattern inside a valid black border decodes to some id of
/// the family after error correction (all four rotations counted).
pub const MAX_FALSE_ACCEPT: f64 = 1e-4;

/// What a cell of the grid is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellRole {
    /// Part of the white margin around the border (normal families).
    Quiet,
    /// Part of the black border ring.
    Border,
    /// The white ring just inside the border of a reversed family.
    InnerWhite,
    /// A data bit.
    Data,
}

/// A marker family. Generated tables (see [`tables`]) are `'static`; a user family parsed at
/// run time borrows its codes from the caller.
#[derive(Debug, Clone, Copy)]
pub struct Family<'a> {
    /// The name users select it by (`tag36h11`, `aruco_6x6_250`, a file stem...).
    pub name: &'a str,
    /// Cells per side of the full grid, quiet rings included.
    pub grid: u8,
    /// Number of all-white rings outside the border.
    pub quiet_rings: u8,
    /// Index (from the outside) of the all-black border ring.
    pub border_ring: u8,
    /// Number of data bits per code.
    pub bits: u8,
    /// Smallest Hamming distance between two codes, or a code and a rotation of any code.
    pub min_hamming: u8,
    /// Most bit errors a decode repairs (see [`max_correction_for`]).
    pub max_correction: u8,
    /// The codes, indexed by id.
    pub codes: &'a [u64],
    /// Ids sorted by code, for exact look-ups in O(log n); may be empty (linear search).
    pub sorted_ids: &'a [u16],
    /// Bucket tables for corrected look-ups (families with `max_correction > 0`); `None`
    /// compares every code instead.
    pub index: Option<&'a MultiIndex<'a>>,
}

/// A successful decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decoded {
    /// The id (line index in the family file).
    pub id: u16,
    /// Number of quarter turns (clockwise, as seen in the image) that map the sampled grid
    /// onto the canonical grid; see [`Family::rotate_grid_index`].
    pub rotation: u8,
    /// Number of corrected bits.
    pub hamming: u8,
}

impl<'a> Family<'a> {
    /// Whether two families read the same cells the same way (same grid, rings and bits), so
    /// one sampled grid serves both.
    pub fn same_layout(&self, other: &Family<'_>) -> bool {
        (self.grid, self.quiet_rings, self.border_ring, self.bits)
            == (other.grid, other.quiet_rings, other.border_ring, other.bits)
    }

    /// True when the data lies outside the border ring (tagStandard41h12 style).
    pub fn reversed(&self) -> bool {
        self.quiet_rings < self.border_ring
    }

    /// Ring index of a cell.
    #[inline]
    pub fn ring(&self, row: usize, col: usize) -> usize {
        let n = self.grid as usize;
        let r = row.min(col);
        let r2 =
            (n.saturating_sub(1).saturating_sub(row)).min(n.saturating_sub(1).saturating_sub(col));
        r.min(r2)
    }

    /// What the cell at (row, col) is for.
    #[inline]
    pub fn role(&self, row: usize, col: usize) -> CellRole {
        let ring = self.ring(row, col);
        let b = self.border_ring as usize;
        if ring == b {
            CellRole::Border
        } else if ring < self.quiet_rings as usize {
            CellRole::Quiet
        } else if self.reversed() && ring == b + 1 {
            CellRole::InnerWhite
        } else {
            CellRole::Data
        }
    }

    /// Cells per side of the square whose edge is the detected contour: the outer edge of the
    /// border for normal families, its inner edge for reversed ones. Its top-left corner sits
    /// at grid coordinate [`Family::quad_offset`].
    pub fn quad_cells(&self) -> usize {
        let n = self.grid as usize;
        let ring = if self.reversed() {
            self.border_ring as usize + 1
        } else {
            self.border_ring as usize
        };
        n.saturating_sub(2 * ring)
    }

    /// Grid coordinate of the detected square's top-left corner.
    pub fn quad_offset(&self) -> usize {
        if self.reversed() {
            self.border_ring as usize + 1
        } else {
            self.border_ring as usize
        }
    }

    /// Whether cell (row, col) of code `id` is white; `None` for an unknown id or a cell
    /// outside the grid. Used to draw markers.
    pub fn cell_is_white(&self, id: usize, row: usize, col: usize) -> Option<bool> {
        let n = self.grid as usize;
        if row >= n || col >= n {
            return None;
        }
        let code = *self.codes.get(id)?;
        match self.role(row, col) {
            CellRole::Quiet | CellRole::InnerWhite => Some(true),
            CellRole::Border => Some(false),
            CellRole::Data => {
                let mut index = 0usize;
                for r in 0..n {
                    for c in 0..n {
                        if r == row && c == col {
                            let shift = (self.bits as usize).checked_sub(index + 1)?;
                            return Some((code >> shift) & 1 == 1);
                        }
                        if self.role(r, c) == CellRole::Data {
                            index += 1;
                        }
                    }
                }
                None
            }
        }
    }

    /// Every cell of code `id` at once, in one raster pass over the grid (where
    /// [`Family::cell_is_white`] counts the data cells before its own, each time): row `r`'s
    /// white cells as bits (bit `c` for column `c`) in `rows[r]`. `None` for an unknown id, a
    /// grid wider than 32 cells, or `rows` shorter than the grid.
    pub fn white_rows(&self, id: usize, rows: &mut [u32]) -> Option<()> {
        let n = self.grid as usize;
        let code = *self.codes.get(id)?;
        if n > 32 {
            return None;
        }
        let mut shift = self.bits as usize;
        for (row, bits) in rows.get_mut(..n)?.iter_mut().enumerate() {
            *bits = 0;
            for col in 0..n {
                let white = match self.role(row, col) {
                    CellRole::Quiet | CellRole::InnerWhite => true,
                    CellRole::Border => false,
                    CellRole::Data => {
                        shift = shift.checked_sub(1)?;
                        (code >> shift) & 1 == 1
                    }
                };
                *bits |= u32::from(white) << col;
            }
        }
        Some(())
    }

    /// Where the cell (row, col) of the canonical grid is found in a grid that was read with
    /// `rotation` quarter turns: `sampled[rotate_grid_index(r, c, k)] == canonical[r][c]`.
    #[inline]
    pub fn rotate_grid_index(&self, row: usize, col: usize, rotation: u8) -> (usize, usize) {
        let last = (self.grid as usize).saturating_sub(1);
        match rotation & 3 {
            0 => (row, col),
            1 => (col, last.saturating_sub(row)),
            2 => (last.saturating_sub(row), last.saturating_sub(col)),
            _ => (last.saturating_sub(col), row),
        }
    }

    /// Packs the data bits of a sampled grid (row-major `grid x grid` booleans, white = true)
    /// read in each of the four rotations.
    pub fn codes_of_grid(&self, cells: &[bool]) -> [u64; 4] {
        let n = self.grid as usize;
        let mut out = [0u64; 4];
        // One pass over the data cells feeds all four rotations (runs once per candidate).
        for r in 0..n {
            for c in 0..n {
                if self.role(r, c) != CellRole::Data {
                    continue;
                }
                for (k, code) in out.iter_mut().enumerate() {
                    let (sr, sc) = self.rotate_grid_index(r, c, k as u8);
                    let bit = cells.get(sr * n + sc).copied().unwrap_or(false);
                    *code = (*code << 1) | bit as u64;
                }
            }
        }
        out
    }

    /// The data cells, (row, column) in row-major order: the order of a code's bits. `None`
    /// for a grid larger than [`MAX_GRID`] (only a hand-built, invalid family). A reader that
    /// asks for them once and walks the list (the detector's read, several passes a
    /// candidate) does not ask every cell's [`Family::role`] each time.
    #[inline(always)] // returned by value, its 516 bytes were copied on every read
    pub(crate) fn data_cells(&self) -> Option<DataCells> {
        let n = self.grid as usize;
        if n > MAX_GRID {
            return None;
        }
        // A cell's role depends on its ring only (the distance to the nearest side, the
        // lesser of its row's and its column's): the roles of the rings, asked once each
        // along the diagonal (cell (k, k) lies on ring k), as a mask.
        let depth = |i: usize| i.min(n - 1 - i);
        let mut data_rings = 0u32;
        for ring in 0..n.div_ceil(2) {
            if self.role(ring, ring) == CellRole::Data {
                data_rings |= 1 << ring;
            }
        }
        let is_data = |ring: usize| (data_rings >> ring) & 1 != 0;
        let mut data = DataCells::new();
        // n <= MAX_GRID: every cell fits, and its row and column a byte.
        let mut push = |r: usize, c: usize| {
            let _ = data.push((r as u8, c as u8));
        };
        for r in 0..n {
            // Along row r (ring dr), columns nearer a side than the row lie on their own
            // rings, the others on the row's: a run of cells of one role.
            let dr = depth(r);
            for c in 0..dr {
                if is_data(c) {
                    push(r, c);
                }
            }
            if is_data(dr) {
                for c in dr..n - dr {
                    push(r, c);
                }
            }
            for c in n - dr..n {
                if is_data(n - 1 - c) {
                    push(r, c);
                }
            }
        }
        Some(data)
    }

    /// [`Family::codes_of_grid`] over the data cells `data` (from [`Family::data_cells`]):
    /// the same codes, without asking every cell's role again. One rotation at a time, so
    /// that a code's two words stay in registers (the four codes at once were spilled on
    /// every bit), each with its own index ([`Family::rotate_grid_index`] for rows and
    /// columns below `n`).
    pub(crate) fn codes_of_data_cells(&self, cells: &[bool], data: &[(u8, u8)]) -> [u64; 4] {
        let n = self.grid as usize;
        let last = n.saturating_sub(1);
        [
            code_of(cells, data, |r, c| r * n + c),
            code_of(cells, data, |r, c| c * n + (last - r)),
            code_of(cells, data, |r, c| (last - r) * n + (last - c)),
            code_of(cells, data, |r, c| (last - c) * n + r),
        ]
    }

    /// Rotates a code by `rotation` quarter turns (used for distance computations).
    pub fn rotate_code(&self, code: u64, rotation: u8) -> u64 {
        let n = self.grid as usize;
        let mut cells = [false; MAX_GRID * MAX_GRID];
        let mut index = 0usize;
        for r in 0..n {
            for c in 0..n {
                if self.role(r, c) == CellRole::Data {
                    let shift = (self.bits as usize).saturating_sub(index + 1);
                    if let Some(cell) = cells.get_mut(r * n + c) {
                        *cell = (code >> shift) & 1 == 1;
                    }
                    index += 1;
                }
            }
        }
        // A grid above MAX_GRID (only possible for a hand-built, invalid Family) reads as 0.
        let cells = cells.get(..n * n).unwrap_or(&[]);
        self.codes_of_grid(cells)
            .get((rotation & 3) as usize)
            .copied()
            .unwrap_or(0)
    }

    /// Finds the id whose code is nearest to one of the four readings, within
    /// `max_hamming` bits (clamped to [`Family::max_correction`]). Exact matches use the
    /// sorted index when the family has one (the first rotation that matches wins); other
    /// matches use the multi-index when there is one, else a scan of every code. Either way
    /// the result is the nearest code, ties going to the smallest id, then rotation.
    pub fn decode(&self, readings: &[u64; 4], max_hamming: u8) -> Option<Decoded> {
        let limit = max_hamming.min(self.max_correction);
        if !self.sorted_ids.is_empty() {
            for (k, &reading) in readings.iter().enumerate() {
                if let Some(id) = self.exact(reading) {
                    return Some(Decoded {
                        id,
                        rotation: k as u8,
                        hamming: 0,
                    });
                }
            }
            if limit == 0 {
                return None;
            }
        }
        match self.index {
            Some(index) if index.covers(limit) => index.nearest(self.codes, readings, limit),
            _ => self.scan(readings, limit),
        }
    }

    /// The look-up without a multi-index: every code against every reading, the first
    /// smallest distance in (id, rotation) order wins.
    fn scan(&self, readings: &[u64; 4], limit: u8) -> Option<Decoded> {
        let limit = u32::from(limit);
        let mut best: Option<Decoded> = None;
        let mut best_distance = limit + 1;
        for (id, &code) in self.codes.iter().enumerate() {
            for (k, &reading) in readings.iter().enumerate() {
                let d = (code ^ reading).count_ones();
                if d < best_distance {
                    best_distance = d;
                    best = Some(Decoded {
                        id: id as u16,
                        rotation: k as u8,
                        hamming: d as u8,
                    });
                    if d == 0 {
                        return best;
                    }
                }
            }
        }
        best
    }

    fn exact(&self, reading: u64) -> Option<u16> {
        let ids = self.sorted_ids;
        let (mut lo, mut hi) = (0usize, ids.len());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let id = *ids.get(mid)?;
            let code = *self.codes.get(id as usize)?;
            match code.cmp(&reading) {
                core::cmp::Ordering::Less => lo = mid + 1,
                core::cmp::Ordering::Greater => hi = mid,
                core::cmp::Ordering::Equal => return Some(id),
            }
        }
        None
    }

    /// Checks that the fields agree with each other: the layout has the declared number of
    /// data bits, every code fits in them, the sorted index is a sorted permutation, and the
    /// multi-index, if any, lists every code in its bucket of every chunk
    /// ([`MultiIndex::check`]).
    pub fn validate(&self) -> Result<(), FamilyErrorKind> {
        self.check_layout()?;
        if self.codes.is_empty() || self.codes.len() > u16::MAX as usize {
            return Err(FamilyErrorKind::NoCodes);
        }
        let bits = self.bits as usize;
        if bits < 64 && self.codes.iter().any(|&c| c >> bits != 0) {
            return Err(FamilyErrorKind::BadCode);
        }
        if !self.sorted_ids.is_empty() {
            if self.sorted_ids.len() != self.codes.len() {
                return Err(FamilyErrorKind::BadIndex);
            }
            let mut previous: Option<u64> = None;
            for &id in self.sorted_ids {
                let code = *self
                    .codes
                    .get(id as usize)
                    .ok_or(FamilyErrorKind::BadIndex)?;
                if previous.is_some_and(|p| p >= code) {
                    return Err(FamilyErrorKind::BadIndex);
                }
                previous = Some(code);
            }
        }
        if let Some(index) = self.index {
            index.check(self.codes, self.bits, self.max_correction)?;
        }
        Ok(())
    }

    /// The O(grid^2) part of [`Family::validate`]: the layout, the bit count and the
    /// correction bound agree. The detector checks this on every frame; the per-code checks
    /// belong where a family is built (bad codes cannot make decoding panic, only miss).
    pub fn check_layout(&self) -> Result<(), FamilyErrorKind> {
        let n = self.grid as usize;
        if !(3..=MAX_GRID).contains(&n) || self.border_ring as usize >= n / 2 {
            return Err(FamilyErrorKind::BadGrid);
        }
        if self.quiet_rings > self.border_ring {
            return Err(FamilyErrorKind::NoBorder);
        }
        let mut bits = 0usize;
        for r in 0..n {
            for c in 0..n {
                if self.role(r, c) == CellRole::Data {
                    bits += 1;
                }
            }
        }
        if bits != self.bits as usize || bits > MAX_BITS || bits == 0 {
            return Err(FamilyErrorKind::TooManyBits);
        }
        if self.max_correction as u32 > (self.min_hamming as u32).saturating_sub(1) / 2 {
            return Err(FamilyErrorKind::BadCorrection);
        }
        // Ids are u16: a larger table would report wrapped ids.
        if self.codes.is_empty() || self.codes.len() > u16::MAX as usize {
            return Err(FamilyErrorKind::NoCodes);
        }
        Ok(())
    }
}

/// Smallest distance between any two codes, counting all rotations, and between each code
/// and its own rotations (a nearly symmetric code would decode in the wrong orientation).
/// O(n^2): meant for user families and the generator, not the per-frame path.
pub fn min_hamming_of(family: &Family<'_>) -> u8 {
    let mut best = family.bits as u32;
    for (i, &a) in family.codes.iter().enumerate() {
        for k in 1..4u8 {
            best = best.min((a ^ family.rotate_code(a, k)).count_ones());
        }
        for k in 0..4u8 {
            let ra = family.rotate_code(a, k);
            for &b in family.codes.get(i + 1..).unwrap_or(&[]) {
                best = best.min((ra ^ b).count_ones());
            }
        }
    }
    best as u8
}

/// The error-correction bound used for a family of `codes` codes with `bits` data bits and
/// minimum distance `min_hamming` (see the module docs).
pub fn max_correction_for(bits: u8, codes: usize, min_hamming: u8) -> u8 {
    let unique = (min_hamming as u32).saturating_sub(1) / 2;
    let mut space = 1.0f64;
    for _ in 0..bits {
        space *= 2.0;
    }
    let mut ball = 0.0f64; // number of patterns within distance k of one code
    let mut choose = 1.0f64; // C(bits, k)
    let mut chosen = 0u8;
    for k in 0..=unique {
        if k > 0 {
            choose = choose * (bits as f64 - (k as f64 - 1.0)) / k as f64;
        }
        ball += choose;
        let p = 4.0 * codes as f64 * ball / space;
        if p > MAX_FALSE_ACCEPT {
            break;
        }
        chosen = k as u8;
    }
    chosen
}

/// The code of the bits of `cells` at `index(row, column)` of each data cell in turn.
#[inline(always)]
fn code_of(cells: &[bool], data: &[(u8, u8)], index: impl Fn(usize, usize) -> usize) -> u64 {
    let mut code = 0u64;
    for &(r, c) in data {
        let bit = cells
            .get(index(r as usize, c as usize))
            .copied()
            .unwrap_or(false);
        code = (code << 1) | bit as u64;
    }
    code
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The codes from the data-cell list are those of the whole grid, in every built-in
    /// family (normal and reversed), on pseudo-random grids.
    #[test]
    fn codes_of_data_cells_are_the_familys_codes_of_the_grid() {
        let mut seed = 0x2545_f491u32;
        for family in tables::ALL {
            let n = family.grid as usize;
            let data = family.data_cells().unwrap();
            assert_eq!(data.len(), family.bits as usize, "{}", family.name);
            for _ in 0..50 {
                let cells: [bool; MAX_GRID * MAX_GRID] = core::array::from_fn(|_| {
                    seed ^= seed << 13;
                    seed ^= seed >> 17;
                    seed ^= seed << 5;
                    seed & 1 == 1
                });
                let cells = &cells[..n * n];
                assert_eq!(
                    family.codes_of_data_cells(cells, &data),
                    family.codes_of_grid(cells),
                    "{}",
                    family.name
                );
            }
        }
    }

    /// The rows at once are the cells one by one, for every shipped family (the reversed
    /// ones, whose data lies outside the border, included) and ids across each; an unknown id
    /// or a short output is refused.
    #[test]
    fn white_rows_are_the_cells_one_by_one() {
        for family in tables::ALL {
            let n = family.grid as usize;
            let count = family.codes.len();
            for id in [0, 1, count / 2, count - 1] {
                let mut rows = [u32::MAX; 32];
                assert_eq!(
                    family.white_rows(id, &mut rows),
                    Some(()),
                    "{}",
                    family.name
                );
                for (row, bits) in rows.iter().enumerate().take(n) {
                    for col in 0..n {
                        let one = family.cell_is_white(id, row, col);
                        assert_eq!(
                            Some(bits >> col & 1 == 1),
                            one,
                            "{} {id} ({row}, {col})",
                            family.name
                        );
                    }
                    assert_eq!(bits >> n, 0, "{} {id} row {row}", family.name);
                }
            }
            assert_eq!(family.white_rows(count, &mut [0; 32]), None);
            assert_eq!(family.white_rows(0, &mut [0; 32][..n - 1]), None);
        }
    }

    #[test]
    fn correction_bounds_of_the_shipped_families() {
        assert_eq!(max_correction_for(36, 587, 11), 2); // tag36h11
        assert_eq!(max_correction_for(36, 250, 11), 2); // aruco_6x6_250
        assert_eq!(max_correction_for(41, 2115, 12), 3); // tagStandard41h12
        assert_eq!(max_correction_for(49, 250, 17), 6); // aruco_7x7_250
        assert_eq!(max_correction_for(16, 30, 5), 0); // tag16h5
        assert_eq!(max_correction_for(16, 50, 4), 0); // aruco_4x4_50
    }
}
