//! `twinbench identify step|frf`: identification of the dyno loop from a step response or
//! from a sine sweep / white noise (paper Fig. 2, Eq. 9–10).

use anyhow::Context;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tb_analysis::fit::{self, FitConfig, FrfFit, LagOrder, Sampling};
use tb_analysis::frf::{self, Detrend, Frf, WelchConfig};
use tb_analysis::signal::TimeSeries;
use tb_analysis::step::{self, StepConfig, StepResult};

#[derive(clap::Args, Debug)]
pub struct IdentifyArgs {
    #[command(subcommand)]
    pub command: IdentifyCommand,
}

impl IdentifyArgs {
    /// Whether the subcommand prints JSON.
    pub fn json(&self) -> bool {
        match &self.command {
            IdentifyCommand::Step(a) => a.json,
            IdentifyCommand::Frf(a) => a.json,
        }
    }
}

#[derive(clap::Subcommand, Debug)]
pub enum IdentifyCommand {
    /// Dead time, rise time (10–90 %) and transient time (±2 % band) of a step response.
    Step(StepArgs),
    /// Frequency response by Welch's method (H1), coherence, phase and group delay, and a
    /// least-squares fit of dead time + lag written as the dyno's parameters.
    Frf(FrfArgs),
}

#[derive(clap::Args, Debug)]
pub struct StepArgs {
    /// CSV with a header row; uniformly sampled.
    pub csv: PathBuf,
    /// Time column [s].
    #[arg(long, default_value = "time")]
    pub time: String,
    /// Setpoint column (the step).
    #[arg(long, default_value = "torque_setpoint")]
    pub setpoint: String,
    /// Response column.
    #[arg(long, default_value = "torque_dyno")]
    pub response: String,
    /// Settling band, share of the step height.
    #[arg(long, default_value_t = 0.02)]
    pub band: f64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelForm {
    /// Continuous G(jω); on data with a held input the dead time includes half a sample.
    Continuous,
    /// Input held between samples, continuous delay and lag (exact for sampled bench data).
    Held,
    /// The dyno FMU's own discrete loop at its controller cycle (= the sampling step).
    DynoCycle,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DetrendArg {
    None,
    Constant,
}

#[derive(clap::Args, Debug)]
pub struct FrfArgs {
    /// CSV with a header row; uniformly sampled.
    pub csv: PathBuf,
    /// Time column [s].
    #[arg(long, default_value = "time")]
    pub time: String,
    /// Input column (the excitation, e.g. the torque setpoint).
    #[arg(long, default_value = "torque_setpoint")]
    pub input: String,
    /// Output column (e.g. the air-gap or measured torque).
    #[arg(long, default_value = "torque_dyno")]
    pub output: String,
    /// Welch segment length (samples; Hann window).
    #[arg(long, default_value_t = 1024)]
    pub nperseg: usize,
    /// Overlap of the segments (samples) [default: nperseg/2].
    #[arg(long)]
    pub noverlap: Option<usize>,
    /// Per-segment detrending.
    #[arg(long, value_enum, default_value_t = DetrendArg::Constant)]
    pub detrend: DetrendArg,
    /// Order of the lag after the dead time.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub order: u8,
    /// Lowest frequency of the fit [Hz].
    #[arg(long, default_value_t = 0.0)]
    pub f_min: f64,
    /// Highest frequency of the fit [Hz] [default: 0.4·fs].
    #[arg(long)]
    pub f_max: Option<f64>,
    /// Bins with lower coherence are left out of the fit.
    #[arg(long, default_value_t = 0.8)]
    pub min_coherence: f64,
    /// Form of the fitted model.
    #[arg(long, value_enum, default_value_t = ModelForm::Held)]
    pub model: ModelForm,
    /// Instance name for the parameter snippet (system file).
    #[arg(long, default_value = "dyno_rl")]
    pub instance: String,
    /// Also write the parameter snippet to this file.
    #[arg(long, value_name = "FILE")]
    pub snippet: Option<PathBuf>,
    /// Write the plots STEM-bode-magnitude, STEM-bode-phase, STEM-group-delay and
    /// STEM-coherence, each as SVG and PNG.
    #[arg(long, value_name = "STEM")]
    pub plot: Option<PathBuf>,
    /// Rows of the FRF table (log-spaced frequencies).
    #[arg(long, default_value_t = 16)]
    pub rows: usize,
    /// Print JSON (full FRF, fit, snippet) instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: IdentifyArgs) -> anyhow::Result<()> {
    match args.command {
        IdentifyCommand::Step(a) => run_step(a),
        IdentifyCommand::Frf(a) => run_frf(a),
    }
}

fn run_step(a: StepArgs) -> anyhow::Result<()> {
    let ts = TimeSeries::read_csv(&a.csv, &a.time)?;
    let cfg = StepConfig {
        band: a.band,
        ..StepConfig::default()
    };
    let r = step::analyse(&ts, &a.setpoint, &a.response, &cfg)?;
    if a.json {
        super::json::print(&serde_json::to_string_pretty(&r)?)?;
    } else {
        print!("{}", step_table(&r, &a, &cfg));
    }
    Ok(())
}

fn ms(x: f64) -> String {
    format!("{:.4} ms", x * 1e3)
}

fn step_table(r: &StepResult, a: &StepArgs, cfg: &StepConfig) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Step response: {} ({} → {}), sampled every {} (fs {:.1} Hz)\n",
        a.csv.display(),
        a.setpoint,
        a.response,
        ms(r.dt),
        1.0 / r.dt
    );
    let rows: Vec<(&str, String)> = vec![
        ("step at", format!("{:.6} s", r.t_step)),
        (
            "setpoint",
            format!("{} → {}", r.setpoint_before, r.setpoint_after),
        ),
        (
            "response",
            format!(
                "{:.4} → {:.4} (noise σ {:.3})",
                r.response_before, r.response_after, r.noise_std
            ),
        ),
        (
            "dead time T_d",
            format!(
                "{} ({:.2} samples; least-squares dead time + first-order lag)",
                ms(r.dead_time),
                r.dead_time / r.dt
            ),
        ),
        (
            "response start",
            format!(
                "{} (first departure beyond the noise)",
                ms(r.response_start)
            ),
        ),
        (
            "rise time",
            format!(
                "{} ({:.0}–{:.0} %)",
                ms(r.rise_time),
                cfg.rise_low * 100.0,
                cfg.rise_high * 100.0
            ),
        ),
        (
            "transient time",
            match r.transient_time {
                Some(t) => format!("{} (±{:.0} % band)", ms(t), cfg.band * 100.0),
                None => "not settled by the end of the record".into(),
            },
        ),
        ("overshoot", format!("{:.2} %", r.overshoot * 100.0)),
        (
            "fitted lag",
            format!(
                "T = {}, gain {:.4}, rms residual {:.4}",
                ms(r.fit.time_constant),
                r.fit.gain,
                r.fit.rms_residual
            ),
        ),
    ];
    for (k, v) in rows {
        let _ = writeln!(s, "{k:<16} {v}");
    }
    if r.noise_limited {
        let _ = writeln!(
            s,
            "\nnote: the noise (3σ = {:.3}) is wider than the settling band; the transient time is lengthened by noise",
            3.0 * r.noise_std
        );
    }
    s
}

