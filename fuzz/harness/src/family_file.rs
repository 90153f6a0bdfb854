//! The `family_file` target: the core's family-file parser on arbitrary text, and the
//! detector run with the family it builds.

use touchdown_core::camera::CameraModel;
use touchdown_core::detect::QvgaWorkspace;
use touchdown_core::family::parse_family;
use touchdown_core::filter::VehicleState;
use touchdown_core::image::GrayImage;
use touchdown_core::pad::{PadLayout, PadMarker};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};

use crate::detect::check_detections;

/// Pixels per cell of the marker drawn by [`family_file`].
const FAMILY_CELL_PX: usize = 4;
/// Ids [`family_file`] checks for the decode round trip (the first ones).
const FAMILY_CHECKED_IDS: usize = 32;

/// The family-file parser on arbitrary text, and the family it builds.
///
/// Byte 0 sizes the caller's code buffer (1 to 1021 codes, so "too many codes" is reached),
/// the rest is the file. When the file parses into a family: each of the first ids decodes
/// back to itself from its own code in every rotation, and the per-frame path
/// ([`FramePipeline`]), given the family alone and a pad of its marker 0, runs on an image of
/// that marker drawn axis-aligned and reports only ids of the family (and a valid fix, if
/// any).
pub fn family_file(data: &[u8]) {
    let Some((&size, text)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(text) else {
        return;
    };
    let mut codes = vec![0u64; 1 + 4 * usize::from(size)];
    let Ok(header) = parse_family(text, "fuzz", &mut codes) else {
        return;
    };
    assert!(header.count >= 1 && header.count <= codes.len());
    let mut sorted_ids = vec![0u16; header.count];
    let Ok(family) = header.into_family(&codes, &mut sorted_ids) else {
        return;
    };
    assert_eq!(family.validate(), Ok(()));
    assert_eq!(family.check_layout(), Ok(()));
    for (id, &code) in family.codes.iter().enumerate().take(FAMILY_CHECKED_IDS) {
        for start in 0..4u8 {
            let readings = [0u8, 1, 2, 3].map(|k| family.rotate_code(code, start + k));
            let Some(decoded) = family.decode(&readings, 0) else {
                panic!("id {id} (code {code:#x}) does not decode");
            };
            assert_eq!(usize::from(decoded.id), id, "code {code:#x} turned {start}");
            assert_eq!(decoded.hamming, 0);
        }
    }

    let grid = usize::from(family.grid);
    let side = (grid + 2) * FAMILY_CELL_PX;
    let mut pixels = vec![255u8; side * side];
    for row in 0..grid {
        for col in 0..grid {
            if family.cell_is_white(0, row, col) == Some(false) {
                for y in 0..FAMILY_CELL_PX {
                    let start =
                        ((row + 1) * FAMILY_CELL_PX + y) * side + (col + 1) * FAMILY_CELL_PX;
                    pixels[start..start + FAMILY_CELL_PX].fill(0);
                }
            }
        }
    }
    let image = GrayImage::new(&pixels, side, side).expect("a valid size");
    let families = [&family];
    let marker = PadMarker {
        family: family.name,
        id: 0,
        size: 0.16,
        x: 0.0,
        y: 0.0,
        yaw_deg: 0.0,
    };
    let pad = PadLayout::new("fuzz", &[marker]).expect("a one-marker pad of a named family");
    let focal = side as f32;
    let centre = (side as f32 - 1.0) * 0.5;
    let camera = CameraModel::pinhole(side as u32, side as u32, focal, focal, centre, centre);
    let mut workspace = Box::new(QvgaWorkspace::new());
    let mut pipeline = Box::new(
        FramePipeline::new(
            &families,
            &pad,
            camera,
            PipelineConfig::default(),
            PipelineSettings::default(),
        )
        .expect("the default trackers are valid"),
    );
    let report = pipeline.process(&image, 0, &VehicleState::new(), &mut workspace.buffers());
    assert_eq!(
        report.detect_error, None,
        "a validated family and QVGA buffers"
    );
    check_detections(pipeline.detector().detections(), &families);
    if let Some(fix) = report.fix {
        assert!(fix.pose.is_valid(), "pad fix {fix:?}");
    }
}
