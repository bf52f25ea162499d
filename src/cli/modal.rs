//! `twinbench modal`: modal analysis of a torsional drivetrain chain (paper Eq. 1–8), and
//! the side-by-side comparison of two chains (vehicle vs. bench).

use anyhow::Context;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tb_analysis::modal::{self, Comparison, ModalResult, ModeKind};
use tb_analysis::Chain;

#[derive(clap::Args, Debug)]
pub struct ModalArgs {
    /// Chain description (TOML: [[inertia]] and [[spring]] tables, optional
    /// [ground_left]/[ground_right]); see examples/chains/.
    pub chain: PathBuf,
    /// A second chain to set beside the first (e.g. the bench against the vehicle): which
    /// mode moved and which component is responsible.
    #[arg(long, value_name = "OTHER.toml")]
    pub compare: Option<PathBuf>,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Write the mode-shape plot to STEM.svg and STEM.png (with --compare: STEM-a.* and
    /// STEM-b.*).
    #[arg(long, value_name = "STEM")]
    pub plot: Option<PathBuf>,
}

pub fn run(args: ModalArgs) -> anyhow::Result<()> {
    let a = analyse(&args.chain)?;
    let b = args.compare.as_deref().map(analyse).transpose()?;
    if let Some(stem) = &args.plot {
        match &b {
            None => plot_shapes(&a, stem)?,
            Some(b) => {
                plot_shapes(&a, &suffixed(stem, "-a"))?;
                plot_shapes(b, &suffixed(stem, "-b"))?;
            }
        }
    }
    match (&b, args.json) {
        (None, true) => super::json::print(&serde_json::to_string_pretty(&a)?)?,
        (None, false) => print!("{}", table(&a)),
        (Some(b), json) => {
            let cmp = modal::compare(&a, b);
            if json {
                super::json::print(&serde_json::to_string_pretty(&cmp)?)?;
            } else {
                print!("{}\n{}\n{}", table(&a), table(b), comparison_table(&cmp));
            }
        }
    }
    Ok(())
}

fn analyse(path: &Path) -> anyhow::Result<ModalResult> {
    let chain = Chain::from_file(path)?;
    Ok(modal::analyse(&chain)?)
}

fn suffixed(stem: &Path, suffix: &str) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.prec$}"))
}

/// Human-readable tables of one chain's modes.
pub fn table(r: &ModalResult) -> String {
    let mut s = String::new();
    let ends = if r.free_free {
        "both ends free"
    } else {
        "grounded"
    };
    let _ = writeln!(
        s,
        "Chain: {} ({} inertias, {ends})\n",
        r.chain,
        r.inertias.len()
    );
    let _ = writeln!(
        s,
        "{:<5} {:<11} {:>10} {:>8} {:>10} {:>12} {:>14}",
        "mode", "kind", "f0 [Hz]", "D [-]", "fd [Hz]", "μ [kg·m²]", "γ [N·m/rad]"
    );
    for m in &r.modes {
        let _ = writeln!(
            s,
            "{:<5} {:<11} {:>10.3} {:>8} {:>10} {:>12.4} {:>14.4e}",
            m.number,
            match m.kind {
                ModeKind::RigidBody => "rigid body",
                ModeKind::Elastic => "elastic",
            },
            m.f0,
            opt(m.damping_ratio, 4),
            match m.kind {
                ModeKind::RigidBody => "-".into(),
                ModeKind::Elastic => m.f_d.map_or("overdamped".into(), |f| format!("{f:.3}")),
            },
            m.modal_mass,
            m.modal_stiffness
        );
    }
    let width = r
        .inertias
        .iter()
        .chain(&r.springs)
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(9)
        .max(9);
    mode_table(
        &mut s,
        r,
        width,
        "Mode shapes v_ki (max |v| = 1)",
        &r.inertias,
        |m, k| format!("{:.4}", m.shape[k]),
    );
    mode_table(
        &mut s,
        r,
        width,
        "Mass sensitivity μ_ik (Eq. 6)",
        &r.inertias,
        |m, k| format!("{:.4}", m.mass_sensitivity[k]),
    );
    mode_table(
        &mut s,
        r,
        width,
        "Stiffness sensitivity γ_ik (Eq. 7)",
        &r.springs,
        |m, k| opt(m.stiffness_sensitivity.as_ref().map(|g| g[k]), 4),
    );
    s
}

