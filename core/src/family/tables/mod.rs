//! Generated code tables of the shipped families (placeholder until the generator runs).

use super::Family;

/// Every shipped family.
pub static ALL: &[&Family<'static>] = &[];

/// A shipped family by its contract name (`tag36h11`, `aruco_6x6_250`, ...).
pub fn by_name(name: &str) -> Option<&'static Family<'static>> {
    ALL.iter().copied().find(|f| f.name == name)
}
