//! Line plots for twinbench reports, written as SVG and PNG with plotters.
//!
//! The PNG backend needs a font to draw text; DejaVu Sans is bundled (its licence is in
//! `fonts/`) so that plots look the same on every machine, with no system font lookup.

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;
use std::sync::Once;

#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("plot '{title}' to {path}: {message}")]
    Draw {
        title: String,
        path: String,
        message: String,
    },
    #[error("plot '{0}' has no finite data to draw")]
    Empty(String),
}

static FONT: &[u8] = include_bytes!("../fonts/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

fn register_font() {
    REGISTER.call_once(|| {
        // The bundled font is valid; a failure here would only mean text-less PNGs.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// How a line is drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Style {
    /// A colour of its own (the palette in order).
    #[default]
    Line,
    /// What the others are judged against (a measurement): black, drawn last so that it
    /// lies on top of the lines it is compared with.
    Reference,
    /// A line for context (a start point): light grey, drawn first.
    Faint,
}

/// One named line.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
}

/// A 2-D line plot with a legend above the data (never on it).
#[derive(Clone, Debug)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub log_x: bool,
    pub log_y: bool,
    /// The x axis counts something (generations): whole-number ticks only.
    pub integer_x: bool,
    pub size: (u32, u32),
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
const FAINT: RGBColor = RGBColor(170, 170, 170);

/// A tick label: as few digits as the number needs (`20000`, `0.35`, `2.5e-4`), never
/// `20000.0`.
pub fn tick_label(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let a = x.abs();
    if !(1e-3..1e7).contains(&a) {
        let s = format!("{x:.3e}");
        let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        return format!("{mantissa}e{exponent}");
    }
    // Six significant digits, then trailing zeros dropped: tick values carry rounding
    // noise (0.30000000000000004).
    let decimals = (5 - a.log10().floor() as i32).clamp(0, 9) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Ticks of a log axis over `[lo, hi]` (both > 0): 1, 2 and 5 times every power of ten.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut ticks = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi && ticks.len() < 64 {
        for m in [1.0, 2.0, 5.0] {
            let t = m * decade;
            if (lo..=hi).contains(&t) {
                ticks.push(t);
            }
        }
        decade *= 10.0;
    }
    ticks
}

/// A whole-number tick label; empty between whole numbers (a count has no 2.5).
fn integer_tick_label(x: f64) -> String {
    if (x - x.round()).abs() < 1e-9 {
        format!("{}", x.round() as i64)
    } else {
        String::new()
    }
}

impl LinePlot {
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        LinePlot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            log_x: false,
            log_y: false,
            integer_x: false,
            size: (1200, 600),
        }
    }

    pub fn series(self, name: impl Into<String>, points: &[(f64, f64)]) -> Self {
        self.styled(name, points, Style::Line)
    }

    /// The line the others are compared with (a measurement): black, on top.
    pub fn reference(self, name: impl Into<String>, points: &[(f64, f64)]) -> Self {
        self.styled(name, points, Style::Reference)
    }

    pub fn styled(mut self, name: impl Into<String>, points: &[(f64, f64)], style: Style) -> Self {
        self.series.push(Series {
            name: name.into(),
            points: points.to_vec(),
            style,
        });
        self
    }

    pub fn log_x(mut self, on: bool) -> Self {
        self.log_x = on;
        self
    }

    /// A logarithmic y axis (a cost that falls by decades); points at or below 0 are left out.
    pub fn log_y(mut self, on: bool) -> Self {
        self.log_y = on;
        self
    }

    /// Whole-number ticks on x (a count).
    pub fn integer_x(mut self, on: bool) -> Self {
        self.integer_x = on;
        self
    }

    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.size = (width, height);
        self
    }

    pub fn save_svg(&self, path: &Path) -> Result<(), PlotError> {
        register_font();
        let root = SVGBackend::new(path, self.size).into_drawing_area();
        self.draw(&root, path)?;
        root.present().map_err(|e| self.error(path, &e))
    }

    pub fn save_png(&self, path: &Path) -> Result<(), PlotError> {
        register_font();
        let root = BitMapBackend::new(path, self.size).into_drawing_area();
        self.draw(&root, path)?;
        root.present().map_err(|e| self.error(path, &e))
    }

    /// Both files, `<stem>.svg` and `<stem>.png`.
    pub fn save_both(&self, stem: &Path) -> Result<(), PlotError> {
        self.save_svg(&stem.with_extension("svg"))?;
        self.save_png(&stem.with_extension("png"))
    }

    /// The SVG as text, for a page that carries its pictures inline (the HTML report)
    /// rather than as files beside it.
    pub fn svg_string(&self) -> Result<String, PlotError> {
        register_font();
        let place = Path::new("(inline SVG)");
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, self.size).into_drawing_area();
            self.draw(&root, place)?;
            root.present().map_err(|e| self.error(place, &e))?;
        }
        Ok(svg)
    }

    fn error(&self, path: &Path, e: &dyn std::fmt::Display) -> PlotError {
        PlotError::Draw {
            title: self.title.clone(),
            path: path.display().to_string(),
            message: e.to_string(),
        }
    }

    fn drawable(&self, x: f64, y: f64) -> bool {
        x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0) && (!self.log_y || y > 0.0)
    }

    fn bounds(&self) -> Option<((f64, f64), (f64, f64))> {
        let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
        let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(x, y) in &s.points {
                if self.drawable(x, y) {
                    xs = (xs.0.min(x), xs.1.max(x));
                    ys = (ys.0.min(y), ys.1.max(y));
                }
            }
        }
        if !xs.0.is_finite() {
            return None;
        }
        let pad = |(a, b): (f64, f64), log: bool| {
            if log {
                if a == b {
                    (a * 0.5, b * 2.0)
                } else {
                    (a / 1.2, b * 1.2)
                }
            } else if a == b {
                (a - 1.0, b + 1.0)
            } else {
                let d = (b - a) * 0.03;
                (a - d, b + d)
            }
        };
        let xr = if self.log_x && xs.0 != xs.1 {
            xs
        } else {
            pad(xs, self.log_x)
        };
        Some((xr, pad(ys, self.log_y)))
    }

    /// The plot into `area` (a whole picture, or one panel of a [`Figure`]).
    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, plotters::coord::Shift>,
        path: &Path,
    ) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        let err = |e: &dyn std::fmt::Display| self.error(path, e);
        let ((x0, x1), (y0, y1)) = self
            .bounds()
            .ok_or_else(|| PlotError::Empty(self.title.clone()))?;
        area.fill(&WHITE).map_err(|e| err(&e))?;
        let (_, height) = area.dim_in_pixel();
        let title = area
            .titled(&self.title, ("sans-serif", 20))
            .map_err(|e| err(&e))?;
        // The legend gets a strip of its own above the data.
        let labelled = self.series.iter().any(|s| !s.name.is_empty());
        let legend_height = if labelled { 26 } else { 0 };
        let (legend, plot) = title.split_vertically(legend_height);
        if labelled {
            self.draw_legend(&legend).map_err(|e| err(&e))?;
        }
        let mut builder = ChartBuilder::on(&plot);
        builder
            .margin_left(12)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(45)
            .y_label_area_size(80);
        let y_ticks = ((height / 60) as usize).clamp(3, 10);
        let x_format = |x: &f64| match self.integer_x {
            true => integer_tick_label(*x),
            false => tick_label(*x),
        };
        let y_format = |y: &f64| tick_label(*y);
        macro_rules! finish {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .x_desc(self.x_label.as_str())
                    .y_desc(self.y_label.as_str())
                    .x_label_formatter(&x_format)
                    .y_label_formatter(&y_format)
                    .y_labels(y_ticks)
                    .label_style(("sans-serif", 14))
                    .draw()
                    .map_err(|e| err(&e))?;
                // Faint lines first, references last: what is compared with lies on top.
                for pass in [Style::Faint, Style::Line, Style::Reference] {
                    for (i, s) in self.series.iter().enumerate() {
                        if s.style != pass {
                            continue;
                        }
                        let pts = s
                            .points
                            .iter()
                            .copied()
                            .filter(|&(x, y)| self.drawable(x, y));
                        chart
                            .draw_series(LineSeries::new(pts, self.stroke(i)))
                            .map_err(|e| err(&e))?;
                    }
                }
            }};
        }
        match (self.log_x, self.log_y) {
            (false, false) => finish!(builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(&e))?),
            (true, false) => finish!(builder
                .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                .map_err(|e| err(&e))?),
            // Log y ticks at 1, 2 and 5 of every decade (plotters' own skip the lower decades).
            (false, true) => finish!(builder
                .build_cartesian_2d(
                    x0..x1,
                    (y0..y1).log_scale().with_key_points(log_ticks(y0, y1))
                )
                .map_err(|e| err(&e))?),
            (true, true) => finish!(builder
                .build_cartesian_2d(
                    (x0..x1).log_scale(),
                    (y0..y1).log_scale().with_key_points(log_ticks(y0, y1))
                )
                .map_err(|e| err(&e))?),
        }
        Ok(())
    }

    fn stroke(&self, i: usize) -> ShapeStyle {
        match self.series[i].style {
            Style::Reference => BLACK.stroke_width(1),
            Style::Faint => FAINT.stroke_width(2),
            Style::Line => {
                // The palette counts only the coloured lines.
                let k = self.series[..i]
                    .iter()
                    .filter(|s| s.style == Style::Line)
                    .count();
                COLORS[k % COLORS.len()].stroke_width(2)
            }
        }
    }

    /// The series' names in a row, each after a short line in its style.
    fn draw_legend<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let font = ("sans-serif", 14).into_font();
        let mut x = 90i32;
        let y = 13i32;
        for (i, s) in self.series.iter().enumerate() {
            if s.name.is_empty() {
                continue;
            }
            area.draw(&PathElement::new(vec![(x, y), (x + 24, y)], self.stroke(i)))?;
            let text_style = TextStyle::from(font.clone()).pos(Pos::new(HPos::Left, VPos::Center));
            area.draw(&Text::new(s.name.clone(), (x + 30, y), text_style.clone()))?;
            let (w, _) = area.estimate_text_size(&s.name, &text_style)?;
            x += 30 + w as i32 + 28;
        }
        Ok(())
    }
}

