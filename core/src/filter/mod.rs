//! Filters that smooth the pad position over time (in progress, issue 3).
