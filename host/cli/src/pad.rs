//! `touchdown pad`: a printable SVG of a pad layout at true size, and its `pad.toml`.
//!
//! The SVG's user unit is the millimetre and its width and height are given in `mm`, so
//! printing at 100 % gives the real marker sizes; the 10 cm scale bar checks that the
//! printer did not rescale. Each marker is one `<path>` of its black cells (a single path
//! so renderers leave no hairline seams between cells), drawn on the white sheet the
//! simulator renders ([`touchdown_sim::pad`]: each marker's grid plus one cell of white).
//! Cut marks sit outside the sheet's corners; marker labels go in light grey beside each
//! marker where they fit clear of every marker's grid (light grey thresholds as white, so a
//! label never looks like a marker edge), and every marker is listed under the sheet.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use clap::builder::PossibleValuesParser;
use clap::{ArgGroup, Args};

use super::{CliError, Outcome};
use touchdown_formats::pad::{load_pad, pad_toml};
use touchdown_sim::pad::{design_names, PrintedPad, Rect};

/// `touchdown pad --help`.
pub const LONG_HELP: &str = "\
Write a printable landing pad: pad.svg at true size and the matching pad.toml.

Give a shipped design (--design) or your own layout (--layout pad.toml, the contract's
format: name, then [[marker]] tables with family, id, size (outer black border, metres), x,
y (centre in the pad frame, metres) and yaw_deg). Families must be shipped ones.

pad.svg is in millimetres: print it at 100 % (no \"fit to page\"), then check the 10 cm
scale bar with a ruler; cut along the cut marks at the corners. Marker ids are printed in
light grey beside the markers and listed under the sheet. The white sheet includes one cell
of white around every marker; keep it white and flat.

pad.toml is the layout to give the camera board and `replay`: the same numbers as the SVG.

A pad larger than your printer's paper: --tile a4 (or a3, letter, legal) also writes the
drawing cut into pages, pad-page-ROW-COL.svg, each to print at 100 % on that paper. Pages
overlap by 10 mm; lay them out in order, slide each over its neighbour until the grey
alignment crosses coincide, tape, then cut the whole at the corner marks.

Exit status: 0 on success; 2 with one line on stderr for a bad option or layout.";

/// Arguments of `touchdown pad`.
#[derive(Debug, Clone, Args)]
#[command(group(ArgGroup::new("source").required(true).args(["design", "layout"])))]
pub struct PadArgs {
    /// A shipped pad design
    #[arg(long, value_name = "NAME", value_parser = PossibleValuesParser::new(design_names()))]
    pub design: Option<String>,

    /// A pad layout file (pad.toml)
    #[arg(long, value_name = "pad.toml")]
    pub layout: Option<PathBuf>,

    /// Directory to write pad.svg and pad.toml into (created if needed)
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Also write the drawing cut into printable pages of this paper size
    #[arg(long, value_name = "PAPER", value_parser = PossibleValuesParser::new(PAPERS.iter().map(|p| p.name)))]
    pub tile: Option<String>,
}

/// A paper size for `--tile`, portrait, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Paper {
    /// The option's value.
    pub name: &'static str,
    /// Width, mm.
    pub width: f64,
    /// Height, mm.
    pub height: f64,
}

/// The papers `--tile` knows (ISO 216 A4 and A3; US letter and legal).
pub const PAPERS: [Paper; 4] = [
    Paper {
        name: "a4",
        width: 210.0,
        height: 297.0,
    },
    Paper {
        name: "a3",
        width: 297.0,
        height: 420.0,
    },
    Paper {
        name: "letter",
        width: 215.9,
        height: 279.4,
    },
    Paper {
        name: "legal",
        width: 215.9,
        height: 355.6,
    },
];

/// Unprinted edge of a tiled page (most printers leave 3-6 mm), mm.
const PAGE_MARGIN_MM: f64 = 10.0;
/// How far neighbouring pages overlap, mm (the alignment crosses sit in the middle of it).
const PAGE_OVERLAP_MM: f64 = 10.0;
/// Arm of an alignment cross, mm.
const CROSS_ARM_MM: f64 = 4.0;

/// Border around the sheet for cut marks, mm.
const BORDER_MM: f64 = 25.0;
/// Extra border under the sheet for the scale bar and the legend, mm.
const FOOTER_MM: f64 = 40.0;
/// Gap between a cut mark and the sheet corner, mm.
const CUT_GAP_MM: f64 = 3.0;
/// Length of a cut mark, mm.
const CUT_LENGTH_MM: f64 = 15.0;
/// Label grey (thresholds as white next to black ink).
const LABEL_GREY: &str = "#a8a8a8";

