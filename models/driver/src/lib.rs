//! Driver of the road-load simulation: follows a distance-based target speed `v(s)`.
//!
//! The target comes from a resource file (`target_speed.csv`, columns `s,v[,a]`). The driver
//! looks ahead by `preview_time`, feeds forward the target's acceleration `v·dv/ds` and
//! the driving resistance, closes a PI loop on the speed error, and turns the force demand
//! into exactly one pedal: the accelerator for a positive demand, the brake for a negative
//! one.

mod target;

use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo, ModelState, Resource};
use std::cell::Cell;
use std::sync::Arc;
pub use target::TargetSpeed;

/// Name of the target speed file in the FMU's `resources/`.
pub const TARGET_FILE: &str = "target_speed.csv";

/// The bundled target as the build script parsed it (`fmu_export::preparsed`; empty if the
/// bundled file does not parse, then the resource is parsed at run time and its error shown).
const TARGET_PREPARSED: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/target_speed.preparsed"));

const G: f64 = 9.81;

fmu_export::variables! {
    /// Variables of the driver.
    pub struct DriverVars {
        v: Real = 0.0 => input(1).unit("m/s").describe("Vehicle speed"),
        s: Real = 0.0 => input(2).unit("m")
            .describe("Distance along the track (may grow past the lap length or wrap at it)"),
        omega_rl: Real = 0.0 => input(3).unit("rad/s")
            .describe("Rear left (driven) wheel speed, for the traction limit (unconnected: 0, no limit)"),
        omega_rr: Real = 0.0 => input(4).unit("rad/s")
            .describe("Rear right (driven) wheel speed, for the traction limit (unconnected: 0, no limit)"),
        accel_pedal: Real = 0.0 => output(10).unit("1").range(0.0, 1.0)
            .describe("Accelerator pedal, 0..1 (share of the available drive force)"),
        brake_pedal: Real = 0.0 => output(11).unit("1").range(0.0, 1.0)
            .describe("Brake pedal, 0..1 (share of the full braking deceleration); never together with the accelerator"),
        v_target: Real = 0.0 => output(12).unit("m/s").init_depends_on(&[s])
            .describe("Target speed at the current distance s"),
        lap_length: Real = 0.0 => output(13).unit("m")
            .describe("Length of the target's lap (the last s of the target file)"),
        target_speed_file: String = "" => parameter(40)
            .describe("The target speed file (CSV with columns s, v): an absolute path or a file:// URI; empty: the bundled resources/target_speed.csv"),
        preview_time: Real = 0.0 => tunable(20).unit("s").range(0.0, 5.0)
            .describe("The driver takes the target's acceleration v·preview_time ahead (with preview_distance_min): the delay from pedal to tyre force it anticipates (0: the chain's few milliseconds are covered by preview_distance_min)"),
        preview_distance_min: Real = 1.0 => tunable(21).unit("m").range(0.0, 1000.0)
            .describe("Least preview distance (at low speed)"),
        speed_loop_bandwidth: Real = 1.5 => tunable(22).unit("Hz").range(0.01, 50.0)
            .describe("Crossover of the speed loop: proportional gain 2π·bandwidth on the speed error, in m/s2 per m/s"),
        integral_time: Real = 0.5 => tunable(23).unit("s").range(0.001, 1000.0)
            .describe("Integral time of the speed PI"),
        integral_limit: Real = 5.0 => tunable(24).unit("m/s2").range(0.0, 100.0)
            .describe("Bound of the PI's integral part (anti-windup besides conditional integration)"),
        feed_forward_gain: Real = 1.0 => tunable(25).unit("1").range(0.0, 2.0)
            .describe("Scale of the feed-forward (target acceleration and driving resistance); 0 turns it off"),
        mass: Real = 880.0 => tunable(26).unit("kg").range(1.0, 1e5)
            .describe("Vehicle mass the driver assumes"),
        drive_force_max: Real = 7450.0 => tunable(27).unit("N").range(1.0, 1e6)
            .describe("Drive force at full accelerator below the power limit (150 N.m · 17.86 · 0.96 / 0.345 m)"),
        drive_power_max: Real = 192000.0 => tunable(28).unit("W").range(1.0, 1e8)
            .describe("Drive power at full accelerator at the wheels (200 kW · 0.96)"),
        brake_decel_max: Real = 23.0 => tunable(29).unit("m/s2").range(0.1, 100.0)
            .describe("Deceleration at full brake pedal"),
        drag_area: Real = 1.1505 => tunable(30).unit("m2").range(0.0, 100.0)
            .describe("c_drag·A for the driving-resistance feed-forward"),
        rho_air: Real = 1.18 => tunable(31).unit("kg/m3").range(0.0, 10.0)
            .describe("Air density for the driving-resistance feed-forward"),
        f_roll: Real = 0.02 => tunable(32).unit("1").range(0.0, 1.0)
            .describe("Rolling resistance coefficient for the feed-forward"),
        wheel_radius: Real = 0.345 => tunable(33).unit("m").range(0.05, 2.0)
            .describe("Rolling radius of the driven wheels, for their slip"),
        slip_limit: Real = 0.12 => tunable(34).unit("1").range(0.0, 1.0)
            .describe("Traction limit: the driver eases the accelerator when a driven wheel's slip exceeds it, as a racing driver keeps the wheels at their grip (0: off)"),
        traction_gain: Real = 60.0 => tunable(35).unit("1/s").range(0.0, 1e4)
            .describe("How fast the accelerator's limit falls per unit of slip above slip_limit"),
        traction_recovery: Real = 4.0 => tunable(36).unit("1/s").range(0.0, 1e4)
            .describe("How fast the accelerator's limit returns to 1 while the slip is below slip_limit"),
        pedal_limit: Real = 1.0 => local(53).unit("1")
            .describe("The accelerator's present limit from the traction limit (1: none)"),
        v_preview: Real = 0.0 => local(50).unit("m/s")
            .describe("Target speed at the preview point"),
        a_target: Real = 0.0 => local(51).unit("m/s2")
            .describe("Target acceleration at the preview point, v·dv/ds"),
        a_demand: Real = 0.0 => local(52).unit("m/s2")
            .describe("Acceleration demand: feed-forward plus PI, before the pedals"),
    }
}

