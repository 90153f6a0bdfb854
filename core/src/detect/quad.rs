//! quad (in progress)
