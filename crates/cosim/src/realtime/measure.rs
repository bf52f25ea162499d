//! The worker's half of a real-time check: the measured steps.

use super::{CheckSpec, Counts, Measurement, SlowStep, TimeStats};
use crate::backend::Backend;
use std::time::Instant;
use tb_fmi::FmuError;

/// Steps the initialised instance `i` as `spec` says, the counters armed around each step's
/// FMI calls only (everything else here, from the inputs' interpolation to the clock, is
/// outside the armed window). An FMU's error ends the check with that error.
pub fn measure(i: &mut dyn Backend, spec: &CheckSpec) -> Result<Measurement, FmuError> {
    let mut m = Measurement {
        allocations_seen: tb_rtcount::interposed(),
        ..Default::default()
    };
    if !m.allocations_seen {
        m.notes.push(
            "allocations were not counted: the worker is not the twinbench executable".into(),
        );
    }
    if spec.count_syscalls {
        match super::trap::install() {
            Ok(()) => m.syscalls_seen = true,
            Err(why) => m
                .notes
                .push(format!("system calls were not counted: {why}")),
        }
    }
    let total = spec.steps as usize * spec.passes.max(1) as usize;
    // Every buffer made before the first step: nothing below grows.
    let mut times: Vec<u32> = Vec::with_capacity(total);
    let mut noise: Vec<u32> = Vec::with_capacity(total);
    let mut slowest: Vec<SlowStep> = Vec::with_capacity(6);
    let mut inputs = vec![0.0; spec.inputs.vrs.len()];
    let mut outputs = vec![0.0; spec.outputs.len()];
    tb_rtcount::reset();
    for pass in 0..spec.passes.max(1) {
        if pass > 0 {
            if let Err(e) = i.reset().and_then(|()| initialise(i, spec)) {
                m.notes.push(format!(
                    "{pass} pass(es) of {}: the instance could not be reset for another ({e})",
                    spec.passes
                ));
                break;
            }
        }
        let mut cursor = 0;
        for k in 0..spec.steps {
            let t = spec.start + k as f64 * spec.step;
            spec.inputs.at(t, &mut cursor, &mut inputs);
            let t0 = Instant::now();
            tb_rtcount::arm();
            let result = one_step(i, spec, t, &inputs, &mut outputs);
            tb_rtcount::disarm();
            let dt = t0.elapsed().as_nanos().min(u32::MAX as u128) as u32;
            result?;
            times.push(dt);
            // The same around nothing: what the clock and the machine add.
            let n0 = Instant::now();
            tb_rtcount::arm();
            tb_rtcount::disarm();
            noise.push(n0.elapsed().as_nanos().min(u32::MAX as u128) as u32);
            keep_slowest(&mut slowest, pass, t, dt);
        }
        m.passes = pass + 1;
    }
    m.counts = Counts::from_snapshot(&tb_rtcount::snapshot());
    m.step_time = TimeStats::of(&mut times);
    m.noise = TimeStats::of(&mut noise);
    m.slowest = slowest;
    Ok(m)
}

/// One step as a real-time target makes it: the inputs set, `doStep`, the outputs read.
fn one_step(
    i: &mut dyn Backend,
    spec: &CheckSpec,
    t: f64,
    inputs: &[f64],
    outputs: &mut [f64],
) -> Result<(), FmuError> {
    if !inputs.is_empty() {
        i.set_real(&spec.inputs.vrs, inputs)?;
    }
    i.do_step(t, spec.step)?;
    if !outputs.is_empty() {
        i.get_real(&spec.outputs, outputs)?;
    }
    Ok(())
}

/// Set up, the spec's Real parameters set, and initialised at `start` with the inputs
/// there: the host's first initialisation and every pass after a reset.
pub fn initialise(i: &mut dyn Backend, spec: &CheckSpec) -> Result<(), FmuError> {
    i.setup_experiment(tb_fmi::Experiment::from(spec.start))?;
    let (vrs, values): (Vec<u32>, Vec<f64>) = spec.parameters.iter().copied().unzip();
    if !vrs.is_empty() {
        i.set_real(&vrs, &values)?;
    }
    i.enter_initialization_mode()?;
    let mut inputs = vec![0.0; spec.inputs.vrs.len()];
    spec.inputs.at(spec.start, &mut 0, &mut inputs);
    if !inputs.is_empty() {
        i.set_real(&spec.inputs.vrs, &inputs)?;
    }
    i.exit_initialization_mode()
}

/// Keeps the five slowest steps, slowest first (capacity 6: no allocation).
fn keep_slowest(slowest: &mut Vec<SlowStep>, pass: u32, t: f64, ns: u32) {
    let seconds = ns as f64 * 1e-9;
    if slowest.len() == 5 && slowest[4].seconds >= seconds {
        return;
    }
    let at = slowest
        .iter()
        .position(|s| s.seconds < seconds)
        .unwrap_or(slowest.len());
    slowest.insert(at, SlowStep { pass, t, seconds });
    slowest.truncate(5);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::realtime::Inputs;

    #[test]
    fn inputs_are_linear_between_rows_and_held_beyond() {
        let inp = Inputs {
            vrs: vec![1, 2],
            time: vec![0.0, 1.0, 3.0],
            columns: vec![vec![0.0, 10.0, 30.0], vec![5.0, 5.0, -5.0]],
        };
        let mut out = [0.0; 2];
        let mut c = 0;
        for (t, a, b) in [
            (-1.0, 0.0, 5.0),
            (0.5, 5.0, 5.0),
            (2.0, 20.0, 0.0),
            (3.0, 30.0, -5.0),
            (9.0, 30.0, -5.0),
        ] {
            inp.at(t, &mut c, &mut out);
            assert!(
                (out[0] - a).abs() < 1e-12 && (out[1] - b).abs() < 1e-12,
                "{t}: {out:?}"
            );
        }
        // A step back (a new pass) starts the search again.
        inp.at(0.5, &mut c, &mut out);
        assert!((out[0] - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_five_slowest_are_kept_slowest_first() {
        let mut s = Vec::with_capacity(6);
        for (k, ns) in [5u32, 1, 9, 3, 7, 8, 2, 10].iter().enumerate() {
            keep_slowest(&mut s, 0, k as f64, *ns);
        }
        let kept: Vec<f64> = s.iter().map(|x| x.seconds * 1e9).collect();
        assert_eq!(
            kept.iter().map(|x| x.round() as u32).collect::<Vec<_>>(),
            [10, 9, 8, 7, 5]
        );
        assert_eq!(s.capacity(), 6);
    }

    #[test]
    fn time_quantiles_count_from_the_top() {
        let mut ns: Vec<u32> = (1..=10_000).collect();
        let t = TimeStats::of(&mut ns);
        assert_eq!(t.steps, 10_000);
        assert!((t.median - 5000e-9).abs() < 1e-15);
        assert!((t.p99_9 - 9990e-9).abs() < 1e-15);
        assert!((t.p99_99 - 9999e-9).abs() < 1e-15);
        assert!((t.max - 10_000e-9).abs() < 1e-15);
    }
}
