//! Property tests under arbitrary input: the modelDescription reader, the system file
//! (parsed, then validated against real FMUs), the measurement CSV reader and the MDF 4
//! reader never panic; they answer Ok or an error. Inputs are arbitrary strings and random
//! byte edits of real files (the seeds of the `fuzz/` corpus). Bounded: a few hundred cases each. The
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

/// `edits` applied to the seed `k` of `seeds` (counted round).
fn edited(seeds: &[Vec<u8>], k: usize, edits: &[Edit]) -> Vec<u8> {
    apply(&seeds[k % seeds.len()], edits)
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
        let text = edited(md_seeds(), k, &edits);
        let _ = tb_fmi::import::description::parse(&String::from_utf8_lossy(&text));
    }

    #[test]
    fn model_description_never_panics_on_arbitrary_text(text in "\\PC{0,400}") {
        let _ = tb_fmi::import::description::parse(&text);
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
    common::shared_cache()
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
        let text = edited(system_seeds(), k, &edits);
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
        check_csv(&edited(csv_seeds(), k, &edits));
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

// ---- MDF 4 measurements ----

fn mdf_seeds() -> &'static Vec<Vec<u8>> {
    static S: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    S.get_or_init(|| seeds("mdf4"))
}

/// An 8-byte little-endian value written over the file: a link, a length or a count.
fn word() -> impl Strategy<Value = Edit> {
    let value = prop_oneof![
        Just(0u64),
        Just(u64::MAX),
        0..4096u64,
        any::<u64>(),
        (0..32u64).prop_map(|k| 1 << (k + 32)),
    ];
    (any::<usize>(), value).prop_map(|(p, v)| Edit::Overwrite(p & !7, v.to_le_bytes().to_vec()))
}

proptest! {
    #![proptest_config(config(400))]

    /// The MDF 4 reader (the block-graph check, then mdf4-rs) never panics, hangs or runs
    /// out of memory on a damaged file: edits of files written by twinbench, asammdf and
    /// by hand (fuzz/corpus/mdf4), byte edits and whole words over links and sizes. The
    /// check refuses what would make the crate panic: its caught panic is never the answer.
    #[test]
    fn mdf4_never_panics_on_edits(
        k in 0..64usize,
        edits in prop::collection::vec(prop_oneof![edit(), word()], 1..6),
    ) {
        if let Err(e) = tb_table::mdf::read_bytes(&edited(mdf_seeds(), k, &edits), "edited.mf4") {
            prop_assert!(!e.to_string().contains("the MDF reader (mdf4-rs) failed"), "{e}");
        }
    }
}

// ---- system files edited by meaning: every case reaches the validator ----

/// What an edit by meaning changes in the bundled bench's system file.
#[derive(Clone, Debug)]
enum Change {
    /// A connection's source or target becomes another `instance.variable`.
    Endpoint(usize, bool, usize, usize),
    /// A parameter with a value of some type.
    Parameter(usize, usize, ParamKind),
    Step(f64),
    Stop(usize, usize, f64),
    Record(usize, usize),
    /// An instance is dropped.
    DropInstance(usize),
    Algorithm(bool),
}

#[derive(Clone, Debug)]
enum ParamKind {
    Real(f64),
    Integer(i64),
    Boolean(bool),
    Text,
}

fn change() -> impl Strategy<Value = Change> {
    let number = prop_oneof![
        -1e6f64..1e6,
        Just(0.0),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(1e-20),
        Just(-1.0),
        Just(1e300),
    ];
    prop_oneof![
        (
            any::<usize>(),
            any::<bool>(),
            any::<usize>(),
            any::<usize>()
        )
            .prop_map(|(c, side, i, v)| Change::Endpoint(c, side, i, v)),
        (
            any::<usize>(),
            any::<usize>(),
            prop_oneof![
                number.clone().prop_map(ParamKind::Real),
                any::<i64>().prop_map(ParamKind::Integer),
                any::<bool>().prop_map(ParamKind::Boolean),
                Just(ParamKind::Text),
            ]
        )
            .prop_map(|(i, v, k)| Change::Parameter(i, v, k)),
        number.clone().prop_map(Change::Step),
        (any::<usize>(), any::<usize>(), number).prop_map(|(i, v, x)| Change::Stop(i, v, x)),
        (any::<usize>(), any::<usize>()).prop_map(|(i, v)| Change::Record(i, v)),
        any::<usize>().prop_map(Change::DropInstance),
        any::<bool>().prop_map(Change::Algorithm),
    ]
}

/// Instance names and, per instance, its FMU's variable names (plus a misspelled one).
fn bench_names() -> &'static Vec<(String, Vec<String>)> {
    static N: OnceLock<Vec<(String, Vec<String>)>> = OnceLock::new();
    N.get_or_init(|| {
        common::fmu_dir();
        let plan =
            tb_cosim::Plan::load(&root().join("systems/rls_v.toml"), shared_cache()).unwrap();
        plan.instances
            .iter()
            .map(|i| {
                let mut v: Vec<String> = i
                    .description()
                    .variables
                    .iter()
                    .map(|v| v.name.clone())
                    .collect();
                v.push("no_such_variable".into());
                (i.name.clone(), v)
            })
            .collect()
    })
}

