//! Pose of the whole landing pad from every visible marker of its layout.
//!
//! Why one refinement over all corners: a single marker's pose is weak in rotation and
//! ambiguous when it is small in the image; corners spread over several markers constrain
//! the pad's tilt far better, and one least-squares fit weights each marker by how much it
//! actually tells (its image size, its distance). The fit's normal matrix gives the
//! covariance, so the filter can tell a 40 m single-marker fix from a 2 m six-marker fix.
//!
//! Steps:
//! 1. Keep the detections whose family name and id are in the layout (others ignored; a
//!    layout marker seen twice is used once). Their corners become pad-frame model points.
//! 2. Start from the marker with the largest image: both IPPE solutions of it, refined on its
//!    own corners and moved into the pad frame.
//! 3. Refine each start on all corners (Levenberg-Marquardt, [`levenberg_marquardt`](super::levenberg_marquardt)); keep
//!    the lower reprojection error, or, when the two are within [`AMBIGUOUS_RMS_RATIO`] and a
//!    prediction is given, the one whose camera position is nearer the prediction.
//! 4. Covariance `(J^T J)^-1 sigma^2`, sigma from the residuals with a floor of
//!    [`PIXEL_NOISE_FLOOR_PX`].
//!
//! ## Frames
//! - [`PadFix::pose`] maps pad-frame points into the camera frame (`X_cam = R X_pad + t`);
//!   `t` is the pad origin (the landing point) as the camera sees it.
//! - [`PadFix::camera_position`] is the camera centre in the pad frame (x right, y up, z up
//!   out of the pad: the drone's height above the pad is its z).
//! - [`PadFix::covariance`] is over (rotation increment in the camera frame, applied on the
//!   left of `R`; translation `t`), radians and metres.

use super::{ippe, levenberg_marquardt, marker_corners, normalized_corners, Pose, PoseError};
use crate::camera::CameraModel;
use crate::detect::Detection;
use crate::family::Family;
use crate::geometry::{quad_area, Point};
use crate::pad::{PadLayout, PadMarker, MAX_PAD_MARKERS};
use nalgebra::{Matrix3, Matrix6, Vector3};

/// Lower bound of the pixel noise used for the covariance: corner noise is never better than
/// this, even when a fit happens to be nearly exact.
pub const PIXEL_NOISE_FLOOR_PX: f32 = 0.3;
/// When the two flip solutions' reprojection errors are within this ratio (errors below
/// [`PIXEL_NOISE_FLOOR_PX`] counted as the floor), a prediction (if given) decides between
/// them.
pub const AMBIGUOUS_RMS_RATIO: f32 = 2.0;
/// Most markers in one pad fit: the first this many of the pad's markers among a frame's
/// detections. A pad may have more ([`MAX_PAD_MARKERS`]) and a view of its small ones may
/// show more, but forty markers' corners already pin the pose, and the fit's buffers live on
/// the firmware's stack.
pub const MAX_FIX_MARKERS: usize = 40;
/// Most corners in one pad fit.
pub const MAX_PAD_POINTS: usize = 4 * MAX_FIX_MARKERS;

/// A pad pose measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadFix {
    /// Pad frame to camera frame.
    pub pose: Pose,
    /// 6x6 covariance over (rotation increment, left, camera frame; translation).
    pub covariance: Matrix6<f32>,
    /// Layout markers whose corners were used.
    pub markers_used: u8,
    /// RMS reprojection error over all used corners, pixels.
    pub reprojection_rms_px: f32,
    /// Reprojection error of the other flip solution, pixels (`f32::INFINITY` if none).
    pub alternative_rms_px: f32,
}

impl PadFix {
    /// The camera centre in the pad frame, metres (the drone's view; z = height).
    pub fn camera_position(&self) -> Vector3<f32> {
        self.pose.camera_position()
    }

    /// Covariance of [`PadFix::camera_position`] (first-order propagation: with
    /// `c = -R^T t`, `dc/dw = -R^T [t]x` and `dc/dt = -R^T`).
    pub fn camera_position_covariance(&self) -> Matrix3<f32> {
        let rt = self.pose.rotation.transpose();
        let d_w = -(rt * self.pose.translation.cross_matrix());
        let d_t = -rt;
        let mut j = nalgebra::Matrix3x6::<f32>::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&d_w);
        j.fixed_view_mut::<3, 3>(0, 3).copy_from(&d_t);
        j * self.covariance * j.transpose()
    }

    /// Covariance of the pad origin in the camera frame (`t`).
    pub fn pad_position_covariance(&self) -> Matrix3<f32> {
        self.covariance.fixed_view::<3, 3>(3, 3).into_owned()
    }
}

/// The transform from a layout marker's frame to the pad frame.
pub fn marker_to_pad(marker: &PadMarker<'_>) -> Pose {
    let yaw = marker.yaw_deg.to_radians();
    let (s, c) = (libm::sinf(yaw), libm::cosf(yaw));
    Pose {
        rotation: Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
        translation: Vector3::new(marker.x, marker.y, 0.0),
    }
}

/// The layout marker a detection shows, with its index in the layout, if any.
fn layout_marker_index<'l>(
    layout: &'l PadLayout<'l>,
    families: &[&Family<'_>],
    detection: &Detection,
) -> Option<(usize, &'l PadMarker<'l>)> {
    let family = families.get(detection.family as usize)?;
    layout
        .markers()
        .iter()
        .enumerate()
        .find(|(_, m)| m.id == detection.id && m.family.eq_ignore_ascii_case(family.name))
}

