//! Load dynamometer of the powertrain bench, one instance per driven wheel.
//!
//! The rotor (rotor + adapter + tyre part, `inertia`) is driven by the EDU's side shaft
//! and braked by the air-gap torque: `J·dω/dt = shaft_torque − torque_dyno`. The dyno's
//! controller runs at `cycle_time`: each tick it forms a torque demand (the setpoint in
//! torque control, a PI on the speed error in speed control), the demand passes a dead
//! time (plus optional seeded jitter) and a first- or second-order lag to become the
//! air-gap torque. Lag and rotor are integrated exactly between ticks.

mod lag;

use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo, ModelState};
use lag::LagStep;

fmu_export::variables! {
    /// Variables of the dyno.
    pub struct DynoVars {
        shaft_torque: Real = 0.0 => input(1).unit("N.m")
            .describe("Side-shaft torque driving the rotor (from the EDU)"),
        torque_setpoint: Real = 0.0 => input(2).unit("N.m")
            .describe("Load torque setpoint in torque control (from the vehicle model; positive brakes the wheel)"),
        speed_setpoint: Real = 0.0 => input(3).unit("rad/s")
            .describe("Rotor speed setpoint in speed control (control_mode = 1)"),
        omega: Real = 0.0 => output(10).unit("rad/s")
            .describe("Rotor speed (speed sensor)"),
        torque_measured: Real = 0.0 => output(11).unit("N.m").init_depends_on(&[shaft_torque, torque_setpoint, speed_setpoint])
            .describe("Transducer torque at the drive side: torque_dyno + (inertia − inertia_drive_side)·dω/dt"),
        torque_dyno: Real = 0.0 => output(12).unit("N.m").init_depends_on(&[torque_setpoint, speed_setpoint])
            .describe("Air-gap torque the dyno applies (after dead time, lag and limit)"),
        inertia: Real = 0.8 => parameter(20).unit("kg.m2").range(1e-4, 1e3)
            .describe("Rotating inertia on the speed sensor: rotor + adapter + tyre part"),
        inertia_drive_side: Real = 0.0 => parameter(21).unit("kg.m2").range(0.0, 1e3)
            .describe("Part of inertia between side shaft and torque transducer (must not exceed inertia)"),
        omega_start: Real = 0.0 => parameter(22).unit("rad/s").range(-2e4, 2e4)
            .describe("Rotor speed at the start time"),
        dead_time: Real = 5e-4 => parameter(23).unit("s").range(0.0, 0.1)
            .describe("Control-loop dead time from demand to air-gap torque (fractions of a cycle interpolate)"),
        time_constant: Real = 1e-3 => tunable(24).unit("s").range(0.0, 1.0)
            .describe("Lag time constant (order 2: 1/natural frequency); 0: no lag"),
        lag_order: Integer = 1 => parameter(25).range(1.0, 2.0)
            .describe("Order of the torque lag: 1 first order, 2 second order with damping"),
        damping: Real = 0.7 => tunable(26).unit("1").range(0.05, 10.0)
            .describe("Damping ratio of the second-order lag"),
        cycle_time: Real = 1e-4 => parameter(27).unit("s").range(1e-6, 0.01)
            .describe("Dyno controller cycle: demand sampled, delayed and applied every cycle"),
        jitter: Real = 0.0 => parameter(28).unit("s").range(0.0, 0.01)
            .describe("Bound of the per-cycle random dead-time variation (uniform in ±jitter); 0: none"),
        jitter_seed: Integer = 1 => parameter(29).range(0.0, 2147483647.0)
            .describe("Seed of the jitter sequence (same seed, same sequence)"),
        torque_max: Real = 3000.0 => tunable(30).unit("N.m").range(0.0, 1e5)
            .describe("Limit of the torque demand, both directions"),
        control_mode: Integer = 0 => tunable(31).range(0.0, 1.0)
            .describe("0 torque control (torque_setpoint), 1 speed control (PI on speed_setpoint)"),
        speed_kp: Real = 100.0 => tunable(32).unit("N.m.s/rad").range(0.0, 1e6)
            .describe("Speed controller proportional gain"),
        speed_ki: Real = 2500.0 => tunable(33).unit("N.m/rad").range(0.0, 1e9)
            .describe("Speed controller integral gain"),
        inertia_compensation: Boolean = false => parameter(34)
            .describe("Torque control: subtract (inertia − emulated_inertia)·dω/dt from the demand so the rotor behaves like emulated_inertia"),
        emulated_inertia: Real = 0.8 => parameter(35).unit("kg.m2").range(1e-4, 1e3)
            .describe("Wheel inertia the rotor emulates with inertia_compensation"),
        dead_time_compensation: Boolean = false => parameter(36)
            .describe("Extrapolate the demand by dead_time along its slope over prediction_window"),
        prediction_window: Real = 1e-3 => parameter(37).unit("s").range(1e-6, 0.1)
            .describe("Window of the demand slope used by dead_time_compensation (at least one macro step)"),
        torque_demand: Real = 0.0 => local(50).unit("N.m")
            .describe("Controller's torque demand this cycle, before dead time and lag"),
    }
}

