//! The `twinbench` command line: a thin shell over the library.

fn main() -> std::process::ExitCode {
    twinbench::cli::main()
}
