//! The archive's tests: the loader's messages, the checks, the store.

use super::*;
use crate::import::manifest;
use crate::import::store::{self, IndexEntry};

mod load_messages {
    use super::*;

    #[test]
    fn a_missing_dependency_is_named_not_the_fmus_own_library() {
        let path = Path::new("/store/ab12/binaries/linux64/Model.so");
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: libSimulationRuntimeC.so: cannot open shared object file: No such file or directory",
        );
        assert!(
            m.starts_with("binaries/linux64/Model.so needs the library libSimulationRuntimeC.so, which cannot be loaded: cannot open shared object file"),
            "{m}"
        );
        // The library itself missing or broken: its own name and the reason.
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: cannot open shared object file: No such file or directory",
        );
        assert_eq!(
            m,
            "binaries/linux64/Model.so: cannot open shared object file: No such file or directory"
        );
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: undefined symbol: foo",
        );
        assert_eq!(m, "binaries/linux64/Model.so: undefined symbol: foo");
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: libgfortran.so.3: cannot open shared object file: No such file or directory",
        );
        assert!(m.contains("needs the library libgfortran.so.3,"), "{m}");
    }
}

mod cache_and_checks {
    use super::*;
    use std::io::Write;

    /// A small FMU whose description's `description` attribute is `tag` (keep the length
    /// for a rewrite of the same size).
    fn fmu_bytes(tag: &str) -> Vec<u8> {
        fmu_bytes_with(tag, true)
    }

    /// [`fmu_bytes`], with or without its binary.
    fn fmu_bytes_with(tag: &str, binary: bool) -> Vec<u8> {
        let md = format!(
            r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{{g}}" description="{tag}">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables>
    <ScalarVariable name="y" valueReference="1" causality="output" initial="calculated"><Real/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs><InitialUnknowns><Unknown index="1"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>"#
        );
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        // Stored and with a fixed time: a rewrite with an equal-length tag is the same size.
        let opt = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .last_modified_time(zip::DateTime::default());
        for (name, data) in [
            ("modelDescription.xml", md.as_bytes()),
            (
                "binaries/linux64/m.so",
                b"not loaded by these tests".as_slice(),
            ),
            ("resources/data.txt", tag.as_bytes()),
        ] {
            if name.starts_with("binaries/") && !binary {
                continue;
            }
            w.start_file(name, opt).unwrap();
            w.write_all(data).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    struct Scratch {
        dir: store::TestDir,
    }

    impl Scratch {
        fn new() -> Scratch {
            Scratch {
                dir: store::TestDir::new(),
            }
        }
        fn store(&self) -> PathBuf {
            self.dir.path().join("store")
        }
        /// A cache as a new process has it: nothing loaded, the shared store.
        fn cache(&self) -> FmuCache {
            FmuCache::with_store(&self.dir.path().join("root"), &self.store()).unwrap()
        }
        fn fmu(&self, tag: &str) -> PathBuf {
            let p = self.dir.path().join("m.fmu");
            std::fs::write(&p, fmu_bytes(tag)).unwrap();
            p
        }
        fn index_entries(&self) -> usize {
            std::fs::read_dir(self.store().join(store::INDEX_DIR))
                .map_or(0, |d| d.flatten().count())
        }
    }

    fn stats(index_hits: usize, archives_read: usize, extractions: usize) -> CacheStats {
        CacheStats {
            index_hits,
            archives_read,
            extractions,
        }
    }

    /// Sets a file's mtime (and atime) to the given one.
    fn set_mtime(path: &Path, mtime: std::time::SystemTime) {
        std::fs::File::options()
            .write(true)
            .open(path)
            .unwrap()
            .set_times(
                std::fs::FileTimes::new()
                    .set_modified(mtime)
                    .set_accessed(mtime),
            )
            .unwrap();
    }

    #[test]
    fn a_second_process_finds_the_fmu_through_the_index_without_reading_the_archive() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let a = s.cache();
        let la = a.load(&fmu).unwrap();
        assert_eq!(a.stats(), stats(0, 1, 1));
        assert_eq!(s.index_entries(), 1);
        // In-process, the same path again: through the index too.
        let again = a.load(&fmu).unwrap();
        assert!(Arc::ptr_eq(&la, &again));
        assert_eq!(a.stats(), stats(1, 1, 1));
        let b = s.cache();
        let lb = b.load(&fmu).unwrap();
        assert_eq!(b.stats(), stats(1, 0, 0));
        assert_eq!((&lb.dir, &lb.sha256), (&la.dir, &la.sha256));
        assert_eq!(lb.description.description, "first");
        assert_eq!(lb.source, fmu);
    }

    #[test]
    fn a_temporary_cache_on_a_store_removes_its_folder_and_keeps_the_store() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let cache = FmuCache::temporary_with_store(&s.store()).unwrap();
        let root = cache.root().to_path_buf();
        let l = cache.load(&fmu).unwrap();
        assert!(l.dir.starts_with(s.store()));
        assert!(root.is_dir());
        drop(cache);
        assert!(!root.exists());
        assert!(l.dir.join(".complete").is_file());
        assert!(l.dir.join("binaries/linux64/m.so").is_file());
    }

