//! Step 2: following the boundaries of the binary image.
//!
//! ## Where a boundary starts
//! The scan ([`start_bits`]) looks at 32 pixels at a time. By default only **outer**
//! boundaries are followed: a dark 8-connected region is entered at its first pixel in
//! raster order, which is the only kind of pixel whose west, north-west, north and
//! north-east neighbours are all light ([`StartRule::OuterOnly`]). A region has one such
//! pixel per "top" of its shape; the first top traces the outer boundary and marks it in the
//! `visited` bitmap, so every later top on that boundary is skipped. Holes (light regions
//! enclosed by dark) are then never followed, unless one of their walls has a top of its
//! own. This matters for the cost on hostile images: a checkerboard of 2-pixel squares is one
//! dark region (its squares touch at the corners) with ten thousand holes, and a grid of thin
//! lines a single region with one hole per mesh. Following every hole of those costs several
//! typical frames; following the outer boundary costs one trace.
//!
//! Families printed white-on-black, and the paper's pipeline (which traces every contour of
//! its edge map, as OpenCV's `findContours` does), need hole boundaries too
//! ([`StartRule::AllBoundaries`]): then every dark pixel whose west neighbour is light and
//! which no earlier boundary passed through starts one, as before.
//!
//! Single dark pixels (no dark neighbour at all) are never followed: nothing of one pixel is
//! a marker, and a frame of isolated dots would otherwise cost one trace per dot.
//!
//! ## Following
//! From a start pixel, Moore neighbour tracing walks clockwise around the dark region keeping
//! the light pixel on its left, which gives the outer boundary of a dark blob (a marker's
//! black border seen from outside) or the boundary of a hole in it (the inner edge of a
//! border ring), depending on which light region the start pixel faced. The walk stops when
//! it is about to leave the start pixel in the direction it first left it (Jacob's
//! criterion), so thin structures are walked fully.
//!
//! A step reads the pixel's whole 3 x 3 neighbourhood from the bitmap, three words (the rows
//! above, at and below it) shifted to its column, and looks the next direction up in one
//! table of every neighbourhood and direction of arrival (`Walk`); a pixel in the first or
//! last column of a bitmap word, whose neighbours span two words a row, probes them one at
//! a time (`next_dark`). That needs every dark pixel to have its eight neighbours inside the
//! frame: the detector clears the frame's outermost rows and columns first
//! ([`clear_border`]); nothing on them could be decoded anyway, since a marker needs its
//! light margin.
//!
//! Where the boundary runs straight along a row (a marker's top and bottom edges), the walk
//! takes the run's steps at once on 64-bit targets: the run's length is a count of ones in
//! the row's words it has read anyway (`Rows::run`), its pixels are stored and marked as
//! the steps would have, and the walk goes on from the run's end. Same pixels, same steps
//! charged; on a frame of long straight edges (a checkerboard) most steps are such runs
//! (the speed-up: `docs/performance.md`). The Cortex-M7 walks step by step: working out the
//! run's length at every step costs it more instructions than the runs save.
//!
//! Every step marks the pixel in the `visited` bitmap, so no boundary is followed twice, and
//! draws from the frame's work budget (one unit per step), so the time per frame is bounded on any image: a
//! frame the budget cannot cover ends with [`Trace::OutOfBudget`] rather than a long stall.

use core::hint::select_unpredictable;

/// A boundary pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[repr(C)]
pub(crate) struct Pixel {
    pub x: u16,
    pub y: u16,
}

/// The shortest run along a row ([`Rows::run`]) the walk takes at once. Shorter ones are
/// walked step by step: on a ragged boundary runs of one or two are common, and the branch
/// past them stays predictable (on one of AprilTag's textured test photos 4 % of the steps
/// start a run of three or more, 10 % one of one or two).
const MIN_RUN: usize = 3;

/// Neighbour offsets, clockwise on screen (y down) starting east.
const DX: [isize; 8] = [1, 1, 0, -1, -1, -1, 0, 1];
const DY: [isize; 8] = [0, 1, 1, 1, 0, -1, -1, -1];
/// Direction of the light start neighbour (west).
const WEST: usize = 4;
/// The same offsets packed as `dx + (dy << 16)` (two's complement, wrapping).
const XY_STEP: [u32; 8] = [
    pack_xy(1, 0),
    pack_xy(1, 1),
    pack_xy(0, 1),
    pack_xy(-1, 1),
    pack_xy(-1, 0),
    pack_xy(-1, -1),
    pack_xy(0, -1),
    pack_xy(1, -1),
];

/// `dx + (dy << 16)` as a wrapping `u32` offset of a packed `(x, y)`.
const fn pack_xy(dx: i32, dy: i32) -> u32 {
    dx.wrapping_add(dy << 16) as u32
}

/// A closed boundary as stored by [`Tracer::trace`]: its pixels (all of them, or evenly
/// spaced ones of a boundary longer than the buffer) and its length in steps.
#[derive(Debug)]
pub(crate) struct Boundary<'c> {
    pub points: &'c [Pixel],
    pub length: usize,
}

/// How a trace ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Trace {
    /// The boundary closed: `points` of its pixels were stored, evenly spaced along its
    /// `length` steps (every pixel when it fitted the output buffer; see [`Tracer::trace`]).
    Closed { points: usize, length: usize },
    /// The boundary closed but the output buffer holds fewer than two pixels.
    TooLong,
    /// The frame's work budget ran out in the middle of the boundary.
    OutOfBudget,
}

/// Which dark pixels start a boundary (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum StartRule {
    /// Outer boundaries of dark regions (and holes only where a wall has a top of its own).
    OuterOnly,
    /// Every boundary: outer ones and those of holes.
    AllBoundaries,
}

/// Boundary follower over one frame's bitmaps.
pub(crate) struct Tracer<'b> {
    bitmap: &'b [u32],
    visited: &'b mut [u32],
    /// Per neighbour direction the bit-index offset (`DX + DY * stride`), directions 0 to 7
    /// twice over, so that the seven directions after any one are a run of the table
    /// ([`next_dark`]).
    moves: [isize; 16],
    /// Bits per bitmap row.
    stride: usize,
    /// Work units left for this frame (one per step, see `charge`).
    budget: u32,
    /// Work units set aside from `budget` for a later step ([`Tracer::hold`]).
    held: u32,
    /// The frame's whole budget.
    total: u32,
    /// Steps taken so far.
    steps: u32,
}

