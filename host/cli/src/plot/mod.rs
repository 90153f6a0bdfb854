//! Figures of a replay in the manner of the reference paper's Figures 8-13: per axis, the
//! estimates against the truth over time, and the error over time; PNG and SVG.
//!
//! Each figure is drawn twice with the same code, into an RGB pixel buffer (encoded as PNG by
//! the `image` crate) and into an SVG string. Text is rendered with DejaVu Sans embedded in
//! the binary (plotters' `ab_glyph` backend), so the figures look the same on every machine
//! and no system font library is needed.
//!
//! Figures (`NAME.png` and `NAME.svg` in the output directory):
//! - `position-x`, `position-y`, `position-z`: the true camera position on that pad axis
//!   (black), every method's filtered estimate (a line, broken where it gives none) and its
//!   raw per-frame pose (dots of the same colour);
//! - `error-x`, `error-y`, `error-z`: truth - estimate on that axis, centimetres, filtered
//!   (line) and raw (dots), with a zero line. Only with a truth.
//!
//! Axis ranges follow the truth and the filtered estimates; raw poses far outside (a wrong
//! pose at 40 m, say) are left out of the picture, and the figure's title says how many.
//!
//! ## Layout
//! Top to bottom: the title; the legend, in a band of its own above the plotting area (it
//! flows into as many rows as the methods need, so it never covers data, however many
//! methods there are and wherever their data lie); the plotting area; the time axis. Under
//! the time axis's tick labels, the set points: each run of frames with the same label is
//! named at its middle, in up to [`MARK_ROWS`] staggered rows so that no two names overlap,
//! with a light vertical line between set points across the plot. A trace without labels but
//! with a truth (the landing scenario) gets the true altitude at a few round times instead.
//! The figure's height grows with the legend's and the set points' rows; its width is
//! [`FIGURE_WIDTH`].

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use touchdown_eval::trace::{Trace, TraceFrame};

mod layout;
mod marks;

use layout::*;
use marks::*;

/// Figure width, pixels (PNG) and user units (SVG).
pub const FIGURE_WIDTH: u32 = 1200;
/// Height of the plotting area, pixels; the figure adds the title, the legend and the axes.
const PLOT_HEIGHT: i32 = 380;
/// Space around the figure, pixels.
const MARGIN: i32 = 14;
/// Height of the title row, pixels.
const TITLE_HEIGHT: i32 = 34;
const TITLE_FONT: u32 = 22;
/// Width of the y axis' tick labels and description, pixels.
const Y_LABEL_AREA: i32 = 72;
/// Space right of the plotting area, for the last time tick label.
const RIGHT_GAP: i32 = 16;
/// Legend: row height, font size, the sample's width, the gaps between entries, pixels.
const LEGEND_ROW: i32 = 22;
const LEGEND_FONT: u32 = 15;
const LEGEND_SAMPLE: i32 = 26;
const LEGEND_ENTRY_GAP: i32 = 24;
/// Between the legend band and the plotting area, pixels.
const LEGEND_GAP: i32 = 8;
/// The time axis: its tick labels' band, the set points' rows, the description's band.
const TICK_LABEL_BAND: i32 = 26;
const MARK_ROW: i32 = 17;
const MARK_FONT: u32 = 13;
/// Most rows of set-point names; a name that fits in none is left out (never drawn over
/// another).
pub const MARK_ROWS: usize = 3;
/// Least space between two names in a row, pixels.
const MARK_GAP: i32 = 6;
const X_DESC_BAND: i32 = 28;
/// Altitude marks (a trace without set points): at most this many.
const ALTITUDE_MARKS: usize = 10;

/// Colours of the methods, in order: Okabe-Ito without black and yellow, then two of Paul
/// Tol's muted colours (wine, olive), told apart with colour blindness too. A ninth method
/// takes the first colour again.
const METHOD_COLOURS: [RGBColor; 8] = [
    RGBColor(213, 94, 0),
    RGBColor(0, 114, 178),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(136, 34, 85),
    RGBColor(153, 153, 51),
];
const TRUTH_COLOUR: RGBColor = RGBColor(0, 0, 0);
/// Separators between set points and their ticks: light enough not to compete with data.
const SEPARATOR_COLOUR: RGBColor = RGBColor(200, 200, 200);
const NOTE_COLOUR: RGBColor = RGBColor(90, 90, 90);
const FONT: &str = "sans-serif";

