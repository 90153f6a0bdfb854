//! The family text format (`shared/data/families/*.txt`, the project contract).
//!
//! ```text
//! # family tag36h11          <- optional header lines `# key value`
//! # cells 10
//! # min_hamming 11
//! 1111111111100000000110...  <- one code per line: the full grid, row-major, '1' white
//! ```
//! Other `#` lines and blank lines are ignored. A custom marker is a one-line file holding
//! its 64 cells: the grid size comes from the line length. The parser writes the codes into
//! a caller-provided slice (no allocation) and reports errors with their line number.

use super::{max_correction_for, min_hamming_of, Family, MAX_BITS, MAX_GRID};

/// What is wrong with a family file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FamilyErrorKind {
    /// A code line holds a character other than '0' and '1'.
    BadCharacter,
    /// A code line's length is not a square of 3..=16, or differs from `# cells`.
    BadLength,
    /// A header value is not a number, or is out of range.
    BadHeader,
    /// The file has no code line.
    NoCodes,
    /// More codes than the caller's buffer holds (or than 65,535).
    TooManyCodes,
    /// No ring of the grid is black in every code, so there is no border to detect.
    NoBorder,
    /// Data outside the border but no all-white ring inside it to detect against.
    NoInnerWhiteRing,
    /// More than 64 data bits, or none.
    TooManyBits,
    /// Grid size out of range.
    BadGrid,
    /// A code has bits above the family's bit count.
    BadCode,
    /// The sorted index is not a sorted permutation of the ids.
    BadIndex,
    /// The multi-index does not list every code in its bucket of every chunk, or does not
    /// have enough chunks for the correction bound.
    BadMultiIndex,
    /// The correction bound exceeds half the minimum distance.
    BadCorrection,
    /// Two ids have the same code (or one is a rotation of another).
    DuplicateCode,
    /// A code equals its own rotation by 90 or 180 degrees, so the marker's orientation (and
    /// with it the order of its corners) cannot be told from its image.
    SymmetricCode,
}

/// A family file error: what and on which line (1-based; 0 when it concerns the whole file).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FamilyError {
    /// 1-based line number, 0 for the whole file.
    pub line: usize,
    /// What is wrong.
    pub kind: FamilyErrorKind,
}

impl core::fmt::Display for FamilyErrorKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = match self {
            FamilyErrorKind::BadCharacter => "code line holds a character other than 0 and 1",
            FamilyErrorKind::BadLength => {
                "code line length is not cells*cells (a square of 3..16, matching `# cells`)"
            }
            FamilyErrorKind::BadHeader => "header value is not a valid number",
            FamilyErrorKind::NoCodes => "no code lines",
            FamilyErrorKind::TooManyCodes => "too many codes",
            FamilyErrorKind::NoBorder => "no ring of cells is black in every code",
            FamilyErrorKind::NoInnerWhiteRing => {
                "data outside the black border but no white ring inside it"
            }
            FamilyErrorKind::TooManyBits => "more than 64 data cells (or none)",
            FamilyErrorKind::BadGrid => "grid size out of range",
            FamilyErrorKind::BadCode => "code has bits beyond the layout",
            FamilyErrorKind::BadIndex => "sorted index is not a sorted permutation of the ids",
            FamilyErrorKind::BadMultiIndex => {
                "multi-index does not list every code in its bucket of every chunk"
            }
            FamilyErrorKind::BadCorrection => "correction bound above half the minimum distance",
            FamilyErrorKind::DuplicateCode => {
                "two codes are equal or rotations of each other (minimum distance 0)"
            }
            FamilyErrorKind::SymmetricCode => {
                "code looks the same turned by 90 or 180 degrees (e.g. all black), so its \
                 orientation cannot be told: change some cells"
            }
        };
        f.write_str(text)
    }
}

impl core::fmt::Display for FamilyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.kind)
        } else {
            write!(f, "{}", self.kind)
        }
    }
}

