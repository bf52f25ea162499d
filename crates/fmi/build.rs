// The FMI logger callback is variadic (printf-style); Rust cannot define one on stable, so
// the importer formats messages in a small C shim. Only the `import` feature needs it.
//
// The importer also integrates Model Exchange FMUs with SUNDIALS CVODE 6, linked statically
// (Debian's `libsundials-dev` 6.4.1: its archive is position-independent), so that the
// binaries and the Python module need no SUNDIALS library at run time. CVODE is optional:
// without it the build says so in one warning and compiles everything else; a Model
// Exchange FMU is then refused at load with what to install (`cfg(tb_cvode)` marks a build
// with it). A SUNDIALS that does not match the binding (another major version, not double
// precision, another index size) is refused with one line.
fn main() {
    println!("cargo:rustc-check-cfg=cfg(tb_cvode)");
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

/// What the binding in `src/import/model_exchange/cvode.rs` assumes of SUNDIALS.
#[cfg(feature = "import")]
const EXPECTED: [(&str, &str); 3] = [
    ("SUNDIALS_VERSION_MAJOR", "6"),
    ("SUNDIALS_DOUBLE_PRECISION", "1"),
    // `sunindextype`: the binding's `SunIndex` is i64.
    ("SUNDIALS_INDEX_TYPE", "int64_t"),
];

#[cfg(feature = "import")]
fn link_cvode() {
    use std::path::PathBuf;
    println!("cargo:rerun-if-env-changed=TWINBENCH_SUNDIALS_LIB");
    println!("cargo:rerun-if-env-changed=TWINBENCH_SUNDIALS_INCLUDE");
    let multiarch = format!(
        "/usr/lib/{}-linux-gnu",
        std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default()
    );
    let dirs: Vec<PathBuf> = match std::env::var_os("TWINBENCH_SUNDIALS_LIB") {
        Some(d) => vec![d.into()],
        None => [
            multiarch.as_str(),
            "/usr/lib64",
            "/usr/lib",
            "/usr/local/lib",
            "/usr/local/lib64",
        ]
        .iter()
        .map(PathBuf::from)
        .collect(),
    };
    let found = dirs
        .iter()
        .find(|d| d.join("libsundials_cvode.a").is_file());
    // Watched: the library found, or else every place it may be installed later (found by
    // the next build). Never a missing path beside a found library: Cargo takes a missing
    // path as changed, and would rebuild this crate and all above it every time.
    for d in found
        .into_iter()
        .chain(if found.is_none() { &dirs[..] } else { &[] })
    {
        println!(
            "cargo:rerun-if-changed={}",
            d.join("libsundials_cvode.a").display()
        );
    }
    let Some(dir) = found else {
        println!(
            "cargo:warning=SUNDIALS CVODE (libsundials_cvode.a) not found in {}: twinbench is built without Model Exchange (Co-Simulation is unaffected); for it install libsundials-dev (apt-get install libsundials-dev) or set TWINBENCH_SUNDIALS_LIB, then rebuild",
            dirs.iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        return;
    };
    // The header beside the library: <prefix>/include for <prefix>/lib[/<multiarch>].
    let headers: Vec<PathBuf> = match std::env::var_os("TWINBENCH_SUNDIALS_INCLUDE") {
        Some(d) => vec![PathBuf::from(d)],
        None => dir
            .ancestors()
            .skip(1)
            .take(2)
            .map(|p| p.join("include"))
            .collect(),
    };
    let Some(config) = headers
        .iter()
        .map(|d| d.join("sundials/sundials_config.h"))
        .find(|h| h.is_file())
    else {
        fail(&format!(
            "SUNDIALS CVODE found in {} but not its sundials/sundials_config.h (looked in {}): set TWINBENCH_SUNDIALS_INCLUDE to its include folder",
            dir.display(),
            headers
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    };
    println!("cargo:rerun-if-changed={}", config.display());
    let text = std::fs::read_to_string(&config).unwrap_or_default();
    if let Err(why) = check_config(&text) {
        fail(&format!(
            "SUNDIALS in {} does not match twinbench's CVODE binding: {why} (twinbench needs SUNDIALS 6.x, double precision, 64-bit index, e.g. Debian 12's libsundials-dev 6.4.1); set TWINBENCH_SUNDIALS_LIB to another one, or to a folder without it to build without Model Exchange",
            config.display()
        ));
    }
    println!("cargo:rustc-link-search=native={}", dir.display());
    println!("cargo:rustc-link-lib=static=sundials_cvode");
    println!("cargo:rustc-cfg=tb_cvode");
}

/// A definition of `sundials_config.h` that is not what the binding assumes (a build script
/// has no thiserror: its Display by hand).
#[cfg(feature = "import")]
struct Mismatch {
    name: &'static str,
    /// The defined value; `None` when the name is not defined.
    found: Option<String>,
    expected: &'static str,
}

#[cfg(feature = "import")]
impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (name, expected) = (self.name, self.expected);
        match &self.found {
            Some(v) => write!(f, "{name} is {v}, expected {expected}"),
            None => write!(f, "{name} is not defined, expected {expected}"),
        }
    }
}

/// `Err(what differs)` when `sundials_config.h` is not what the binding assumes.
#[cfg(feature = "import")]
fn check_config(text: &str) -> Result<(), Mismatch> {
    let define = |name: &str| {
        text.lines().find_map(|l| {
            let mut w = l.split_whitespace();
            (w.next() == Some("#define") && w.next() == Some(name))
                .then(|| w.next().unwrap_or("").trim_matches('"').to_string())
        })
    };
    for (name, want) in EXPECTED {
        match define(name) {
            Some(v) if v == want => {}
            found => {
                return Err(Mismatch {
                    name,
                    found,
                    expected: want,
                })
            }
        }
    }
    Ok(())
}

/// Stop the build with one line (no backtrace).
#[cfg(feature = "import")]
fn fail(line: &str) -> ! {
    eprintln!("error: {line}");
    std::process::exit(1)
}
