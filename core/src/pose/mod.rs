//! Marker and pad pose from detected corners.
//!
//! What this module offers: [`marker_pose`] (one decoded marker's [`MarkerPose`], both
//! candidate [`Pose`]s, by a [`PoseMethod`]) and the pad fix, [`pad_pose`] and
//! [`pad_pose_with_prediction`] (a [`PadFix`] from every marker of the pad in view, with a
//! covariance; [`crate::pipeline::FramePipeline`] also levels it with the attitude). It takes
//! the decoded markers of [`crate::detect`] with the [`crate::camera`] model and the
//! [`crate::pad`] layout; the fix goes on to the estimator, [`crate::filter`].
//!
//! A [`Pose`] maps points of a marker (or pad) frame into the camera frame,
//! `X_cam = R X_marker + t`, with the contract's frames: marker x right, y up, z out of the
//! printed face towards the viewer; camera x right, y down, z forward. The camera's own
//! position in the marker frame (what a landing drone wants) is [`Pose::camera_position`].
//!
//! ## Methods
//! - [`PoseMethod::Ippe`] (the one touchdown uses): the planar square has two poses that
//!   explain four corners almost equally well when the marker is small or seen nearly
//!   face-on (the "flip" ambiguity). Infinitesimal Plane-based Pose Estimation (Collins and
//!   Bartoli 2014, in `ippe`) gives both in closed form from the corner homography; each is
//!   polished by Levenberg-Marquardt on the pixel reprojection error with the lens
//!   distortion included (`levenberg_marquardt`), and the one with the lower error is reported
//!   first.
//!   The other is kept so a caller with a prediction (the filter) can choose
//!   ([`MarkerPose::choose_by_predicted_camera_position`]).
//! - [`PoseMethod::PaperHomography`]: the paper's equations 5-7, `H = K [r1 r2 t]` decomposed
//!   directly with no refinement (`homography_decomposition`); kept so the paper's tables
//!   can be reproduced.
//!
//! The whole landing pad (all corners of all visible markers in one refinement, with a
//! covariance) is [`pad_pose`], in `pad_pose`; the fix with the tilt taken from gravity
//! instead of the image is in `level`. These submodules are private: the functions and types
//! above are the module's surface.
//!
//! Every iterative step has a fixed iteration cap; nothing allocates; bad input is a
//! [`PoseError`].

mod homography_decomposition;
mod ippe;
mod level;
mod levenberg_marquardt;
mod pad_pose;

pub(crate) use level::level_pad_fix;
pub(crate) use pad_pose::{largest_layout_marker, layout_marker, marker_to_pad};
pub use pad_pose::{
    pad_pose, pad_pose_with_prediction, PadFix, MAX_FIX_MARKERS, PIXEL_NOISE_FLOOR_PX,
};

use crate::camera::CameraModel;
use crate::geometry::Point;
use nalgebra::{Matrix3, Vector3};

/// Error of a pose computation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PoseError {
    /// The marker size is not a finite positive number.
    BadMarkerSize,
    /// The camera model does not validate.
    BadCamera,
    /// The pad layout does not validate.
    BadLayout,
    /// A corner could not be undistorted (outside the invertible part of the lens model).
    CornerNotUndistortable,
    /// The corners are degenerate (collinear, coincident) or the homography is singular.
    DegenerateCorners,
    /// The solver produced no finite pose with the marker in front of the camera.
    NoSolution,
    /// No detection belongs to the pad layout.
    NoPadMarkers,
    /// Model and image point lists differ in length, or have fewer than four points.
    BadPointCount,
}

/// A rigid transform from a marker (or pad) frame into the camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation, marker frame to camera frame.
    pub rotation: Matrix3<f32>,
    /// Marker origin in the camera frame, metres.
    pub translation: Vector3<f32>,
}

