//! Camera model: pinhole intrinsics and Brown-Conrady distortion (in progress, issue 3).
