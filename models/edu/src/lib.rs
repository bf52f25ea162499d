//! twinbench reference electric drive unit (EDU): motor with torque and power limit and a
//! current-loop lag, one-stage gearbox with efficiency, open differential, two side shafts
//! as torsional spring-dampers. A stand-in for a supplier's EDU FMU.

use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo, ModelState};

fmu_export::variables! {
    /// Variables of the EDU model.
    pub struct EduVars {
        torque_max: Real = 150.0 => parameter(1).unit("N.m").range(0.0, 1e5)
            .describe("Motor torque limit at the motor shaft"),
        power_max: Real = 200000.0 => parameter(2).unit("W").range(0.0, 1e8)
            .describe("Motor mechanical power limit at the motor shaft (after motor losses)"),
        motor_efficiency: Real = 0.9 => parameter(3).unit("1").range(0.1, 1.0)
            .describe("Motor + inverter efficiency: electric = mechanical / eta when motoring, mechanical x eta when generating"),
        gear_ratio: Real = 17.86 => parameter(4).unit("1").range(0.1, 100.0)
            .describe("Gearbox ratio, motor speed / differential case speed"),
        gearbox_efficiency: Real = 0.96 => parameter(5).unit("1").range(0.1, 1.0)
            .describe("Gearbox efficiency, applied in the direction of the power flow"),
        motor_inertia: Real = 0.01 => parameter(6).unit("kg.m2").range(1e-6, 100.0)
            .describe("Rotor inertia (with the gearbox input side)"),
        current_time_constant: Real = 0.001 => parameter(7).unit("s").range(1e-6, 1.0)
            .describe("Time constant of the first-order current (torque) loop"),
        shaft_stiffness: Real = 12000.0 => parameter(8).unit("N.m/rad").range(1.0, 1e8)
            .describe("Torsional stiffness of each side shaft"),
        shaft_damping: Real = 40.0 => parameter(9).unit("N.m.s/rad").range(0.01, 1e6)
            .describe("Torsional damping of each side shaft"),
        omega_wheel_start: Real = 151.97 => parameter(10).unit("rad/s").range(-2000.0, 2000.0)
            .describe("Initial wheel-side speed: the motor starts at gear_ratio x this with untwisted shafts (default: the vehicle's v_start / wheel_radius)"),
        substep_max: Real = 1e-4 => parameter(11).unit("s").range(1e-6, 0.01)
            .describe("Largest internal integration step"),
        range_check: Integer = 1 => parameter(12).range(0.0, 1.0)
            .describe("An input outside its declared range (beyond a float32 rounding): 1 refuses it with fmi2Error, 0 uses it with a warning"),

        accel_pedal: Real = 0.0 => input(50).unit("1").range(-1.0, 1.0)
            .describe("Torque request as a share of the available torque; 0..1 drives, negative values request regenerative braking"),
        omega_left: Real = 0.0 => input(51).unit("rad/s")
            .describe("Left side shaft speed at the wheel side (from the dyno)"),
        omega_right: Real = 0.0 => input(52).unit("rad/s")
            .describe("Right side shaft speed at the wheel side (from the dyno)"),

        torque_left: Real = 0.0 => output(100).unit("N.m").depends_on(&[omega_left, omega_right])
            .describe("Left side shaft torque at the wheel side, positive drives the wheel forward"),
        torque_right: Real = 0.0 => output(101).unit("N.m").depends_on(&[omega_left, omega_right])
            .describe("Right side shaft torque at the wheel side, positive drives the wheel forward"),
        motor_speed: Real = 0.0 => output(102).unit("rad/s").describe("Motor speed"),
        motor_torque: Real = 0.0 => output(103).unit("N.m").describe("Motor air-gap torque (after the current-loop lag)"),
        electric_power: Real = 0.0 => output(104).unit("W")
            .describe("Electric power drawn from the battery (negative when generating)"),
        mechanical_power: Real = 0.0 => output(105).unit("W").describe("Motor shaft power, motor_torque x motor_speed"),
        shaft_power: Real = 0.0 => output(106).unit("W").depends_on(&[omega_left, omega_right])
            .describe("Power delivered to the wheels: torque_left x omega_left + torque_right x omega_right"),
        torque_limit: Real = 0.0 => output(107).unit("N.m")
            .describe("Motor torque available at the present speed: min(torque_max, power_max / |motor_speed|)"),
        shaft_twist_left: Real = 0.0 => local(108).unit("rad").describe("Twist of the left side shaft"),
        shaft_twist_right: Real = 0.0 => local(109).unit("rad").describe("Twist of the right side shaft"),
    }
}

