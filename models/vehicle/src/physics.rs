//! Pure equations of the vehicle model: tyre loads (paper Eq. 11–15), the Magic Formula,
//! and the driving resistances. Kept free of state so the acceptance tests check them exactly.

/// Parameters the loads need (a copy of the variable table's values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadParams {
    pub m: f64,
    pub g: f64,
    pub x_cog: f64,
    pub h_cog: f64,
    pub l: f64,
    pub b_front: f64,
    pub b_rear: f64,
    pub x_rc: f64,
    pub area: f64,
    pub rho_air: f64,
    pub c_lift_front: f64,
    pub c_lift_rear: f64,
}

/// Tyre vertical loads [N], order fl, fr, rl, rr.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Loads {
    pub fl: f64,
    pub fr: f64,
    pub rl: f64,
    pub rr: f64,
}

impl Loads {
    pub fn sum(&self) -> f64 {
        self.fl + self.fr + self.rl + self.rr
    }
}

/// Eq. 11–15: loads from speed and the (low-passed) accelerations, ISO 8855 (a_y > 0 left).
pub fn wheel_loads(p: &LoadParams, v: f64, a_x: f64, a_y: f64) -> Loads {
    let q = p.area * p.rho_air * v * v;
    let lift_front = 0.25 * p.c_lift_front * q;
    let lift_rear = 0.25 * p.c_lift_rear * q;
    let long = a_x * p.h_cog / p.l;
    let rear_axle = 0.5 * (p.x_cog * p.g + long);
    let front_axle = 0.5 * ((1.0 - p.x_cog) * p.g - long);
    let lat_rear = (1.0 - p.x_rc) * a_y * p.h_cog / p.b_rear;
    let lat_front = p.x_rc * a_y * p.h_cog / p.b_front;
    Loads {
        rl: p.m * (rear_axle - lat_rear) + lift_rear,
        rr: p.m * (rear_axle + lat_rear) + lift_rear,
        fl: p.m * (front_axle - lat_front) + lift_front,
        fr: p.m * (front_axle + lat_front) + lift_front,
    }
}

/// Magic Formula shape coefficients (longitudinal, pure slip).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MagicFormula {
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub e: f64,
}

impl MagicFormula {
    /// Friction coefficient μ(κ) = D·sin(C·atan(Bκ − E(Bκ − atan Bκ))); odd in κ.
    #[inline]
    pub fn mu(&self, kappa: f64) -> f64 {
        let bk = self.b * kappa;
        self.d * (self.c * (bk - self.e * (bk - bk.atan())).atan()).sin()
    }

    /// Tyre longitudinal force: friction proportional to the load, no force off the ground.
    #[inline]
    pub fn force(&self, fz: f64, kappa: f64) -> f64 {
        fz.max(0.0) * self.mu(kappa)
    }
}

/// A sign that ramps linearly through zero over `±eps`: Coulomb friction (brakes, rolling
/// resistance) without chatter at standstill.
#[inline]
pub fn soft_sign(x: f64, eps: f64) -> f64 {
    (x / eps).clamp(-1.0, 1.0)
}