/// Ticks closer than this fraction of a cycle to an instant count as at that instant.
const TICK_EPS: f64 = 1e-9;

#[derive(Clone, Debug)]
pub struct Dyno {
    // Fixed from parameters at initialisation.
    cycle: f64,
    inertia: f64,
    rotor_share: f64,
    dead_cycles: f64,
    max_delay_cycles: f64,
    jitter_cycles: f64,
    window_cycles: usize,
    lag_cycle: LagStep,
    st: DynoState,
}

fmu_export::states! {
    /// The dyno's dynamic state. The tick clock's origin is in it: a deserializing host
    /// re-initialises at another time.
    #[derive(Clone, Debug, PartialEq)]
    pub struct DynoState for Dyno.st {
        start_time: f64,
        tick: u64,
        omega: f64,
        omega_prev_tick: f64,
        lag_x: f64,
        lag_dx: f64,
        lag_input: f64,
        integral: f64,
        last_mode: i32,
        rng: u64,
        /// Demands of past ticks (after compensation and limit); `hist_head` is the newest.
        hist: Vec<f64>,
        hist_head: usize,
        /// Raw demands for the dead-time compensation's slope.
        raw: Vec<f64>,
        raw_head: usize,
    }
}

/// SplitMix64: tiny, seedable, good enough for a bounded timing jitter.
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Round to an integer when within floating-point noise of it (0.5 ms / 0.1 ms is 5).
fn snap(x: f64) -> f64 {
    if (x - x.round()).abs() < 1e-9 {
        x.round()
    } else {
        x
    }
}

impl Dyno {
    fn tick_time(&self) -> f64 {
        // Through i64: one conversion instruction (tick < 2^63, the same value as u64's).
        self.st.start_time + self.st.tick as i64 as f64 * self.cycle
    }

    fn clip(x: f64, limit: f64) -> f64 {
        x.clamp(-limit, limit)
    }

    /// Speed PI: positive error (too slow) needs less load torque.
    fn speed_demand(&self, vars: &DynoVars) -> f64 {
        -vars.speed_kp * (vars.speed_setpoint - self.st.omega) + self.st.integral
    }

