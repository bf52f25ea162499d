//! Unit conversion across connections: by the units both FMUs declare (twinbench's table or
//! the FMU's own definitions, with factor and offset), as the system file overrides them
//! (`from_unit`, `to_unit`, `scale`, `offset`), and refused where it cannot be right.

mod support;

use support::{assert_close, instances, last, Bench};
use tb_cosim::Simulation;
use tb_testkit::assert_contains;

/// source -> sink over `connection`, one step, recording `signals`.
fn link(connection: &str, signals: &str) -> String {
    let instances = instances(&[("src", "source"), ("snk", "sink")]);
    format!(
        r#"connections = [{connection}]

{instances}[experiment]
step = 0.5
stop = 1.0

[record]
signals = [{signals}]
"#
    )
}

/// Runs `link(connection, signal)`: the simulation and the last value of `signal`.
fn run_link(b: &Bench, connection: &str, signal: &str) -> (Simulation, f64) {
    let (sim, _) = b.run(&link(connection, &format!("\"{signal}\"")));
    let value = last(&sim, signal);
    (sim, value)
}

#[test]
fn declared_units_convert_by_their_factors() {
    let b = Bench::new();
    let (sim, _) = b.run(&link(
        "\"src.y_kmh -> snk.v\", \"src.y_rpm -> snk.w\", \"src.share -> snk.x\"",
        "\"snk.v_out\", \"snk.w_out\", \"snk.x_out\"",
    ));
    // 36 km/h = 10 m/s; 36 rpm = 36·π/30 rad/s; 50 % = 0.5 (tolerance: one rounding).
    assert_close(last(&sim, "snk.v_out"), 10.0, 1e-14);
    assert_close(
        last(&sim, "snk.w_out"),
        36.0 * std::f64::consts::PI / 30.0,
        1e-14,
    );
    assert_close(last(&sim, "snk.x_out"), 0.5, 1e-16);
    let c = &sim.plan().connections[0];
    assert_close(c.scale, 1.0 / 3.6, 1e-16);
    assert_eq!(c.offset, 0.0);
    // Nothing was overridden: no notes.
    assert!(sim.plan().notes.is_empty(), "{:?}", sim.plan().notes);
}

#[test]
fn an_fmus_own_unit_definitions_convert_with_their_offset() {
    let b = Bench::new();
    let (sim, _) = b.run(&link("\"src.temp -> snk.temp_k\"", "\"snk.temp_out\""));
    // degC (K, offset 273.15) to K: 25 °C = 298.15 K (tolerance: one rounding).
    assert_close(last(&sim, "snk.temp_out"), 298.15, 1e-12);
    let c = &sim.plan().connections[0];
    assert_eq!((c.scale, c.offset), (1.0, 273.15));
}

#[test]
fn a_rad_exponent_on_one_side_only_converts_with_a_note() {
    let b = Bench::new();
    // 36 rpm into a frequency in Hz (1/s): rad taken as dimensionless.
    let (sim, _) = b.run(&link("\"src.y_rpm -> snk.freq\"", "\"snk.freq_out\""));
    assert_close(
        last(&sim, "snk.freq_out"),
        36.0 * std::f64::consts::PI / 30.0,
        1e-14,
    );
    assert_contains(
        &sim.plan().notes.join("\n"),
        &["units 'rpm' and 'Hz' differ only in their rad exponent (1 and 0): rad taken as dimensionless (SI), 1 rpm = 0.1047"],
    );
    // Without the rad, the dimensions must agree: rpm is no plain number.
    let e = b.error(&link("\"src.y_rpm -> snk.x\"", "\"snk.x_out\""));
    assert_contains(&e, &["incompatible units 'rpm' and '1'"]);
}

