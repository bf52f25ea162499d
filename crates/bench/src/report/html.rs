//! report.html: the study's report on one page an engineer can hand to a colleague. It is
//! self-contained (no network, no external style, script or font; every picture inline
//! SVG), so that it renders the same from a mail attachment or an archive years later.
//!
//! It carries Tab. 1 (from the same [`Table1`] as table1.md, through the same sentences),
//! the parameters' picture ([`super::forest`]), every compared signal measured against the
//! twin ([`super::signals`]), the study's other plots (their SVG files, read back), and
//! where the page came from ([`super::provenance`]). Everything that comes from a file or
//! a name is escaped: a path or a variable may hold `<` or `&`.

pub use super::escape::esc;
use super::forest::{self, Row};
use super::provenance::{self, Provenance};
use super::signals::SignalFigure;
use super::truth::Truth;
use super::{
    parameter_line, short, table1_statements, values_to_load, ReportError, Table1, TableStep,
    TABLE1_LEGEND,
};
use std::path::{Path, PathBuf};
use tb_optimize::{Study, StudyResult};

/// What the page is made of.
pub struct Page<'a> {
    pub study: &'a Study,
    pub result: &'a StudyResult,
    pub table: &'a Table1,
    pub signals: &'a [SignalFigure],
    /// The files the report wrote before the page: their SVGs are inlined.
    pub plots: &'a [PathBuf],
}

/// A sentence of the Markdown report in HTML: escaped, its `code` spans as code.
fn prose(s: &str) -> String {
    s.split('`')
        .enumerate()
        .map(|(k, part)| match k % 2 {
            1 => format!("<code>{}</code>", esc(part)),
            _ => esc(part),
        })
        .collect()
}

/// The page.
pub fn page(p: &Page) -> Result<String, ReportError> {
    let truth = Truth::beside(&p.study.measurement_path);
    let rows = forest::rows(p.table, truth.as_ref());
    let provenance = provenance::collect(p.study, truth.as_ref().map(|t| t.path.as_path()));
    let title = format!("twinbench report: study {}", p.table.study);
    let mut s = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        esc(&title)
    );
    s.push_str(&header(p, &provenance));
    s.push_str("<main class=\"wrap\">\n");
    s.push_str(&facts(p));
    s.push_str(&table1_section(p.table));
    s.push_str(&parameters_section(&rows, truth.as_ref()));
    s.push_str(&signals_section(p.study, p.signals));
    s.push_str(&plots_section(p)?);
    s.push_str(&provenance_section(&provenance, p.result));
    s.push_str("</main>\n</body>\n</html>\n");
    Ok(s)
}