/// A figure that could not be drawn or written: one line naming the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlotError(pub String);

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PlotError {}

/// Registers the embedded font once per process.
fn register_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError(
            "the embedded plot font could not be loaded".into(),
        ))
    }
}

/// Width and height of `text` in the embedded font at `size`, pixels.
fn text_size(text: &str, size: u32) -> Result<(i32, i32), PlotError> {
    let (w, h) = (FONT, size)
        .into_font()
        .box_size(text)
        .map_err(|e| PlotError(format!("cannot measure the text {text:?}: {e:?}")))?;
    Ok((w as i32, h as i32))
}

/// What a figure shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Position,
    Error,
}

/// Writes the figures of `trace` into `dir` (created if needed); returns the files written.
/// `title` names the run (e.g. `scenario paper, seed 1`).
pub fn write_figures(trace: &Trace, dir: &Path, title: &str) -> Result<Vec<PathBuf>, PlotError> {
    register_font()?;
    std::fs::create_dir_all(dir)
        .map_err(|e| PlotError(format!("{}: cannot create directory: {e}", dir.display())))?;
    let mut written = Vec::new();
    let kinds: &[Kind] = if trace.has_truth() {
        &[Kind::Position, Kind::Error]
    } else {
        &[Kind::Position]
    };
    for &kind in kinds {
        for axis in 0..3 {
            let figure = Figure::new(trace, kind, axis, title);
            let layout = Layout::new(&figure)?;
            let stem = format!(
                "{}-{}",
                match kind {
                    Kind::Position => "position",
                    Kind::Error => "error",
                },
                ["x", "y", "z"][axis]
            );
            let png = dir.join(format!("{stem}.png"));
            let (w, h) = layout.size;
            let mut pixels = vec![0u8; (w as usize) * (h as usize) * 3];
            {
                let root = BitMapBackend::with_buffer(&mut pixels, layout.size).into_drawing_area();
                let drawn = figure
                    .draw(&layout, &root)
                    .map_err(|e| PlotError(format!("{}: cannot draw: {e}", png.display())))?;
                // The layout's promise, checked on every figure a debug build draws (the
                // tests check it on traces made to break it).
                debug_assert_eq!(drawn.check(), Ok(()), "{}", png.display());
            }
            image::save_buffer(&png, &pixels, w, h, image::ExtendedColorType::Rgb8)
                .map_err(|e| PlotError(format!("{}: cannot write: {e}", png.display())))?;
            written.push(png);
            let svg = dir.join(format!("{stem}.svg"));
            let mut text = String::new();
            {
                let root = SVGBackend::with_string(&mut text, layout.size).into_drawing_area();
                figure
                    .draw(&layout, &root)
                    .map_err(|e| PlotError(format!("{}: cannot draw: {e}", svg.display())))?;
            }
            std::fs::write(&svg, text)
                .map_err(|e| PlotError(format!("{}: cannot write: {e}", svg.display())))?;
            written.push(svg);
        }
    }
    Ok(written)
}

/// One method's data in a figure: the filtered line (pieces) and the raw dots.
struct MethodSeries {
    name: String,
    colour: RGBColor,
    lines: Vec<Vec<(f64, f64)>>,
    dots: Vec<(f64, f64)>,
}

/// Everything one figure draws, in plot units (seconds; metres or centimetres).
struct Figure {
    caption: String,
    y_label: String,
    x_range: Range<f64>,
    y_range: Range<f64>,
    truth: Vec<Vec<(f64, f64)>>,
    methods: Vec<MethodSeries>,
    zero_line: bool,
    mark_kind: MarkKind,
    marks: Vec<Mark>,
    /// Times of the lines between set points.
    separators: Vec<f64>,
}

/// Splits `frames` into runs where `value` gives a point, breaking at sequence changes.
fn pieces(
    frames: &[TraceFrame],
    t0: f64,
    value: impl Fn(&TraceFrame) -> Option<f64>,
) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    let mut sequence = None;
    for f in frames {
        if sequence != Some(f.sequence) && !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
        sequence = Some(f.sequence);
        match value(f) {
            Some(v) if v.is_finite() => current.push((f.t_s() - t0, v)),
            _ => {
                if !current.is_empty() {
                    out.push(std::mem::take(&mut current));
                }
            }
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// A padded range around `values` (at least `min_span` wide).
fn padded_range(values: impl Iterator<Item = f64>, min_span: f64) -> Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return -min_span..min_span;
    }
    let centre = 0.5 * (lo + hi);
    let span = (hi - lo).max(min_span);
    let pad = 0.06 * span;
    (centre - 0.5 * span - pad)..(centre + 0.5 * span + pad)
}