#[test]
fn units_an_fmu_declares_wrongly_are_overridden_in_the_system_file() {
    let b = Bench::new();
    // The source's km/h taken as m/s: no conversion, and the run's log says so.
    let (sim, value) = run_link(
        &b,
        "{ from = \"src.y_kmh\", to = \"snk.v\", from_unit = \"m/s\" }",
        "snk.v_out",
    );
    assert_eq!(value, 36.0);
    assert_contains(
        &sim.plan().notes.join("\n"),
        &["units overridden in the system file: 'm/s' -> 'm/s', scale 1, offset 0"],
    );
    // The sink's m/s taken as km/h: the value passes as 36 (km/h).
    let (_, value) = run_link(
        &b,
        "{ from = \"src.y_kmh\", to = \"snk.v\", to_unit = \"km/h\" }",
        "snk.v_out",
    );
    assert_eq!(value, 36.0);
    // rpm declared for a value that is in rad/s.
    let (_, value) = run_link(
        &b,
        "{ from = \"src.y_rpm\", to = \"snk.w\", from_unit = \"rad/s\" }",
        "snk.w_out",
    );
    assert_eq!(value, 36.0);
}

#[test]
fn scale_and_offset_replace_the_units() {
    let b = Bench::new();
    let (sim, _) = b.run(&link(
        "{ from = \"src.y_kmh\", to = \"snk.v\", scale = 2.0, offset = 1.0 }",
        "\"snk.v_out\"",
    ));
    // 2·36 + 1, exact.
    assert_eq!(last(&sim, "snk.v_out"), 73.0);
    let c = &sim.plan().connections[0];
    assert_eq!((c.scale, c.offset), (2.0, 1.0));
    assert_contains(
        &sim.plan().notes.join("\n"),
        &["scale 2 and offset 1 from the system file (declared units 'km/h' and 'm/s' not used)"],
    );
    // An offset alone keeps the scale at 1.
    let (_, value) = run_link(
        &b,
        "{ from = \"src.y_kmh\", to = \"snk.v\", offset = -6.0 }",
        "snk.v_out",
    );
    assert_eq!(value, 30.0);
}

#[test]
fn a_replayed_columns_unit_converts_too() {
    let b = Bench::new();
    b.write("speeds.csv", "time,v\ns,km/h\n0,72\n10,72\n");
    let instances = instances(&[("snk", "sink")]);
    let text = format!(
        r#"connections = ["speeds.v -> snk.v"]

{instances}[[replay]]
name = "speeds"
file = "speeds.csv"
basis = "time"

[experiment]
step = 0.5
stop = 1.0

[record]
signals = ["snk.v_out", "speeds.v"]
"#
    );
    let (sim, _) = b.run(&text);
    assert_close(last(&sim, "snk.v_out"), 20.0, 1e-14);
    // The replayed column is recorded in its own unit.
    assert_eq!(last(&sim, "speeds.v"), 72.0);
    assert_eq!(sim.recording().units().unwrap(), ["s", "m/s", "km/h"]);
}

#[test]
fn incompatible_or_unknown_units_are_refused() {
    let cases = [
        (
            "\"src.y_kmh -> snk.w\"",
            "incompatible units 'km/h' and 'rad/s' (different base units); a connection table with a scale converts what the units cannot",
        ),
        (
            "\"src.temp -> snk.v\"",
            "incompatible units 'degC' and 'm/s'",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", from_unit = \"furlong\" }",
            "from_unit = 'furlong' is defined neither by the FMU nor in twinbench's unit table (1, %, s,",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", to_unit = \"rad\" }",
            "incompatible units 'km/h' and 'rad'",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", scale = 2.0, to_unit = \"km/h\" }",
            "give either scale/offset or from_unit/to_unit, not both",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", scale = 0.0 }",
            "scale must be a finite non-zero number and offset a finite number, got scale = 0, offset = 0",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", offset = nan }",
            "got scale = 1, offset = NaN",
        ),
        (
            "{ from = \"src.count\", to = \"snk.n\", scale = 2.0 }",
            "a scale, an offset or a unit applies to Real inputs only, this one is Integer",
        ),
        (
            "{ from = \"src.y_kmh\", to = \"snk.v\", gain = 2.0 }",
            "connection table: unknown field `gain`",
        ),
    ];
    // Each error names the system file.
    Bench::new().refuses(&cases, &["system.toml"], |connection| {
        link(connection, "\"snk.v_out\"")
    });
}
