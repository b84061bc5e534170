//! The calibration report's figures (SVG, plotters, the stack's embedded font).

use pcr_figures::{FONT_FAMILY, LEG_COLOURS, MEASURED, PLANNED};
use plotters::prelude::*;
use std::path::Path;

/// Why a figure could not be drawn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("figure {file}: {message}")]
pub struct FigureError {
    /// The file.
    pub file: String,
    /// What failed.
    pub message: String,
}

fn ferr<E: std::fmt::Debug>(file: &Path) -> impl Fn(E) -> FigureError + '_ {
    move |e| FigureError {
        file: file.display().to_string(),
        message: format!("{e:?}"),
    }
}

/// Symmetric-ish bounds of a point set with a margin.
fn bounds(pts: impl Iterator<Item = (f64, f64)>, margin: f64) -> ([f64; 2], [f64; 2]) {
    let mut b = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for (x, y) in pts {
        if x.is_finite() && y.is_finite() {
            b = [b[0].min(x), b[1].max(x), b[2].min(y), b[3].max(y)];
        }
    }
    if !b[0].is_finite() {
        return ([-1.0, 1.0], [-1.0, 1.0]);
    }
    let dx = (b[1] - b[0]).max(1e-9) * margin;
    let dy = (b[3] - b[2]).max(1e-9) * margin;
    ([b[0] - dx, b[1] + dx], [b[2] - dy, b[3] + dy])
}

/// A named group of points in a scatter panel.
pub struct Group<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Colour.
    pub colour: RGBColor,
    /// Filled marker (else hollow).
    pub filled: bool,
    /// The points.
    pub points: Vec<(f64, f64)>,
}

/// Scatter panels side by side (e.g. Fig. 5: one panel per orientation), equal axes.
pub fn scatter_panels(
    file: &Path,
    title: &str,
    panels: &[(String, Vec<Group>)],
    x_desc: &str,
    y_desc: &str,
) -> Result<(), FigureError> {
    pcr_figures::init();
    let e = ferr(file);
    let w = 420 * panels.len().max(1) as u32;
    let root = SVGBackend::new(file, (w, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(&e)?;
    let root = root.titled(title, (FONT_FAMILY, 18)).map_err(&e)?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    let all = panels
        .iter()
        .flat_map(|p| p.1.iter().flat_map(|g| g.points.iter().copied()));
    let (xr, yr) = bounds(all, 0.08);
    let half = ((xr[1] - xr[0]).max(yr[1] - yr[0])) / 2.0;
    let (cx, cy) = ((xr[0] + xr[1]) / 2.0, (yr[0] + yr[1]) / 2.0);
    for (area, (name, groups)) in areas.iter().zip(panels) {
        let mut c = ChartBuilder::on(area)
            .caption(name, (FONT_FAMILY, 15))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)
            .map_err(&e)?;
        c.configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style((FONT_FAMILY, 12))
            .draw()
            .map_err(&e)?;
        for g in groups {
            let style = if g.filled {
                g.colour.filled()
            } else {
                g.colour.stroke_width(1)
            };
            c.draw_series(g.points.iter().map(|p| Circle::new(*p, 3, style)))
                .map_err(&e)?
                .label(g.label)
                .legend(move |(x, y)| Circle::new((x + 8, y), 3, style));
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT_FAMILY, 12))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(&e)?;
    }
    root.present().map_err(&e)?;
    Ok(())
}

/// An arrow: start point and displacement, mm.
pub type Arrow = ((f64, f64), (f64, f64));

/// A labelled curve: label, colour index (0..3 leg colours, 3 = grey), points.
pub type Curve = (String, usize, Vec<(f64, f64)>);

