//! The fuzz harnesses: one function per cargo-fuzz target, each taking the raw input bytes
//! and panicking when an invariant breaks.
//!
//! A library of its own, not code in `fuzz_targets/`, so that two crates run the same checks:
//! the cargo-fuzz targets (`fuzz/`, its own workspace, built with nightly flags and
//! libFuzzer) hand libFuzzer's bytes to these functions, and this crate's
//! `tests/regressions.rs` replays the seed corpora and every saved regression input
//! (`fuzz/corpus/`, `fuzz/regressions/`) in the normal `cargo test`. Hence no libFuzzer and
//! no dependency beyond the core, the file parsers (`touchdown-formats`) and nalgebra:
//! structured inputs are read with [`Input`], a byte reader that yields zeros once the data
//! runs out.
//!
//! | target | input | checked |
//! |---|---|---|
//! | [`detect`] | frame size, family set, pixels | detections name real ids, finite corners, step budget |
//! | [`family_file`] | buffer size, family text | ids decode back to themselves; detector runs with the family |
//! | [`config_toml`] | text | an accepted camera validates, an accepted pad builds its layout |
//! | [`recording`] | selector, `frames.csv` text or PGM bytes | accepted rows and frames are consistent |
//! | [`mavlink_stream`] | a script of link bytes, frames, params, time steps | every emitted frame is valid MAVLink, targets finite, draining ends |
//! | [`frame_stream`] | chunk size, bytes | the viewer's reader returns whole, consistent records; the board's request parser only sensible requests |
//! | [`signed_stream`] | a key, then signed / wrongly signed / unsigned / replayed writes, armed HEARTBEATs, bytes, time steps | only writes signed with the key in force change anything, none but TD_LOCK while locked; every frame sent signed and valid, timestamps rising |

mod config_toml;
mod detect;
mod family_file;
mod frame_stream;
mod input;
mod mavlink_stream;
mod recording;
mod signed_stream;

pub use config_toml::config_toml;
pub use detect::{
    check_detections, detect, DetectState, DETECT_MAX_HEIGHT, DETECT_MAX_WIDTH, FAMILY_SETS,
};
pub use family_file::family_file;
pub use frame_stream::frame_stream;
pub use input::Input;
pub use mavlink_stream::{check_emitted, drain, mavlink_frame, mavlink_stream, Op};
pub use recording::recording;
pub use signed_stream::{frame as signed_frame, signed_stream};
