//! SSP import (`tb_cosim::ssp_import::load`), structure-aware: the input is the package's
//! `SystemStructure.ssd`, zipped into an `.ssp` with description-only copies of twinbench's
//! four FMUs and the Reference FMUs' Feedthrough
//! (`resources/{vehicle,driver,dyno,edu,Feedthrough}.fmu`: their modelDescription.xml from
//! `corpus/model_description/` and an empty library), so that the XML reader and the import
//! behind it (components, connectors, units, parameter bindings, connections, experiment)
//! are exercised rather than the zip checks. Input after a line `<!--ssv-->` becomes the
//! package's `resources/parameters.ssv`. Each input is unpacked into a fresh cache folder,
//! removed after it. Any input gives a system file or an error, never a panic or a hang.
#![no_main]

use std::io::Write;
use std::path::PathBuf;
use std::sync::OnceLock;

struct Setup {
    /// This process's folder: the package and the cache of one input.
    base: PathBuf,
    /// The FMUs of every package: (entry, zip bytes).
    fmus: Vec<(String, Vec<u8>)>,
}

const MODELS: [(&str, &str); 5] = [
    ("vehicle", include_str!("../corpus/model_description/vehicle.xml")),
    ("driver", include_str!("../corpus/model_description/driver.xml")),
    ("dyno", include_str!("../corpus/model_description/dyno.xml")),
    ("edu", include_str!("../corpus/model_description/edu.xml")),
    (
        "Feedthrough",
        include_str!("../corpus/model_description/ref_Feedthrough_fmi2.xml"),
    ),
];

fn stored() -> zip::write::SimpleFileOptions {
    zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored)
}

fn model_identifier(xml: &str) -> &str {
    let at = xml.find("modelIdentifier=\"").expect("a modelIdentifier") + 17;
    let end = xml[at..].find('"').expect("a closing quote");
    &xml[at..at + end]
}

fn setup() -> Setup {
    let base = std::env::temp_dir().join(format!("twinbench-fuzz-ssp-{}", std::process::id()));
    std::fs::create_dir_all(&base).expect("a folder for the fuzz packages");
    let fmus = MODELS
        .iter()
        .map(|(name, xml)| {
            let mut z = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
            z.start_file("modelDescription.xml", stored()).unwrap();
            z.write_all(xml.as_bytes()).unwrap();
            let lib = format!("binaries/linux64/{}.so", model_identifier(xml));
            z.start_file(lib, stored()).unwrap();
            (format!("resources/{name}.fmu"), z.finish().unwrap().into_inner())
        })
        .collect();
    Setup { base, fmus }
}

fn package(data: &[u8], fmus: &[(String, Vec<u8>)]) -> Vec<u8> {
    const SSV: &[u8] = b"\n<!--ssv-->\n";
    let (ssd, ssv) = match data.windows(SSV.len()).position(|w| w == SSV) {
        Some(i) => (&data[..i], Some(&data[i + SSV.len()..])),
        None => (data, None),
    };
    let mut z = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    z.start_file("SystemStructure.ssd", stored()).unwrap();
    z.write_all(ssd).unwrap();
    if let Some(ssv) = ssv {
        z.start_file("resources/parameters.ssv", stored()).unwrap();
        z.write_all(ssv).unwrap();
    }
    for (entry, bytes) in fmus {
        z.start_file(entry.as_str(), stored()).unwrap();
        z.write_all(bytes).unwrap();
    }
    z.finish().unwrap().into_inner()
}

static SETUP: OnceLock<Setup> = OnceLock::new();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let s = SETUP.get_or_init(setup);
    let ssp = s.base.join("fuzz.ssp");
    std::fs::write(&ssp, package(data, &s.fmus)).expect("the package written");
    let run = s.base.join("cache");
    {
        let cache = tb_fmi::FmuCache::persistent(&run).expect("a cache folder");
        let _ = tb_cosim::ssp_import::load(&ssp, &cache);
    }
    let _ = std::fs::remove_dir_all(&run);
});
