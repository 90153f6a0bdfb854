//! refine (in progress)
