//! Where everything of a figure goes, computed before anything is drawn: the legend band
//! and its entries, the chart's area, the time axis' set-point rows (see the module docs of
//! [`super`] for the order top to bottom), and the pixel rectangles the tests check.

use super::*;

/// A rectangle in figure pixels: `x0 <= x < x1`, `y0 <= y < y1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct PixelRect {
    pub(super) x0: i32,
    pub(super) y0: i32,
    pub(super) x1: i32,
    pub(super) y1: i32,
}

impl PixelRect {
    pub(super) fn contains(&self, (x, y): (i32, i32)) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    pub(super) fn overlaps(&self, other: &PixelRect) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }
}

/// What a legend entry shows beside its text.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Sample {
    /// The truth's black line.
    Truth,
    /// A method's line with a dot on it.
    Method(RGBColor),
    /// No sample: a note on how to read the figure.
    Note,
}

/// One legend entry: its sample, text and where it goes.
pub(super) struct LegendEntry {
    pub(super) sample: Sample,
    pub(super) text: String,
    pub(super) rect: PixelRect,
}

/// Where everything of a figure goes, computed before drawing (the figure's height follows
/// from the legend's and the time axis' rows).
pub(super) struct Layout {
    pub(super) size: (u32, u32),
    /// The legend band (all its entries).
    pub(super) legend: PixelRect,
    pub(super) entries: Vec<LegendEntry>,
    /// The area given to the chart (plotting area, axes' labels).
    pub(super) chart: PixelRect,
    /// The plotting area's left and right pixels (the time axis' ends).
    pub(super) plot_x: (i32, i32),
    /// Height of the chart's time-axis band.
    pub(super) x_label_area: i32,
    /// Each mark's text box, or `None` when it fits in no row (in `figure.marks` order).
    pub(super) marks: Vec<Option<PixelRect>>,
    /// Rows of marks in use.
    pub(super) mark_rows: usize,
}

/// The pixel column of time `t` on an axis from `range.start` at `plot_x.0` to `range.end`
/// at `plot_x.1` (as plotters maps it: its last pixel is one short of the area's end).
pub(super) fn time_pixel(t: f64, range: &Range<f64>, plot_x: (i32, i32)) -> i32 {
    let span = range.end - range.start;
    let f = if span > 0.0 {
        (t - range.start) / span
    } else {
        0.5
    };
    plot_x.0 + (f * f64::from(plot_x.1 - 1 - plot_x.0)).round() as i32
}

impl Layout {
    pub(super) fn new(figure: &Figure) -> Result<Layout, PlotError> {
        let width = FIGURE_WIDTH as i32;
        let plot_x = (MARGIN + Y_LABEL_AREA, width - MARGIN - RIGHT_GAP);

        // The legend: entries flow left to right over the plotting area's width.
        let mut items: Vec<(Sample, String)> = Vec::new();
        if !figure.truth.is_empty() {
            items.push((Sample::Truth, "truth".into()));
        }
        for m in &figure.methods {
            items.push((Sample::Method(m.colour), m.name.clone()));
        }
        if !figure.methods.is_empty() {
            items.push((
                Sample::Note,
                "line: filtered estimate, dots: raw pose of each frame".into(),
            ));
        }
        let legend_top = MARGIN + TITLE_HEIGHT;
        let mut entries = Vec::new();
        let (mut x, mut row) = (plot_x.0, 0);
        for (sample, text) in items {
            let sample_w = if sample == Sample::Note {
                0
            } else {
                LEGEND_SAMPLE + 6
            };
            let w = sample_w + text_size(&text, LEGEND_FONT)?.0;
            if x > plot_x.0 && x + w > plot_x.1 {
                x = plot_x.0;
                row += 1;
            }
            let y0 = legend_top + row * LEGEND_ROW;
            entries.push(LegendEntry {
                sample,
                text,
                rect: PixelRect {
                    x0: x,
                    y0,
                    x1: x + w,
                    y1: y0 + LEGEND_ROW,
                },
            });
            x += w + LEGEND_ENTRY_GAP;
        }
        let legend = PixelRect {
            x0: plot_x.0,
            y0: legend_top,
            x1: entries.iter().map(|e| e.rect.x1).max().unwrap_or(plot_x.0),
            y1: entries
                .iter()
                .map(|e| e.rect.y1)
                .max()
                .unwrap_or(legend_top),
        };

        // The time axis' marks, in rows under the tick labels.
        let rows = match figure.mark_kind {
            MarkKind::SetPoints => MARK_ROWS,
            MarkKind::Altitudes => 1,
        };
        let mut centres = Vec::with_capacity(figure.marks.len());
        let mut widths = Vec::with_capacity(figure.marks.len());
        for mark in &figure.marks {
            centres.push(time_pixel(mark.t, &figure.x_range, plot_x));
            widths.push(text_size(&mark.text, MARK_FONT)?.0);
        }
        let placed = place_marks(&centres, &widths, plot_x, rows);
        let mark_rows = placed
            .iter()
            .flatten()
            .map(|(r, _)| r + 1)
            .max()
            .unwrap_or(0);
        let x_label_area = TICK_LABEL_BAND + MARK_ROW * mark_rows as i32 + X_DESC_BAND;
        let chart_top = legend.y1 + LEGEND_GAP;
        let chart = PixelRect {
            x0: MARGIN,
            y0: chart_top,
            x1: width - MARGIN,
            y1: chart_top + PLOT_HEIGHT + x_label_area,
        };
        let plot_bottom = chart.y0 + PLOT_HEIGHT;
        let marks = placed
            .iter()
            .zip(&widths)
            .map(|(p, &w)| {
                p.map(|(row, left)| {
                    let y0 = plot_bottom + TICK_LABEL_BAND + MARK_ROW * row as i32;
                    PixelRect {
                        x0: left,
                        y0,
                        x1: left + w,
                        y1: y0 + MARK_ROW,
                    }
                })
            })
            .collect();
        Ok(Layout {
            size: (FIGURE_WIDTH, (chart.y1 + MARGIN) as u32),
            legend,
            entries,
            chart,
            plot_x,
            x_label_area,
            marks,
            mark_rows,
        })
    }
}
