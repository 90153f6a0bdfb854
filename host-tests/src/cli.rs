//! The `touchdown` command-line tool (subcommands; in progress).