/// What [`parse_family`] learnt from the file; the codes are in the caller's buffer.
#[derive(Debug, Clone, Copy)]
pub struct FamilyHeader<'t> {
    /// `# family` value, or the fallback name.
    pub name: &'t str,
    /// Cells per side.
    pub grid: u8,
    /// All-white outer rings.
    pub quiet_rings: u8,
    /// The all-black ring.
    pub border_ring: u8,
    /// Data bits per code.
    pub bits: u8,
    /// Number of codes written.
    pub count: usize,
    /// `# min_hamming` when the file gives it.
    pub min_hamming: Option<u8>,
}

fn err(line: usize, kind: FamilyErrorKind) -> FamilyError {
    FamilyError { line, kind }
}

fn grid_side(len: usize) -> Option<usize> {
    (3..=MAX_GRID).find(|n| n * n == len)
}

/// Parses a family file, writing one code per id into `codes`.
pub fn parse_family<'t>(
    text: &'t str,
    fallback_name: &'t str,
    codes: &mut [u64],
) -> Result<FamilyHeader<'t>, FamilyError> {
    let mut name = fallback_name;
    let mut grid: Option<usize> = None;
    let mut min_hamming = None;
    // Pass 1: headers, line shapes, and which rings are uniformly black / white.
    let mut all_black = [true; MAX_GRID / 2 + 1];
    let mut all_white = [true; MAX_GRID / 2 + 1];
    let mut count = 0usize;
    for (index, raw) in text.lines().enumerate() {
        let line_no = index + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(rest) = line.strip_prefix('#') {
            let mut words = rest.split_whitespace();
            match (words.next(), words.next(), words.next()) {
                (Some("family"), Some(value), None) => name = value,
                (Some("cells"), Some(value), None) => {
                    let n: usize = value
                        .parse()
                        .map_err(|_| err(line_no, FamilyErrorKind::BadHeader))?;
                    if !(3..=MAX_GRID).contains(&n) {
                        return Err(err(line_no, FamilyErrorKind::BadGrid));
                    }
                    if grid.is_some_and(|g| g != n) {
                        return Err(err(line_no, FamilyErrorKind::BadLength));
                    }
                    grid = Some(n);
                }
                (Some("min_hamming"), Some(value), None) => {
                    let d: u8 = value
                        .parse()
                        .map_err(|_| err(line_no, FamilyErrorKind::BadHeader))?;
                    min_hamming = Some(d);
                }
                _ => {}
            }
            continue;
        }
        let n = match grid {
            Some(n) => n,
            None => {
                let n = grid_side(line.len()).ok_or(err(line_no, FamilyErrorKind::BadLength))?;
                grid = Some(n);
                n
            }
        };
        if line.len() != n * n {
            return Err(err(line_no, FamilyErrorKind::BadLength));
        }
        for (k, ch) in line.bytes().enumerate() {
            let white = match ch {
                b'1' => true,
                b'0' => false,
                _ => return Err(err(line_no, FamilyErrorKind::BadCharacter)),
            };
            let (r, c) = (k / n, k % n);
            let ring = r.min(c).min(n - 1 - r).min(n - 1 - c);
            if let (Some(b), Some(w)) = (all_black.get_mut(ring), all_white.get_mut(ring)) {
                *b &= !white;
                *w &= white;
            }
        }
        count += 1;
        if count > codes.len() || count > u16::MAX as usize {
            return Err(err(line_no, FamilyErrorKind::TooManyCodes));
        }
    }
    let n = grid.ok_or(err(0, FamilyErrorKind::NoCodes))?;
    if count == 0 {
        return Err(err(0, FamilyErrorKind::NoCodes));
    }
    let rings = n.div_ceil(2);
    // The border is the first all-black ring that leaves something inside it.
    let border = (0..n / 2)
        .find(|&r| all_black.get(r).copied().unwrap_or(false) && n - 2 * r > 2)
        .ok_or(err(0, FamilyErrorKind::NoBorder))?;
    let quiet = (0..border)
        .take_while(|&r| all_white.get(r).copied().unwrap_or(false))
        .count();
    let reversed = quiet < border;
    if reversed && !all_white.get(border + 1).copied().unwrap_or(false) {
        return Err(err(0, FamilyErrorKind::NoInnerWhiteRing));
    }
    let _ = rings;
    let layout = Family {
        name,
        grid: n as u8,
        quiet_rings: quiet as u8,
        border_ring: border as u8,
        bits: 0,
        min_hamming: 0,
        max_correction: 0,
        codes: &[],
        sorted_ids: &[],
        index: None,
    };
    let bits = (0..n * n)
        .filter(|k| layout.role(k / n, k % n) == super::CellRole::Data)
        .count();
    if bits == 0 || bits > MAX_BITS {
        return Err(err(0, FamilyErrorKind::TooManyBits));
    }
    // Pass 2: pack the data bits.
    let mut id = 0usize;
    for (line_index, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if is_rotation_symmetric(line.as_bytes(), n) {
            return Err(err(line_index + 1, FamilyErrorKind::SymmetricCode));
        }
        let mut code = 0u64;
        for (k, ch) in line.bytes().enumerate() {
            if layout.role(k / n, k % n) == super::CellRole::Data {
                code = (code << 1) | (ch == b'1') as u64;
            }
        }
        if let Some(slot) = codes.get_mut(id) {
            *slot = code;
        }
        id += 1;
    }
    Ok(FamilyHeader {
        name,
        grid: n as u8,
        quiet_rings: quiet as u8,
        border_ring: border as u8,
        bits: bits as u8,
        count,
        min_hamming,
    })
}

