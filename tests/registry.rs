//! The model registry is the one list of models: every model crate under `models/` (a crate
//! with an `fmu` feature, which exports the FMI symbols) is registered, and every registered
//! model is such a crate; `pack` and the native backend read the same list.

use std::collections::BTreeSet;

#[test]
fn the_registry_and_the_model_folders_agree() {
    let root = twinbench::pack::workspace_root();
    let mut folders = BTreeSet::new();
    for e in std::fs::read_dir(root.join("models")).unwrap().flatten() {
        let manifest = e.path().join("Cargo.toml");
        let Ok(text) = std::fs::read_to_string(&manifest) else {
            continue;
        };
        let t: toml::Table = toml::from_str(&text).unwrap();
        let exports = t.get("features").and_then(|f| f.get("fmu")).is_some();
        if exports {
            let name = t["package"]["name"].as_str().unwrap().to_string();
            folders.insert(name);
        }
    }
    let registered: BTreeSet<String> = twinbench::registry::models()
        .iter()
        .map(|m| m.pack.package.to_string())
        .collect();
    assert_eq!(folders, registered);
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
