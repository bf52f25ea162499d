//! FMU archives are untrusted input: every hostile archive is refused with a message naming
//! the file and the reason, before anything is written outside the cache or loaded.
//! The archives are built here from the packed `faulty` FMU with the `zip` crate.

mod common;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use tb_fmi::import::archive::Limits;
use tb_fmi::{FmuCache, FmuError};
use tb_testkit::assert_contains;
use zip::write::SimpleFileOptions;

/// The entries of the packed faulty FMU (name, content).
fn base_entries() -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(common::fmu("faulty")).unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    (0..zip.len())
        .map(|i| {
            let mut f = zip.by_index(i).unwrap();
            let mut data = Vec::new();
            f.read_to_end(&mut data).unwrap();
            (f.name().to_string(), data)
        })
        .collect()
}

fn model_description() -> String {
    let e = base_entries();
    let md = &e.iter().find(|e| e.0 == "modelDescription.xml").unwrap().1;
    String::from_utf8(md.clone()).unwrap()
}

/// Build an archive from entries, then let `extra` add hostile ones.
fn build(
    entries: &[(String, Vec<u8>)],
    extra: impl FnOnce(&mut zip::ZipWriter<std::io::Cursor<Vec<u8>>>),
) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opt = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, data) in entries {
        w.start_file(name.as_str(), opt).unwrap();
        w.write_all(data).unwrap();
    }
    extra(&mut w);
    w.finish().unwrap().into_inner()
}

/// The test FMU's archive with what `extra` adds is refused (default limits), saying `says`.
fn refused_with(
    name: &str,
    says: &str,
    extra: impl FnOnce(&mut zip::ZipWriter<std::io::Cursor<Vec<u8>>>),
) {
    let e = default_refused(name, &build(&base_entries(), extra));
    assert!(e.contains(says), "{name}: {e}");
}

/// The base entries with one replaced (or removed with `None`).
fn with_entry(name: &str, data: Option<Vec<u8>>) -> Vec<(String, Vec<u8>)> {
    let mut e: Vec<_> = base_entries().into_iter().filter(|e| e.0 != name).collect();
    if let Some(d) = data {
        e.push((name.to_string(), d));
    }
    e
}

/// A scratch folder: the hostile file, a persistent cache, and a place a zip-slip would hit.
struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Scratch {
        Scratch {
            dir: tempfile::tempdir().unwrap(),
        }
    }
    fn cache_dir(&self) -> PathBuf {
        // Deep enough that `../..` from an unpacked FMU stays inside the scratch folder.
        self.dir.path().join("a/b/cache")
    }

    /// Load `bytes` saved as `name`: the error text, after checking that nothing was
    /// extracted (the cache is empty, nothing appeared next to it) and nothing was loaded.
    fn refused(&self, name: &str, bytes: &[u8], limits: Limits) -> String {
        let fmu = self.dir.path().join(name);
        std::fs::write(&fmu, bytes).unwrap();
        let before = list(self.dir.path());
        let cache = FmuCache::persistent(&self.cache_dir())
            .unwrap()
            .with_limits(limits);
        let err = match cache.load(&fmu) {
            Ok(_) => panic!("{name} was accepted"),
            Err(e) => {
                // Refused as an archive or a description, of this file.
                assert!(
                    matches!(&e, FmuError::Archive { path, .. }
                        | FmuError::Description { path, .. }
                        | FmuError::DescriptionParse { path, .. } if *path == fmu),
                    "{name}: {e:?}"
                );
                e.to_string()
            }
        };
        assert!(
            err.contains(&fmu.display().to_string()),
            "the message does not name the file: {err}"
        );
        let after = list(self.dir.path());
        let cache_dir = self.cache_dir();
        let new: Vec<_> = after
            .iter()
            .filter(|p| !before.contains(p) && !cache_dir.starts_with(p))
            .collect();
        assert!(new.is_empty(), "{name}: files written: {new:?}");
        assert!(
            !mapped(&cache_dir),
            "{name}: a library under the cache is mapped"
        );
        err
    }
}

