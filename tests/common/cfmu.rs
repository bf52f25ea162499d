//! Test FMUs written in C (`tests/cfmus/<name>.c` with its `<name>.xml`), built here with gcc
//! into `target/c-fmus/<name>.fmu` (FMI 2.0, linux64): supplier FMUs with the features
//! other tools' FMUs have and ours do not (value references shared across types, alias
//! sets, an internal variable-step solver), sharing `fmi2_common.h`. Rebuilt when a source is
//! newer than the FMU; a lock serialises test binaries that build at the same time.

use std::io::Write;
use std::path::PathBuf;
use std::process::Command;

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
    let lock = std::fs::File::create(out.join(".lock")).unwrap();
    use std::os::fd::AsRawFd;
    assert_eq!(unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX) }, 0);
    // The header the sources share counts too.
    let newest = [&c, &xml, &src.join("fmi2_common.h")]
        .iter()
        .map(|p| std::fs::metadata(p).and_then(|m| m.modified()).unwrap())
        .max()
        .unwrap();
    if std::fs::metadata(&fmu)
        .and_then(|m| m.modified())
        .is_ok_and(|t| t >= newest)
    {
        return fmu;
    }
    let so = out.join(format!("{name}.so"));
    let built = Command::new("gcc")
        .args(["-shared", "-fPIC", "-O2", "-Wall", "-Werror", "-o"])
        .arg(&so)
        .arg(&c)
        .arg("-lm")
        .output()
        .expect("gcc runs");
    assert!(
        built.status.success(),
        "gcc {name}: {}",
        String::from_utf8_lossy(&built.stderr)
    );
    let tmp = out.join(format!(".{name}.fmu.tmp"));
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&tmp).unwrap());
    let o = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("modelDescription.xml", o).unwrap();
    zip.write_all(&std::fs::read(&xml).unwrap()).unwrap();
    zip.start_file(format!("binaries/linux64/{name}.so"), o)
        .unwrap();
    zip.write_all(&std::fs::read(&so).unwrap()).unwrap();
    zip.finish().unwrap();
    std::fs::rename(&tmp, &fmu).unwrap();
    std::fs::remove_file(&so).unwrap();
    fmu
}
