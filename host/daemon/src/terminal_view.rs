//! `tactile watch`: the live terminal dashboard (ratatui). [`DashboardState`] folds the
//! daemon's live-feed events into what is shown; [`render`] draws it: the pressure trace,
//! the a–u_s points so far against the fitted model curve, the modulus estimate with its
//! interval, stream losses and faults. Drawing is separate from the terminal so tests
//! render onto ratatui's `TestBackend`.

use std::collections::VecDeque;

use ratatui::Frame;
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph};

use crate::api::{Event, FitSummary, Job, StatusReport};

/// Seconds of pressure history shown.
pub const PRESSURE_WINDOW_S: f64 = 10.0;

/// Everything the dashboard shows.
#[derive(Debug, Clone, Default)]
pub struct DashboardState {
    /// (device time s, gauge kPa), oldest first, the last [`PRESSURE_WINDOW_S`].
    pub pressure: VecDeque<(f64, f64)>,
    /// a–u_s points of the current experiment: (u_s mm, a mm).
    pub points: Vec<(f64, f64)>,
    /// Model curve at the estimate: (u_s mm, a mm).
    pub model: Vec<(f64, f64)>,
    pub fit: Option<FitSummary>,
    pub fit_final: bool,
    pub connected: bool,
    pub port: Option<String>,
    pub job: Option<Job>,
    pub samples_received: u64,
    pub blocks_lost: u64,
    pub frame_errors: u64,
    /// Events this client missed because it fell behind.
    pub feed_lagged: u64,
    pub faults: Vec<String>,
    /// Last notable message (link gaps, emergency stops).
    pub message: String,
}

impl DashboardState {
    /// Starts from a status snapshot.
    pub fn from_status(s: &StatusReport) -> Self {
        Self {
            connected: s.connected,
            port: s.port.clone(),
            job: s.current_job.clone(),
            faults: s.faults.clone(),
            samples_received: s.link.map(|l| l.samples_received).unwrap_or(0),
            blocks_lost: s.link.map(|l| l.blocks_lost).unwrap_or(0),
            frame_errors: s.link.map(|l| l.frame_errors).unwrap_or(0),
            ..Self::default()
        }
    }

    /// Folds one live-feed event in.
    pub fn apply(&mut self, event: &Event) {
        match event {
            Event::Sample {
                device_time_us,
                pressure_kpa: Some(p),
                ..
            } => {
                let t = *device_time_us as f64 * 1e-6;
                if self.pressure.back().is_some_and(|(t0, _)| t < *t0) {
                    self.pressure.clear(); // the device rebooted
                }
                self.pressure.push_back((t, *p));
                while self
                    .pressure
                    .front()
                    .is_some_and(|(t0, _)| t - t0 > PRESSURE_WINDOW_S)
                {
                    self.pressure.pop_front();
                }
            }
            Event::Point { u_s_mm, a_mm, .. } => self.points.push((*u_s_mm, *a_mm)),
            Event::Fit {
                fit,
                model,
                final_fit,
            } => {
                self.fit = Some(*fit);
                self.fit_final = *final_fit;
                self.model = model.iter().map(|p| (p[0], p[1])).collect();
            }
            Event::Job { job } => {
                let new_experiment = job.state == crate::JobState::Running
                    && self.job.as_ref().is_none_or(|j| j.id != job.id);
                if new_experiment && job.kind == crate::api::JobKind::Experiment {
                    self.points.clear();
                    self.model.clear();
                    self.fit = None;
                    self.fit_final = false;
                }
                self.job = Some(job.clone());
            }
            Event::Link {
                connected,
                port,
                message,
                ..
            } => {
                self.connected = *connected;
                self.port = port.clone();
                self.message = message.clone();
            }
            Event::Fault { latched, .. } => self.faults = latched.clone(),
            Event::Stats {
                blocks_lost,
                frame_errors,
                samples_received,
                ..
            } => {
                self.blocks_lost = *blocks_lost;
                self.frame_errors = *frame_errors;
                self.samples_received = *samples_received;
            }
            Event::EmergencyStop { acknowledged } => {
                self.message = format!(
                    "EMERGENCY STOP {}",
                    if *acknowledged {
                        "acknowledged"
                    } else {
                        "not acknowledged"
                    }
                );
            }
            Event::Lagged { skipped } => self.feed_lagged += skipped,
            _ => {}
        }
    }
}

fn bounds(values: impl Iterator<Item = f64>, pad_min: f64) -> [f64; 2] {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return [0.0, 1.0];
    }
    if hi - lo < pad_min {
        let mid = 0.5 * (hi + lo);
        return [mid - 0.5 * pad_min, mid + 0.5 * pad_min];
    }
    [lo, hi]
}

fn axis_labels(b: [f64; 2], decimals: usize) -> Vec<Span<'static>> {
    vec![
        Span::raw(format!("{:.*}", decimals, b[0])),
        Span::raw(format!("{:.*}", decimals, 0.5 * (b[0] + b[1]))),
        Span::raw(format!("{:.*}", decimals, b[1])),
    ]
}