fmu_export::states! {
    /// The driver's dynamic state.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct DriverState for Driver.st {
        /// ∫ speed error dt [m], the PI's integral state.
        error_integral: f64,
        /// The accelerator's limit from the traction limit, 0..1.
        pedal_limit: f64,
    }
}

#[derive(Clone, Debug)]
pub struct Driver {
    target: Arc<TargetSpeed>,
    st: DriverState,
    /// Segments of the last target lookups at the car and at the preview point (search
    /// hints only: results do not depend on them).
    hint_here: Cell<usize>,
    hint_preview: Cell<usize>,
    /// The last [`Driver::targets`] and the bits of the inputs it came from (s, v,
    /// preview_time, preview_distance_min).
    last_targets: Cell<Option<([u64; 4], Targets)>>,
}

/// What the target asks at the car and at the preview point.
#[derive(Clone, Copy, Debug)]
struct Targets {
    v_preview: f64,
    a_target: f64,
    v_target: f64,
}

impl Driver {
    /// Proportional gain [1/s] of the speed loop: for the integrator plant dv/dt = a it
    /// puts the crossover at the bandwidth.
    fn kp(vars: &DriverVars) -> f64 {
        2.0 * std::f64::consts::PI * vars.speed_loop_bandwidth
    }

    fn integral_part(&self, vars: &DriverVars) -> f64 {
        Self::kp(vars) * self.st.error_integral / vars.integral_time
    }

