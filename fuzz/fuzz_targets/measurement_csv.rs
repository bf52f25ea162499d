//! Measurement CSV: any bytes give a table and a measurement, or an error.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(t) = tb_compare::Table::from_reader(data, "fuzz.csv") {
        let _ = tb_compare::Measurement::from_table(t);
    }
});
