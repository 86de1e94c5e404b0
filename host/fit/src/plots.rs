//! Plots of a record, each as SVG and PNG (plotters with its SVG and bitmap backends and an
//! embedded font, DejaVu Sans Mono in `fit/assets/`, so no system font or graphics
//! library is needed; the PNG is encoded with the `png` crate):
//!
//! - `a_us`: measured a–u_s points, the fitted curve and the table's curves at the grid
//!   moduli around the estimate;
//! - `residuals`: a - model against u_s;
//! - `pressure`: the manometer trace of `samples.csv` against time.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::{FitPoint, LutModel, ModulusFit};

const W: u32 = 800;
const H: u32 = 520;
const FONT: &str = "sans-serif";
/// Largest `samples.csv` plotted (a minute at 2 kHz is ~6 MB; the curve files' own limit).
const MAX_SAMPLES_CSV_BYTES: u64 = 64 << 20;

/// Registers the embedded font once (plotters looks fonts up by family name).
fn font_ready() -> bool {
    static READY: OnceLock<bool> = OnceLock::new();
    *READY.get_or_init(|| {
        plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            include_bytes!("../assets/DejaVuSansMono.ttf"),
        )
        .is_ok()
    })
}

/// A polyline: points, colour, stroke width (px).
type Line = (Vec<(f64, f64)>, RGBColor, u32);

/// One x–y chart.
#[derive(Debug, Clone, Default)]
struct XyPlot {
    title: String,
    x_label: String,
    y_label: String,
    x: (f64, f64),
    y: (f64, f64),
    /// Lines: points, colour, width.
    lines: Vec<Line>,
    /// Markers.
    points: Vec<(f64, f64)>,
}

/// Why a plot was not written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("the embedded plot font could not be loaded")]
    Font,
    #[error("{path}: drawing failed: {message}")]
    Draw { path: PathBuf, message: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: PNG encoding failed: {message}")]
    Encode { path: PathBuf, message: String },
    #[error("{path}: header lacks host_time_us or manometer_counts")]
    SamplesHeader { path: PathBuf },
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, plot: &XyPlot) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(root)
        .caption(&plot.title, (FONT, 18))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(70)
        .build_cartesian_2d(plot.x.0..plot.x.1, plot.y.0..plot.y.1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label.as_str())
        .y_desc(plot.y_label.as_str())
        .label_style((FONT, 13))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(e)?;
    for (pts, colour, width) in &plot.lines {
        chart
            .draw_series(LineSeries::new(
                pts.iter().copied(),
                colour.stroke_width(*width),
            ))
            .map_err(e)?;
    }
    let marker = RGBColor(34, 51, 102);
    chart
        .draw_series(
            plot.points
                .iter()
                .map(|&p| Circle::new(p, 2, marker.filled())),
        )
        .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

/// Writes `<dir>/<name>.svg` and `<dir>/<name>.png`.
fn render(dir: &Path, name: &str, plot: &XyPlot) -> Result<(), PlotError> {
    if !font_ready() {
        return Err(PlotError::Font);
    }
    let svg_path = dir.join(format!("{name}.svg"));
    {
        let root = SVGBackend::new(&svg_path, (W, H)).into_drawing_area();
        draw(&root, plot).map_err(|message| PlotError::Draw {
            path: svg_path.clone(),
            message,
        })?;
    }
    let png_path = dir.join(format!("{name}.png"));
    let mut rgb = vec![0u8; (W * H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (W, H)).into_drawing_area();
        draw(&root, plot).map_err(|message| PlotError::Draw {
            path: png_path.clone(),
            message,
        })?;
    }
    write_png_rgb(&png_path, W, H, &rgb)
}