impl Pose {
    /// The identity transform.
    pub fn identity() -> Self {
        Pose {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// Maps a marker-frame point into the camera frame.
    pub fn transform(&self, point: &Vector3<f32>) -> Vector3<f32> {
        self.rotation * point + self.translation
    }

    /// The inverse transform (camera frame to marker frame).
    pub fn inverse(&self) -> Pose {
        let rt = self.rotation.transpose();
        Pose {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// `self` after `inner`: `x -> self(inner(x))`.
    pub fn compose(&self, inner: &Pose) -> Pose {
        Pose {
            rotation: self.rotation * inner.rotation,
            translation: self.rotation * inner.translation + self.translation,
        }
    }

    /// The camera centre in the marker (pad) frame, `-R^T t`: the drone's view.
    pub fn camera_position(&self) -> Vector3<f32> {
        -(self.rotation.transpose() * self.translation)
    }

    /// The rotation row-major (`r00 r01 r02 r10 ...`), as the CLI prints it.
    pub fn rotation_row_major(&self) -> [f32; 9] {
        let r = &self.rotation;
        [
            r.m11, r.m12, r.m13, r.m21, r.m22, r.m23, r.m31, r.m32, r.m33,
        ]
    }

    /// Angle of the rotation between `self` and `other`, radians.
    pub fn rotation_angle_to(&self, other: &Pose) -> f32 {
        let relative = self.rotation.transpose() * other.rotation;
        let cos = ((relative.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
        libm::acosf(cos)
    }

    /// All entries finite and the marker origin in front of the camera.
    pub fn is_valid(&self) -> bool {
        self.rotation.iter().all(|v| v.is_finite())
            && self.translation.iter().all(|v| v.is_finite())
            && self.translation.z > 0.0
    }
}

/// How a single marker's pose is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PoseMethod {
    /// The paper's homography decomposition, no refinement (to reproduce its tables).
    PaperHomography,
    /// IPPE's two candidates, each refined by Levenberg-Marquardt (touchdown's method).
    #[default]
    Ippe,
}

/// One pose hypothesis and how well it explains the corners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCandidate {
    /// The pose.
    pub pose: Pose,
    /// Root-mean-square distance between the observed corners and the corners reprojected
    /// with this pose (distortion included), pixels.
    pub reprojection_rms_px: f32,
}

/// The pose of one marker: the best candidate and, for IPPE, the other member of the flip
/// pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerPose {
    /// The candidate with the lower reprojection error.
    pub best: PoseCandidate,
    /// The other planar solution, when the method yields one.
    pub alternative: Option<PoseCandidate>,
}

impl MarkerPose {
    /// Resolves the flip ambiguity with a prediction of the camera position in the marker
    /// frame (from a filter): when the alternative's reprojection error is within
    /// `ambiguity_ratio` times the best one's (e.g. 2.0; errors below
    /// [`PIXEL_NOISE_FLOOR_PX`] count as the floor, since they are all equally "exact"),
    /// the candidate whose
    /// [`Pose::camera_position`] is nearer the prediction wins; otherwise the reprojection
    /// error decides.
    pub fn choose_by_predicted_camera_position(
        &self,
        predicted: &Vector3<f32>,
        ambiguity_ratio: f32,
    ) -> &PoseCandidate {
        match &self.alternative {
            Some(alt)
                if alt.reprojection_rms_px
                    <= ambiguity_ratio
                        * self.best.reprojection_rms_px.max(PIXEL_NOISE_FLOOR_PX) =>
            {
                let d_best = (self.best.pose.camera_position() - predicted).norm();
                let d_alt = (alt.pose.camera_position() - predicted).norm();
                if d_alt < d_best {
                    alt
                } else {
                    &self.best
                }
            }
            _ => &self.best,
        }
    }
}

/// Corners of a square marker of edge `size` in its own frame, contract order: top-left,
/// top-right, bottom-right, bottom-left = (-s/2, +s/2), (+s/2, +s/2), (+s/2, -s/2),
/// (-s/2, -s/2), z = 0.
pub fn marker_corners(size: f32) -> [Vector3<f32>; 4] {
    let h = 0.5 * size;
    [
        Vector3::new(-h, h, 0.0),
        Vector3::new(h, h, 0.0),
        Vector3::new(h, -h, 0.0),
        Vector3::new(-h, -h, 0.0),
    ]
}

/// Root-mean-square reprojection error (pixels) of `pose` over matching model and image
/// points; `None` when the lists are empty or differ in length, or a point is behind the
/// camera.
pub fn reprojection_rms(
    camera: &CameraModel,
    pose: &Pose,
    model: &[Vector3<f32>],
    image: &[Point],
) -> Option<f32> {
    if model.is_empty() || model.len() != image.len() {
        return None;
    }
    let mut sum = 0.0f32;
    for (m, observed) in model.iter().zip(image) {
        let p = camera.project(&pose.transform(m))?;
        let (dx, dy) = (p.x - observed.x, p.y - observed.y);
        sum += dx * dx + dy * dy;
    }
    Some(libm::sqrtf(sum / model.len() as f32))
}

/// Undistorted normalised coordinates of four corners.
pub fn normalized_corners(
    camera: &CameraModel,
    corners: &[Point; 4],
) -> Result<[Point; 4], PoseError> {
    let mut out = [Point::default(); 4];
    for (o, c) in out.iter_mut().zip(corners) {
        *o = camera
            .undistort(*c)
            .ok_or(PoseError::CornerNotUndistortable)?;
    }
    Ok(out)
}

/// Pose of one square marker of edge `size` (metres) from its four corners in contract
/// order (pixels, as the detector reports them).
pub fn marker_pose(
    corners: &[Point; 4],
    size: f32,
    camera: &CameraModel,
    method: PoseMethod,
) -> Result<MarkerPose, PoseError> {
    if !(size.is_finite() && size > 0.0) {
        return Err(PoseError::BadMarkerSize);
    }
    camera.validate().map_err(|_| PoseError::BadCamera)?;
    let normalized = normalized_corners(camera, corners)?;
    let model = marker_corners(size);
    match method {
        PoseMethod::PaperHomography => {
            let pose = homography_decomposition::paper_pose(&normalized, size)?;
            let rms =
                reprojection_rms(camera, &pose, &model, corners).ok_or(PoseError::NoSolution)?;
            Ok(MarkerPose {
                best: PoseCandidate {
                    pose,
                    reprojection_rms_px: rms,
                },
                alternative: None,
            })
        }
        PoseMethod::Ippe => {
            let starts = ippe::square_poses(&normalized, size)?;
            let mut refined: [Option<PoseCandidate>; 2] = [None, None];
            for (slot, start) in refined.iter_mut().zip(starts.iter()) {
                *slot = levenberg_marquardt::refine(camera, &model, corners, start)
                    .ok()
                    .map(|r| PoseCandidate {
                        pose: r.pose,
                        reprojection_rms_px: r.rms_px,
                    });
            }
            match refined {
                [Some(a), Some(b)] => {
                    let (best, alt) = if a.reprojection_rms_px <= b.reprojection_rms_px {
                        (a, b)
                    } else {
                        (b, a)
                    };
                    Ok(MarkerPose {
                        best,
                        alternative: Some(alt),
                    })
                }
                [Some(a), None] | [None, Some(a)] => Ok(MarkerPose {
                    best: a,
                    alternative: None,
                }),
                [None, None] => Err(PoseError::NoSolution),
            }
        }
    }
}
