//! Exact zero-order-hold discretisation of the air-gap torque lag.
//!
//! Between two controller ticks the lag's input `u` is constant, so the lag and the
//! integral of its output (which drives the rotor) have closed forms. That keeps the
//! response independent of the sub-step and exact at any ratio of step to time constant.

/// Transition of the lag over one interval `dt` with constant input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LagStep {
    /// No lag (time constant 0): the output equals the input at once.
    PassThrough,
    /// First order: `x(dt) = u + (x0 − u)·a`, `∫x = u·dt + (x0 − u)·b`.
    First { a: f64, b: f64 },
    /// Second order on `z = [x − u, dx/dt]`: `z(dt) = phi·z0`, `∫(x − u) = psi·z0`.
    Second { phi: [[f64; 2]; 2], psi: [f64; 2] },
}

impl LagStep {
    /// `order` 1 or 2; `time_constant` τ (for order 2 the natural frequency is 1/τ) and
    /// `damping` ζ of the second order.
    pub fn new(order: i32, time_constant: f64, damping: f64, dt: f64) -> Self {
        if time_constant <= 0.0 {
            return LagStep::PassThrough;
        }
        if order == 2 {
            let wn = 1.0 / time_constant;
            let a = [[0.0, 1.0], [-wn * wn, -2.0 * damping * wn]];
            let phi = expm2(a, dt);
            // ∫₀ᵈᵗ e^{As} ds = A⁻¹(Φ − I); A⁻¹ = [[−2ζ/ωn, −1/ωn²], [1, 0]].
            let ainv = [[-2.0 * damping / wn, -1.0 / (wn * wn)], [1.0, 0.0]];
            let m = [[phi[0][0] - 1.0, phi[0][1]], [phi[1][0], phi[1][1] - 1.0]];
            let psi = [
                ainv[0][0] * m[0][0] + ainv[0][1] * m[1][0],
                ainv[0][0] * m[0][1] + ainv[0][1] * m[1][1],
            ];
            LagStep::Second { phi, psi }
        } else {
            let a = (-dt / time_constant).exp();
            LagStep::First {
                a,
                b: time_constant * (1.0 - a),
            }
        }
    }

    /// Advance the lag state (`x`, `dx`) by one interval `dt` with input `u`; returns
    /// ∫x dt over the interval.
    #[inline]
    pub fn advance(&self, x: &mut f64, dx: &mut f64, u: f64, dt: f64) -> f64 {
        match *self {
            LagStep::PassThrough => {
                *x = u;
                *dx = 0.0;
                u * dt
            }
            LagStep::First { a, b } => {
                let e = *x - u;
                *x = u + e * a;
                *dx = 0.0;
                u * dt + e * b
            }
            LagStep::Second { phi, psi } => {
                let e = *x - u;
                let v = *dx;
                *x = u + phi[0][0] * e + phi[0][1] * v;
                *dx = phi[1][0] * e + phi[1][1] * v;
                u * dt + psi[0] * e + psi[1] * v
            }
        }
    }
}

fn mul2(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
    [
        [
            a[0][0] * b[0][0] + a[0][1] * b[1][0],
            a[0][0] * b[0][1] + a[0][1] * b[1][1],
        ],
        [
            a[1][0] * b[0][0] + a[1][1] * b[1][0],
            a[1][0] * b[0][1] + a[1][1] * b[1][1],
        ],
    ]
}

/// e^{A·t} of a 2×2 matrix by scaling and squaring with a Taylor series: valid for any
/// damping (under-, critically or over-damped) without case distinctions.
fn expm2(a: [[f64; 2]; 2], t: f64) -> [[f64; 2]; 2] {
    let mut norm = (a[0][0].abs() + a[0][1].abs()).max(a[1][0].abs() + a[1][1].abs()) * t;
    let mut squarings = 0;
    let mut scale = t;
    while norm > 0.25 && squarings < 60 {
        norm *= 0.5;
        scale *= 0.5;
        squarings += 1;
    }
    let m = [
        [a[0][0] * scale, a[0][1] * scale],
        [a[1][0] * scale, a[1][1] * scale],
    ];
    let mut result = [[1.0, 0.0], [0.0, 1.0]];
    let mut term = [[1.0, 0.0], [0.0, 1.0]];
    for k in 1..=16 {
        term = mul2(term, m);
        let inv = 1.0 / k as f64;
        term = [
            [term[0][0] * inv, term[0][1] * inv],
            [term[1][0] * inv, term[1][1] * inv],
        ];
        for i in 0..2 {
            for j in 0..2 {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        result = mul2(result, result);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_matches_closed_form() {
        let tau = 1e-3;
        let dt = 1e-4;
        let s = LagStep::new(1, tau, 0.7, dt);
        let (mut x, mut dx) = (0.0, 0.0);
        let mut integral = 0.0;
        for _ in 0..20 {
            integral += s.advance(&mut x, &mut dx, 1.0, dt);
        }
        let t: f64 = 20.0 * dt;
        let exact = 1.0 - (-t / tau).exp();
        let exact_int = t - tau * (1.0 - (-t / tau).exp());
        assert!((x - exact).abs() < 1e-14, "x {x} vs {exact}");
        assert!(
            (integral - exact_int).abs() < 1e-15,
            "∫x {integral} vs {exact_int}"
        );
    }

    #[test]
    fn second_order_matches_closed_form() {
        // Underdamped step response: x = 1 − e^{−ζωt}(cos ωd t + ζ/√(1−ζ²) sin ωd t).
        let (tau, zeta, dt) = (1e-3, 0.3, 1e-4);
        let s = LagStep::new(2, tau, zeta, dt);
        let (mut x, mut dx) = (0.0, 0.0);
        let mut integral = 0.0;
        let wn = 1.0 / tau;
        let wd = wn * (1.0 - zeta * zeta).sqrt();
        let exact = |t: f64| {
            1.0 - (-zeta * wn * t).exp()
                * ((wd * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (wd * t).sin())
        };
        for k in 1..=50 {
            integral += s.advance(&mut x, &mut dx, 1.0, dt);
            assert!((x - exact(k as f64 * dt)).abs() < 1e-12, "step {k}");
        }
        // ∫x over 5 ms by fine trapezoid of the closed form.
        let n = 200_000;
        let h = 50.0 * dt / n as f64;
        let quad: f64 = (0..n)
            .map(|i| 0.5 * h * (exact(i as f64 * h) + exact((i + 1) as f64 * h)))
            .sum();
        assert!((integral - quad).abs() < 1e-10, "∫x {integral} vs {quad}");
    }

    #[test]
    fn zero_time_constant_passes_through() {
        let s = LagStep::new(2, 0.0, 0.7, 1e-4);
        let (mut x, mut dx) = (3.0, 1.0);
        assert_eq!(s.advance(&mut x, &mut dx, 5.0, 1e-4), 5.0 * 1e-4);
        assert_eq!(x, 5.0);
    }
}
