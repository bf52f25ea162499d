//! Stage "experiment": the time axis of a run checked before anything is loaded: a
//! positive finite step, a finite start, a stop after it, a step count the master can
//! count, a decimation of at least one.

use super::MAX_STEPS;
use crate::config::{StopConfig, SystemFile};
use crate::{invalid, SystemError};

pub(super) fn check(file: &SystemFile, ctx_file: &str) -> Result<(), SystemError> {
    let e = &file.experiment;
    if !(e.step > 0.0 && e.step.is_finite()) {
        return Err(invalid(
            ctx_file,
            format!(
                "experiment.step must be positive, got {}",
                tb_files::number(e.step)
            ),
        ));
    }
    if !e.start.is_finite() {
        return Err(invalid(
            ctx_file,
            format!("experiment.start must be a finite time, got {}", e.start),
        ));
    }
    match &e.stop {
        StopConfig::Time(t) if !t.is_finite() => {
            return Err(invalid(
                ctx_file,
                format!("experiment.stop must be a finite time, got {t}"),
            ))
        }
        StopConfig::Time(t) if *t <= e.start || t.is_nan() => {
            return Err(invalid(
                ctx_file,
                format!("experiment.stop {t} is not after start {}", e.start),
            ))
        }
        _ => {}
    }
    // The step count of the run (the stop time, or max_time with a condition) must be a
    // number the master can count: beyond it (or infinite: a subnormal step, a stop time
    // near the largest double) the count would wrap and run nothing. (An infinite
    // max_time is refused with the stop condition.)
    let span = match &e.stop {
        StopConfig::Time(t) => t - e.start,
        StopConfig::Word(_) => e.max_time,
    };
    let steps = span / e.step;
    let (step_s, span_s) = (tb_files::number(e.step), tb_files::number(span));
    // The master drops a last step shorter than 1e-9 of a step (rounding): a step that
    // much longer than the whole run would run nothing and report success.
    if matches!(e.stop, StopConfig::Time(_)) && span > 0.0 && span <= e.step * 1e-9 {
        return Err(invalid(
            ctx_file,
            format!("experiment.step = {step_s} s is longer than the whole run ({span_s} s): not one step would be taken"),
        ));
    }
    if span.is_finite() && (steps.is_nan() || steps > MAX_STEPS) {
        return Err(invalid(
            ctx_file,
            format!("experiment.step = {step_s} s over {span_s} s is {steps:.3e} macro steps, more than {MAX_STEPS:.0e}: a larger step"),
        ));
    }
    if let Some(t) = e.tolerance {
        super::instances::check_tolerance(t, &format!("{ctx_file}: experiment.tolerance"))?;
    }
    if file.record.decimation == 0 {
        return Err(invalid(ctx_file, "record.decimation must be at least 1"));
    }
    Ok(())
}
