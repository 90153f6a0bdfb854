//! `touchdown replay --json`: every table of the text output as one JSON object, for scripts
//! and CI (the keys are documented in `docs/interfaces.md`, "touchdown replay").
//!
//! The numbers are the ones the tables print, unrounded, from the same [`Report`] and
//! [`Trace`]: lengths in centimetres where the tables give centimetres (keys ending in `_cm`),
//! altitudes in metres (`_m`), rates as fractions of frames (`_rate`, 0 to 1, where the
//! tables print percent). A value a table prints as `-` (no frame to average) is `null`.

use serde_json::{json, Map, Value};

use super::{ReplayArgs, ALTITUDE_CHECKPOINTS_M, ALTITUDE_TOLERANCE};
use crate::replay::calibration::HoverCalibration;
use crate::replay::in_view::InViewSummary;
use crate::replay::input::Input;
use touchdown_eval::flight::{ErrorKind, ErrorStats, FlightSetup, FlightTrace};
use touchdown_eval::trace::{MethodSummary, Trace};
use touchdown_eval::{published, AxisStats, Method, MethodKind, Report, SetPointResult};
use touchdown_sim::effects::FlightEffects;

/// Metres as centimetres; `null` when absent or not finite.
fn cm(v: Option<f64>) -> Value {
    v.filter(|v| v.is_finite())
        .map_or(Value::Null, |v| json!(100.0 * v))
}

/// A finite number, else `null`.
fn finite(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// Three metre values as `{"x", "y", "z"}` in centimetres.
fn xyz_cm(v: [Option<f64>; 3]) -> Value {
    json!({"x": cm(v[0]), "y": cm(v[1]), "z": cm(v[2])})
}

fn xyz_of(v: Option<[f64; 3]>) -> Value {
    match v {
        Some(v) => xyz_cm(v.map(Some)),
        None => Value::Null,
    }
}

/// One line of the on-axis statistics (estimate, error, |error|, RMS), centimetres.
fn on_axis(a: &AxisStats) -> Value {
    json!({
        "frames": a.count(),
        "mean_estimate_cm": cm(a.mean_estimate()),
        "mean_error_cm": cm(a.mean_error()),
        "mean_abs_error_cm": cm(a.mean_abs_error()),
        "rms_error_cm": cm(a.rms_error()),
    })
}

/// What a replay produced: what the text tables are printed from.
pub(super) struct Results<'a> {
    pub(super) report: &'a Report,
    pub(super) trace: &'a Trace,
    pub(super) summaries: &'a [MethodSummary],
    /// Wall-clock time of the replay, seconds.
    pub(super) elapsed_s: f64,
    /// In flight: the setup and the three errors.
    pub(super) flight: Option<FlightResults<'a>>,
    /// A scenario: each method's figures over the frames with a marker in view.
    pub(super) in_view: Option<&'a [InViewSummary]>,
}

/// What a replay in flight adds.
pub(super) struct FlightResults<'a> {
    pub(super) setup: &'a FlightSetup,
    /// The flight effects a scenario was rendered with.
    pub(super) effects: Option<&'a FlightEffects>,
    /// The board was given the true mount.
    pub(super) mount_known: bool,
    /// What `--calibration-hover` left on the board.
    pub(super) hover: Option<&'a HoverCalibration>,
    pub(super) trace: &'a FlightTrace,
}

/// One error's statistics, centimetres.
fn error_stats(e: &ErrorStats) -> Value {
    json!({
        "frames": e.frames,
        "mean_horizontal_cm": cm(e.mean_horizontal),
        "mean_abs_error_cm": xyz_of(e.mean_abs),
        "mean_error_cm": xyz_of(e.mean),
        "rms_error_cm": xyz_of(e.rms),
    })
}

/// The three errors as `{"sent", "reconstructed", "ideal"}`.
fn three(stats: impl Fn(ErrorKind) -> ErrorStats) -> Value {
    let mut m = Map::new();
    for k in ErrorKind::ALL {
        m.insert(k.key().into(), error_stats(&stats(k)));
    }
    Value::Object(m)
}

/// The `error_model` key: the autopilot, every term with its value and unit, the flight
/// effects, the mount and the calibration.
fn error_model(f: &FlightResults<'_>) -> Value {
    let terms: Map<String, Value> = f
        .setup
        .model
        .terms()
        .iter()
        .map(|(name, value, unit)| ((*name).to_string(), json!({"value": value, "unit": unit})))
        .collect();
    json!({
        "autopilot": f.setup.autopilot.name(),
        "seed": f.setup.seed,
        "terms": terms,
        "flight_effects": f.effects.map(|e| json!({
            "readout_ms": e.readout_ms,
            "vibration_deg": e.vibration_deg,
            "mount_roll_deg": e.mount_roll_deg,
            "mount_pitch_deg": e.mount_pitch_deg,
        })),
        "mount_known": f.mount_known,
        "calibration_hover": f.hover.map(|h| json!({
            "frames": h.frames,
            "fixes": h.fixes,
            "applied": h.applied,
            "TD_CAM_ROLL": h.roll_deg,
            "TD_CAM_PITCH": h.pitch_deg,
        })),
        "board_params": f.setup.params.iter().map(|(n, v)| json!({"name": n, "value": v})).collect::<Vec<_>>(),
    })
}