    /// One controller cycle at the current tick time: form the demand, push it into the
    /// dead-time line and read the delayed value as the lag's new input.
    fn controller_tick(&mut self, vars: &mut DynoVars) {
        let alpha = (self.st.omega - self.st.omega_prev_tick) / self.cycle;
        self.st.omega_prev_tick = self.st.omega;
        let limit = vars.torque_max;

        let raw = if vars.control_mode == 1 {
            if self.st.last_mode != 1 {
                // Bumpless switch: the integrator takes over the demand in force.
                self.st.integral = self.st.hist[self.st.hist_head]
                    + vars.speed_kp * (vars.speed_setpoint - self.st.omega);
            }
            let demand = self.speed_demand(vars);
            let error = vars.speed_setpoint - self.st.omega;
            // Anti-windup: integrate only while the demand is inside the limit or the
            // error pulls it back in.
            let pushes_out = (demand >= limit && error < 0.0) || (demand <= -limit && error > 0.0);
            if !pushes_out {
                self.st.integral =
                    Self::clip(self.st.integral - vars.speed_ki * error * self.cycle, limit);
            }
            demand
        } else {
            let mut demand = vars.torque_setpoint;
            if vars.inertia_compensation {
                demand -= (self.inertia - vars.emulated_inertia) * alpha;
            }
            demand
        };
        self.st.last_mode = vars.control_mode;

        let mut demand = raw;
        if vars.dead_time_compensation {
            let n = self.st.raw.len();
            self.st.raw_head = wrap_next(self.st.raw_head, n);
            self.st.raw[self.st.raw_head] = raw;
            let oldest = self.st.raw[wrap_next(self.st.raw_head, n)];
            let slope = (raw - oldest) / (self.window_cycles as f64 * self.cycle);
            demand += slope * self.dead_cycles * self.cycle;
        }
        let demand = Self::clip(demand, limit);
        vars.torque_demand = demand;

        let n = self.st.hist.len();
        self.st.hist_head = wrap_next(self.st.hist_head, n);
        self.st.hist[self.st.hist_head] = demand;

        let mut delay = self.dead_cycles;
        if self.jitter_cycles > 0.0 {
            let u = (splitmix64(&mut self.st.rng) >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
            delay += self.jitter_cycles * (2.0 * u - 1.0);
        }
        let delay = delay.clamp(0.0, self.max_delay_cycles);
        // delay >= 0: truncation is floor (no libm call), and the ring indices below stay in
        // [0, 2n), so one conditional subtraction wraps them (no division per tick).
        let i = delay as usize;
        let frac = delay - i as f64;
        let newer = self.st.hist[wrap_back(self.st.hist_head + n - i, n)];
        self.st.lag_input = if frac > 0.0 {
            let older = self.st.hist[wrap_back(self.st.hist_head + n - i - 1, n)];
            newer + frac * (older - newer)
        } else {
            newer
        };
        self.st.tick += 1;
    }

    /// `n` whole cycles from the tick at `t` to `end` in plain torque control (no
    /// compensation, no jitter, no switch of mode): [`Dyno::controller_tick`] and
    /// [`Dyno::advance`] with what does not change within the step worked out once (the
    /// clipped demand, the delay's index and fraction). The same operations on the same
    /// values as the general path, so the same bits. Returns `end`.
    fn whole_cycles_torque_control(
        &mut self,
        vars: &mut DynoVars,
        n: u64,
        t: f64,
        end: f64,
    ) -> f64 {
        let demand = Self::clip(vars.torque_setpoint, vars.torque_max);
        vars.torque_demand = demand;
        let delay = self.dead_cycles.clamp(0.0, self.max_delay_cycles);
        let i = delay as usize;
        let frac = delay - i as f64;
        let len = self.st.hist.len();
        let first_order = match self.lag_cycle {
            LagStep::First { a, b } if vars.lag_order != 2 => Some((a, b)),
            _ => None,
        };
        let (start, cycle, inertia, shaft) = (
            self.st.start_time,
            self.cycle,
            self.inertia,
            vars.shaft_torque,
        );
        // The state in locals: the delay line's stores cannot alias them.
        let mut head = self.st.hist_head;
        let mut tick = self.st.tick;
        let mut omega = self.st.omega;
        let mut lag_x = self.st.lag_x;
        let mut lag_dx = self.st.lag_dx;
        let mut lag_input = self.st.lag_input;
        let mut t = t;
        for k in 1..=n {
            self.st.omega_prev_tick = omega;
            head = wrap_next(head, len);
            self.st.hist[head] = demand;
            let newer = self.st.hist[wrap_back(head + len - i, len)];
            lag_input = if frac > 0.0 {
                let older = self.st.hist[wrap_back(head + len - i - 1, len)];
                newer + frac * (older - newer)
            } else {
                newer
            };
            tick += 1;
            let t_next = if k == n {
                end
            } else {
                start + tick as i64 as f64 * cycle
            };
            let dt = t_next - t;
            match first_order {
                // LagStep::advance of the cycle's first-order step and the rotor, written out.
                Some((a, b)) if (dt - cycle).abs() <= TICK_EPS * cycle => {
                    let e = lag_x - lag_input;
                    lag_x = lag_input + e * a;
                    lag_dx = 0.0;
                    let torque_integral = lag_input * dt + e * b;
                    omega += (shaft * dt - torque_integral) / inertia;
                }
                _ => {
                    (
                        self.st.omega,
                        self.st.lag_x,
                        self.st.lag_dx,
                        self.st.lag_input,
                    ) = (omega, lag_x, lag_dx, lag_input);
                    self.advance(vars, dt);
                    (omega, lag_x, lag_dx) = (self.st.omega, self.st.lag_x, self.st.lag_dx);
                }
            }
            t = t_next;
        }
        self.st.hist_head = head;
        self.st.tick = tick;
        (
            self.st.omega,
            self.st.lag_x,
            self.st.lag_dx,
            self.st.lag_input,
        ) = (omega, lag_x, lag_dx, lag_input);
        t
    }

    /// Integrate lag and rotor over `dt` with the lag input and shaft torque held.
    #[inline(always)]
    fn advance(&mut self, vars: &DynoVars, dt: f64) {
        let full = (dt - self.cycle).abs() <= TICK_EPS * self.cycle;
        let step = if full {
            self.lag_cycle
        } else {
            LagStep::new(vars.lag_order, vars.time_constant, vars.damping, dt)
        };
        let torque_integral = step.advance(
            &mut self.st.lag_x,
            &mut self.st.lag_dx,
            self.st.lag_input,
            dt,
        );
        if vars.lag_order == 2 && self.st.lag_x.abs() > vars.torque_max {
            // A second-order overshoot cannot exceed the drive's torque limit.
            self.st.lag_x = Self::clip(self.st.lag_x, vars.torque_max);
            self.st.lag_dx = 0.0;
        }
        self.st.omega += (vars.shaft_torque * dt - torque_integral) / self.inertia;
    }
}

impl Model for Dyno {
    type Vars = DynoVars;
    const INFO: ModelInfo = ModelInfo::new("dyno", "Load dynamometer: rotor inertia, controller cycle, dead time, torque lag, torque or speed control", env!("CARGO_PKG_VERSION"))
        .experiment(1.0, 1e-3)
        .documentation(DOCUMENTATION);

