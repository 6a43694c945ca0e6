//! Small SVG line and scatter plots (loss curves, error against time or cost), written by hand so
//! they need no font or graphics libraries. Axes may be logarithmic; linear ones get round ticks.
//! The legend sits right of the plot area and the canvas widens to hold it; a reference series
//! (full space among reduced methods) can be drawn apart from the axis it would stretch.

use std::fmt::Write;

/// One named series of (x, y) points.
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Draw as a polyline (true) or as markers.
    pub line: bool,
    /// A dashed polyline (with `line`).
    pub dashed: bool,
    /// Index into the palette; by default the series' position, so that a series can share its
    /// colour with another (the same method measured two ways, say).
    pub color: Option<usize>,
    /// A reference drawn apart (full space beside reduced methods): it does not set the y-axis
    /// range, and a point beyond that range is drawn on the axis edge as a hollow triangle
    /// pointing off the plot, with its value beside it.
    pub reference: bool,
}

/// Axis scaling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Linear,
    Log,
}

/// A plot's title, axis labels and scales.
#[derive(Debug, Clone)]
pub struct Plot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_scale: Scale,
    pub y_scale: Scale,
}

const COLORS: [&str; 7] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
];
/// The colour of guides drawn over the series (a Pareto front): [`Series::color`] past the
/// palette's end.
pub const GUIDE: usize = COLORS.len();
const GUIDE_COLOR: &str = "#555555";
/// The plot area's size and margins (the legend sits right of the plot area, and the canvas
/// widens to hold its longest entry).
const PLOT_W: f64 = 470.0;
const H: f64 = 440.0;
const LEFT: f64 = 80.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;
/// Width of a character of the 12 px sans-serif text, generously: DejaVu Sans, the usual
/// fallback, averages about 7 px.
const CHAR_W: f64 = 7.2;

fn color(index: usize) -> &'static str {
    COLORS.get(index).copied().unwrap_or(GUIDE_COLOR)
}

fn tr(v: f64, scale: Scale) -> Option<f64> {
    match scale {
        Scale::Linear => v.is_finite().then_some(v),
        Scale::Log => (v.is_finite() && v > 0.0).then(|| v.log10()),
    }
}

/// One axis: its range (log10 values on a log axis) and its ticks, every decade on a log axis
/// and round steps (1, 2 or 5 times a power of ten, about five of them) on a linear one, whose
/// range is widened to the steps around the data.
#[derive(Debug)]
struct Axis {
    lo: f64,
    hi: f64,
    scale: Scale,
    ticks: Vec<f64>,
    /// Decimals of the linear ticks' labels.
    decimals: usize,
}

impl Axis {
    /// `pad` (in decades, on a log axis) keeps markers near a decade's end off the frame.
    fn fit(mut lo: f64, mut hi: f64, scale: Scale, pad: f64) -> Self {
        // No point to show: an empty range (∞, −∞).
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (0.0, 1.0);
        }
        if scale == Scale::Log {
            (lo, hi) = ((lo - pad).floor(), (hi + pad).ceil());
        }
        if hi - lo < 1e-12 {
            lo -= 0.5;
            hi += 0.5;
        }
        match scale {
            Scale::Log => Self {
                ticks: (lo as i64..=hi as i64).map(|v| v as f64).collect(),
                lo,
                hi,
                scale,
                decimals: 0,
            },
            Scale::Linear => {
                let raw = (hi - lo) / 5.0;
                let magnitude = 10f64.powf(raw.log10().floor());
                let step = magnitude
                    * [1.0, 2.0, 5.0, 10.0]
                        .into_iter()
                        .find(|&m| m * magnitude >= raw * (1.0 - 1e-9))
                        .unwrap_or(10.0);
                let (first, last) = ((lo / step).floor(), (hi / step).ceil());
                Self {
                    ticks: (first as i64..=last as i64)
                        .map(|i| i as f64 * step)
                        .collect(),
                    lo: first * step,
                    hi: last * step,
                    scale,
                    decimals: (-step.log10().floor()).max(0.0) as usize,
                }
            }
        }
    }

    fn label(&self, v: f64) -> String {
        match self.scale {
            Scale::Log => format!("1e{}", v.round() as i64),
            // Round steps: a tick's value needs no more decimals than its step.
            Scale::Linear => format!("{:.*}", self.decimals, v + 0.0),
        }
    }
}

