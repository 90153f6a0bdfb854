//! contour (in progress)
/// A boundary pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Pixel { pub x: u16, pub y: u16 }
