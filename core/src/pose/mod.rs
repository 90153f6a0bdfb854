//! Marker and pad pose from corners (in progress, issue 3).
