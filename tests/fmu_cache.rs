//! The unpack cache under concurrent loads: threads of one process share one cache, and
//! processes (several caches) share one folder. Every load succeeds, each content is
//! unpacked into one folder, and nothing half-unpacked stays behind.
//! The store of unpacked FMUs shared by processes: a second process finds an unchanged FMU
//! through the stat index, a rewritten one is read anew.

mod common;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Barrier};
use tb_fmi::import::archive::CacheStats;
use tb_fmi::FmuCache;

/// The cache folder's entries: unpacked FMUs (and, if the race were back, temporaries);
/// not the stat index's folder.
fn entries(root: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != "index")
        .collect();
    v.sort();
    v
}

/// Eight threads, each `prepare`s, waits for the others, then `act`s on what it prepared:
/// what they acted to, in thread order.
fn eight_at_once<P, T: Send>(
    prepare: impl Fn() -> P + Sync,
    act: impl Fn(P) -> T + Sync,
) -> Vec<T> {
    let barrier = Barrier::new(8);
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|_| {
                s.spawn(|| {
                    let p = prepare();
                    barrier.wait();
                    act(p)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

/// `round(k, cache)` for each k of `0..rounds`, each with a cache folder of its own.
fn in_fresh_folders(rounds: usize, tag: &str, round: impl Fn(usize, &Path)) {
    for k in 0..rounds {
        let dir = tb_testkit::scratch(tag);
        round(k, &dir.path().join("cache"));
    }
}

#[test]
fn eight_threads_load_the_same_fmu_into_one_cache_a_hundred_times() {
    let fmu = common::fmu("faulty");
    in_fresh_folders(100, "cache-race", |round, root| {
        let cache = FmuCache::persistent(root).unwrap();
        let loaded = eight_at_once(|| (), |()| cache.load(&fmu));
        let loaded: Vec<_> = loaded
            .into_iter()
            .map(|r| r.unwrap_or_else(|e| panic!("round {round}: {e}")))
            .collect();
        // One load: every thread got the same unpacked FMU.
        assert!(
            loaded.iter().all(|l| Arc::ptr_eq(l, &loaded[0])),
            "round {round}: several loads of one content"
        );
        let e = entries(root);
        assert_eq!(e.len(), 1, "round {round}: {e:?}");
        assert!(!e[0].contains("tmp"), "round {round}: {e:?}");
        assert!(loaded[0].dir.join(".complete").exists());
    });
}

#[test]
fn caches_of_several_processes_share_one_folder_without_losing_an_unpacking() {
    // Eight caches on one folder stand for eight processes: one unpacks (the store's
    // unpack lock), the others wait and use its folder; none unpacks a copy of its own
    // (eight used to, briefly taking several times the FMU's size on disk).
    let fmu = common::fmu("faulty");
    in_fresh_folders(20, "cache-procs", |round, root| {
        let dirs = eight_at_once(
            || FmuCache::persistent(root).unwrap(),
            |cache| {
                let l = cache
                    .load(&fmu)
                    .unwrap_or_else(|e| panic!("round {round}: {e}"));
                (l.dir.clone(), cache.stats().extractions)
            },
        );
        let unpackings: usize = dirs.iter().map(|d| d.1).sum();
        assert_eq!(unpackings, 1, "round {round}");
        let dirs: Vec<PathBuf> = dirs.into_iter().map(|d| d.0).collect();
        assert!(dirs.iter().all(|d| *d == dirs[0]), "round {round}");
        let e = entries(root);
        assert_eq!(e.len(), 1, "round {round}: {e:?}");
        assert!(dirs[0].join(".complete").exists());
    });
}

/// The faulty FMU rebuilt stored (not deflated) with a fixed time, its GUID's first digit
/// replaced by `digit`: rebuilds with two digits have the same size and differ in the
/// description's bytes (and so in its CRC).
fn faulty_with_guid_digit(digit: char) -> (Vec<u8>, String) {
    let bytes = std::fs::read(common::fmu("faulty")).unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opt = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .last_modified_time(zip::DateTime::default());
    let mut guid = String::new();
    for i in 0..zip.len() {
        let mut f = zip.by_index(i).unwrap();
        let mut data = Vec::new();
        f.read_to_end(&mut data).unwrap();
        if f.name() == "modelDescription.xml" {
            let mut md = String::from_utf8(data).unwrap();
            let at = md.find("guid=\"{").unwrap() + "guid=\"{".len();
            md.replace_range(at..at + 1, &digit.to_string());
            guid = md[at - 1..].split('"').next().unwrap().to_string();
            data = md.into_bytes();
        }
        w.start_file(f.name(), opt).unwrap();
        w.write_all(&data).unwrap();
    }
    (w.finish().unwrap().into_inner(), guid)
}

/// Sets a file's modification (and access) time to `t` (`utimensat`).
fn set_mtime(path: &Path, t: &libc::timespec) {
    let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    let times = [*t, *t];
    assert_eq!(
        unsafe { libc::utimensat(libc::AT_FDCWD, c.as_ptr(), times.as_ptr(), 0) },
        0
    );
}

fn mtime(path: &Path) -> libc::timespec {
    use std::os::unix::fs::MetadataExt;
    let m = std::fs::metadata(path).unwrap();
    libc::timespec {
        tv_sec: m.mtime(),
        tv_nsec: m.mtime_nsec(),
    }
}

#[test]
fn an_fmu_rewritten_in_place_with_the_same_size_and_mtime_is_read_anew() {
    let dir = tb_testkit::scratch("cache-rewrite");
    let store = dir.path().join("store");
    let fmu = dir.path().join("faulty.fmu");
    let (v1, guid1) = faulty_with_guid_digit('1');
    let (v2, guid2) = faulty_with_guid_digit('2');
    assert_eq!(v1.len(), v2.len());
    assert_ne!(guid1, guid2);
    std::fs::write(&fmu, &v1).unwrap();
    let cache =
        |n: usize| FmuCache::with_store(&dir.path().join(format!("root{n}")), &store).unwrap();
    let first = cache(1).load(&fmu).unwrap();
    assert_eq!(first.description.guid, guid1);
    // A second process: the index.
    let c = cache(2);
    assert_eq!(c.load(&fmu).unwrap().dir, first.dir);
    assert_eq!(c.stats().index_hits, 1);
    // Rewritten in place (same inode, same size), its mtime set back.
    let t = mtime(&fmu);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&fmu)
        .unwrap()
        .write_all(&v2)
        .unwrap();
    set_mtime(&fmu, &t);
    let now = mtime(&fmu);
    assert_eq!((now.tv_sec, now.tv_nsec), (t.tv_sec, t.tv_nsec));
    assert_eq!(std::fs::metadata(&fmu).unwrap().len(), v1.len() as u64);
    let c = cache(3);
    let second = c.load(&fmu).unwrap();
    assert_eq!(second.description.guid, guid2, "the old content was used");
    assert_ne!(second.dir, first.dir);
    let md = std::fs::read_to_string(second.dir.join("modelDescription.xml")).unwrap();
    assert!(md.contains(&guid2));
    assert_eq!(
        c.stats(),
        CacheStats {
            index_hits: 0,
            archives_read: 1,
            extractions: 1
        }
    );
}

/// The index entry files of a store, with their inode (a rewrite is a new inode).
fn index_inodes(store: &Path) -> Vec<(PathBuf, u64)> {
    use std::os::unix::fs::MetadataExt;
    let mut v: Vec<_> = std::fs::read_dir(store.join("index"))
        .map(|d| {
            d.flatten()
                .map(|e| (e.path(), e.metadata().unwrap().ino()))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_second_twinbench_process_uses_the_store_and_its_index() {
    // `twinbench info` twice on one store: the first unpacks the FMU and writes its index
    // entry; the second finds it (the full path would have rewritten the entry) and unpacks
    // nothing. Neither leaves anything in its temporary folder.
    let fmu = common::fmu("faulty");
    let dir = tb_testkit::scratch("cache-store");
    let store = dir.path().join("store");
    let tmp = dir.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let info = || {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .args(["info", fmu.to_str().unwrap()])
            .env("TWINBENCH_CACHE", &store)
            .env("TMPDIR", &tmp)
            .output()
            .unwrap();
        common::cli::assert_success(&out);
    };
    info();
    let unpacked = entries(&store);
    assert_eq!(unpacked.len(), 1, "{unpacked:?}");
    let index = index_inodes(&store);
    assert_eq!(index.len(), 1, "{index:?}");
    info();
    assert_eq!(entries(&store), unpacked);
    assert_eq!(
        index_inodes(&store),
        index,
        "the second process rewrote the entry"
    );
    assert_eq!(entries(&tmp), Vec::<String>::new());
}

#[test]
fn a_kept_temporary_cache_holds_its_own_copy_of_the_fmus() {
    // `--keep-extracted` shows the unpacked FMUs in the printed folder, a copy apart from
    // the store (looking into it or changing it leaves the store as it is).
    let cache = FmuCache::temporary(true).unwrap();
    let root = cache.root().to_path_buf();
    assert_eq!(cache.store(), None);
    let l = cache.load(&common::fmu("faulty")).unwrap();
    drop(cache);
    let kept = l.dir.starts_with(&root) && l.dir.join(".complete").is_file();
    let _ = std::fs::remove_dir_all(&root);
    assert!(kept, "{} is not under {}", l.dir.display(), root.display());
}
