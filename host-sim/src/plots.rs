//! Plots (plotters): loops, time series and residuals, as SVG or PNG files or as SVG text for
//! the HTML report. The font is bundled (no system fonts needed).

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, bail, Result};
use plotters::coord::ranged1d::Ranged;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One curve.
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
    /// Palette index (0 measured, 1 model, 2 residual, …).
    pub color: usize,
}

/// A chart: title, axis labels with units, curves.
pub struct Chart {
    /// Caption.
    pub title: String,
    /// x axis label with unit.
    pub x_label: String,
    /// y axis label with unit.
    pub y_label: String,
    /// The curves.
    pub series: Vec<Series>,
    /// A fixed y range (e.g. 0–1 for a coherence); `None`: the data's.
    pub y_range: Option<(f64, f64)>,
}

const PALETTE: [RGBColor; 5] = [
    RGBColor(30, 30, 30),
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
];

fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut ok = true;
    ONCE.call_once(|| {
        ok = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        )
        .is_ok();
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("cannot load the bundled plot font"))
    }
}

/// The x axis of a chart: linear, or logarithmic (frequency axes of spectra and Bode plots).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XScale {
    /// Linear.
    Linear,
    /// Base-10 logarithmic, points at x ≤ 0 left out; linear when the data span less than a
    /// decade (a log axis would show one or two labels).
    Log,
}

/// How the curves are stroked: the measured one wider than the rest (SVG, where the viewer
/// joins lines), or every curve one pixel wide (bitmaps).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Lines {
    WideMeasured,
    Thin,
}

fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: &Chart,
    scale: XScale,
    lines: Lines,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let shown = |x: f64, y: f64| x.is_finite() && y.is_finite() && (scale == XScale::Linear || x > 0.0);
    let pts = c.series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        if shown(x, y) {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (1.0, 10.0, 0.0, 1.0);
    }
    if let Some((lo, hi)) = c.y_range {
        (y0, y1) = (lo, hi);
    }
    let scale = if scale == XScale::Log && x1 < 10.0 * x0 { XScale::Linear } else { scale };
    let pad = |a: f64, b: f64| if b > a { 0.04 * (b - a) } else { 0.5 * a.abs().max(1e-9) };
    let py = pad(y0, y1);
    let y = (y0 - py)..(y1 + py);
    let title = fitted_title(area, &c.title)?;
    match scale {
        XScale::Linear => {
            let px = pad(x0, x1);
            let x = (x0 - px)..(x1 + px);
            let (legend, y) = place_legend(area, c, &title, x.clone(), y, &shown)?;
            let y_format = linear_format(&y);
            draw_on(area, c, &title, legend, x.clone(), &linear_format(&x), y, &y_format, shown, lines)
        }
        XScale::Log => {
            let (lo, hi) = if x1 > x0 { (x0 / 1.1, x1 * 1.1) } else { (x0 / 2.0, x0 * 2.0) };
            let (bold, light) = log_ticks(lo, hi);
            let (legend, y) = place_legend(area, c, &title, (lo..hi).log_scale(), y, &shown)?;
            let y_format = linear_format(&y);
            let x = (lo..hi).log_scale().with_key_points(bold).with_light_points(light);
            draw_on(area, c, &title, legend, x, &log_label, y, &y_format, shown, lines)
        }
    }
}

/// Caption size and the chart's margins (in pixels), as [`chart_on`] lays them out.
const CAPTION_FONT: u32 = 18;
const MARGIN: u32 = 12;

/// `title`, shortened at its start (`…`) until it fits the area's width: a long input path
/// would otherwise be cut off at both ends, and with it what the chart shows.
fn fitted_title<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str) -> Result<String>
where
    DB::ErrorType: 'static,
{
    let style = TextStyle::from(("sans-serif", CAPTION_FONT).into_font());
    let room = area.dim_in_pixel().0.saturating_sub(2 * MARGIN);
    let chars: Vec<char> = title.chars().collect();
    for cut in 0..chars.len() {
        let text: String = if cut == 0 {
            title.to_string()
        } else {
            std::iter::once('…').chain(chars[cut..].iter().copied()).collect()
        };
        let (w, _) = area.estimate_text_size(&text, &style).map_err(|e| anyhow!("{e}"))?;
        if w <= room {
            return Ok(text);
        }
    }
    Ok(String::new())
}

