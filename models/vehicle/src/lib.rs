//! twinbench vehicle model: the road-load simulation (RLS) of the bench. Residual vehicle
//! (point mass with the paper's tyre-load equations, Eq. 11–15), simulated front wheels,
//! Magic Formula tyres with transient slip, brakes, aero and rolling resistance, and the
//! track as distance-based data. The rear wheels are on the dynos: their speeds come in,
//! their load torques go out as the dynos' setpoints.

pub mod physics;
pub mod track;

use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo, ModelState, Resource};
use physics::{soft_sign, wheel_loads, LoadParams, Loads, MagicFormula};
use std::sync::Arc;
use track::{Track, TrackPoint};

/// Name of the track file in the FMU's resources.
pub const TRACK_FILE: &str = "track.csv";

/// The bundled track as the build script parsed it (`fmu_export::preparsed`; empty if the
/// bundled file does not parse, then the resource is parsed at run time and its error shown).
const TRACK_PREPARSED: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/track.preparsed"));

fmu_export::variables! {
    /// Variables of the vehicle model (names as in docs/bench.md and the paper, hence the case).
    #[allow(non_snake_case)]
    pub struct VehicleVars {
        m: Real = 880.0 => parameter(1).unit("kg").range(1.0, 1e5)
            .describe("Vehicle mass"),
        g: Real = 9.81 => parameter(2).unit("m/s2").range(0.0, 100.0)
            .describe("Gravitational acceleration"),
        x_cog: Real = 0.615 => parameter(3).unit("1").range(0.0, 1.0)
            .describe("Share of the static weight on the rear axle"),
        h_cog: Real = 0.345 => parameter(4).unit("m").range(0.0, 5.0)
            .describe("Height of the centre of gravity"),
        l: Real = 3.10 => tunable(5).unit("m").range(0.1, 20.0)
            .describe("Wheelbase in the load-transfer equations (an optimiser may tune it as a virtual geometry)"),
        b_front: Real = 1.55 => tunable(6).unit("m").range(0.1, 10.0)
            .describe("Front track width in the load-transfer equations (tunable virtual geometry)"),
        b_rear: Real = 1.50 => tunable(7).unit("m").range(0.1, 10.0)
            .describe("Rear track width in the load-transfer equations (tunable virtual geometry)"),
        x_rc: Real = 0.5 => parameter(8).unit("1").range(0.0, 1.0)
            .describe("Front axle's share of the lateral load transfer (roll centre)"),
        A: Real = 1.5 => parameter(9).unit("m2").range(0.01, 50.0)
            .describe("Frontal area"),
        c_drag: Real = 0.767 => parameter(10).unit("1").range(0.0, 5.0)
            .describe("Drag coefficient"),
        rho_air: Real = 1.18 => parameter(11).unit("kg/m3").range(0.01, 5.0)
            .describe("Air density"),
        f_roll: Real = 0.02 => parameter(12).unit("1").range(0.0, 0.5)
            .describe("Rolling-resistance coefficient (force per unit of total tyre load)"),
        wheel_radius: Real = 0.345 => parameter(13).unit("m").range(0.05, 2.0)
            .describe("Dynamic rolling radius of all four wheels"),
        c_lift_front: Real = 1.653 => tunable(14).unit("1").range(-2.0, 6.0)
            .describe("Front lift coefficient, paper's sign: positive presses the car down (default is the bench's mis-set initial value)"),
        c_lift_rear: Real = 2.027 => tunable(15).unit("1").range(-2.0, 6.0)
            .describe("Rear lift coefficient, paper's sign: positive presses the car down (default is the bench's mis-set initial value)"),
        chassis_model: Enumeration = ChassisModel::FirstOrder.value() => parameter(42).items(&CHASSIS_MODEL)
            .describe("How the accelerations in the load equations follow the car's: a first-order low-pass (chassis_time_constant) or sprung pitch and roll modes (pitch_/roll_frequency and _damping)"),
        chassis_time_constant: Real = 0.05 => tunable(16).unit("s").range(0.001, 5.0)
            .describe("Time constant of the first-order low-pass on a_x, a_y used in the load equations (chassis_model = first_order)"),
        pitch_frequency: Real = 2.0 => tunable(43).unit("Hz").range(0.2, 20.0)
            .describe("Natural frequency of the sprung body's pitch mode: how fast the longitudinal load transfer follows a_x (chassis_model = second_order)"),
        pitch_damping: Real = 0.5 => tunable(44).unit("1").range(0.05, 3.0)
            .describe("Damping ratio of the pitch mode (below 1 it overshoots; chassis_model = second_order)"),
        roll_frequency: Real = 2.0 => tunable(45).unit("Hz").range(0.2, 20.0)
            .describe("Natural frequency of the sprung body's roll mode: how fast the lateral load transfer follows a_y (chassis_model = second_order)"),
        roll_damping: Real = 0.5 => tunable(46).unit("1").range(0.05, 3.0)
            .describe("Damping ratio of the roll mode (below 1 it overshoots; chassis_model = second_order)"),
        tyre_B: Real = 12.0 => parameter(17).unit("1").range(0.1, 100.0)
            .describe("Magic Formula stiffness factor B"),
        tyre_C: Real = 1.65 => parameter(18).unit("1").range(1.0, 2.0)
            .describe("Magic Formula shape factor C (1..2: the curve has a peak)"),
        tyre_D: Real = 1.45 => parameter(19).unit("1").range(0.05, 3.0)
            .describe("Magic Formula peak friction coefficient D (force per unit load)"),
        tyre_E: Real = 0.3 => parameter(20).unit("1").range(-10.0, 1.0)
            .describe("Magic Formula curvature factor E"),
        relaxation_length: Real = 0.3 => parameter(21).unit("m").range(0.01, 5.0)
            .describe("Tyre longitudinal relaxation length: slip lags with time constant relaxation_length/|v|"),
        tyre_carcass_damping: Real = 1500.0 => parameter(32).unit("N.s/m").range(0.0, 1e6)
            .describe("Longitudinal carcass damping: force per m/s of σ·dκ/dt (zero in steady slip; damps the wheel/tyre mode)"),
        v_min: Real = 1.0 => parameter(22).unit("m/s").range(0.01, 50.0)
            .describe("Lower bound of the speed in the slip denominator (keeps slip finite near standstill)"),
        brake_force_max: Real = 22000.0 => parameter(23).unit("N").range(0.0, 1e6)
            .describe("Total brake force at the contact patches at full brake pedal (brake torque = force x wheel_radius)"),
        brake_balance_front: Real = 0.6 => parameter(24).unit("1").range(0.0, 1.0)
            .describe("Front axle's share of the brake torque"),
        brake_speed_threshold: Real = 1.0 => parameter(25).unit("rad/s").range(0.001, 100.0)
            .describe("Wheel speed over which the brake torque ramps through zero (friction without chatter at standstill)"),
        front_wheel_inertia: Real = 0.8 => parameter(26).unit("kg.m2").range(0.001, 100.0)
            .describe("Inertia of each simulated front wheel"),
        road_stiffness: Real = 150000.0 => parameter(27).unit("N/m").range(0.0, 1e8)
            .describe("Road excitation gain: load added per metre of road height under the wheel (0 switches the excitation off)"),
        road_wheelbase: Real = 3.10 => parameter(28).unit("m").range(0.0, 20.0)
            .describe("Distance the rear wheels run behind the front ones on the road profile (the physical wheelbase, not the tuned l)"),
        v_start: Real = 52.43 => parameter(29).unit("m/s").range(0.0, 150.0)
            .describe("Initial speed (the default study is a flying lap)"),
        s_start: Real = 0.0 => parameter(30).unit("m").range(0.0, 1e7)
            .describe("Initial position along the track (less than the lap length)"),
        substep_max: Real = 1e-3 => parameter(31).unit("s").range(1e-6, 0.01)
            .describe("Largest internal integration step (the step is split into equal sub-steps no longer than this)"),
        range_check: Integer = 1 => parameter(41).range(0.0, 1.0)
            .describe("An input outside its declared range (beyond a float32 rounding): 1 refuses it with fmi2Error, 0 uses it with a warning"),

        omega_rl: Real = 0.0 => input(50).unit("rad/s")
            .describe("Rear left wheel speed (from the dyno speed sensor)"),
        omega_rr: Real = 0.0 => input(51).unit("rad/s")
            .describe("Rear right wheel speed (from the dyno speed sensor)"),
        brake_pedal: Real = 0.0 => input(52).unit("1").range(0.0, 1.0)
            .describe("Brake pedal position, 0 released .. 1 full"),

        torque_setpoint_rl: Real = 0.0 => output(100).unit("N.m")
            .describe("Rear left load torque for the dyno: tyre reaction Fx·r plus brake torque, positive opposes forward wheel rotation"),
        torque_setpoint_rr: Real = 0.0 => output(101).unit("N.m")
            .describe("Rear right load torque for the dyno: tyre reaction Fx·r plus brake torque, positive opposes forward wheel rotation"),
        v: Real = 0.0 => output(102).unit("m/s").describe("Vehicle speed"),
        s: Real = 0.0 => output(103).unit("m")
            .describe("Position along the track, wraps to 0 at the lap length"),
        distance: Real = 0.0 => output(104).unit("m")
            .describe("Total distance driven since the start (integral of v)"),
        lap: Integer = 0 => discrete_output(105)
            .describe("Number of times the start/finish line (s = 0) was crossed forwards"),
        lap_time: Real = 0.0 => output(106).unit("s")
            .describe("Duration of the last complete lap (0 before; a start away from s = 0 gives an out-lap that is not timed)"),
        lap_length: Real = 0.0 => output(107).unit("m")
            .describe("Length of the lap of the track (the bundled one or track_file)"),
        track_file: String = "" => parameter(40)
            .describe("The track file (CSV with columns s, curvature, grade, z_road_left, z_road_right): an absolute path or a file:// URI; empty: the bundled resources/track.csv"),
        a_x: Real = 0.0 => output(108).unit("m/s2")
            .describe("Longitudinal acceleration of the car, dv/dt: what an accelerometer on it measures (the logger's a_x)"),
        a_y: Real = 0.0 => output(109).unit("m/s2")
            .describe("Lateral acceleration of the car, v²·curvature, positive in a left turn: what an accelerometer on it measures"),
        a_x_chassis: Real = 0.0 => output(110).unit("m/s2")
            .describe("Longitudinal acceleration after the chassis (low-pass or pitch mode): the one the load equations use"),
        a_y_chassis: Real = 0.0 => output(111).unit("m/s2")
            .describe("Lateral acceleration after the chassis (low-pass or roll mode): the one the load equations use"),
        Fz_fl: Real = 0.0 => output(112).unit("N").describe("Tyre vertical load, front left"),
        Fz_fr: Real = 0.0 => output(113).unit("N").describe("Tyre vertical load, front right"),
        Fz_rl: Real = 0.0 => output(114).unit("N").describe("Tyre vertical load, rear left"),
        Fz_rr: Real = 0.0 => output(115).unit("N").describe("Tyre vertical load, rear right"),
        Fz_sum: Real = 0.0 => output(116).unit("N").describe("Sum of the four tyre loads (paper Eq. 17)"),
        slip_fl: Real = 0.0 => output(117).unit("1").describe("Longitudinal slip (relaxed), front left"),
        slip_fr: Real = 0.0 => output(118).unit("1").describe("Longitudinal slip (relaxed), front right"),
        slip_rl: Real = 0.0 => output(119).unit("1").describe("Longitudinal slip (relaxed), rear left"),
        slip_rr: Real = 0.0 => output(120).unit("1").describe("Longitudinal slip (relaxed), rear right"),
        Fx_fl: Real = 0.0 => output(121).unit("N").describe("Tyre longitudinal force, front left (positive drives the car)"),
        Fx_fr: Real = 0.0 => output(122).unit("N").describe("Tyre longitudinal force, front right (positive drives the car)"),
        Fx_rl: Real = 0.0 => output(123).unit("N").describe("Tyre longitudinal force, rear left (positive drives the car)"),
        Fx_rr: Real = 0.0 => output(124).unit("N").describe("Tyre longitudinal force, rear right (positive drives the car)"),
        omega_fl: Real = 0.0 => output(125).unit("rad/s").describe("Simulated front left wheel speed"),
        omega_fr: Real = 0.0 => output(126).unit("rad/s").describe("Simulated front right wheel speed"),
        curvature: Real = 0.0 => output(127).unit("1/m").describe("Track curvature at s (positive: left turn)"),
        grade: Real = 0.0 => output(128).unit("rad").describe("Track grade at s (positive: uphill)"),
        F_resistance: Real = 0.0 => output(129).unit("N")
            .describe("Driving resistance: aero drag + rolling resistance + grade force"),
    }
}