impl<'b> Tracer<'b> {
    /// A tracer over `bitmap` (whose outermost rows and columns must be light, see
    /// [`clear_border`]) marking `visited`, both `words_per_row` words a row, allowed
    /// `budget` steps.
    pub fn new(
        bitmap: &'b [u32],
        visited: &'b mut [u32],
        words_per_row: usize,
        budget: u32,
    ) -> Self {
        let stride = words_per_row * 32;
        let mut moves = [0isize; 16];
        for (m, (dx, dy)) in moves.iter_mut().zip(DX.iter().zip(DY.iter())) {
            *m = dx + dy * stride as isize;
        }
        let (once, again) = moves.split_at_mut(8);
        again.copy_from_slice(once);
        // Both bitmaps cut to one length (the detector's are), so that in the walk one bounds
        // check covers a pixel of either.
        let words = bitmap.len().min(visited.len());
        let (bitmap, visited) = (bitmap.split_at(words).0, visited.split_at_mut(words).0);
        Tracer {
            bitmap,
            visited,
            moves,
            stride,
            budget,
            held: 0,
            total: budget,
            steps: 0,
        }
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Work units left of the frame's budget (steps and whatever else was charged).
    pub fn remaining(&self) -> u32 {
        self.budget
    }

    /// Takes `units` of other work from the frame's budget; false (and nothing left) when
    /// there was not enough.
    pub fn charge(&mut self, units: u32) -> bool {
        match self.budget.checked_sub(units) {
            Some(left) => {
                self.budget = left;
                true
            }
            None => {
                self.budget = 0;
                false
            }
        }
    }

    /// Sets `units` of the budget aside, if it has them, they are at most a quarter of the
    /// frame's budget and nothing is set aside yet: the scan then stops that much earlier,
    /// and the step they are held for still runs when a cluttered frame's scan uses up the
    /// rest ([`Tracer::release`]). Half a QVGA frame's budget held for a far marker's fit
    /// lost a landing's last metre (the markers at the frame's edge not reached).
    pub fn hold(&mut self, units: u32) {
        if self.held == 0 && self.budget >= units && units <= self.total / 4 {
            self.budget -= units;
            self.held = units;
        }
    }

    /// Gives back what [`Tracer::hold`] set aside.
    pub fn release(&mut self) {
        self.budget = self.budget.saturating_add(self.held);
        self.held = 0;
    }

    /// The visited bitmap's word `index` (all ones past the end, so nothing starts there).
    #[inline]
    pub fn visited_word(&self, index: usize) -> u32 {
        self.visited.get(index).copied().unwrap_or(u32::MAX)
    }

    /// The first word of `row` from word `from` on with a dark pixel whose west neighbour is
    /// light and which no followed boundary has passed, a word that may hold a start
    /// ([`start_bits`] tells): its index, the word before it and the word. `row` is the
    /// bitmap row whose first word is `visited`'s word `first_word`.
    ///
    /// On 64-bit targets a loop of its own, so that its few values stay in registers: inside
    /// the detector's scan, whose state is mostly in memory, each word passed costs several
    /// loads and stores (a checkerboard's squares' insides are long runs of dark words). On
    /// the Cortex-M7 a call per word that may hold a start costs more than it saves (on a
    /// checkerboard of 2-pixel squares nearly every word may): there it is inlined.
    #[cfg_attr(target_pointer_width = "64", inline(never))]
    #[cfg_attr(not(target_pointer_width = "64"), inline(always))]
    pub fn next_start_word(
        &self,
        row: &[u32],
        first_word: usize,
        from: usize,
    ) -> Option<(usize, u32, u32)> {
        let mut left = from
            .checked_sub(1)
            .and_then(|k| row.get(k))
            .copied()
            .unwrap_or(0);
        let mut k = from;
        while let Some(&dark) = row.get(k) {
            let light_west = dark & !((dark << 1) | (left >> 31));
            if light_west & !self.visited_word(first_word + k) != 0 {
                return Some((k, left, dark));
            }
            left = dark;
            k += 1;
        }
        None
    }

    /// First dark neighbour of the pixel at bit index `bit` ([`next_dark`]).
    #[cfg(test)]
    fn next(&self, bit: usize, from: usize) -> Option<usize> {
        next_dark(self.bitmap, &self.moves, bit, from)
    }

    /// Follows the boundary through the dark pixel (x0, y0) whose west neighbour is light,
    /// storing its pixels in `out`.
    ///
    /// A boundary longer than `out` is not dropped: each time `out` fills, every second
    /// stored pixel is dropped and from then on only every second step is stored, so a
    /// boundary of any length ends as between half and all of `out`, evenly spaced along it
    /// (a marker of 2,000 pixels across, 8,000 boundary steps, is stored as every second
    /// pixel). The points stay on the boundary, which is all the quad fit needs: its
    /// tolerance is a fraction of the length, tens of pixels on such a boundary. The cost is
    /// one test per step and, in all, at most one move per step for the thinning.
    ///
    /// Not inlined: inside the detector's scan loop the walk's dozen live values compete
    /// with the scan's for registers, and the spills cost more than the call (measured on
    /// the Cortex-M7 benchmark).
    #[inline(never)]
    pub fn trace(&mut self, x0: usize, y0: usize, out: &mut [Pixel]) -> Trace {
        let stride = self.stride;
        let start = y0 * stride + x0;
        // x in the low half, y in the high half: one addition moves both (no pixel on the
        // boundary is at x = 0, so x never borrows from y).
        let start_xy = (x0 as u32 & 0xFFFF) | ((y0 as u32) << 16);
        let start_pixel = Pixel {
            x: x0 as u16,
            y: y0 as u16,
        };
        let capacity = out.len();
        // Steps allowed in this walk.
        let limit = self.budget as usize;
        let mut walk = Walk::new(self);
        // The walk's position: bit index from the row above (see `Walk`).
        let start_rel = start.wrapping_sub(stride);
        // The first step: the first dark neighbour clockwise from the light west one, as
        // after a step north (`NEXT`); none for an isolated pixel.
        let first = match walk.look(start_rel).map(|rows| rows.neighbourhood()) {
            Some(neighbourhood) if neighbourhood & !CENTRE == 0 => None,
            Some(neighbourhood) => Some(walk.next(6, neighbourhood)),
            None => {
                walk.mark(start_rel);
                walk.probe(start_rel, WEST)
            }
        };
        let Some(first) = first else {
            // An isolated pixel.
            return match out.first_mut() {
                Some(slot) => {
                    *slot = start_pixel;
                    Trace::Closed {
                        points: 1,
                        length: 1,
                    }
                }
                None => Trace::TooLong,
            };
        };
        // The walk's state: at the pixel `xy` (position `rel`), to step in direction `d`, the
        // `run` steps after that one going the same way along the row.
        let (mut rel, mut xy, mut d, mut run) = (start_rel, start_xy, first, 0);
        // Dense phase: while the buffer has room and the budget lasts, every step is stored
        // at `out[len]` and neither the spacing nor the budget needs a look (most boundaries
        // end here). At `dense_end` the general loop below takes over, from the top of the
        // same step (marking a pixel twice changes nothing). Each pixel is marked as the walk
        // arrives on it, so a pixel the dense phase reached but did not store is marked, as
        // the general loop would mark it before anything else.
        let dense_end = capacity.min(limit);
        let dense_out = out.get_mut(..dense_end).unwrap_or(&mut []);
        let mut len = 0;
        let mut dense = None;
        while let Some(slot) = dense_out.get_mut(len) {
            *slot = Pixel {
                x: xy as u16,
                y: (xy >> 16) as u16,
            };
            len += 1;
            if run >= MIN_RUN {
                // The steps after this one along the same row, at once. None of them can
                // end the walk: Jacob's criterion needs the start, whose west neighbour is
                // light, and every pixel a run passes has a dark one (going east it came from
                // there, going west it goes there).
                let run = run.min(dense_end - len);
                walk.mark_run(rel, d, run);
                let slots = dense_out.get_mut(len..len + run).unwrap_or(&mut []);
                for slot in slots {
                    xy = xy.wrapping_add(step_xy(d));
                    *slot = Pixel {
                        x: xy as u16,
                        y: (xy >> 16) as u16,
                    };
                }
                len += run;
                rel = walk.along(rel, d, run);
            }
            xy = xy.wrapping_add(step_xy(d));
            rel = walk.advance(rel, xy, d);
            match walk.arrive(rel, d) {
                Some((next, after)) if xy != start_xy || next != first => (d, run) = (next, after),
                _ => {
                    dense = Some(());
                    break;
                }
            }
        }
        // Steps taken (and pixels stored) in the dense phase.
        let dense = dense.map(|()| Trace::Closed {
            points: len,
            length: len,
        });
        let mut thinned = Thinned {
            stored: len,
            spacing_mask: 0,
        };
        let result = if let Some(closed) = dense {
            closed
        } else {
            loop {
                walk.mark(rel);
                thinned.record(out, len, xy);
                len += 1;
                if len > limit {
                    break Trace::OutOfBudget;
                }
                if run >= MIN_RUN {
                    let run = run.min(limit - len);
                    walk.mark_run(rel, d, run);
                    for _ in 0..run {
                        xy = xy.wrapping_add(step_xy(d));
                        thinned.record(out, len, xy);
                        len += 1;
                    }
                    rel = walk.along(rel, d, run);
                }
                xy = xy.wrapping_add(step_xy(d));
                rel = walk.advance(rel, xy, d);
                // There is always a dark neighbour: the pixel just left.
                let Some((next, after)) = walk.arrive(rel, d) else {
                    break Trace::Closed {
                        points: thinned.stored,
                        length: len,
                    };
                };
                // Jacob's criterion: back at the start and about to leave it the same way.
                if xy == start_xy && next == first {
                    break Trace::Closed {
                        points: thinned.stored,
                        length: len,
                    };
                }
                (d, run) = (next, after);
            }
        };
        let steps = match result {
            Trace::OutOfBudget => len - 1,
            _ => len,
        } as u32;
        self.steps += steps;
        self.budget = self.budget.saturating_sub(steps);
        match result {
            Trace::Closed { .. } if len > capacity && capacity < 2 => Trace::TooLong,
            other => other,
        }
    }
}

/// Bit of a pixel's 3 x 3 neighbourhood (see [`Walk::arrive`]) that holds its neighbour in
/// each direction: bits 0 to 2 are the row above (west to east), 3 to 5 the pixel's own
/// row, 6 to 8 the row below.
const NEIGHBOURHOOD_BIT: [u32; 8] = [5, 8, 7, 6, 3, 0, 1, 2];
/// The pixel's own bit in its neighbourhood.
const CENTRE: usize = 1 << 4;

/// `NEXT`: the direction of the next step, for every direction `d` of the step that arrived on a
/// pixel and every 3 x 3 neighbourhood of it (`d << 9 | neighbourhood`, see
/// [`NEIGHBOURHOOD_BIT`]): the first dark neighbour clockwise from the light one the search
/// before saw, as [`next_dark`] finds it. (A neighbourhood without a dark neighbour cannot
/// come up during a walk, which always has the pixel it just left: those entries are 0.)
/// [`NEXT`] and [`XY_STEP`] in one static, so that the walk keeps one address for both.
#[repr(C)]
struct WalkTables {
    xy_step: [u32; 8],
    next: [u8; 8 << 9],
}

static WALK: WalkTables = WalkTables {
    xy_step: XY_STEP,
    next: next_table(),
};

// Evaluated by the compiler: an index out of range would fail the build, not panic.
#[allow(clippy::indexing_slicing)]
const fn next_table() -> [u8; 8 << 9] {
    let mut table = [0u8; 8 << 9];
    let mut d = 0;
    while d < 8 {
        let from = (d + 6 - (d & 1)) & 7;
        let mut nb = 0;
        while nb < 512 {
            let mut k = 1;
            while k < 8 {
                let dir = (from + k) & 7;
                if (nb >> NEIGHBOURHOOD_BIT[dir]) & 1 == 1 {
                    table[(d << 9) | nb] = dir as u8;
                    break;
                }
                k += 1;
            }
            nb += 1;
        }
        d += 1;
    }
    table
}

/// The packed `(x, y)` offset of a step in direction `d` ([`XY_STEP`]).
#[inline(always)]
fn step_xy(d: usize) -> u32 {
    WALK.xy_step.get(d & 7).copied().unwrap_or(0)
}

/// The bitmaps as a walk reads and marks them.
///
/// A position is the pixel's bit index counted from the row above (`y * stride + x -
/// stride`): its word index `i` is then the index of the word above it, and the words of
/// its own row and of the row below sit at the same index of the windows `mid` and `down`,
/// which are as long as `up` (and as the visited bitmap's window `seen`), so one bounds
/// check covers all four. The three words give the pixel's whole 3 x 3 neighbourhood in
/// three shifts, and [`NEXT`] the next direction from it. Cheaper on the Cortex-M7 than
/// probing the neighbours one by one (2.4 probes a step on noise, ten instructions each):
/// about 50 instructions a step against 58 (the walk's live values do not all fit the
/// registers; the position is recomputed from `(x, y)` by a multiplication rather than kept).
/// A pixel in the first or last column of a word has its neighbourhood in two words a row;
/// it is probed one neighbour at a time ([`next_dark`]).
struct Walk<'w> {
    bitmap: &'w [u32],
    up: &'w [u32],
    mid: &'w [u32],
    down: &'w [u32],
    /// `visited` split around the window of the pixels' own rows (`seen`).
    before: &'w mut [u32],
    seen: &'w mut [u32],
    after: &'w mut [u32],
    stride: usize,
    moves: &'w [isize; 16],
}