/// A side-shaft torque beyond this many times torque_max x gear_ratio is divergence.
const DIVERGENCE_FACTOR: f64 = 10.0;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Params {
    torque_max: f64,
    power_max: f64,
    eta_motor: f64,
    ratio: f64,
    eta_gear: f64,
    j_motor: f64,
    tau_current: f64,
    c: f64,
    d: f64,
    substep_max: f64,
}

impl Params {
    fn from_vars(x: &EduVars) -> Params {
        Params {
            torque_max: x.torque_max,
            power_max: x.power_max,
            eta_motor: x.motor_efficiency,
            ratio: x.gear_ratio,
            eta_gear: x.gearbox_efficiency,
            j_motor: x.motor_inertia,
            tau_current: x.current_time_constant,
            c: x.shaft_stiffness,
            d: x.shaft_damping,
            substep_max: x.substep_max,
        }
    }

    fn torque_limit(&self, omega_m: f64) -> f64 {
        if omega_m == 0.0 {
            self.torque_max
        } else {
            self.torque_max.min(self.power_max / omega_m.abs())
        }
    }

    /// Gearbox input torque [N·m] needed for the output torque `t_out` at case speed
    /// `omega_c`: losses always reduce the power that arrives, whichever way it flows.
    fn gearbox_input_torque(&self, t_out: f64, omega_c: f64) -> f64 {
        if t_out * omega_c >= 0.0 {
            t_out / (self.ratio * self.eta_gear) // motor drives the wheels
        } else {
            t_out * self.eta_gear / self.ratio // wheels drive the motor
        }
    }

    fn electric_power(&self, mechanical: f64) -> f64 {
        if mechanical >= 0.0 {
            mechanical / self.eta_motor
        } else {
            mechanical * self.eta_motor
        }
    }
}

fmu_export::states! {
    /// Dynamic state. The differential's side gears are massless, so the two shaft torques are
    /// always equal; the twists are kept as their mean and their difference.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct State for Edu.st {
        omega_m: f64,
        torque_m: f64,
        /// Mean twist (φ_l + φ_r)/2 [rad].
        twist_mean: f64,
        /// Twist difference φ_l − φ_r [rad].
        twist_diff: f64,
    }
}

#[derive(Clone, Debug)]
pub struct Edu {
    p: Params,
    st: State,
}

impl Edu {
    /// Torque in each side shaft for wheel-side speeds `wl`, `wr`.
    fn shaft_torque(&self, wl: f64, wr: f64) -> f64 {
        let omega_c = self.st.omega_m / self.p.ratio;
        self.p.c * self.st.twist_mean + self.p.d * (omega_c - 0.5 * (wl + wr))
    }

    fn substep(&mut self, h: f64, pedal: f64, wl: f64, wr: f64) {
        let p = self.p;
        let t_shaft = self.shaft_torque(wl, wr);
        let omega_c = self.st.omega_m / p.ratio;
        let t_in = p.gearbox_input_torque(2.0 * t_shaft, omega_c);
        let st = &mut self.st;
        st.omega_m += h * (st.torque_m - t_in) / p.j_motor;
        // Semi-implicit: the twist sees the updated motor speed (keeps the shaft mode stable).
        st.twist_mean += h * (st.omega_m / p.ratio - 0.5 * (wl + wr));
        // Equal torques force d·(dΔ/dt) = −c·Δ: the difference relaxes, solved exactly.
        st.twist_diff *= (-p.c / p.d * h).exp();
        let limit = p.torque_limit(st.omega_m);
        let command = pedal * limit;
        let lagged = command + (st.torque_m - command) * (-h / p.tau_current).exp();
        // Clamp at the limit of the new speed: the lag must not carry torque past it.
        st.torque_m = lagged.clamp(-limit, limit);
    }
}