fn run_frf(a: FrfArgs) -> anyhow::Result<()> {
    let ts = TimeSeries::read_csv(&a.csv, &a.time)?;
    let source = a.csv.display().to_string();
    let u = ts.column(&a.input)?;
    let y = ts.column(&a.output)?;
    let welch = WelchConfig {
        nperseg: a.nperseg,
        noverlap: a.noverlap,
        detrend: match a.detrend {
            DetrendArg::None => Detrend::None,
            DetrendArg::Constant => Detrend::Constant,
        },
    };
    let frf = frf::h1(u, y, ts.fs(), &welch, &source)?;
    let cfg = FitConfig {
        order: if a.order == 2 {
            LagOrder::Second
        } else {
            LagOrder::First
        },
        f_min: a.f_min,
        f_max: a.f_max.unwrap_or(0.4 * ts.fs()),
        min_coherence: a.min_coherence,
        sampling: match a.model {
            ModelForm::Continuous => Sampling::Continuous,
            ModelForm::Held => Sampling::HeldInput,
            ModelForm::DynoCycle => Sampling::DynoCycle { cycle_time: ts.dt },
        },
    };
    let fitted = fit::fit(&frf, &cfg)?;
    let snippet = fitted.parameters_toml(&a.instance);
    if let Some(path) = &a.snippet {
        std::fs::write(path, &snippet)
            .with_context(|| format!("writing the parameter snippet {}", path.display()))?;
    }
    if let Some(stem) = &a.plot {
        plots(&frf, &fitted, stem)?;
    }
    if a.json {
        let doc = serde_json::json!({
            "file": source,
            "input": a.input,
            "output": a.output,
            "fs": ts.fs(),
            "welch": welch,
            "frf": frf,
            "fit": fitted,
            "snippet": snippet,
        });
        super::json::print(&serde_json::to_string_pretty(&doc)?)?;
    } else {
        print!("{}", frf_table(&frf, &fitted, &a, &ts, &welch));
        println!("\n{snippet}");
    }
    Ok(())
}

