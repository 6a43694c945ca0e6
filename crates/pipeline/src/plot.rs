//! Small SVG line and scatter plots (loss curves, error against time), written by hand so they
//! need no font or graphics libraries. Axes may be logarithmic.

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

const COLORS: [&str; 6] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
];
const W: f64 = 720.0;
const H: f64 = 440.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 170.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;

fn tr(v: f64, scale: Scale) -> Option<f64> {
    match scale {
        Scale::Linear => v.is_finite().then_some(v),
        Scale::Log => (v.is_finite() && v > 0.0).then(|| v.log10()),
    }
}

fn label(v: f64, scale: Scale) -> String {
    match scale {
        Scale::Log => format!("1e{}", v.round() as i64),
        Scale::Linear => {
            if v.abs() >= 1e4 || (v != 0.0 && v.abs() < 1e-2) {
                format!("{v:.1e}")
            } else {
                format!("{v:.3}")
                    .trim_end_matches('0')
                    .trim_end_matches('.')
                    .to_string()
            }
        }
    }
}

/// Renders `series` as an SVG document. Points that cannot be shown (non-positive on a log axis,
/// non-finite) are skipped.
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
    let all: Vec<&(f64, f64)> = pts.iter().flatten().collect();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &&(x, y) in &all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if all.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let pad = |lo: &mut f64, hi: &mut f64, scale: Scale| {
        if scale == Scale::Log {
            *lo = lo.floor();
            *hi = hi.ceil();
        }
        if *hi - *lo < 1e-12 {
            *lo -= 0.5;
            *hi += 0.5;
        }
    };
    pad(&mut x0, &mut x1, plot.x_scale);
    pad(&mut y0, &mut y1, plot.y_scale);
    let px = |x: f64| LEFT + (x - x0) / (x1 - x0) * (W - LEFT - RIGHT);
    let py = |y: f64| H - BOTTOM - (y - y0) / (y1 - y0) * (H - TOP - BOTTOM);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
        (LEFT + W - RIGHT) / 2.0,
        escape(&plot.title)
    );
    // Ticks: every decade on log axes, five divisions on linear ones.
    let ticks = |lo: f64, hi: f64, scale: Scale| -> Vec<f64> {
        match scale {
            Scale::Log => (lo as i64..=hi as i64).map(|v| v as f64).collect(),
            Scale::Linear => (0..=5).map(|i| lo + (hi - lo) * i as f64 / 5.0).collect(),
        }
    };
    for t in ticks(x0, x1, plot.x_scale) {
        let x = px(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            TOP,
            H - BOTTOM,
            H - BOTTOM + 18.0,
            label(t, plot.x_scale)
        );
    }
    for t in ticks(y0, y1, plot.y_scale) {
        let y = py(t);
        let _ = writeln!(
            s,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            W - RIGHT,
            LEFT - 6.0,
            y + 4.0,
            label(t, plot.y_scale)
        );
    }
    let _ = writeln!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{:.1}" height="{:.1}" fill="none" stroke="#333"/>"##,
        W - LEFT - RIGHT,
        H - TOP - BOTTOM
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        (LEFT + W - RIGHT) / 2.0,
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
        let color = COLORS[ser.color.unwrap_or(i) % COLORS.len()];
        let dash = if ser.dashed {
            r#" stroke-dasharray="6,4""#
        } else {
            ""
        };
        if ser.line && p.len() > 1 {
            let path: Vec<String> = p
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline fill="none" stroke="{color}" stroke-width="1.5"{dash} points="{}"/>"#,
                path.join(" ")
            );
        } else {
            for &(x, y) in p {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="5" fill="{color}"/>"#,
                    px(x),
                    py(y)
                );
            }
        }
        let ly = TOP + 14.0 + 20.0 * i as f64;
        let lx = W - RIGHT + 12.0;
        if ser.line {
            let _ = writeln!(
                s,
                r#"<line x1="{lx}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{color}" stroke-width="2"{dash}/>"#,
                ly - 4.0,
                lx + 14.0,
                ly - 4.0
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
