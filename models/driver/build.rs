//! Parses the bundled target speed once, at build time, with the model's own parser
//! (`src/target.rs`): the model embeds the numbers and takes them instead of parsing the
//! resource again while the resource has the same bytes (`fmu_export::preparsed`).

#[path = "src/target.rs"]
#[allow(dead_code)]
mod target;

fn main() {
    println!("cargo:rerun-if-changed=src/target.rs");
    let csv = "resources/target_speed.csv";
    fmu_export::preparsed::build(csv, "target_speed.preparsed", 3, |text| {
        target::TargetSpeed::parse(text, csv)
            .ok()
            .map(|t| t.values())
    });
}
