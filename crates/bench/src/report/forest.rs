//! The parameters' picture of report.html, a forest plot: one row per parameter with its
//! start, its answer, the answer's 95 % scatter interval, the interval with the model's
//! share where it differs, and the truth where the lap carries one.
//!
//! The parameters have different units and scales, so each row has axes of its own rather
//! than one normalised axis: the left strip spans the start and the answer (how far the
//! optimiser moved it), the right one closes in on the answer (an interval of a percent is
//! a dot beside a move of 50 %). The numbers stand beside each row, as in Tab. 1.
//!
//! Hand-written SVG (not tb-plot's line plots): markers and bars, no lines over distance.

use super::escape::esc;
use super::truth::Truth;
use super::{short, Table1, TableParameter};

/// A 95 % interval; `None` at an end: open (beyond the parameter's range).
pub type Interval = (Option<f64>, Option<f64>);

/// One parameter's row.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub name: String,
    pub unit: Option<String>,
    pub start: f64,
    pub answer: f64,
    pub change_percent: f64,
    pub interval: Option<Interval>,
    pub with_model: Option<Interval>,
    pub truth: Option<f64>,
}

/// The rows: the study's answer (Tab. 1's row "all") where it has one, else every step's
/// parameters (then they carry the intervals).
pub fn rows(t: &Table1, truth: Option<&Truth>) -> Vec<Row> {
    let parameters: Vec<&TableParameter> = match &t.joint {
        Some(j) => j.parameters.iter().collect(),
        None => t.steps.iter().flat_map(|s| &s.parameters).collect(),
    };
    parameters
        .into_iter()
        .map(|p| Row {
            name: short(&p.name).to_string(),
            unit: p.unit.clone(),
            start: p.initial,
            answer: p.optimized,
            change_percent: p.change_percent,
            interval: p.interval,
            // Drawn only where it says more than the scatter interval.
            with_model: p.interval_with_model.filter(|m| Some(*m) != p.interval),
            truth: truth.and_then(|t| t.of(&p.name)),
        })
        .collect()
}

const WIDTH: f64 = 1200.0;
const HEAD: f64 = 80.0;
const ROW: f64 = 88.0;
/// The strips: from the start to the answer, and the close-up of the answer.
const OVERVIEW: (f64, f64) = (175.0, 300.0);
const CLOSE_UP: (f64, f64) = (510.0, 380.0);
const TEXT_X: f64 = 915.0;
const ANSWER: &str = "#1f4e9a";
const MODEL: &str = "#f0a030";
const TRUTH: &str = "#c62828";
const START: &str = "#666";

/// The whole picture.
pub fn svg(rows: &[Row]) -> String {
    let height = HEAD + ROW * rows.len() as f64 + 10.0;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" viewBox="0 0 {WIDTH} {height}" font-family="system-ui, 'DejaVu Sans', sans-serif" font-size="12" role="img" aria-label="The parameters: start, answer and 95 % intervals">"#
    );
    s.push_str(&format!(
        r#"<rect width="{WIDTH}" height="{height}" fill="white"/>"#
    ));
    s.push_str(&legend(rows));
    for (k, row) in rows.iter().enumerate() {
        s.push_str(&row_svg(HEAD + ROW * k as f64, k, row));
    }
    s.push_str("</svg>");
    s
}

/// The marks' key and the strips' headings.
fn legend(rows: &[Row]) -> String {
    // The marks' centre line, low enough for the truth's triangle above it.
    let y = 26.0;
    let mut items = vec![
        (start_mark(20.0, y), "start (the value its step began from)"),
        (answer_mark(20.0, y), "answer"),
        (bar(8.0, 32.0, y, ANSWER, 3.0), "95 % scatter interval"),
    ];
    if rows.iter().any(|r| r.with_model.is_some()) {
        items.push((band(8.0, 32.0, y), "with the model's share"));
    }
    if rows.iter().any(|r| r.truth.is_some()) {
        items.push((truth_mark(20.0, y), "truth of the lap"));
    }
    let mut s = String::new();
    let mut x = 10.0;
    for (mark, label) in items {
        s.push_str(&format!(
            r#"<g transform="translate({x},0)">{mark}<text x="40" y="{}">{}</text></g>"#,
            y + 4.0,
            esc(label)
        ));
        x += 60.0 + 6.6 * label.chars().count() as f64;
    }
    for ((x0, _), heading) in [
        (OVERVIEW, "from the start to the answer"),
        (CLOSE_UP, "the answer close up, with its intervals"),
        ((TEXT_X, 0.0), "values"),
    ] {
        s.push_str(&format!(
            r##"<text x="{x0}" y="68" font-weight="600" fill="#333">{}</text>"##,
            esc(heading)
        ));
    }
    s
}

