//! Parses the bundled target speed once, at build time, with the model's own parser
//! (`src/target.rs`): the model embeds the numbers and takes them instead of parsing the
//! resource again while the resource has the same bytes (`fmu_export::sidecar`).

#[path = "src/target.rs"]
#[allow(dead_code)]
mod target;

fn main() {
    let csv = "resources/target_speed.csv";
    println!("cargo:rerun-if-changed={csv}");
    println!("cargo:rerun-if-changed=src/target.rs");
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo"));
    let blob = std::fs::read_to_string(csv)
        .ok()
        .and_then(|text| {
            let t = target::TargetSpeed::parse(&text, csv).ok()?;
            Some(fmu_export::sidecar::encode(
                fmu_export::sidecar::digest(text.as_bytes()),
                2,
                &t.values(),
            ))
        })
        .unwrap_or_default();
    std::fs::write(out.join("target_speed.sidecar"), blob).expect("OUT_DIR is writable");
}