impl Figure {
    fn new(trace: &Trace, kind: Kind, axis: usize, title: &str) -> Self {
        let frames = &trace.frames;
        let t0 = frames.first().map_or(0.0, TraceFrame::t_s);
        let t1 = frames.last().map_or(1.0, TraceFrame::t_s);
        let x_range = 0.0..(t1 - t0).max(1e-3);
        let axis_name = ["x", "y", "z"][axis];
        // Position in metres; error (truth - value) in centimetres.
        let value = |f: &TraceFrame, v: Option<nalgebra::Vector3<f64>>| -> Option<f64> {
            let v = v?;
            match kind {
                Kind::Position => Some(v[axis]),
                Kind::Error => f.truth.map(|t| 100.0 * (t[axis] - v[axis])),
            }
        };
        let mut methods: Vec<MethodSeries> = trace
            .methods
            .iter()
            .enumerate()
            .map(|(m, name)| MethodSeries {
                name: name.clone(),
                colour: METHOD_COLOURS[m % METHOD_COLOURS.len()],
                lines: pieces(frames, t0, |f| {
                    value(f, f.outcomes.get(m).and_then(|o| o.estimate))
                }),
                dots: frames
                    .iter()
                    .filter_map(|f| {
                        value(f, f.outcomes.get(m).and_then(|o| o.raw)).map(|v| (f.t_s() - t0, v))
                    })
                    .collect(),
            })
            .collect();
        let truth = match kind {
            Kind::Position => pieces(frames, t0, |f| f.truth.map(|t| t[axis])),
            Kind::Error => Vec::new(),
        };
        let line_values = || {
            truth
                .iter()
                .chain(methods.iter().flat_map(|m| m.lines.iter()))
                .flatten()
                .map(|p| p.1)
        };
        let y_range = match kind {
            Kind::Position => padded_range(line_values(), 0.2),
            Kind::Error => {
                // Symmetric about zero, to the largest filtered error (and at least the raw
                // dots' typical spread, so a figure of a perfect filter still shows them).
                let mut raw: Vec<f64> = methods
                    .iter()
                    .flat_map(|m| m.dots.iter().map(|p| p.1.abs()))
                    .collect();
                raw.sort_by(f64::total_cmp);
                let raw_p90 = raw.get(raw.len() * 9 / 10).copied().unwrap_or(0.0);
                let top = line_values()
                    .map(f64::abs)
                    .fold(0.0f64, f64::max)
                    .max(raw_p90)
                    .max(1.0);
                -1.1 * top..1.1 * top
            }
        };
        let mut hidden = 0usize;
        for m in &mut methods {
            let before = m.dots.len();
            m.dots.retain(|p| y_range.contains(&p.1));
            hidden += before - m.dots.len();
        }
        let what = match kind {
            Kind::Position => format!("{}: estimates and truth", axis_name.to_uppercase()),
            Kind::Error => format!(
                "{}: error (truth \u{2212} estimate)",
                axis_name.to_uppercase()
            ),
        };
        let mut caption = format!("{what} \u{2014} {title}");
        if hidden > 0 {
            let plural = if hidden == 1 { "" } else { "s" };
            caption.push_str(&format!(" ({hidden} raw pose{plural} off the scale)"));
        }
        let y_label = match (kind, axis) {
            (Kind::Position, 2) => "altitude above the pad z (m)".to_string(),
            (Kind::Position, _) => format!("camera position {axis_name} (m)"),
            (Kind::Error, _) => format!("error in {axis_name} (cm)"),
        };
        let runs = set_point_runs(frames, t0);
        let (mark_kind, marks, separators) = if runs.is_empty() {
            let span = x_range.end - x_range.start;
            (
                MarkKind::Altitudes,
                altitude_marks(frames, t0, span),
                Vec::new(),
            )
        } else {
            let marks = runs
                .iter()
                .map(|r| Mark {
                    t: 0.5 * (r.start + r.end),
                    text: r.label.clone(),
                })
                .collect();
            let separators = runs
                .windows(2)
                .map(|w| 0.5 * (w[0].end + w[1].start))
                .collect();
            (MarkKind::SetPoints, marks, separators)
        };
        Figure {
            caption,
            y_label,
            x_range,
            y_range,
            truth,
            methods,
            zero_line: kind == Kind::Error,
            mark_kind,
            marks,
            separators,
        }
    }
}