/// One parameter: its name, both strips, its numbers.
fn row_svg(top: f64, k: usize, row: &Row) -> String {
    let y = top + 40.0;
    let mut s = String::new();
    if k.is_multiple_of(2) {
        s.push_str(&format!(
            r##"<rect x="0" y="{top}" width="{WIDTH}" height="{ROW}" fill="#f6f8fa"/>"##
        ));
    }
    let unit = row
        .unit
        .as_deref()
        .map(|u| format!(" [{u}]"))
        .unwrap_or_default();
    s.push_str(&format!(
        r##"<text x="12" y="{}" font-size="14" font-weight="600">{}</text><text x="12" y="{}" fill="#5b6676">{}{}</text>"##,
        y - 4.0,
        esc(&row.name),
        y + 14.0,
        super::change_words(row.change_percent, row.start, row.answer),
        esc(&unit)
    ));
    // Everything drawn lies within its strip: the close-up's values and the start.
    let mut overview = close_up_values(row);
    overview.push(row.start);
    let overview = Scale::over(&overview, OVERVIEW, 0.08);
    s.push_str(&axis(&overview, y));
    s.push_str(&marks(&overview, y, row, false));
    let close_up = Scale::over(&close_up_values(row), CLOSE_UP, 0.15);
    s.push_str(&axis(&close_up, y));
    s.push_str(&marks(&close_up, y, row, true));
    s.push_str(&numbers(top, row));
    s
}

/// What the close-up must show: the answer, its intervals' finite ends, the truth.
fn close_up_values(row: &Row) -> Vec<f64> {
    let mut v = vec![row.answer];
    for (lo, hi) in row.interval.iter().chain(&row.with_model) {
        v.extend(lo.iter().chain(hi));
    }
    v.extend(row.truth);
    v
}

/// The marks of a row on one strip. The start appears on the close-up only where it lies
/// within it; an open end of an interval runs to the strip's edge with an arrow.
fn marks(s: &Scale, y: f64, row: &Row, close_up: bool) -> String {
    let mut out = String::new();
    if !close_up {
        // The move, faint: the direction from the start to the answer.
        out.push_str(&format!(
            r##"<line x1="{:.1}" y1="{y}" x2="{:.1}" y2="{y}" stroke="#b8c2cc" stroke-width="2"/>"##,
            s.x(row.start),
            s.x(row.answer)
        ));
    }
    if let Some(m) = row.with_model {
        let (a, b) = s.ends(m);
        out.push_str(&band(a, b, y));
        out.push_str(&open_arrows(s, m, y, MODEL));
    }
    if let Some(i) = row.interval {
        let (a, b) = s.ends(i);
        out.push_str(&bar(a, b, y, ANSWER, 3.0));
        out.push_str(&open_arrows(s, i, y, ANSWER));
    }
    if !close_up || s.contains(row.start) {
        out.push_str(&start_mark(s.x(row.start), y));
    }
    if let Some(t) = row.truth {
        out.push_str(&truth_mark(s.x(t), y));
    }
    out.push_str(&answer_mark(s.x(row.answer), y));
    out
}

/// The row's numbers, in Tab. 1's precision.
fn numbers(top: f64, row: &Row) -> String {
    let unit = row
        .unit
        .as_deref()
        .map(|u| format!(" {u}"))
        .unwrap_or_default();
    let mut lines = vec![format!(
        "answer {:.4}{unit} (start {:.4})",
        row.answer, row.start
    )];
    lines.push(match row.interval {
        Some(i) => format!("95 % interval {}", interval_text(i)),
        None => "no interval (Tab. 1 says why)".into(),
    });
    if let Some(m) = row.with_model {
        lines.push(format!("with the model's share {}", interval_text(m)));
    }
    if let Some(t) = row.truth {
        lines.push(format!("truth {t:.4}{unit}"));
    }
    lines
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let weight = if k == 0 { r#" font-weight="600""# } else { "" };
            format!(
                r#"<text x="{TEXT_X}" y="{}"{weight}>{}</text>"#,
                top + 22.0 + 17.0 * k as f64,
                esc(l)
            )
        })
        .collect()
}