impl<'w> Walk<'w> {
    /// The walk over `tracer`'s bitmaps.
    #[inline(always)]
    fn new(tracer: &'w mut Tracer<'_>) -> Self {
        let (bitmap, stride) = (tracer.bitmap, tracer.stride);
        let wpr = stride / 32;
        let visited = &mut *tracer.visited;
        let n = bitmap.len().min(visited.len()).saturating_sub(2 * wpr);
        let window = |skip: usize| bitmap.get(skip..).and_then(|rest| rest.get(..n));
        let (up, mid, down) = match (window(0), window(wpr), window(2 * wpr)) {
            (Some(up), Some(mid), Some(down)) => (up, mid, down),
            _ => (&[][..], &[][..], &[][..]),
        };
        let (before, rest) = visited.split_at_mut(wpr.min(visited.len()));
        let (seen, after) = rest.split_at_mut(up.len().min(rest.len()));
        Walk {
            bitmap,
            up,
            mid,
            down,
            before,
            seen,
            after,
            stride,
            moves: &tracer.moves,
        }
    }

    /// The position of the pixel at packed `(x, y)` `xy`.
    #[inline(always)]
    fn position(&self, xy: u32) -> usize {
        ((xy >> 16) as usize)
            .wrapping_sub(1)
            .wrapping_mul(self.stride)
            .wrapping_add((xy & 0xFFFF) as usize)
    }