/// Every path under `dir`.
fn list(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p.clone());
            }
            out.push(p);
        }
    }
    out.sort();
    out
}

/// Whether this process maps a file under `dir` (a loaded library).
fn mapped(dir: &Path) -> bool {
    std::fs::read_to_string("/proc/self/maps")
        .unwrap()
        .contains(&dir.display().to_string())
}

fn default_refused(name: &str, bytes: &[u8]) -> String {
    Scratch::new().refused(name, bytes, Limits::default())
}

/// [`default_refused`] of the archive of `entries`.
fn refused_entries(name: &str, entries: &[(String, Vec<u8>)]) -> String {
    default_refused(name, &build(entries, |_| {}))
}

/// The test FMU's archive with `md` as its modelDescription.xml.
fn with_description(md: impl Into<Vec<u8>>) -> Vec<u8> {
    build(&with_entry("modelDescription.xml", Some(md.into())), |_| {})
}

#[test]
fn the_rebuilt_base_archive_loads() {
    // The control: the same construction without a hostile entry is accepted.
    let s = Scratch::new();
    let fmu = s.dir.path().join("ok.fmu");
    std::fs::write(&fmu, build(&base_entries(), |_| {})).unwrap();
    let cache = FmuCache::persistent(&s.cache_dir()).unwrap();
    let l = cache.load(&fmu).unwrap();
    assert_eq!(l.model_identifier(), "faulty");
    assert!(l.dir.starts_with(s.cache_dir()));
}

#[test]
fn zip_slip_with_parent_components_is_refused() {
    for evil in [
        "../../escaped.txt",
        "resources/../../../escaped.txt",
        "..\\..\\escaped.txt",
    ] {
        let bytes = build(&base_entries(), |w| {
            w.start_file(evil, SimpleFileOptions::default()).unwrap();
            w.write_all(b"owned").unwrap();
        });
        let e = default_refused("slip.fmu", &bytes);
        assert_contains(&e, &[&format!("entry '{evil}' escapes the archive")]);
    }
}

#[test]
fn absolute_entry_paths_are_refused() {
    let target = std::env::temp_dir().join(format!("tb-abs-{}.txt", std::process::id()));
    let name = target.display().to_string();
    let bytes = build(&base_entries(), |w| {
        w.start_file(name.as_str(), SimpleFileOptions::default())
            .unwrap();
        w.write_all(b"owned").unwrap();
    });
    let e = default_refused("absolute.fmu", &bytes);
    assert_contains(&e, &["escapes the archive (absolute path or '..')"]);
    assert!(!target.exists());
}

#[test]
fn symbolic_links_are_refused() {
    let says = "entry 'resources/passwd' is a symbolic link";
    refused_with("symlink.fmu", says, |w| {
        let o = SimpleFileOptions::default();
        w.add_symlink("resources/passwd", "/etc/passwd", o).unwrap();
    });
}

#[test]
fn too_many_entries_are_refused() {
    let says = "10003 entries, more than the limit of 10000";
    refused_with("many.fmu", says, |w| {
        let opt = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        for i in 0..tb_fmi::import::archive::MAX_ENTRIES {
            w.start_file(format!("resources/{i}"), opt).unwrap();
        }
    });
}

/// Overwrite the declared uncompressed size of `name` in the central directory and the
/// local header.
fn patch_declared_size(bytes: &mut [u8], name: &str, size: u32) {
    let mut patched = 0;
    for i in 0..bytes.len().saturating_sub(46) {
        // (name length at, name at, uncompressed size at)
        let (len_at, name_at, size_at) = match &bytes[i..i + 4] {
            b"PK\x01\x02" => (28, 46, 24),
            b"PK\x03\x04" => (26, 30, 22),
            _ => continue,
        };
        let n = u16::from_le_bytes([bytes[i + len_at], bytes[i + len_at + 1]]) as usize;
        if bytes.get(i + name_at..i + name_at + n) == Some(name.as_bytes()) {
            bytes[i + size_at..i + size_at + 4].copy_from_slice(&size.to_le_bytes());
            patched += 1;
        }
    }
    assert_eq!(patched, 2, "headers of {name} not found");
}

