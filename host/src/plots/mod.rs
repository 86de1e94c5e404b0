//! Plots of a fit as SVG, written directly (no font or raster libraries: the text is SVG
//! text, rendered by the viewer): measured a–u_s points with the fitted curve and the table
//! curves at the neighbouring grid moduli, and the residuals against u_s.
//! (PNG output through plotters is not implemented.)

use std::fmt::Write as _;
use std::path::Path;

use crate::fit::{FitPoint, LutModel, ModulusFit};

const W: f64 = 640.0;
const H: f64 = 420.0;
const M: f64 = 60.0;

struct Axes {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Axes {
    fn px(&self, x: f64) -> f64 {
        M + (x - self.x0) / (self.x1 - self.x0) * (W - 1.5 * M)
    }
    fn py(&self, y: f64) -> f64 {
        H - M - (y - self.y0) / (self.y1 - self.y0) * (H - 1.8 * M)
    }
    fn frame(&self, svg: &mut String, title: &str, xlabel: &str, ylabel: &str) {
        let _ = write!(
            svg,
            r##"<rect x="{M}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
            0.8 * M,
            W - 1.5 * M,
            H - 1.8 * M
        );
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="15" text-anchor="middle">{title}</text>"#,
            W / 2.0,
            0.5 * M
        );
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle">{xlabel}</text>"#,
            W / 2.0,
            H - 0.3 * M
        );
        let _ = write!(
            svg,
            r#"<text x="15" y="{:.1}" font-size="13" transform="rotate(-90 15 {:.1})" text-anchor="middle">{ylabel}</text>"#,
            H / 2.0,
            H / 2.0
        );
        for k in 0..=4 {
            let x = self.x0 + (self.x1 - self.x0) * f64::from(k) / 4.0;
            let y = self.y0 + (self.y1 - self.y0) * f64::from(k) / 4.0;
            let _ = write!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="middle">{x:.2}</text>"#,
                self.px(x),
                H - M + 16.0
            );
            let _ = write!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{y:.3}</text>"#,
                M - 4.0,
                self.py(y) + 4.0
            );
        }
    }
    fn polyline(&self, svg: &mut String, pts: &[(f64, f64)], colour: &str, dash: bool) {
        if pts.len() < 2 {
            return;
        }
        let d: Vec<String> = pts
            .iter()
            .map(|&(x, y)| format!("{:.1},{:.1}", self.px(x), self.py(y)))
            .collect();
        let _ = write!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.6"{}/>"#,
            d.join(" "),
            if dash {
                r#" stroke-dasharray="5,4""#
            } else {
                ""
            }
        );
    }
}

fn header() -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>"#
    )
}

/// Writes `a_us.svg` and `residuals.svg` into `dir`.
pub fn write_fit_plots(
    dir: &Path,
    model: &LutModel<'_>,
    points: &[FitPoint],
    fit: &ModulusFit,
) -> std::io::Result<()> {
    if points.is_empty() {
        return Ok(());
    }
    let p = points[0].p_air_kpa;
    let u_max = points.iter().map(|q| q.u_s_mm).fold(0.0, f64::max);
    let a_max = points.iter().map(|q| q.a_mm).fold(0.0, f64::max);
    let ax = Axes {
        x0: 0.0,
        x1: u_max * 1.05,
        y0: 0.0,
        y1: a_max * 1.1,
    };
    let mut svg = header();
    ax.frame(
        &mut svg,
        &format!(
            "a–u_s at {p} kPa: E2 = {:.1} kPa [{:.1}, {:.1}]",
            fit.modulus_kpa, fit.ci95_kpa[0], fit.ci95_kpa[1]
        ),
        "u_s (mm)",
        "a (mm)",
    );
    let curve = |e: f64| -> Vec<(f64, f64)> {
        (0..=100)
            .filter_map(|k| {
                let u = u_max * f64::from(k) / 100.0;
                model.sample(e, p, u).ok().map(|s| (u, s.a_mm))
            })
            .collect()
    };
    let grid = model.moduli_kpa();
    for &e in grid
        .iter()
        .filter(|&&e| e > fit.modulus_kpa / 2.5 && e < fit.modulus_kpa * 2.5)
    {
        ax.polyline(&mut svg, &curve(e), "#9ab", true);
    }
    ax.polyline(&mut svg, &curve(fit.modulus_kpa), "#c22", false);
    for q in points {
        let _ = write!(
            svg,
            r##"<circle cx="{:.1}" cy="{:.1}" r="2" fill="#236"/>"##,
            ax.px(q.u_s_mm),
            ax.py(q.a_mm)
        );
    }
    svg.push_str("</svg>\n");
    std::fs::write(dir.join("a_us.svg"), svg)?;

    let res: Vec<(f64, f64)> = points
        .iter()
        .filter_map(|q| {
            model
                .sample(fit.modulus_kpa, q.p_air_kpa, q.u_s_mm)
                .ok()
                .map(|s| (q.u_s_mm, q.a_mm - s.a_mm))
        })
        .collect();
    let r_max = res.iter().map(|r| r.1.abs()).fold(1e-6, f64::max) * 1.1;
    let ax = Axes {
        x0: 0.0,
        x1: u_max * 1.05,
        y0: -r_max,
        y1: r_max,
    };
    let mut svg = header();
    ax.frame(
        &mut svg,
        &format!("residuals (RMS {:.4} mm)", fit.rms_residual_mm),
        "u_s (mm)",
        "a - model (mm)",
    );
    ax.polyline(&mut svg, &[(0.0, 0.0), (u_max * 1.05, 0.0)], "#888", true);
    for (u, r) in res {
        let _ = write!(
            svg,
            r##"<circle cx="{:.1}" cy="{:.1}" r="2" fill="#236"/>"##,
            ax.px(u),
            ax.py(r)
        );
    }
    svg.push_str("</svg>\n");
    std::fs::write(dir.join("residuals.svg"), svg)
}

