//! `touchdown sitl` against stand-ins for an autopilot's two ports: the board's link
//! ([`connect`]: a landing rendered from the stand-in's ground truth) and the ground station's
//! ([`gcs`]: what a user meets before the flight starts).
//!
//! One test binary, so that their waits overlap: most of their time is the wall clock of a
//! link (a scripted descent, a SITL that is not there, a parameter that never answers), not
//! work; the ground-station cases shorten the waits they provoke with `--connect-timeout`
//! and `--param-timeout`.

#[allow(dead_code)] // `scratch` is for the tests that write files; these write none.
#[path = "../common/mod.rs"]
mod common;

mod connect;
mod gcs;