#[test]
fn a_declared_size_past_the_limit_is_refused_before_extraction() {
    let mut bytes = build(&base_entries(), |w| {
        let opt = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        w.start_file("resources/huge.bin", opt).unwrap();
        w.write_all(&[0u8; 16]).unwrap();
    });
    patch_declared_size(&mut bytes, "resources/huge.bin", 0xF000_0000);
    let e = default_refused("declared.fmu", &bytes);
    assert_contains(
        &e,
        &["uncompressed size exceeds the limit of 2147483648 bytes"],
    );
}

#[test]
fn a_lying_declared_size_is_caught_while_extracting_and_nothing_stays() {
    // 4 MB of zeros deflate to a few kB; the headers claim 10 bytes.
    let bytes = {
        let mut b = build(&base_entries(), |w| {
            w.start_file("resources/bomb.bin", SimpleFileOptions::default())
                .unwrap();
            w.write_all(&vec![0u8; 4 << 20]).unwrap();
        });
        patch_declared_size(&mut b, "resources/bomb.bin", 10);
        b
    };
    let limits = Limits {
        max_entries: 100,
        max_total_bytes: 2 << 20,
    };
    let s = Scratch::new();
    let e = s.refused("bomb.fmu", &bytes, limits);
    assert_contains(&e, &["uncompressed size exceeds the limit of 2097152 bytes while extracting 'resources/bomb.bin'"]);
    // The half-extracted folder was removed: the cache is empty.
    assert_eq!(list(&s.cache_dir()), Vec::<PathBuf>::new());
}

#[test]
fn a_missing_linux64_binary_is_refused() {
    let e = refused_entries(
        "nobinary.fmu",
        &with_entry("binaries/linux64/faulty.so", None),
    );
    assert_contains(&e, &["no binaries/linux64/faulty.so (the FMU has no binary for this platform; it has no binaries at all)"]);
    // Only a Windows binary.
    let mut entries = with_entry("binaries/linux64/faulty.so", None);
    entries.push(("binaries/win64/faulty.dll".into(), b"MZ".to_vec()));
    let e = refused_entries("win64only.fmu", &entries);
    assert_contains(
        &e,
        &["no binaries/linux64/faulty.so", "it has binaries for win64"],
    );
    // An empty linux64 folder beside a Windows binary: empty, not a binary for linux64.
    entries.push(("binaries/linux64/".into(), Vec::new()));
    let e = refused_entries("emptylinux.fmu", &entries);
    assert_contains(&e, &["no binaries/linux64/faulty.so (the folder binaries/linux64/ is empty (the FMU has binaries for win64))"]);
    // A library of another name there.
    let mut entries = with_entry("binaries/linux64/faulty.so", None);
    entries.push(("binaries/linux64/Faulty.so".into(), b"\x7fELF".to_vec()));
    let e = refused_entries("othername.fmu", &entries);
    assert_contains(&e, &["binaries/linux64/ holds Faulty.so but not the library its modelIdentifier \"faulty\" names"]);
}

#[test]
fn a_missing_model_description_is_refused() {
    let e = refused_entries("nomd.fmu", &with_entry("modelDescription.xml", None));
    assert_contains(&e, &["no modelDescription.xml at the archive's root"]);
    // One in a sub-folder does not count.
    let mut entries = with_entry("modelDescription.xml", None);
    entries.push((
        "sources/modelDescription.xml".into(),
        model_description().into_bytes(),
    ));
    let e = refused_entries("nestedmd.fmu", &entries);
    assert!(e.contains("no modelDescription.xml"), "{e}");
}

#[test]
fn a_non_utf8_model_description_is_refused() {
    let mut md = model_description().into_bytes();
    let at = md.len() / 2;
    md.splice(at..at, [0xFF, 0xFE]);
    let e = default_refused("latin.fmu", &with_description(md));
    assert!(e.contains("modelDescription.xml is not UTF-8 (byte"), "{e}");
}

