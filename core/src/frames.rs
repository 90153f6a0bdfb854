//! Vehicle attitude and MAVLink frames (in progress, issue 3).