fmu_export::enumeration! {
    /// `chassis_model`'s items: how the load equations' accelerations follow the car's.
    pub enum ChassisModel in CHASSIS_MODEL {
        description: "How the load equations' accelerations follow the car's",
        FirstOrder = "first_order" => "first-order low-pass of time constant chassis_time_constant",
        SecondOrder = "second_order"
            => "sprung pitch and roll modes: natural frequency and damping ratio each",
    }
}

/// How the load equations' accelerations follow the car's.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Chassis {
    /// τ·dâ/dt = a − â.
    FirstOrder { tau: f64 },
    /// â'' + 2ζω·â' + ω²·â = ω²·a for pitch (a_x) and roll (a_y).
    SecondOrder { pitch: Mode, roll: Mode },
}

/// A sprung mode: ω = 2π·f [rad/s] and ζ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mode {
    pub omega: f64,
    pub zeta: f64,
}

impl Mode {
    fn new(frequency: f64, damping: f64) -> Mode {
        Mode {
            omega: 2.0 * std::f64::consts::PI * frequency,
            zeta: damping,
        }
    }

    /// The transition matrix over `h` of (â − a, â') with a held: exp(A·h) for
    /// A = [[0, 1], [−ω², −2ζω]], row-major. Exact for every ζ: the under-, critically and
    /// over-damped forms (sin/ωd → h as ωd → 0, where the forms meet).
    pub fn transition(&self, h: f64) -> [f64; 4] {
        let (w, z) = (self.omega, self.zeta);
        let sigma = z * w;
        let d = 1.0 - z * z;
        // c = cos(ωd·h) or cosh, g = sin(ωd·h)/ωd or sinh/ωd.
        let (c, g) = if d.abs() < 1e-12 {
            (1.0, h)
        } else if d > 0.0 {
            let wd = w * d.sqrt();
            ((wd * h).cos(), (wd * h).sin() / wd)
        } else {
            let wd = w * (-d).sqrt();
            ((wd * h).cosh(), (wd * h).sinh() / wd)
        };
        let e = (-sigma * h).exp();
        [
            e * (c + sigma * g),
            e * g,
            -e * w * w * g,
            e * (c - sigma * g),
        ]
    }
}