    #[test]
    fn a_rewrite_in_place_under_a_forged_stat_is_caught_by_the_central_directory() {
        // The stat key cannot match after a rewrite (the ctime changes); forge the index
        // entry of the rewritten file from the old one, so that only the central directory
        // check stands between the new bytes and the old unpacked folder.
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let mtime = std::fs::metadata(&fmu).unwrap().modified().unwrap();
        let old = s.cache().load(&fmu).unwrap();
        let old_key = store::index_key(
            &std::fs::canonicalize(&fmu).unwrap(),
            &std::fs::metadata(&fmu).unwrap(),
        );
        let old_entry = store::read_entry(&s.store(), &old_key).unwrap();
        let size = std::fs::metadata(&fmu).unwrap().len();
        std::fs::write(&fmu, fmu_bytes("secnd")).unwrap();
        set_mtime(&fmu, mtime);
        let meta = std::fs::metadata(&fmu).unwrap();
        assert_eq!((meta.len(), meta.modified().unwrap()), (size, mtime));
        let new_key = store::index_key(&std::fs::canonicalize(&fmu).unwrap(), &meta);
        store::write_entry(
            &s.store(),
            &IndexEntry {
                key: new_key.clone(),
                ..old_entry
            },
        )
        .unwrap();
        let cache = s.cache();
        let new = cache.load(&fmu).unwrap();
        assert_eq!(cache.stats(), stats(0, 1, 1));
        assert_eq!(new.description.description, "secnd");
        assert_ne!(new.dir, old.dir);
        assert_eq!(
            std::fs::read_to_string(new.dir.join("resources/data.txt")).unwrap(),
            "secnd"
        );
        // The entry was rewritten: the next process hits it.
        assert_eq!(
            store::read_entry(&s.store(), &new_key).unwrap().sha256,
            new.sha256
        );
        let next = s.cache();
        assert_eq!(next.load(&fmu).unwrap().dir, new.dir);
        assert_eq!(next.stats(), stats(1, 0, 0));
    }