    /// The traction limit over a step: the accelerator's limit falls while a driven wheel
    /// slips more than `slip_limit` and recovers while none does (a racing driver's throttle
    /// on a corner exit). Unconnected wheel speeds (0) read as no slip.
    fn traction(&mut self, vars: &DriverVars, step: f64) {
        if vars.slip_limit <= 0.0 {
            self.st.pedal_limit = 1.0;
            return;
        }
        let v = vars.v.max(1.0);
        let slip = (vars.omega_rl.max(vars.omega_rr) * vars.wheel_radius - v) / v;
        let change = if slip > vars.slip_limit {
            -vars.traction_gain * (slip - vars.slip_limit)
        } else {
            vars.traction_recovery
        };
        self.st.pedal_limit = (self.st.pedal_limit + change * step).clamp(0.0, 1.0);
    }

    /// Target at the preview point: (v_preview, a_target). The target's own acceleration
    /// where it carries one (a measured lap's a_x), else v·dv/ds of its speed.
    fn preview(&self, vars: &DriverVars) -> (f64, f64) {
        let distance = (vars.v.max(0.0) * vars.preview_time).max(vars.preview_distance_min);
        self.target
            .speed_and_acceleration_near(vars.s + distance, &self.hint_preview)
    }

    /// The target's numbers for the inputs in `vars`: (v_preview, a_target, v_target). A
    /// step asks twice for the same inputs (the pedals before the integral moves, the
    /// outputs after): the second answer is the first's, kept with the inputs it came from.
    fn targets(&self, vars: &DriverVars) -> Targets {
        let key = [
            vars.s.to_bits(),
            vars.v.to_bits(),
            vars.preview_time.to_bits(),
            vars.preview_distance_min.to_bits(),
        ];
        if let Some((k, t)) = self.last_targets.get() {
            if k == key {
                return t;
            }
        }
        let (v_preview, a_target) = self.preview(vars);
        let v_target = self.target.at_near(vars.s, &self.hint_here).0;
        let t = Targets {
            v_preview,
            a_target,
            v_target,
        };
        self.last_targets.set(Some((key, t)));
        t
    }

    /// Pedals from the state and the inputs in `vars`; writes every output. Returns the
    /// pedal saturation: +1 accelerator at its stop, −1 brake at its stop, 0 neither.
    fn write_outputs(&self, vars: &mut DriverVars) -> i32 {
        let Targets {
            v_preview: vp,
            a_target,
            v_target,
        } = self.targets(vars);
        let error = v_target - vars.v;
        let a_fb = Self::kp(vars) * error + self.integral_part(vars);
        let ff = vars.feed_forward_gain;
        let a_demand = ff * a_target + a_fb;
        let v = vars.v.max(0.0);
        let resistance = 0.5 * vars.rho_air * vars.drag_area * v * v + vars.f_roll * vars.mass * G;
        let force = vars.mass * a_demand + ff * resistance;
        // The accelerator scales the available force, which the power limit caps.
        let available = vars.drive_force_max.min(vars.drive_power_max / v.max(0.1));
        let (accel, brake) = if force >= 0.0 {
            (force / available, 0.0)
        } else {
            (0.0, -force / (vars.mass * vars.brake_decel_max))
        };
        vars.accel_pedal = accel.min(self.st.pedal_limit);
        vars.brake_pedal = brake.min(1.0);
        vars.pedal_limit = self.st.pedal_limit;
        vars.v_target = v_target;
        vars.v_preview = vp;
        vars.a_target = a_target;
        vars.a_demand = a_demand;
        if accel >= self.st.pedal_limit {
            1
        } else if brake >= 1.0 {
            -1
        } else {
            0
        }
    }
}

impl Model for Driver {
    type Vars = DriverVars;
    const INFO: ModelInfo = ModelInfo::new("driver", "Driver: follows a distance-based target speed with preview, feed-forward and PI, one pedal at a time", env!("CARGO_PKG_VERSION"))
        .experiment(10.0, 1e-3)
        .documentation(DOCUMENTATION)
        .resources(&[
            Resource::file(TARGET_FILE, include_bytes!("../resources/target_speed.csv")).default_of("target_speed_file"),
            Resource::file("NOTICE", include_bytes!("../resources/NOTICE")),
        ]);

