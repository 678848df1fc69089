//! Batch figures: Pr(safe) with its Clopper–Pearson interval per controller (one point each), or
//! along a `--sweep` (one line per controller), with the claimed 1 − ε as a dashed line.
//! Written as SVG (plotters' SVG backend) next to every `--out` JSON file: `run.json` → `run.svg`.
//!
//! The drawing takes plain data ([`SafetyFigure`]); [`from_results`] is the only part that
//! knows the batch result types.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use plotters::prelude::*;

use super::BatchResult;

/// One Pr(safe) estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyPoint {
    /// Controller kind.
    pub controller: String,
    /// The sweep value (`None` without a sweep).
    pub x: Option<f64>,
    /// k / n.
    pub rate: f64,
    /// Interval bounds.
    pub lower: f64,
    /// Interval bounds.
    pub upper: f64,
}

/// What one figure shows.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyFigure {
    /// Caption (world, trials).
    pub title: String,
    /// The sweep key (`None` without a sweep: controllers along x).
    pub x_label: Option<String>,
    /// Confidence of the intervals (e.g. 0.95).
    pub confidence: f64,
    /// The claimed 1 − ε, if any.
    pub claimed: Option<f64>,
    /// Points, any order.
    pub points: Vec<SafetyPoint>,
}

const WIDTH: u32 = 720;
const HEIGHT: u32 = 440;

fn colour(i: usize) -> RGBColor {
    const C: [(u8, u8, u8); 6] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (148, 103, 189),
        (23, 190, 207),
        (140, 86, 75),
    ];
    let (r, g, b) = C[i % C.len()];
    RGBColor(r, g, b)
}

impl SafetyFigure {
    /// Controllers in order of first appearance.
    fn controllers(&self) -> Vec<&str> {
        let mut v: Vec<&str> = Vec::new();
        for p in &self.points {
            if !v.contains(&p.controller.as_str()) {
                v.push(&p.controller);
            }
        }
        v
    }

    /// y range: from just below the lowest interval bound (or the claim) to 1.
    fn y_range(&self) -> std::ops::Range<f64> {
        let lo = self
            .points
            .iter()
            .map(|p| p.lower)
            .chain(self.claimed)
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::min);
        let pad = ((1.0 - lo) * 0.1).max(0.01);
        (lo - pad).max(0.0)..1.0 + pad.min(0.02)
    }

    /// x of point `p` of controller number `c` (controllers side by side at a sweep value).
    fn x_of(&self, p: &SafetyPoint, c: usize, n: usize, step: f64) -> f64 {
        let offset = (c as f64 - (n as f64 - 1.0) / 2.0) * step;
        p.x.unwrap_or(c as f64) + if p.x.is_some() { offset } else { 0.0 }
    }
}

/// The figure as an SVG document.
pub fn svg(fig: &SafetyFigure) -> anyhow::Result<String> {
    if fig.points.is_empty() {
        return Err(anyhow!("figure `{}`: no points to draw", fig.title));
    }
    if let Some(p) = fig.points.iter().find(|p| {
        ![p.rate, p.lower, p.upper].iter().all(|v| v.is_finite())
            || p.x.is_some_and(|x| !x.is_finite())
    }) {
        return Err(anyhow!(
            "figure `{}`: controller {} has a non-finite rate, bound or sweep value",
            fig.title,
            p.controller
        ));
    }
    let mut text = String::new();
    draw(fig, &mut text).map_err(|e| anyhow!("figure `{}`: {e}", fig.title))?;
    Ok(text)
}