fn pick(names: &[(String, Vec<String>)], i: usize, v: usize) -> String {
    let (inst, vars) = &names[i % names.len()];
    format!("{inst}.{}", vars[v % vars.len()])
}

fn apply_changes(doc: &mut toml::Table, changes: &[Change]) {
    let names = bench_names();
    for c in changes {
        match c {
            Change::Endpoint(k, side, i, v) => {
                if let Some(toml::Value::Array(conns)) = doc.get_mut("connections") {
                    if conns.is_empty() {
                        continue;
                    }
                    let n = conns.len();
                    let text = conns[k % n].as_str().unwrap_or("a.b -> c.d").to_string();
                    let (a, b) = text.split_once("->").unwrap_or(("a.b", "c.d"));
                    let new = pick(names, *i, *v);
                    conns[k % n] = toml::Value::String(if *side {
                        format!("{new} -> {}", b.trim())
                    } else {
                        format!("{} -> {new}", a.trim())
                    });
                }
            }
            Change::Parameter(i, v, kind) => {
                let value = match kind {
                    ParamKind::Real(x) => toml::Value::Float(*x),
                    ParamKind::Integer(n) => toml::Value::Integer(*n),
                    ParamKind::Boolean(b) => toml::Value::Boolean(*b),
                    ParamKind::Text => toml::Value::String("text".into()),
                };
                if let Some(toml::Value::Table(p)) = doc.get_mut("parameters") {
                    p.insert(pick(names, *i, *v), value);
                }
            }
            Change::Step(h) => {
                if let Some(toml::Value::Table(e)) = doc.get_mut("experiment") {
                    e.insert("step".into(), toml::Value::Float(*h));
                }
            }
            Change::Stop(i, v, x) => {
                if let Some(toml::Value::Table(e)) = doc.get_mut("experiment") {
                    let stop = if x.is_finite() && *x > 0.0 && *x < 3.0 {
                        toml::Value::Float(*x)
                    } else {
                        toml::Value::String(format!("{} >= {x}", pick(names, *i, *v)))
                    };
                    e.insert("stop".into(), stop);
                }
            }
            Change::Record(i, v) => {
                if let Some(toml::Value::Table(r)) = doc.get_mut("record") {
                    if let Some(toml::Value::Array(s)) = r.get_mut("signals") {
                        s.push(toml::Value::String(pick(names, *i, *v)));
                    }
                }
            }
            Change::DropInstance(k) => {
                if let Some(toml::Value::Array(insts)) = doc.get_mut("instance") {
                    if !insts.is_empty() {
                        let n = insts.len();
                        insts.remove(k % n);
                    }
                }
            }
            Change::Algorithm(jacobi) => {
                if let Some(toml::Value::Table(e)) = doc.get_mut("experiment") {
                    let a = if *jacobi { "jacobi" } else { "gauss-seidel" };
                    e.insert("algorithm".into(), toml::Value::String(a.into()));
                }
            }
        }
    }
}

#[test]
fn system_files_edited_by_meaning_reach_the_validator_and_never_panic() {
    use proptest::test_runner::TestRunner;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let path = root().join("systems/rls_v.toml");
    let seed: toml::Table = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    bench_names();
    let (parsed, accepted, refused) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    let cases = 300;
    let mut runner = TestRunner::new(config(cases));
    runner
        .run(&prop::collection::vec(change(), 1..4), |changes| {
            let mut doc = seed.clone();
            apply_changes(&mut doc, &changes);
            let text = toml::to_string(&doc).unwrap();
            let Ok(file) = tb_cosim::SystemFile::parse(&text, &path) else {
                return Ok(());
            };
            parsed.fetch_add(1, Ordering::Relaxed);
            match tb_cosim::Plan::from_file(file, &path, shared_cache()) {
                Ok(plan) => {
                    accepted.fetch_add(1, Ordering::Relaxed);
                    prop_assert!(tb_cosim::Simulation::new(plan).is_ok());
                }
                Err(e) => {
                    refused.fetch_add(1, Ordering::Relaxed);
                    // A refusal names the file and says what is wrong.
                    let m = e.to_string();
                    prop_assert!(m.len() > 20, "terse message: {m}");
                }
            }
            Ok(())
        })
        .unwrap();
    let (p, a, r) = (
        parsed.into_inner(),
        accepted.into_inner(),
        refused.into_inner(),
    );
    eprintln!(
        "{cases} edited system files: {p} parsed, {a} accepted, {r} refused by the validator"
    );
    // Edits by meaning keep the file valid TOML: nearly all reach the validator, and both
    // of its answers are exercised.
    assert!(p as f64 >= 0.95 * cases as f64, "{p} of {cases} parsed");
    assert!(a as f64 >= 0.05 * cases as f64, "{a} accepted");
    assert!(r as f64 >= 0.3 * cases as f64, "{r} refused");
}