#[test]
fn fmi_1_is_refused_with_its_version_and_3_0_is_read_as_3_0() {
    let md2 = model_description();
    {
        let v = "1.0";
        let md = md2.replace("fmiVersion=\"2.0\"", &format!("fmiVersion=\"{v}\""));
        let e = default_refused(&format!("fmi{v}.fmu"), &with_description(md));
        assert_contains(
            &e,
            &[&format!(
                "fmiVersion is \"{v}\"; twinbench runs FMI 2.0 and 3.0 FMUs"
            )],
        );
    }
    // A genuine FMI 3.0 description (different elements) says the same.
    let md3 = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="faulty" instantiationToken="{x}">
  <CoSimulation modelIdentifier="faulty"/>
  <ModelVariables><Float64 name="y" valueReference="1" causality="output"/></ModelVariables>
  <ModelStructure><Output valueReference="1"/></ModelStructure>
</fmiModelDescription>"#;
    let e = default_refused("fmi3.fmu", &with_description(md3));
    // Read as FMI 3.0: its library is looked for in the 3.0 platform folder.
    assert_contains(
        &e,
        &["no binaries/x86_64-linux/faulty.so", "binaries for linux64"],
    );
    // An FMI 2.0 description that only claims 3.0: its variables are not 3.0 elements.
    let claimed = md2.replace("fmiVersion=\"2.0\"", "fmiVersion=\"3.0\"");
    let e = default_refused("claims3.fmu", &with_description(claimed));
    assert_contains(&e, &["<ScalarVariable> is not an FMI 3.0 variable element"]);
    // FMI 1.0's CoSimulation_StandAlone description.
    let md1 = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="1.0" modelName="faulty" modelIdentifier="faulty" guid="{x}">
  <ModelVariables><ScalarVariable name="y" valueReference="1"><Real/></ScalarVariable></ModelVariables>
  <Implementation><CoSimulation_StandAlone><Capabilities/></CoSimulation_StandAlone></Implementation>
</fmiModelDescription>"#;
    let e = default_refused("fmi1.fmu", &with_description(md1));
    assert!(e.contains("fmiVersion is \"1.0\""), "{e}");
}

#[test]
fn an_fmi2_model_exchange_only_fmu_loads_and_a_library_without_its_functions_is_named() {
    // Model Exchange only: loaded (twinbench integrates it); a library that lacks the
    // Model Exchange functions (this one is a Co-Simulation library) is named with the
    // .fmu, its entry and the first missing function, when an instance needs it.
    let md = model_description().replace("CoSimulation", "ModelExchange");
    let s = Scratch::new();
    let fmu = s.dir.path().join("me.fmu");
    std::fs::write(&fmu, with_description(md)).unwrap();
    let cache = FmuCache::persistent(&s.cache_dir()).unwrap();
    let l = cache.load(&fmu).unwrap();
    assert_eq!(l.default_interface(), tb_fmi::Interface::ModelExchange);
    assert_eq!(l.model_identifier(), "faulty");
    let e = l.library_me().err().unwrap();
    assert!(
        matches!(&e, FmuError::Archive { path, .. } if *path == fmu),
        "{e}"
    );
    assert_contains(&e.to_string(), &["me.fmu: binaries/linux64/faulty.so does not export the required FMI 2.0 Model Exchange function fmi2EnterEventMode"]);
    let e = l
        .check_interface(tb_fmi::Interface::CoSimulation)
        .unwrap_err();
    assert!(
        matches!(
            &e,
            tb_fmi::import::InterfaceError::NotDeclared { element: "CoSimulation", supported }
                if supported == &["model-exchange"]
        ),
        "{e}"
    );
}