/// What was drawn where, for the tests: the plotting area, the legend band, the marks' text
/// boxes and the pixel of every data point (line vertices and dots).
struct Drawn {
    plot: PixelRect,
    legend: PixelRect,
    marks: Vec<PixelRect>,
    points: Vec<(i32, i32)>,
}

impl Drawn {
    /// What the layout promises: no data point under the legend or outside the plotting
    /// area, the legend and the marks off the plotting area, no two marks over each other.
    /// `Err` names the first breach.
    fn check(&self) -> Result<(), String> {
        if self.legend.overlaps(&self.plot) {
            return Err(format!(
                "legend {:?} on the plot {:?}",
                self.legend, self.plot
            ));
        }
        if let Some(p) = self.points.iter().find(|&&p| self.legend.contains(p)) {
            return Err(format!("point {p:?} under the legend {:?}", self.legend));
        }
        if let Some(p) = self.points.iter().find(|&&p| !self.plot.contains(p)) {
            return Err(format!("point {p:?} outside the plot {:?}", self.plot));
        }
        for (i, a) in self.marks.iter().enumerate() {
            if a.overlaps(&self.plot) {
                return Err(format!("mark {a:?} on the plot"));
            }
            if let Some(b) = self.marks[i + 1..].iter().find(|b| a.overlaps(b)) {
                return Err(format!("marks {a:?} and {b:?} overlap"));
            }
        }
        Ok(())
    }
}