/// Runs `touchdown pad`.
pub fn run(args: &PadArgs, out: &mut dyn Write, _err: &mut dyn Write) -> Result<Outcome, CliError> {
    let pad = match (&args.design, &args.layout) {
        (Some(name), _) => {
            PrintedPad::design(name).ok_or_else(|| CliError(format!("unknown design `{name}`")))?
        }
        (None, Some(path)) => {
            let config = load_pad(path).map_err(CliError::new)?;
            PrintedPad::from_config(&config)
                .map_err(|e| CliError(format!("{}: {e}", path.display())))?
        }
        (None, None) => return Err(CliError("give --design NAME or --layout pad.toml".into())),
    };
    std::fs::create_dir_all(&args.out).map_err(|e| {
        CliError(format!(
            "{}: cannot create directory: {e}",
            args.out.display()
        ))
    })?;
    let svg_path = args.out.join("pad.svg");
    let toml_path = args.out.join("pad.toml");
    std::fs::write(&svg_path, pad_svg(&pad))
        .map_err(|e| CliError(format!("{}: cannot write: {e}", svg_path.display())))?;
    std::fs::write(&toml_path, pad_toml(&pad.config))
        .map_err(|e| CliError(format!("{}: cannot write: {e}", toml_path.display())))?;
    let count = pad.markers.len();
    writeln!(
        out,
        "wrote {} ({:.0} x {:.0} mm sheet, {count} marker{}; print at 100 %) and {}",
        svg_path.display(),
        pad.sheet.width() * 1000.0,
        pad.sheet.height() * 1000.0,
        if count == 1 { "" } else { "s" },
        toml_path.display()
    )
    .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
    if let Some(name) = &args.tile {
        let paper = PAPERS
            .iter()
            .find(|p| p.name == name)
            .ok_or_else(|| CliError(format!("unknown paper `{name}`")))?;
        let pages = pad_pages(&pad, paper);
        for page in &pages {
            let path = args.out.join(&page.file_name);
            std::fs::write(&path, &page.svg)
                .map_err(|e| CliError(format!("{}: cannot write: {e}", path.display())))?;
        }
        let (rows, cols) = pages.last().map_or((0, 0), |p| (p.row + 1, p.col + 1));
        writeln!(
            out,
            "wrote {} {} pages ({rows} rows x {cols} columns, pad-page-ROW-COL.svg; print each at 100 %, overlap by {PAGE_OVERLAP_MM:.0} mm matching the grey crosses)",
            pages.len(),
            paper.name
        )
        .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
    }
    Ok(Outcome::Success)
}

/// A number in the SVG (mm), short but exact to a micrometre.
fn n(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The pad as an SVG document (millimetres).
pub fn pad_svg(pad: &PrintedPad) -> String {
    let drawing = pad_drawing(pad);
    let mut svg = svg_header(drawing.width, drawing.height, &pad.name);
    svg.push_str(&drawing.body);
    svg.push_str("</svg>\n");
    svg
}

/// The start of an SVG document of `width` x `height` mm (one user unit per mm).
fn svg_header(width: f64, height: f64, name: &str) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
         <svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}mm\" height=\"{h}mm\" \
         viewBox=\"0 0 {w} {h}\">\n\
         <title>touchdown landing pad {name}</title>\n",
        w = n(width),
        h = n(height),
        name = escape(name)
    )
}

/// The drawing of a pad: its size in mm and its SVG elements.
struct Drawing {
    width: f64,
    height: f64,
    body: String,
}

/// Legend lines start this far below the scale bar, mm.
const LEGEND_TOP_MM: f64 = 20.0;
/// Line pitch of the legend, mm.
const LEGEND_LINE_MM: f64 = 4.5;
/// Widest text line at a font size, mm (sans-serif averages about 0.6 em per character).
fn text_width(text: &str, font_mm: f64) -> f64 {
    0.6 * font_mm * text.chars().count() as f64
}

