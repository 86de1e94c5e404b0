//! `tactile radius FRAME... [--reference REF] [--json]`: contact radius per frame.
//!
//! FRAME may be a PGM/PNG image, a directory of them, or a raw MJPEG stream file
//! (`.mjpeg`, `.mjpg`, `.jpg`, `.jpeg`). Without `--reference`, the first frame is the
//! no-contact reference (record the probe in the air first). Prints, per frame,
//! `radius_px`, `center_px`, `ellipse`, `quality`, `contact`, and the time per frame on
//! stderr.

use camera::{
    CameraError, Frame, FrameDirSource, FrameSource, GrayImage, MjpegFileSource, read_gray_image,
};
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;
use vision::{ContactRadius, ContactRadiusConfig, ContactRadiusEstimator};

#[derive(Debug, Args)]
pub struct RadiusArgs {
    /// Frames: PGM/PNG files, directories of them, or raw MJPEG stream files.
    #[arg(required = true)]
    pub frames: Vec<PathBuf>,
    /// No-contact reference frame (PGM/PNG/JPEG); default: the first frame.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// One JSON array on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn is_mjpeg(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        ["mjpeg", "mjpg", "jpg", "jpeg"].contains(&e.to_ascii_lowercase().as_str())
    })
}

/// Every frame named on the command line, in order, with a label.
fn load_frames(paths: &[PathBuf]) -> Result<Vec<(String, GrayImage)>, CameraError> {
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut src = FrameDirSource::open(path)?;
            collect(&mut src, &path.display().to_string(), &mut out)?;
        } else if is_mjpeg(path) {
            let mut src = MjpegFileSource::open(path)?;
            collect(&mut src, &path.display().to_string(), &mut out)?;
        } else {
            out.push((path.display().to_string(), read_gray_image(path)?));
        }
    }
    Ok(out)
}

fn collect(
    src: &mut dyn FrameSource,
    label: &str,
    out: &mut Vec<(String, GrayImage)>,
) -> Result<(), CameraError> {
    while let Some(frame) = src.next_frame()? {
        let frame: Frame = frame;
        out.push((format!("{label}#{}", frame.sequence), frame.luma()?));
    }
    Ok(())
}

fn json_row(label: &str, m: &ContactRadius) -> serde_json::Value {
    let d = m.disc.as_ref();
    serde_json::json!({
        "frame": label,
        "contact": m.contact,
        "radius_px": d.map(|d| d.radius_px),
        "radius_sigma_px": d.map(|d| d.radius_sigma_px),
        "center_px": d.map(|d| d.center_px),
        "ellipse": d.map(|d| serde_json::json!({
            "semi_major_px": d.ellipse.semi_major_px,
            "semi_minor_px": d.ellipse.semi_minor_px,
            "angle_deg": d.ellipse.angle_rad.to_degrees(),
            "eccentricity": d.eccentricity,
            "tilted": d.tilted,
        })),
        "quality": m.quality,
        "contrast": d.map(|d| d.contrast),
        "edge_snr": d.map(|d| d.edge_snr),
    })
}

pub fn run(args: RadiusArgs) -> ExitCode {
    let reference = match &args.reference {
        Some(p) if is_mjpeg(p) => {
            MjpegFileSource::open(p).and_then(|mut s| match s.next_frame()? {
                Some(f) => Ok(f.luma()?),
                None => Err(CameraError::BadFile {
                    path: p.clone(),
                    message: "no frame".to_string(),
                }),
            })
        }
        Some(p) => read_gray_image(p),
        None => Err(CameraError::BadFile {
            path: PathBuf::new(),
            message: String::new(),
        }),
    };
    let frames = match load_frames(&args.frames) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let reference = match (args.reference.is_some(), reference) {
        (true, Ok(r)) => r,
        (true, Err(e)) => {
            eprintln!("error: reference: {e}");
            return ExitCode::from(2);
        }
        (false, _) => match frames.first() {
            Some((label, img)) => {
                eprintln!(
                    "note: no --reference; using the first frame ({label}) as the no-contact reference"
                );
                img.clone()
            }
            None => {
                eprintln!("error: no frames");
                return ExitCode::from(2);
            }
        },
    };
    let estimator = match ContactRadiusEstimator::new(reference, ContactRadiusConfig::default()) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: reference: {e}");
            return ExitCode::from(2);
        }
    };
    let mut rows = Vec::new();
    let mut total_s = 0.0;
    if !args.json {
        println!(
            "{:<40} {:>7} {:>10} {:>19} {:>24} {:>7}",
            "frame", "contact", "radius_px", "center_px", "ellipse a/b/angle", "quality"
        );
    }
    for (label, img) in &frames {
        let t0 = Instant::now();
        let m = match estimator.measure(img) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("error: {label}: {e}");
                return ExitCode::from(2);
            }
        };
        total_s += t0.elapsed().as_secs_f64();
        if args.json {
            rows.push(json_row(label, &m));
        } else {
            match &m.disc {
                Some(d) => println!(
                    "{:<40} {:>7} {:>10.3} {:>9.2},{:>9.2} {:>8.2}/{:>6.2}/{:>6.1}° {:>7.3}",
                    label,
                    m.contact,
                    d.radius_px,
                    d.center_px[0],
                    d.center_px[1],
                    d.ellipse.semi_major_px,
                    d.ellipse.semi_minor_px,
                    d.ellipse.angle_rad.to_degrees(),
                    m.quality
                ),
                None => println!("{:<40} {:>7}", label, m.contact),
            }
        }
    }
    if args.json {
        println!("{}", serde_json::Value::Array(rows));
    }
    if !frames.is_empty() {
        eprintln!(
            "{} frames, contact radius {:.3} ms per frame",
            frames.len(),
            total_s * 1e3 / frames.len() as f64
        );
    }
    ExitCode::SUCCESS
}
