//! The `twinbench` command line: a thin shell over the library.

mod interpose;

fn main() -> std::process::ExitCode {
    interpose::install();
    twinbench::cli::main()
}