/// Draws `fig` into `out` (kept short by delegating the series to [`draw_points`]).
fn draw(fig: &SafetyFigure, out: &mut String) -> Result<(), String> {
    let root = SVGBackend::with_string(out, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let ctrl = fig.controllers();
    let xs: Vec<f64> = fig.points.iter().filter_map(|p| p.x).collect();
    let (x0, x1) = match (
        xs.iter().copied().reduce(f64::min),
        xs.iter().copied().reduce(f64::max),
    ) {
        (Some(a), Some(b)) if b > a => (a - (b - a) * 0.08, b + (b - a) * 0.08),
        (Some(a), _) => (a - 1.0, a + 1.0),
        _ => (-0.5, ctrl.len() as f64 - 0.5),
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(&fig.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, fig.y_range())
        .map_err(|e| e.to_string())?;
    let names = ctrl.clone();
    let by_index = move |x: &f64| {
        let i = x.round();
        if (x - i).abs() < 1e-9 && i >= 0.0 {
            names
                .get(i as usize)
                .map_or(String::new(), |s| s.to_string())
        } else {
            String::new()
        }
    };
    let plain = |x: &f64| short(*x);
    let sweep = fig.x_label.is_some();
    let y_desc = format!(
        "Pr(safe), {:.0}% Clopper–Pearson interval",
        fig.confidence * 100.0
    );
    chart
        .configure_mesh()
        .x_desc(fig.x_label.clone().unwrap_or_else(|| "controller".into()))
        .y_desc(y_desc)
        .x_labels(if sweep { 10 } else { ctrl.len().max(2) * 2 + 1 })
        .x_label_formatter(if sweep { &plain } else { &by_index })
        .light_line_style(WHITE)
        .draw()
        .map_err(|e| e.to_string())?;
    if let Some(c) = fig.claimed {
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, c), (x1, c)],
                6,
                4,
                RED.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?
            .label(format!("claimed 1 − ε = {c}"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], RED));
    }
    draw_points(fig, &mut chart, &ctrl, (x1 - x0) * 0.012)?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerLeft)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())?;
    Ok(())
}

