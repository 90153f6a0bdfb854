//! `touchdown sitl` against stand-ins for an autopilot's two ports: the board's link
//! ([`connect`]: a landing rendered from the stand-in's ground truth) and the ground station's
//! ([`gcs`]: what a user meets before the flight starts).
//!
//! One test binary, so that their waits overlap: most of their time is the wall clock of a
//! link (a scripted descent, a SITL that is not there retried for the run's patience), not
//! work. The test harness starts tests in name order, as many at once as there are cores:
//! the longest wait, [`gcs::a_closed_port_asks_whether_the_sitl_runs`], sorts first, so that
//! on two cores the others run beside it rather than after it.

#[allow(dead_code)] // `scratch` is for the tests that write files; these write none.
#[path = "../common/mod.rs"]
mod common;

mod connect;
mod gcs;