/// The chart frame every plot uses: caption, margins, label areas.
fn chart_on<'a, DB: DrawingBackend, X: plotters::coord::ranged1d::AsRangedCoord<Value = f64>>(
    area: &'a DrawingArea<DB, Shift>,
    title: &str,
    x: X,
    y: std::ops::Range<f64>,
) -> Result<ChartContext<'a, DB, Cartesian2d<X::CoordDescType, RangedCoordf64>>>
where
    DB::ErrorType: 'static,
{
    ChartBuilder::on(area)
        .caption(title, ("sans-serif", CAPTION_FONT))
        .margin(MARGIN)
        // Room for half of the last x tick's label, centred on the plot's right edge.
        .margin_right(3 * MARGIN)
        .x_label_area_size(42)
        .y_label_area_size(64)
        .build_cartesian_2d(x, y)
        .map_err(|e| anyhow!("{e}"))
}

/// Where the legend goes, and the y range that keeps it off the data: the first corner whose
/// legend box no curve crosses (upper left, upper right, lower left, lower right), else the
/// upper left with the y range raised until the curves pass below the box. Laid out on a scratch
/// SVG of the area's size, with plotters' own legend metrics.
fn place_legend<DB: DrawingBackend, X: plotters::coord::ranged1d::AsRangedCoord<Value = f64>>(
    area: &DrawingArea<DB, Shift>,
    c: &Chart,
    title: &str,
    x: X,
    y: std::ops::Range<f64>,
    shown: &impl Fn(f64, f64) -> bool,
) -> Result<(SeriesLabelPosition, std::ops::Range<f64>)>
where
    DB::ErrorType: 'static,
{
    let labels: Vec<&str> = c.series.iter().map(|s| s.label.as_str()).filter(|l| !l.is_empty()).collect();
    if labels.is_empty() {
        return Ok((SeriesLabelPosition::UpperLeft, y));
    }
    let mut scratch = String::new();
    let root = SVGBackend::with_string(&mut scratch, area.dim_in_pixel()).into_drawing_area();
    let chart = chart_on(&root, title, x, y.clone())?;
    // The legend's size as plotters lays it out: text lines, a 30 px swatch, 10 px margins.
    let font = TextStyle::from(("sans-serif", LEGEND_FONT).into_font());
    let mut text = MultiLineText::<_, &str>::new((0, 0), &font);
    for l in &labels {
        text.push_line(*l);
    }
    let (w, h) = text.estimate_dimension().map_err(|e| anyhow!("{e}"))?;
    let (w, h) = (f64::from(w + 30 + 20), f64::from(h + 20));
    let (px, py) = chart.plotting_area().get_base_pixel();
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let (px, py, pw, ph) = (f64::from(px), f64::from(py), f64::from(pw), f64::from(ph));
    // A few pixels of air around the box.
    let gap = 4.0;
    let corner = |right: bool, low: bool| {
        let x0 = if right { px + pw - w - 5.0 } else { px + 5.0 };
        let y0 = if low { py + ph - h - 5.0 } else { py + 5.0 };
        (x0 - gap, y0 - gap, x0 + w + gap, y0 + h + gap)
    };
    let segments: Vec<((f64, f64), (f64, f64))> = c
        .series
        .iter()
        .flat_map(|s| {
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|p| shown(p.0, p.1))
                .map(|p| {
                    let (bx, by) = chart.backend_coord(p);
                    (f64::from(bx), f64::from(by))
                })
                .collect();
            let single = (pts.len() == 1).then(|| (pts[0], pts[0]));
            pts.windows(2).map(|w| (w[0], w[1])).chain(single).collect::<Vec<_>>()
        })
        .collect();
    for (pos, right, low) in [
        (SeriesLabelPosition::UpperLeft, false, false),
        (SeriesLabelPosition::UpperRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, true),
    ] {
        let b = corner(right, low);
        if !segments.iter().any(|(a, e)| segment_hits_box(*a, *e, b)) {
            return Ok((pos, y));
        }
    }
    // Raise the top so that the highest curve point lies below the upper-left box: with the
    // box's bottom a share f of the plot height down from the top, top' = (y_max − f·lo)/(1 − f).
    let f = (corner(false, false).3 - py) / ph;
    if !(f > 0.0 && f < 0.6) {
        return Ok((SeriesLabelPosition::UpperLeft, y));
    }
    let y_max = c
        .series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| shown(p.0, p.1))
        .map(|p| p.1)
        .fold(f64::NEG_INFINITY, f64::max)
        .min(y.end);
    let top = (y_max - f * y.start) / (1.0 - f);
    Ok((SeriesLabelPosition::UpperLeft, y.start..top.max(y.end)))
}