/// Parameters in the form the equations use.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Params {
    loads: LoadParams,
    tyre: MagicFormula,
    c_drag: f64,
    f_roll: f64,
    r: f64,
    chassis: Chassis,
    sigma: f64,
    v_min: f64,
    brake_torque_max: f64,
    brake_front: f64,
    brake_eps: f64,
    j_front: f64,
    road_k: f64,
    road_wheelbase: f64,
    substep_max: f64,
    carcass_damping: f64,
}

impl Params {
    fn from_vars(x: &VehicleVars) -> Params {
        Params {
            loads: LoadParams {
                m: x.m,
                g: x.g,
                x_cog: x.x_cog,
                h_cog: x.h_cog,
                l: x.l,
                b_front: x.b_front,
                b_rear: x.b_rear,
                x_rc: x.x_rc,
                area: x.A,
                rho_air: x.rho_air,
                c_lift_front: x.c_lift_front,
                c_lift_rear: x.c_lift_rear,
            },
            tyre: MagicFormula {
                b: x.tyre_B,
                c: x.tyre_C,
                d: x.tyre_D,
                e: x.tyre_E,
            },
            c_drag: x.c_drag,
            f_roll: x.f_roll,
            r: x.wheel_radius,
            chassis: match ChassisModel::of(x.chassis_model) {
                ChassisModel::SecondOrder => Chassis::SecondOrder {
                    pitch: Mode::new(x.pitch_frequency, x.pitch_damping),
                    roll: Mode::new(x.roll_frequency, x.roll_damping),
                },
                ChassisModel::FirstOrder => Chassis::FirstOrder {
                    tau: x.chassis_time_constant,
                },
            },
            sigma: x.relaxation_length,
            v_min: x.v_min,
            brake_torque_max: x.brake_force_max * x.wheel_radius,
            brake_front: x.brake_balance_front,
            brake_eps: x.brake_speed_threshold,
            j_front: x.front_wheel_inertia,
            road_k: x.road_stiffness,
            road_wheelbase: x.road_wheelbase,
            substep_max: x.substep_max,
            carcass_damping: x.tyre_carcass_damping,
        }
    }