/// Error vectors at points, before (grey) and after (colour), magnified by `gain`.
pub fn error_vectors(
    file: &Path,
    title: &str,
    before: &[Arrow],
    after: &[Arrow],
    gain: f64,
) -> Result<(), FigureError> {
    pcr_figures::init();
    let e = ferr(file);
    let root = SVGBackend::new(file, (620, 620)).into_drawing_area();
    root.fill(&WHITE).map_err(&e)?;
    let pts = before
        .iter()
        .chain(after)
        .flat_map(|(p, d)| [*p, (p.0 + gain * d.0, p.1 + gain * d.1)]);
    let (xr, yr) = bounds(pts, 0.08);
    let half = ((xr[1] - xr[0]).max(yr[1] - yr[0])) / 2.0;
    let (cx, cy) = ((xr[0] + xr[1]) / 2.0, (yr[0] + yr[1]) / 2.0);
    let mut c = ChartBuilder::on(&root)
        .caption(title, (FONT_FAMILY, 16))
        .margin(12)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)
        .map_err(&e)?;
    c.configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 12))
        .draw()
        .map_err(&e)?;
    for (set, colour, label) in [
        (before, PLANNED.mix(0.5), format!("before (x{gain:.0})")),
        (after, MEASURED.mix(1.0), format!("after (x{gain:.0})")),
    ] {
        c.draw_series(set.iter().map(|(p, d)| {
            PathElement::new(
                vec![*p, (p.0 + gain * d.0, p.1 + gain * d.1)],
                colour.stroke_width(2),
            )
        }))
        .map_err(&e)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        c.draw_series(set.iter().map(|(p, _)| Circle::new(*p, 2, colour.filled())))
            .map_err(&e)?;
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT_FAMILY, 12))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(&e)?;
    root.present().map_err(&e)?;
    Ok(())
}

/// One panel per leg: measured points and curves of y over x.
pub struct CurvePanel {
    /// Panel title.
    pub title: String,
    /// Scatter points (measured).
    pub points: Vec<(f64, f64)>,
    /// Curves.
    pub curves: Vec<Curve>,
}

/// Everything a panel draws: its points and its curves.
fn panel_points(p: &CurvePanel) -> impl Iterator<Item = (f64, f64)> + '_ {
    p.points
        .iter()
        .copied()
        .chain(p.curves.iter().flat_map(|c| c.2.iter().copied()))
}

/// Panels of curves with data points (e.g. curvature over tendon displacement per leg), each
/// panel on its own scales.
pub fn curve_panels(
    file: &Path,
    title: &str,
    panels: &[CurvePanel],
    x_desc: &str,
    y_desc: &str,
) -> Result<(), FigureError> {
    draw_curve_panels(file, title, panels, x_desc, y_desc, false)
}

/// Panels of curves with data points on one pair of scales, so that the panels compare at a
/// glance (e.g. a residual before and after a correction).
pub fn curve_panels_shared(
    file: &Path,
    title: &str,
    panels: &[CurvePanel],
    x_desc: &str,
    y_desc: &str,
) -> Result<(), FigureError> {
    draw_curve_panels(file, title, panels, x_desc, y_desc, true)
}

fn draw_curve_panels(
    file: &Path,
    title: &str,
    panels: &[CurvePanel],
    x_desc: &str,
    y_desc: &str,
    shared: bool,
) -> Result<(), FigureError> {
    pcr_figures::init();
    let e = ferr(file);
    let w = 420 * panels.len().max(1) as u32;
    let root = SVGBackend::new(file, (w, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(&e)?;
    let root = root.titled(title, (FONT_FAMILY, 18)).map_err(&e)?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    let common = bounds(panels.iter().flat_map(panel_points), 0.05);
    for (area, p) in areas.iter().zip(panels) {
        let (xr, yr) = if shared {
            common
        } else {
            bounds(panel_points(p), 0.05)
        };
        let mut c = ChartBuilder::on(area)
            .caption(&p.title, (FONT_FAMILY, 15))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(xr[0]..xr[1], yr[0]..yr[1])
            .map_err(&e)?;
        c.configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style((FONT_FAMILY, 12))
            .draw()
            .map_err(&e)?;
        c.draw_series(
            p.points
                .iter()
                .map(|q| Circle::new(*q, 2, MEASURED.filled())),
        )
        .map_err(&e)?
        .label("measured")
        .legend(|(x, y)| Circle::new((x + 8, y), 3, MEASURED.filled()));
        for (label, colour, pts) in &p.curves {
            let col = if *colour < 3 {
                LEG_COLOURS[*colour]
            } else {
                RGBColor(0x88, 0x88, 0x88)
            };
            c.draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
                .map_err(&e)?
                .label(label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2))
                });
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT_FAMILY, 12))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(&e)?;
    }
    root.present().map_err(&e)?;
    Ok(())
}

