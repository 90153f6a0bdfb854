//! A small perspective renderer of markers for tests (in progress).
