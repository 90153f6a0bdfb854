//! 3x3 matrix arithmetic in `f64`: the homographies that map a marker's grid to the image
//! (product, inverse, application with the horizon test) and the rotations that place it.
//! The simulator's matrix helpers ([`crate::sim::math`]) use the same row-major layout and
//! call into this.

/// A 3x3 matrix, row-major rows.
pub(crate) type Mat3 = [[f64; 3]; 3];

/// The product `a b`.
pub(crate) fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for (r, row) in c.iter_mut().enumerate() {
        for (k, out) in row.iter_mut().enumerate() {
            *out = (0..3).map(|j| a[r][j] * b[j][k]).sum();
        }
    }
    c
}

/// The inverse, or `None` for a singular (or non-finite) matrix.
pub(super) fn invert3(m: &Mat3) -> Option<Mat3> {
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    if !det.is_finite() || det.abs() <= 1e-300 {
        return None;
    }
    Some(adj.map(|row| row.map(|v| v / det)))
}

/// Applies a homography; `None` at or behind the horizon (w <= 0: the plane point is not in
/// front of the camera, or the pixel's ray misses the plane's front side).
pub(crate) fn apply(m: &Mat3, x: f64, y: f64) -> Option<(f64, f64)> {
    let w = m[2][0] * x + m[2][1] * y + m[2][2];
    if w.is_nan() || w <= 1e-12 {
        return None;
    }
    Some((
        (m[0][0] * x + m[0][1] * y + m[0][2]) / w,
        (m[1][0] * x + m[1][1] * y + m[1][2]) / w,
    ))
}

/// Rotation by `angle` radians about the unit `axis` (Rodrigues).
pub(super) fn rotation_about(axis: &[f64; 3], angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = *axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}