/// The whole replay as one JSON object (see the module docs); `figures` is the directory
/// and the number of files written, if any.
pub(super) fn document(
    args: &ReplayArgs,
    input: &Input,
    methods: &[Method],
    results: &Results<'_>,
    figures: Option<(&std::path::Path, usize)>,
) -> Value {
    let Results {
        report,
        trace,
        summaries,
        elapsed_s,
        flight,
        in_view,
    } = results;
    let (report, trace, summaries, elapsed_s) = (*report, *trace, *summaries, *elapsed_s);
    let mut root = Map::new();
    root.insert(
        "setup".into(),
        setup(args, input, methods, trace, elapsed_s),
    );
    root.insert(
        "set_points".into(),
        Value::Array(
            report
                .rows
                .iter()
                .map(|r| set_point(r, &report.methods, input))
                .collect(),
        ),
    );
    root.insert(
        "error_model".into(),
        flight.as_ref().map_or(Value::Null, error_model),
    );
    let mut summary = summary(trace, summaries, input.has_truth);
    if let (Some(f), Some(methods)) = (flight, summary["methods"].as_array_mut()) {
        for (m, entry) in methods.iter_mut().enumerate() {
            entry["flight"] = three(|k| f.trace.summary(m, k));
            entry["flight"]["latency_ms"] = match f.trace.latency_ms(m) {
                Some((mean, max)) => json!({"mean": mean, "max": max}),
                None => Value::Null,
            };
            entry["flight"]["pad_moving_from_frame"] = json!(f.trace.pad_moving_from(m));
        }
    }
    if let Some(methods) = summary["methods"].as_array_mut() {
        for (m, entry) in methods.iter_mut().enumerate() {
            entry["in_view"] = in_view
                .and_then(|v| v.get(m))
                .map_or(Value::Null, in_view_summary);
        }
    }
    root.insert("summary".into(), summary);
    // The text prints the altitude table only for a run with truth and without set points.
    let mut altitudes = if report.rows.is_empty() && input.has_truth {
        altitudes(trace)
    } else {
        Vec::new()
    };
    if let Some(f) = flight {
        for entry in &mut altitudes {
            let altitude = entry["altitude_m"].as_f64().unwrap_or(f64::NAN);
            if let Some(methods) = entry["methods"].as_array_mut() {
                for (m, method) in methods.iter_mut().enumerate() {
                    method["flight"] =
                        three(|k| f.trace.at_altitude(m, k, altitude, ALTITUDE_TOLERANCE));
                }
            }
        }
    }
    root.insert("altitudes".into(), Value::Array(altitudes));
    root.insert(
        "figures".into(),
        figures.map_or(
            Value::Null,
            |(dir, files)| json!({"dir": dir.display().to_string(), "files": files}),
        ),
    );
    Value::Object(root)
}

/// What was replayed, with what: the input, camera, pad and the methods' settings.
fn setup(
    args: &ReplayArgs,
    input: &Input,
    methods: &[Method],
    trace: &Trace,
    elapsed_s: f64,
) -> Value {
    let source = match (&args.scenario, &args.recording) {
        (Some(name), _) => json!({
            "kind": "scenario",
            "scenario": name,
            "seed": args.seed.unwrap_or(1),
        }),
        (None, dir) => json!({
            "kind": "recording",
            "recording": dir.as_ref().map(|d| d.display().to_string()),
        }),
    };
    let c = &input.camera;
    let flight_s = trace
        .frames
        .last()
        .zip(trace.frames.first())
        .map_or(0.0, |(b, a)| b.t_s() - a.t_s());
    json!({
        "input": source,
        "title": input.title,
        "frames": trace.frames.len(),
        "frames_limit": args.frames,
        "sequences": trace.sequences(),
        "flight_s": flight_s,
        "replay_s": elapsed_s,
        "frame_rate_hz": trace.frame_period_s().map(|p| 1.0 / p),
        "has_truth": input.has_truth,
        "camera": {
            "width": c.width,
            "height": c.height,
            "fx": c.fx,
            "fy": c.fy,
            "cx": c.cx,
            "cy": c.cy,
            "distortion": c.distortion,
            "distorted": c.has_distortion(),
        },
        "pad": {
            "name": input.pad.name,
            "markers": input.pad.markers.iter().map(|m| json!({
                "family": m.family,
                "id": m.id,
                "size_m": m.size,
                "x_m": m.x,
                "y_m": m.y,
                "yaw_deg": m.yaw_deg,
            })).collect::<Vec<_>>(),
        },
        "methods": methods.iter().map(method).collect::<Vec<_>>(),
    })
}