/// One small stylesheet: a sober print-friendly page, numbers in tabular figures.
const STYLE: &str = "
:root{--ink:#1d2430;--muted:#5b6676;--line:#d8dee6;--soft:#f6f8fa;--accent:#1f4e9a;--good:#2e7d32;--warn:#b26a00;--bad:#c62828}
*{box-sizing:border-box}
body{margin:0;color:var(--ink);background:#fff;font:15px/1.5 system-ui,-apple-system,'Segoe UI',Roboto,'DejaVu Sans',Arial,sans-serif}
.wrap{max-width:1240px;margin:0 auto;padding:0 28px}
header{background:#1d2430;color:#fff;padding:26px 0 20px}
header h1{margin:0 0 6px;font-size:26px;font-weight:600}
header p{margin:2px 0;color:#c5cdd8;font-size:14px}
nav{background:var(--soft);border-bottom:1px solid var(--line);font-size:14px}
nav a{color:var(--accent);text-decoration:none;margin-right:22px;line-height:42px}
section{padding:4px 0 22px;border-bottom:1px solid var(--line)}
h2{font-size:20px;margin:26px 0 10px}
h3{font-size:15px;margin:20px 0 6px}
p{margin:8px 0;max-width:75em}
.muted{color:var(--muted)}
.facts{display:grid;grid-template-columns:repeat(auto-fit,minmax(230px,1fr));gap:14px;margin:22px 0}
.fact{border:1px solid var(--line);border-radius:6px;padding:10px 14px}
.fact span{display:block;color:var(--muted);font-size:13px}
.fact b{display:block;font-size:20px;font-weight:600;font-variant-numeric:tabular-nums}
table{border-collapse:collapse;width:100%;font-size:13.5px}
th,td{border-bottom:1px solid var(--line);padding:6px 8px;text-align:left;vertical-align:top}
th{background:var(--soft);font-weight:600}
th.n,td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.better{color:var(--good)}
td.worse{color:var(--bad)}
tbody.step{border-top:2px solid #a9b3bf}
td.params{min-width:22em}
td.params div{margin-bottom:2px}
.verdict{border-left:4px solid var(--good);background:var(--soft);padding:8px 14px;margin:12px 0}
.verdict.wanting{border-left-color:var(--warn)}
.legend{color:var(--muted);font-size:13px}
figure{margin:16px 0 22px;break-inside:avoid}
figure>svg{display:block;width:100%;height:auto;border:1px solid var(--line);border-radius:4px}
figcaption{color:var(--muted);font-size:13px;margin-top:6px}
.missing{border:1px dashed var(--warn);border-radius:4px;padding:12px 16px;color:var(--warn);margin:16px 0}
code{font:13px ui-monospace,'DejaVu Sans Mono',monospace;background:var(--soft);padding:1px 4px;border-radius:3px}
td.hash{font:12px ui-monospace,'DejaVu Sans Mono',monospace;word-break:break-all}
td.path{word-break:break-all}
@media print{header{background:none;color:#000}header p{color:#333}nav{display:none}}
";

/// The title, what was compared, and the contents.
fn header(p: &Page, prov: &Provenance) -> String {
    let lap = p.study.measurement_path.display().to_string();
    let system = p.study.system_path.display().to_string();
    format!(
        "<header><div class=\"wrap\"><h1>Study {}: the twin against the measured lap</h1>\
         <p>measurement {} · system {}</p><p>written {} by twinbench {}</p></div></header>\n\
         <nav><div class=\"wrap\"><a href=\"#tab1\">Tab. 1</a><a href=\"#parameters\">Parameters</a>\
         <a href=\"#signals\">Signals</a><a href=\"#plots\">More plots</a>\
         <a href=\"#provenance\">Provenance</a></div></nav>\n",
        esc(&p.table.study),
        esc(&lap),
        esc(&system),
        esc(&prov.date),
        esc(prov.version)
    )
}

/// The figures a reader looks for first, as cards above the table.
fn facts(p: &Page) -> String {
    let mut cards: Vec<(String, String, String)> = Vec::new();
    if let Some(d) = p.table.lap_time_difference {
        cards.push((
            "lap time, twin − vehicle".into(),
            format!("{:+.3} s → {:+.3} s", d.initial_s, d.optimized_s),
            format!("initial → optimised; measured {:.3} s", d.measured_s),
        ));
    }
    let answer = p.table.joint.as_ref();
    let signals: Vec<_> = match answer {
        Some(j) => j.signals.iter().collect(),
        None => p.table.steps.iter().flat_map(|s| &s.signals).collect(),
    };
    if !signals.is_empty() {
        let mean = |f: fn(&super::TableRow) -> f64| {
            signals.iter().map(|r| f(r)).sum::<f64>() / signals.len() as f64
        };
        cards.push((
            "mean e of the fitted signals".into(),
            format!(
                "{:.4} → {:.4}",
                mean(|r| r.e_initial),
                mean(|r| r.e_optimized)
            ),
            format!("{} signals, initial → optimised (0: equal)", signals.len()),
        ));
    }
    if let Some(c) = &p.table.model_check {
        cards.push((
            "model check".into(),
            if c.discrepancy {
                "the twin is wanting"
            } else {
                "the twin holds"
            }
            .into(),
            format!("p = {:.3} ({} terms)", c.p_value, c.degrees_of_freedom),
        ));
    }
    let r = p.result;
    cards.push((
        "optimisation".into(),
        format!("{} laps in {:.1} s", r.simulations, r.wall_seconds),
        format!("{} threads, seed {}", r.threads, r.seed),
    ));
    let cards: String = cards
        .iter()
        .map(|(label, value, note)| {
            format!(
                "<div class=\"fact\"><span>{}</span><b>{}</b><span>{}</span></div>",
                esc(label),
                esc(value),
                esc(note)
            )
        })
        .collect();
    format!("<div class=\"facts\">{cards}</div>\n")
}

/// Tab. 1 as a table, then the sentences table1.md has under it.
fn table1_section(t: &Table1) -> String {
    let mut s = format!(
        "<section id=\"tab1\"><h2>Tab. 1: the twin against the vehicle measurement before and \
         after the optimisation ({})</h2>\n<table><thead><tr><th>step</th><th>validation signal</th>\
         <th>optimised parameters</th><th class=\"n\">e initial</th><th class=\"n\">e optimised</th>\
         <th class=\"n\">m initial</th><th class=\"n\">m optimised</th><th class=\"n\">bias initial</th>\
         <th class=\"n\">bias optimised</th></tr></thead>\n",
        esc(&t.study)
    );
    let labelled = t
        .steps
        .iter()
        .map(|st| (st.step.to_string(), st))
        .chain(t.joint.iter().map(|st| ("all".to_string(), st)))
        .chain(t.hold_out.iter().map(|st| ("held out".to_string(), st)));
    for (label, st) in labelled {
        s.push_str(&table1_body(&label, st));
    }
    s.push_str("</table>\n");
    s.push_str(&table1_notes(t));
    s.push_str("</section>\n");
    s
}

/// One step of Tab. 1: its label and parameters span its signals' rows.
fn table1_body(label: &str, st: &TableStep) -> String {
    let n = st.signals.len();
    let params: String = st
        .parameters
        .iter()
        .map(|p| format!("<div>{}</div>", esc(&parameter_line(p))))
        .collect();
    let mut s = String::from("<tbody class=\"step\">");
    for (k, r) in st.signals.iter().enumerate() {
        s.push_str("<tr>");
        if k == 0 {
            s.push_str(&format!(
                "<td rowspan=\"{n}\"><b>{}</b><div class=\"muted\">{}</div></td>",
                esc(label),
                esc(&st.name)
            ));
        }
        let signal = match &r.lap {
            Some(lap) => format!("{} ({lap})", r.signal),
            None => r.signal.clone(),
        };
        s.push_str(&format!("<td>{}</td>", esc(&signal)));
        if k == 0 {
            s.push_str(&format!(
                "<td rowspan=\"{n}\" class=\"params\">{params}</td>"
            ));
        }
        // e falls where the twin got closer: green; red where it rose.
        let class = match r.e_optimized.partial_cmp(&r.e_initial) {
            Some(std::cmp::Ordering::Less) => "n better",
            Some(std::cmp::Ordering::Greater) => "n worse",
            _ => "n",
        };
        s.push_str(&format!(
            "<td class=\"n\">{:.4}</td><td class=\"{class}\">{:.4}</td><td class=\"n\">{:.4}</td>\
             <td class=\"n\">{:.4}</td><td class=\"n\">{:+.2} %</td><td class=\"n\">{:+.2} %</td></tr>\n",
            r.e_initial,
            r.e_optimized,
            r.slope_initial,
            r.slope_optimized,
            r.bias_percent_initial,
            r.bias_percent_optimized
        ));
    }
    s.push_str("</tbody>\n");
    s
}

/// What table1.md says under the table, in the same words.
fn table1_notes(t: &Table1) -> String {
    let mut s = String::new();
    if let Some(j) = &t.joint {
        s.push_str(&format!("<p>{}</p>\n", prose(&values_to_load(j))));
    }
    if let Some(c) = &t.model_check {
        let (class, verdict) = match c.discrepancy {
            true => (
                "verdict wanting",
                "The twin, not the noise, limits the answer",
            ),
            false => ("verdict", "The noise, not the twin, limits the answer"),
        };
        s.push_str(&format!(
            "<div class=\"{class}\"><b>Model check: {verdict}.</b> {} ({}).</div>\n",
            esc(&c.detail),
            esc(&c.method)
        ));
    }
    if let Some(b) = &t.bootstrap {
        s.push_str(&format!(
            "<p>{} (1: the sandwich's intervals are as wide as the refits scatter; the refits see only the noise, not the twin's share).</p>\n",
            esc(&b.summary(|n| short(n).to_string()))
        ));
    }
    let statements = table1_statements(t);
    if !statements.is_empty() {
        s.push_str("<h3>About the intervals</h3>\n<ul>\n");
        for line in statements {
            let line = line.strip_prefix("- ").unwrap_or(&line);
            s.push_str(&format!("<li>{}</li>\n", prose(line)));
        }
        s.push_str("</ul>\n");
    }
    if let Some(d) = t.lap_time_difference {
        s.push_str(&format!(
            "<p>Lap time, twin − vehicle: {:+.3} s initial, {:+.3} s optimised (measured {:.3} s).</p>\n",
            d.initial_s, d.optimized_s, d.measured_s
        ));
    }
    s.push_str(&format!(
        "<p class=\"legend\">{}</p>\n",
        prose(TABLE1_LEGEND)
    ));
    s
}

/// The forest plot of the parameters.
fn parameters_section(rows: &[Row], truth: Option<&Truth>) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let truth_note = match truth {
        Some(t) => format!(
            " Red: the truth of this synthetic lap, from {}.",
            t.path.display()
        ),
        None => String::new(),
    };
    let caption = format!(
        "Each parameter on axes of its own: left, the move from the value its step started from \
         (circle) to the answer (diamond); right, the answer close up with its 95 % scatter interval \
         (bar) and, where wider, the interval with the model's share (band); an arrow: the \
         interval is open to that side.{truth_note}"
    );
    format!(
        "<section id=\"parameters\"><h2>Parameters: the answer and its intervals against the start</h2>\n{}</section>\n",
        figure(&forest::svg(rows), &caption)
    )
}

/// Every compared signal, or why one is missing.
fn signals_section(study: &Study, figures: &[SignalFigure]) -> String {
    // A study of several laps draws its first fitted one (the laps the result keeps).
    let lap = match study.laps.first() {
        Some(lap) if study.laps.len() > 1 => format!(" (the first fitted lap, {})", lap.name),
        _ => String::new(),
    };
    let mut s = format!(
        "<section id=\"signals\"><h2>Signals: the vehicle measured against the twin</h2>\n\
         <p class=\"muted\">Each signal the study compares, and the four wheel loads, over the \
         lap's distance{}, filtered as the comparison sees them: the vehicle (black), the twin \
         with the initial parameters (grey) and with the optimised ones.</p>\n",
        esc(&lap)
    );
    for f in figures {
        match f {
            SignalFigure::Plot { signal, svg } => s.push_str(&figure(svg, signal)),
            SignalFigure::Missing { signal, why } => s.push_str(&format!(
                "<div class=\"missing\"><b>{}</b>: {}</div>\n",
                esc(signal),
                esc(why)
            )),
        }
    }
    s.push_str("</section>\n");
    s
}

/// The study's own plots, in the order a reader wants them; each SVG file read back.
fn plots_section(p: &Page) -> Result<String, ReportError> {
    // Fz_sum filtered is among the signals already where the study compares it.
    let shown = |signal: &str| {
        p.signals
            .iter()
            .any(|f| matches!(f, SignalFigure::Plot { signal: s, .. } if s == signal))
    };
    let mut svgs: Vec<&PathBuf> = p
        .plots
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "svg"))
        .filter(|f| !(stem(f) == "fz_sum_filtered" && shown("Fz_sum")))
        .collect();
    svgs.sort_by_key(|f| PLOT_ORDER.iter().position(|s| *s == stem(f)).unwrap_or(99));
    let mut s = String::from("<section id=\"plots\"><h2>More plots</h2>\n");
    for f in svgs {
        s.push_str(&figure(&inline_svg(f)?, &caption(&stem(f))));
    }
    s.push_str("</section>\n");
    Ok(s)
}

const PLOT_ORDER: [&str; 5] = [
    "time_over_distance",
    "a_x_over_distance",
    "fz_sum_filtered",
    "fz_sum_unfiltered",
    "best_cost_per_generation",
];

fn stem(f: &Path) -> String {
    f.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A plot's caption: the file it also is (the picture carries its own title).
fn caption(stem: &str) -> String {
    let what = match stem {
        "time_over_distance" => "Time over distance and the twin's lead or lag".to_string(),
        "a_x_over_distance" => "Longitudinal acceleration".into(),
        "fz_sum_filtered" => "Sum of the wheel loads, filtered".into(),
        "fz_sum_unfiltered" => "Sum of the wheel loads, unfiltered, the road's excitation".into(),
        "best_cost_per_generation" => "How the optimiser converged".into(),
        s => match s.strip_prefix("profile_") {
            Some(name) => format!("Profile likelihood of {name}"),
            None => s.into(),
        },
    };
    format!("{what} ({stem}.svg, .png beside this page)")
}

/// An SVG file as an element of the page (an XML declaration has no place inside HTML).
fn inline_svg(path: &Path) -> Result<String, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let start = text.find("<svg").unwrap_or(0);
    Ok(text[start..].trim_end().to_string())
}

/// A picture with its caption; the test of the page counts these.
fn figure(svg: &str, caption: &str) -> String {
    format!(
        "<figure class=\"plot\">{svg}<figcaption>{}</figcaption></figure>\n",
        esc(caption)
    )
}

/// Which twinbench wrote the page, when, and the digests of its inputs.
fn provenance_section(prov: &Provenance, result: &StudyResult) -> String {
    let mut s = format!(
        "<section id=\"provenance\"><h2>Provenance</h2>\n<table><tbody>\
         <tr><th>written by</th><td>twinbench {}</td></tr>\
         <tr><th>date</th><td>{}</td></tr>\
         <tr><th>study file</th><td class=\"path\">{}</td></tr>\
         <tr><th>run</th><td>seed {}, {} full-lap simulations on {} threads, {:.1} s{}</td></tr>\
         </tbody></table>\n<h3>Inputs (SHA-256)</h3>\n<table><thead><tr><th>input</th><th>file</th>\
         <th class=\"n\">bytes</th><th>SHA-256</th></tr></thead><tbody>\n",
        esc(prov.version),
        esc(&prov.date),
        esc(&prov.study.display().to_string()),
        result.seed,
        result.simulations,
        result.threads,
        result.wall_seconds,
        if result.resumed {
            ", resumed from a checkpoint"
        } else {
            ""
        }
    );
    for input in &prov.inputs {
        let (size, digest) = match &input.digest {
            Ok((size, hex)) => (size.to_string(), hex.clone()),
            Err(e) => (String::new(), format!("not readable: {e}")),
        };
        s.push_str(&format!(
            "<tr><td>{}</td><td class=\"path\">{}</td><td class=\"n\">{}</td><td class=\"hash\">{}</td></tr>\n",
            esc(&input.role),
            esc(&input.path.display().to_string()),
            esc(&size),
            esc(&digest)
        ));
    }
    s.push_str("</tbody></table>\n</section>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_attributes_are_escaped() {
        assert_eq!(
            esc(r#"<b> & "x" 'y'"#),
            "&lt;b&gt; &amp; &quot;x&quot; &#39;y&#39;"
        );
        assert_eq!(esc("Fz_fl ≤ 5 kN"), "Fz_fl ≤ 5 kN");
        // Markdown code spans become code, their text escaped too.
        assert_eq!(
            prose("see `a<b>` & <c>"),
            "see <code>a&lt;b&gt;</code> &amp; &lt;c&gt;"
        );
    }

    /// A step's name and a lap name with markup in them stay text in Tab. 1.
    #[test]
    fn tab1_escapes_names_and_spans_a_steps_rows() {
        let row = |signal: &str| super::super::TableRow {
            lap: Some("lap <2> & more".into()),
            signal: signal.into(),
            e_initial: 0.2,
            e_optimized: 0.1,
            slope_initial: 1.0,
            slope_optimized: 1.0,
            r_squared_initial: 0.9,
            r_squared_optimized: 0.95,
            bias_percent_initial: 1.0,
            bias_percent_optimized: -0.5,
        };
        let step = TableStep {
            step: 1,
            name: "<script>alert(1)</script>".into(),
            parameters: Vec::new(),
            signals: vec![row("Fz_fl"), row("Fz_fr")],
        };
        let html = table1_body("1", &step);
        assert!(!html.contains("<script>"), "{html}");
        assert!(html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
        assert!(html.contains("Fz_fl (lap &lt;2&gt; &amp; more)"));
        assert!(html.contains("rowspan=\"2\""));
        assert!(html.contains("<td class=\"n better\">0.1000</td>"));
    }
}
