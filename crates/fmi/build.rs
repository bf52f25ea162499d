// The FMI logger callback is variadic (printf-style); Rust cannot define one on stable, so
// the importer formats messages in a small C shim. Only the `import` feature needs it.
//
// The importer also integrates Model Exchange FMUs with SUNDIALS CVODE: Debian's
// `libsundials-dev` (6.4.1), linked statically (its archive is position-independent), so
// that the binaries and the Python module need no SUNDIALS library at run time.
fn main() {
    #[cfg(feature = "import")]
    {
        println!("cargo:rerun-if-changed=src/import/logger_shim.c");
        cc::Build::new()
            .file("src/import/logger_shim.c")
            .warnings(true)
            .compile("twinbench_logger_shim");
        link_cvode();
    }
}

#[cfg(feature = "import")]
fn link_cvode() {
    println!("cargo:rerun-if-env-changed=TWINBENCH_SUNDIALS_LIB");
    let dirs: Vec<std::path::PathBuf> = match std::env::var_os("TWINBENCH_SUNDIALS_LIB") {
        Some(d) => vec![d.into()],
        None => [
            "/usr/lib/x86_64-linux-gnu",
            "/usr/lib64",
            "/usr/lib",
            "/usr/local/lib",
        ]
        .iter()
        .map(std::path::PathBuf::from)
        .collect(),
    };
    let Some(dir) = dirs
        .iter()
        .find(|d| d.join("libsundials_cvode.a").is_file())
    else {
        panic!(
            "SUNDIALS CVODE (libsundials_cvode.a) not found in {}: install it with `apt-get install libsundials-dev` (Debian 12: SUNDIALS 6.4.1), or set TWINBENCH_SUNDIALS_LIB to the folder that holds it",
            dirs.iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    println!(
        "cargo:rerun-if-changed={}",
        dir.join("libsundials_cvode.a").display()
    );
    println!("cargo:rustc-link-search=native={}", dir.display());
    println!("cargo:rustc-link-lib=static=sundials_cvode");
}