fn write_png_rgb(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), PlotError> {
    let file = std::fs::File::create(path).map_err(|source| PlotError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let encode = |e: png::EncodingError| PlotError::Encode {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(encode)?;
    writer.write_image_data(rgb).map_err(encode)?;
    writer.finish().map_err(encode)
}

/// Writes `a_us.{svg,png}` and `residuals.{svg,png}` into `dir`.
pub fn write_fit_plots(
    dir: &Path,
    model: &LutModel<'_>,
    points: &[FitPoint],
    fit: &ModulusFit,
) -> Result<(), PlotError> {
    if points.is_empty() {
        return Ok(());
    }
    let p = points[0].p_air_kpa;
    let u_max = points.iter().map(|q| q.u_s_mm).fold(0.0, f64::max);
    let a_max = points.iter().map(|q| q.a_mm).fold(0.0, f64::max);
    let curve = |e: f64| -> Vec<(f64, f64)> {
        (0..=100)
            .filter_map(|k| {
                let u = u_max * f64::from(k) / 100.0;
                model.sample(e, p, u).ok().map(|s| (u, s.a_mm))
            })
            .collect()
    };
    let mut lines: Vec<Line> = model
        .moduli_kpa()
        .iter()
        .filter(|&&e| e > fit.modulus_kpa / 2.5 && e < fit.modulus_kpa * 2.5)
        .map(|&e| (curve(e), RGBColor(150, 170, 190), 1))
        .collect();
    lines.push((curve(fit.modulus_kpa), RGBColor(200, 30, 30), 2));
    render(
        dir,
        "a_us",
        &XyPlot {
            title: format!(
                "a-u_s at {p} kPa: E2 = {:.1} kPa [{:.1}, {:.1}] (grey: table grid)",
                fit.modulus_kpa, fit.ci95_kpa[0], fit.ci95_kpa[1]
            ),
            x_label: "u_s (mm)".into(),
            y_label: "a (mm)".into(),
            x: (0.0, u_max * 1.05),
            y: (0.0, a_max * 1.1),
            lines,
            points: points.iter().map(|q| (q.u_s_mm, q.a_mm)).collect(),
        },
    )?;
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
    render(
        dir,
        "residuals",
        &XyPlot {
            title: format!("residuals (RMS {:.4} mm)", fit.rms_residual_mm),
            x_label: "u_s (mm)".into(),
            y_label: "a - model (mm)".into(),
            x: (0.0, u_max * 1.05),
            y: (-r_max, r_max),
            lines: vec![(
                vec![(0.0, 0.0), (u_max * 1.05, 0.0)],
                RGBColor(136, 136, 136),
                1,
            )],
            points: res,
        },
    )
}

/// Manometer pressure against time from a record's `samples.csv` (raw counts converted
/// with the device's nominal transfer function, as `samples.csv` stores them), as
/// `pressure.{svg,png}`. Returns the (t_s, p_kpa) trace plotted.
pub fn write_pressure_trace(dir: &Path) -> Result<Vec<(f64, f64)>, PlotError> {
    let trace = pressure_trace(&dir.join("samples.csv"))?;
    if trace.len() < 2 {
        return Ok(trace);
    }
    let (t0, t1) = (trace[0].0, trace[trace.len() - 1].0);
    let p_min = trace.iter().map(|q| q.1).fold(f64::INFINITY, f64::min);
    let p_max = trace.iter().map(|q| q.1).fold(f64::NEG_INFINITY, f64::max);
    let pad = ((p_max - p_min) * 0.1).max(0.05);
    render(
        dir,
        "pressure",
        &XyPlot {
            title: "pressure trace".into(),
            x_label: "t (s)".into(),
            y_label: "p (kPa, manometer reading)".into(),
            x: (t0, t1.max(t0 + 1e-3)),
            y: (p_min - pad, p_max + pad),
            lines: vec![(decimate(&trace, 4000), RGBColor(34, 51, 102), 1)],
            points: Vec::new(),
        },
    )?;
    Ok(trace)
}

/// At most `n` points, evenly picked.
fn decimate(v: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let step = v.len().div_ceil(n.max(1)).max(1);
    v.iter().step_by(step).copied().collect()
}

/// (t_s from the first sample, manometer kPa) from `samples.csv`: columns `host_time_us`
/// and `manometer_counts`, p = (counts - 6554) x 9.5367e-4 kPa (controller::device_constants).
pub fn pressure_trace(samples_csv: &Path) -> Result<Vec<(f64, f64)>, PlotError> {
    let bytes = fem_core::input_file::read_limited(samples_csv, MAX_SAMPLES_CSV_BYTES, "samples")
        .map_err(|source| PlotError::Io {
        path: samples_csv.to_path_buf(),
        source,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    let col = |name: &str| header.split(',').position(|c| c == name);
    let (Some(it), Some(ip)) = (col("host_time_us"), col("manometer_counts")) else {
        return Err(PlotError::SamplesHeader {
            path: samples_csv.to_path_buf(),
        });
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pressure_trace_writes_svg_and_a_decodable_png() {
        let dir = std::env::temp_dir().join(format!("tactile-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // 6 kPa = 6554 + 6 / 9.5367e-4 counts
        let mut csv = String::from("host_time_us,manometer_counts\n");
        for k in 0..500 {
            let counts = 6554.0 + (6.0 + 0.1 * (f64::from(k) * 0.05).sin()) / 9.5367e-4;
            csv.push_str(&format!("{},{}\n", 1000 * k, counts.round()));
        }
        std::fs::write(dir.join("samples.csv"), csv).unwrap();
        let trace = write_pressure_trace(&dir).unwrap();
        assert_eq!(trace.len(), 500);
        assert!((trace[0].1 - 6.0).abs() < 1e-3, "{:?}", trace[0]);
        let svg = std::fs::read_to_string(dir.join("pressure.svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("pressure trace"));
        let decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(dir.join("pressure.png")).unwrap(),
        ));
        let reader = decoder.read_info().unwrap();
        assert_eq!((reader.info().width, reader.info().height), (W, H));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