/// A table under `title`: a row per component of `names` (its index `k` into the mode's
/// values), a column per mode of `r`, each cell as `cell` writes it.
fn mode_table(
    s: &mut String,
    r: &ModalResult,
    width: usize,
    title: &str,
    names: &[String],
    cell: impl Fn(&modal::Mode, usize) -> String,
) {
    let _ = write!(s, "\n{title}\n{:<width$}", "component");
    for m in &r.modes {
        let _ = write!(s, " {:>8}", format!("mode {}", m.number));
    }
    s.push('\n');
    for (k, name) in names.iter().enumerate() {
        let _ = write!(s, "{name:<width$}");
        for m in &r.modes {
            let _ = write!(s, " {:>8}", cell(m, k));
        }
        s.push('\n');
    }
}

/// The comparison of two chains, mode by mode.
pub fn comparison_table(c: &Comparison) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Comparison: A = {}, B = {}\n", c.a.chain, c.b.chain);
    let _ = writeln!(
        s,
        "{:<9} {:>10} {:>10} {:>10} {:>8}  responsible component (largest change of its sensitivity coefficient)",
        "mode A/B", "A f0 [Hz]", "B f0 [Hz]", "shift", "[%]"
    );
    let coeff = |k: tb_analysis::modal::ComponentKind| match k {
        tb_analysis::modal::ComponentKind::Inertia => "μ",
        tb_analysis::modal::ComponentKind::Spring => "γ",
    };
    for p in &c.pairs {
        let r = &p.responsible;
        let why = if p.kind == ModeKind::RigidBody {
            "rigid-body mode (no elastic deformation)".to_string()
        } else {
            format!(
                "{} ({} {:.3} → {:.3}); dominated by {} ({} {:.3}) in A, {} ({} {:.3}) in B",
                r.name,
                coeff(r.kind),
                r.a,
                r.b,
                p.dominant_a.name,
                coeff(p.dominant_a.kind),
                p.dominant_a.a,
                p.dominant_b.name,
                coeff(p.dominant_b.kind),
                p.dominant_b.b
            )
        };
        let _ = writeln!(
            s,
            "{:<9} {:>10.3} {:>10.3} {:>+10.3} {:>8}  {why}",
            format!("{}/{}", p.number_a, p.number_b),
            p.f0_a,
            p.f0_b,
            p.shift_hz,
            p.shift_rel
                .map_or("-".into(), |x| format!("{:+.1}", x * 100.0)),
        );
    }
    if !c.unmatched_a.is_empty() || !c.unmatched_b.is_empty() {
        let list = |v: &[usize]| {
            v.iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            s,
            "\nmodes without a partner (the chains have different numbers of inertias): A: [{}], B: [{}]",
            list(&c.unmatched_a),
            list(&c.unmatched_b)
        );
    }
    if let Some(p) = c
        .pairs
        .iter()
        .filter(|p| p.kind == ModeKind::Elastic)
        .max_by(|x, y| {
            x.shift_rel
                .unwrap_or(0.0)
                .abs()
                .total_cmp(&y.shift_rel.unwrap_or(0.0).abs())
        })
    {
        let _ = writeln!(
            s,
            "\nLargest move: mode {}/{} from {:.2} Hz to {:.2} Hz ({:+.1} %); responsible: {} ({} coefficient {:.3} → {:.3}).",
            p.number_a,
            p.number_b,
            p.f0_a,
            p.f0_b,
            p.shift_rel.unwrap_or(0.0) * 100.0,
            p.responsible.name,
            coeff(p.responsible.kind),
            p.responsible.a,
            p.responsible.b
        );
    }
    s
}

fn plot_shapes(r: &ModalResult, stem: &Path) -> anyhow::Result<()> {
    let mut plot = tb_plot::LinePlot::new(
        format!(
            "Torsional mode shapes of {}: each inertia's angle in the mode, normalised",
            r.chain
        ),
        "inertia along the chain (1 = left end)",
        "normalised angle v_k",
    )
    .integer_x(true);
    for m in &r.modes {
        let pts: Vec<(f64, f64)> = m
            .shape
            .iter()
            .enumerate()
            .map(|(k, v)| ((k + 1) as f64, *v))
            .collect();
        let name = match m.kind {
            ModeKind::RigidBody => format!("mode {}: rigid body", m.number),
            ModeKind::Elastic => format!("mode {}: {:.2} Hz", m.number, m.f0),
        };
        plot = plot.series(name, &pts);
    }
    plot.save_both(stem)
        .with_context(|| format!("writing the mode-shape plot {}", stem.display()))?;
    eprintln!(
        "wrote {} and {}",
        stem.with_extension("svg").display(),
        stem.with_extension("png").display()
    );
    Ok(())
}
