use super::*;
use nalgebra::Vector3;
use touchdown_eval::MethodOutcome;

/// One method's outcome of a frame (the only place the tests build one).
fn outcome(raw: Option<Vector3<f64>>, estimate: Option<Vector3<f64>>) -> MethodOutcome {
    MethodOutcome {
        pose_found: raw.is_some(),
        raw,
        estimate,
    }
}

fn frame(index: usize, t_us: u64, sequence: usize, label: Option<&str>) -> TraceFrame {
    TraceFrame {
        index,
        t_us,
        sequence,
        truth: None,
        label: label.map(str::to_string),
        outcomes: Vec::new(),
    }
}

/// Draws `figure` into a pixel buffer; returns what went where.
fn draw_png(figure: &Figure) -> (Layout, Drawn) {
    register_font().unwrap();
    let layout = Layout::new(figure).unwrap();
    let (w, h) = layout.size;
    let mut pixels = vec![0u8; (w * h * 3) as usize];
    let drawn = {
        let root = BitMapBackend::with_buffer(&mut pixels, layout.size).into_drawing_area();
        figure.draw(&layout, &root).unwrap()
    };
    (layout, drawn)
}

/// The paper scenario's shape: 18 set points of 16 frames at 30 Hz, sequences 1 s apart,
/// `methods` methods whose estimates and raw poses spread over the whole range (every
/// corner of the plot has data).
fn paper_like(methods: usize) -> Trace {
    let labels = [
        "z=5", "z=10", "z=15", "z=20", "z=25", "z=30", "z=40", "z=50", "x=1.2", "x=2.4", "x=3.6",
        "x=4.8", "x=6", "y=1.2", "y=2.4", "y=3.6", "y=4.8", "y=6",
    ];
    let mut trace = Trace::new((0..methods).map(|m| format!("method number {m}")).collect());
    let mut t_us = 0u64;
    for (s, label) in labels.iter().enumerate() {
        for k in 0..16 {
            let index = trace.frames.len();
            let mut f = frame(index, t_us, s, Some(label));
            // A saw-tooth truth from 0 to 10 m in every set point, and estimates off by
            // up to a metre either way: data at the top and bottom of both ends.
            let z = if k % 2 == 0 { 0.0 } else { 10.0 };
            f.truth = Some(Vector3::new(z, z, z));
            f.outcomes = (0..methods)
                .map(|m| {
                    let off = (m as f64 - methods as f64 / 2.0) * 0.1;
                    let v = Vector3::repeat(z + off);
                    outcome(Some(v), Some(v))
                })
                .collect();
            trace.frames.push(f);
            t_us += 33_333;
        }
        t_us += 1_000_000;
    }
    trace
}