fn pad_drawing(pad: &PrintedPad) -> Drawing {
    let sheet = pad.sheet;
    let (sheet_w, sheet_h) = (sheet.width() * 1000.0, sheet.height() * 1000.0);
    let legend = legend_lines(pad);
    let caption = format!(
        "touchdown pad {}: sheet {} x {} mm (cut at the corner marks); pad frame x right, y up this page, origin = landing point",
        pad.name,
        n(sheet_w),
        n(sheet_h)
    );
    // Wide enough for the sheet and every line of text under it; tall enough for the scale
    // bar, the caption and every legend line.
    let text_w = legend
        .iter()
        .map(|l| text_width(l, 3.5))
        .chain([
            text_width(&caption, 4.0),
            110.0 + text_width(SCALE_NOTE, 4.0),
        ])
        .fold(0.0, f64::max);
    let width = (sheet_w + 2.0 * BORDER_MM).max(text_w + 2.0 * BORDER_MM);
    let footer = FOOTER_MM.max(LEGEND_TOP_MM + LEGEND_LINE_MM * legend.len() as f64 + 5.0);
    let height = sheet_h + 2.0 * BORDER_MM + footer;
    // Pad metres to SVG millimetres (y down).
    let to_svg = |x: f64, y: f64| {
        (
            BORDER_MM + (x - sheet.x0) * 1000.0,
            BORDER_MM + (sheet.y1 - y) * 1000.0,
        )
    };
    let mut svg = String::new();
    let (sx, sy) = to_svg(sheet.x0, sheet.y1);
    let _ = writeln!(
        svg,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#ffffff\"/>",
        n(sx),
        n(sy),
        n(sheet_w),
        n(sheet_h)
    );
    // Markers: one path of black cells each, rows merged into runs.
    for m in &pad.markers {
        let (cx, cy) = to_svg(m.x, m.y);
        let cell = m.cell * 1000.0;
        let half = 0.5 * cell * m.grid() as f64;
        let mut d = String::new();
        for row in 0..m.grid() {
            let mut col = 0;
            while col < m.grid() {
                if m.pattern.is_white(row, col) {
                    col += 1;
                    continue;
                }
                let start = col;
                while col < m.grid() && !m.pattern.is_white(row, col) {
                    col += 1;
                }
                let _ = write!(
                    d,
                    "M{} {}h{}v{}h{}z",
                    n(-half + start as f64 * cell),
                    n(-half + row as f64 * cell),
                    n((col - start) as f64 * cell),
                    n(cell),
                    n(-((col - start) as f64) * cell)
                );
            }
        }
        let _ = writeln!(
            svg,
            "<path transform=\"translate({} {}) rotate({})\" fill=\"#000000\" d=\"{}\"><title>{} id {}, {} mm</title></path>",
            n(cx),
            n(cy),
            n(-m.yaw_deg),
            d,
            escape(&m.family),
            m.id,
            n(m.size * 1000.0)
        );
    }
    // Labels beside the markers, where they fit.
    let grids: Vec<Rect> = pad.markers.iter().map(grid_bounds).collect();
    for (k, m) in pad.markers.iter().enumerate() {
        let text = format!("{} #{} ({} mm)", m.family, m.id, n(m.size * 1000.0));
        let font = (m.cell * 1000.0 * 0.3).clamp(3.0, 12.0) / 1000.0;
        let text_w = 0.6 * font * text.chars().count() as f64;
        let g = grids[k];
        let gap = 0.3 * font;
        let (mx, my) = (0.5 * (g.x0 + g.x1), 0.5 * (g.y0 + g.y1));
        // Below, above, right, left of the grid (pad frame: y up); the text's box.
        let candidates = [
            (mx, g.y0 - gap - font),
            (mx, g.y1 + gap),
            (g.x1 + gap + 0.5 * text_w, my - 0.5 * font),
            (g.x0 - gap - 0.5 * text_w, my - 0.5 * font),
        ];
        // On the sheet if possible, else in the border beside it (cut off with the trim).
        let page = Rect {
            x0: sheet.x0 - BORDER_MM / 1000.0,
            x1: sheet.x1 + BORDER_MM / 1000.0,
            y0: sheet.y0 - BORDER_MM / 1000.0,
            y1: sheet.y1 + BORDER_MM / 1000.0,
        };
        let fits = |&(x, y): &(f64, f64), within: &Rect| {
            let b = Rect {
                x0: x - 0.5 * text_w,
                x1: x + 0.5 * text_w,
                y0: y,
                y1: y + font,
            };
            let inside =
                b.x0 >= within.x0 && b.x1 <= within.x1 && b.y0 >= within.y0 && b.y1 <= within.y1;
            inside
                && grids
                    .iter()
                    .all(|r| b.x1 <= r.x0 || b.x0 >= r.x1 || b.y1 <= r.y0 || b.y0 >= r.y1)
        };
        let place = candidates
            .iter()
            .find(|c| fits(c, &sheet))
            .or_else(|| candidates.iter().find(|c| fits(c, &page)));
        if let Some(&(x, y)) = place {
            // SVG text sits on its baseline: the box's bottom edge (pad y0).
            let (tx, ty) = to_svg(x, y);
            let _ = writeln!(
                svg,
                "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"{}\" text-anchor=\"middle\" fill=\"{LABEL_GREY}\">{}</text>",
                n(tx),
                n(ty - 0.15 * font * 1000.0),
                n(font * 1000.0),
                escape(&text)
            );
        }
    }
    // Cut marks at the four corners, outside the sheet.
    let (x0, y0) = (BORDER_MM, BORDER_MM);
    let (x1, y1) = (BORDER_MM + sheet_w, BORDER_MM + sheet_h);
    let mut marks = String::new();
    for (x, y, dx, dy) in [
        (x0, y0, -1.0, -1.0),
        (x1, y0, 1.0, -1.0),
        (x1, y1, 1.0, 1.0),
        (x0, y1, -1.0, 1.0),
    ] {
        let _ = write!(
            marks,
            "M{} {}h{}M{} {}v{}",
            n(x + dx * CUT_GAP_MM),
            n(y),
            n(dx * CUT_LENGTH_MM),
            n(x),
            n(y + dy * CUT_GAP_MM),
            n(dy * CUT_LENGTH_MM)
        );
    }
    let _ = writeln!(
        svg,
        "<path d=\"{marks}\" stroke=\"#000000\" stroke-width=\"0.3\" fill=\"none\"/>"
    );
    // Scale bar: 100 mm, a tick every 10 mm.
    let bar_x = BORDER_MM;
    let bar_y = y1 + BORDER_MM;
    let mut ticks = String::new();
    for k in 0..=10 {
        let len = if k % 5 == 0 { 6.0 } else { 3.0 };
        let _ = write!(
            ticks,
            "M{} {}v{}",
            n(bar_x + 10.0 * k as f64),
            n(bar_y),
            n(-len)
        );
    }
    let _ = writeln!(
        svg,
        "<g font-family=\"sans-serif\" font-size=\"4\" fill=\"#000000\">\n\
         <rect x=\"{bx}\" y=\"{by}\" width=\"100\" height=\"1.5\"/>\n\
         <path d=\"{ticks}\" stroke=\"#000000\" stroke-width=\"0.3\"/>\n\
         <text x=\"{bx}\" y=\"{t1}\">0</text><text x=\"{b100}\" y=\"{t1}\" text-anchor=\"middle\">100 mm</text>\n\
         <text x=\"{b110}\" y=\"{t0}\">{SCALE_NOTE}</text>\n\
         </g>",
        bx = n(bar_x),
        by = n(bar_y),
        t1 = n(bar_y + 6.0),
        b100 = n(bar_x + 100.0),
        b110 = n(bar_x + 110.0),
        t0 = n(bar_y + 1.5),
    );
    let _ = writeln!(
        svg,
        "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"4\" fill=\"#000000\">{}</text>",
        n(bar_x),
        n(bar_y + 14.0),
        escape(&caption)
    );
    for (k, line) in legend.iter().enumerate() {
        let _ = writeln!(
            svg,
            "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"3.5\" fill=\"#000000\">{}</text>",
            n(bar_x),
            n(bar_y + LEGEND_TOP_MM + LEGEND_LINE_MM * k as f64),
            escape(line)
        );
    }
    Drawing {
        width,
        height,
        body: svg,
    }
}

