//! `tactile radius FRAME... [--reference REF] [--json]`: contact radius per frame.
//!
//! FRAME may be a PGM/PNG image, a directory of them, or a raw MJPEG stream file
//! (`.mjpeg`, `.mjpg`, `.jpg`, `.jpeg`); or, with `--camera DEV --count N`, N live frames
//! from a V4L2 camera (the format negotiated as `tactile measure` does, or `--format`),
//! each with the driver's sequence number and timestamp. Without `--reference`, the first
//! frame is the no-contact reference (record the probe in the air first). Prints, per
//! frame, `radius_px`, `center_px`, `ellipse`, `quality`, `contact`, and the time per frame
//! on stderr.

use camera::{
    CameraError, Frame, FrameDirSource, FrameSource, GrayImage, MjpegFileSource, PixelFormat,
    V4l2Config, V4l2Source, read_gray_image,
};
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;
use vision::{ContactRadius, ContactRadiusConfig, ContactRadiusEstimator};

#[derive(Debug, Args)]
pub struct RadiusArgs {
    /// Frames: PGM/PNG files, directories of them, or raw MJPEG stream files.
    #[arg(required_unless_present = "camera", conflicts_with = "camera")]
    pub frames: Vec<PathBuf>,
    /// Live frames from this V4L2 camera (e.g. /dev/video0) instead of files.
    #[arg(long, value_name = "DEV")]
    pub camera: Option<PathBuf>,
    /// With --camera: how many frames to measure (after the reference frame when there is
    /// no --reference); default 30 unless --seconds is given.
    #[arg(long, requires = "camera")]
    pub count: Option<usize>,
    /// With --camera: measure frames for this many seconds (and at most --count frames).
    #[arg(long, requires = "camera")]
    pub seconds: Option<f64>,
    /// With --camera: the pixel format to ask for first (default: the one the device is
    /// set to); the driver may choose another, which is reported.
    #[arg(long, value_enum, requires = "camera")]
    pub format: Option<FormatArg>,
    /// No-contact reference frame (PGM/PNG/JPEG); default: the first frame.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// One JSON array on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Pixel formats that can be asked of a camera.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum FormatArg {
    Grey,
    Yuyv,
    Mjpeg,
}

impl From<FormatArg> for PixelFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Grey => PixelFormat::Gray8,
            FormatArg::Yuyv => PixelFormat::Yuyv,
            FormatArg::Mjpeg => PixelFormat::Mjpeg,
        }
    }
}

/// One frame to measure: its label, luma plane and, for a live camera, what the driver
/// said of it.
struct LabelledFrame {
    label: String,
    image: GrayImage,
    live: Option<LiveFrame>,
}

/// A live frame's pixel format, driver sequence number and timestamp (host clock).
struct LiveFrame {
    format: PixelFormat,
    sequence: u64,
    host_time_us: u64,
}

/// Where the frames come from: files read up front, or a camera read as it delivers.
enum FrameFeed {
    Files(std::vec::IntoIter<LabelledFrame>),
    Camera {
        source: Box<V4l2Source>,
        device: PathBuf,
        limit: CaptureLimit,
    },
}

/// When a live capture stops: after `frames` frames or at `until`, whichever comes first.
struct CaptureLimit {
    frames: usize,
    until: Option<Instant>,
    /// The duration, started at the first frame (the reference, if it is taken live).
    seconds: Option<f64>,
}

impl CaptureLimit {
    /// `count` frames (30 without `count` or `seconds`) plus the reference frame when it is
    /// taken from the camera, and at most `seconds`.
    fn new(count: Option<usize>, seconds: Option<f64>, live_reference: bool) -> Self {
        let frames = match (count, seconds) {
            (Some(n), _) => n,
            (None, Some(_)) => usize::MAX,
            (None, None) => 30,
        };
        Self {
            frames: frames.saturating_add(usize::from(live_reference)),
            until: None,
            seconds: seconds.filter(|s| s.is_finite() && *s >= 0.0),
        }
    }

    /// Counts one frame; false once the capture is over.
    fn take(&mut self) -> bool {
        let now = Instant::now();
        let until = *self.until.get_or_insert_with(|| {
            now + std::time::Duration::from_secs_f64(self.seconds.unwrap_or(1e9))
        });
        if self.frames == 0 || now > until {
            return false;
        }
        self.frames -= 1;
        true
    }
}

impl FrameFeed {
    /// The camera at `device`, `count` frames; the negotiated format is reported on stderr.
    fn camera(
        device: &Path,
        format: Option<FormatArg>,
        limit: CaptureLimit,
    ) -> Result<FrameFeed, CameraError> {
        let source = V4l2Source::open(&V4l2Config {
            device: Some(device.to_path_buf()),
            preferred: format.map(PixelFormat::from),
            ..V4l2Config::default()
        })?;
        let (negotiated, width, height) = source.format();
        let asked = match format.map(PixelFormat::from) {
            Some(asked) if asked != negotiated => {
                format!(" (asked for {asked:?}; the driver chose another)")
            }
            _ => String::new(),
        };
        eprintln!(
            "camera {}: {negotiated:?} {width}x{height}{asked}",
            device.display()
        );
        Ok(FrameFeed::Camera {
            source: Box::new(source),
            device: device.to_path_buf(),
            limit,
        })
    }