    /// Brake torque on one wheel [N·m], opposing its rotation (`front`: a front wheel).
    fn brake_torque(&self, pedal: f64, front: bool, omega: f64) -> f64 {
        let share = if front {
            self.brake_front
        } else {
            1.0 - self.brake_front
        };
        0.5 * share * pedal * self.brake_torque_max * soft_sign(omega, self.brake_eps)
    }

    /// Aero drag + rolling resistance + grade force [N], positive opposing forward motion.
    fn resistance(&self, v: f64, fz_sum: f64, grade: f64) -> f64 {
        let p = &self.loads;
        // Rolling resistance ramps through zero at standstill (0.1 m/s), like a brake.
        0.5 * p.rho_air * self.c_drag * p.area * v * v.abs()
            + self.f_roll * fz_sum.max(0.0) * soft_sign(v, 0.1)
            + p.m * p.g * grade.sin()
    }
}

fmu_export::states! {
    /// The dynamic state; `Copy`, so save/restore is a plain copy.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct State for Vehicle.st {
        v: f64,
        /// Position in `[0, lap length)`.
        s: f64,
        distance: f64,
        /// Time the current lap started; NaN while on an untimed out-lap.
        lap_start: f64,
        lap_time: f64,
        /// The chassis' accelerations in the load equations (â_x, â_y), and dv/dt.
        ax: f64,
        ay: f64,
        /// dâ_x/dt, dâ_y/dt: the pitch and roll modes' rates (second order; zero otherwise).
        ax_rate: f64,
        ay_rate: f64,
        ax_raw: f64,
        lap: i32,
        omega_front: [f64; 2],
        /// Relaxed slips fl, fr, rl, rr.
        kappa: [f64; 4],
        /// Lookup cursors of the front and rear axle on the track (speed only, not results).
        cursor_front: usize,
        cursor_rear: usize,
    }
}

#[derive(Clone, Debug)]
pub struct Vehicle {
    track: Arc<Track>,
    p: Params,
    st: State,
    /// Last (κ, μ(κ)) per tyre: the outputs at the end of a step and the first sub-step of
    /// the next one evaluate the Magic Formula at the same slip (a derived value, exact).
    mu_cache: [(f64, f64); 4],
    /// The second-order chassis' transition matrices (pitch, roll) for the sub-step length
    /// they were made for (NaN: none yet); derived from the parameters, not state.
    transitions: (f64, [f64; 4], [f64; 4]),
    /// The track under the front and the rear axle and the bits of the s they are for: the
    /// outputs at the end of a step and the first sub-step of the next one look them up at
    /// the same s (a derived value, exact; `road_wheelbase` is fixed after initialisation).
    track_here: Option<(u64, TrackPoint, TrackPoint)>,
    /// The first-order chassis' 1 − e^(−h/τ) for the sub-step length it was made for (NaN:
    /// none yet); derived from the parameters, as `transitions`.
    first_order: (f64, f64),
}