/// The note beside the scale bar.
const SCALE_NOTE: &str = "scale bar: must measure 100 mm. Print at 100 %, no fit-to-page.";

/// One line per marker for the list under the sheet.
fn legend_lines(pad: &PrintedPad) -> Vec<String> {
    pad.markers
        .iter()
        .map(|m| {
            format!(
                "{} #{}: {} mm at x {} y {} mm, yaw {} deg",
                m.family,
                m.id,
                n(m.size * 1000.0),
                n(m.x * 1000.0),
                n(m.y * 1000.0),
                n(m.yaw_deg)
            )
        })
        .collect()
}

/// One printable page of a tiled pad.
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    /// Row from the top, 0-based.
    pub row: usize,
    /// Column from the left, 0-based.
    pub col: usize,
    /// `pad-page-ROW-COL.svg`, 1-based, zero-padded so that names sort in page order.
    pub file_name: String,
    /// The SVG document of the page.
    pub svg: String,
}

/// The drawing cut into pages of `paper`, row by row.
///
/// Each page prints, inside a `PAGE_MARGIN_MM` edge, the part of the drawing it covers;
/// neighbours share a `PAGE_OVERLAP_MM` band. Alignment crosses are part of the drawing, in
/// the middle of every band (two per shared edge), so each appears on both pages at the same
/// place on the pad: laying one page over the other until they coincide joins them without
/// a shift or a turn. The crosses are in the labels' light grey, which the detector reads as
/// white, so the ones left visible on the assembled pad do no harm.
pub fn pad_pages(pad: &PrintedPad, paper: &Paper) -> Vec<Page> {
    let drawing = pad_drawing(pad);
    let (area_w, area_h) = (
        paper.width - 2.0 * PAGE_MARGIN_MM,
        paper.height - 2.0 * PAGE_MARGIN_MM,
    );
    let (step_x, step_y) = (area_w - PAGE_OVERLAP_MM, area_h - PAGE_OVERLAP_MM);
    let count =
        |extent: f64, area: f64, step: f64| 1 + ((extent - area).max(0.0) / step).ceil() as usize;
    let cols = count(drawing.width, area_w, step_x);
    let rows = count(drawing.height, area_h, step_y);
    // Crosses: in the middle of each band between neighbours, at a quarter and three
    // quarters of the edge the two pages share.
    let mut crosses = Vec::new();
    for col in 1..cols {
        let x = col as f64 * step_x + 0.5 * PAGE_OVERLAP_MM;
        for row in 0..rows {
            let y0 = row as f64 * step_y;
            crosses.push((x, y0 + 0.25 * area_h));
            crosses.push((x, y0 + 0.75 * area_h));
        }
    }
    for row in 1..rows {
        let y = row as f64 * step_y + 0.5 * PAGE_OVERLAP_MM;
        for col in 0..cols {
            let x0 = col as f64 * step_x;
            crosses.push((x0 + 0.25 * area_w, y));
            crosses.push((x0 + 0.75 * area_w, y));
        }
    }
    let mut marks = String::new();
    for (x, y) in &crosses {
        let _ = write!(
            marks,
            "M{} {}h{}M{} {}v{}",
            n(x - CROSS_ARM_MM),
            n(*y),
            n(2.0 * CROSS_ARM_MM),
            n(*x),
            n(y - CROSS_ARM_MM),
            n(2.0 * CROSS_ARM_MM)
        );
    }
    let crosses_svg = format!(
        "<path d=\"{marks}\" stroke=\"{LABEL_GREY}\" stroke-width=\"0.25\" fill=\"none\"/>\n"
    );
    let mut pages = Vec::with_capacity(rows * cols);
    for row in 0..rows {
        for col in 0..cols {
            let (x0, y0) = (col as f64 * step_x, row as f64 * step_y);
            let mut svg = svg_header(paper.width, paper.height, &pad.name);
            let _ = writeln!(
                svg,
                "<svg x=\"{m}\" y=\"{m}\" width=\"{w}\" height=\"{h}\" viewBox=\"{x0} {y0} {w} {h}\">",
                m = n(PAGE_MARGIN_MM),
                w = n(area_w),
                h = n(area_h),
                x0 = n(x0),
                y0 = n(y0)
            );
            svg.push_str(&drawing.body);
            svg.push_str(&crosses_svg);
            svg.push_str("</svg>\n");
            let _ = writeln!(
                svg,
                "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"3\" fill=\"{LABEL_GREY}\">touchdown pad {}: page row {} column {} of {rows} x {cols} (100 %; overlap {} mm, match the crosses)</text>",
                n(PAGE_MARGIN_MM),
                n(PAGE_MARGIN_MM - 3.0),
                escape(&pad.name),
                row + 1,
                col + 1,
                n(PAGE_OVERLAP_MM)
            );
            svg.push_str("</svg>\n");
            pages.push(Page {
                row,
                col,
                file_name: format!(
                    "pad-page-{:0digits$}-{:0digits$}.svg",
                    row + 1,
                    col + 1,
                    digits = rows.max(cols).to_string().len()
                ),
                svg,
            });
        }
    }
    pages
}

