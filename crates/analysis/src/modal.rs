//! Modal analysis of a torsional chain, paper Eq. 1–8.
//!
//! The undamped eigenproblem `C v = ω² M v` (Eq. 2) is solved as a symmetric generalized
//! eigenproblem: with the Cholesky factor `M = L Lᵀ` it becomes the standard symmetric
//! problem `(L⁻¹ C L⁻ᵀ) w = ω² w`, `v = L⁻ᵀ w`. Eigenfrequencies are then taken from the
//! Rayleigh quotient `ω₀ᵢ² = γᵢ/μᵢ` (Eq. 3), which is accurate to the square of the
//! eigenvector's error. Damping is treated as modal (Eq. 8): `Dᵢ = vᵢᵀBvᵢ / (2√(μᵢγᵢ))`;
//! the off-diagonal modal damping terms of a non-proportionally damped chain are ignored,
//! which is the paper's assumption.

use crate::chain::Chain;
use crate::error::{AnalysisError, Result};
use nalgebra::{DMatrix, SymmetricEigen};
use serde::Serialize;
use std::f64::consts::PI;

/// What kind of mode this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeKind {
    /// All inertias turn together (free-free chain, ω₀ = 0).
    RigidBody,
    /// A torsional vibration mode.
    Elastic,
}

/// One mode of the chain.
#[derive(Debug, Clone, Serialize)]
pub struct Mode {
    /// 1-based, in ascending frequency.
    pub number: usize,
    pub kind: ModeKind,
    /// Undamped eigenfrequency ω₀ᵢ, rad/s (Eq. 3); exactly 0 for the rigid-body mode.
    pub omega0: f64,
    /// ω₀ᵢ / 2π, Hz.
    pub f0: f64,
    /// Modal damping ratio Dᵢ (None for the rigid-body mode).
    pub damping_ratio: Option<f64>,
    /// Damped eigenfrequency ωᵢ = ω₀ᵢ√(1−Dᵢ²), rad/s (Eq. 8); None when Dᵢ ≥ 1 (no oscillation).
    pub omega_d: Option<f64>,
    /// ωᵢ / 2π, Hz.
    pub f_d: Option<f64>,
    /// Mode shape, one entry per inertia, scaled so that max |vₖ| = 1 and the first
    /// non-zero entry is positive.
    pub shape: Vec<f64>,
    /// Modal mass μᵢ = Σ Jₖ vₖᵢ² (Eq. 4), kg·m², with the shape above.
    pub modal_mass: f64,
    /// Modal stiffness γᵢ = Σ c_Tk (vₖᵢ − vₖ₊₁,ᵢ)² (Eq. 5), N·m/rad.
    pub modal_stiffness: f64,
    /// Modal damping βᵢ = vᵢᵀ B vᵢ, N·m·s/rad.
    pub modal_damping: f64,
    /// μᵢₖ = Jₖ vₖᵢ² / μᵢ per inertia (Eq. 6); sums to 1.
    pub mass_sensitivity: Vec<f64>,
    /// γᵢₖ per spring in the order of [`ModalResult::springs`] (Eq. 7); sums to 1.
    /// None for the rigid-body mode (γᵢ = 0: no spring is deformed).
    pub stiffness_sensitivity: Option<Vec<f64>>,
}

/// The modal analysis of one chain.
#[derive(Debug, Clone, Serialize)]
pub struct ModalResult {
    pub chain: String,
    /// Inertia names, left to right.
    pub inertias: Vec<String>,
    /// Spring names in the order of Eq. 5 (ground springs first and last, where present).
    pub springs: Vec<String>,
    /// J_k, kg·m², in the order of `inertias`.
    pub inertia_values: Vec<f64>,
    /// c_Tk, N·m/rad, in the order of `springs`.
    pub stiffness_values: Vec<f64>,
    pub free_free: bool,
    pub modes: Vec<Mode>,
}