impl Model for Edu {
    type Vars = EduVars;
    const INFO: ModelInfo = ModelInfo::new("edu", "Reference electric drive unit: motor with torque/power limit and current-loop lag, gearbox with efficiency, open differential, side shafts as spring-dampers", env!("CARGO_PKG_VERSION"))
        .experiment(10.0, 1e-3)
        .documentation(DOCUMENTATION);

    fn initialize(vars: &mut EduVars, _ctx: &Context) -> Result<Self, ModelError> {
        let p = Params::from_vars(vars);
        let st = State {
            omega_m: p.ratio * vars.omega_wheel_start,
            torque_m: 0.0,
            twist_mean: 0.0,
            twist_diff: 0.0,
        };
        Ok(Edu { p, st })
    }

    fn internal_steps(&self, step: f64) -> f64 {
        step / self.p.substep_max
    }

    fn do_step(&mut self, vars: &mut EduVars, _time: f64, step: f64) -> Result<(), ModelError> {
        // A step a rounding unit longer than a multiple of substep_max (a host's nanosecond
        // clock) must not cost an extra sub-step.
        let n = (step / self.p.substep_max * (1.0 - 1e-9)).ceil().max(1.0);
        let h = step / n;
        let (pedal, wl, wr) = (vars.accel_pedal, vars.omega_left, vars.omega_right);
        for _ in 0..n as usize {
            self.substep(h, pedal, wl, wr);
        }
        if !(self.st.omega_m.is_finite() && self.st.twist_mean.is_finite()) {
            return Err(ModelError::new(format!(
                "the EDU state diverged (motor_speed = {}, twist = {}); check the wheel-speed inputs and substep_max",
                self.st.omega_m, self.st.twist_mean
            )));
        }
        // Divergence found early: a side-shaft torque many times what the motor can deliver
        // is no physical state but a host's coupling going unstable (a parallel master's
        // communication step too long for the shaft stiffness against the dyno inertia).
        let torque = self.shaft_torque(wl, wr); // both shafts carry the same torque
        let bound = DIVERGENCE_FACTOR * self.p.torque_max * self.p.ratio;
        if torque.abs() > bound {
            return Err(ModelError::new(format!(
                "side-shaft torque {torque:.4e} N.m exceeds {DIVERGENCE_FACTOR}x the motor's largest wheel torque ({bound:.4e} N.m = {DIVERGENCE_FACTOR} x torque_max x gear_ratio): the EDU-dyno coupling is diverging; the communication step ({step} s) is too long for a parallel (Jacobi) master with this shaft stiffness (see the EDU's documentation for the stable steps): use a shorter step or a sequential (Gauss-Seidel) master"
            )));
        }
        Ok(())
    }

    fn calculate_outputs(&mut self, x: &mut EduVars) {
        let st = &self.st;
        let t = self.shaft_torque(x.omega_left, x.omega_right);
        x.torque_left = t;
        x.torque_right = t;
        x.motor_speed = st.omega_m;
        x.motor_torque = st.torque_m;
        x.mechanical_power = st.torque_m * st.omega_m;
        x.electric_power = self.p.electric_power(x.mechanical_power);
        x.shaft_power = t * (x.omega_left + x.omega_right);
        x.torque_limit = self.p.torque_limit(st.omega_m);
        x.shaft_twist_left = st.twist_mean + 0.5 * st.twist_diff;
        x.shaft_twist_right = st.twist_mean - 0.5 * st.twist_diff;
    }
}