    fn initialize(vars: &mut DriverVars, ctx: &Context) -> Result<Self, ModelError> {
        let target = if vars.target_speed_file.is_empty() {
            ctx.cached(TARGET_FILE, || {
                let (path, text) = ctx.read_resource(TARGET_FILE)?;
                // The bundled file as the build parsed it, unless it was changed since.
                let digest = fmu_export::preparsed::digest(text.as_bytes());
                match fmu_export::preparsed::decode(TARGET_PREPARSED, digest, 3)
                    .and_then(|v| TargetSpeed::from_values(&v))
                {
                    Some(target) => Ok(target),
                    None => TargetSpeed::parse(&text, &path.display().to_string()),
                }
            })?
        } else {
            let path = fmu_export::resources::parameter_path(
                "target_speed_file",
                &vars.target_speed_file,
            )?;
            fmu_export::resources::shared_file(&path, |p, text| {
                TargetSpeed::parse(text, &p.display().to_string())
            })?
        };
        vars.lap_length = target.lap_length();
        let driver = Driver {
            target,
            st: DriverState {
                error_integral: 0.0,
                pedal_limit: 1.0,
            },
            hint_here: Cell::new(0),
            hint_preview: Cell::new(0),
            last_targets: Cell::new(None),
        };
        Ok(driver)
    }

    fn do_step(&mut self, vars: &mut DriverVars, _time: f64, step: f64) -> Result<(), ModelError> {
        if !vars.v.is_finite() || !vars.s.is_finite() {
            return Err(ModelError::new(format!(
                "non-finite input: v = {}, s = {}",
                vars.v, vars.s
            )));
        }
        // Conditional integration: no integrating further into a pedal's stop (the pedals
        // before the integral moves; the outputs after it are calculate_outputs').
        let saturation = self.write_outputs(vars);
        let error = vars.v_target - vars.v;
        let winds_up = (saturation > 0 && error > 0.0) || (saturation < 0 && error < 0.0);
        if !winds_up {
            self.st.error_integral += error * step;
            let bound = vars.integral_limit * vars.integral_time / Self::kp(vars);
            self.st.error_integral = self.st.error_integral.clamp(-bound, bound);
        }
        self.traction(vars, step);
        Ok(())
    }

    fn calculate_outputs(&mut self, vars: &mut DriverVars) {
        self.write_outputs(vars);
    }
}

impl ModelState for Driver {}

