//! The report's figures, drawn with `plotters` into memory (PNG and SVG) and written atomically:
//! Figure 7 (training curves), Figure 8 (periodic evaluations) and evaluation trajectories.
//!
//! Text uses the DejaVu Sans font compiled into the library (`assets/fonts/`), registered with
//! plotters before drawing, so no system font is needed.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Once;

use super::runs::RunData;
use super::table::{algo_title, reward_title, Group, GroupSummary, ALGO_ORDER};
use super::trajectory::Rollouts;
use crate::io::csv::EvalPoint;
use crate::report::method::Method;
use crate::report::metrics::trailing_moving_average;
use crate::reward::RewardFunction;
use crate::train::eval::EvalSummary;
use crate::{Error, Result};

/// DejaVu Sans (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu.txt`).
static FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

static REGISTER: Once = Once::new();

/// Register the embedded font under `sans-serif` (once per process).
pub fn register_font() {
    REGISTER.call_once(|| {
        // The font is compiled in and known to parse (tested); a failure would only leave text out.
        let _ = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

type DrawResult = std::result::Result<(), String>;

fn e<E: std::fmt::Display>(err: E) -> String {
    err.to_string()
}

/// A figure that can be drawn on any plotters backend.
pub trait Figure {
    /// Pixel size of the PNG (and SVG user units).
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult;
}

fn encode_png(rgb: &[u8], (w, h): (u32, u32)) -> std::result::Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header()?;
        writer.write_image_data(rgb)?;
        writer.finish()?;
    }
    Ok(out)
}

/// Draw `fig` and write `<stem>.png` and `<stem>.svg`; returns both paths.
pub fn save(fig: &impl Figure, stem: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    let size = fig.size();
    let fail = |path: &Path, msg: String| Error::io(path, std::io::Error::other(msg));
    let png_path = stem.with_extension("png");
    let mut rgb = vec![255u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE).map_err(|x| fail(&png_path, e(x)))?;
        fig.draw(&root).map_err(|x| fail(&png_path, x))?;
        root.present().map_err(|x| fail(&png_path, e(x)))?;
    }
    let bytes = encode_png(&rgb, size).map_err(|x| fail(&png_path, e(x)))?;
    crate::io::write_atomic(&png_path, &bytes)?;
    let svg_path = stem.with_extension("svg");
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|x| fail(&svg_path, e(x)))?;
        fig.draw(&root).map_err(|x| fail(&svg_path, x))?;
        root.present().map_err(|x| fail(&svg_path, e(x)))?;
    }
    crate::io::write_atomic(&svg_path, svg.as_bytes())?;
    Ok(vec![png_path, svg_path])
}