/// Everything the equations derive from the state at one instant.
struct Forces {
    at: TrackPoint,
    loads: Loads,
    fx: [f64; 4],
    resistance: f64,
}

impl Vehicle {
    /// Loads (Eq. 11–15 plus road excitation) and tyre forces for the current state and the
    /// rear wheel speeds `omega_rear`.
    fn forces(&mut self, omega_rear: [f64; 2]) -> Forces {
        let p = &self.p;
        let s_here = self.st.s;
        let key = s_here.to_bits();
        let (at, rear) = match self.track_here {
            Some((k, at, rear)) if k == key => (at, rear),
            _ => {
                let at = self.track.at(s_here, &mut self.st.cursor_front);
                let rear = self
                    .track
                    .at(s_here - p.road_wheelbase, &mut self.st.cursor_rear);
                self.track_here = Some((key, at, rear));
                (at, rear)
            }
        };
        let st = &self.st;
        let mut loads = wheel_loads(&p.loads, st.v, st.ax, st.ay);
        loads.fl += p.road_k * at.z_left;
        loads.fr += p.road_k * at.z_right;
        loads.rl += p.road_k * rear.z_left;
        loads.rr += p.road_k * rear.z_right;
        let fz = [loads.fl, loads.fr, loads.rl, loads.rr];
        let omegas = [
            st.omega_front[0],
            st.omega_front[1],
            omega_rear[0],
            omega_rear[1],
        ];
        let speed = st.v.abs().max(p.v_min);
        let mut fx = [0.0; 4];
        for i in 0..4 {
            // Carcass damping acts on σ·dκ/dt only: zero in steady slip, it damps the
            // wheel/tyre mode that the bench's delays would otherwise excite.
            let slip_rate = omegas[i] * p.r - st.v - speed * st.kappa[i];
            let limit = p.tyre.d * fz[i].max(0.0);
            let kappa = st.kappa[i];
            let mu = if self.mu_cache[i].0 == kappa {
                self.mu_cache[i].1
            } else {
                let mu = p.tyre.mu(kappa);
                self.mu_cache[i] = (kappa, mu);
                mu
            };
            fx[i] = (fz[i].max(0.0) * mu + p.carcass_damping * slip_rate).clamp(-limit, limit);
        }
        let resistance = p.resistance(st.v, loads.sum(), at.grade);
        Forces {
            at,
            loads,
            fx,
            resistance,
        }
    }

    /// One explicit sub-step of length `h` starting at time `t`.
    fn substep(&mut self, t: f64, h: f64, omega_rear: [f64; 2], pedal: f64) {
        let f = self.forces(omega_rear);
        let p = &self.p;
        let st = &mut self.st;
        let a = (f.fx.iter().sum::<f64>() - f.resistance) / p.loads.m;
        let mut v_new = st.v + a * h;
        let mut omega_front = st.omega_front;
        for (k, w) in omega_front.iter_mut().enumerate() {
            let tb = p.brake_torque(pedal, true, *w);
            *w += h * (-p.r * f.fx[k] - tb) / p.j_front;
        }
        // Standstill: tyre friction and resistance bring the car to rest but cannot drive it
        // backwards. A sub-step that would carry the speed from rest or forward through zero
        // ends at rest while no rear wheel turns backwards (the relaxed slip of a locked
        // wheel would otherwise push the car back); the front wheels stop with it.
        if st.v >= 0.0 && v_new < 0.0 && omega_rear.iter().all(|w| *w >= 0.0) {
            v_new = 0.0;
            for w in omega_front.iter_mut() {
                *w = w.max(0.0);
            }
        }
        // Transient slip σ·dκ/dt = (ω·r − v) − max(|v|, v_min)·κ, solved exactly over the
        // sub-step (inputs frozen): stable however short σ/|v| gets.
        let speed = v_new.abs().max(p.v_min);
        let decay = (-speed * h / p.sigma).exp();
        let omegas = [omega_front[0], omega_front[1], omega_rear[0], omega_rear[1]];
        for (k, kappa) in st.kappa.iter_mut().enumerate() {
            let steady = (omegas[k] * p.r - v_new) / speed;
            *kappa = steady + (*kappa - steady) * decay;
        }
        // The chassis, exact for accelerations held over the sub-step.
        let ay_raw = v_new * v_new * f.at.curvature;
        match p.chassis {
            Chassis::FirstOrder { tau } => {
                // 1 − e^(−h/τ) depends on h and τ only: computed once per sub-step length.
                if self.first_order.0 != h {
                    self.first_order = (h, 1.0 - (-h / tau).exp());
                }
                let alpha = self.first_order.1;
                st.ax += alpha * (a - st.ax);
                st.ay += alpha * (ay_raw - st.ay);
            }
            Chassis::SecondOrder { pitch, roll } => {
                // The transition matrices depend on h and the modes only: computed once
                // per sub-step length.
                if self.transitions.0 != h {
                    self.transitions = (h, pitch.transition(h), roll.transition(h));
                }
                let (_, tp, tr) = self.transitions;
                let (e, r) = (st.ax - a, st.ax_rate);
                st.ax = a + tp[0] * e + tp[1] * r;
                st.ax_rate = tp[2] * e + tp[3] * r;
                let (e, r) = (st.ay - ay_raw, st.ay_rate);
                st.ay = ay_raw + tr[0] * e + tr[1] * r;
                st.ay_rate = tr[2] * e + tr[3] * r;
            }
        }
        st.ax_raw = a;

        let ds = 0.5 * (st.v + v_new) * h;
        st.v = v_new;
        st.omega_front = omega_front;
        st.distance += ds;
        let s_new = st.s + ds;
        let length = self.track.length();
        if s_new >= length {
            // Crossing time interpolated inside the sub-step.
            let t_cross = t + h * ((length - st.s) / ds).clamp(0.0, 1.0);
            st.lap += 1;
            if st.lap_start.is_finite() {
                st.lap_time = t_cross - st.lap_start;
            }
            st.lap_start = t_cross;
            st.s = self.track.wrap(s_new);
        } else if s_new < 0.0 {
            // Rolling backwards over the line: that lap no longer counts, nor is it timed.
            st.lap -= 1;
            st.lap_start = f64::NAN;
            st.s = self.track.wrap(s_new);
        } else {
            st.s = s_new;
        }
    }