    fn initialize(vars: &mut DynoVars, ctx: &Context) -> Result<Self, ModelError> {
        if vars.inertia_drive_side > vars.inertia {
            return Err(ModelError::new(format!(
                "inertia_drive_side = {} kg.m2 exceeds inertia = {} kg.m2",
                vars.inertia_drive_side, vars.inertia
            )));
        }
        let cycle = vars.cycle_time;
        let dead_cycles = snap(vars.dead_time / cycle);
        let jitter_cycles = snap(vars.jitter / cycle);
        let max_delay_cycles = dead_cycles + jitter_cycles;
        // Room for the oldest sample an interpolated read can touch.
        let hist_len = max_delay_cycles.ceil() as usize + 2;
        let window_cycles = (vars.prediction_window / cycle).round().max(1.0) as usize;

        let mut dyno = Dyno {
            cycle,
            inertia: vars.inertia,
            rotor_share: (vars.inertia - vars.inertia_drive_side) / vars.inertia,
            dead_cycles,
            max_delay_cycles,
            jitter_cycles,
            window_cycles,
            lag_cycle: LagStep::new(vars.lag_order, vars.time_constant, vars.damping, cycle),
            st: DynoState {
                start_time: ctx.start_time,
                tick: 0,
                omega: vars.omega_start,
                omega_prev_tick: vars.omega_start,
                lag_x: 0.0,
                lag_dx: 0.0,
                lag_input: 0.0,
                integral: 0.0,
                last_mode: vars.control_mode,
                // Seed 0 is as good as any other through SplitMix64's scrambling.
                rng: (vars.jitter_seed as u64) ^ 0x5EED_D1E0_0000_0000,
                hist: vec![0.0; hist_len],
                hist_head: 0,
                raw: vec![0.0; window_cycles + 1],
                raw_head: 0,
            },
        };
        // Start in equilibrium with the inputs at the start: the demand has been constant
        // for as long as the dead time and lag remember.
        let raw = if vars.control_mode == 1 {
            dyno.st.integral = Dyno::clip(vars.shaft_torque, vars.torque_max);
            dyno.speed_demand(vars)
        } else {
            vars.torque_setpoint
        };
        let demand = Dyno::clip(raw, vars.torque_max);
        dyno.st.hist.fill(demand);
        dyno.st.raw.fill(raw);
        dyno.st.lag_x = demand;
        dyno.st.lag_input = demand;
        vars.torque_demand = demand;
        Ok(dyno)
    }

    fn internal_steps(&self, step: f64) -> f64 {
        step / self.cycle
    }

