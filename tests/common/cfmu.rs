//! Test FMUs written in C (`tests/cfmus/<name>.c` with its `<name>.xml`), built here with gcc
//! into `target/c-fmus/<name>.fmu` (FMI 2.0, linux64): supplier FMUs with the features
//! other tools' FMUs have and ours do not (value references shared across types, alias
//! sets, an internal variable-step solver), sharing `fmi2_common.h`. Rebuilt when a source is
//! newer than the FMU; a lock serialises test binaries that build at the same time.

use super::build;
use crate::args;
use std::path::PathBuf;

/// `<name>.fmu` built from `tests/cfmus/<name>.c` and `.xml` (the model identifier is the
/// name).
pub fn fmu(name: &str) -> PathBuf {
    let root = twinbench::pack::workspace_root();
    let src = root.join("tests/cfmus");
    let (c, xml) = (
        src.join(format!("{name}.c")),
        src.join(format!("{name}.xml")),
    );
    let out = root.join("target/c-fmus");
    std::fs::create_dir_all(&out).unwrap();
    let fmu = out.join(format!("{name}.fmu"));
    let _lock = build::lock(&out);
    // The header the sources share counts too.
    if build::up_to_date(&fmu, &[&c, &xml, &src.join("fmi2_common.h")]) {
        return fmu;
    }
    let so = out.join(format!("{name}.so"));
    build::gcc(
        args!["-shared", "-fPIC", "-O2", "-Wall", "-Werror", "-o", so, c, "-lm"],
        name,
    );
    let tmp = out.join(format!(".{name}.fmu.tmp"));
    let (md, library) = (std::fs::read(&xml).unwrap(), std::fs::read(&so).unwrap());
    let library_entry = format!("binaries/linux64/{name}.so");
    build::zip(
        &tmp,
        &[("modelDescription.xml", &md), (&library_entry, &library)],
    );
    std::fs::rename(&tmp, &fmu).unwrap();
    std::fs::remove_file(&so).unwrap();
    fmu
}
