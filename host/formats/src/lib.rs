//! The files touchdown's host tools read and write, each with its reader and its writer side
//! by side so the two cannot drift apart:
//!
//! - [`camera`]: `camera.toml`, the camera's intrinsics;
//! - [`pad`]: `pad.toml`, the landing pad's layout;
//! - [`recording`]: a recording directory (`frames.csv`, `setpoints.csv`, the frames);
//! - [`pgm`]: the 8-bit binary PGM frames of a recording;
//! - [`image_io`]: image files in general (PNG, PGM, JPEG; colour read as grey);
//! - [`families`]: marker families from disk (a shipped table by name, or a family file);
//! - [`frame_stream`]: the board's frame stream to a viewer (`touchdown view`).
//!
//! The formats themselves are the contract's (`docs/interfaces.md`); these modules implement
//! them and say only what the contract leaves to the implementation. The TOML files share
//! their error types ([`ConfigError`], [`ParseError`]).
//!
//! What this crate is not: it renders nothing (that is `touchdown-sim`), scores nothing
//! (`touchdown-eval`) and has no command line (`touchdown-cli`). It is a crate of its own so
//! that whatever parses untrusted files, the fuzz harness above all, depends on the parsers
//! and their few dependencies (core, serde, toml, image) only, not on a command line's clap
//! and plotting or a simulator's random numbers.

pub mod camera;
pub mod families;
pub mod frame_stream;
pub mod image_io;
pub mod pad;
pub mod pgm;
pub mod recording;
mod toml_file;

pub use toml_file::{toml_string, ConfigError, ParseError};