/// A tick label: at most 4 decimals, no trailing zeros (0.6000000000000001 → "0.6").
fn short(x: f64) -> String {
    let s = format!("{x:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn draw_points(
    fig: &SafetyFigure,
    chart: &mut Chart<'_, '_>,
    ctrl: &[&str],
    step: f64,
) -> Result<(), String> {
    for (c, name) in ctrl.iter().enumerate() {
        let col = colour(c);
        let mut pts: Vec<(f64, &SafetyPoint)> = fig
            .points
            .iter()
            .filter(|p| p.controller == *name)
            .map(|p| (fig.x_of(p, c, ctrl.len(), step), p))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(pts.iter().map(|(x, p)| {
                ErrorBar::new_vertical(*x, p.lower, p.rate, p.upper, col.stroke_width(2), 10)
            }))
            .map_err(|e| e.to_string())?
            .label(name.to_string())
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, col.filled()));
        if pts.len() > 1 {
            chart
                .draw_series(LineSeries::new(pts.iter().map(|(x, p)| (*x, p.rate)), col))
                .map_err(|e| e.to_string())?;
        }
        chart
            .draw_series(
                pts.iter()
                    .map(|(x, p)| Circle::new((*x, p.rate), 4, col.filled())),
            )
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The figure of a batch (one result) or a sweep (one result per value).
pub fn from_results(results: &[BatchResult]) -> SafetyFigure {
    let first = results.first();
    let key = first
        .and_then(|r| r.plan.overrides.first())
        .map(|o| o.key.clone());
    let sweep = results.len() > 1 || key.is_some();
    let points = results
        .iter()
        .flat_map(|r| {
            let x = r.plan.overrides.first().map(|o| o.value).filter(|_| sweep);
            r.summaries.iter().map(move |s| SafetyPoint {
                controller: s.controller.clone(),
                x,
                rate: s.safe_rate,
                lower: s.safe_ci.lower,
                upper: s.safe_ci.upper,
            })
        })
        .collect();
    SafetyFigure {
        title: first.map_or_else(String::new, |r| {
            format!(
                "{}: Pr(safe), {} trials per point",
                r.plan.world, r.plan.trials
            )
        }),
        x_label: key.filter(|_| sweep),
        confidence: first.map_or(0.95, |r| r.plan.confidence),
        claimed: first.and_then(|r| r.plan.claimed_safety()),
        points,
    }
}

/// `x.json` → `x.svg`; `None` for outputs that are not JSON.
fn svg_path(out: &Path) -> Option<PathBuf> {
    let json = out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    json.then(|| out.with_extension("svg"))
}

/// Writes the figure next to every JSON output; returns the files written.
pub fn write_next_to(outs: &[PathBuf], results: &[BatchResult]) -> anyhow::Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = outs.iter().filter_map(|p| svg_path(p)).collect();
    if paths.is_empty() {
        return Ok(paths);
    }
    let text = svg(&from_results(results))?;
    for p in &paths {
        std::fs::write(p, &text).with_context(|| format!("could not write `{}`", p.display()))?;
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(controller: &str, x: Option<f64>, rate: f64) -> SafetyPoint {
        SafetyPoint {
            controller: controller.into(),
            x,
            rate,
            lower: rate - 0.02,
            upper: (rate + 0.01).min(1.0),
        }
    }

    fn figure(points: Vec<SafetyPoint>, x_label: Option<&str>) -> SafetyFigure {
        SafetyFigure {
            title: "corridor_spoof: Pr(safe), 200 trials per point".into(),
            x_label: x_label.map(str::to_string),
            confidence: 0.95,
            claimed: Some(0.95),
            points,
        }
    }

    #[test]
    fn controllers_side_by_side_with_intervals_and_the_claim() {
        let f = figure(
            vec![
                point("ft-cbf-clf", None, 0.99),
                point("baseline", None, 0.6),
            ],
            None,
        );
        let s = svg(&f).expect("svg");
        assert!(s.starts_with("<svg"), "{}", &s[..40]);
        for needed in [
            "ft-cbf-clf",
            "baseline",
            "claimed 1 − ε = 0.95",
            "95% Clopper",
        ] {
            assert!(s.contains(needed), "missing {needed}");
        }
        // The y range reaches below the lowest bound (0.58) and stops near 1.
        let r = f.y_range();
        assert!(r.start < 0.58 && r.start > 0.5 && r.end <= 1.02, "{r:?}");
    }

    #[test]
    fn a_sweep_draws_one_line_per_controller_along_the_key() {
        let pts = [0.0, 0.5, 1.0]
            .iter()
            .flat_map(|&x| [point("a", Some(x), 1.0 - x / 4.0), point("b", Some(x), 0.9)])
            .collect();
        let f = figure(pts, Some("attacks[0].value"));
        let s = svg(&f).expect("svg");
        assert!(s.contains("attacks[0].value"));
        for colour in ["#1F77B4", "#FF7F0E"] {
            let lines: Vec<&str> = s
                .lines()
                .filter(|l| l.starts_with("<polyline") && l.contains(colour))
                .collect();
            assert_eq!(lines.len(), 1, "one line for controller {colour}");
            assert_eq!(lines[0].matches(',').count(), 3, "through 3 sweep values");
            let bars = s
                .lines()
                .filter(|l| l.starts_with("<line") && l.contains(colour))
                .count();
            assert_eq!(bars, 9, "an interval (3 strokes) at each of 3 values");
        }
        // Controllers at one sweep value are drawn side by side, not on top of each other.
        let xa = f.x_of(&f.points[0], 0, 2, 0.01);
        let xb = f.x_of(&f.points[1], 1, 2, 0.01);
        assert!((xa - xb).abs() > 0.005);
    }

    #[test]
    fn bad_data_is_an_error_naming_the_figure_not_a_panic() {
        assert!(svg(&figure(vec![], None)).is_err());
        let mut p = point("a", None, 0.5);
        p.upper = f64::NAN;
        let e = svg(&figure(vec![p], None)).expect_err("NaN");
        assert!(e.to_string().contains("controller a"), "{e}");
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(short(0.6000000000000001), "0.6");
        assert_eq!(short(2.0), "2");
        assert_eq!(short(-0.00001), "0");
        assert_eq!(short(0.125), "0.125");
    }

    #[test]
    fn the_figure_goes_next_to_json_outputs_only() {
        assert_eq!(
            svg_path(Path::new("r/run.json")),
            Some(PathBuf::from("r/run.svg"))
        );
        assert_eq!(
            svg_path(Path::new("r/run.JSON")),
            Some(PathBuf::from("r/run.svg"))
        );
        assert_eq!(svg_path(Path::new("r/run.csv")), None);
    }
}
