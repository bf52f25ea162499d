//! Property tests under arbitrary input: the modelDescription reader, the system file
//! (parsed, then validated against real FMUs) and the measurement CSV reader never panic;
//! they answer Ok or an error. Inputs are arbitrary strings and random byte edits of real
//! files (the seeds of the `fuzz/` corpus). Bounded: a few hundred cases each. The
//! coverage-guided version of the same targets is in `fuzz/` (see docs/robustness.md).

mod common;

use proptest::prelude::*;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use tb_fmi::FmuCache;

/// A random edit: delete, insert or overwrite a few bytes at a position.
#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, Vec<u8>),
    Overwrite(usize, Vec<u8>),
    /// Duplicate a span (repeats elements, attributes, rows).
    Repeat(usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    // Bytes biased to the syntax of the three formats.
    let byte = prop_oneof![
        any::<u8>(),
        prop::sample::select(b"<>/=\"'&;[]{}.,-+eE0123456789\n\r\t #:".to_vec()),
    ];
    prop_oneof![
        (any::<usize>(), 1..16usize).prop_map(|(p, n)| Edit::Delete(p, n)),
        (any::<usize>(), prop::collection::vec(byte.clone(), 1..8))
            .prop_map(|(p, b)| Edit::Insert(p, b)),
        (any::<usize>(), prop::collection::vec(byte, 1..8))
            .prop_map(|(p, b)| Edit::Overwrite(p, b)),
        (any::<usize>(), 1..64usize).prop_map(|(p, n)| Edit::Repeat(p, n)),
    ]
}

fn apply(seed: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for e in edits {
        let len = v.len().max(1);
        match e {
            Edit::Delete(p, n) => {
                let p = p % len;
                let end = (p + n).min(v.len());
                if p < end {
                    v.drain(p..end);
                }
            }
            Edit::Insert(p, b) => {
                let p = p % (v.len() + 1);
                v.splice(p..p, b.iter().copied());
            }
            Edit::Overwrite(p, b) => {
                let p = p % len;
                for (k, x) in b.iter().enumerate() {
                    if let Some(slot) = v.get_mut(p + k) {
                        *slot = *x;
                    }
                }
            }
            Edit::Repeat(p, n) => {
                let p = p % len;
                let end = (p + n).min(v.len());
                if p < end {
                    let span: Vec<u8> = v[p..end].to_vec();
                    v.splice(end..end, span);
                }
            }
        }
    }
    v
}

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

fn seeds(dir: &str) -> Vec<Vec<u8>> {
    let d = root().join("fuzz/corpus").join(dir);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&d)
        .unwrap_or_else(|e| panic!("{}: {e}", d.display()))
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

// ---- modelDescription.xml ----

fn md_seeds() -> &'static Vec<Vec<u8>> {
    static S: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    S.get_or_init(|| seeds("model_description"))
}

proptest! {
    #![proptest_config(config(400))]

    #[test]
    fn model_description_never_panics_on_edits(k in 0..64usize, edits in prop::collection::vec(edit(), 1..6)) {
        let s = md_seeds();
        let text = apply(&s[k % s.len()], &edits);
        let _ = tb_fmi::description::parse(&String::from_utf8_lossy(&text));
    }

    #[test]
    fn model_description_never_panics_on_arbitrary_text(text in "\\PC{0,400}") {
        let _ = tb_fmi::description::parse(&text);
    }
}

// ---- system files: parsed, and the parseable ones validated against the FMUs ----

fn system_seeds() -> &'static Vec<Vec<u8>> {
    static S: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    S.get_or_init(|| {
        common::fmu_dir();
        seeds("system_toml")
    })
}

fn shared_cache() -> Arc<FmuCache> {
    static C: OnceLock<Arc<FmuCache>> = OnceLock::new();
    C.get_or_init(|| Arc::new(FmuCache::temporary(false).unwrap()))
        .clone()
}

/// The seeds name FMUs relative to `systems/`.
fn system_path() -> PathBuf {
    root().join("systems/fuzzed.toml")
}

fn check_system(text: &str) {
    let path = system_path();
    if let Ok(file) = tb_cosim::SystemFile::parse(text, &path) {
        // Only regular files (an edit could name /dev/zero) and no preloaded libraries.
        if file.fmus.values().all(|p| p.is_file())
            && file.replay.iter().all(|r| r.file.is_file())
            && file.preload.is_empty()
        {
            if let Ok(sys) = tb_cosim::Plan::from_file(file, &path, shared_cache()) {
                let _ = tb_cosim::Simulation::new(sys);
            }
        }
    }
}

proptest! {
    #![proptest_config(config(300))]

    #[test]
    fn system_file_never_panics_on_edits(k in 0..64usize, edits in prop::collection::vec(edit(), 1..5)) {
        let s = system_seeds();
        let text = apply(&s[k % s.len()], &edits);
        check_system(&String::from_utf8_lossy(&text));
    }

    #[test]
    fn system_file_never_panics_on_arbitrary_text(text in "\\PC{0,300}") {
        check_system(&text);
    }
}

// ---- measurement CSV ----

fn csv_seeds() -> &'static Vec<Vec<u8>> {
    static S: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    S.get_or_init(|| seeds("measurement_csv"))
}

fn check_csv(bytes: &[u8]) {
    if let Ok(t) = tb_compare::Table::from_reader(bytes, "fuzz.csv") {
        let _ = tb_compare::Measurement::from_table(t);
    }
}

proptest! {
    #![proptest_config(config(500))]

    #[test]
    fn measurement_csv_never_panics_on_edits(k in 0..64usize, edits in prop::collection::vec(edit(), 1..8)) {
        let s = csv_seeds();
        check_csv(&apply(&s[k % s.len()], &edits));
    }

    #[test]
    fn measurement_csv_never_panics_on_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        check_csv(&bytes);
    }

    /// Any table of finite numbers with increasing time and distance reads back exactly.
    #[test]
    fn valid_measurements_read_back(rows in prop::collection::vec((0.001f64..1.0, 0.0f64..10.0, -1e6f64..1e6), 1..40)) {
        let mut text = String::from("time,distance,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr\n");
        let (mut t, mut d) = (0.0, 0.0);
        for (dt, dd, x) in &rows {
            t += dt;
            d += dd;
            text.push_str(&format!("{t},{d},{x},{x},{x},{x},{x}\n"));
        }
        let m = tb_compare::Measurement::from_table(
            tb_compare::Table::from_reader(text.as_bytes(), "gen.csv").unwrap(),
        )
        .unwrap();
        prop_assert_eq!(m.time().len(), rows.len());
        prop_assert_eq!(*m.distance().last().unwrap(), d);
    }
}