/// The colour of a reward function in every figure.
pub fn reward_color(r: RewardFunction) -> RGBColor {
    match r {
        RewardFunction::Basic => RGBColor(127, 127, 127),
        RewardFunction::Posture => RGBColor(31, 119, 180),
        RewardFunction::Stride => RGBColor(255, 127, 14),
        RewardFunction::Har => RGBColor(44, 160, 44),
        RewardFunction::Sar => RGBColor(214, 39, 40),
    }
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A curve over seeds: mean and min-max band at each x.
#[derive(Clone, Debug, Default)]
pub struct Band {
    pub x: Vec<f64>,
    pub mean: Vec<f64>,
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

impl Band {
    /// Combine per-seed curves `(x, y)` point by point on x (x values matched exactly; a point
    /// missing in some seeds uses the others). A NaN `y` marks a point without a value (e.g. the
    /// mean steps of an evaluation with no success): where no seed has a value the band has a
    /// gap (NaN), and lines are not drawn across it.
    pub fn from_curves(curves: &[Vec<(f64, f64)>]) -> Band {
        let mut pts: std::collections::BTreeMap<i64, Vec<f64>> = std::collections::BTreeMap::new();
        for c in curves {
            for &(x, y) in c {
                let ys = pts.entry((x * 1000.0).round() as i64).or_default();
                if y.is_finite() {
                    ys.push(y);
                }
            }
        }
        let mut b = Band::default();
        for (x, ys) in pts {
            b.x.push(x as f64 / 1000.0);
            if ys.is_empty() {
                b.mean.push(f64::NAN);
                b.lo.push(f64::NAN);
                b.hi.push(f64::NAN);
                continue;
            }
            b.mean.push(ys.iter().sum::<f64>() / ys.len() as f64);
            b.lo.push(ys.iter().copied().fold(f64::INFINITY, f64::min));
            b.hi.push(ys.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        }
        b
    }

    /// Runs of consecutive points with a value: `(x, mean, lo, hi)` per point.
    fn segments(&self) -> Vec<Vec<(f64, f64, f64, f64)>> {
        let mut out: Vec<Vec<(f64, f64, f64, f64)>> = vec![Vec::new()];
        for i in 0..self.x.len() {
            if self.mean[i].is_finite() {
                out.last_mut().expect("one segment").push((self.x[i], self.mean[i], self.lo[i], self.hi[i]));
            } else if !out.last().expect("one segment").is_empty() {
                out.push(Vec::new());
            }
        }
        out.retain(|seg| !seg.is_empty());
        out
    }

    fn range(&self) -> Option<(f64, f64)> {
        let lo = self.lo.iter().copied().filter(|v| v.is_finite()).fold(f64::INFINITY, f64::min);
        let hi = self.hi.iter().copied().filter(|v| v.is_finite()).fold(f64::NEG_INFINITY, f64::max);
        (lo.is_finite() && hi.is_finite()).then_some((lo, hi))
    }
}

/// One panel: a quantity against the episode (or another x) for every reward function of one
/// algorithm.
#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Fixed y range, else from the data (the same for every panel of a figure row).
    pub y_range: Option<(f64, f64)>,
    pub series: Vec<(RewardFunction, String, Band)>,
    /// Draw markers (sparse evaluation points).
    pub markers: bool,
    /// Vertical dashed lines at these x (E_start), in the reward function's colour, named in
    /// the legend.
    pub marks: Vec<(RewardFunction, f64)>,
    /// Horizontal dotted reference lines (label, y): the scripted controller.
    pub refs: Vec<(String, f64)>,
}

/// Width of the legend beside each panel, pixels.
const LEGEND_W: u32 = 230;

/// A grid of panels (rows of quantities, columns of algorithms) under a title.
#[derive(Clone, Debug)]
pub struct CurveFigure {
    pub title: String,
    pub subtitle: String,
    pub rows: usize,
    pub cols: usize,
    pub panels: Vec<Panel>,
}

impl Figure for CurveFigure {
    fn size(&self) -> (u32, u32) {
        (60 + (640 + LEGEND_W) * self.cols.max(1) as u32, 110 + 420 * self.rows.max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        let (head, body) = root.split_vertically(100);
        head.draw(&Text::new(self.title.clone(), (30, 16), (FAMILY, 30).into_font().color(&BLACK)))
            .map_err(e)?;
        for (k, line) in self.subtitle.lines().enumerate() {
            let style = (FAMILY, 16).into_font().color(&RGBColor(80, 80, 80));
            head.draw(&Text::new(line.to_string(), (30, 54 + 22 * k as i32), style)).map_err(e)?;
        }
        let body = body.margin(0, 10, 10, 20);
        if self.panels.is_empty() {
            body.draw(&Text::new("no runs to plot", (40, 40), (FAMILY, 24).into_font())).map_err(e)?;
            return Ok(());
        }
        let areas = body.split_evenly((self.rows.max(1), self.cols.max(1)));
        for (k, (panel, area)) in self.panels.iter().zip(areas.iter()).enumerate() {
            let row = k / self.cols.max(1);
            let range = panel.y_range.unwrap_or_else(|| self.row_range(row));
            draw_panel(panel, range, area)?;
        }
        Ok(())
    }
}

impl CurveFigure {
    /// The y range shared by the panels of figure row `row` (the union of their data, padded),
    /// so that the algorithms' panels of one quantity compare at a glance.
    fn row_range(&self, row: usize) -> (f64, f64) {
        let cols = self.cols.max(1);
        let (lo, hi) = self
            .panels
            .iter()
            .skip(row * cols)
            .take(cols)
            .flat_map(|p| {
                p.series.iter().filter_map(|(_, _, b)| b.range()).chain(p.refs.iter().map(|r| (r.1, r.1)))
            })
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (c, d)| (a.min(c), b.max(d)));
        if lo.is_finite() {
            let pad = ((hi - lo) * 0.05).max(0.5);
            (lo - pad, hi + pad)
        } else {
            (0.0, 1.0)
        }
    }
}

fn draw_panel<DB: DrawingBackend>(
    p: &Panel,
    (ylo, yhi): (f64, f64),
    area: &DrawingArea<DB, Shift>,
) -> DrawResult {
    let (plot_area, legend_area) = area.split_horizontally(area.dim_in_pixel().0.saturating_sub(LEGEND_W));
    let xmax = p.series.iter().flat_map(|(_, _, b)| b.x.iter().copied()).fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&p.title, (FAMILY, 20))
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..xmax * 1.01, ylo..yhi)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(p.x_label.as_str())
        .y_desc(p.y_label.as_str())
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 17))
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(220, 220, 220))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|x| tick(*x, xmax * 1.01))
        .y_label_formatter(&|y| tick(*y, yhi - ylo))
        .draw()
        .map_err(e)?;
    if p.series.is_empty() {
        let text = Text::new("no data", (xmax * 0.4, (ylo + yhi) / 2.0), (FAMILY, 20).into_font());
        chart.draw_series(std::iter::once(text)).map_err(e)?;
    }
    for &(reward, x) in &p.marks {
        let style = reward_color(reward).mix(0.8).stroke_width(1);
        let line = plotters::element::DashedPathElement::new(vec![(x, ylo), (x, yhi)], 6, 5, style);
        chart.draw_series(std::iter::once(line)).map_err(e)?;
    }
    for (_, y) in &p.refs {
        let line = plotters::element::DashedPathElement::new(
            vec![(0.0, *y), (xmax * 1.01, *y)],
            2,
            4,
            BLACK.stroke_width(2),
        );
        chart.draw_series(std::iter::once(line)).map_err(e)?;
    }
    for (reward, _, band) in &p.series {
        let color = reward_color(*reward);
        for seg in band.segments() {
            if seg.len() > 1 && seg.iter().any(|q| q.2 != q.3) {
                let mut poly: Vec<(f64, f64)> = seg.iter().map(|q| (q.0, q.3)).collect();
                poly.extend(seg.iter().rev().map(|q| (q.0, q.2)));
                chart
                    .draw_series(std::iter::once(Polygon::new(poly, color.mix(0.15).filled())))
                    .map_err(e)?;
            }
            let line: Vec<(f64, f64)> = seg.iter().map(|q| (q.0, q.1)).collect();
            chart
                .draw_series(std::iter::once(PathElement::new(line.clone(), color.stroke_width(2))))
                .map_err(e)?;
            if p.markers {
                chart
                    .draw_series(line.iter().map(|&(x, y)| Circle::new((x, y), 3, color.filled())))
                    .map_err(e)?;
            }
        }
    }
    draw_legend(p, &legend_area)
}