    fn do_step(&mut self, vars: &mut DynoVars, time: f64, step: f64) -> Result<(), ModelError> {
        let eps = TICK_EPS * self.cycle;
        let end = time + step;
        let mut t = time;
        if self.tick_time() < t - self.cycle - eps {
            // The host skipped time (not a contiguous run): resume at the next tick.
            self.st.tick = ((t - self.st.start_time) / self.cycle - TICK_EPS)
                .ceil()
                .max(0.0) as u64;
        }
        // The bench's usual case: the step starts on a tick and spans whole controller cycles
        // (1 ms over 0.1 ms): tick, then integrate to the next tick, n times, without
        // locating ticks. The sub-steps are the general loop's below, to the bit (the same
        // tick times, the last one ending at `end`), so either path gives the same result.
        // The nearest whole number of cycles (without libm's round: the check of the tick
        // at `end` below decides whether n is right).
        let n = (step / self.cycle + 0.5) as u64;
        if n >= 1
            && (self.tick_time() - t).abs() <= eps
            && (self.st.start_time + (self.st.tick + n) as i64 as f64 * self.cycle - end).abs()
                <= eps
        {
            if vars.control_mode == 0
                && self.st.last_mode == 0
                && !vars.inertia_compensation
                && !vars.dead_time_compensation
                && self.jitter_cycles == 0.0
            {
                t = self.whole_cycles_torque_control(vars, n, t, end);
            } else {
                for i in 1..=n {
                    self.controller_tick(vars);
                    let t_next = if i == n { end } else { self.tick_time() };
                    self.advance(vars, t_next - t);
                    t = t_next;
                }
            }
        }
        loop {
            // A tick exactly at the end belongs to the next step, with its new inputs.
            if end - t <= eps {
                break;
            }
            let tick_at = self.tick_time();
            if tick_at <= t + eps {
                self.controller_tick(vars);
                continue;
            }
            let t_next = if tick_at < end - eps { tick_at } else { end };
            self.advance(vars, t_next - t);
            t = t_next;
        }
        if !self.st.omega.is_finite() || !self.st.lag_x.is_finite() {
            return Err(ModelError::new(format!(
                "non-finite state (omega = {}, torque_dyno = {})",
                self.st.omega, self.st.lag_x
            )));
        }
        Ok(())
    }

    fn calculate_outputs(&mut self, vars: &mut DynoVars) {
        vars.omega = self.st.omega;
        vars.torque_dyno = self.st.lag_x;
        // The rotor part behind the transducer needs (J_rotor/J)(shaft − T_dyno) to accelerate.
        vars.torque_measured =
            self.st.lag_x + self.rotor_share * (vars.shaft_torque - self.st.lag_x);
    }

