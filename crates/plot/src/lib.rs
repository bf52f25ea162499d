//! Line plots for twinbench reports, written as SVG and PNG with plotters.
//!
//! The PNG backend needs a font to draw text; DejaVu Sans is bundled (its licence is in
//! `fonts/`) so that plots look the same on every machine, with no system font lookup.

use plotters::prelude::*;
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

/// One named line.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// A 2-D line plot with a legend.
#[derive(Clone, Debug)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub log_x: bool,
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
            size: (1200, 600),
        }
    }

    pub fn series(mut self, name: impl Into<String>, points: &[(f64, f64)]) -> Self {
        self.series.push(Series {
            name: name.into(),
            points: points.to_vec(),
        });
        self
    }

    pub fn log_x(mut self, on: bool) -> Self {
        self.log_x = on;
        self
    }

    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.size = (width, height);
        self
    }

    pub fn save_svg(&self, path: &Path) -> Result<(), PlotError> {
        register_font();
        let root = SVGBackend::new(path, self.size).into_drawing_area();
        self.draw(root, path)
    }

    pub fn save_png(&self, path: &Path) -> Result<(), PlotError> {
        register_font();
        let root = BitMapBackend::new(path, self.size).into_drawing_area();
        self.draw(root, path)
    }

    /// Both files, `<stem>.svg` and `<stem>.png`.
    pub fn save_both(&self, stem: &Path) -> Result<(), PlotError> {
        self.save_svg(&stem.with_extension("svg"))?;
        self.save_png(&stem.with_extension("png"))
    }

    fn bounds(&self) -> Option<((f64, f64), (f64, f64))> {
        let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
        let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(x, y) in &s.points {
                if x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0) {
                    xs = (xs.0.min(x), xs.1.max(x));
                    ys = (ys.0.min(y), ys.1.max(y));
                }
            }
        }
        if !xs.0.is_finite() {
            return None;
        }
        let pad = |(a, b): (f64, f64)| {
            if a == b {
                (a - 1.0, b + 1.0)
            } else {
                let d = (b - a) * 0.03;
                (a - d, b + d)
            }
        };
        let xr = if self.log_x { xs } else { pad(xs) };
        Some((
            if xr.0 == xr.1 {
                (xr.0 * 0.5, xr.1 * 2.0)
            } else {
                xr
            },
            pad(ys),
        ))
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
        path: &Path,
    ) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        let err = |e: &dyn std::fmt::Display| PlotError::Draw {
            title: self.title.clone(),
            path: path.display().to_string(),
            message: e.to_string(),
        };
        let ((x0, x1), (y0, y1)) = self
            .bounds()
            .ok_or_else(|| PlotError::Empty(self.title.clone()))?;
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut builder = ChartBuilder::on(&root);
        builder
            .caption(&self.title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70);
        macro_rules! finish {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .x_desc(self.x_label.as_str())
                    .y_desc(self.y_label.as_str())
                    .label_style(("sans-serif", 14))
                    .draw()
                    .map_err(|e| err(&e))?;
                for (i, s) in self.series.iter().enumerate() {
                    let color = COLORS[i % COLORS.len()];
                    let pts = s.points.iter().copied().filter(|&(x, y)| {
                        x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0)
                    });
                    chart
                        .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                        .map_err(|e| err(&e))?
                        .label(s.name.as_str())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        });
                }
                if self.series.len() > 1 || !self.series.iter().all(|s| s.name.is_empty()) {
                    chart
                        .configure_series_labels()
                        .background_style(WHITE.mix(0.85))
                        .border_style(BLACK)
                        .label_font(("sans-serif", 14))
                        .draw()
                        .map_err(|e| err(&e))?;
                }
            }};
        }
        if self.log_x {
            finish!(builder
                .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                .map_err(|e| err(&e))?);
        } else {
            finish!(builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(&e))?);
        }
        root.present().map_err(|e| err(&e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let png = std::fs::read(dir.join("sine.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let logp = LinePlot::new("bode", "f [Hz]", "|H| [dB]")
            .log_x(true)
            .series("H", &[(1.0, 0.0), (10.0, -3.0), (100.0, -20.0)]);
        logp.save_png(&dir.join("bode.png")).unwrap();
        assert!(LinePlot::new("empty", "x", "y")
            .save_svg(&dir.join("e.svg"))
            .is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