    /// The position after a step in direction `d` from position `rel` onto the pixel at
    /// packed `(x, y)` `xy`: both ways give the same position, the faster one per target.
    ///
    /// The walk is a chain of dependent operations (the step's direction decides the next
    /// position, whose neighbourhood decides the next direction), so its speed is that
    /// chain's latency. Where registers are plenty (64-bit targets: the host tools) the
    /// position is carried and moved by the step's offset ([`Walk::moved`]), which takes the
    /// multiplication of [`Walk::position`] off the chain. On the Cortex-M7 carrying it
    /// spills the walk's other values, so there it is recomputed from `(x, y)`.
    #[inline(always)]
    fn advance(&self, rel: usize, xy: u32, d: usize) -> usize {
        if cfg!(target_pointer_width = "64") {
            self.moved(rel, d)
        } else {
            self.position(xy)
        }
    }

    /// The position one step in direction `d` from position `rel`.
    #[inline(always)]
    fn moved(&self, rel: usize, d: usize) -> usize {
        rel.wrapping_add_signed(self.moves.get(d & 7).copied().unwrap_or(0))
    }

    /// The position `run` steps in direction `d` (east or west) from position `rel`.
    #[inline(always)]
    fn along(&self, rel: usize, d: usize, run: usize) -> usize {
        if d == 0 {
            rel.wrapping_add(run)
        } else {
            rel.wrapping_sub(run)
        }
    }

    /// Marks the `run` pixels after position `rel` in direction `d` (east or west), those a
    /// run ([`Rows::run`]) leaves from, all in the word of `rel`.
    #[inline(always)]
    fn mark_run(&mut self, rel: usize, d: usize, run: usize) {
        let (i, b) = (rel / 32, rel % 32);
        let bits = 1u64.checked_shl(run as u32).map_or(u64::MAX, |bit| bit - 1);
        let mask = if d == 0 {
            bits << (b + 1)
        } else {
            bits << b.saturating_sub(run)
        };
        if let Some(word) = self.seen.get_mut(i) {
            *word |= mask as u32;
        }
    }

    /// Marks the pixel at position `rel` as on a followed boundary.
    #[inline(always)]
    fn mark(&mut self, rel: usize) {
        let bit = 1 << (rel % 32);
        if let Some(word) = self.seen.get_mut(rel / 32) {
            *word |= bit;
            return;
        }
        // Outside the window: the first or last row (light in the detector's bitmaps).
        let index = rel.wrapping_add(self.stride) / 32;
        let word = match index.checked_sub(self.before.len()) {
            None => self.before.get_mut(index),
            Some(past) => self.after.get_mut(past.wrapping_sub(self.seen.len())),
        };
        if let Some(word) = word {
            *word |= bit;
        }
    }

    /// Marks the pixel at position `rel`, which the walk reached by a step in direction `d`,
    /// and returns the direction of the next step: the first dark neighbour clockwise from
    /// the light one the last search saw ([`next_dark`]; `None` for none), and how many of
    /// the steps after it go the same way along the row ([`Rows::run`]; 0 for a pixel
    /// probed one neighbour at a time).
    #[inline(always)]
    fn arrive(&mut self, rel: usize, d: usize) -> Option<(usize, usize)> {
        match self.look(rel) {
            Some(rows) => {
                let next = self.next(d, rows.neighbourhood());
                Some((next, rows.run(next)))
            }
            None => {
                self.mark(rel);
                self.probe(rel, (d + 6 - (d & 1)) & 7).map(|next| (next, 0))
            }
        }
    }

    /// The rows of the pixel at position `rel` around it, marking the pixel; `None` (and
    /// nothing marked) for a pixel in the first or last column of a word or outside the
    /// windows.
    #[inline(always)]
    fn look(&mut self, rel: usize) -> Option<Rows> {
        // The shift that brings the west neighbour to bit 0: below 30 when all three
        // columns are in the pixel's word.
        let west = rel.wrapping_sub(1) % 32;
        if west >= 30 {
            return None;
        }
        let rows = self.up.iter().zip(self.mid).zip(self.down);
        let (((&up, &mid), &down), seen) = rows.zip(self.seen.iter_mut()).nth(rel / 32)?;
        *seen |= 2 << west;
        Some(Rows {
            up,
            mid,
            down,
            west,
        })
    }

    /// The direction of the step after one in direction `d` onto a pixel with
    /// `neighbourhood` ([`NEXT`]).
    #[inline(always)]
    fn next(&self, d: usize, neighbourhood: usize) -> usize {
        let next = WALK.next.get(((d & 7) << 9) | (neighbourhood & 511));
        next.map_or(0, |&next| usize::from(next))
    }

    /// The first dark neighbour clockwise from direction `from` of the pixel at position
    /// `rel`, probed one at a time ([`next_dark`]).
    #[inline(always)]
    fn probe(&self, rel: usize, from: usize) -> Option<usize> {
        next_dark(self.bitmap, self.moves, rel.wrapping_add(self.stride), from)
    }
}

/// A pixel's word of the rows above, at and below it ([`Walk::look`]), and the shift that
/// brings its west neighbour to bit 0 (below 30: all three columns are in the words).
struct Rows {
    up: u32,
    mid: u32,
    down: u32,
    west: usize,
}

impl Rows {
    /// The pixel's 3 x 3 neighbourhood ([`NEIGHBOURHOOD_BIT`]).
    #[inline(always)]
    fn neighbourhood(&self) -> usize {
        let column = |row: u32| ((row >> self.west) & 7) as usize;
        column(self.up) | column(self.mid) << 3 | column(self.down) << 6
    }

    /// A run along the row: how many of the steps after the pixel's next one, in direction
    /// `d`, go the same way, within the pixel's word (0 unless `d` is east or west, and 0
    /// on 32-bit targets, see the module docs).
    ///
    /// A pixel reached by a step east steps east again when its north-east neighbour is
    /// light and its east one dark (its search starts past the north neighbour, which the
    /// step before saw light); one reached going west steps west again when its south-west
    /// neighbour is light and its west one dark. So the run is a count of ones in the
    /// word `row & !above` (or `row & !below`), from the words already read for the
    /// neighbourhood, a few instructions off the walk's chain of dependent loads.
    #[inline(always)]
    fn run(&self, d: usize) -> usize {
        if !cfg!(target_pointer_width = "64") {
            return 0;
        }
        // The pixel is at bit `west + 1`; going east, the first pixel that may go on is two
        // to its east; going west, two to its west (bit `west - 1`, moved to bit 63).
        let east = (u64::from(self.mid & !self.up) >> (self.west + 3)).trailing_ones();
        let west = ((u64::from(self.mid & !self.down) << 32) << (32 - self.west)).leading_ones();
        // Which way the walk goes on a ragged boundary is not predictable: a branch on it
        // is mispredicted often, on a textured photo enough to slow the whole detection.
        let run = select_unpredictable(d == 4, west, 0);
        select_unpredictable(d == 0, east, run) as usize
    }
}