/// Whether the segment a–e (pixels) meets the box (x0, y0, x1, y1) (Liang–Barsky clipping).
fn segment_hits_box(a: (f64, f64), e: (f64, f64), b: (f64, f64, f64, f64)) -> bool {
    let (dx, dy) = (e.0 - a.0, e.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 - b.0), (dx, b.2 - a.0), (-dy, a.1 - b.1), (dy, b.3 - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Font size of the legend's text.
const LEGEND_FONT: u32 = 13;

/// How many labels the mesh asks each axis' key points for (at most).
const LABELS: usize = 11;
/// Series of at most this many points are drawn with each point marked.
const FEW_POINTS: usize = 12;

/// Tick labels of a linear axis over `range`: as many decimals as the tick step needs (at least
/// one), and 0 for a tick that rounding leaves at −0.
fn linear_format(range: &std::ops::Range<f64>) -> impl Fn(&f64) -> String {
    let ticks = RangedCoordf64::from(range.clone()).key_points(LABELS);
    let step = ticks.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let decimals =
        if step.is_finite() && step > 0.0 { (-step.log10() - 1e-6).ceil().max(1.0) as usize } else { 1 };
    move |v: &f64| {
        let v = if v.abs() < 0.5 * 10f64.powi(-(decimals as i32)) { 0.0 } else { *v };
        format!("{v:.decimals$}")
    }
}

/// Ticks of a logarithmic axis over `lo..hi`: labelled (bold) ticks at 1, 2, 3, 5, 7 × 10^k, or at
/// 1, 2, 5 × 10^k, or at the decades (every n-th when they are many), the densest choice that
/// labels at most ten; light ticks at every 1…9 × 10^k.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let at = |mantissas: &[f64], every: i32| -> Vec<f64> {
        (k0..=k1)
            .filter(|k| (k - k0) % every == 0)
            .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    let light =
        if k1 - k0 <= 8 { at(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0], 1) } else { at(&[1.0], 1) };
    for mantissas in [&[1.0, 2.0, 3.0, 5.0, 7.0][..], &[1.0, 2.0, 5.0], &[1.0]] {
        let bold = at(mantissas, 1);
        if bold.len() <= 10 {
            return (bold, light);
        }
    }
    (at(&[1.0], (k1 - k0).div_euclid(10) + 1), light)
}