#[test]
fn pieces_break_at_missing_values_and_sequences() {
    let at = |index: usize, sequence: usize, v: Option<f64>| TraceFrame {
        outcomes: vec![outcome(None, v.map(|x| Vector3::new(x, 0.0, 0.0)))],
        ..frame(index, index as u64 * 100_000, sequence, None)
    };
    let frames = [
        at(0, 0, Some(1.0)),
        at(1, 0, Some(2.0)),
        at(2, 0, None),
        at(3, 0, Some(3.0)),
        at(4, 1, Some(4.0)),
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

#[test]
fn set_point_runs_split_at_label_gaps_and_sequences() {
    let frames = [
        frame(0, 0, 0, Some("z=5")),
        frame(1, 250_000, 0, Some("z=5")),
        frame(2, 500_000, 0, None),
        frame(3, 750_000, 0, Some("z=5")),
        frame(4, 1_000_000, 0, Some("z=10")),
        frame(5, 2_000_000, 1, Some("z=10")),
        frame(6, 2_250_000, 1, Some("z=10")),
    ];
    let runs = set_point_runs(&frames, 0.0);
    let got: Vec<(f64, f64, &str)> = runs
        .iter()
        .map(|r| (r.start, r.end, r.label.as_str()))
        .collect();
    assert_eq!(
        got,
        [
            (0.0, 0.25, "z=5"),
            (0.75, 0.75, "z=5"),
            (1.0, 1.0, "z=10"),
            (2.0, 2.25, "z=10")
        ]
    );
}

#[test]
fn marks_never_overlap_and_drop_only_without_room() {
    // Five 40-pixel texts 20 pixels apart in two rows: the first two take one row each,
    // the third finds no room in either and is left out rather than drawn over another,
    // the fourth and fifth fit again.
    let placed = place_marks(&[100, 120, 140, 160, 180], &[40; 5], (0, 1000), 2);
    let rows: Vec<Option<usize>> = placed.iter().map(|p| p.map(|(r, _)| r)).collect();
    assert_eq!(rows, [Some(0), Some(1), None, Some(0), Some(1)]);
    // Clamped inside the axis.
    let placed = place_marks(&[2, 998], &[40, 40], (0, 1000), 1);
    assert_eq!(placed, [Some((0, 0)), Some((0, 960))]);
}

/// The paper scenario's 18 set points all get their name on the time axis, readable (in
/// rows, none over another or over the plot), each inside its own set point's span, and
/// a separator between each two; the time axis spans the sequences' real times.
#[test]
fn paper_set_points_are_all_named_at_their_middle() {
    let trace = paper_like(2);
    let figure = Figure::new(&trace, Kind::Position, 2, "test");
    assert_eq!(figure.mark_kind, MarkKind::SetPoints);
    assert_eq!(figure.marks.len(), 18);
    assert_eq!(figure.separators.len(), 17);
    // 18 sequences of 15 frame periods and 17 one-second gaps.
    let span = 18.0 * 15.0 * 0.033_333 + 17.0 * (1.0 + 0.033_333);
    assert!(
        (figure.x_range.end - span).abs() < 1e-6,
        "{:?}",
        figure.x_range
    );
    let (layout, drawn) = draw_png(&figure);
    assert_eq!(drawn.marks.len(), 18, "every set point named");
    assert_eq!(drawn.check(), Ok(()));
    for (i, a) in drawn.marks.iter().enumerate() {
        assert!(!a.overlaps(&drawn.plot), "name {i} on the plot");
        assert!(a.y0 >= drawn.plot.y1, "name {i} above the axis");
        for b in &drawn.marks[i + 1..] {
            assert!(!a.overlaps(b), "names overlap: {a:?} {b:?}");
        }
    }
    // Each name's centre lies between the separators either side of its set point.
    let runs = set_point_runs(&trace.frames, 0.0);
    for (k, (run, rect)) in runs.iter().zip(layout.marks.iter()).enumerate() {
        let rect = rect.expect("placed");
        let centre = (rect.x0 + rect.x1) / 2;
        let lo = time_pixel(run.start - 0.5, &figure.x_range, layout.plot_x);
        let hi = time_pixel(run.end + 0.5, &figure.x_range, layout.plot_x);
        assert!(
            lo <= centre && centre <= hi,
            "name {k} at {centre}, span {lo}..{hi}"
        );
    }
}

/// The legend is a band of its own: no plotted point falls inside it, for data that fill
/// every corner of the plotting area, with 2, 8 and 12 methods (more methods than
/// colours: the legend takes more rows, nothing breaks).
#[test]
fn legend_never_covers_data() {
    for methods in [2, 8, 12] {
        let trace = paper_like(methods);
        for (kind, axis) in [(Kind::Position, 0), (Kind::Error, 2)] {
            let figure = Figure::new(&trace, kind, axis, "test");
            let (layout, drawn) = draw_png(&figure);
            assert_eq!(
                layout.entries.len(),
                methods + 1 + usize::from(kind == Kind::Position)
            );
            assert!(
                !drawn.legend.overlaps(&drawn.plot),
                "{methods}: legend on the plot"
            );
            for e in &layout.entries {
                assert!(
                    e.rect.x1 <= FIGURE_WIDTH as i32 - MARGIN,
                    "entry off the figure"
                );
            }
            let corners = [
                (drawn.plot.x0, drawn.plot.y0),
                (drawn.plot.x1 - 1, drawn.plot.y0),
                (drawn.plot.x0, drawn.plot.y1 - 1),
                (drawn.plot.x1 - 1, drawn.plot.y1 - 1),
            ];
            let near = |(cx, cy): (i32, i32)| {
                drawn
                    .points
                    .iter()
                    .any(|&(x, y)| (x - cx).abs() < 60 && (y - cy).abs() < 60)
            };
            if kind == Kind::Position {
                assert!(corners.iter().all(|&c| near(c)), "data in every corner");
            }
            assert!(drawn.points.len() > 18 * 16 * methods);
            for &p in &drawn.points {
                assert!(drawn.plot.contains(p), "{p:?} outside the plot");
                assert!(!drawn.legend.contains(p), "{p:?} under the legend");
            }
            assert_eq!(drawn.check(), Ok(()));
        }
    }
}

#[test]
fn time_axis_mapping_is_the_charts() {
    // The marks are placed with `time_pixel` before the chart exists: it must agree with
    // the chart's own mapping, or the names would drift off their set points.
    let trace = paper_like(1);
    let figure = Figure::new(&trace, Kind::Position, 0, "test");
    register_font().unwrap();
    let layout = Layout::new(&figure).unwrap();
    let mut pixels = vec![0u8; (layout.size.0 * layout.size.1 * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut pixels, layout.size).into_drawing_area();
    let c = layout.chart;
    let area = root.shrink((c.x0, c.y0), ((c.x1 - c.x0) as u32, (c.y1 - c.y0) as u32));
    let chart = ChartBuilder::on(&area)
        .margin_right(RIGHT_GAP)
        .x_label_area_size(layout.x_label_area)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(figure.x_range.clone(), figure.y_range.clone())
        .unwrap();
    for k in 0..=20 {
        let t = figure.x_range.end * f64::from(k) / 20.0;
        let ours = time_pixel(t, &figure.x_range, layout.plot_x);
        let theirs = chart.backend_coord(&(t, figure.y_range.start)).0;
        assert!((ours - theirs).abs() <= 1, "t {t}: {ours} vs {theirs}");
    }
}

#[test]
fn landing_without_labels_gets_altitude_marks() {
    // 30 s of descent from 40 m, one sequence, no labels.
    let mut trace = Trace::new(vec!["ours".into()]);
    for k in 0..900 {
        let mut f = frame(k, k as u64 * 33_333, 0, None);
        let z = 40.0 - 39.5 * k as f64 / 899.0;
        f.truth = Some(Vector3::new(0.0, 0.0, z));
        f.outcomes = vec![outcome(None, Some(Vector3::new(0.0, 0.0, z)))];
        trace.frames.push(f);
    }
    let figure = Figure::new(&trace, Kind::Position, 2, "landing");
    assert_eq!(figure.mark_kind, MarkKind::Altitudes);
    assert!(figure.separators.is_empty());
    let texts: Vec<&str> = figure.marks.iter().map(|m| m.text.as_str()).collect();
    // Every 5 s (30 s in at most 10 round steps): 40 m at 0 s, about 33 m at 5 s, ...
    assert_eq!(texts.first(), Some(&"40 m"));
    assert_eq!(texts.len(), 6, "{texts:?}");
    assert_eq!(texts[1], "33 m");
    let (_, drawn) = draw_png(&figure);
    assert_eq!(drawn.marks.len(), 6);
}

/// The files: six figures, PNG and SVG of each at the same size (one drawing code).
/// `TOUCHDOWN_PLOT_TEST_DIR` keeps them somewhere to look at.
#[test]
fn writes_png_and_svg_of_the_same_size() {
    let dir = std::env::var_os("TOUCHDOWN_PLOT_TEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            std::env::temp_dir().join(format!("touchdown-plot-test-{}", std::process::id()))
        });
    let trace = paper_like(3);
    let files = write_figures(&trace, &dir, "synthetic, 3 methods").unwrap();
    assert_eq!(files.len(), 12);
    for png in files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
    {
        let (w, h) = image::image_dimensions(png).unwrap();
        assert_eq!(w, FIGURE_WIDTH);
        let svg = std::fs::read_to_string(png.with_extension("svg")).unwrap();
        assert!(
            svg.contains(&format!("width=\"{w}\" height=\"{h}\"")),
            "{}: the SVG is not {w}x{h}",
            png.display()
        );
        assert!(svg.contains("\nz=50\n") && svg.contains("\nset point\n"));
    }
    if std::env::var_os("TOUCHDOWN_PLOT_TEST_DIR").is_none() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn round_steps() {
    assert_eq!(round_step(30.0, 10), 5.0);
    assert_eq!(round_step(44.0, 10), 5.0);
    assert_eq!(round_step(9.0, 10), 1.0);
    assert_eq!(round_step(0.0, 10), 1.0);
}
