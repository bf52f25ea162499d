//! The FMI 3.0 modelDescription.xml reader on its own (`model_description` dispatches on
//! `fmiVersion` and mostly reaches the FMI 2.0 reader): any text gives Ok or an error, never
//! a panic, a hang or an unbounded allocation (array dimensions, Binary values).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = tb_fmi::import::description3::parse(text);
    }
});