/// Mass, damping and stiffness matrices of Eq. 1.
pub fn matrices(chain: &Chain) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let n = chain.inertias.len();
    let m = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        n,
        chain.inertias.iter().map(|j| j.inertia),
    ));
    let mut b = DMatrix::zeros(n, n);
    let mut c = DMatrix::zeros(n, n);
    for (k, j) in chain.inertias.iter().enumerate() {
        b[(k, k)] += j.damping;
    }
    for (s, place) in chain.all_springs() {
        for (mat, value) in [(&mut c, s.stiffness), (&mut b, s.damping)] {
            match (place.left, place.right) {
                (Some(l), Some(r)) => {
                    mat[(l, l)] += value;
                    mat[(r, r)] += value;
                    mat[(l, r)] -= value;
                    mat[(r, l)] -= value;
                }
                (Some(k), None) | (None, Some(k)) => mat[(k, k)] += value,
                (None, None) => {}
            }
        }
    }
    (m, b, c)
}

/// Modal analysis of a validated chain.
pub fn analyse(chain: &Chain) -> Result<ModalResult> {
    chain.validate()?;
    let n = chain.inertias.len();
    let (m, b, c) = matrices(chain);
    let eigen_err = |message: &str| AnalysisError::Eigen {
        chain: chain.name.clone(),
        message: message.to_string(),
    };
    let chol = nalgebra::Cholesky::new(m.clone())
        .ok_or_else(|| eigen_err("the mass matrix is not positive definite"))?;
    let l_inv = chol
        .l()
        .try_inverse()
        .ok_or_else(|| eigen_err("the Cholesky factor is singular"))?;
    let a = &l_inv * &c * l_inv.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let eig = SymmetricEigen::new(a);
    let vectors = l_inv.transpose() * &eig.eigenvectors;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));

    let free_free = chain.is_free_free();
    let springs: Vec<(&crate::chain::Spring, crate::chain::SpringPlace)> =
        chain.all_springs().collect();
    let mut modes = Vec::with_capacity(n);
    for (idx, &col) in order.iter().enumerate() {
        let rigid = free_free && idx == 0;
        let mut shape: Vec<f64> = if rigid {
            vec![1.0; n]
        } else {
            vectors.column(col).iter().copied().collect()
        };
        normalise_shape(&mut shape);
        let mass_terms: Vec<f64> = chain
            .inertias
            .iter()
            .zip(&shape)
            .map(|(j, v)| j.inertia * v * v)
            .collect();
        let modal_mass: f64 = mass_terms.iter().sum();
        let stiffness_terms: Vec<f64> = springs
            .iter()
            .map(|(s, place)| {
                let vl = place.left.map_or(0.0, |k| shape[k]);
                let vr = place.right.map_or(0.0, |k| shape[k]);
                s.stiffness * (vl - vr) * (vl - vr)
            })
            .collect();
        let modal_stiffness: f64 = if rigid {
            0.0
        } else {
            stiffness_terms.iter().sum()
        };
        let v = nalgebra::DVector::from_column_slice(&shape);
        let modal_damping = (v.transpose() * &b * &v)[(0, 0)];
        let omega0 = (modal_stiffness / modal_mass).sqrt();
        let (damping_ratio, omega_d) = if rigid {
            (None, None)
        } else {
            let d = modal_damping / (2.0 * (modal_mass * modal_stiffness).sqrt());
            let wd = (d < 1.0).then(|| omega0 * (1.0 - d * d).sqrt());
            (Some(d), wd)
        };
        modes.push(Mode {
            number: idx + 1,
            kind: if rigid {
                ModeKind::RigidBody
            } else {
                ModeKind::Elastic
            },
            omega0,
            f0: omega0 / (2.0 * PI),
            damping_ratio,
            omega_d,
            f_d: omega_d.map(|w| w / (2.0 * PI)),
            mass_sensitivity: mass_terms.iter().map(|t| t / modal_mass).collect(),
            stiffness_sensitivity: (!rigid).then(|| {
                stiffness_terms
                    .iter()
                    .map(|t| t / modal_stiffness)
                    .collect()
            }),
            shape,
            modal_mass,
            modal_stiffness,
            modal_damping,
        });
    }
    Ok(ModalResult {
        chain: chain.name.clone(),
        inertias: chain.inertias.iter().map(|j| j.name.clone()).collect(),
        springs: springs.iter().map(|(s, _)| s.name.clone()).collect(),
        inertia_values: chain.inertias.iter().map(|j| j.inertia).collect(),
        stiffness_values: springs.iter().map(|(s, _)| s.stiffness).collect(),
        free_free,
        modes,
    })
}