/// The FRF at log-spaced frequencies beside the fitted model, then the fit.
fn frf_table(frf: &Frf, f: &FrfFit, a: &FrfArgs, ts: &TimeSeries, w: &WelchConfig) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "FRF {} → {}: {} ({} samples at {:.1} Hz), Welch Hann nperseg {} overlap {}, {} segments\n",
        a.input,
        a.output,
        a.csv.display(),
        ts.len(),
        ts.fs(),
        w.nperseg,
        w.overlap(),
        frf.segments
    );
    let _ = writeln!(
        s,
        "{:>10} {:>10} {:>11} {:>9} {:>11} {:>11} {:>11}",
        "f [Hz]", "|H| [dB]", "phase [°]", "coh [-]", "τ_gr [ms]", "fit [dB]", "fit [°]"
    );
    // log-spaced rows between the first bin and Nyquist
    let n = frf.freq.len();
    let (f0, f1) = (frf.freq[0].max(1e-12), frf.freq[n - 1]);
    let mut rows: Vec<usize> = (0..a.rows.max(2))
        .map(|i| {
            let target = f0 * (f1 / f0).powf(i as f64 / (a.rows.max(2) - 1) as f64);
            frf.freq
                .iter()
                .enumerate()
                .min_by(|x, y| (x.1 - target).abs().total_cmp(&(y.1 - target).abs()))
                .map_or(0, |(k, _)| k)
        })
        .collect();
    rows.dedup();
    // the model's phase is unwrapped alongside the data's, so both start from the same branch
    let model: Vec<_> = frf.freq.iter().map(|&fr| f.response(fr)).collect();
    let model_phase = frf::unwrap(&model.iter().map(|z| z.arg()).collect::<Vec<_>>());
    for k in rows {
        let _ = writeln!(
            s,
            "{:>10.2} {:>10.3} {:>11.2} {:>9.4} {:>11.4} {:>11.3} {:>11.2}",
            frf.freq[k],
            20.0 * frf.magnitude[k].log10(),
            frf.phase[k].to_degrees(),
            frf.coherence[k],
            frf.group_delay[k] * 1e3,
            20.0 * model[k].norm().log10(),
            model_phase[k].to_degrees()
        );
    }
    write_fit(&mut s, frf, f, a, ts);
    s
}