    fn parameters_changed(&mut self, vars: &DynoVars) -> Result<(), ModelError> {
        self.lag_cycle = LagStep::new(vars.lag_order, vars.time_constant, vars.damping, self.cycle);
        Ok(())
    }
}

impl ModelState for Dyno {
    /// The buffers' lengths follow from dead_time, jitter, cycle_time and
    /// prediction_window: a state of other ones is refused.
    fn state_loaded(&mut self) -> Result<(), ModelError> {
        let st = &self.st;
        // As initialize sizes them.
        let (hist_len, raw_len) = (
            self.max_delay_cycles.ceil() as usize + 2,
            self.window_cycles + 1,
        );
        if st.hist.len() != hist_len
            || st.raw.len() != raw_len
            || st.hist_head >= hist_len
            || st.raw_head >= raw_len
        {
            return Err(ModelError::new(
                "serialized dyno state does not match dead_time, jitter, cycle_time or prediction_window",
            ));
        }
        Ok(())
    }
}

const DOCUMENTATION: &str = r#"
<p>A load dynamometer of the powertrain bench, one instance per driven wheel. Sign
convention: <code>shaft_torque</code> drives the rotor, <code>torque_dyno</code> (and its
setpoint) brakes it.</p>
<h3>Rotor</h3>
<p class="eq">J·dω/dt = shaft_torque − torque_dyno,&nbsp;&nbsp; J = <code>inertia</code>
(rotor + adapter + tyre part), ω(start) = <code>omega_start</code></p>
<h3>Controller</h3>
<p>The controller runs every <code>cycle_time</code> T<sub>c</sub> (default 0.1 ms, ten
cycles per 1 ms macro step; the model sub-steps each macro step at the ticks). A tick at
a communication point uses the inputs set for the step that starts there. Each tick forms
the demand T<sub>dem</sub>:</p>
<ul>
<li><code>control_mode</code> = 0 (torque control): T<sub>dem</sub> = torque_setpoint; with
<code>inertia_compensation</code> T<sub>dem</sub> −= (J − J<sub>emul</sub>)·α̂, α̂ the speed
difference of the last cycle over T<sub>c</sub>, so that the rotor obeys
J<sub>emul</sub>·dω/dt = shaft_torque − torque_setpoint (the compensation torque drives
the rotor, hence the minus on a load torque).</li>
<li><code>control_mode</code> = 1 (speed control): T<sub>dem</sub> = −k<sub>p</sub>·e + I,
dI/dt = −k<sub>i</sub>·e, e = speed_setpoint − ω; conditional integration as anti-windup
when the demand is at <code>torque_max</code>; the integrator starts at the shaft torque
(equilibrium) and takes over the demand on a switch of mode.</li>
<li><code>dead_time_compensation</code>: T<sub>dem</sub> += T<sub>d</sub>·(T<sub>raw,k</sub> −
T<sub>raw,k−n</sub>)/(n·T<sub>c</sub>), n·T<sub>c</sub> = <code>prediction_window</code>: the
demand is extrapolated along its slope by the dead time (exact on ramps; it amplifies
steps by T<sub>d</sub>/window, so keep the window at least one macro step).</li>
<li>T<sub>dem</sub> is clipped to ±<code>torque_max</code>.</li>
</ul>
<h3>Dead time, jitter, lag</h3>
<p>The demand passes a delay line: the lag's input at tick k is T<sub>dem</sub> at
t<sub>k</sub> − T<sub>d,k</sub>, with T<sub>d,k</sub> = <code>dead_time</code> + δ<sub>k</sub>,
δ<sub>k</sub> uniform in [−jitter, +jitter] from a SplitMix64 sequence seeded by
<code>jitter_seed</code> (deterministic, bounded), clipped at 0. A dead time that is not a
whole number of cycles interpolates linearly between the stored samples, so
<code>dead_time</code> is a continuous parameter for identification. The delay line is
allocated at initialisation.</p>
<p>The air-gap torque follows the delayed demand u, held between ticks, through
<code>lag_order</code> 1: τ·dT/dt = u − T, or 2: d²T/dt² = ω<sub>n</sub>²(u − T) −
2ζω<sub>n</sub>·dT/dt with ω<sub>n</sub> = 1/τ, ζ = <code>damping</code>; τ =
<code>time_constant</code>, 0 for none. Both the lag and the rotor speed are integrated
exactly (zero-order-hold transition and its integral), so any macro step gives the same
response at the ticks. A second-order overshoot is clipped at <code>torque_max</code>.</p>
<p>Step response (torque control, defaults): the air-gap torque stays at its old value for
0.5 ms, then rises as 1 − e<sup>−(t − 0.5 ms)/1 ms</sup>.</p>
<h3>Transducer</h3>
<p class="eq">torque_measured = torque_dyno + (J − J<sub>drive side</sub>)·dω/dt</p>
<p>The transducer sits between <code>inertia_drive_side</code> (default 0: all of the
inertia is behind it, so it reads the shaft torque) and the rest of the rotor. Outputs at a
communication point are the values at the end of the step, with the step's inputs held
(no direct feed-through).</p>
<h3>Defaults</h3>
<p>dead time 0.5 ms, time constant 1 ms, cycle 0.1 ms, inertia 0.8 kg·m², torque limit
3000 N·m; speed PI k<sub>p</sub> = 100 N·m·s/rad, k<sub>i</sub> = 2500 N·m/rad (about 20 Hz
speed loop crossover with 0.8 kg·m²; scale both with the inertia).</p>
"#;

#[cfg(feature = "fmu")]
fmu_export::export_fmu!(crate::Dyno);

/// Next index of a ring of length `n`.
#[inline]
fn wrap_next(i: usize, n: usize) -> usize {
    if i + 1 == n {
        0
    } else {
        i + 1
    }
}

/// An index in `[0, 2n)` wrapped into the ring of length `n`.
#[inline]
fn wrap_back(j: usize, n: usize) -> usize {
    if j >= n {
        j - n
    } else {
        j
    }
}

#[cfg(test)]
mod tests;