/// Manometer pressure against time from a record's `samples.csv` (raw counts converted
/// with the device's nominal transfer function, as `samples.csv` stores them), as
/// `pressure.svg`. Returns the (t_s, p_kpa) trace plotted.
pub fn write_pressure_trace(dir: &Path) -> std::io::Result<Vec<(f64, f64)>> {
    let trace = pressure_trace(&dir.join("samples.csv"))?;
    if trace.len() < 2 {
        return Ok(trace);
    }
    let (t0, t1) = (trace[0].0, trace[trace.len() - 1].0);
    let p_min = trace.iter().map(|q| q.1).fold(f64::INFINITY, f64::min);
    let p_max = trace.iter().map(|q| q.1).fold(f64::NEG_INFINITY, f64::max);
    let pad = ((p_max - p_min) * 0.1).max(0.05);
    let ax = Axes {
        x0: t0,
        x1: t1.max(t0 + 1e-3),
        y0: p_min - pad,
        y1: p_max + pad,
    };
    let mut svg = header();
    ax.frame(
        &mut svg,
        "pressure trace",
        "t (s)",
        "p (kPa, gauge reading)",
    );
    ax.polyline(&mut svg, &decimate(&trace, 2000), "#236", false);
    svg.push_str("</svg>\n");
    std::fs::write(dir.join("pressure.svg"), svg)?;
    Ok(trace)
}

/// At most `n` points, evenly picked.
fn decimate(v: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let step = v.len().div_ceil(n.max(1)).max(1);
    v.iter().step_by(step).copied().collect()
}

/// (t_s from the first sample, manometer kPa) from `samples.csv`: columns `host_time_us`
/// and `manometer_counts`, p = (counts - 6554) x 9.5367e-4 kPa (README: manometer).
pub fn pressure_trace(samples_csv: &Path) -> std::io::Result<Vec<(f64, f64)>> {
    let text = std::fs::read_to_string(samples_csv)?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    let col = |name: &str| header.split(',').position(|c| c == name);
    let (Some(it), Some(ip)) = (col("host_time_us"), col("manometer_counts")) else {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "{}: header lacks host_time_us or manometer_counts",
                samples_csv.display()
            ),
        ));
    };
    let mut out = Vec::new();
    let mut t0 = None;
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let (Some(t), Some(c)) = (
            f.get(it).and_then(|s| s.parse::<f64>().ok()),
            f.get(ip).and_then(|s| s.parse::<f64>().ok()),
        ) else {
            continue;
        };
        let t0 = *t0.get_or_insert(t);
        out.push(((t - t0) * 1e-6, (c - 6554.0) * 9.5367e-4));
    }
    Ok(out)
}
