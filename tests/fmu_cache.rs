//! The unpack cache under concurrent loads: threads of one process share one cache, and
//! processes (several caches) share one folder. Every load succeeds, each content is
//! unpacked into one folder, and nothing half-unpacked stays behind.

mod common;

use std::path::Path;
use std::sync::{Arc, Barrier};
use tb_fmi::FmuCache;

/// The cache folder's entries: unpacked FMUs (and, if the race were back, temporaries).
fn entries(root: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn eight_threads_load_the_same_fmu_into_one_cache_a_hundred_times() {
    let fmu = common::fmu("faulty");
    for round in 0..100 {
        let dir = tb_testkit::scratch("cache-race");
        let root = dir.path().join("cache");
        let cache = FmuCache::persistent(&root).unwrap();
        let barrier = Barrier::new(8);
        let loaded: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..8)
                .map(|_| {
                    s.spawn(|| {
                        barrier.wait();
                        cache.load(&fmu)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let loaded: Vec<_> = loaded
            .into_iter()
            .map(|r| r.unwrap_or_else(|e| panic!("round {round}: {e}")))
            .collect();
        // One load: every thread got the same unpacked FMU.
        assert!(
            loaded.iter().all(|l| Arc::ptr_eq(l, &loaded[0])),
            "round {round}: several loads of one content"
        );
        let e = entries(&root);
        assert_eq!(e.len(), 1, "round {round}: {e:?}");
        assert!(!e[0].contains("tmp"), "round {round}: {e:?}");
        assert!(loaded[0].dir.join(".complete").exists());
    }
}

#[test]
fn caches_of_several_processes_share_one_folder_without_losing_an_unpacking() {
    // Eight caches on one folder stand for eight processes: each unpacks into a folder of
    // its own and renames it into place; the losers use the winner's.
    let fmu = common::fmu("faulty");
    for round in 0..20 {
        let dir = tb_testkit::scratch("cache-procs");
        let root = dir.path().join("cache");
        let barrier = Barrier::new(8);
        let dirs: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..8)
                .map(|_| {
                    s.spawn(|| {
                        let cache = FmuCache::persistent(&root).unwrap();
                        barrier.wait();
                        let l = cache
                            .load(&fmu)
                            .unwrap_or_else(|e| panic!("round {round}: {e}"));
                        l.dir.clone()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert!(dirs.iter().all(|d| *d == dirs[0]), "round {round}");
        let e = entries(&root);
        assert_eq!(e.len(), 1, "round {round}: {e:?}");
        assert!(dirs[0].join(".complete").exists());
    }
}