/// A logarithmic axis' tick label: the value m × 10^k with the decimals 10^k needs (200, 0.5).
fn log_label(v: &f64) -> String {
    let decimals = (-(v.log10() + 1e-9).floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

#[allow(clippy::too_many_arguments)]
fn draw_on<DB: DrawingBackend, X>(
    area: &DrawingArea<DB, Shift>,
    c: &Chart,
    title: &str,
    legend: SeriesLabelPosition,
    x: X,
    x_format: &dyn Fn(&f64) -> String,
    y: std::ops::Range<f64>,
    y_format: &dyn Fn(&f64) -> String,
    shown: impl Fn(f64, f64) -> bool,
    lines: Lines,
) -> Result<()>
where
    DB::ErrorType: 'static,
    X: plotters::coord::ranged1d::AsRangedCoord<Value = f64>,
    X::CoordDescType: plotters::coord::ranged1d::ValueFormatter<f64>,
{
    let mut chart = chart_on(area, title, x, y)?;
    chart
        .configure_mesh()
        .x_desc(&c.x_label)
        .y_desc(&c.y_label)
        .x_labels(LABELS)
        .x_label_formatter(x_format)
        .y_labels(LABELS)
        .y_label_formatter(y_format)
        .label_style(("sans-serif", 13))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    for s in &c.series {
        let color = PALETTE[s.color % PALETTE.len()];
        let points: Vec<(f64, f64)> = s.points.iter().copied().filter(|p| shown(p.0, p.1)).collect();
        // A series of a few points (a Bode plot of sine recordings: one per excited line) gets
        // them marked: a bare straight line between two would read as a measured curve.
        if points.len() <= FEW_POINTS {
            chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))
                .map_err(|e| anyhow!("{e}"))?;
        }
        // The measured trace is drawn wider, under the model's: where they agree it shows as
        // a dark edge on both sides of the model's line instead of vanishing beneath it.
        let width = if s.color == 0 && lines == Lines::WideMeasured { 3 } else { 1 };
        let drawn = chart
            .draw_series(LineSeries::new(points, color.stroke_width(width)))
            .map_err(|e| anyhow!("{e}"))?;
        // An unlabelled series (a second bound line) shares its neighbour's legend entry.
        if !s.label.is_empty() {
            drawn.label(&s.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(width.max(2)))
            });
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font(("sans-serif", LEGEND_FONT))
        .position(legend)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// Draws `chart` to `path` (`.svg` or `.png`, 800 × 500).
pub fn write(path: &Path, chart: &Chart) -> Result<()> {
    write_panels(path, std::slice::from_ref(chart), XScale::Linear)
}

/// Draws `charts` stacked top to bottom (panels sharing one figure, e.g. gain over phase) to
/// `path` (`.svg` or `.png`, 800 wide, 500 for one panel and 300 more for each further one).
pub fn write_panels(path: &Path, charts: &[Chart], scale: XScale) -> Result<()> {
    register_font()?;
    let size = (800, 500 + 300 * charts.len().saturating_sub(1) as u32);
    match path.extension().and_then(|e| e.to_str()) {
        Some("svg") => {
            let text = svg_text(size, |root| draw_panels(root, charts, scale, Lines::WideMeasured))?;
            crate::files::write_atomic(path, text.as_bytes())
        }
        Some("png") => {
            // The encoder picks the format from the name: draw into a unique `.png` temporary
            // file beside the target (concurrent runs never share one), then rename it into place.
            let tmp = crate::files::partial_file_with_suffix(
                crate::files::output_dir(path),
                crate::partials::PNG_SUFFIX,
            )?;
            {
                let root = BitMapBackend::new(tmp.path(), size).into_drawing_area();
                // Thin: the bitmap backend joins wide polylines with unbounded miters, which
                // draw spikes where a loop turns back on itself.
                draw_panels(&root, charts, scale, Lines::Thin)?;
                root.present().map_err(|e| anyhow!("{e}"))?;
            }
            crate::files::persist(tmp, path)
        }
        _ => bail!("{}: plots are written as .svg or .png", path.display()),
    }
}

fn draw_panels<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    charts: &[Chart],
    scale: XScale,
    lines: Lines,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    for (panel, chart) in area.split_evenly((charts.len().max(1), 1)).iter().zip(charts) {
        draw(panel, chart, scale, lines)?;
    }
    Ok(())
}

