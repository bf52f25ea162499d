//! Builds the model crates as FMU libraries (`cdylib`, release, their `fmu` feature) with a
//! cargo of their own, into `target/fmu-build`, and tells the crate where they are: the
//! binary embeds them, so `twinbench pack` needs neither the sources nor cargo (an installed
//! binary packs the FMUs anywhere). The models are the crates under `models/` with an `fmu`
//! feature; the registry (`src/registry.rs`) lists the same ones (a test checks).

use std::path::{Path, PathBuf};
use std::process::Command;

/// Crates under `models/` whose manifest declares an `fmu` feature.
fn model_crates(root: &Path) -> Vec<String> {
    let mut names = Vec::new();
    let Ok(entries) = std::fs::read_dir(root.join("models")) else {
        return names;
    };
    for e in entries.flatten() {
        let Ok(text) = std::fs::read_to_string(e.path().join("Cargo.toml")) else {
            continue;
        };
        let has_fmu_feature = text
            .lines()
            .skip_while(|l| l.trim() != "[features]")
            .take_while(|l| !l.trim().starts_with('[') || l.trim() == "[features]")
            .any(|l| l.trim_start().starts_with("fmu ") || l.trim_start().starts_with("fmu="));
        let name = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("name = "))
            .map(|n| n.trim_matches('"').to_string());
        if let (true, Some(name)) = (has_fmu_feature, name) {
            names.push(name);
        }
    }
    names.sort();
    names
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("set by cargo"));
    for p in [
        "models",
        "crates/fmi/src",
        "crates/fmi/Cargo.toml",
        "Cargo.lock",
    ] {
        println!("cargo:rerun-if-changed={}", root.join(p).display());
    }
    let models = model_crates(&root);
    let target = root.join("target").join("fmu-build");
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(&root)
        .args(["build", "--release", "--offline", "--target-dir"])
        .arg(&target);
    for m in &models {
        cmd.args(["-p", m]);
    }
    let features: Vec<String> = models.iter().map(|m| format!("{m}/fmu")).collect();
    cmd.arg("--features").arg(features.join(","));
    // This build's wrappers and flags are not the models' (clippy, a target of its own).
    for v in [
        "RUSTC_WRAPPER",
        "RUSTC_WORKSPACE_WRAPPER",
        "CARGO_TARGET_DIR",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "CARGO_BUILD_TARGET",
        "CARGO_PRIMARY_PACKAGE",
    ] {
        cmd.env_remove(v);
    }
    let out = cmd
        .output()
        .expect("cannot run cargo to build the model libraries");
    if !out.status.success() {
        eprintln!("{}", String::from_utf8_lossy(&out.stderr));
        panic!(
            "building the model libraries (cargo build -p <model> --features <model>/fmu) failed"
        );
    }
    for m in &models {
        println!(
            "cargo:rustc-env=TWINBENCH_LIB_{m}={}",
            target
                .join("release")
                .join(format!("lib{}.so", m.replace('-', "_")))
                .display()
        );
    }
}