/// Axis-aligned bounds of a marker's grid (quiet rings included) in the pad frame.
fn grid_bounds(m: &touchdown_sim::pad::PrintedMarker) -> Rect {
    let h = 0.5 * m.grid_size();
    let corners = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| m.to_pad(x, y));
    Rect {
        x0: corners.iter().map(|c| c[0]).fold(f64::INFINITY, f64::min),
        x1: corners
            .iter()
            .map(|c| c[0])
            .fold(f64::NEG_INFINITY, f64::max),
        y0: corners.iter().map(|c| c[1]).fold(f64::INFINITY, f64::min),
        y1: corners
            .iter()
            .map(|c| c[1])
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_formats::pad::{MarkerConfig, PadConfig};

    #[test]
    fn svg_is_true_size_with_every_marker() {
        let pad = PrintedPad::design("nested").unwrap();
        let svg = pad_svg(&pad);
        let w = pad.sheet.width() * 1000.0 + 2.0 * BORDER_MM;
        assert!(
            svg.contains(&format!("width=\"{}mm\"", n(w))),
            "{}",
            &svg[..300]
        );
        assert_eq!(svg.matches("<path transform").count(), 6);
        assert!(svg.contains("tag36h11 #5 (160 mm)"));
        assert!(svg.contains("100 mm"));
    }

    /// The `y` of every `<text>` element and the document's height.
    fn text_rows_and_height(svg: &str) -> (Vec<f64>, f64) {
        let number_after = |text: &str, key: &str| -> f64 {
            let rest = &text[text.find(key).expect(key) + key.len()..];
            rest[..rest.find('"').unwrap()]
                .trim_end_matches("mm")
                .parse()
                .unwrap()
        };
        let rows = svg
            .split("<text ")
            .skip(1)
            .map(|t| number_after(t, " y=\""))
            .collect();
        (rows, number_after(svg, " height=\""))
    }

    #[test]
    fn legend_fits_the_page_for_any_number_of_markers() {
        let ten = PadConfig {
            name: "ten".into(),
            markers: (0..10)
                .map(|k| MarkerConfig {
                    family: "tag36h11".into(),
                    id: k,
                    size: 0.1,
                    x: 0.15 * f64::from(k),
                    y: 0.0,
                    yaw_deg: 0.0,
                })
                .collect(),
        };
        for pad in [
            PrintedPad::design("nested").unwrap(),
            PrintedPad::from_config(&ten).unwrap(),
        ] {
            let svg = pad_svg(&pad);
            let (rows, height) = text_rows_and_height(&svg);
            for m in &pad.markers {
                assert!(
                    svg.contains(&format!("{} #{}: ", m.family, m.id)),
                    "{}",
                    pad.name
                );
            }
            let lowest = rows.iter().copied().fold(0.0, f64::max);
            assert!(
                lowest + 2.0 <= height,
                "{}: text at {lowest} mm on a {height} mm page",
                pad.name
            );
        }
    }

    #[test]
    fn tiles_cover_the_drawing_with_shared_crosses() {
        let pad = PrintedPad::design("nested").unwrap();
        let drawing = pad_drawing(&pad);
        let a4 = &PAPERS[0];
        let pages = pad_pages(&pad, a4);
        let (rows, cols) = (pages.last().unwrap().row + 1, pages.last().unwrap().col + 1);
        assert_eq!(pages.len(), rows * cols);
        // 1.56 m x 2.78 m plus borders and legend on 190 x 277 mm areas stepping 180 x 267.
        let (step_x, step_y) = (180.0, 267.0);
        assert!((cols - 1) as f64 * step_x + 190.0 >= drawing.width);
        assert!((cols - 2) as f64 * step_x + 190.0 < drawing.width);
        assert!((rows - 1) as f64 * step_y + 277.0 >= drawing.height);
        for page in &pages {
            assert!(page.svg.contains("width=\"210mm\" height=\"297mm\""));
            assert!(page.svg.contains(&format!(
                "viewBox=\"{} {} 190 277\"",
                n(page.col as f64 * step_x),
                n(page.row as f64 * step_y)
            )));
            assert_eq!(page.svg.matches("<path transform").count(), 6);
        }
        // Each shared edge has two crosses in the middle of the overlap band, within both pages.
        let first_band = step_x + 5.0;
        assert!(pages[0]
            .svg
            .contains(&format!("M{} ", n(first_band - CROSS_ARM_MM))));
        assert!(first_band > step_x && first_band < 190.0);
    }
}