/// Whether the pixel at bit index `bit` of `bitmap` is dark (past the bitmap: light). (A
/// rotation rather than a shift: the Cortex-M7's takes the amount modulo 32 itself, so it
/// needs no masking instruction.)
#[inline(always)]
fn dark(bitmap: &[u32], bit: usize) -> bool {
    bitmap
        .get(bit / 32)
        .is_some_and(|w| w.rotate_right(bit as u32) & 1 == 1)
}

/// First dark neighbour of the pixel at bit index `bit`, searching clockwise from the light
/// neighbour in direction `from` (which is not probed again: it is the last light pixel the
/// search before this one saw, or the start's light west neighbour), by `moves`
/// ([`Tracer::moves`]).
///
/// The walk's way for a pixel in the first or last column of a bitmap word (see [`Walk`]):
/// probing one neighbour at a time, each probe a load and a shift (2.4 probes a step on
/// noise). The seven directions are one run of `moves`, so each probe reads its offset at a
/// constant distance from the run's start and the direction is worked out once, when found.
#[inline(always)]
fn next_dark(bitmap: &[u32], moves: &[isize; 16], bit: usize, from: usize) -> Option<usize> {
    let first = (from & 7) + 1;
    let run = moves.get(first..first + 7)?;
    run.iter()
        .position(|&m| dark(bitmap, bit.wrapping_add_signed(m)))
        .map(|i| (first + i) & 7)
}

/// The pixels a walk stores once its boundary has outgrown the output buffer: every
/// `spacing_mask + 1`-th step (see [`Tracer::trace`]).
struct Thinned {
    /// Pixels stored.
    stored: usize,
    /// Steps per stored pixel minus one (a power of two minus one).
    spacing_mask: usize,
}

impl Thinned {
    /// Stores the pixel at packed `(x, y)` `xy`, the walk's step `len`, if the spacing
    /// keeps it; when `out` is full, first keeps every second pixel and halves the rate.
    #[inline(always)]
    fn record(&mut self, out: &mut [Pixel], len: usize, xy: u32) {
        if len & self.spacing_mask != 0 {
            return;
        }
        let capacity = out.len();
        let slot = match out.get_mut(self.stored) {
            Some(slot) => Some(slot),
            // Full: keep every second pixel and store at half the rate. `len` is a multiple
            // of the new spacing too when the buffer fills (at a multiple of twice the old
            // spacing, for an even `capacity` as the detector's).
            None if capacity >= 2 => {
                thin_out(out);
                self.stored = capacity / 2;
                self.spacing_mask = 2 * self.spacing_mask + 1;
                out.get_mut(self.stored)
                    .filter(|_| len & self.spacing_mask == 0)
            }
            None => None,
        };
        if let Some(slot) = slot {
            *slot = Pixel {
                x: xy as u16,
                y: (xy >> 16) as u16,
            };
            self.stored += 1;
        }
    }
}

/// Keeps every second pixel of a full output buffer, in order, in its first half.
fn thin_out(out: &mut [Pixel]) {
    for i in 0..out.len() / 2 {
        if let Some(&kept) = out.get(2 * i) {
            if let Some(slot) = out.get_mut(i) {
                *slot = kept;
            }
        }
    }
}

/// The dark pixels of 32 in one bitmap row, with their neighbours: the word itself, the words
/// left and right of it in the same row, and the three words above and below (0 outside the
/// frame).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Neighbourhood {
    pub left: u32,
    pub dark: u32,
    pub right: u32,
    pub above: [u32; 3],
    pub below: [u32; 3],
}

/// Pixels of the word with a dark neighbour in row `[left, middle, right]`: directly above
/// or below, or diagonally.
#[inline(always)]
fn any_of_three(row: [u32; 3]) -> u32 {
    let [left, middle, right] = row;
    middle | (middle << 1) | (left >> 31) | (middle >> 1) | (right << 31)
}

/// Start pixels among 32: dark, west neighbour light, not yet on a followed boundary, and
/// under [`StartRule::OuterOnly`] also the top of a region (north-west, north and north-east
/// light) with at least one dark neighbour.
#[inline]
pub(crate) fn start_bits(n: &Neighbourhood, visited: u32, rule: StartRule) -> u32 {
    let west = (n.dark << 1) | (n.left >> 31);
    let starts = n.dark & !west & !visited;
    match rule {
        StartRule::AllBoundaries => starts,
        StartRule::OuterOnly => {
            let east = (n.dark >> 1) | (n.right << 31);
            starts & !any_of_three(n.above) & (east | any_of_three(n.below))
        }
    }
}