/// The legend beside a panel, outside the data: one line per series, then the dashed E_start
/// marks and the reference lines, each named.
fn draw_legend<DB: DrawingBackend>(p: &Panel, area: &DrawingArea<DB, Shift>) -> DrawResult {
    let font = TextStyle::from((FAMILY, 14).into_font());
    let mut y = 50;
    let mut entry =
        |sample: &dyn Fn(&DrawingArea<DB, Shift>, i32) -> DrawResult, label: String| -> DrawResult {
            sample(area, y)?;
            area.draw(&Text::new(label, (36, y - 8), font.clone())).map_err(e)?;
            y += 22;
            Ok(())
        };
    for (reward, label, _) in &p.series {
        let color = reward_color(*reward);
        entry(
            &|a, y| a.draw(&PathElement::new(vec![(4, y), (28, y)], color.stroke_width(3))).map_err(e),
            label.clone(),
        )?;
    }
    for &(reward, x) in &p.marks {
        let style = reward_color(reward).stroke_width(1);
        let label = format!("E_start {}: {x:.0}", reward_title(reward));
        entry(
            &|a, y| {
                a.draw(&plotters::element::DashedPathElement::new(vec![(4, y), (28, y)], 5, 3, style))
                    .map_err(e)
            },
            label,
        )?;
    }
    for (label, _) in &p.refs {
        entry(
            &|a, y| {
                a.draw(&plotters::element::DashedPathElement::new(
                    vec![(4, y), (28, y)],
                    2,
                    3,
                    BLACK.stroke_width(2),
                ))
                .map_err(e)
            },
            label.clone(),
        )?;
    }
    Ok(())
}