    fn next(&mut self) -> Result<Option<LabelledFrame>, CameraError> {
        match self {
            FrameFeed::Files(frames) => Ok(frames.next()),
            FrameFeed::Camera {
                source,
                device,
                limit,
            } => {
                let Some(frame) = source.next_frame()? else {
                    return Ok(None);
                };
                if !limit.take() {
                    return Ok(None);
                }
                Ok(Some(LabelledFrame {
                    label: format!("{}#{}", device.display(), frame.sequence),
                    image: frame.luma()?,
                    live: Some(LiveFrame {
                        format: frame.format,
                        sequence: frame.sequence,
                        host_time_us: frame.host_time_us,
                    }),
                }))
            }
        }
    }
}

fn read_reference(p: &Path) -> Result<GrayImage, CameraError> {
    if is_mjpeg(p) {
        let mut s = MjpegFileSource::open(p)?;
        match s.next_frame()? {
            Some(f) => Ok(f.luma()?),
            None => Err(CameraError::BadFile {
                path: p.to_path_buf(),
                message: "no frame".to_string(),
            }),
        }
    } else {
        read_gray_image(p)
    }
}

fn is_mjpeg(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        ["mjpeg", "mjpg", "jpg", "jpeg"].contains(&e.to_ascii_lowercase().as_str())
    })
}

/// Every frame named on the command line, in order, with a label.
fn load_frames(paths: &[PathBuf]) -> Result<Vec<LabelledFrame>, CameraError> {
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut src = FrameDirSource::open(path)?;
            collect(&mut src, &path.display().to_string(), &mut out)?;
        } else if is_mjpeg(path) {
            let mut src = MjpegFileSource::open(path)?;
            collect(&mut src, &path.display().to_string(), &mut out)?;
        } else {
            out.push(LabelledFrame {
                label: path.display().to_string(),
                image: read_gray_image(path)?,
                live: None,
            });
        }
    }
    Ok(out)
}

fn collect(
    src: &mut dyn FrameSource,
    label: &str,
    out: &mut Vec<LabelledFrame>,
) -> Result<(), CameraError> {
    while let Some(frame) = src.next_frame()? {
        let frame: Frame = frame;
        out.push(LabelledFrame {
            label: format!("{label}#{}", frame.sequence),
            image: frame.luma()?,
            live: None,
        });
    }
    Ok(())
}

fn json_row(frame: &LabelledFrame, m: &ContactRadius) -> serde_json::Value {
    let d = m.disc.as_ref();
    let mut row = serde_json::json!({
        "frame": frame.label,
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
    });
    if let (Some(live), Some(obj)) = (&frame.live, row.as_object_mut()) {
        obj.insert("pixel_format".into(), serde_json::json!(live.format));
        obj.insert("sequence".into(), serde_json::json!(live.sequence));
        obj.insert("host_time_us".into(), serde_json::json!(live.host_time_us));
    }
    row
}

pub fn run(args: RadiusArgs) -> ExitCode {
    let fail = |what: &str, e: &dyn std::fmt::Display| {
        eprintln!("error: {what}{e}");
        ExitCode::from(2)
    };
    let reference = match args.reference.as_deref().map(read_reference).transpose() {
        Ok(r) => r,
        Err(e) => return fail("reference: ", &e),
    };
    let feed = match &args.camera {
        Some(device) => FrameFeed::camera(
            device,
            args.format,
            CaptureLimit::new(args.count, args.seconds, reference.is_none()),
        ),
        None => load_frames(&args.frames).map(|f| FrameFeed::Files(f.into_iter())),
    };
    let mut feed = match feed {
        Ok(f) => f,
        Err(e) => return fail("", &e),
    };
    // Without --reference the first frame is the reference: a file is also measured (it
    // reads "no contact"), a live frame is not counted.
    let mut first_file = None;
    let reference = match reference {
        Some(r) => r,
        None => match feed.next() {
            Ok(Some(first)) => {
                eprintln!(
                    "note: no --reference; using the first frame ({}) as the no-contact reference",
                    first.label
                );
                let image = first.image.clone();
                if matches!(feed, FrameFeed::Files(_)) {
                    first_file = Some(first);
                }
                image
            }
            Ok(None) => return fail("", &"no frames"),
            Err(e) => return fail("", &e),
        },
    };
    let estimator = match ContactRadiusEstimator::new(reference, ContactRadiusConfig::default()) {
        Ok(e) => e,
        Err(e) => return fail("reference: ", &e),
    };
    let mut rows = Vec::new();
    let (mut measured, mut total_s) = (0usize, 0.0);
    if !args.json {
        println!(
            "{:<40} {:>7} {:>10} {:>19} {:>24} {:>7}",
            "frame", "contact", "radius_px", "center_px", "ellipse a/b/angle", "quality"
        );
    }
    loop {
        let frame = match first_file
            .take()
            .map(Ok)
            .or_else(|| feed.next().transpose())
        {
            Some(Ok(f)) => f,
            Some(Err(e)) => return fail("", &e),
            None => break,
        };
        let label = &frame.label;
        let t0 = Instant::now();
        let m = match estimator.measure(&frame.image) {
            Ok(m) => m,
            Err(e) => return fail(&format!("{label}: "), &e),
        };
        total_s += t0.elapsed().as_secs_f64();
        measured += 1;
        if args.json {
            rows.push(json_row(&frame, &m));
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
    if measured > 0 {
        eprintln!(
            "{measured} frames, contact radius {:.3} ms per frame",
            total_s * 1e3 / measured as f64
        );
    }
    ExitCode::SUCCESS
}
