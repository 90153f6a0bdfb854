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

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use touchdown_eval::trace::{Trace, TraceFrame};

/// Figure size, pixels (PNG) and user units (SVG).
pub const FIGURE_SIZE: (u32, u32) = (1200, 520);

/// Colours of the methods, in order (Okabe-Ito, told apart with colour blindness too).
const METHOD_COLOURS: [RGBColor; 4] = [
    RGBColor(213, 94, 0),
    RGBColor(0, 114, 178),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
];
const TRUTH_COLOUR: RGBColor = RGBColor(0, 0, 0);
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
            let stem = format!(
                "{}-{}",
                match kind {
                    Kind::Position => "position",
                    Kind::Error => "error",
                },
                ["x", "y", "z"][axis]
            );
            let png = dir.join(format!("{stem}.png"));
            let (w, h) = FIGURE_SIZE;
            let mut pixels = vec![0u8; (w * h * 3) as usize];
            {
                let root = BitMapBackend::with_buffer(&mut pixels, FIGURE_SIZE).into_drawing_area();
                figure
                    .draw(&root)
                    .map_err(|e| PlotError(format!("{}: cannot draw: {e}", png.display())))?;
            }
            image::save_buffer(&png, &pixels, w, h, image::ExtendedColorType::Rgb8)
                .map_err(|e| PlotError(format!("{}: cannot write: {e}", png.display())))?;
            written.push(png);
            let svg = dir.join(format!("{stem}.svg"));
            let mut text = String::new();
            {
                let root = SVGBackend::with_string(&mut text, FIGURE_SIZE).into_drawing_area();
                figure
                    .draw(&root)
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
        Figure {
            caption,
            y_label,
            x_range,
            y_range,
            truth,
            methods,
            zero_line: kind == Kind::Error,
        }
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.caption, (FONT, 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
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
        for m in self.methods.iter().filter(|m| !m.dots.is_empty()) {
            let colour = m.colour.mix(0.45);
            let series = chart.draw_series(
                m.dots
                    .iter()
                    .map(|&p| Circle::new(p, dot_radius, colour.filled())),
            )?;
            series
                .label(format!("{}: raw pose", m.name))
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, colour.filled()));
        }
        for (k, piece) in self.truth.iter().enumerate() {
            let series = chart.draw_series(LineSeries::new(
                piece.iter().copied(),
                TRUTH_COLOUR.stroke_width(2),
            ))?;
            if k == 0 {
                series.label("truth").legend(|(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], TRUTH_COLOUR.stroke_width(2))
                });
            }
        }
        for m in &self.methods {
            let style = m.colour.stroke_width(2);
            for (k, piece) in m.lines.iter().enumerate() {
                // A lone estimate (the paper's filter between missed detections) has no
                // line to draw: a short dash of the line's colour marks it.
                let series = if let [p] = piece.as_slice() {
                    chart.draw_series(std::iter::once(EmptyElement::at(*p) + lone_mark(style)))?
                } else {
                    chart.draw_series(LineSeries::new(piece.iter().copied(), style))?
                };
                if k == 0 {
                    series
                        .label(format!("{}: filtered", m.name))
                        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
                }
            }
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()
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
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use touchdown_eval::MethodOutcome;

    #[test]
    fn pieces_break_at_missing_values_and_sequences() {
        let frame = |index: usize, sequence: usize, v: Option<f64>| TraceFrame {
            index,
            t_us: index as u64 * 100_000,
            sequence,
            truth: None,
            label: None,
            outcomes: vec![MethodOutcome {
                pose_found: v.is_some(),
                raw: None,
                estimate: v.map(|x| Vector3::new(x, 0.0, 0.0)),
            }],
        };
        let frames = [
            frame(0, 0, Some(1.0)),
            frame(1, 0, Some(2.0)),
            frame(2, 0, None),
            frame(3, 0, Some(3.0)),
            frame(4, 1, Some(4.0)),
        ];
        let p = pieces(&frames, 0.0, |f| f.outcomes[0].estimate.map(|e| e.x));
        let lengths: Vec<usize> = p.iter().map(Vec::len).collect();
        assert_eq!(lengths, [2, 1, 1]);
    }

    #[test]
    fn range_is_padded_and_never_empty() {
        let r = padded_range([1.0, 3.0].into_iter(), 0.1);
        assert!(r.start < 1.0 && r.end > 3.0);
        let r = padded_range(std::iter::empty(), 0.5);
        assert!(r.end - r.start >= 1.0);
        let r = padded_range([2.0].into_iter(), 0.2);
        assert!(r.start < 2.0 && r.end > 2.0);
    }
}