fn normalise_shape(shape: &mut [f64]) {
    let max = shape.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    if max == 0.0 {
        return;
    }
    let first = shape
        .iter()
        .copied()
        .find(|v| v.abs() > 1e-9 * max)
        .unwrap_or(1.0);
    let scale = first.signum() / max;
    shape.iter_mut().for_each(|v| *v *= scale);
}

/// Whether a component is an inertia (μ coefficient) or a spring (γ coefficient).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ComponentKind {
    Inertia,
    Spring,
}

/// A component's sensitivity coefficient in one mode of both chains.
#[derive(Debug, Clone, Serialize)]
pub struct ComponentShare {
    pub name: String,
    pub kind: ComponentKind,
    /// Coefficient in chain A (0 when the component is not in A).
    pub a: f64,
    /// Coefficient in chain B (0 when the component is not in B).
    pub b: f64,
    /// The component differs between the chains: present in one only, or with another
    /// inertia or stiffness.
    pub changed: bool,
}

/// One mode of chain A set beside the mode of the same rank in chain B.
#[derive(Debug, Clone, Serialize)]
pub struct ModePair {
    pub kind: ModeKind,
    /// Mode numbers in A and B.
    pub number_a: usize,
    pub number_b: usize,
    pub f0_a: f64,
    pub f0_b: f64,
    /// f0_b − f0_a, Hz.
    pub shift_hz: f64,
    /// (f0_b − f0_a)/f0_a; None for rigid-body modes.
    pub shift_rel: Option<f64>,
    pub damping_ratio_a: Option<f64>,
    pub damping_ratio_b: Option<f64>,
    /// The component with the largest sensitivity coefficient in A and in B.
    pub dominant_a: ComponentShare,
    pub dominant_b: ComponentShare,
    /// Among the components that differ between the chains (added, removed or changed in
    /// value), the one whose sensitivity coefficient in this mode changed most: the one
    /// responsible for the shift. (Unchanged components only when nothing differs.)
    pub responsible: ComponentShare,
}

/// Two chains side by side.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    pub a: ModalResult,
    pub b: ModalResult,
    pub pairs: Vec<ModePair>,
    /// Modes of the longer chain that have no partner (different numbers of inertias).
    pub unmatched_a: Vec<usize>,
    pub unmatched_b: Vec<usize>,
}

/// (name, kind, coefficient, parameter value) of every component in one mode.
fn shares(r: &ModalResult, mode: &Mode) -> Vec<(String, ComponentKind, f64, f64)> {
    let mut out: Vec<(String, ComponentKind, f64, f64)> = r
        .inertias
        .iter()
        .zip(&mode.mass_sensitivity)
        .zip(&r.inertia_values)
        .map(|((n, v), j)| (n.clone(), ComponentKind::Inertia, *v, *j))
        .collect();
    let zeros = vec![0.0; r.springs.len()];
    let g = mode.stiffness_sensitivity.as_ref().unwrap_or(&zeros);
    out.extend(
        r.springs
            .iter()
            .zip(g)
            .zip(&r.stiffness_values)
            .map(|((n, v), c)| (n.clone(), ComponentKind::Spring, *v, *c)),
    );
    out
}