/// A value beyond a log axis, for the label of a reference point drawn on its edge.
fn value_label(v: f64, scale: Scale) -> String {
    match scale {
        Scale::Log => format!("{:.1e}", 10f64.powf(v)),
        Scale::Linear => format!("{v:.3e}"),
    }
}

/// Renders `series` as an SVG document. Points that cannot be shown (non-positive on a log axis,
/// non-finite) are skipped; a series with no point to show is left out of the legend.
pub fn svg(plot: &Plot, series: &[Series]) -> String {
    let pts: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .filter_map(|&(x, y)| Some((tr(x, plot.x_scale)?, tr(y, plot.y_scale)?)))
                .collect()
        })
        .collect();
    let range = |v: &mut dyn Iterator<Item = f64>| {
        v.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
    };
    let (x0, x1) = range(&mut pts.iter().flatten().map(|p| p.0));
    // The y axis fits the series that are not references, unless there are none.
    let fitted = |reference: bool| {
        series
            .iter()
            .zip(&pts)
            .filter(move |(s, _)| s.reference == reference)
            .flat_map(|(_, p)| p.iter().map(|p| p.1))
    };
    let (y0, y1) = match range(&mut fitted(false)) {
        (lo, hi) if lo <= hi => (lo, hi),
        _ => range(&mut fitted(true)),
    };
    // Whole decades on log axes; where markers are drawn, one near a decade's end moves the
    // axis on to the next (0.08 decade is about a marker's half-width).
    let pad = if series.iter().any(|s| !s.line) {
        0.08
    } else {
        0.0
    };
    let (xa, ya) = (
        Axis::fit(x0, x1, plot.x_scale, pad),
        Axis::fit(y0, y1, plot.y_scale, pad),
    );
    let listed: Vec<usize> = (0..series.len()).filter(|&i| !pts[i].is_empty()).collect();
    let longest = listed
        .iter()
        .map(|&i| series[i].name.chars().count())
        .max()
        .unwrap_or(0);
    let legend_w = if listed.is_empty() {
        20.0
    } else {
        40.0 + CHAR_W * longest as f64
    };
    let w = (LEFT + PLOT_W + legend_w).ceil();
    let right = LEFT + PLOT_W;
    let px = |x: f64| LEFT + (x - xa.lo) / (xa.hi - xa.lo) * PLOT_W;
    let py = |y: f64| H - BOTTOM - (y - ya.lo) / (ya.hi - ya.lo) * (H - TOP - BOTTOM);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{w}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
        (LEFT + right) / 2.0,
        escape(&plot.title)
    );
    for &t in &xa.ticks {
        let x = px(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            TOP,
            H - BOTTOM,
            H - BOTTOM + 18.0,
            xa.label(t)
        );
    }
    for &t in &ya.ticks {
        let y = py(t);
        let _ = writeln!(
            s,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{right:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            LEFT - 6.0,
            y + 4.0,
            ya.label(t)
        );
    }
    let _ = writeln!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{PLOT_W:.1}" height="{:.1}" fill="none" stroke="#333"/>"##,
        H - TOP - BOTTOM
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        (LEFT + right) / 2.0,
        H - 15.0,
        escape(&plot.x_label)
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(18,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        (TOP + H - BOTTOM) / 2.0,
        escape(&plot.y_label)
    );
    for (i, (ser, p)) in series.iter().zip(&pts).enumerate() {
        let color = color(ser.color.unwrap_or(i));
        let dash = if ser.dashed {
            r#" stroke-dasharray="6,4""#
        } else {
            ""
        };
        if ser.line && p.len() > 1 {
            let path: Vec<String> = p
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y.clamp(ya.lo, ya.hi))))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline fill="none" stroke="{color}" stroke-width="1.5"{dash} points="{}"/>"#,
                path.join(" ")
            );
        } else {
            for &(x, y) in p {
                let (cx, cy) = (px(x), py(y));
                if y >= ya.lo && y <= ya.hi {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{cx:.1}" cy="{cy:.1}" r="5" fill="{color}"/>"#
                    );
                    continue;
                }
                // Off the axis (a reference): a triangle on the edge, pointing the way it lies.
                let (edge, dir) = if y < ya.lo {
                    (H - BOTTOM, 1.0)
                } else {
                    (TOP, -1.0)
                };
                let (tip, base) = (edge - 2.0 * dir, edge - 14.0 * dir);
                let _ = writeln!(
                    s,
                    r#"<path d="M{:.1},{base:.1} L{:.1},{base:.1} L{cx:.1},{tip:.1} Z" fill="white" stroke="{color}" stroke-width="2"/><text x="{:.1}" y="{:.1}" text-anchor="end" fill="{color}">{}</text>"#,
                    cx - 7.0,
                    cx + 7.0,
                    cx - 11.0,
                    (tip + base) / 2.0 + 4.0,
                    value_label(y, plot.y_scale)
                );
            }
        }
    }
    for (row, &i) in listed.iter().enumerate() {
        let ser = &series[i];
        let off_axis = pts[i].iter().any(|&(_, y)| y < ya.lo || y > ya.hi);
        let color = color(ser.color.unwrap_or(i));
        let ly = TOP + 14.0 + 20.0 * row as f64;
        let lx = right + 12.0;
        if ser.line {
            let dash = if ser.dashed {
                r#" stroke-dasharray="6,4""#
            } else {
                ""
            };
            let _ = writeln!(
                s,
                r#"<line x1="{lx}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{color}" stroke-width="2"{dash}/>"#,
                ly - 4.0,
                lx + 14.0,
                ly - 4.0
            );
        } else if off_axis {
            // The hollow triangle it is drawn as where it lies off the axis.
            let _ = writeln!(
                s,
                r#"<path d="M{lx},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="white" stroke="{color}" stroke-width="2"/>"#,
                ly - 10.0,
                lx + 12.0,
                ly - 10.0,
                lx + 6.0,
                ly + 1.0
            );
        } else {
            let _ = writeln!(
                s,
                r#"<rect x="{lx}" y="{:.1}" width="12" height="12" fill="{color}"/>"#,
                ly - 10.0
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{ly:.1}">{}</text>"#,
            lx + 18.0,
            escape(&ser.name)
        );
    }
    s.push_str("</svg>\n");
    s
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every method has a colour of its own in the palette, whichever plot draws it.
    #[test]
    fn each_method_has_its_own_colour() {
        let all = crate::simulate::Method::ALL;
        let colors: std::collections::BTreeSet<&str> =
            all.iter().map(|m| color(m.color())).collect();
        assert_eq!(colors.len(), all.len());
        assert!(!colors.contains(GUIDE_COLOR));
    }

    #[test]
    fn log_plots_skip_unshowable_points_and_are_well_formed() {
        let plot = Plot {
            title: "a < b".into(),
            x_label: "epoch".into(),
            y_label: "loss".into(),
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
        };
        let s = svg(
            &plot,
            &[Series {
                name: "train".into(),
                points: vec![
                    (1.0, 1.0),
                    (2.0, 0.1),
                    (3.0, 0.0),
                    (4.0, f64::NAN),
                    (5.0, 0.01),
                ],
                line: true,
                ..Default::default()
            }],
        );
        assert!(s.starts_with("<svg") && s.ends_with("</svg>\n"));
        assert!(s.contains("a &lt; b"));
        let poly = s.lines().find(|l| l.starts_with("<polyline")).unwrap();
        assert_eq!(poly.matches(',').count(), 3, "{poly}");
        assert!(s.contains(">1e-2<") && s.contains(">1e0<"));
    }

    /// The text of every tick label (`>label</text>` after a grid line).
    fn tick_labels(svg: &str) -> Vec<&str> {
        svg.lines()
            .filter(|l| l.starts_with("<line") && l.contains("stroke=\"#ddd\""))
            .filter_map(|l| l.rsplit_once("\">")?.1.strip_suffix("</text>"))
            .collect()
    }

    #[test]
    fn linear_ticks_are_round_and_cover_the_data() {
        let plot = Plot {
            title: "t".into(),
            x_label: "time (s)".into(),
            y_label: "e".into(),
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
        };
        // Frames 1..=100 of h = 0.01: the axis used to tick at 0.01, 0.208, 0.406, ….
        let points = (1..=100)
            .map(|j| (j as f64 * 0.01, 1e-3 * j as f64))
            .collect();
        let s = svg(
            &plot,
            &[Series {
                name: "a".into(),
                points,
                line: true,
                ..Default::default()
            }],
        );
        let labels = tick_labels(&s);
        assert_eq!(labels[..6], ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        assert_eq!(labels[6..], ["1e-3", "1e-2", "1e-1"]);
        let axis = Axis::fit(3.0, 1234.0, Scale::Linear, 0.0);
        assert_eq!((axis.lo, axis.hi), (0.0, 1500.0));
        assert_eq!(axis.label(axis.ticks[1]), "500");
        let axis = Axis::fit(-0.013, 0.0021, Scale::Linear, 0.0);
        assert_eq!(
            axis.ticks
                .iter()
                .map(|&t| axis.label(t))
                .collect::<Vec<_>>(),
            ["-0.015", "-0.010", "-0.005", "0.000", "0.005"]
        );
    }

    #[test]
    fn a_reference_off_the_axis_is_marked_on_its_edge_without_stretching_it() {
        let plot = Plot {
            title: "t".into(),
            x_label: "ms".into(),
            y_label: "error".into(),
            x_scale: Scale::Log,
            y_scale: Scale::Log,
        };
        let marker = |name: &str, x, y, reference| Series {
            name: name.into(),
            points: vec![(x, y)],
            reference,
            ..Default::default()
        };
        let long = "neural-cubature (dim 20, 155 el.) with a long name";
        let s = svg(
            &plot,
            &[
                marker("full-newton", 125.0, 4.26e-9, true),
                marker("pca", 10.0, 7.3e-3, false),
                marker(long, 0.03, 1.27e-2, false),
            ],
        );
        // The y axis spans the reduced methods' decades only; x still reaches the reference.
        assert_eq!(
            tick_labels(&s),
            [
                "1e-2", "1e-1", "1e0", "1e1", "1e2", "1e3", "1e-3", "1e-2", "1e-1"
            ]
        );
        assert_eq!(s.matches("<circle").count(), 2);
        // The reference: a triangle at the bottom edge, its value beside it, and in the legend.
        assert_eq!(s.matches("<path").count(), 2, "{s}");
        assert!(s.contains(">4.3e-9</text>"));
        // The legend fits the canvas: its longest entry ends inside the width.
        let width: f64 = s
            .split_once("width=\"")
            .and_then(|(_, rest)| rest.split_once('"'))
            .map(|(w, _)| w.parse().unwrap())
            .unwrap();
        let entry = s.lines().find(|l| l.contains(long)).unwrap();
        let x: f64 = entry
            .split_once("x=\"")
            .and_then(|(_, rest)| rest.split_once('"'))
            .map(|(x, _)| x.parse().unwrap())
            .unwrap();
        assert!(
            x + CHAR_W * long.chars().count() as f64 <= width,
            "{x} {width}"
        );
    }

    #[test]
    fn a_dashed_series_can_share_a_colour() {
        let plot = Plot {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            x_scale: Scale::Linear,
            y_scale: Scale::Linear,
        };
        let line = |name: &str, dashed, color| Series {
            name: name.into(),
            points: vec![(0.0, 1.0), (1.0, 2.0)],
            line: true,
            dashed,
            color,
            ..Default::default()
        };
        let s = svg(
            &plot,
            &[
                line("a", false, None),
                line("b", false, None),
                line("a, dashed", true, Some(0)),
            ],
        );
        let polys: Vec<&str> = s.lines().filter(|l| l.starts_with("<polyline")).collect();
        assert_eq!(polys.len(), 3);
        assert!(polys[0].contains(COLORS[0]) && !polys[0].contains("dasharray"));
        assert!(polys[1].contains(COLORS[1]));
        assert!(polys[2].contains(COLORS[0]) && polys[2].contains("stroke-dasharray"));
        // Legend entries of lines are line samples, dashed where the series is.
        assert_eq!(s.matches("stroke-dasharray").count(), 2);
    }
}