/// Makes the frame's outermost rows and columns light, so every dark pixel has all eight
/// neighbours inside the frame (the [`Tracer`]'s precondition).
pub(crate) fn clear_border(bitmap: &mut [u32], words_per_row: usize, width: usize) {
    let wpr = words_per_row.max(1);
    let last_word = width.saturating_sub(1) / 32;
    let last_bit = width.saturating_sub(1) % 32;
    for row in bitmap.chunks_mut(wpr) {
        if let Some(word) = row.first_mut() {
            *word &= !1;
        }
        if let Some(word) = row.get_mut(last_word) {
            *word &= !(1 << last_bit);
        }
    }
    let rows = bitmap.len() / wpr;
    for row in [0, rows.saturating_sub(1)] {
        if let Some(words) = bitmap.get_mut(row * wpr..(row + 1) * wpr) {
            words.fill(0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::threshold::{set_bit, words_per_row};

    /// The two ways to the next position ([`Walk::advance`]): moving the carried one by the
    /// step's offset (64-bit targets) and recomputing it from the moved `(x, y)` (the
    /// Cortex-M7) agree for every direction, at every pixel a walk can stand on (one pixel
    /// in from the border), on bitmaps of one and several words a row.
    #[test]
    fn carried_and_recomputed_positions_agree() {
        for (wpr, rows) in [(1usize, 6usize), (3, 5), (7, 4)] {
            let bitmap = [0u32; 7 * 6];
            let mut visited = [0u32; 7 * 6];
            let words = wpr * rows;
            let mut tracer = Tracer::new(&bitmap[..words], &mut visited[..words], wpr, 0);
            let walk = Walk::new(&mut tracer);
            for y in 1..rows - 1 {
                for x in 1..wpr * 32 - 1 {
                    let xy = x as u32 | (y as u32) << 16;
                    for d in 0..8 {
                        let moved = xy.wrapping_add(step_xy(d));
                        let recomputed = walk.position(moved);
                        assert_eq!(walk.moved(walk.position(xy), d), recomputed);
                        assert_eq!(walk.advance(walk.position(xy), moved, d), recomputed);
                    }
                }
            }
        }
    }

    fn bitmap_of(rows: &[&str]) -> (usize, usize, [u32; 64]) {
        let (w, h) = (rows[0].len(), rows.len());
        let mut bm = [0u32; 64];
        for (y, row) in rows.iter().enumerate() {
            for (x, ch) in row.bytes().enumerate() {
                if ch == b'#' {
                    set_bit(&mut bm, words_per_row(w), x, y);
                }
            }
        }
        (w, h, bm)
    }

    /// A boundary of `n` steps, stored whole.
    fn closed(n: usize) -> Trace {
        Trace::Closed {
            points: n,
            length: n,
        }
    }

    fn trace_at(rows: &[&str], x: usize, y: usize) -> (Trace, [Pixel; 64]) {
        let (w, _, bm) = bitmap_of(rows);
        let mut visited = [0u32; 64];
        let mut t = Tracer::new(&bm, &mut visited, words_per_row(w), 1000);
        let mut out = [Pixel::default(); 64];
        (t.trace(x, y, &mut out), out)
    }

    /// Runs the detector's scan (one word per row, `w <= 32`) and returns the start pixel and
    /// the result of every trace, as `detect` would.
    fn scan(rows: &[&str], rule: StartRule) -> heapless::Vec<((usize, usize), Trace), 16> {
        let (w, h, bm) = bitmap_of(rows);
        assert!(w <= 32);
        let word = |y: isize| {
            if y < 0 {
                0
            } else {
                bm.get(y as usize).copied().unwrap_or(0)
            }
        };
        let mut visited = [0u32; 64];
        let mut t = Tracer::new(&bm, &mut visited, 1, 1000);
        let mut out = [Pixel::default(); 64];
        let mut traces = heapless::Vec::new();
        for y in 0..h {
            let yi = y as isize;
            let n = Neighbourhood {
                dark: word(yi),
                above: [0, word(yi - 1), 0],
                below: [0, word(yi + 1), 0],
                ..Neighbourhood::default()
            };
            loop {
                let starts = start_bits(&n, t.visited_word(y), rule);
                if starts == 0 {
                    break;
                }
                let x = starts.trailing_zeros() as usize;
                traces.push(((x, y), t.trace(x, y, &mut out))).unwrap();
            }
        }
        traces
    }

    #[test]
    fn square_outer_boundary() {
        let rows = ["......", ".####.", ".####.", ".####.", "......"];
        let (r, out) = trace_at(&rows, 1, 1);
        assert_eq!(r, closed(10));
        // Clockwise on screen: along the top row first.
        assert_eq!((out[1].x, out[1].y), (2, 1));
        assert_eq!((out[3].x, out[3].y), (4, 1));
        assert_eq!((out[4].x, out[4].y), (4, 2));
    }

    #[test]
    fn ring_hole_is_followed_from_its_own_start() {
        let rows = [
            ".......", ".#####.", ".#...#.", ".#...#.", ".#####.", ".......",
        ];
        // (5, 2) is dark with a hole pixel to its west: the hole boundary.
        let (r, _) = trace_at(&rows, 5, 2);
        assert!(matches!(r, Trace::Closed { points, .. } if points >= 8));
    }

    #[test]
    fn single_pixel_and_thin_line() {
        let (r, _) = trace_at(&["...", ".#.", "..."], 1, 1);
        assert_eq!(r, closed(1));
        let (r, _) = trace_at(&[".....", ".###.", "....."], 1, 1);
        assert_eq!(r, closed(4)); // there and back
    }

    #[test]
    fn budget_stops_the_walk() {
        let rows = ["......", ".####.", ".####.", ".####.", "......"];
        let (_, _, bm) = bitmap_of(&rows);
        let mut visited = [0u32; 64];
        let mut t = Tracer::new(&bm, &mut visited, 1, 3);
        let mut out = [Pixel::default(); 64];
        assert_eq!(t.trace(1, 1, &mut out), Trace::OutOfBudget);
        assert_eq!(t.steps(), 3);
    }

    #[test]
    fn long_boundary_is_stored_thinned_out() {
        let rows = ["......", ".####.", ".####.", ".####.", "......"];
        let (r, whole) = trace_at(&rows, 1, 1);
        assert_eq!(r, closed(10));
        let (_, _, bm) = bitmap_of(&rows);
        let mut visited = [0u32; 64];
        let mut t = Tracer::new(&bm, &mut visited, 1, 1000);
        // Four slots for ten steps: thinned twice, every fourth pixel is kept.
        let mut out = [Pixel::default(); 4];
        assert_eq!(
            t.trace(1, 1, &mut out),
            Trace::Closed {
                points: 3,
                length: 10
            }
        );
        assert_eq!(out[..3], [whole[0], whole[4], whole[8]]);
        // Every step is still marked and paid for.
        assert_eq!(t.visited_word(3) & 0b11110, 0b11110);
        assert_eq!(t.steps(), 10);
        // A buffer of one cannot be thinned.
        let mut visited = [0u32; 64];
        let mut t = Tracer::new(&bm, &mut visited, 1, 1000);
        assert_eq!(t.trace(1, 1, &mut [Pixel::default(); 1]), Trace::TooLong);
    }

    #[test]
    fn all_boundaries_follows_the_hole_of_a_ring() {
        // Walls two pixels thick: a one-pixel wall is on both boundaries, so the outer
        // trace would already have marked the hole's start.
        let rows = [
            ".........",
            ".#######.",
            ".#######.",
            ".##...##.",
            ".##...##.",
            ".#######.",
            ".#######.",
            ".........",
        ];
        let traces = scan(&rows, StartRule::AllBoundaries);
        assert_eq!(traces.len(), 2, "{traces:?}");
        assert_eq!(traces[0], ((1, 1), closed(22)));
        assert_eq!(traces[1].0, (6, 3));
        // Outer-only: the ring's outer boundary alone.
        let traces = scan(&rows, StartRule::OuterOnly);
        assert_eq!(traces.len(), 1, "{traces:?}");
        assert_eq!(traces[0], ((1, 1), closed(22)));
    }

    #[test]
    fn a_region_with_two_tops_is_followed_once() {
        // A "V": both arm tops pass the top test; the second is on the boundary the first
        // trace walked, so it is skipped.
        let rows = [
            ".........",
            ".#.....#.",
            "..#...#..",
            "...#.#...",
            "....#....",
            ".........",
        ];
        let traces = scan(&rows, StartRule::OuterOnly);
        assert_eq!(traces.len(), 1, "{traces:?}");
        assert_eq!(traces[0].0, (1, 1));
    }

    #[test]
    fn a_checkerboard_is_one_region() {
        // 2-pixel squares touching at corners: one dark region, one trace.
        let rows = [
            "............",
            ".##..##..##.",
            ".##..##..##.",
            "...##..##...",
            "...##..##...",
            ".##..##..##.",
            ".##..##..##.",
            "............",
        ];
        let outer = scan(&rows, StartRule::OuterOnly);
        assert_eq!(outer.len(), 1, "{outer:?}");
    }

    #[test]
    fn isolated_pixels_are_not_followed() {
        let rows = ["......", ".#.#..", "......", "..#...", "..##..", "......"];
        let traces = scan(&rows, StartRule::OuterOnly);
        // The two single pixels of row 1 are skipped; the L of rows 3-4 is followed.
        assert_eq!(traces.len(), 1, "{traces:?}");
        assert_eq!(traces[0].0, (2, 3));
        // A pixel whose only dark neighbour is diagonal below is not isolated.
        let traces = scan(&["....", ".#..", "..#.", "...."], StartRule::OuterOnly);
        assert_eq!(traces.len(), 1, "{traces:?}");
    }

    #[test]
    fn a_hole_wall_with_its_own_top_is_followed_as_a_hole() {
        // A dark spike rising into the hole from its floor: its tip is a top whose west
        // neighbour is in the hole, so the hole boundary is followed (once).
        let rows = [
            ".........",
            ".#######.",
            ".#.....#.",
            ".#..#..#.",
            ".#..#..#.",
            ".#######.",
            ".........",
        ];
        let traces = scan(&rows, StartRule::OuterOnly);
        assert_eq!(traces.len(), 2, "{traces:?}");
        assert_eq!(traces[1].0, (4, 3));
    }

    #[test]
    fn packed_steps_match_the_directions() {
        for d in 0..8 {
            let xy = (100u32 | (100 << 16)).wrapping_add(XY_STEP[d]);
            let (x, y) = ((xy & 0xFFFF) as isize, (xy >> 16) as isize);
            assert_eq!((x - 100, y - 100), (DX[d], DY[d]), "direction {d}");
        }
    }

    /// 3 rows of 2 words (64 x 3): a dark pixel at row 1, column `x`, and its neighbours dark
    /// where `ring` has a bit (bit `d`: direction `d`).
    fn ring_bitmap(x: usize, ring: u32) -> [u32; 6] {
        let mut bm = [0u32; 6];
        for d in 0..8 {
            if (ring >> d) & 1 == 1 {
                let (px, py) = ((x as isize + DX[d]) as usize, (1 + DY[d]) as usize);
                set_bit(&mut bm, 2, px, py);
            }
        }
        set_bit(&mut bm, 2, x, 1);
        bm
    }

    /// The search through the doubled move table equals the definition (the first dark one
    /// of the seven directions clockwise after `from`) for every neighbourhood, at columns
    /// inside a word and at both its edges.
    #[test]
    fn next_dark_is_the_first_dark_neighbour_clockwise() {
        use crate::detect::threshold::get_bit;
        // 3 rows of 2 words (64 x 3): the pixel at row 1, column `x`.
        for x in [1usize, 17, 30, 31, 32, 33] {
            for ring in 0..256u32 {
                let bm = ring_bitmap(x, ring);
                let mut visited = [0u32; 6];
                let t = Tracer::new(&bm, &mut visited, 2, 1000);
                for from in 0..8 {
                    let expected = (1..8)
                        .map(|i| (from + i) % 8)
                        .find(|&d| get_bit(&bm, 2, x as isize + DX[d], 1 + DY[d], 64, 3));
                    assert_eq!(
                        t.next(64 + x, from),
                        expected,
                        "x {x}, ring {ring:08b}, from {from}"
                    );
                }
            }
        }
    }

    /// The walk's step (the table at most columns, the probes at a word's edges) equals the
    /// definition for every neighbourhood and every direction of arrival, and marks the
    /// pixel.
    #[test]
    fn the_walk_steps_to_the_first_dark_neighbour_clockwise() {
        use crate::detect::threshold::get_bit;
        // 3 rows of 2 words (64 x 3): the pixel at row 1, column `x`.
        for x in [1usize, 2, 17, 29, 30, 31, 32, 33, 62] {
            for ring in 0..256u32 {
                let bm = ring_bitmap(x, ring);
                let mut visited = [0u32; 6];
                let mut t = Tracer::new(&bm, &mut visited, 2, 1000);
                for d in 0..8 {
                    // The pixel the step came from is dark (the table has no answer for a
                    // pixel without dark neighbours, which a walk never reaches).
                    if (ring >> ((d + 4) % 8)) & 1 == 0 {
                        continue;
                    }
                    let from = (d + 6 - (d & 1)) % 8;
                    let expected = (1..8)
                        .map(|i| (from + i) % 8)
                        .find(|&e| get_bit(&bm, 2, x as isize + DX[e], 1 + DY[e], 64, 3));
                    let mut walk = Walk::new(&mut t);
                    assert_eq!(
                        walk.arrive(x, d).map(|(next, _)| next),
                        expected,
                        "x {x}, ring {ring:08b}, d {d}"
                    );
                }
                if ring != 0 {
                    assert_eq!(t.visited_word(2 + x / 32), 1 << (x % 32), "marked");
                }
            }
        }
    }

    /// The definition of a walk from the start (x, y) of a 70 x 12 bitmap of three words a
    /// row: Moore tracing one probe at a time, stopped by Jacob's criterion.
    fn probed_walk(bm: &[u32; 36], x: usize, y: usize) -> heapless::Vec<Pixel, 512> {
        let wpr = 3;
        let probe = Tracer::new(bm, &mut [0u32; 36], wpr, 0).moves;
        let next = |bit: usize, from: usize| next_dark(bm, &probe, bit, from);
        let start = y * wpr * 32 + x;
        let mut expected = heapless::Vec::new();
        let (mut bit, mut d) = (start, next(start, WEST));
        let first = d;
        while let Some(dir) = d {
            let stride = wpr * 32;
            let (px, py) = (bit % stride, bit / stride);
            expected
                .push(Pixel {
                    x: px as u16,
                    y: py as u16,
                })
                .unwrap();
            bit = bit.wrapping_add_signed(probe[dir]);
            let n = next(bit, (dir + 6 - (dir & 1)) & 7);
            if bit == start && n == first {
                break;
            }
            d = n;
        }
        if first.is_none() {
            expected
                .push(Pixel {
                    x: x as u16,
                    y: y as u16,
                })
                .unwrap();
        }
        expected
    }

    /// Random 70 x 12 bitmaps with a light border, `round` choosing the kind: noise of 35 to
    /// 64 % dark (ragged boundaries), or overlapping dark and light rectangles (long straight
    /// runs along the rows, across the words' edges: the walk's runs, see `Rows::run`).
    fn random_bitmap(round: u32, seed: &mut u32) -> [u32; 36] {
        let (w, h, wpr) = (70usize, 12usize, 3usize);
        let mut random = |below: u32| {
            *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (*seed >> 8) % below
        };
        let mut bm = [0u32; 36];
        if round.is_multiple_of(2) {
            for y in 1..h - 1 {
                for x in 1..w - 1 {
                    if random(100) < 35 + round % 30 {
                        set_bit(&mut bm, wpr, x, y);
                    }
                }
            }
            return bm;
        }
        for rectangle in 0..2 + random(5) {
            let (x0, y0) = (1 + random(66) as usize, 1 + random(9) as usize);
            let (x1, y1) = (
                (x0 + 2 + random(60) as usize).min(w - 1),
                (y0 + 1 + random(8) as usize).min(h - 1),
            );
            for y in y0..y1 {
                for x in x0..x1 {
                    let bit = 1 << (x % 32);
                    let word = &mut bm[y * wpr + x / 32];
                    *word = if rectangle % 3 == 2 {
                        *word & !bit
                    } else {
                        *word | bit
                    };
                }
            }
        }
        bm
    }

    /// On random bitmaps (every pixel a start), the walk visits the pixels the definition
    /// does ([`probed_walk`]), marks them all, and stores them thinned out evenly when the
    /// buffer is short; a budget shorter than the boundary stops it after that many steps.
    #[test]
    fn traces_match_probing_one_neighbour_at_a_time() {
        let (w, h, wpr) = (70usize, 12usize, 3usize);
        let mut seed = 3u32;
        for round in 0..400 {
            let bm = random_bitmap(round, &mut seed);
            for (y, x) in (1..h - 1).flat_map(|y| (1..w - 1).map(move |x| (y, x))) {
                let dark = |x: usize, y: usize| bm[y * wpr + x / 32] >> (x % 32) & 1 == 1;
                if !dark(x, y) || dark(x - 1, y) {
                    continue;
                }
                let mut visited = [0u32; 3 * 12];
                let mut t = Tracer::new(&bm, &mut visited, wpr, 10_000);
                let mut out = [Pixel::default(); 512];
                let got = t.trace(x, y, &mut out);
                let expected = probed_walk(&bm, x, y);
                let n = expected.len();
                assert_eq!(got, closed(n), "round {round} at ({x}, {y})");
                assert_eq!(out[..n], expected[..], "round {round} at ({x}, {y})");
                for p in &expected {
                    let word = t.visited_word(p.y as usize * wpr + p.x as usize / 32);
                    assert_eq!(word >> (p.x % 32) & 1, 1, "unmarked {p:?}");
                }
                // A short buffer: every `spacing`-th pixel, the smallest power of two
                // that fits.
                let mut short = [Pixel::default(); 8];
                let mut visited = [0u32; 36];
                let mut t = Tracer::new(&bm, &mut visited, wpr, 10_000);
                let got = t.trace(x, y, &mut short);
                let spacing = (0..10)
                    .map(|k| 1 << k)
                    .find(|s| n.div_ceil(*s) <= 8)
                    .unwrap();
                let points = n.div_ceil(spacing);
                assert_eq!(
                    got,
                    Trace::Closed { points, length: n },
                    "round {round} at ({x}, {y})"
                );
                let thinned = expected.iter().step_by(spacing);
                assert!(
                    short[..points].iter().eq(thinned),
                    "round {round} at ({x}, {y})"
                );
                // A budget of fewer steps than the boundary's.
                if n > 2 {
                    let budget = n as u32 / 2;
                    let mut visited = [0u32; 36];
                    let mut t = Tracer::new(&bm, &mut visited, wpr, budget);
                    let (mut dense, mut short) = ([Pixel::default(); 512], [Pixel::default(); 4]);
                    assert_eq!(t.trace(x, y, &mut dense), Trace::OutOfBudget);
                    assert_eq!(t.steps(), budget, "round {round} at ({x}, {y})");
                    let mut visited = [0u32; 36];
                    let mut t = Tracer::new(&bm, &mut visited, wpr, budget);
                    assert_eq!(t.trace(x, y, &mut short), Trace::OutOfBudget);
                    assert_eq!(t.steps(), budget, "round {round} at ({x}, {y})");
                }
            }
        }
    }

    /// The scan's skip loop finds the first word from `from` on with a dark, unvisited
    /// pixel whose west neighbour (across the word's edge too) is light, as pixel by pixel.
    #[test]
    fn next_start_word_finds_the_first_word_with_a_possible_start() {
        let mut seed = 11u32;
        let mut random = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed
        };
        for round in 0..500 {
            // Row 1 of a bitmap of 3 rows of 5 words; mostly dark, some words all dark or all
            // light, some visited bits.
            let mut bm = [0u32; 15];
            let mut visited = [0u32; 15];
            for k in 5..10 {
                bm[k] = match random() % 4 {
                    0 => u32::MAX,
                    1 => 0,
                    _ => random() | random(),
                };
                visited[k] = if round % 3 == 0 {
                    0
                } else {
                    random() & random()
                };
            }
            let t = Tracer::new(&bm, &mut visited, 5, 0);
            let dark = |x: usize| bm[5 + x / 32] >> (x % 32) & 1 == 1;
            let seen = |x: usize| t.visited_word(5 + x / 32) >> (x % 32) & 1 == 1;
            let row = &bm[5..10];
            for from in 0..6 {
                let expected = (from * 32..160)
                    .find(|&x| dark(x) && (x == 0 || !dark(x - 1)) && !seen(x))
                    .map(|x| x / 32);
                let got = t.next_start_word(row, 5, from);
                assert_eq!(
                    got.map(|(k, _, _)| k),
                    expected,
                    "round {round}, from {from}"
                );
                if let Some((k, left, word)) = got {
                    assert_eq!((left, word), (if k > 0 { row[k - 1] } else { 0 }, row[k]));
                }
            }
        }
    }

    #[test]
    fn start_bits_cross_word_edges() {
        let n = Neighbourhood {
            left: 1 << 31,
            dark: 0b1 | (1 << 31),
            right: 0,
            above: [0; 3],
            below: [0, 0b10, 0],
        };
        // Bit 0's west neighbour (the previous word's bit 31) is dark; bit 31 is isolated.
        assert_eq!(start_bits(&n, 0, StartRule::AllBoundaries), 1 << 31);
        assert_eq!(start_bits(&n, 0, StartRule::OuterOnly), 0);
        // Bit 31 with a dark pixel below-right (the next row's next word, bit 0).
        let n = Neighbourhood {
            dark: 1 << 31,
            below: [0, 0, 1],
            ..Neighbourhood::default()
        };
        assert_eq!(start_bits(&n, 0, StartRule::OuterOnly), 1 << 31);
        // ... and one above-right: not a top.
        let n = Neighbourhood {
            above: [0, 0, 1],
            ..n
        };
        assert_eq!(start_bits(&n, 0, StartRule::OuterOnly), 0);
        assert_eq!(start_bits(&n, 1 << 31, StartRule::AllBoundaries), 0);
    }

    #[test]
    fn clear_border_lights_the_frame_edge() {
        // 40 x 4: two words a row, the last column is bit 7 of the second word.
        let mut bm = [
            u32::MAX,
            0xFF,
            u32::MAX,
            0xFF,
            u32::MAX,
            0xFF,
            u32::MAX,
            0xFF,
        ];
        clear_border(&mut bm, 2, 40);
        assert_eq!(bm, [0, 0, u32::MAX - 1, 0x7F, u32::MAX - 1, 0x7F, 0, 0]);
    }
}
