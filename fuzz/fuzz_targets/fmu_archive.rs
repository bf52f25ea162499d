//! FMU archive checks (before anything is extracted): any bytes are refused or accepted,
//! never a panic.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tb_fmi::import::archive::check_archive(std::path::Path::new("fuzz.fmu"), data);
});