    /// The parsed track (for hosts and tests).
    pub fn track(&self) -> &Track {
        &self.track
    }
}

impl Model for Vehicle {
    type Vars = VehicleVars;
    const INFO: ModelInfo = ModelInfo::new("vehicle", "Road-load simulation of the bench: residual vehicle, tyres (Magic Formula, relaxation length), tyre loads by Eq. 11-15, brakes, aero, track", env!("CARGO_PKG_VERSION"))
        .experiment(100.0, 1e-3)
        .documentation(DOCUMENTATION)
        .resources(&[
            Resource::file(TRACK_FILE, include_bytes!("../resources/track.csv")).default_of("track_file"),
            Resource::file("NOTICE", include_bytes!("../resources/NOTICE")),
        ]);

    fn initialize(vars: &mut VehicleVars, ctx: &Context) -> Result<Self, ModelError> {
        let (track, track_path) = if vars.track_file.is_empty() {
            let track = ctx.cached(TRACK_FILE, || {
                let (path, text) = ctx.read_resource(TRACK_FILE)?;
                // The bundled file as the build parsed it, unless it was changed since.
                let digest = fmu_export::preparsed::digest(text.as_bytes());
                match fmu_export::preparsed::decode(TRACK_PREPARSED, digest, 5)
                    .and_then(|v| Track::from_values(&v))
                {
                    Some(track) => Ok(track),
                    None => Track::parse(&path.display().to_string(), &text),
                }
            })?;
            (track, ctx.resource(TRACK_FILE)?)
        } else {
            let path = fmu_export::resources::parameter_path("track_file", &vars.track_file)?;
            let track = fmu_export::resources::shared_file(&path, |p, text| {
                Track::parse(&p.display().to_string(), text)
            })?;
            (track, path)
        };
        if vars.s_start >= track.length() {
            return Err(ModelError::new(format!(
                "s_start = {} m is not less than the lap length {} m of {}",
                vars.s_start,
                track.length(),
                track_path.display()
            )));
        }
        let p = Params::from_vars(vars);
        let v0 = vars.v_start;
        let mut cursor = 0;
        let at = track.at(vars.s_start, &mut cursor);
        // A consistent start: constant speed, front wheels rolling free, no slip, the
        // chassis filter settled on the steady cornering acceleration.
        let st = State {
            v: v0,
            s: vars.s_start,
            distance: 0.0,
            lap: 0,
            lap_start: if vars.s_start == 0.0 {
                ctx.start_time
            } else {
                f64::NAN
            },
            lap_time: 0.0,
            omega_front: [v0 / p.r; 2],
            kappa: [0.0; 4],
            ax: 0.0,
            ay: v0 * v0 * at.curvature,
            ax_rate: 0.0,
            ay_rate: 0.0,
            ax_raw: 0.0,
            cursor_front: cursor,
            cursor_rear: 0,
        };
        Ok(Vehicle {
            track,
            p,
            st,
            mu_cache: [(f64::NAN, 0.0); 4],
            transitions: (f64::NAN, [0.0; 4], [0.0; 4]),
            track_here: None,
            first_order: (f64::NAN, 0.0),
        })
    }

    fn internal_steps(&self, step: f64) -> f64 {
        step / self.p.substep_max
    }

    fn do_step(&mut self, vars: &mut VehicleVars, time: f64, step: f64) -> Result<(), ModelError> {
        // A step a rounding unit longer than a multiple of substep_max (a host's nanosecond
        // clock) must not cost an extra sub-step.
        let n = (step / self.p.substep_max * (1.0 - 1e-9)).ceil().max(1.0);
        let h = step / n;
        let omega_rear = [vars.omega_rl, vars.omega_rr];
        let pedal = vars.brake_pedal;
        for k in 0..n as usize {
            self.substep(time + k as f64 * h, h, omega_rear, pedal);
        }
        if !(self.st.v.is_finite() && self.st.kappa.iter().all(|k| k.is_finite())) {
            return Err(ModelError::new(format!(
                "the vehicle state diverged (v = {}, slips {:?}); check the wheel-speed inputs and substep_max",
                self.st.v, self.st.kappa
            )));
        }
        Ok(())
    }

