//! `touchdown`: the host command-line tool (see `touchdown --help`; the logic is in the
//! library, `touchdown_cli`, so its unit tests drive it without a process).

fn main() -> std::process::ExitCode {
    touchdown_cli::main()
}
