//! Marker families by name or from family files (in progress).
