//! Landing pad layouts (in progress, issue 3).
