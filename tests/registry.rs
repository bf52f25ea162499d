//! The model registry is the one list of models: every model crate of the workspace (a crate
//! with an `fmu` feature, which exports the FMI symbols) is registered (a path dependency of
//! `crates/bench/Cargo.toml`, which its build.rs reads), and every registered model is such a crate;
//! `pack` and the native backend read the same list.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The workspace's member folders (`members` of the root manifest, `dir/*` expanded).
fn workspace_members(root: &Path) -> Vec<PathBuf> {
    let text = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    let t: toml::Table = toml::from_str(&text).unwrap();
    let mut dirs = Vec::new();
    for m in t["workspace"]["members"].as_array().unwrap() {
        let m = m.as_str().unwrap();
        match m.strip_suffix("/*") {
            Some(parent) => {
                for e in std::fs::read_dir(root.join(parent)).unwrap().flatten() {
                    dirs.push(e.path());
                }
            }
            None => dirs.push(root.join(m)),
        }
    }
    dirs
}

#[test]
fn the_registry_and_the_workspace_model_crates_agree() {
    let root = twinbench::pack::workspace_root();
    let mut crates = BTreeSet::new();
    let mut test_crates = BTreeSet::new();
    for dir in workspace_members(&root) {
        let Ok(text) = std::fs::read_to_string(dir.join("Cargo.toml")) else {
            continue;
        };
        let t: toml::Table = toml::from_str(&text).unwrap();
        let exports = t.get("features").and_then(|f| f.get("fmu")).is_some();
        if exports {
            let name = t["package"]["name"].as_str().unwrap().to_string();
            let test = t["package"]
                .get("metadata")
                .and_then(|m| m.get("twinbench"))
                .and_then(|m| m.get("test"))
                .and_then(|t| t.as_bool())
                .unwrap_or(false);
            if test {
                test_crates.insert(name.clone());
            }
            crates.insert(name);
        }
    }
    let registry = twinbench::registry::models();
    let registered: BTreeSet<String> = registry
        .iter()
        .map(|m| m.pack.package.to_string())
        .collect();
    assert_eq!(
        crates, registered,
        "a model crate of the workspace is not registered: add `<name> = {{ path = \"...\" }}` to crates/bench/Cargo.toml's [dependencies]"
    );
    let registered_tests: BTreeSet<String> = registry
        .iter()
        .filter(|m| m.pack.test_only)
        .map(|m| m.pack.package.to_string())
        .collect();
    assert_eq!(test_crates, registered_tests);
    assert!(registered_tests.contains("faulty"));
    // Packing and the native backend see the same models, under the names in the FMUs.
    let packed: BTreeSet<&str> = twinbench::pack::models()
        .iter()
        .map(|s| s.info.name)
        .collect();
    let native: BTreeSet<&str> = twinbench::registry::native_models()
        .iter()
        .map(|m| m.name)
        .collect();
    assert_eq!(packed, native);
    assert_eq!(packed.len(), registered.len());
}