/// Draws the dashboard into `area`.
pub fn render(state: &DashboardState, frame: &mut Frame, area: Rect) {
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(3),
            Constraint::Min(8),
            Constraint::Length(5),
        ])
        .split(area);
    // header
    let device = if state.connected {
        Span::styled(
            format!("connected {}", state.port.as_deref().unwrap_or("")),
            Style::default().fg(Color::Green),
        )
    } else {
        Span::styled(
            "DEVICE NOT CONNECTED".to_string(),
            Style::default().fg(Color::Red).add_modifier(Modifier::BOLD),
        )
    };
    let job = match &state.job {
        Some(j) => format!(
            "job {} {:?} {:.0} %: {}",
            j.id,
            j.state,
            j.progress * 100.0,
            j.message
        ),
        None => "no job".to_string(),
    };
    frame.render_widget(
        Paragraph::new(Line::from(vec![device, Span::raw("   "), Span::raw(job)])).block(
            Block::default()
                .borders(Borders::ALL)
                .title("tactile watch"),
        ),
        rows[0],
    );
    let charts = Layout::default()
        .direction(Direction::Horizontal)
        .constraints([Constraint::Percentage(50), Constraint::Percentage(50)])
        .split(rows[1]);
    // pressure trace
    let trace: Vec<(f64, f64)> = state.pressure.iter().copied().collect();
    let tb = bounds(trace.iter().map(|p| p.0), 1.0);
    let pb = bounds(trace.iter().map(|p| p.1), 1.0);
    let now_kpa = trace
        .last()
        .map(|p| format!(" {:.2} kPa", p.1))
        .unwrap_or_default();
    let pressure = Chart::new(vec![
        Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Cyan))
            .data(&trace),
    ])
    .block(
        Block::default()
            .borders(Borders::ALL)
            .title(format!("pressure{now_kpa}")),
    )
    .x_axis(
        Axis::default()
            .title("t s")
            .bounds(tb)
            .labels(axis_labels(tb, 0)),
    )
    .y_axis(
        Axis::default()
            .title("kPa")
            .bounds(pb)
            .labels(axis_labels(pb, 1)),
    );
    frame.render_widget(pressure, charts[0]);
    // a–u_s
    let xb = bounds(
        state.points.iter().chain(state.model.iter()).map(|p| p.0),
        0.5,
    );
    let yb = bounds(
        state.points.iter().chain(state.model.iter()).map(|p| p.1),
        0.5,
    );
    let curve = Chart::new(vec![
        Dataset::default()
            .name("measured")
            .marker(Marker::Dot)
            .graph_type(GraphType::Scatter)
            .style(Style::default().fg(Color::Yellow))
            .data(&state.points),
        Dataset::default()
            .name("model")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Magenta))
            .data(&state.model),
    ])
    .block(
        Block::default()
            .borders(Borders::ALL)
            .title(format!("a–u_s ({} points)", state.points.len())),
    )
    .x_axis(
        Axis::default()
            .title("u_s mm")
            .bounds(xb)
            .labels(axis_labels(xb, 2)),
    )
    .y_axis(
        Axis::default()
            .title("a mm")
            .bounds(yb)
            .labels(axis_labels(yb, 2)),
    );
    frame.render_widget(curve, charts[1]);
    // footer
    let modulus = match &state.fit {
        Some(f) => format!(
            "E2 = {:.1} kPa (95 % CI {:.1} .. {:.1} kPa), {} points, RMS {:.4} mm{}",
            f.modulus_kpa,
            f.ci95_kpa[0],
            f.ci95_kpa[1],
            f.points,
            f.rms_residual_mm,
            if state.fit_final {
                ", final"
            } else {
                ", running"
            }
        ),
        None => "E2 = - (no fit yet)".to_string(),
    };
    let stream = format!(
        "stream: {} samples, {} blocks lost, {} frame errors, feed lagged {}",
        state.samples_received, state.blocks_lost, state.frame_errors, state.feed_lagged
    );
    let faults = if state.faults.is_empty() {
        Span::styled(
            "faults: none".to_string(),
            Style::default().fg(Color::Green),
        )
    } else {
        Span::styled(
            format!("faults: {}", state.faults.join(", ")),
            Style::default().fg(Color::Red).add_modifier(Modifier::BOLD),
        )
    };
    let lines = vec![
        Line::from(modulus),
        Line::from(stream),
        Line::from(vec![
            faults,
            Span::raw("   "),
            Span::raw(state.message.clone()),
        ]),
    ];
    frame.render_widget(
        Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title("q: quit")),
        rows[2],
    );
}

/// Renders `state` on an off-screen terminal of `width` x `height` cells and returns its
/// rows as text (tests, and a plain-text snapshot of the dashboard).
pub fn render_to_text(state: &DashboardState, width: u16, height: u16) -> Vec<String> {
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;
    let Ok(mut terminal) = Terminal::new(TestBackend::new(width, height));
    if terminal.draw(|f| render(state, f, f.area())).is_err() {
        return Vec::new();
    }
    let buffer = terminal.backend().buffer();
    (0..height)
        .map(|y| {
            (0..width)
                .map(|x| buffer[(x, y)].symbol().to_string())
                .collect::<String>()
        })
        .collect()
}