    #[test]
    fn a_damaged_index_or_an_incomplete_folder_takes_the_full_path() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let entry_file = std::fs::read_dir(s.store().join(store::INDEX_DIR))
            .unwrap()
            .flatten()
            .next()
            .unwrap()
            .path();
        // A damaged entry: read again, not unpacked again, the entry rewritten.
        std::fs::write(&entry_file, b"twinbench-unpack-index 1\nkey zz\n").unwrap();
        let c = s.cache();
        assert_eq!(c.load(&fmu).unwrap().dir, first.dir);
        assert_eq!(c.stats(), stats(0, 1, 0));
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        // A folder without `.complete` (emptied behind its back): unpacked again in its place.
        std::fs::remove_file(first.dir.join(".complete")).unwrap();
        std::fs::remove_file(first.dir.join("binaries/linux64/m.so")).unwrap();
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert_eq!(l.dir, first.dir);
        assert!(l.dir.join("binaries/linux64/m.so").is_file());
        // An unpacked description that is not the manifest's: the full path, which finds
        // the folder damaged and unpacks it again.
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        let md = l.dir.join("modelDescription.xml");
        let good = std::fs::read(&md).unwrap();
        std::fs::write(&md, b"<not xml").unwrap();
        let c = s.cache();
        let e = c.load(&fmu).err();
        assert!(e.is_none(), "{e:?}");
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert_eq!(std::fs::read(&md).unwrap(), good);
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        // No temporaries left in the store.
        let names: Vec<String> = std::fs::read_dir(s.store())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
    }

    /// The library's store copy with one byte changed, its size kept.
    fn flip_a_byte(path: &Path) {
        use std::os::unix::fs::PermissionsExt;
        let mut bytes = std::fs::read(path).unwrap();
        bytes[3] ^= 0x20;
        let mode = std::fs::metadata(path).unwrap().permissions().mode();
        std::fs::write(path, &bytes).unwrap();
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn n03_a_changed_byte_in_the_stores_library_is_found_before_loading_and_repaired() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let so = first.library_path();
        let good = std::fs::read(&so).unwrap();
        assert!(first.checked_library().is_ok());
        flip_a_byte(&so);
        // A later process: the index still hits (nothing of the archive changed), and the
        // library is verified before anything could load it.
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        let checked = l.checked_library().unwrap();
        assert_eq!(checked.path(), so);
        assert_eq!(std::fs::read(&so).unwrap(), good);
        checked.verify().unwrap();
        // A resource changed: not read by the host (the FMU reads it), found by a full
        // verification (a remote worker's) and repaired too.
        let data = l.dir.join("resources/data.txt");
        flip_a_byte(&data);
        let l = s.cache().load(&fmu).unwrap();
        l.verify_all().unwrap();
        assert_eq!(std::fs::read_to_string(&data).unwrap(), "first");
    }

    #[test]
    fn n19_a_complete_folder_without_its_library_is_unpacked_again() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        std::fs::remove_file(first.library_path()).unwrap();
        // After deleting the index and touching the FMU too: the full path finds the folder
        // complete, and the library is missing when it is checked.
        std::fs::remove_dir_all(s.store().join(store::INDEX_DIR)).unwrap();
        set_mtime(&fmu, std::time::SystemTime::now());
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 0));
        l.checked_library().unwrap();
        assert!(l.library_path().is_file());
        // The manifest gone: the folder is not used as it is, but unpacked again.
        std::fs::remove_file(l.dir.join(manifest::MANIFEST)).unwrap();
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert!(l.dir.join(manifest::MANIFEST).is_file());
    }

    #[test]
    fn n27_folders_and_files_anyone_else_can_write_are_not_used() {
        use std::os::unix::fs::PermissionsExt;
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode(&first.dir), 0o700);
        assert_eq!(mode(&first.dir.join("binaries/linux64")), 0o700);
        assert_eq!(mode(&first.library_path()), 0o700);
        assert_eq!(mode(&first.dir.join("modelDescription.xml")), 0o600);
        assert_eq!(mode(&s.store().join(store::INDEX_DIR)), 0o700);
        // A folder on the way to the library that others can write: repaired, not used.
        let linux64 = first.dir.join("binaries/linux64");
        std::fs::set_permissions(&linux64, std::fs::Permissions::from_mode(0o777)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        l.checked_library().unwrap();
        assert_eq!(mode(&linux64), 0o700);
        // The library itself group-writable: the same.
        let so = l.library_path();
        std::fs::set_permissions(&so, std::fs::Permissions::from_mode(0o770)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        l.checked_library().unwrap();
        assert_eq!(mode(&so), 0o700);
        // The store's own folder: no repair can help, the library is refused with the path
        // and the mode.
        std::fs::set_permissions(s.store(), std::fs::Permissions::from_mode(0o775)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        let e = l.checked_library().unwrap_err();
        assert!(
            matches!(&e, FmuError::Archive { path, .. } if *path == fmu),
            "{e}"
        );
        assert!(
            e.to_string().contains(&format!(
                "{}: mode 775: group or others can write it",
                s.store().display()
            )),
            "{e}"
        );
    }

    #[test]
    fn a_hit_still_applies_this_caches_limits() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        s.cache().load(&fmu).unwrap();
        let few = s.cache().with_limits(Limits {
            max_entries: 2,
            max_total_bytes: MAX_TOTAL_BYTES,
        });
        let e = few.load(&fmu).err().expect("refused");
        assert!(
            matches!(&e, FmuError::Archive { path, .. } if *path == fmu),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("3 entries, more than the limit of 2"),
            "{e}"
        );
        assert_eq!(few.stats(), stats(0, 1, 0));
    }

    #[test]
    fn another_file_with_the_same_content_shares_the_folder_with_an_entry_of_its_own() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let copy = s.dir.path().join("copy.fmu");
        std::fs::copy(&fmu, &copy).unwrap();
        let a = s.cache().load(&fmu).unwrap();
        let c = s.cache();
        let b = c.load(&copy).unwrap();
        assert_eq!(a.dir, b.dir);
        assert_eq!(c.stats(), stats(0, 1, 0));
        assert_eq!(s.index_entries(), 2);
    }

    #[test]
    fn only_a_description_only_cache_takes_an_fmu_without_a_binary() {
        let s = Scratch::new();
        let fmu = s.dir.path().join("m.fmu");
        std::fs::write(&fmu, fmu_bytes_with("first", false)).unwrap();
        let refused = |c: &FmuCache| {
            let e = c.load(&fmu).err().expect("refused");
            assert!(
                matches!(&e, FmuError::Archive { path, .. } if *path == fmu),
                "{e}"
            );
            assert!(
                e.to_string().contains("no binaries/linux64/m.so (the FMU has no binary for this platform; it has no binaries at all)"),
                "{e}"
            );
        };
        refused(&s.cache());
        let l = s.cache().description_only().load(&fmu).unwrap();
        assert_eq!(l.description.model_name, "m");
        // Its library is not there to load, and the error says which.
        let e = l.library().err().expect("no library");
        assert!(
            matches!(&e, FmuError::Load { path, .. } if *path == fmu),
            "{e}"
        );
        assert!(e.to_string().contains("binaries/linux64/m.so"), "{e}");
        // The store now indexes it: an ordinary cache on the same store still refuses it.
        assert_eq!(s.index_entries(), 1);
        refused(&s.cache());
    }
}
