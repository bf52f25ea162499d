//! modelDescription.xml reader: any text gives Ok or an error, never a panic or a hang.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = tb_fmi::import::description::parse(text);
    }
});