#[test]
fn a_model_identifier_that_is_a_path_is_refused() {
    for id in ["../../../tmp/evil", "/tmp/evil", "a b", ""] {
        let md = model_description().replace(
            "modelIdentifier=\"faulty\"",
            &format!("modelIdentifier=\"{id}\""),
        );
        let mut entries = with_entry("modelDescription.xml", Some(md.into_bytes()));
        entries.push((format!("binaries/linux64/{id}.so"), b"x".to_vec()));
        let e = refused_entries("id.fmu", &entries);
        assert!(
            e.contains(&format!(
                "modelIdentifier \"{id}\" is not a valid C identifier"
            )) || e.contains("escapes the archive"),
            "{e}"
        );
    }
}

#[test]
fn not_a_zip_and_truncated_archives_are_refused() {
    let e = default_refused("text.fmu", b"this is not a zip archive");
    assert!(e.contains("not a valid zip archive"), "{e}");
    let full = build(&base_entries(), |_| {});
    let e = default_refused("truncated.fmu", &full[..full.len() / 2]);
    assert!(e.contains("not a valid zip archive"), "{e}");
}

#[test]
fn a_fifo_or_a_device_given_as_an_fmu_is_refused_without_reading_it() {
    // A FIFO would block the read forever, /dev/zero would fill the memory.
    let s = Scratch::new();
    let fifo = s.dir.path().join("pipe.fmu");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let cache = FmuCache::persistent(&s.cache_dir()).unwrap();
    for path in [fifo.as_path(), Path::new("/dev/zero")] {
        let err = cache.load(path).err().expect("refused");
        assert!(
            matches!(&err, FmuError::Archive { path: p, .. } if p == path),
            "{err}"
        );
        assert_contains(
            &err.to_string(),
            &[
                &path.display().to_string(),
                "not a regular file (an FMU is a zip archive)",
            ],
        );
    }
}

#[test]
fn a_model_description_over_64_mib_is_an_error_not_cut() {
    // Valid XML padded past the limit (it compresses to almost nothing): an error that says
    // so, not an XML syntax error at the cut.
    let md = model_description();
    let padded = md.replacen(
        "<ModelVariables>",
        &format!("<ModelVariables>{}", " ".repeat(64 << 20)),
        1,
    );
    let bytes = with_description(padded);
    let err = default_refused("huge_md.fmu", &bytes);
    assert_contains(&err, &["modelDescription.xml is larger than 64 MiB"]);
}

#[test]
fn a_broken_or_foreign_binary_is_named_by_the_fmu_and_its_entry() {
    let so = "binaries/linux64/faulty.so";
    let real = base_entries().into_iter().find(|e| e.0 == so).unwrap().1;
    // Not an ELF file, a 32-bit ELF (the class byte of the real one flipped), and a
    // library for aarch64 (its machine field changed; red team N28: the loader said "No
    // such file or directory").
    let mut elf32 = real.clone();
    elf32[4] = 1;
    let mut aarch64 = real.clone();
    aarch64[18..20].copy_from_slice(&183u16.to_le_bytes());
    for (name, binary, expected) in [
        ("garbage.fmu", vec![b'x'; 4096], "not an ELF shared library"),
        (
            "elf32.fmu",
            elf32,
            "a library for x86-64 but not 64-bit little-endian (ELF machine 62)",
        ),
        (
            "aarch64.fmu",
            aarch64,
            "a library for aarch64 (ELF machine 183)",
        ),
    ] {
        let s = Scratch::new();
        let fmu = s.dir.path().join(name);
        std::fs::write(&fmu, build(&with_entry(so, Some(binary)), |_| {})).unwrap();
        let cache = FmuCache::persistent(&s.cache_dir()).unwrap();
        // Reading the archive runs no code: it loads; the library fails when first needed.
        let loaded = cache.load(&fmu).unwrap();
        let err = loaded.library().err().expect("refused");
        assert!(
            matches!(&err, FmuError::Load { path, .. } if *path == fmu),
            "{err}"
        );
        assert_contains(
            &err.to_string(),
            &[
                &format!("{}: cannot load shared library: {so}: ", fmu.display()),
                expected,
            ],
        );
        assert!(
            !err.to_string()
                .contains(&s.cache_dir().display().to_string()),
            "the message names the unpacked copy: {err}"
        );
    }
}