/// A method's name, path and settings.
fn method(m: &Method) -> Value {
    let (kind, settings) = match &m.kind {
        MethodKind::Paper(filter) => (
            "paper",
            json!({"filter": {
                "x0": filter.x0,
                "v0": filter.v0,
                "p0": filter.p0,
                "r": filter.r,
                "q": filter.q,
            }}),
        ),
        MethodKind::Board(config) => (
            "board",
            json!({
                "level_fix": config.level_fix,
                "flip_by_prediction": config.flip_by_prediction,
                "detector": {"fit_small_markers": config.detector.fit_small_markers},
                "correct_rolling_shutter": config.correct_rolling_shutter,
                "look_again": config.look_again,
            }),
        ),
    };
    json!({
        "name": m.name,
        "kind": kind,
        "attitude_given": m.use_attitude,
        "settings": settings,
    })
}

/// One set point: the set-point table's row and the all-axes table's (with truth), or the
/// vision-only table's (without).
fn set_point(results: &[SetPointResult], names: &[String], input: &Input) -> Value {
    let Some(first) = results.first() else {
        return Value::Null;
    };
    let sp = &first.set_point;
    let reference = sp.reference_m.is_finite().then_some(100.0 * sp.reference_m);
    let published = published(sp.axis, sp.reference_m)
        .map(|p| json!({"estimate_cm": p.estimate_cm, "error_cm": p.error_cm}));
    let methods: Vec<Value> = results
        .iter()
        .zip(names)
        .map(|(r, name)| {
            let estimate = [0, 1, 2].map(|k| r.filtered[k].mean_estimate());
            let mut m = json!({
                "name": name,
                "frames": r.frames,
                "detection_rate": r.detection_rate(),
                "estimate_rate": r.estimate_rate(),
                "mean_estimate_cm": xyz_cm(estimate),
            });
            if input.has_truth {
                let error = [0, 1, 2].map(|k| r.filtered[k].mean_error());
                m["on_axis"] = on_axis(r.on_axis());
                m["mean_error_cm"] = xyz_cm(error);
                m["raw_on_axis"] = on_axis(r.raw_on_axis());
            }
            m
        })
        .collect();
    json!({
        "label": sp.label,
        "axis": sp.axis.name().to_ascii_lowercase(),
        "reference_cm": reference,
        "published": published,
        "methods": methods,
    })
}

/// The summary table, per method.
fn summary(trace: &Trace, summaries: &[MethodSummary], has_truth: bool) -> Value {
    let methods: Vec<Value> = summaries
        .iter()
        .zip(&trace.methods)
        .map(|(m, name)| {
            json!({
                "name": name,
                "frames": m.frames,
                "detected": m.detected,
                "detection_rate": m.detection_rate(),
                "estimated": m.estimated,
                "estimate_rate": m.estimate_rate(),
                "scored": m.scored,
                "rms_error_cm": if has_truth { xyz_of(m.rms) } else { Value::Null },
                "raw_rms_error_cm": if has_truth { xyz_of(m.raw_rms) } else { Value::Null },
                "longest_gap": m.longest_gap.map(|g| json!({
                    "frames": g.frames,
                    "seconds": g.seconds,
                    "first_index": g.first_index,
                })),
                "slowest_first_estimate": m.slowest_acquisition.map(|a| json!({
                    "frames": a.frames,
                    "index": a.index,
                    "altitude_m": a.altitude_m,
                })),
                "sequences_without_estimate": m.sequences_without_estimate,
                "lag_frames": m.lag_frames.map_or(Value::Null, finite),
            })
        })
        .collect();
    json!({
        "frames": trace.frames.len(),
        "frame_rate_hz": trace.frame_period_s().map(|p| 1.0 / p),
        "methods": methods,
    })
}

/// A method's figures over the frames with a marker in view (`replay::in_view`).
fn in_view_summary(v: &InViewSummary) -> Value {
    json!({
        "frames": v.frames,
        "detected": v.detected,
        "detection_rate": v.detection_rate(),
        "longest_gap": v.longest_gap.map(|(frames, seconds, first_index)| json!({
            "frames": frames,
            "seconds": seconds,
            "first_index": first_index,
        })),
    })
}

/// The altitude table: one entry per checkpoint the flight passes.
fn altitudes(trace: &Trace) -> Vec<Value> {
    ALTITUDE_CHECKPOINTS_M
        .iter()
        .filter_map(|&altitude| {
            let stats: Vec<_> = (0..trace.methods.len())
                .map(|m| trace.at_altitude(m, altitude, ALTITUDE_TOLERANCE))
                .collect();
            let frames = stats.first().map_or(0, |a| a.frames);
            if frames == 0 {
                return None;
            }
            let methods: Vec<Value> = stats
                .iter()
                .zip(&trace.methods)
                .map(|(a, name)| {
                    let n = a.frames.max(1) as f64;
                    json!({
                        "name": name,
                        "detection_rate": a.detected as f64 / n,
                        "estimate_rate": a.estimated as f64 / n,
                        "mean_abs_error_cm": xyz_of(a.mean_abs),
                        "mean_error_norm_cm": cm(a.mean_norm),
                    })
                })
                .collect();
            Some(json!({
                "altitude_m": altitude,
                "tolerance": ALTITUDE_TOLERANCE,
                "frames": frames,
                "methods": methods,
            }))
        })
        .collect()
}
