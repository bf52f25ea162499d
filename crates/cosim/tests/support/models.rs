//! The test models: small enough that every result can be written down exactly.
//!
//! - `gain`: y = k·u, a direct feed-through (declared), no units;
//! - `integrator`: x' = u by explicit Euler (exact for binary fractions), x and the step
//!   count as outputs, no feed-through; fails on purpose when |x| exceeds `x_max` (> 0);
//! - `source`: constant and counting outputs of every type and of several units;
//! - `sink`: an input of every type, each fed through to an output, and parameters of
//!   every type (a range, an Enumeration, a `_file` path read at initialisation).

use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo};

const fn info(name: &'static str, description: &'static str) -> ModelInfo {
    ModelInfo::new(name, description, "1").experiment(1.0, 0.125)
}

fmu_export::variables! {
    /// Variables of `gain`.
    pub struct GainVars {
        k: Real = 2.0 => tunable(1).range(-1000.0, 1000.0).describe("Gain"),
        u: Real = 0.0 => input(2).describe("Input"),
        y: Real = 0.0 => output(3).depends_on(&[u]).describe("k·u"),
    }
}

/// y = k·u.
#[derive(Clone, Debug)]
pub struct Gain;

impl Model for Gain {
    type Vars = GainVars;
    const INFO: ModelInfo = info("gain", "y = k·u");

    fn initialize(v: &mut GainVars, _ctx: &Context) -> Result<Self, ModelError> {
        v.y = v.k * v.u;
        Ok(Gain)
    }
    fn do_step(&mut self, v: &mut GainVars, _t: f64, _h: f64) -> Result<(), ModelError> {
        v.y = v.k * v.u;
        Ok(())
    }
    fn calculate_outputs(&mut self, v: &mut GainVars) {
        v.y = v.k * v.u;
    }
}

impl fmu_export::Stateless for Gain {}

fmu_export::variables! {
    /// Variables of `integrator`.
    pub struct IntegratorVars {
        x0: Real = 0.0 => parameter(1).unit("m").describe("Initial value"),
        x_max: Real = 0.0 => parameter(2).unit("m").describe("|x| above it fails the step (0: no limit)"),
        u: Real = 0.0 => input(3).unit("m/s").describe("Rate"),
        x: Real = 0.0 => output(4).unit("m").describe("x0 + ∫u dt"),
        steps: Integer = 0 => discrete_output(5).describe("Steps taken"),
    }
}

/// x' = u, explicit Euler.
#[derive(Clone, Debug)]
pub struct Integrator;

impl Model for Integrator {
    type Vars = IntegratorVars;
    const INFO: ModelInfo = info("integrator", "x' = u");

    fn initialize(v: &mut IntegratorVars, _ctx: &Context) -> Result<Self, ModelError> {
        v.x = v.x0;
        v.steps = 0;
        Ok(Integrator)
    }
    fn do_step(&mut self, v: &mut IntegratorVars, t: f64, h: f64) -> Result<(), ModelError> {
        v.x += v.u * h;
        v.steps += 1;
        if v.x_max > 0.0 && v.x.abs() > v.x_max {
            return Err(ModelError::new(format!(
                "x = {} exceeds x_max = {} in the step from t = {t}",
                v.x, v.x_max
            )));
        }
        Ok(())
    }
    /// x and the step count are the integration's own: written by `do_step`.
    fn calculate_outputs(&mut self, _v: &mut IntegratorVars) {}
}

impl fmu_export::Stateless for Integrator {}

fmu_export::variables! {
    /// Variables of `source`.
    pub struct SourceVars {
        speed: Real = 36.0 => tunable(1).unit("km/h").describe("The speed given out"),
        prefix: String = "n" => parameter(2).describe("Head of the label"),
        y_kmh: Real = 0.0 => output(10).unit("km/h").describe("speed"),
        y_rpm: Real = 0.0 => output(11).unit("rpm").describe("speed's number, in rpm"),
        t: Real = 0.0 => output(12).unit("s").describe("Time at the end of the last step"),
        count: Integer = 0 => discrete_output(13).describe("Steps taken"),
        odd: Boolean = false => discrete_output(14).describe("An odd number of steps taken"),
        label: String = "" => discrete_output(15).describe("prefix and count"),
        gear: Integer = 1 => discrete_output(16).describe("1 + count mod 3 (an Enumeration in the FMU)"),
        // Its unit (degC) is the FMU's own, not in twinbench's table: set in the description
        // by the test support (`with_variable_units`), as the table accepts table units only.
        temp: Real = 25.0 => output(17).describe("A constant temperature"),
        share: Real = 50.0 => output(18).unit("%").describe("A constant share"),
    }
}

/// Outputs of every type.
#[derive(Clone, Debug)]
pub struct Source;

fn source_outputs(v: &mut SourceVars, t: f64) {
    v.y_kmh = v.speed;
    v.y_rpm = v.speed;
    v.t = t;
    v.odd = v.count % 2 == 1;
    v.label = format!("{}{}", v.prefix, v.count);
    v.gear = 1 + v.count % 3;
}

