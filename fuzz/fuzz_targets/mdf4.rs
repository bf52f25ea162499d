//! MDF 4 reader (`tb_table::mdf::read_bytes`: the block-graph check, then mdf4-rs): any
//! bytes give a table or an error, never a panic (libFuzzer aborts on one, even one the
//! reader catches), a hang or an allocation beyond the limits.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tb_table::mdf::read_bytes(data, "fuzz.mf4");
});
