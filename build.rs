// The FMI logger callback is variadic: a small C shim formats messages for the importer.
fn main() {
    println!("cargo:rerun-if-changed=src/fmu/logger_shim.c");
    cc::Build::new()
        .file("src/fmu/logger_shim.c")
        .warnings(true)
        .compile("twinbench_logger_shim");
}
