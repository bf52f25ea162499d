//! The stop condition: when a run ends (a time, or `signal OP threshold` holding after a
//! step), and stage "stop" that resolves it. The operators are one list ([`Op::ALL`]):
//! parsing, printing and evaluating all read it, and `tools/fmpy_cosim.py`'s parser is
//! tested against it (`tests/stop_condition_parsers.rs`).

use super::instances::Units;
use super::{Endpoint, SignalTable};
use crate::config::{ExperimentConfig, StopConfig};
use crate::{invalid, SystemError};
use std::fmt;
use tb_fmi::ScalarType;

/// How a condition compares the signal with its threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    AtLeast,
    AtMost,
    Above,
    Below,
}

impl Op {
    /// Every operator (adding one here adds it to parsing, printing and the docs' list).
    pub const ALL: [Op; 4] = [Op::AtLeast, Op::AtMost, Op::Above, Op::Below];

    pub fn symbol(self) -> &'static str {
        match self {
            Op::AtLeast => ">=",
            Op::AtMost => "<=",
            Op::Above => ">",
            Op::Below => "<",
        }
    }

    #[inline]
    pub fn holds(self, x: f64, threshold: f64) -> bool {
        match self {
            Op::AtLeast => x >= threshold,
            Op::AtMost => x <= threshold,
            Op::Above => x > threshold,
            Op::Below => x < threshold,
        }
    }

    /// The symbols, for messages: `>=, <=, >, <`.
    pub fn symbols() -> String {
        Op::ALL.map(Op::symbol).join(", ")
    }
}

/// `signal OP threshold`, e.g. `vehicle.lap >= 1`.
#[derive(Clone, Debug, PartialEq)]
pub struct Condition {
    pub signal: String,
    /// The signal's exchange slot.
    pub slot: usize,
    pub op: Op,
    pub threshold: f64,
}

impl Condition {
    /// Parse `instance.variable OP number` (OP one of [`Op::ALL`]; where one symbol starts
    /// another, `>=` before `>`, the longer is tried first).
    pub fn parse(text: &str) -> Option<(String, Op, f64)> {
        let mut ops = Op::ALL;
        ops.sort_by_key(|op| std::cmp::Reverse(op.symbol().len()));
        for op in ops {
            if let Some((a, b)) = text.split_once(op.symbol()) {
                let signal = a.trim();
                let threshold: f64 = b.trim().parse().ok()?;
                if crate::split_name(signal).is_none() || !threshold.is_finite() {
                    return None;
                }
                return Some((signal.to_string(), op, threshold));
            }
        }
        None
    }

    #[inline]
    pub fn holds(&self, x: f64) -> bool {
        self.op.holds(x, self.threshold)
    }
}

impl fmt::Display for Condition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {} {}", self.signal, self.op.symbol(), self.threshold)
    }
}

/// When a run ends.
#[derive(Clone, Debug, PartialEq)]
pub enum Stop {
    /// At this time (the last step clamped to it).
    Time(f64),
    /// When the condition holds after a step; an error after `max_time` of simulated time.
    When { condition: Condition, max_time: f64 },
}

/// Stage "stop": the experiment's stop time, or its condition resolved to a slot.
pub(super) fn stop(
    experiment: &ExperimentConfig,
    units: Units<'_>,
    signals: &mut SignalTable,
    ctx_file: &str,
) -> Result<Stop, SystemError> {
    let w = match &experiment.stop {
        StopConfig::Time(t) => return Ok(Stop::Time(*t)),
        StopConfig::Word(w) => w,
    };
    let (ctx, text) = if w == "lap" {
        let signal = experiment.lap_signal.as_deref().ok_or_else(|| {
            invalid(
                ctx_file,
                "stop = \"lap\" needs lap_signal (or write the condition: stop = \"vehicle.lap >= 1\")",
            )
        })?;
        (
            "experiment.lap_signal",
            format!("{signal} >= {}", experiment.lap_count),
        )
    } else {
        ("experiment.stop", w.clone())
    };
    let (signal, op, threshold) = Condition::parse(&text).ok_or_else(|| {
        invalid(
            ctx_file,
            format!(
                "experiment.stop must be a time in s or a condition such as \"vehicle.lap >= 1\" (operators {}), got \"{w}\"",
                Op::symbols()
            ),
        )
    })?;
    let max_time = experiment.max_time;
    if !(max_time.is_finite() && max_time > 0.0) {
        return Err(invalid(
            ctx_file,
            format!("experiment.max_time must be a positive number of seconds, got {max_time}"),
        ));
    }
    let e = units.endpoint(&format!("{ctx_file}: {ctx}"), &signal)?;
    if let Endpoint::Fmu {
        ty: ScalarType::String,
        ..
    } = e
    {
        return Err(invalid(
            format!("{ctx_file}: {ctx}"),
            format!("'{signal}' is a String; a stop condition compares a number"),
        ));
    }
    Ok(Stop::When {
        condition: Condition {
            slot: signals.slot(&e, &signal),
            signal,
            op,
            threshold,
        },
        max_time,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions_parse_and_hold() {
        let (s, op, t) = Condition::parse(" vehicle.lap >= 1 ").unwrap();
        assert_eq!((s.as_str(), op, t), ("vehicle.lap", Op::AtLeast, 1.0));
        let c = Condition {
            signal: s,
            slot: 0,
            op,
            threshold: t,
        };
        assert!(c.holds(1.0) && !c.holds(0.999));
        assert_eq!(c.to_string(), "vehicle.lap >= 1");
        assert_eq!(Condition::parse("x.y < -2.5").unwrap().1, Op::Below);
        for bad in [
            "lap",
            "vehicle.lap >= ",
            "lap >= 1",
            "a.b >= nan",
            "a.b = 1",
        ] {
            assert!(Condition::parse(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn every_operator_parses_prints_and_holds_as_its_symbol_says() {
        for op in Op::ALL {
            let text = format!("a.b {} 2", op.symbol());
            let (_, parsed, t) = Condition::parse(&text).unwrap();
            assert_eq!((parsed, t), (op, 2.0), "{text}");
            // What the symbol means, on both sides of the threshold and at it.
            for x in [1.0, 2.0, 3.0] {
                let expected = match op.symbol() {
                    ">=" => x >= 2.0,
                    "<=" => x <= 2.0,
                    ">" => x > 2.0,
                    "<" => x < 2.0,
                    s => panic!("a new operator {s}: say here what it means"),
                };
                assert_eq!(op.holds(x, 2.0), expected, "{text} at {x}");
            }
        }
    }
}