/// The labelled and the grid-only ticks of a log axis over `lo..hi` (`0 < lo < hi`): 1, 2 and 5
/// times the powers of ten (only the powers of ten when that gives more than eight labels, and
/// every integer multiple when 1-2-5 gives fewer than three), and the integer multiples for the
/// grid.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let decades = lo.log10().floor() as i32..=hi.log10().ceil() as i32;
    // m x 10^e parsed from its decimal form: 0.2, not 0.20000000000000004.
    let within = |mantissas: &[u32]| -> Vec<f64> {
        decades
            .clone()
            .flat_map(|e| mantissas.iter().map(move |m| format!("{m}e{e}")))
            .filter_map(|t| t.parse::<f64>().ok())
            .filter(|v| *v >= lo * (1.0 - 1e-12) && *v <= hi * (1.0 + 1e-12))
            .collect()
    };
    let all: Vec<u32> = (1..=9).collect();
    let mut major = within(&[1, 2, 5]);
    if major.len() > 8 {
        major = within(&[1]);
    } else if major.len() < 3 {
        major = within(&all);
    }
    (major, within(&all))
}

/// A tick label of a log axis: the value with as many decimals as its first significant digit
/// needs ("0.05", "0.2", "3", "20").
pub fn tick_label(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return format!("{v}");
    }
    let decimals = (-(v.log10() + 1e-9).floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// Horizontal comparison bars: one row per label, several values per row (log scale).
pub fn bars(
    file: &Path,
    title: &str,
    labels: &[String],
    series: &[(&str, RGBColor, Vec<Option<f64>>)],
    x_desc: &str,
) -> Result<(), FigureError> {
    pcr_figures::init();
    let e = ferr(file);
    let h = 60 + 26 * labels.len() as u32;
    let root = SVGBackend::new(file, (760, h.max(300))).into_drawing_area();
    root.fill(&WHITE).map_err(&e)?;
    let vals = series
        .iter()
        .flat_map(|s| s.2.iter().flatten().copied())
        .filter(|v| *v > 0.0);
    let (lo, hi) = vals.fold((f64::INFINITY, 0.0f64), |a, v| (a.0.min(v), a.1.max(v)));
    // Room on the right of the longest bar for the legend (about a fifth of the axis).
    let (lo, hi) = if lo.is_finite() {
        let lo = lo / 2.0;
        (lo, hi * (hi / lo).powf(0.3).max(2.0))
    } else {
        (0.01, 10.0)
    };
    let n = labels.len();
    let (major, minor) = log_ticks(lo, hi);
    let mut c = ChartBuilder::on(&root)
        .caption(title, (FONT_FAMILY, 16))
        .margin(12)
        .x_label_area_size(35)
        .y_label_area_size(150)
        .build_cartesian_2d(
            (lo..hi)
                .log_scale()
                .with_key_points(major)
                .with_light_points(minor),
            0.0..n as f64,
        )
        .map_err(&e)?;
    let labels_owned: Vec<String> = labels.to_vec();
    c.configure_mesh()
        .x_desc(x_desc)
        .x_label_formatter(&|v: &f64| tick_label(*v))
        .y_max_light_lines(0)
        .y_labels(n * 2 + 1)
        .y_label_formatter(&move |y: &f64| {
            let k = (y - 0.5).round();
            if (y - 0.5 - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < n {
                labels_owned[n - 1 - k as usize].clone()
            } else {
                String::new()
            }
        })
        .label_style((FONT_FAMILY, 12))
        .draw()
        .map_err(&e)?;
    let m = series.len().max(1) as f64;
    for (si, (label, colour, v)) in series.iter().enumerate() {
        let col = *colour;
        c.draw_series(v.iter().enumerate().filter_map(|(k, val)| {
            let val = (*val)?;
            let row = (n - 1 - k) as f64;
            let y0 = row + 0.1 + 0.8 * si as f64 / m;
            let y1 = row + 0.1 + 0.8 * (si + 1) as f64 / m;
            Some(Rectangle::new([(lo, y0), (val.max(lo), y1)], col.filled()))
        }))
        .map_err(&e)?
        .label(*label)
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], col.filled()));
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT_FAMILY, 12))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(&e)?;
    root.present().map_err(&e)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The text elements of an SVG: (x, y, text).
    fn texts(svg: &str) -> Vec<(f64, f64, String)> {
        let attr = |tag: &str, name: &str| -> f64 {
            let key = format!(" {name}=\"");
            tag.find(&key)
                .and_then(|i| {
                    let v = &tag[i + key.len()..];
                    v[..v.find('"')?].parse().ok()
                })
                .unwrap_or(f64::NAN)
        };
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let (tag, rest) = t.split_once('>')?;
                let text = rest.split_once("</text>")?.0;
                Some((attr(tag, "x"), attr(tag, "y"), text.trim().to_string()))
            })
            .collect()
    }

    fn temp_svg(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("pcr-figures-{name}-{}.svg", std::process::id()))
    }

    #[test]
    fn log_ticks_are_one_two_five_with_short_labels() {
        let (major, minor) = log_ticks(0.115, 5.8);
        assert_eq!(major, [0.2, 0.5, 1.0, 2.0, 5.0]);
        assert_eq!(minor.len(), 8 + 5, "{minor:?}");
        let labels: Vec<String> = major.iter().map(|v| tick_label(*v)).collect();
        assert_eq!(labels, ["0.2", "0.5", "1", "2", "5"]);
        assert_eq!(tick_label(0.05), "0.05");
        assert_eq!(tick_label(3e-3), "0.003");
        assert_eq!(tick_label(20.0), "20");
        // Six decades: powers of ten only; a narrow range: every integer multiple.
        assert_eq!(
            log_ticks(0.01, 9000.0).0,
            [0.01, 0.1, 1.0, 10.0, 100.0, 1000.0]
        );
        assert_eq!(log_ticks(0.25, 0.7).0, [0.3, 0.4, 0.5, 0.6, 0.7]);
        assert!(log_ticks(0.0, 1.0).0.is_empty() && log_ticks(2.0, 1.0).0.is_empty());
    }

    #[test]
    fn bars_label_their_log_axis_with_separate_numbers() {
        let file = temp_svg("bars");
        let labels = vec!["check poses RMS (mm)".to_string(), "circle RMS (mm)".into()];
        let series = vec![
            (
                "nominal",
                RGBColor(150, 150, 150),
                vec![Some(2.9), Some(2.85)],
            ),
            (
                "calibrated",
                RGBColor(31, 119, 180),
                vec![Some(0.23), Some(1.01)],
            ),
            ("extended", RGBColor(214, 39, 40), vec![Some(0.3), None]),
        ];
        bars(&file, "Error on the robot", &labels, &series, "mm").unwrap();
        let svg = std::fs::read_to_string(&file).unwrap();
        let _ = std::fs::remove_file(&file);
        // The x axis labels: below the plot, numbers.
        let axis: Vec<(f64, String)> = texts(&svg)
            .into_iter()
            .filter(|(_, _, t)| t.parse::<f64>().is_ok())
            .map(|(x, _, t)| (x, t))
            .collect();
        let values: Vec<&str> = axis.iter().map(|a| a.1.as_str()).collect();
        assert_eq!(values, ["0.2", "0.5", "1", "2", "5"], "{axis:?}");
        for w in axis.windows(2) {
            // At least the width of the labels apart (12 px font: under 8 px a character).
            let gap = w[1].0 - w[0].0;
            assert!(gap > 8.0 * (w[0].1.len() + w[1].1.len()) as f64, "{axis:?}");
        }
    }

    #[test]
    fn shared_panels_have_one_scale() {
        let file = temp_svg("shared");
        let panel = |title: &str, top: f64| CurvePanel {
            title: title.into(),
            points: (0..50)
                .map(|k| (k as f64, top * (k % 7) as f64 / 6.0))
                .collect(),
            curves: vec![],
        };
        let panels = [panel("before", 3.0), panel("after", 0.4)];
        let axis_labels = |file: &Path| {
            let svg = std::fs::read_to_string(file).unwrap();
            // y labels: numbers right-aligned left of each panel (at 60 px into the panel).
            let mut sides = (Vec::new(), Vec::new());
            for (x, _, t) in texts(&svg) {
                if t.parse::<f64>().is_ok() && x % 420.0 <= 70.0 {
                    if x < 420.0 {
                        sides.0.push(t)
                    } else {
                        sides.1.push(t)
                    }
                }
            }
            sides
        };
        curve_panels_shared(&file, "residual", &panels, "t (s)", "mm").unwrap();
        let (a, b) = axis_labels(&file);
        assert!(a.len() >= 3, "{a:?}");
        assert_eq!(a, b);
        assert!(a.iter().any(|t| t.parse::<f64>().unwrap() >= 2.0), "{a:?}");
        // Each panel on its own scale otherwise.
        curve_panels(&file, "residual", &panels, "t (s)", "mm").unwrap();
        let (a, b) = axis_labels(&file);
        let _ = std::fs::remove_file(&file);
        assert_ne!(a, b);
    }
}