    /// Every output from the current state (the inputs as held over the last step).
    fn calculate_outputs(&mut self, x: &mut VehicleVars) {
        let f = self.forces([x.omega_rl, x.omega_rr]);
        let st = self.st;
        let r = self.p.r;
        x.v = st.v;
        x.s = st.s;
        x.distance = st.distance;
        x.lap = st.lap;
        x.lap_time = st.lap_time;
        x.lap_length = self.track.length();
        x.a_x = st.ax_raw;
        x.a_y = st.v * st.v * f.at.curvature;
        x.a_x_chassis = st.ax;
        x.a_y_chassis = st.ay;
        x.Fz_fl = f.loads.fl;
        x.Fz_fr = f.loads.fr;
        x.Fz_rl = f.loads.rl;
        x.Fz_rr = f.loads.rr;
        x.Fz_sum = f.loads.sum();
        x.slip_fl = st.kappa[0];
        x.slip_fr = st.kappa[1];
        x.slip_rl = st.kappa[2];
        x.slip_rr = st.kappa[3];
        x.Fx_fl = f.fx[0];
        x.Fx_fr = f.fx[1];
        x.Fx_rl = f.fx[2];
        x.Fx_rr = f.fx[3];
        x.omega_fl = st.omega_front[0];
        x.omega_fr = st.omega_front[1];
        x.curvature = f.at.curvature;
        x.grade = f.at.grade;
        x.F_resistance = f.resistance;
        x.torque_setpoint_rl = r * f.fx[2] + self.p.brake_torque(x.brake_pedal, false, x.omega_rl);
        x.torque_setpoint_rr = r * f.fx[3] + self.p.brake_torque(x.brake_pedal, false, x.omega_rr);
    }

    fn parameters_changed(&mut self, vars: &VehicleVars) -> Result<(), ModelError> {
        self.p = Params::from_vars(vars);
        self.transitions.0 = f64::NAN;
        self.first_order.0 = f64::NAN;
        // μ(κ) is the tyre's: new parameters, new curve.
        self.mu_cache = [(f64::NAN, 0.0); 4];
        Ok(())
    }
}

impl ModelState for Vehicle {
    /// The cursors are search hints: one past this track's end is brought back onto it.
    fn state_loaded(&mut self) -> Result<(), ModelError> {
        let n = self.track.rows();
        self.st.cursor_front = self.st.cursor_front.min(n - 1);
        self.st.cursor_rear = self.st.cursor_rear.min(n - 1);
        Ok(())
    }
}

const DOCUMENTATION: &str = r#"
<h2>Vehicle model (road-load simulation)</h2>
<p>The residual vehicle of the bench: everything of the car that is not on the bench. The
rear (driven) wheels turn on the dynos; their speeds <code>omega_rl</code>, <code>omega_rr</code>
come in, and their load torques go out as <code>torque_setpoint_rl/rr</code> (tyre reaction
F<sub>x</sub>·r plus brake torque; positive opposes forward wheel rotation, so the dyno computes
J·dω/dt = shaft_torque − torque_dyno). Axes ISO 8855: x forward, y left.</p>

<h3>Tyre vertical loads (paper Eq. 11–15)</h3>
<pre>
Fz_rl = m(½(x_cog·g + a_x·h_cog/l) − (1−x_rc)·a_y·h_cog/b_rear) + F_lift,rear + k_road·z_left(s − l_road)
Fz_rr = m(½(x_cog·g + a_x·h_cog/l) + (1−x_rc)·a_y·h_cog/b_rear) + F_lift,rear + k_road·z_right(s − l_road)
Fz_fl = m(½((1−x_cog)·g − a_x·h_cog/l) − x_rc·a_y·h_cog/b_front) + F_lift,front + k_road·z_left(s)
Fz_fr = m(½((1−x_cog)·g − a_x·h_cog/l) + x_rc·a_y·h_cog/b_front) + F_lift,front + k_road·z_right(s)
F_lift,front/rear = ¼·c_lift,front/rear·A·rho_air·v²      (per wheel; c_lift &gt; 0 presses down)
Fz_sum = m·g + ½(c_lift,front + c_lift,rear)·A·rho_air·v²  (Eq. 18, without road excitation)
</pre>
<p>a<sub>x</sub>, a<sub>y</sub> in the loads are the chassis' outputs â (the outputs
<code>a_x_chassis</code>, <code>a_y_chassis</code>) for the car's accelerations
a<sub>x</sub> = dv/dt and a<sub>y</sub> = v²·κ(s) (the outputs <code>a_x</code>,
<code>a_y</code>: what an accelerometer on the car measures, to be compared with a logger's).
<code>chassis_model</code> = <code>first_order</code> (1, the
default): a low-pass τ·dâ/dt = a − â, τ = <code>chassis_time_constant</code>.
<code>second_order</code> (2): the sprung body's pitch (for a<sub>x</sub>) and roll (for
a<sub>y</sub>) modes, d²â/dt² + 2ζω·dâ/dt + ω²·â = ω²·a with ω = 2π·f, f and ζ =
<code>pitch_frequency</code>, <code>pitch_damping</code> and <code>roll_frequency</code>,
<code>roll_damping</code>: below ζ = 1 a step overshoots by exp(−πζ/√(1 − ζ²)). Both are
integrated exactly for the acceleration held over a sub-step (for a mode, the closed-form
transition matrix of (â − a, dâ/dt)).
The road excitation k_road·z (k_road = <code>road_stiffness</code>) is a distance-based signal
from the track; the rear wheels see the profile <code>road_wheelbase</code> later than the front
ones. The lift coefficients default to the bench's mis-set initial values (1.653, 2.027);
<code>c_lift_*</code>, <code>l</code>, <code>b_front</code>, <code>b_rear</code>,
<code>chassis_time_constant</code> and the four mode parameters are tunable for the
optimiser.</p>

