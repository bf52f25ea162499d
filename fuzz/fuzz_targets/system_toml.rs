//! System file: parsed; a parseable one is not loaded (that reads FMUs named by the input),
//! so this target covers the TOML layer and path resolution. The property tests in
//! tests/robustness_props.rs also validate parseable edits against the real FMUs.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let path = std::path::Path::new("systems/fuzzed.toml");
        let _ = tb_cosim::SystemFile::parse(text, path);
    }
});