const DOCUMENTATION: &str = r#"
<p>A driver for the RLS/v mode: it follows a <b>distance-based</b> target speed, so a
stronger or weaker powertrain drives the same lap.</p>
<h3>Target</h3>
<p><code>resources/target_speed.csv</code>: a header naming the columns <code>s</code> [m]
and <code>v</code> [m/s], optionally <code>a</code> [m/s²] (the car's own longitudinal
acceleration there, the feed-forward's a<sub>target</sub> in place of v·dv/ds: a measured
speed smoothed over 9 m rounds off every braking point, the measured acceleration does
not), then rows with strictly increasing s ≥ 0 (at least two; finite, v ≥ 0, |a| at most
100 m/s²). The target is piecewise linear in s and periodic: the lap length L is the last s
of the file and every position is taken modulo L, so the vehicle's <code>s</code> may keep
growing over several laps or wrap at L itself. The default file is the Spielberg lap of
<code>data/spielberg_lap.csv</code>, resampled every 1 m and smoothed over 3 m
(<code>twinbench lap</code> makes the same file for any measured lap; provenance in
<code>resources/NOTICE</code>). <code>target_speed_file</code> names another file. A
missing or malformed file fails the initialisation with the file and row named.</p>
<h3>Control law</h3>
<p class="eq">s<sub>p</sub> = s + max(v·t<sub>p</sub>, d<sub>min</sub>),&nbsp;
v<sub>p</sub> = v<sub>target</sub>(s<sub>p</sub>),&nbsp;
a<sub>target</sub> = a(s<sub>p</sub>) with a column <code>a</code>, else v<sub>p</sub>·dv<sub>target</sub>/ds(s<sub>p</sub>)</p>
<p class="eq">e = v<sub>p</sub> − v,&nbsp; a<sub>demand</sub> = k<sub>ff</sub>·a<sub>target</sub> +
k<sub>p</sub>·(e + ∫e dt / T<sub>i</sub>),&nbsp; k<sub>p</sub> = 2π·f<sub>bw</sub></p>
<p class="eq">F = m·a<sub>demand</sub> + k<sub>ff</sub>·(½·ρ·c<sub>d</sub>A·v² + f<sub>roll</sub>·m·g)</p>
<p class="eq">F ≥ 0: accel_pedal = min(1, F / min(F<sub>max</sub>, P<sub>max</sub>/v)), brake_pedal = 0;&nbsp;
F &lt; 0: brake_pedal = min(1, −F / (m·a<sub>brake,max</sub>)), accel_pedal = 0</p>
<p>t<sub>p</sub> = <code>preview_time</code> (0 s), d<sub>min</sub> =
<code>preview_distance_min</code> (1 m): the target's acceleration is taken where the car
is (1 m ahead: the few milliseconds from pedal to tyre force), so a target that is a car's
measured speed is followed as that car drove it, without the lag or lead a longer preview
gives (a preview of 0.2 s made the twin's a_x run 4 m behind a measured lap's; set it to
the delay of a slower powertrain), f<sub>bw</sub> = <code>speed_loop_bandwidth</code>
(1.5 Hz: for the plant dv/dt = a the loop crosses over there), T<sub>i</sub> =
<code>integral_time</code> (0.5 s), k<sub>ff</sub> = <code>feed_forward_gain</code>. The
feed-forward gains are the car's: <code>mass</code> 880 kg, <code>drive_force_max</code>
7450 N (150 N·m · 17.86 · 0.96 / 0.345 m), <code>drive_power_max</code> 192 kW (200 kW ·
0.96 at the wheels; the accelerator scales the available force as the EDU's pedal scales
its available torque), <code>brake_decel_max</code> 23 m/s², resistance with c<sub>d</sub>A =
1.1505 m², ρ = 1.18 kg/m³, f<sub>roll</sub> = 0.02 (downforce and grade are left to the
PI). Anti-windup: the integral stops while a pedal is at its stop and the error pushes
further, and its part is bounded by <code>integral_limit</code>.</p>
<h3>Traction</h3>
<p>As a racing driver keeps the driven wheels at their grip out of a corner, the
accelerator is limited: with the driven wheels' speeds <code>omega_rl</code>,
<code>omega_rr</code> and <code>wheel_radius</code> r, κ = (max ω·r − v)/max(v, 1 m/s);
while κ &gt; <code>slip_limit</code> (0.12, about the tyres' peak) the limit falls at
<code>traction_gain</code>·(κ − slip_limit) per second, otherwise it returns to 1 at
<code>traction_recovery</code> per second; accel_pedal = min(pedal, limit). Unconnected wheel
speeds read as no slip; <code>slip_limit</code> = 0 turns it off.</p><p> One signed force decides
the pedal, so the two pedals are never pressed together.</p>
<p>Stepping: the integral advances by e·h with the inputs held over the step; the outputs
at the end of a step use those inputs (no direct feed-through). <code>v_target</code> is
the target at the current s (for speed-error statistics), <code>v_preview</code>,
<code>a_target</code>, <code>a_demand</code> are exposed as locals.</p>
"#;

#[cfg(feature = "fmu")]
fmu_export::export_fmu!(crate::Driver);

#[cfg(test)]
mod tests;