/// Whether the `n` x `n` cell grid `cells` (row-major) reads the same turned by 90 or 180
/// degrees (a grid equal to its 90-degree turn also equals its 180-degree one).
fn is_rotation_symmetric(cells: &[u8], n: usize) -> bool {
    let at = |r: usize, c: usize| cells.get(r * n + c);
    let half_turn = (0..n).all(|r| (0..n).all(|c| at(r, c) == at(n - 1 - r, n - 1 - c)));
    let quarter_turn = (0..n).all(|r| (0..n).all(|c| at(r, c) == at(c, n - 1 - r)));
    half_turn || quarter_turn
}

impl<'t> FamilyHeader<'t> {
    /// Builds the family over the parsed codes (`codes[..count]`), sorting `sorted_ids` (at
    /// least `count` long) as its exact-match index. The minimum distance is computed from the
    /// codes (the header value, if any, is checked against it).
    pub fn into_family<'b>(
        self,
        codes: &'b [u64],
        sorted_ids: &'b mut [u16],
    ) -> Result<Family<'b>, FamilyError>
    where
        't: 'b,
    {
        let codes = codes
            .get(..self.count)
            .ok_or(err(0, FamilyErrorKind::TooManyCodes))?;
        let ids = sorted_ids
            .get_mut(..self.count)
            .ok_or(err(0, FamilyErrorKind::TooManyCodes))?;
        for (k, slot) in ids.iter_mut().enumerate() {
            *slot = k as u16;
        }
        ids.sort_unstable_by_key(|&id| codes.get(id as usize).copied().unwrap_or(0));
        let mut family = Family {
            name: self.name,
            grid: self.grid,
            quiet_rings: self.quiet_rings,
            border_ring: self.border_ring,
            bits: self.bits,
            min_hamming: 0,
            max_correction: 0,
            codes,
            sorted_ids: &[],
            index: None,
        };
        let d = min_hamming_of(&family);
        if d == 0 {
            return Err(err(0, FamilyErrorKind::DuplicateCode));
        }
        family.min_hamming = d;
        family.max_correction = max_correction_for(self.bits, self.count, d);
        family.sorted_ids = ids;
        family.validate().map_err(|kind| err(0, kind))?;
        Ok(family)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_4X4: &str = "# family mini\n# cells 8\n\
        1111111110000001101011011001010110001101100010011000000111111111\n\
        1111111110000001101001011011010110101101101010011000000111111111\n";

    #[test]
    fn parses_layout_and_bits() {
        let mut codes = [0u64; 4];
        let h = parse_family(TWO_4X4, "x", &mut codes).unwrap();
        assert_eq!(
            (
                h.name,
                h.grid,
                h.quiet_rings,
                h.border_ring,
                h.bits,
                h.count
            ),
            ("mini", 8, 1, 1, 16, 2)
        );
        // Row 2 of code 0 is 10101101 -> data cells (cols 2..6) 1011; row 3: 10010101 -> 0101...
        assert_eq!(codes[0] >> 12, 0b1011);
        let mut ids = [0u16; 4];
        let f = h.into_family(&codes, &mut ids).unwrap();
        assert!(f.min_hamming >= 1);
        for id in 0..2 {
            let readings = [
                f.rotate_code(f.codes[id], 0),
                f.rotate_code(f.codes[id], 1),
                0,
                0,
            ];
            assert_eq!(f.decode(&readings, 0).map(|d| d.id), Some(id as u16));
        }
    }

    #[test]
    fn rotations_compose_to_identity() {
        let mut codes = [0u64; 4];
        let h = parse_family(TWO_4X4, "x", &mut codes).unwrap();
        let mut ids = [0u16; 4];
        let f = h.into_family(&codes, &mut ids).unwrap();
        let c = f.codes[0];
        let mut r = c;
        for _ in 0..4 {
            r = f.rotate_code(r, 1);
        }
        assert_eq!(r, c);
        assert_ne!(f.rotate_code(c, 1), c);
        assert_eq!(f.rotate_code(f.rotate_code(c, 1), 1), f.rotate_code(c, 2));
    }

    #[test]
    fn one_line_custom_marker() {
        // A paper-style 8x8 design: black border ring 0, 6x6 data inside, no header.
        let text = "00000000\n".repeat(0)
            + "0000000001100110011111100100001001011010011001100100001000000000";
        let mut codes = [0u64; 1];
        let h = parse_family(&text, "custom", &mut codes).unwrap();
        assert_eq!(
            (h.grid, h.quiet_rings, h.border_ring, h.bits),
            (8, 0, 0, 36)
        );
    }

    #[test]
    fn errors_name_the_line() {
        let mut codes = [0u64; 4];
        let bad = "# cells 8\n1111111110000001\n";
        assert_eq!(
            parse_family(bad, "x", &mut codes).unwrap_err(),
            FamilyError {
                line: 2,
                kind: FamilyErrorKind::BadLength
            }
        );
        let bad = "# cells 3\n1x1101111\n";
        assert_eq!(
            parse_family(bad, "x", &mut codes).unwrap_err().kind,
            FamilyErrorKind::BadCharacter
        );
        assert_eq!(
            parse_family("", "x", &mut codes).unwrap_err().kind,
            FamilyErrorKind::NoCodes
        );
        let no_border = "101010101\n";
        assert_eq!(
            parse_family(no_border, "x", &mut codes).unwrap_err().kind,
            FamilyErrorKind::NoBorder
        );
        let mut tiny = [0u64; 1];
        assert_eq!(
            parse_family(TWO_4X4, "x", &mut tiny).unwrap_err(),
            FamilyError {
                line: 4,
                kind: FamilyErrorKind::TooManyCodes
            }
        );
        let all_black = "# cells 8\n\
            0000000000000000000000000000000000000000000000000000000000000000\n";
        assert_eq!(
            parse_family(all_black, "x", &mut codes).unwrap_err(),
            FamilyError {
                line: 2,
                kind: FamilyErrorKind::SymmetricCode
            }
        );
        let dup = "0000000001100110011111100100001001011010011001100100001000000000\n".repeat(2);
        let h = parse_family(&dup, "x", &mut codes).unwrap();
        let mut ids = [0u16; 4];
        assert_eq!(
            h.into_family(&codes, &mut ids).unwrap_err().kind,
            FamilyErrorKind::DuplicateCode
        );
    }
}
