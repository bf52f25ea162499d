//! A deliberately faulty FMU for tests of hosts: `y` integrates `gain·u`, and at
//! `fault_time` the model does what `fault_kind` says.

use fmu_export::variables::*;
use fmu_export::{
    Context, DefaultExperiment, Model, ModelError, ModelInfo, ModelState, StateReader, StateWriter,
};

fmu_export::variables! {
    /// Variables of the faulty test model.
    pub struct FaultyVars {
        gain: Real = 1.0 => tunable(1).unit("1").range(-1e6, 1e6).describe("Integrator gain"),
        fault_kind: Integer = 0 => parameter(2).range(0.0, 9.0)
            .describe("0 none, 1 return an error, 2 panic, 3 output NaN, 4 abort the process, 5 never return, 6 error in initialization, 7 discard the step, 8 fatal error, 9 error in fmi2Terminate"),
        fault_time: Real = 1.0 => parameter(3).unit("s").describe("Time from which the fault occurs"),
        u: Real = 0.0 => input(4).unit("1").describe("Integrator input"),
        y: Real = 0.0 => output(5).unit("s").describe("Integral of gain·u"),
        steps: Integer = 0 => discrete_output(6).describe("Steps taken"),
        y_direct: Real = 0.0 => output(7).unit("1").depends_on(&[u])
            .describe("gain·u: direct feed-through of the input"),
        tag: String = "" => discrete_input(8).describe("A text input (for hosts' tests of String variables)"),
        tag_out: String = "" => discrete_output(9).depends_on(&[tag])
            .describe("tag and the steps taken, e.g. \"lap 3\" after 3 steps of tag \"lap\""),
    }
}

#[derive(Clone, Debug)]
pub struct Faulty {
    y: f64,
    steps: i32,
}

impl Model for Faulty {
    type Vars = FaultyVars;
    const INFO: ModelInfo = ModelInfo {
        name: "faulty",
        identifier: "faulty",
        description: "Integrator that fails on purpose, for host tests",
        version: env!("CARGO_PKG_VERSION"),
        default_experiment: DefaultExperiment { start_time: 0.0, stop_time: 2.0, step_size: 1e-3 },
        documentation: "<p>y(t) = ∫ gain·u dt. At <code>fault_time</code> the step fails as <code>fault_kind</code> says.</p>",
        resources: &[],
    };

    fn initialize(vars: &mut FaultyVars, _ctx: &Context) -> Result<Self, ModelError> {
        if vars.fault_kind == 6 {
            return Err(ModelError::new(
                "fault_kind = 6: initialization fails on purpose",
            ));
        }
        vars.y = 0.0;
        vars.steps = 0;
        Ok(Faulty { y: 0.0, steps: 0 })
    }

    fn do_step(&mut self, vars: &mut FaultyVars, time: f64, step: f64) -> Result<(), ModelError> {
        if time + step > vars.fault_time + 1e-12 {
            match vars.fault_kind {
                1 => return Err(ModelError::new("fault_kind = 1: the step fails on purpose")),
                2 => panic!("fault_kind = 2: the model panics on purpose"),
                3 => {
                    vars.y = f64::NAN;
                    return Ok(());
                }
                4 => std::process::abort(),
                5 => loop {
                    std::thread::sleep(std::time::Duration::from_secs(3600));
                },
                7 => {
                    return Err(ModelError::discard(
                        "fault_kind = 7: the step is discarded on purpose",
                    ))
                }
                8 => {
                    return Err(ModelError::fatal(
                        "fault_kind = 8: a fatal error on purpose",
                    ))
                }
                _ => {}
            }
        }
        self.y += vars.gain * vars.u * step;
        self.steps += 1;
        vars.y = self.y;
        vars.steps = self.steps;
        Ok(())
    }

    fn terminate(&mut self, vars: &FaultyVars) -> Result<(), ModelError> {
        if vars.fault_kind == 9 {
            return Err(ModelError::new(
                "fault_kind = 9: fmi2Terminate fails on purpose",
            ));
        }
        Ok(())
    }

    fn calculate_outputs(&mut self, vars: &mut FaultyVars) {
        vars.y_direct = vars.gain * vars.u;
        vars.tag_out = format!("{} {}", vars.tag, self.steps);
    }
}

impl ModelState for Faulty {
    fn save_state(&self, w: &mut StateWriter) {
        w.f64(self.y);
        w.i32(self.steps);
    }

    fn load_state(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        self.y = r.f64()?;
        self.steps = r.i32()?;
        Ok(())
    }
}

#[cfg(feature = "fmu")]
fmu_export::export_fmu!(crate::Faulty);

#[cfg(test)]
mod tests {
    use super::*;
    use fmu_export::{NullLogger, Runtime, Value};

    #[test]
    fn table_is_consistent() {
        fmu_export::description::validate_table::<FaultyVars>().unwrap();
    }

    #[test]
    fn integrates_and_fails_at_fault_time() {
        let mut rt = Runtime::<Faulty>::new("f", None, Box::new(NullLogger), false);
        assert_eq!(rt.set_by_name("fault_kind", Value::Integer(1)).0, 0);
        rt.setup_experiment(0.0, None);
        rt.enter_initialization_mode();
        rt.set_by_name("u", Value::Real(2.0));
        assert_eq!(rt.exit_initialization_mode().0, 0);
        for k in 0..10 {
            assert_eq!(rt.do_step(k as f64 * 0.1, 0.1).0, 0);
        }
        assert!((rt.get_by_name("y").unwrap().as_f64() - 2.0).abs() < 1e-12);
        assert_eq!(rt.do_step(1.0, 0.1).0, 3);
        assert_eq!(rt.phase(), fmu_export::Phase::Error);
    }

    fn run_to_fault(kind: i32) -> (Runtime<Faulty>, fmu_export::fmi2::fmi2Status) {
        let mut rt = Runtime::<Faulty>::new("f", None, Box::new(NullLogger), false);
        assert_eq!(rt.set_by_name("fault_kind", Value::Integer(kind)).0, 0);
        rt.setup_experiment(0.0, None);
        rt.enter_initialization_mode();
        assert_eq!(rt.exit_initialization_mode().0, 0);
        for k in 0..10 {
            assert_eq!(rt.do_step(k as f64 * 0.1, 0.1).0, 0);
        }
        let s = rt.do_step(1.0, 0.1);
        (rt, s)
    }

    #[test]
    fn discard_keeps_the_instance_usable_at_the_last_good_time() {
        let (mut rt, s) = run_to_fault(7);
        assert_eq!(s, fmu_export::fmi2::fmi2Status::DISCARD);
        assert_eq!(rt.phase(), fmu_export::Phase::StepComplete);
        assert!((rt.time() - 1.0).abs() < 1e-12);
        assert_eq!(rt.get_by_name("steps").unwrap().as_f64(), 10.0);
        assert_eq!(rt.terminate().0, 0);
    }

    #[test]
    fn fatal_poisons_the_instance_until_reset() {
        let (mut rt, s) = run_to_fault(8);
        assert_eq!(s, fmu_export::fmi2::fmi2Status::FATAL);
        assert_eq!(rt.phase(), fmu_export::Phase::Error);
        assert_eq!(rt.do_step(1.0, 0.1).0, 3);
        assert_eq!(rt.reset().0, 0);
    }
}
