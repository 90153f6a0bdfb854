//! Host-side support for touchdown: image files, owned work memory, marker families from
//! files, the command-line tool's pieces, and the test renderer.
//!
//! Everything algorithmic lives in `touchdown-core`; this crate only does what needs `std`
//! (files, allocation, formatting) and calls the core exactly as the firmware does.

pub mod cli;
pub mod eval;
pub use touchdown_formats as formats;
pub use touchdown_formats::{families, image_io};
pub mod plot;
pub mod render;
pub mod shared_data;
pub mod sim;
pub mod trace;
pub mod workspace;