/// `[0.8101, 0.8215]`, an open end as "open".
pub fn interval_text((lo, hi): Interval) -> String {
    let end = |e: Option<f64>| e.map_or("open".to_string(), |x| format!("{x:.4}"));
    format!("[{}, {}]", end(lo), end(hi))
}

/// A strip's axis line with its ticks, labelled below.
fn axis(s: &Scale, y: f64) -> String {
    let base = y + 16.0;
    let mut out = format!(
        r##"<line x1="{}" y1="{base}" x2="{}" y2="{base}" stroke="#9aa5b1"/>"##,
        s.x0,
        s.x0 + s.w
    );
    for t in s.ticks() {
        let x = s.x(t);
        out.push_str(&format!(
            r##"<line x1="{x:.1}" y1="{base}" x2="{x:.1}" y2="{}" stroke="#9aa5b1"/><text x="{x:.1}" y="{}" text-anchor="middle" font-size="11" fill="#5b6676">{}</text>"##,
            base + 4.0,
            base + 16.0,
            esc(&tb_plot::tick_label(t))
        ));
    }
    out
}

fn start_mark(x: f64, y: f64) -> String {
    format!(
        r#"<circle cx="{x:.1}" cy="{y}" r="5" fill="white" stroke="{START}" stroke-width="2"/>"#
    )
}

fn answer_mark(x: f64, y: f64) -> String {
    format!(
        r#"<polygon points="{:.1},{y} {x:.1},{} {:.1},{y} {x:.1},{}" fill="{ANSWER}"/>"#,
        x - 6.0,
        y - 6.0,
        x + 6.0,
        y + 6.0
    )
}

/// A red tick through the axis with a triangle above: visible over a bar.
fn truth_mark(x: f64, y: f64) -> String {
    format!(
        r#"<line x1="{x:.1}" y1="{}" x2="{x:.1}" y2="{}" stroke="{TRUTH}" stroke-width="2"/><polygon points="{:.1},{} {:.1},{} {x:.1},{}" fill="{TRUTH}"/>"#,
        y - 11.0,
        y + 11.0,
        x - 5.0,
        y - 19.0,
        x + 5.0,
        y - 19.0,
        y - 11.0
    )
}

/// An interval: a bar with end caps.
fn bar(a: f64, b: f64, y: f64, colour: &str, width: f64) -> String {
    format!(
        r#"<line x1="{a:.1}" y1="{y}" x2="{b:.1}" y2="{y}" stroke="{colour}" stroke-width="{width}"/><line x1="{a:.1}" y1="{}" x2="{a:.1}" y2="{}" stroke="{colour}" stroke-width="2"/><line x1="{b:.1}" y1="{}" x2="{b:.1}" y2="{}" stroke="{colour}" stroke-width="2"/>"#,
        y - 6.0,
        y + 6.0,
        y - 6.0,
        y + 6.0
    )
}

/// The wider interval with the model's share: a light band behind the scatter interval.
fn band(a: f64, b: f64, y: f64) -> String {
    format!(
        r#"<rect x="{a:.1}" y="{}" width="{:.1}" height="16" fill="{MODEL}" fill-opacity="0.45"/>"#,
        y - 8.0,
        (b - a).max(1.0)
    )
}

/// Arrowheads at a strip's edges where an interval is open.
fn open_arrows(s: &Scale, (lo, hi): Interval, y: f64, colour: &str) -> String {
    let head = |x: f64, dir: f64| {
        format!(
            r#"<polygon points="{:.1},{y} {:.1},{} {:.1},{}" fill="{colour}"/>"#,
            x + 8.0 * dir,
            x,
            y - 6.0,
            x,
            y + 6.0
        )
    };
    let mut out = String::new();
    if lo.is_none() {
        out.push_str(&head(s.x0 + 8.0, -1.0));
    }
    if hi.is_none() {
        out.push_str(&head(s.x0 + s.w - 8.0, 1.0));
    }
    out
}