/// A tick label with as many decimals as the axis span needs, and no "-0".
fn tick(v: f64, span: f64) -> String {
    let decimals = if span >= 10.0 {
        0
    } else if span >= 1.0 {
        1
    } else {
        2
    };
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Algorithms that have a primary group, in Table 1's order.
fn algos(groups: &[Group]) -> Vec<Method> {
    ALGO_ORDER
        .into_iter()
        .filter(|a| groups.iter().any(|g| g.primary && g.algo == *a && !g.runs.is_empty()))
        .collect()
}

fn series_label(g: &Group) -> String {
    format!("{} ({} seed{})", reward_title(g.reward), g.runs.len(), if g.runs.len() == 1 { "" } else { "s" })
}

/// Points kept of a training curve in Figure 7: about one per two pixels of a panel's plotting
/// area (its 640 px less the axes), which a moving average over 100 episodes does not need more
/// of; 1200 before made each Figure 7 SVG about four times larger for no visible difference.
const CURVE_POINTS: usize = 320;

/// Keep about `max_points` evenly spaced points (always the last one).
fn thin(curve: Vec<(f64, f64)>, max_points: usize) -> Vec<(f64, f64)> {
    let step = curve.len().div_ceil(max_points.max(1)).max(1);
    let last = curve.last().copied();
    let mut out: Vec<(f64, f64)> = curve.into_iter().step_by(step).collect();
    if let Some(l) = last {
        if out.last() != Some(&l) {
            out.push(l);
        }
    }
    out
}

/// One series per primary reward function of algorithm `a`: `curve` of each run, the mean and
/// the min-max band over the runs.
fn algo_series(
    groups: &[Group],
    a: Method,
    curve: impl Fn(&RunData) -> Vec<(f64, f64)>,
) -> Vec<(RewardFunction, String, Band)> {
    groups
        .iter()
        .filter(|g| g.primary && g.algo == a && !g.runs.is_empty())
        .map(|g| {
            let curves: Vec<Vec<(f64, f64)>> = g.runs.iter().map(&curve).collect();
            (g.reward, series_label(g), Band::from_curves(&curves))
        })
        .collect()
}

/// Figure 7: training episode reward and steps against the episode, moving average over
/// `window` episodes, mean over seeds with the min-max band; one column per algorithm, one
/// colour per reward function (primary configurations only), a dashed line at the mean E_start
/// (from `summaries`, the groups' indicators).
pub fn figure7(groups: &[Group], summaries: &[GroupSummary], window: usize, study: &str) -> CurveFigure {
    let algos = algos(groups);
    let mut panels = Vec::new();
    let max_steps =
        groups.iter().flat_map(|g| g.runs.iter()).map(|r| r.config.task.max_steps).max().unwrap_or(50);
    for (row, (what, unit)) in
        [("episode reward", "episode reward R_episode (eq. 16)"), ("steps", "steps per episode")]
            .into_iter()
            .enumerate()
    {
        for &a in &algos {
            let series = algo_series(groups, a, |r| {
                // Non-finite rewards (reported in the table) would poison the running sum.
                let (xs, ys): (Vec<f64>, Vec<f64>) = r
                    .episodes
                    .iter()
                    .map(|e| (e.episode as f64, if row == 0 { e.reward } else { f64::from(e.steps) }))
                    .filter(|(_, y)| y.is_finite())
                    .unzip();
                let sm = trailing_moving_average(&ys, window);
                thin(xs.into_iter().zip(sm).collect(), CURVE_POINTS)
            });
            let marks = summaries
                .iter()
                .filter(|s| s.primary && s.algo == a)
                .filter_map(|s| s.e_start.map(|m| (s.reward, m.mean)))
                .collect();
            panels.push(Panel {
                title: format!("{} — {what}", algo_title(a)),
                x_label: "episode".into(),
                y_label: unit.to_string(),
                y_range: (row == 1).then_some((0.0, f64::from(max_steps) + 2.0)),
                series,
                markers: false,
                marks,
                refs: Vec::new(),
            });
        }
    }
    CurveFigure {
        title: "Figure 7: training".into(),
        subtitle: format!(
            "{study}\nMoving average over {window} episodes. Line: mean over seeds; band: min-max over seeds; dashed: mean E_start of the converged seeds. Steps: {max_steps} = episode limit (target not reached)."
        ),
        rows: 2,
        cols: algos.len(),
        panels,
    }
}

/// Figure 8: the periodic evaluations of `eval.csv` (deterministic policy) against the training
/// episode: success rate, mean episode reward and mean steps of the successful trials; mean over
/// seeds with the min-max band.
pub fn figure8(groups: &[Group], study: &str, reference: Option<&EvalSummary>) -> CurveFigure {
    let algos = algos(groups);
    // Runs on a budget of environment steps are drawn against the steps.
    let on_steps = groups.iter().flat_map(|g| g.runs.iter()).any(|r| r.config.train.env_steps.is_some());
    let trials =
        groups.iter().flat_map(|g| g.runs.iter()).map(|r| r.config.train.eval_trials).max().unwrap_or(0);
    let mut panels = Vec::new();
    let rows = [
        ("success rate", "success rate (%)"),
        ("evaluation reward", "mean episode reward (eq. 16)"),
        ("evaluation steps", "mean steps (successful trials)"),
    ];
    for (row, (what, unit)) in rows.into_iter().enumerate() {
        for &a in &algos {
            let mut series = algo_series(groups, a, |r| {
                // Steps are undefined (NaN: no line through it) at an evaluation with no success.
                let y = |p: &EvalPoint| match row {
                    0 => 100.0 * p.success_rate,
                    1 => p.mean_reward,
                    _ => p.mean_steps.unwrap_or(f64::NAN),
                };
                r.eval_points.iter().map(|p| (eval_x(r, p), y(p))).collect()
            });
            series.retain(|(_, _, band)| band.mean.iter().any(|m| m.is_finite()));
            // The scripted controller's success rate and steps do not depend on the reward.
            let refs = match (row, reference) {
                (0, Some(r)) => vec![(REFERENCE_LABEL.to_string(), 100.0 * r.success_rate)],
                (2, Some(r)) => r.mean_steps.map(|s| (REFERENCE_LABEL.to_string(), s)).into_iter().collect(),
                _ => Vec::new(),
            };
            panels.push(Panel {
                title: format!("{} — {what}", algo_title(a)),
                x_label: if on_steps { "environment steps".into() } else { "episode".into() },
                y_label: unit.to_string(),
                y_range: (row == 0).then_some((0.0, 102.0)),
                series,
                markers: true,
                marks: Vec::new(),
                refs,
            });
        }
    }
    CurveFigure {
        title: "Figure 8: evaluation during training".into(),
        subtitle: format!(
            "{study}\nDeterministic policy on {trials} fixed random targets at each evaluation point (eval.csv); line: mean over seeds, band: min-max over seeds; no line through an evaluation without success (steps undefined)."
        ),
        rows: 3,
        cols: algos.len(),
        panels,
    }
}

/// Where Figure 8 puts an evaluation: its episode; for a run on a budget of environment steps
/// evaluated every `K` steps, the multiple of `K` it was due at (it runs after the episode that
/// passes it: at most one episode later), so that the seeds' points line up.
fn eval_x(r: &RunData, p: &EvalPoint) -> f64 {
    match (r.config.train.env_steps, r.config.train.eval_every_env_steps) {
        (Some(_), Some(k)) if k > 0 => (p.env_steps / k * k) as f64,
        (Some(_), _) => p.env_steps as f64,
        _ => p.episode as f64,
    }
}

/// Performance profiles of the evaluation success rate (Agarwal et al. 2021): for each threshold
/// tau, the share of runs whose success rate exceeds it; one panel per algorithm, one line per
/// reward function. A curve further up and to the right is better throughout.
pub fn profile_figure(a: &super::aggregate::Aggregates, study: &str) -> CurveFigure {
    let algos: Vec<Method> =
        ALGO_ORDER.into_iter().filter(|al| a.profiles.iter().any(|p| p.algo == *al)).collect();
    let panels = algos
        .iter()
        .map(|&al| Panel {
            title: format!("{} — success-rate profile", algo_title(al)),
            x_label: "success-rate threshold tau (%)".into(),
            y_label: "runs with success rate > tau (%)".into(),
            y_range: Some((0.0, 102.0)),
            series: a
                .profiles
                .iter()
                .filter(|p| p.algo == al)
                .map(|p| {
                    let x: Vec<f64> = p.taus.iter().map(|t| 100.0 * t).collect();
                    let y: Vec<f64> = p.fraction_above.iter().map(|f| 100.0 * f).collect();
                    let label = format!("{} ({} runs)", reward_title(p.reward), p.runs);
                    (p.reward, label, Band { x, mean: y.clone(), lo: y.clone(), hi: y })
                })
                .collect(),
            markers: false,
            marks: Vec::new(),
            refs: Vec::new(),
        })
        .collect();
    CurveFigure {
        title: "Performance profiles: evaluation success rate".into(),
        subtitle: format!("{study}\nEach run's closing evaluation; the share of runs above each threshold (Agarwal et al., NeurIPS 2021)."),
        rows: 1,
        cols: algos.len(),
        panels,
    }
}

/// The legend name of the scripted controller's reference lines.
pub const REFERENCE_LABEL: &str = "Jacobian controller";

/// End-effector paths towards their targets in three projections, one row per rollout set.
pub struct TrajectoryFigure {
    pub sets: Vec<Rollouts>,
}

impl Figure for TrajectoryFigure {
    fn size(&self) -> (u32, u32) {
        (1500, 110 + 530 * self.sets.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        let (head, body) = root.split_vertically(100);
        head.draw(&Text::new(
            "Evaluation trajectories: best and worst reward function",
            (30, 16),
            (FAMILY, 30).into_font(),
        ))
        .map_err(e)?;
        head.draw(&Text::new(
            "End-effector path from the home pose (black square) to the target (x, circle of radius beta); dot: where the episode ended. Metres, base frame; R: episode reward (eq. 16).",
            (30, 60),
            (FAMILY, 17).into_font().color(&RGBColor(80, 80, 80)),
        ))
        .map_err(e)?;
        if self.sets.is_empty() {
            body.draw(&Text::new("no checkpoint to roll out", (40, 40), (FAMILY, 24).into_font()))
                .map_err(e)?;
            return Ok(());
        }
        let rows = body.split_evenly((self.sets.len(), 1));
        for (set, row) in self.sets.iter().zip(rows.iter()) {
            let (cap, panels) = row.split_vertically(66);
            cap.draw(&Text::new(set.title.clone(), (30, 8), (FAMILY, 21).into_font())).map_err(e)?;
            let mut x = 30;
            for (n, path) in set.paths.iter().enumerate() {
                let color = PALETTE[n % PALETTE.len()];
                let label = format!(
                    "trial {}: {}, {} steps, R = {:.2}",
                    path.trial,
                    if path.success { "reached" } else { "missed" },
                    path.points.len().saturating_sub(1),
                    path.reward
                );
                let font = TextStyle::from((FAMILY, 14).into_font());
                let width = cap.estimate_text_size(&label, &font).map_or(8 * label.len() as u32, |(w, _)| w);
                cap.draw(&PathElement::new(vec![(x, 48), (x + 24, 48)], color.stroke_width(4))).map_err(e)?;
                cap.draw(&Text::new(label, (x + 30, 40), font)).map_err(e)?;
                x += 30 + width as i32 + 22;
            }
            let panels = panels.split_evenly((1, 3));
            for (k, (i, j)) in [(0usize, 1usize), (0, 2), (1, 2)].into_iter().enumerate() {
                draw_projection(set, i, j, &panels[k])?;
            }
        }
        Ok(())
    }
}

fn draw_projection<DB: DrawingBackend>(
    set: &Rollouts,
    i: usize,
    j: usize,
    area: &DrawingArea<DB, Shift>,
) -> DrawResult {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let all = set.paths.iter().flat_map(|p| p.points.iter().chain(std::iter::once(&p.target)));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all {
        for (k, c) in [i, j].into_iter().enumerate() {
            lo[k] = lo[k].min(p[c]);
            hi[k] = hi[k].max(p[c]);
        }
    }
    if !lo[0].is_finite() {
        return Ok(());
    }
    // Equal scales on both axes: the same span, centred on the data.
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.05) * 1.15;
    let c0 = 0.5 * (lo[0] + hi[0]);
    let c1 = 0.5 * (lo[1] + hi[1]);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{}-{} projection", AXES[i], AXES[j]), (FAMILY, 18))
        .margin(10)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(c0 - span / 2.0..c0 + span / 2.0, c1 - span / 2.0..c1 + span / 2.0)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(format!("{} (m)", AXES[i]))
        .y_desc(format!("{} (m)", AXES[j]))
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&|x| tick(*x, span))
        .y_label_formatter(&|y| tick(*y, span))
        .draw()
        .map_err(e)?;
    let to_px = (area.dim_in_pixel().0 as f64 - 85.0).max(1.0) / span;
    for (n, path) in set.paths.iter().enumerate() {
        let color = PALETTE[n % PALETTE.len()];
        let pts: Vec<(f64, f64)> = path.points.iter().map(|p| (p[i], p[j])).collect();
        chart
            .draw_series(std::iter::once(PathElement::new(pts.clone(), color.stroke_width(2))))
            .map_err(e)?;
        if let (Some(&first), Some(&last)) = (pts.first(), pts.last()) {
            chart
                .draw_series(std::iter::once(
                    EmptyElement::at(first) + Rectangle::new([(-4, -4), (4, 4)], BLACK.filled()),
                ))
                .map_err(e)?;
            chart.draw_series(std::iter::once(Circle::new(last, 4, color.filled()))).map_err(e)?;
        }
        let t = (path.target[i], path.target[j]);
        let r_px = ((set.beta_m * to_px).round() as i32).max(2);
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(t) + Circle::new((0, 0), r_px, color.stroke_width(1)),
            ))
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(EmptyElement::at(t) + Cross::new((0, 0), 7, color.stroke_width(2))))
            .map_err(e)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_font_parses() {
        assert!(plotters::style::register_font("stagerl-test", FontStyle::Normal, FONT).is_ok());
    }

    #[test]
    fn bands_over_seeds() {
        let b = Band::from_curves(&[vec![(1.0, 1.0), (2.0, 2.0)], vec![(1.0, 3.0), (3.0, 5.0)]]);
        assert_eq!(b.x, vec![1.0, 2.0, 3.0]);
        assert_eq!(b.mean, vec![2.0, 2.0, 5.0]);
        assert_eq!((b.lo[0], b.hi[0]), (1.0, 3.0));
    }

    #[test]
    fn thinning_keeps_the_ends() {
        let c: Vec<(f64, f64)> = (0..5000).map(|i| (i as f64, 0.0)).collect();
        let t = thin(c, 1200);
        assert!(t.len() <= 1202);
        assert_eq!(t.first().unwrap().0, 0.0);
        assert_eq!(t.last().unwrap().0, 4999.0);
    }
}