/// The fitted lag below the FRF table: its order and model, the dead time, the time constant
/// or mode, the gain and residual, and the low-frequency group delay it explains.
fn write_fit(s: &mut String, frf: &Frf, f: &FrfFit, a: &FrfArgs, ts: &TimeSeries) {
    let _ = writeln!(
        s,
        "\nFit ({} order lag, {} model, {:.1}–{:.1} Hz, {} bins with coherence ≥ {}):",
        match f.order {
            LagOrder::First => "first",
            LagOrder::Second => "second",
        },
        match f.sampling {
            Sampling::Continuous => "continuous",
            Sampling::HeldInput => "held-input sampled",
            Sampling::DynoCycle { .. } => "dyno-cycle sampled",
        },
        f.f_lo,
        f.f_hi,
        f.bins,
        a.min_coherence
    );
    let _ = writeln!(
        s,
        "  dead time T_d   {} ({:.2} samples)",
        ms(f.dead_time),
        f.dead_time * ts.fs()
    );
    if let Some(t) = f.time_constant {
        let _ = writeln!(s, "  time constant T {}", ms(t));
    }
    if let (Some(wn), Some(z)) = (f.natural_frequency, f.damping_ratio) {
        let _ = writeln!(
            s,
            "  ω_n             {wn:.2} rad/s ({:.2} Hz; time_constant {})\n  damping ζ       {z:.4}",
            wn / (2.0 * std::f64::consts::PI),
            ms(1.0 / wn)
        );
    }
    let _ = writeln!(
        s,
        "  gain K          {:.4}\n  rms log residual {:.4}",
        f.gain, f.rms_residual
    );
    // the group delay at low frequency is T_d + T (first order)
    let coherent: Vec<f64> = frf
        .group_delay
        .iter()
        .zip(&frf.coherence)
        .zip(&frf.freq)
        .filter(|((_, c), fr)| **c >= a.min_coherence && **fr <= f.f_hi)
        .map(|((g, _), _)| *g)
        .take(8)
        .collect();
    if !coherent.is_empty() {
        let _ = writeln!(
            s,
            "  low-frequency group delay {} (≈ T_d + T for a first-order lag)",
            ms(coherent.iter().sum::<f64>() / coherent.len() as f64)
        );
    }
}

fn plots(frf: &Frf, f: &FrfFit, stem: &Path) -> anyhow::Result<()> {
    let with = |suffix: &str| {
        let mut s = stem.as_os_str().to_owned();
        s.push(suffix);
        PathBuf::from(s)
    };
    let pts = |ys: &[f64]| -> Vec<(f64, f64)> {
        frf.freq
            .iter()
            .zip(ys)
            .filter(|(fr, _)| **fr > 0.0)
            .map(|(a, b)| (*a, *b))
            .collect()
    };
    let model: Vec<_> = frf.freq.iter().map(|&fr| f.response(fr)).collect();
    let db: Vec<f64> = frf.magnitude.iter().map(|m| 20.0 * m.log10()).collect();
    let model_db: Vec<f64> = model.iter().map(|z| 20.0 * z.norm().log10()).collect();
    let deg: Vec<f64> = frf.phase.iter().map(|p| p.to_degrees()).collect();
    let model_deg: Vec<f64> = frf::unwrap(&model.iter().map(|z| z.arg()).collect::<Vec<_>>())
        .iter()
        .map(|p| p.to_degrees())
        .collect();
    let gd: Vec<f64> = frf.group_delay.iter().map(|g| g * 1e3).collect();
    let model_gd: Vec<f64> = frf::group_delay(
        &frf.freq,
        &frf::unwrap(&model.iter().map(|z| z.arg()).collect::<Vec<_>>()),
    )
    .iter()
    .map(|g| g * 1e3)
    .collect();
    // The fitted model's curve over the measured estimate's.
    let against = |title: &str, y_label: &str, model: &[f64], measured: &[f64]| {
        tb_plot::LinePlot::new(title, "f [Hz]", y_label)
            .series("fitted model", &pts(model))
            .reference("measured (H1 estimate)", &pts(measured))
            .log_x(true)
    };
    let out = [
        (
            against("Dyno loop frequency response: magnitude of the torque transfer, measured (H1) against the fitted model", "|H| [dB]", &model_db, &db),
            with("-bode-magnitude"),
        ),
        (
            against("Dyno loop frequency response: phase (unwrapped), measured (H1) against the fitted model", "phase [°]", &model_deg, &deg),
            with("-bode-phase"),
        ),
        (
            against("Dyno loop group delay −dφ/dω: the loop's dead time plus its lag, measured (H1) against the fitted model", "τ_gr [ms]", &model_gd, &gd),
            with("-group-delay"),
        ),
        (
            tb_plot::LinePlot::new("Coherence of setpoint and response: where near 1, the estimate above is trustworthy", "f [Hz]", "γ² [-]")
                .series("coherence", &pts(&frf.coherence))
                .log_x(true),
            with("-coherence"),
        ),
    ];
    for (plot, path) in out {
        plot.save_both(&path)
            .with_context(|| format!("writing the plot {}", path.display()))?;
        eprintln!("wrote {}.svg and .png", path.display());
    }
    Ok(())
}