/// Stacked panels as SVG text (for inlining in HTML); `size` is the whole figure's.
pub fn svg_panels(charts: &[Chart], size: (u32, u32), scale: XScale) -> Result<String> {
    svg_text(size, |root| draw_panels(root, charts, scale, Lines::WideMeasured))
}

/// One SVG document of `size` drawn by `draw` on its root area. The document is presented once,
/// on the root, after everything is drawn: the SVG backend closes the document (`</svg>`) at the
/// first `present`, so presenting a panel would leave the panels drawn after it outside.
fn svg_text(
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Result<()>,
) -> Result<String> {
    register_font()?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        draw(&root)?;
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    Ok(text)
}

/// A grouped bar chart: one group per category (named on the x axis), one bar per series in
/// each group, the value written on top of each bar.
pub struct Bars {
    /// Caption.
    pub title: String,
    /// y axis label with unit.
    pub y_label: String,
    /// The category names on the x axis.
    pub categories: Vec<String>,
    /// (legend text, one value per category (None: no bar), palette index).
    pub series: Vec<(String, Vec<Option<f64>>, usize)>,
    /// How a value is written on its bar (e.g. `11.2 %`).
    pub value_format: fn(f64) -> String,
}

fn draw_bars<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, b: &Bars) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let top = b
        .series
        .iter()
        .flat_map(|s| s.1.iter().flatten())
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(*v));
    let top = if top > 0.0 { 1.15 * top } else { 1.0 };
    let groups = b.categories.len().max(1);
    let mut chart = ChartBuilder::on(area)
        .caption(&b.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..groups as f64, 0.0..top)
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc(&b.y_label)
        .label_style(("sans-serif", 13))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    // Category k spans [k, k + 1]; its bars share the middle 70 %, side by side.
    let width = 0.7 / b.series.len().max(1) as f64;
    for (s_idx, (label, values, color)) in b.series.iter().enumerate() {
        let color = PALETTE[color % PALETTE.len()];
        let left = |k: usize| k as f64 + 0.15 + s_idx as f64 * width;
        let bars = values.iter().enumerate().filter_map(|(k, v)| {
            let v = v.filter(|v| v.is_finite())?;
            let mut r = Rectangle::new([(left(k), 0.0), (left(k) + width, v)], color.filled());
            r.set_margin(0, 0, 1, 1);
            Some(r)
        });
        chart
            .draw_series(bars)
            .map_err(|e| anyhow!("{e}"))?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
        let texts = values.iter().enumerate().filter_map(|(k, v)| {
            let v = v.filter(|v| v.is_finite())?;
            Some(
                EmptyElement::at((left(k), v))
                    + Text::new((b.value_format)(v), (0, -16), ("sans-serif", 12).into_font()),
            )
        });
        chart.draw_series(texts).map_err(|e| anyhow!("{e}"))?;
    }
    // The category names under the axis, centred on their group (drawn on the whole area: the
    // plot area clips what lies below its axis).
    for (k, name) in b.categories.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(k as f64 + 0.5, 0.0));
        let style = TextStyle::from(("sans-serif", 13).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
        area.draw(&Text::new(name.clone(), (x, y + 8), style)).map_err(|e| anyhow!("{e}"))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// The bar chart as SVG text (for inlining in HTML).
pub fn bars_svg(bars: &Bars, size: (u32, u32)) -> Result<String> {
    svg_text(size, |root| draw_bars(root, bars))
}

/// The chart as SVG text (for inlining in HTML).
pub fn svg(chart: &Chart, size: (u32, u32)) -> Result<String> {
    svg_text(size, |root| draw(root, chart, XScale::Linear, Lines::WideMeasured))
}

/// Every `step`-th point (plots need no more than a few thousand).
pub fn thin<T: Copy>(v: &[T], max_points: usize) -> Vec<T> {
    let step = v.len().div_ceil(max_points.max(1)).max(1);
    v.iter().step_by(step).copied().collect()
}
#[cfg(test)]
mod tests;
