//! `touchdown`: the host command-line tool (see `touchdown --help`; the logic is in
//! `touchdown_host::cli` so tests can drive it without a process).

fn main() -> std::process::ExitCode {
    touchdown_host::cli::main()
}