/// A linear axis over `[lo, hi]` drawn from `x0` over `w` pixels.
struct Scale {
    lo: f64,
    hi: f64,
    x0: f64,
    w: f64,
}

impl Scale {
    /// The finite `values` with `pad` of their span on each side (a span of one value:
    /// a percent of it, so that a parameter that did not move still has an axis).
    fn over(values: &[f64], (x0, w): (f64, f64), pad: f64) -> Scale {
        let finite = values.iter().copied().filter(|v| v.is_finite());
        let (mut lo, mut hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        let span = hi - lo;
        let d = if span > 1e-12 * lo.abs().max(hi.abs()) {
            span * pad
        } else {
            (0.01 * lo.abs()).max(1e-9)
        };
        Scale {
            lo: lo - d,
            hi: hi + d,
            x0,
            w,
        }
    }

    fn x(&self, v: f64) -> f64 {
        self.x0 + (v - self.lo) / (self.hi - self.lo) * self.w
    }

    fn contains(&self, v: f64) -> bool {
        (self.lo..=self.hi).contains(&v)
    }

    /// An interval's ends in pixels, an open end at the strip's edge.
    fn ends(&self, (lo, hi): Interval) -> (f64, f64) {
        (
            lo.map_or(self.x0, |v| self.x(v)),
            hi.map_or(self.x0 + self.w, |v| self.x(v)),
        )
    }

    /// About four round ticks (1, 2 or 5 times a power of ten apart).
    fn ticks(&self) -> Vec<f64> {
        let raw = (self.hi - self.lo) / 4.0;
        let magnitude = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|m| m * magnitude)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * magnitude);
        let first = (self.lo / step).ceil() as i64;
        let last = (self.hi / step).floor() as i64;
        (first..=last).map(|k| k as f64 * step).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> Row {
        Row {
            name: "c_lift<front>".into(),
            unit: None,
            start: 1.653,
            answer: 0.8158,
            change_percent: -50.6,
            interval: Some((Some(0.8101), Some(0.8215))),
            with_model: Some((Some(0.7943), None)),
            truth: Some(0.827),
        }
    }

    /// The picture names each parameter (escaped), carries its interval's numbers and
    /// the truth, and draws an open end as an arrow.
    #[test]
    fn the_forest_plot_shows_the_answer_its_intervals_and_the_truth() {
        let svg = svg(&[row()]);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        assert!(svg.contains("c_lift&lt;front&gt;"), "{svg}");
        assert!(!svg.contains("c_lift<front>"));
        assert!(svg.contains("answer 0.8158 (start 1.6530)"), "{svg}");
        assert!(svg.contains("95 % interval [0.8101, 0.8215]"), "{svg}");
        assert!(
            svg.contains("with the model&#39;s share [0.7943, open]"),
            "{svg}"
        );
        assert!(svg.contains("truth 0.8270"), "{svg}");
        assert!(
            svg.contains("truth of the lap"),
            "the legend names the truth"
        );
        // Three arrows: none for the scatter interval, one for the open end of the
        // model's (on both strips).
        assert_eq!(svg.matches(&format!("fill=\"{MODEL}\"/>")).count(), 2);
        // No truth, no model's share: neither is in the key.
        let plain = Row {
            truth: None,
            with_model: None,
            interval: None,
            ..row()
        };
        let svg = super::svg(&[plain]);
        assert!(!svg.contains("truth") && !svg.contains("model&#39;s share"));
        assert!(svg.contains("no interval"));
    }

    #[test]
    fn ticks_are_round_and_within_the_axis() {
        let s = Scale::over(&[0.8101, 0.8215], (0.0, 100.0), 0.0);
        let t = s.ticks();
        assert!((2..=6).contains(&t.len()), "{t:?}");
        assert!(t.iter().all(|&v| s.contains(v)));
        assert_eq!(tb_plot::tick_label(t[0]), "0.815");
        // One value: still an axis.
        let s = Scale::over(&[2.0, 2.0], (0.0, 100.0), 0.1);
        assert!(s.hi > s.lo && !s.ticks().is_empty());
    }
}
