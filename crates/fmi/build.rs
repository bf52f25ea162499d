// The FMI logger callback is variadic (printf-style); Rust cannot define one on stable, so
// the importer formats messages in a small C shim. Only the `import` feature needs it.
fn main() {
    #[cfg(feature = "import")]
    {
        println!("cargo:rerun-if-changed=src/import/logger_shim.c");
        cc::Build::new()
            .file("src/import/logger_shim.c")
            .warnings(true)
            .compile("twinbench_logger_shim");
    }
}
