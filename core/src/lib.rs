//! # touchdown-core
//!
//! Everything of the touchdown landing aid that does not touch hardware: finding fiducial
//! markers in a grey frame, the marker families, pose, the landing pad, filters, the MAVLink
//! companion logic, the parameters, and the sensor-independent side of the camera (its units
//! and frame timing, and the software auto-exposure loop: [`sensor`]).
//!
//! The camera sensor drivers are not here: they are the `touchdown-sensors` crate
//! (`sensors/`). A driver is I/O against a bus (register writes over SCCB through
//! embedded-hal-async traits); this crate is algorithms on plain values, testable on the host
//! and depending on no hardware trait. The drivers depend on core for the types they share
//! with it ([`sensor::GainX16`], [`sensor::FrameTiming`]), core depends on nothing of theirs,
//! and the firmware wires the two: the bus into the driver, the frames and the timing into
//! core.
//!
//! The crate is `no_std`, allocates nothing and contains no `unsafe`. All working memory is
//! either owned by a struct with capacities fixed by named constants, or lent by the caller,
//! so the firmware can place every buffer in the RAM it chooses and the host can size buffers
//! to the image it reads. No function panics on any input: bad input is an error value.
//!
//! The data path is one straight line:
//! frame ([`image::GrayImage`]) -> candidates ([`detect`]) -> decoded markers
//! ([`detect::Detection`]) -> pad fix ([`pose`], with the [`camera`] model and the [`pad`]
//! layout) -> estimator ([`filter`], with the vehicle's [`filter::Attitude`] and
//! [`filter::CameraMount`]) -> messages ([`companion`]). Everything up to the estimate is one
//! type that every caller uses, [`pipeline::FramePipeline`]; the MAVLink side turns its output
//! into bytes. The MAVLink parameters and what they set are [`params`].
//!
//! Each module is one concern: its stages are private submodules and its entry types are
//! re-exported at the module (`filter::PadEstimator`, not a path through the file it is
//! written in), so a stage can be split or moved without changing any caller. The only public
//! submodules are namespaces of data, not stages: the generated family tables
//! ([`family::tables`]), the pad designs by name ([`pad::designs`]) and the MAVLink crate with
//! its message types ([`companion::mavlink`]).
//!
//! Conventions (the project's contract, see `docs/interfaces.md`): pixel (0, 0) is the
//! centre of the top-left pixel, x right, y down; marker corners are the outer corners of the
//! black border, ordered top-left, top-right, bottom-right, bottom-left of the marker's
//! canonical image.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// `!(x > y)` is used on purpose: it is also true when x is NaN, so NaN is rejected.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]

pub mod camera;
pub mod companion;
pub mod crc;
pub mod detect;
pub mod family;
pub mod filter;
pub mod frame_stream;
pub mod geometry;
pub mod image;
pub mod pad;
pub mod params;
pub mod pipeline;
pub mod pose;
pub mod sensor;
pub mod sha256;