impl ModelState for Edu {}

const DOCUMENTATION: &str = r#"
<h2>Reference electric drive unit</h2>
<p>Motor, one-stage gearbox, open differential and two side shafts. Inputs are the pedal and
the wheel-side shaft speeds (measured at the dynos); outputs the side-shaft torques that drive
the dynos. Signs: positive torque drives the wheels forward.</p>
<h3>Motor</h3>
<pre>
T_avail   = min(torque_max, power_max / |ω_m|)
T_cmd     = accel_pedal · T_avail            (accel_pedal &lt; 0: regenerative torque)
τ_i·dT_m/dt = T_cmd − T_m,  |T_m| ≤ T_avail(ω_m)   (current loop, τ_i = current_time_constant)
J_m·dω_m/dt = T_m − T_in
P_el = T_m·ω_m / η_m  when motoring,  T_m·ω_m · η_m  when generating   (η_m = motor_efficiency)
</pre>
<p>torque_max and power_max hold at the motor shaft (after the motor losses): with the defaults
150 N·m and 200 kW, the battery delivers up to 222 kW.</p>
<h3>Gearbox and open differential</h3>
<pre>
ω_c = ω_m / i                                         (i = gear_ratio)
T_out = T_left + T_right
T_in = T_out / (i·η_g)   when T_out·ω_c ≥ 0 (motor drives the wheels)
T_in = T_out·η_g / i     otherwise (wheels drive the motor)
</pre>
<p>The losses always take power away from the flow, so shaft power = P_el·η_m·η_g when
motoring and P_el/(η_m·η_g) when braking. The differential's side gears are massless: both
side shafts carry the same torque at all times.</p>
<h3>Side shafts</h3>
<pre>
T_left = T_right = c·(φ_l + φ_r)/2 + d·(ω_c − (ω_left + ω_right)/2)
d(φ_l + φ_r)/dt = 2ω_c − ω_left − ω_right,   d·d(φ_l − φ_r)/dt = −c·(φ_l − φ_r)
</pre>
<p>c = <code>shaft_stiffness</code>, d = <code>shaft_damping</code> (each shaft). The shaft
torques depend directly on the speed inputs through the damper (declared feed-through).</p>
<h3>Numerics and start</h3>
<p>Equal sub-steps of at most <code>substep_max</code> (0.1 ms), semi-implicit in the motor/shaft
mode; the current lag and the twist difference are solved exactly per sub-step. The run starts
with ω_m = i·<code>omega_wheel_start</code>, untwisted shafts and zero motor torque.</p>
<h3>Communication step in a host</h3>
<p>The side shafts couple the motor to the dyno's inertia through a stiff spring
(12 000 N·m/rad against 0.8 kg·m²): a host that exchanges the shaft speeds and torques only
once per communication step must keep that step short. Measured on the Spielberg lap of the
virtual bench (vehicle, driver, two dynos, this EDU; the lap is 98.116 s at 1 ms):</p>
<table>
<tr><th>master</th><th>lap within 0.01 s</th><th>completes, but the lap is wrong</th><th>diverges</th></tr>
<tr><td>sequential (Gauss-Seidel: dyno, then EDU)</td><td>up to 1.5 ms (2 ms: 0.02 s off, 4 ms: 0.07 s)</td><td>10 ms (110.8 s)</td><td>20 ms</td></tr>
<tr><td>parallel (Jacobi, FMPy <code>simulate_ssp</code>, libcosim)</td><td>up to 1.5 ms</td><td>2–4 ms (97.9 s to 133 s)</td><td>5 ms and above</td></tr>
</table>
<p>Divergence is stopped early: a side-shaft torque above 10 × <code>torque_max</code> ×
<code>gear_ratio</code> ends the step with <code>fmi2Error</code> and a message naming the
coupling (at 5 ms with a parallel master: at t = 0.2 s, long before an overflow).</p>
"#;

#[cfg(feature = "fmu")]
fmu_export::export_fmu!(crate::Edu);