/// Compare two chains mode by mode: elastic modes are paired by rank (the i-th elastic mode
/// of A with the i-th of B), rigid-body modes with each other. Components are matched by
/// name and kind; a component present in only one chain has coefficient 0 in the other.
pub fn compare(a: &ModalResult, b: &ModalResult) -> Comparison {
    let split = |r: &ModalResult| -> (Vec<usize>, Vec<usize>) {
        let rigid = r
            .modes
            .iter()
            .enumerate()
            .filter(|(_, m)| m.kind == ModeKind::RigidBody)
            .map(|(i, _)| i)
            .collect();
        let elastic = r
            .modes
            .iter()
            .enumerate()
            .filter(|(_, m)| m.kind == ModeKind::Elastic)
            .map(|(i, _)| i)
            .collect();
        (rigid, elastic)
    };
    let (ra, ea) = split(a);
    let (rb, eb) = split(b);
    let mut pairs = Vec::new();
    let mut unmatched_a = Vec::new();
    let mut unmatched_b = Vec::new();
    for (la, lb) in [(&ra, &rb), (&ea, &eb)] {
        let common = la.len().min(lb.len());
        for k in 0..common {
            pairs.push(pair(a, &a.modes[la[k]], b, &b.modes[lb[k]]));
        }
        unmatched_a.extend(la[common..].iter().map(|&i| a.modes[i].number));
        unmatched_b.extend(lb[common..].iter().map(|&i| b.modes[i].number));
    }
    Comparison {
        a: a.clone(),
        b: b.clone(),
        pairs,
        unmatched_a,
        unmatched_b,
    }
}

fn pair(a: &ModalResult, ma: &Mode, b: &ModalResult, mb: &Mode) -> ModePair {
    let sa = shares(a, ma);
    let sb = shares(b, mb);
    let mut all: Vec<ComponentShare> = Vec::new();
    let mut values: Vec<f64> = Vec::new();
    for (name, kind, v, value) in &sa {
        all.push(ComponentShare {
            name: name.clone(),
            kind: *kind,
            a: *v,
            b: 0.0,
            changed: true,
        });
        values.push(*value);
    }
    for (name, kind, v, value) in &sb {
        if let Some(i) = all.iter().position(|c| &c.name == name && c.kind == *kind) {
            all[i].b = *v;
            all[i].changed = values[i] != *value;
        } else {
            all.push(ComponentShare {
                name: name.clone(),
                kind: *kind,
                a: 0.0,
                b: *v,
                changed: true,
            });
        }
    }
    let any_changed = all.iter().any(|c| c.changed);
    let pick = |key: &dyn Fn(&ComponentShare) -> f64| -> ComponentShare {
        // Largest key; on a tie, prefer the component that gained participation in B.
        all.iter()
            .max_by(|x, y| {
                key(x)
                    .total_cmp(&key(y))
                    .then((x.b - x.a).total_cmp(&(y.b - y.a)))
            })
            .cloned()
            .expect("a chain has components")
    };
    let dominant_a = pick(&|c| if c.a > 0.0 { c.a } else { -1.0 });
    let dominant_b = pick(&|c| if c.b > 0.0 { c.b } else { -1.0 });
    let responsible = pick(&|c| {
        if c.changed || !any_changed {
            (c.b - c.a).abs()
        } else {
            -1.0
        }
    });
    let rigid = ma.kind == ModeKind::RigidBody;
    ModePair {
        kind: ma.kind,
        number_a: ma.number,
        number_b: mb.number,
        f0_a: ma.f0,
        f0_b: mb.f0,
        shift_hz: mb.f0 - ma.f0,
        shift_rel: (!rigid).then(|| (mb.f0 - ma.f0) / ma.f0),
        damping_ratio_a: ma.damping_ratio,
        damping_ratio_b: mb.damping_ratio,
        dominant_a,
        dominant_b,
        responsible,
    }
}