impl Figure {
    fn draw<DB: DrawingBackend>(
        &self,
        layout: &Layout,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<Drawn, DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let width = layout.size.0 as i32;
        root.draw_text(
            &self.caption,
            &(FONT, TITLE_FONT)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Center)),
            (width / 2, MARGIN + TITLE_HEIGHT / 2),
        )?;
        self.draw_legend(layout, root)?;

        let c = layout.chart;
        let area = root
            .clone()
            .shrink((c.x0, c.y0), ((c.x1 - c.x0) as u32, (c.y1 - c.y0) as u32));
        let mut chart = ChartBuilder::on(&area)
            .margin_right(RIGHT_GAP)
            .x_label_area_size(layout.x_label_area)
            .y_label_area_size(Y_LABEL_AREA)
            .build_cartesian_2d(self.x_range.clone(), self.y_range.clone())?;
        let y_decimals = decimals_for(self.y_range.end - self.y_range.start);
        let x_decimals = decimals_for(self.x_range.end - self.x_range.start);
        let y_format = move |v: &f64| format!("{v:.y_decimals$}");
        let x_format = move |v: &f64| format!("{v:.x_decimals$}");
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(self.y_label.as_str())
            .x_label_formatter(&x_format)
            .y_label_formatter(&y_format)
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .max_light_lines(2)
            .light_line_style(RGBColor(238, 238, 238))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()?;
        let (px, py) = chart.plotting_area().get_pixel_range();
        let plot = PixelRect {
            x0: px.start,
            y0: py.start,
            x1: px.end,
            y1: py.end,
        };
        let mut points: Vec<(i32, i32)> = Vec::new();

        // Under the data: the lines between set points, continued as ticks between the
        // marks' rows (not through the time axis' own tick labels).
        let separator_bottom = plot.y1 + TICK_LABEL_BAND + MARK_ROW * layout.mark_rows as i32;
        for &t in &self.separators {
            chart.draw_series(LineSeries::new(
                [(t, self.y_range.start), (t, self.y_range.end)],
                SEPARATOR_COLOUR.stroke_width(1),
            ))?;
            let x = time_pixel(t, &self.x_range, layout.plot_x);
            root.draw(&PathElement::new(
                [(x, plot.y1 + TICK_LABEL_BAND - 3), (x, separator_bottom)],
                SEPARATOR_COLOUR.stroke_width(1),
            ))?;
        }
        if self.zero_line {
            chart.draw_series(LineSeries::new(
                [(self.x_range.start, 0.0), (self.x_range.end, 0.0)],
                RGBColor(120, 120, 120).stroke_width(1),
            ))?;
        }
        let dot_radius = if self.methods.iter().map(|m| m.dots.len()).sum::<usize>() > 2000 {
            1
        } else {
            2
        };
        for m in &self.methods {
            let colour = m.colour.mix(0.45);
            chart.draw_series(
                m.dots
                    .iter()
                    .map(|&p| Circle::new(p, dot_radius, colour.filled())),
            )?;
            points.extend(m.dots.iter().map(|p| chart.backend_coord(p)));
        }
        for piece in &self.truth {
            chart.draw_series(LineSeries::new(
                piece.iter().copied(),
                TRUTH_COLOUR.stroke_width(2),
            ))?;
            points.extend(piece.iter().map(|p| chart.backend_coord(p)));
        }
        for m in &self.methods {
            let style = m.colour.stroke_width(2);
            for piece in &m.lines {
                // A lone estimate (the paper's filter between missed detections) has no
                // line to draw: a short dash of the line's colour marks it.
                if let [p] = piece.as_slice() {
                    chart.draw_series(std::iter::once(EmptyElement::at(*p) + lone_mark(style)))?;
                } else {
                    chart.draw_series(LineSeries::new(piece.iter().copied(), style))?;
                }
                points.extend(piece.iter().map(|p| chart.backend_coord(p)));
            }
        }

        // The marks: each text in its box, under the time axis' tick labels.
        let mark_style = (FONT, MARK_FONT)
            .into_font()
            .color(&RGBColor(40, 40, 40))
            .pos(Pos::new(HPos::Left, VPos::Top));
        for (mark, rect) in self.marks.iter().zip(&layout.marks) {
            if let Some(rect) = rect {
                root.draw_text(&mark.text, &mark_style, (rect.x0, rect.y0 + 1))?;
            }
        }
        if layout.mark_rows > 0 {
            let heading = match self.mark_kind {
                MarkKind::SetPoints => "set point",
                MarkKind::Altitudes => "altitude",
            };
            root.draw_text(
                heading,
                &(FONT, MARK_FONT)
                    .into_font()
                    .color(&NOTE_COLOUR)
                    .pos(Pos::new(HPos::Right, VPos::Top)),
                (plot.x0 - 8, plot.y1 + TICK_LABEL_BAND + 1),
            )?;
        }
        root.present()?;
        Ok(Drawn {
            plot,
            legend: layout.legend,
            marks: layout.marks.iter().flatten().copied().collect(),
            points,
        })
    }

    /// The legend band: each entry's sample and text where the layout put them.
    fn draw_legend<DB: DrawingBackend>(
        &self,
        layout: &Layout,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let font = (FONT, LEGEND_FONT).into_font();
        for entry in &layout.entries {
            let r = entry.rect;
            let y = (r.y0 + r.y1) / 2;
            let sample_end = r.x0 + LEGEND_SAMPLE;
            let text_x = match entry.sample {
                Sample::Truth => {
                    root.draw(&PathElement::new(
                        [(r.x0, y), (sample_end, y)],
                        TRUTH_COLOUR.stroke_width(2),
                    ))?;
                    sample_end + 6
                }
                Sample::Method(colour) => {
                    root.draw(&PathElement::new(
                        [(r.x0, y), (sample_end, y)],
                        colour.stroke_width(2),
                    ))?;
                    root.draw(&Circle::new(
                        ((r.x0 + sample_end) / 2, y),
                        4,
                        colour.mix(0.45).filled(),
                    ))?;
                    sample_end + 6
                }
                Sample::Note => r.x0,
            };
            let colour = if entry.sample == Sample::Note {
                NOTE_COLOUR
            } else {
                BLACK
            };
            root.draw_text(
                &entry.text,
                &font
                    .clone()
                    .color(&colour)
                    .pos(Pos::new(HPos::Left, VPos::Center)),
                (text_x, y),
            )?;
        }
        Ok(())
    }
}

/// Decimals for tick labels over a span (ticks are about a tenth of it apart).
fn decimals_for(span: f64) -> usize {
    if span >= 20.0 {
        0
    } else if span >= 2.0 {
        1
    } else if span >= 0.2 {
        2
    } else {
        3
    }
}

/// The mark of a lone filtered estimate: a horizontal dash 9 pixels long.
fn lone_mark(style: ShapeStyle) -> PathElement<(i32, i32)> {
    PathElement::new([(-4, 0), (4, 0)], style)
}

#[cfg(test)]
mod tests;