impl Model for Source {
    type Vars = SourceVars;
    const INFO: ModelInfo = info("source", "Outputs of every type");

    fn initialize(v: &mut SourceVars, ctx: &Context) -> Result<Self, ModelError> {
        v.count = 0;
        source_outputs(v, ctx.start_time);
        Ok(Source)
    }
    fn do_step(&mut self, v: &mut SourceVars, t: f64, h: f64) -> Result<(), ModelError> {
        v.count += 1;
        source_outputs(v, t + h);
        Ok(())
    }
    /// The outputs follow the step count and time: written by `do_step`.
    fn calculate_outputs(&mut self, _v: &mut SourceVars) {}
}

impl fmu_export::Stateless for Source {}

fmu_export::variables! {
    /// Variables of `sink`.
    pub struct SinkVars {
        v: Real = 0.0 => input(1).unit("m/s").describe("Speed"),
        w: Real = 0.0 => input(2).unit("rad/s").describe("Angular speed"),
        n: Integer = 0 => discrete_input(3).describe("A count"),
        on: Boolean = false => discrete_input(4).describe("A switch"),
        text: String = "" => discrete_input(5).describe("A text"),
        gear_in: Integer = 1 => discrete_input(6).describe("A gear (an Enumeration in the FMU)"),
        temp_k: Real = 0.0 => input(7).describe("A temperature (K, the FMU's own unit)"),
        x: Real = 0.0 => input(8).unit("1").describe("A number"),
        freq: Real = 0.0 => input(9).unit("Hz").describe("A frequency"),

        limit: Real = 1.0 => parameter(20).unit("m/s").range(0.0, 10.0).describe("A bounded Real"),
        level: Integer = 0 => parameter(21).range(0.0, 5.0).describe("A bounded Integer"),
        mode: Integer = 1 => parameter(22).describe("A mode (an Enumeration in the FMU)"),
        invert: Boolean = false => parameter(23).describe("Inverts on_out"),
        name: String = "sink" => parameter(24).describe("Head of text_out"),
        data_file: String = "" => parameter(25).describe("A file whose lines are counted"),

        v_out: Real = 0.0 => output(30).unit("m/s").depends_on(&[v]).describe("v"),
        w_out: Real = 0.0 => output(31).unit("rad/s").depends_on(&[w]).describe("w"),
        n_out: Integer = 0 => discrete_output(32).depends_on(&[n]).describe("n"),
        on_out: Boolean = false => discrete_output(33).depends_on(&[on]).describe("on xor invert"),
        text_out: String = "" => discrete_output(34).depends_on(&[text]).describe("name:text"),
        gear_out: Integer = 1 => discrete_output(35).depends_on(&[gear_in]).describe("gear_in"),
        temp_out: Real = 0.0 => output(36).depends_on(&[temp_k]).describe("temp_k (K)"),
        x_out: Real = 0.0 => output(37).unit("1").depends_on(&[x]).describe("x"),
        level_out: Integer = 0 => discrete_output(38).describe("level"),
        mode_out: Integer = 0 => discrete_output(39).describe("mode"),
        limit_out: Real = 0.0 => output(40).unit("m/s").describe("limit"),
        freq_out: Real = 0.0 => output(42).unit("Hz").depends_on(&[freq]).describe("freq"),
        file_lines: Integer = 0 => discrete_output(41).describe("Lines of data_file (0 without one)"),
    }
}

/// Inputs and parameters of every type, fed through.
#[derive(Clone, Debug)]
pub struct Sink;

fn sink_outputs(v: &mut SinkVars) {
    v.v_out = v.v;
    v.w_out = v.w;
    v.n_out = v.n;
    v.on_out = v.on != v.invert;
    v.text_out = format!("{}:{}", v.name, v.text);
    v.gear_out = v.gear_in;
    v.temp_out = v.temp_k;
    v.x_out = v.x;
    v.freq_out = v.freq;
}

impl Model for Sink {
    type Vars = SinkVars;
    const INFO: ModelInfo = info("sink", "Inputs of every type, fed through");

    fn initialize(v: &mut SinkVars, _ctx: &Context) -> Result<Self, ModelError> {
        v.file_lines = if v.data_file.is_empty() {
            0
        } else {
            let path = fmu_export::model::parameter_path("data_file", &v.data_file)?;
            let text = std::fs::read_to_string(&path)
                .map_err(|e| ModelError::new(format!("{}: {e}", path.display())))?;
            text.lines().count() as i32
        };
        v.level_out = v.level;
        v.mode_out = v.mode;
        v.limit_out = v.limit;
        sink_outputs(v);
        Ok(Sink)
    }
    fn do_step(&mut self, v: &mut SinkVars, _t: f64, _h: f64) -> Result<(), ModelError> {
        sink_outputs(v);
        Ok(())
    }
    fn calculate_outputs(&mut self, v: &mut SinkVars) {
        sink_outputs(v);
    }
}

impl fmu_export::Stateless for Sink {}