/// The layout marker a detection shows, if any.
pub(crate) fn layout_marker<'l>(
    layout: &'l PadLayout<'l>,
    families: &[&Family<'_>],
    detection: &Detection,
) -> Option<&'l PadMarker<'l>> {
    layout_marker_index(layout, families, detection).map(|(_, m)| m)
}

/// The layout marker with the largest image among the detections, with its detection (the
/// paper's method uses one marker; the pad fit starts from it).
pub fn largest_layout_marker<'d, 'l>(
    detections: &'d [Detection],
    families: &[&Family<'_>],
    layout: &'l PadLayout<'l>,
) -> Option<(&'d Detection, &'l PadMarker<'l>)> {
    detections
        .iter()
        .filter_map(|d| Some((d, layout_marker(layout, families, d)?)))
        .max_by(|a, b| quad_area(&a.0.corners).total_cmp(&quad_area(&b.0.corners)))
}

/// [`pad_pose_with_prediction`] without a prediction.
pub fn pad_pose(
    detections: &[Detection],
    families: &[&Family<'_>],
    layout: &PadLayout<'_>,
    camera: &CameraModel,
) -> Result<PadFix, PoseError> {
    pad_pose_with_prediction(detections, families, layout, camera, None)
}

/// The pad pose from this frame's detections. `families` is the slice the detector ran with
/// (a detection's `family` indexes it). `predicted_camera_position` (pad frame, e.g. from
/// the filter) only breaks near-ties between the two flip solutions.
pub fn pad_pose_with_prediction(
    detections: &[Detection],
    families: &[&Family<'_>],
    layout: &PadLayout<'_>,
    camera: &CameraModel,
    predicted_camera_position: Option<&Vector3<f32>>,
) -> Result<PadFix, PoseError> {
    camera.validate().map_err(|_| PoseError::BadCamera)?;
    if layout.markers().is_empty() {
        return Err(PoseError::BadLayout);
    }
    let mut model = [Vector3::<f32>::zeros(); MAX_PAD_POINTS];
    let mut image = [Point::default(); MAX_PAD_POINTS];
    let mut used = [false; MAX_PAD_MARKERS];
    let mut count = 0usize;
    let mut markers_used = 0u8;
    // (layout marker, corners) of the marker with the largest image.
    let mut anchor: Option<(&PadMarker<'_>, [Point; 4], f32)> = None;

    for detection in detections {
        if count + 4 > MAX_PAD_POINTS {
            break;
        }
        let Some((index, marker)) = layout_marker_index(layout, families, detection) else {
            continue;
        };
        match used.get_mut(index) {
            Some(flag) if !*flag => *flag = true,
            _ => continue,
        }
        let corners_pad = marker_corners(marker.size).map(|c| marker.to_pad(&c));
        let slots = model
            .iter_mut()
            .zip(image.iter_mut())
            .skip(count)
            .zip(corners_pad.iter().zip(detection.corners.iter()));
        for ((m, i), (cp, ci)) in slots {
            *m = *cp;
            *i = *ci;
        }
        count += 4;
        markers_used = markers_used.saturating_add(1);
        let area = quad_area(&detection.corners);
        if anchor.is_none_or(|(_, _, best)| area > best) {
            anchor = Some((marker, detection.corners, area));
        }
    }
    let Some((anchor_marker, anchor_corners, _)) = anchor else {
        return Err(PoseError::NoPadMarkers);
    };
    let (model, image) = (
        model.get(..count).ok_or(PoseError::BadPointCount)?,
        image.get(..count).ok_or(PoseError::BadPointCount)?,
    );

    // Both flip solutions of the anchor marker, polished on its corners, in the pad frame.
    let normalized = normalized_corners(camera, &anchor_corners)?;
    let starts = ippe::square_poses(&normalized, anchor_marker.size)?;
    let anchor_model = marker_corners(anchor_marker.size);
    let pad_to_marker = marker_to_pad(anchor_marker).inverse();
    let mut fits: [Option<levenberg_marquardt::Refined>; 2] = [None, None];
    for (fit, start) in fits.iter_mut().zip(starts.iter()) {
        let single = levenberg_marquardt::refine(camera, &anchor_model, &anchor_corners, start)
            .map(|r| r.pose)
            .unwrap_or(*start);
        *fit =
            levenberg_marquardt::refine(camera, model, image, &single.compose(&pad_to_marker)).ok();
    }
    let (best, other) = match fits {
        [Some(a), Some(b)] => {
            let (lo, hi) = if a.rms_px <= b.rms_px { (a, b) } else { (b, a) };
            let ambiguous = hi.rms_px <= AMBIGUOUS_RMS_RATIO * lo.rms_px.max(PIXEL_NOISE_FLOOR_PX);
            match predicted_camera_position {
                Some(p) if ambiguous => {
                    let d_lo = (lo.pose.camera_position() - p).norm();
                    let d_hi = (hi.pose.camera_position() - p).norm();
                    if d_hi < d_lo {
                        (hi, Some(lo))
                    } else {
                        (lo, Some(hi))
                    }
                }
                _ => (lo, Some(hi)),
            }
        }
        [Some(a), None] | [None, Some(a)] => (a, None),
        [None, None] => return Err(PoseError::NoSolution),
    };
    let covariance = best
        .covariance(PIXEL_NOISE_FLOOR_PX)
        .ok_or(PoseError::NoSolution)?;
    Ok(PadFix {
        pose: best.pose,
        covariance,
        markers_used,
        reprojection_rms_px: best.rms_px,
        alternative_rms_px: other.map_or(f32::INFINITY, |o| o.rms_px),
    })
}