/// Plots stacked over each other in one picture (a quantity and its difference), sharing
/// nothing but the picture.
#[derive(Clone, Debug)]
pub struct Figure {
    pub panels: Vec<(LinePlot, u32)>,
    pub width: u32,
}

impl Figure {
    pub fn new(width: u32) -> Self {
        Figure {
            panels: Vec::new(),
            width,
        }
    }

    /// A panel `height` pixels high below the others.
    pub fn panel(mut self, plot: LinePlot, height: u32) -> Self {
        self.panels.push((plot, height));
        self
    }

    fn height(&self) -> u32 {
        self.panels.iter().map(|p| p.1).sum()
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
        path: &Path,
    ) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        let mut rest = root.clone();
        for (plot, h) in &self.panels {
            let (top, bottom) = rest.split_vertically(*h);
            plot.draw(&top, path)?;
            rest = bottom;
        }
        root.present().map_err(|e| PlotError::Draw {
            title: self
                .panels
                .first()
                .map(|p| p.0.title.clone())
                .unwrap_or_default(),
            path: path.display().to_string(),
            message: e.to_string(),
        })
    }

    /// `<stem>.svg` and `<stem>.png`.
    pub fn save_both(&self, stem: &Path) -> Result<(), PlotError> {
        register_font();
        let size = (self.width, self.height());
        let svg = stem.with_extension("svg");
        self.draw(SVGBackend::new(&svg, size).into_drawing_area(), &svg)?;
        let png = stem.with_extension("png");
        self.draw(BitMapBackend::new(&png, size).into_drawing_area(), &png)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_have_the_digits_they_need() {
        assert_eq!(tick_label(20000.0), "20000");
        assert_eq!(tick_label(0.35), "0.35");
        assert_eq!(tick_label(0.1 + 0.2), "0.3");
        assert_eq!(tick_label(-2.5), "-2.5");
        assert_eq!(tick_label(2.5e-4), "2.5e-4");
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(integer_tick_label(4.0), "4");
        assert_eq!(integer_tick_label(2.5), "");
        let t = log_ticks(0.008, 0.4);
        assert_eq!(t.len(), 5);
        assert!(
            (t[0] - 0.01).abs() < 1e-15 && (t[4] - 0.2).abs() < 1e-15,
            "{t:?}"
        );
    }

    #[test]
    fn writes_svg_and_png() {
        let dir = std::env::temp_dir().join(format!("tb-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pts: Vec<(f64, f64)> = (0..100)
            .map(|i| (i as f64, (i as f64 / 10.0).sin()))
            .collect();
        let p = LinePlot::new("sine", "x [1]", "y [1]").series("sin", &pts);
        p.save_both(&dir.join("sine")).unwrap();
        let svg = std::fs::read_to_string(dir.join("sine.svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("sine"));
        // The same picture as text (the HTML report's inline SVG).
        assert_eq!(p.svg_string().unwrap(), svg);
        let png = std::fs::read(dir.join("sine.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let logp = LinePlot::new("bode", "f [Hz]", "|H| [dB]")
            .log_x(true)
            .series("H", &[(1.0, 0.0), (10.0, -3.0), (100.0, -20.0)]);
        logp.save_png(&dir.join("bode.png")).unwrap();
        assert!(LinePlot::new("empty", "x", "y")
            .save_svg(&dir.join("e.svg"))
            .is_err());
        let cost = LinePlot::new("cost", "generation", "cost")
            .log_y(true)
            .integer_x(true)
            .series("a", &[(1.0, 0.3), (2.0, 0.01), (3.0, 0.001)])
            .reference("measured", &[(1.0, 0.2), (3.0, 0.02)]);
        Figure::new(800)
            .panel(cost.clone(), 300)
            .panel(cost, 200)
            .save_both(&dir.join("figure"))
            .unwrap();
        let svg = std::fs::read_to_string(dir.join("figure.svg")).unwrap();
        assert!(
            svg.contains("height=\"500\""),
            "two panels, 300 + 200 px high"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