<h3>Tyres</h3>
<pre>
μ(κ) = D·sin(C·atan(Bκ − E(Bκ − atan Bκ)))
σ·dκ_i/dt = (ω_i·r − v) − max(|v|, v_min)·κ_i       (relaxation length σ; steady state κ = (ω·r − v)/max(|v|, v_min))
F_x,i = clamp(max(Fz_i, 0)·μ(κ_i) + k_c·σ·dκ_i/dt, ±D·max(Fz_i, 0))
</pre>
<p>k_c = <code>tyre_carcass_damping</code> is the damping of the carcass deflection σ·κ: it is
zero in steady slip (the steady force is the pure Magic Formula) and damps the wheel/tyre mode
(about 30 Hz with a 0.8 kg·m² wheel), which is lightly damped at low speed (damping ∝ v/σ)
and which the bench's delays (co-simulation step, dyno dead time and lag) would otherwise
drive unstable. With the defaults and a 1 ms macro step the loop through a dyno with 0.5 ms
dead time and 1 ms lag settles cleanly from 5 to 50 m/s; with 2 ms dead time it rings by a few
N·m; from about 3 ms it becomes a limit cycle bounded only by the tyre friction, which is what
the dyno's dead-time compensation is for. Set k_c = 0 for the bare relaxation-length model.</p>

<h3>Longitudinal dynamics and wheels</h3>
<pre>
m·dv/dt = Σ F_x,i − ½·rho_air·c_drag·A·v·|v| − f_roll·Σ Fz·sgn(v) − m·g·sin(grade(s))
J_f·dω_f/dt = −r·F_x,f − T_brake,f                    (front wheels, simulated)
T_brake = ½·share·brake_pedal·brake_force_max·r·sgn(ω)  (share: brake_balance_front or 1 − it)
torque_setpoint_r = r·F_x,r + T_brake,r                 (rear wheels, on the dynos)
</pre>
<p>sgn ramps linearly over ±<code>brake_speed_threshold</code> (brakes) and ±0.1 m/s (rolling
resistance): friction without chatter at standstill. Tyre loads below zero (a wheel lifting)
give no tyre force; the load outputs still show the equations' value.</p>

<h3>Track and laps</h3>
<p>The track is the resource <code>track.csv</code> (columns <code>s, curvature, grade,
z_road_left, z_road_right</code>; s starts at 0 and increases; the lap length is the last s plus
one spacing, and the last interval interpolates back to the first row). Values are linear
interpolations in s. <code>s</code> wraps to 0 at the lap length; <code>distance</code> is the
integral of v; <code>lap</code> counts forward crossings of s = 0; <code>lap_time</code> is the
duration of the last complete lap (crossing time interpolated within the sub-step). A start
at <code>s_start</code> ≠ 0 makes the first lap an untimed out-lap.</p>

<h3>Numerics and start</h3>
<p>Each step is split into equal sub-steps of at most <code>substep_max</code> (1 ms by
default: one per 1 ms macro step). Forces are explicit; the slip relaxation and the chassis
are solved exactly over each sub-step, so they are stable at any sub-step; the explicit
front-wheel spin (time constant J/(k<sub>c</sub>·r²) ≈ 4.5 ms with the carcass damping) needs
sub-steps well below 9 ms. On the Spielberg lap 1 ms and 0.1 ms sub-steps differ by 0.02 s in
lap time and 0.011 m/s RMS in speed, at a seventh of the cost. The inputs are held over the step, and the
outputs are those of the state at its end (no direct feed-through: the relaxation length
breaks the wheel-speed → torque loop). The run starts at <code>v_start</code>, front wheels at
v/r, slips zero, â<sub>x</sub> = 0 and â<sub>y</sub> = v²·κ(s_start) with zero rates (the
chassis at equilibrium).</p>
"#;

#[cfg(feature = "fmu")]
fmu_export::export_fmu!(crate::Vehicle);
