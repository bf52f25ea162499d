//! Parses the bundled track once, at build time, with the model's own parser
//! (`src/track.rs`): the model embeds the numbers and takes them instead of parsing the
//! resource again while the resource has the same bytes (`fmu_export::preparsed`).

#[path = "src/track.rs"]
#[allow(dead_code)]
mod track;

fn main() {
    println!("cargo:rerun-if-changed=src/track.rs");
    let csv = "resources/track.csv";
    fmu_export::preparsed::build(csv, "track.preparsed", 5, |text| {
        track::Track::parse(csv, text).ok().map(|t| t.values())
    });
}
