//! Which marker families the vision task searches.
//!
//! - Default: core's [`tables::DEFAULT`] (tag36h11 and aruco_6x6_250, the same as the host
//!   CLI without `--family`).
//! - Feature `user-family` (`cargo fw --features user-family`): only your own family, the
//!   generated [`user_family::USER_FAMILY`](crate::user_family::USER_FAMILY). Replace
//!   `src/user_family.rs` with your markers' table first:
//!   `python3 tools/gen_families.py --user MY_FAMILY.txt --out firmware/src/user_family.rs`
//!   (the text format of `shared/data/families`: the full cell grid of each code).
//!
//! To search the user family *and* the defaults, list them together in [`SEARCHED`]; at most
//! [`MAX_FAMILIES`](touchdown_core::detect::MAX_FAMILIES) families are searched at once, and
//! each extra family costs decode time on every candidate quad. Only the families named here
//! end up in flash: the link-time optimiser drops every other generated table.
//!
//! [`tables::DEFAULT`]: touchdown_core::family::tables::DEFAULT

use touchdown_core::family::Family;

/// The families searched in every frame, in the order detections refer to by index.
#[cfg(not(feature = "user-family"))]
pub static SEARCHED: &[&Family<'static>] = touchdown_core::family::tables::DEFAULT;

/// The families searched in every frame, in the order detections refer to by index.
#[cfg(feature = "user-family")]
pub static SEARCHED: &[&Family<'static>] = &[&crate::user_family::USER_FAMILY];
