//! Parses the bundled track once, at build time, with the model's own parser
//! (`src/track.rs`): the model embeds the numbers and takes them instead of parsing the
//! resource again while the resource has the same bytes (`fmu_export::sidecar`).

#[path = "src/track.rs"]
#[allow(dead_code)]
mod track;

fn main() {
    let csv = "resources/track.csv";
    println!("cargo:rerun-if-changed={csv}");
    println!("cargo:rerun-if-changed=src/track.rs");
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo"));
    let blob = std::fs::read_to_string(csv)
        .ok()
        .and_then(|text| {
            let t = track::Track::parse(csv, &text).ok()?;
            Some(fmu_export::sidecar::encode(
                fmu_export::sidecar::digest(text.as_bytes()),
                5,
                &t.values(),
            ))
        })
        .unwrap_or_default();
    std::fs::write(out.join("track.sidecar"), blob).expect("OUT_DIR is writable");
}
