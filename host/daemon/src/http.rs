//! The HTTP API (axum): routes, the security layer and the live feed (Server-Sent Events).
//!
//! Security, in the order it is checked for every request:
//! 1. `Host` must name the daemon's own address (`127.0.0.1:PORT`, `localhost:PORT`,
//!    `[::1]:PORT` on loopback, or the explicit listen address) and `Origin`, when present,
//!    must be `http://` + one of those: a web page in the user's browser (DNS rebinding, a
//!    cross-site form) gets 403;
//! 2. `Authorization: Bearer <token>` must carry the token from the daemon's 0600 token
//!    file, or the request carries the web dashboard's session cookie, with which a change
//!    (POST, DELETE) also needs an `Origin` header and the CSRF header
//!    ([`super::dashboard::session`]; 403 otherwise); without either: 401, except for the
//!    dashboard's public paths (`/`, `/assets/...`);
//! 3. bodies are limited to [`MAX_BODY_BYTES`] (413), must be JSON (415), parse (400) and
//!    validate (422, naming each bad field); nothing changes unless all of that passed.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::rejection::JsonRejection;
use axum::extract::{DefaultBodyLimit, FromRequest, Path, Request, State};
use axum::http::{HeaderMap, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use futures_util::Stream;
use tokio::sync::{broadcast, oneshot};

use super::api::{
    ApiError, Event, ExperimentRequest, FieldError, JobKind, MAX_BODY_BYTES, PressureRequest,
    PressureSetting, StopReport, VentRequest,
};
use super::dashboard::session::DashboardAuth;
use super::guarded_transport::StopKind;
use super::listener::{BODY_READ_TIMEOUT, Connection};
use super::shared::{CancelError, Command, Shared};
use super::token::tokens_equal;

/// Who may talk to the daemon.
#[derive(Debug)]
pub struct Access {
    pub token: String,
    /// Acceptable `Host` header values (lower case).
    pub hosts: Vec<String>,
    /// The address the daemon listens on.
    pub addr: std::net::SocketAddr,
    /// The web dashboard's login tokens, session cookie and CSRF token.
    pub dashboard: DashboardAuth,
}

impl Access {
    /// The host names a daemon listening on `addr` answers to.
    pub fn for_addr(addr: std::net::SocketAddr, token: String) -> Self {
        let port = addr.port();
        let mut hosts = vec![addr.to_string().to_ascii_lowercase()];
        if addr.ip().is_loopback() {
            for h in ["127.0.0.1", "localhost", "[::1]"] {
                hosts.push(format!("{h}:{port}"));
            }
        }
        hosts.dedup();
        let dashboard = DashboardAuth::new(&token, port);
        Self {
            token,
            hosts,
            addr,
            dashboard,
        }
    }
}

/// How a request was authorised (a request extension set by the guard).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AuthorizedBy {
    Bearer,
    /// The dashboard's session cookie (with the CSRF rules for changes).
    Cookie,
    /// Nothing: only the dashboard's public paths are reached this way.
    Public,
}

/// Paths served without credentials (after the Host and Origin checks): the page (which
/// itself shows the dashboard only to a logged-in browser) and its script and style.
fn is_public(path: &str) -> bool {
    path == "/" || path.starts_with("/assets/")
}

#[derive(Debug, Clone)]
pub struct App {
    pub shared: Arc<Shared>,
    pub access: Arc<Access>,
}

/// A JSON error answer.
pub fn error(status: StatusCode, message: impl Into<String>) -> Response {
    (
        status,
        Json(ApiError {
            error: message.into(),
            fields: Vec::new(),
        }),
    )
        .into_response()
}

fn field_errors(fields: Vec<FieldError>) -> Response {
    (
        StatusCode::UNPROCESSABLE_ENTITY,
        Json(ApiError {
            error: "invalid request body".into(),
            fields,
        }),
    )
        .into_response()
}

/// `Json<T>` whose rejections are JSON errors with the right status.
#[derive(Debug)]
pub struct Body<T>(pub T);

impl<S, T> FromRequest<S> for Body<T>
where
    Json<T>: FromRequest<S, Rejection = JsonRejection>,
    S: Send + Sync,
{
    type Rejection = Response;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let read = tokio::time::timeout(BODY_READ_TIMEOUT, Json::<T>::from_request(req, state));
        match read.await {
            Err(_) => Err(error(
                StatusCode::REQUEST_TIMEOUT,
                format!(
                    "request body not received within {} s",
                    BODY_READ_TIMEOUT.as_secs()
                ),
            )),
            Ok(Ok(Json(v))) => Ok(Body(v)),
            Ok(Err(rejection)) => {
                let status = rejection.status();
                let text = rejection.body_text();
                Err(error(status, format!("request body: {text}")))
            }
        }
    }
}

async fn guard(State(app): State<App>, mut req: Request, next: Next) -> Response {
    let headers = req.headers();
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .map(str::to_ascii_lowercase);
    match host {
        Some(h) if app.access.hosts.contains(&h) => {}
        Some(h) => return error(StatusCode::FORBIDDEN, format!("foreign Host header: {h}")),
        None => return error(StatusCode::FORBIDDEN, "missing Host header"),
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let ok = origin.to_str().ok().is_some_and(|o| {
            let o = o.to_ascii_lowercase();
            app.access.hosts.iter().any(|h| o == format!("http://{h}"))
        });
        if !ok {
            return error(StatusCode::FORBIDDEN, "foreign Origin header");
        }
    }
    let by = if authorized(headers, &app.access.token) {
        AuthorizedBy::Bearer
    } else if app.access.dashboard.has_session(headers)
        && !app.access.dashboard.fetch_site_ok(headers)
    {
        // A browser says where a request comes from (Sec-Fetch-Site): the cookie counts
        // only for the dashboard's own pages and for what the user opened directly, not
        // for an image, script or feed another site embeds, nor for a link from another
        // site (browsers count another port of 127.0.0.1 as the same site and send the
        // cookie there too): such a request is treated as one without the cookie.
        if !is_public(req.uri().path()) {
            return error(
                StatusCode::FORBIDDEN,
                "the dashboard's session cookie is accepted only from the dashboard's own pages",
            );
        }
        AuthorizedBy::Public
    } else if app.access.dashboard.has_session(headers) {
        let safe = matches!(*req.method(), Method::GET | Method::HEAD);
        // A change made with the cookie needs the page's own Origin (checked above) and the
        // CSRF token the page was given: the cookie alone never authorises it.
        if !safe
            && (headers.get(header::ORIGIN).is_none() || !app.access.dashboard.csrf_ok(headers))
        {
            return error(
                StatusCode::FORBIDDEN,
                "a change made with the dashboard's session cookie needs the page's Origin and X-Tactile-CSRF headers",
            );
        }
        AuthorizedBy::Cookie
    } else if is_public(req.uri().path()) {
        AuthorizedBy::Public
    } else {
        return (
            StatusCode::UNAUTHORIZED,
            [(header::WWW_AUTHENTICATE, "Bearer")],
            Json(ApiError {
                error: "missing or wrong bearer token (see the daemon's token file)".into(),
                fields: Vec::new(),
            }),
        )
            .into_response();
    };
    if by != AuthorizedBy::Public
        && let Some(conn) = req.extensions().get::<Arc<Connection>>()
    {
        conn.authenticate();
    }
    req.extensions_mut().insert(by);
    next.run(req).await
}

/// `Authorization: Bearer <token>`; the scheme name is case-insensitive (RFC 9110, 11.1).
fn authorized(headers: &HeaderMap, token: &str) -> bool {
    headers
        .get(header::AUTHORIZATION)
        .and_then(|h| h.to_str().ok())
        .and_then(|h| h.trim_start().split_once(' '))
        .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
        .is_some_and(|(_, t)| tokens_equal(t.trim(), token))
}

/// The router with every route and the security layer.
pub fn router(app: App) -> Router {
    Router::new()
        .route("/v1/status", get(status))
        .route("/v1/stop", post(emergency_stop))
        .route("/v1/pressure", post(pressure))
        .route("/v1/vent", post(vent))
        .route("/v1/clear-fault", post(clear_fault))
        .route("/v1/experiments", get(list_jobs).post(submit_experiment))
        .route("/v1/experiments/{id}", get(get_job).delete(cancel_job))
        .route("/v1/calibrations", get(list_calibrations).post(calibrate))
        .route("/v1/calibrations/{name}", get(get_calibration))
        .route("/v1/records", get(list_records))
        .route("/v1/records/{name}", get(list_record_files))
        .route("/v1/records/{name}/{file}", get(get_record_file))
        .route("/v1/records/{name}/probe/", get(list_probe_files))
        .route("/v1/records/{name}/probe/{file}", get(get_probe_file))
        .route("/v1/events", get(events))
        .route("/v1/live", get(super::dashboard::live))
        .route("/v1/login-link", post(login_link))
        .route("/", get(super::dashboard::page))
        .route("/assets/{file}", get(super::dashboard::asset))
        .fallback(|| async { error(StatusCode::NOT_FOUND, "no such endpoint") })
        .layer(axum::middleware::from_fn_with_state(app.clone(), guard))
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .with_state(app)
}

/// `POST /v1/login-link`: a new one-time dashboard login address, for bearer-token
/// holders only (`tactile dashboard`).
async fn login_link(
    State(app): State<App>,
    axum::Extension(by): axum::Extension<AuthorizedBy>,
) -> Response {
    if by != AuthorizedBy::Bearer {
        return error(
            StatusCode::FORBIDDEN,
            "a login address is given only for the bearer token",
        );
    }
    super::dashboard::login_link(State(app)).await
}

async fn status(State(app): State<App>) -> Response {
    Json(app.shared.status()).into_response()
}

async fn send_command(
    app: &App,
    make: impl FnOnce(super::shared::CommandReply) -> Command,
) -> Response {
    if !app.shared.status().connected {
        return error(StatusCode::SERVICE_UNAVAILABLE, "device not connected");
    }
    if app.shared.status().current_job.is_some() {
        return error(
            StatusCode::CONFLICT,
            "an experiment is running: cancel it first (emergency stop always works: POST /v1/stop)",
        );
    }
    let (tx, rx) = oneshot::channel();
    if app.shared.commands.send(make(tx)).is_err() {
        return error(StatusCode::SERVICE_UNAVAILABLE, "device thread stopped");
    }
    match tokio::time::timeout(Duration::from_secs(5), rx).await {
        Ok(Ok(Ok(()))) => Json(serde_json::json!({ "ok": true })).into_response(),
        Ok(Ok(Err(e))) => error(StatusCode::BAD_GATEWAY, format!("device: {e}")),
        _ => error(
            StatusCode::GATEWAY_TIMEOUT,
            "the device thread did not answer in 5 s",
        ),
    }
}

async fn pressure(State(app): State<App>, Body(req): Body<PressureRequest>) -> Response {
    if !(req.kpa.is_finite() && (0.0..=15.0).contains(&req.kpa)) {
        return field_errors(vec![FieldError {
            field: "kpa".into(),
            reason: format!("{} is outside 0..=15 kPa", req.kpa),
        }]);
    }
    send_command(&app, |reply| Command::SetPressure {
        kpa: req.kpa,
        reply,
    })
    .await
}

async fn vent(State(app): State<App>, Body(req): Body<VentRequest>) -> Response {
    send_command(&app, |reply| Command::Vent {
        open: req.open,
        reply,
    })
    .await
}

async fn clear_fault(State(app): State<App>) -> Response {
    send_command(&app, |reply| Command::ClearFault { reply }).await
}

async fn emergency_stop(State(app): State<App>) -> Response {
    let shared = &app.shared;
    if !shared.status().connected {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "device not connected (a controller that lost power is vented and stopped)",
        );
    }
    let started = Instant::now();
    shared.switch.request(StopKind::Emergency);
    shared
        .emergency_stops
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let running = shared.cancel_all("cancelled by emergency stop");
    if let Some(id) = running {
        shared.lock().cancel = Some(id);
    }
    let outcome = loop {
        let o = shared.switch.outcome();
        if o.acked_after.is_some() || started.elapsed() > Duration::from_secs(2) {
            break o;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    };
    let report = StopReport {
        sent: outcome.sent_after.is_some(),
        acknowledged: outcome.acked_after.is_some(),
        sent_after_ms: outcome.sent_after.map(|d| d.as_secs_f64() * 1e3),
        acknowledged_after_ms: outcome.acked_after.map(|d| d.as_secs_f64() * 1e3),
        cancelled_job: running,
    };
    let _ = shared.events.send(Event::EmergencyStop {
        acknowledged: report.acknowledged,
    });
    let status = if report.sent {
        StatusCode::OK
    } else {
        StatusCode::GATEWAY_TIMEOUT
    };
    (status, Json(report)).into_response()
}

async fn submit_experiment(State(app): State<App>, Body(req): Body<ExperimentRequest>) -> Response {
    if let Err(fields) = req.validate() {
        return field_errors(fields);
    }
    if let Some(reason) = app.shared.pressure_refusal(&req) {
        let field = match (req.pressure_kpa, req.probe_pressure_kpa) {
            (PressureSetting::Auto, Some(_)) => "probe_pressure_kpa",
            _ => "pressure_kpa",
        };
        return field_errors(vec![FieldError {
            field: field.into(),
            reason,
        }]);
    }
    let job = app.shared.submit(JobKind::Experiment, Some(req));
    (StatusCode::ACCEPTED, Json(job)).into_response()
}

async fn list_jobs(State(app): State<App>) -> Response {
    Json(app.shared.lock().jobs.clone()).into_response()
}

/// A job id from a URL (the error message for a 400).
fn parse_id(id: &str) -> Result<u64, String> {
    id.parse()
        .map_err(|_| format!("job id {id:?} is not a number"))
}

async fn get_job(State(app): State<App>, Path(id): Path<String>) -> Response {
    let id = match parse_id(&id) {
        Ok(i) => i,
        Err(r) => return error(StatusCode::BAD_REQUEST, r),
    };
    match app.shared.lock().jobs.iter().find(|j| j.id == id) {
        Some(j) => Json(j.clone()).into_response(),
        None => error(StatusCode::NOT_FOUND, format!("no job {id}")),
    }
}

async fn cancel_job(State(app): State<App>, Path(id): Path<String>) -> Response {
    let id = match parse_id(&id) {
        Ok(i) => i,
        Err(r) => return error(StatusCode::BAD_REQUEST, r),
    };
    match app.shared.cancel(id) {
        Ok(job) => Json(job).into_response(),
        Err(CancelError::NotFound) => error(StatusCode::NOT_FOUND, format!("no job {id}")),
        Err(CancelError::Finished(s)) => error(
            StatusCode::CONFLICT,
            format!("job {id} already ended ({s:?})"),
        ),
    }
}

async fn calibrate(State(app): State<App>) -> Response {
    if !app.shared.can_calibrate {
        return error(
            StatusCode::NOT_IMPLEMENTED,
            "calibration through the daemon needs the simulated bench (--sim); on real hardware put a calibration record in <records>/calibrations",
        );
    }
    let job = app.shared.submit(JobKind::Calibration, None);
    (StatusCode::ACCEPTED, Json(job)).into_response()
}

/// A file or directory name from a URL: no separators, no leading dot (the error message
/// for a 400 otherwise).
fn safe_name(name: &str) -> Result<&str, String> {
    let ok = !name.is_empty()
        && !name.starts_with('.')
        && name.len() <= 200
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b));
    if ok {
        Ok(name)
    } else {
        Err(format!("bad name {name:?}"))
    }
}

fn list_dir(dir: &std::path::Path, dirs: bool) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map(|it| {
            it.filter_map(Result::ok)
                // `file_type` does not follow links: a symlink is neither, and is not listed.
                .filter(|e| {
                    e.file_type()
                        .is_ok_and(|t| if dirs { t.is_dir() } else { t.is_file() })
                })
                .filter_map(|e| e.file_name().to_str().map(String::from))
                .filter(|n| !n.starts_with('.') && n != "calibrations")
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

async fn list_calibrations(State(app): State<App>) -> Response {
    Json(list_dir(&app.shared.calibrations_dir, false)).into_response()
}

async fn get_calibration(State(app): State<App>, Path(name): Path<String>) -> Response {
    let name = match safe_name(&name) {
        Ok(n) => n,
        Err(r) => return error(StatusCode::BAD_REQUEST, r),
    };
    match real_entry(&app.shared.calibrations_dir, &[name], false) {
        Some(path) => send_file(&path).await,
        None => error(StatusCode::NOT_FOUND, format!("no calibration {name}")),
    }
}

/// `base/parts...` if every part below `base` is a real directory (and the last a regular
/// file unless `dir`), never a symbolic link: a link planted in the records or
/// calibrations folder must not serve what it points to.
fn real_entry(base: &std::path::Path, parts: &[&str], dir: bool) -> Option<std::path::PathBuf> {
    let mut path = base.to_path_buf();
    for (k, part) in parts.iter().enumerate() {
        path.push(part);
        let meta = std::fs::symlink_metadata(&path).ok()?;
        let last = k + 1 == parts.len();
        let ok = if last && !dir {
            meta.file_type().is_file()
        } else {
            meta.file_type().is_dir()
        };
        if !ok {
            return None;
        }
    }
    Some(path)
}

async fn list_records(State(app): State<App>) -> Response {
    let dir = &app.shared.records_dir;
    let list: Vec<serde_json::Value> = list_dir(dir, true)
        .into_iter()
        .map(|n| {
            let status = std::fs::read_to_string(dir.join(&n).join("meta.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .and_then(|m| m.get("status").cloned())
                .unwrap_or(serde_json::Value::Null);
            serde_json::json!({ "name": n, "status": status })
        })
        .collect();
    Json(list).into_response()
}

async fn list_record_files(State(app): State<App>, Path(name): Path<String>) -> Response {
    list_in_record(&app, &name, None)
}

async fn get_record_file(
    State(app): State<App>,
    Path((name, file)): Path<(String, String)>,
) -> Response {
    file_in_record(&app, &name, None, &file).await
}

/// `GET /v1/records/{name}/probe/`: the files of the probe record an automatic pressure
/// choice keeps inside the experiment's record.
async fn list_probe_files(State(app): State<App>, Path(name): Path<String>) -> Response {
    list_in_record(&app, &name, Some(crate::jobs::PROBE_DIR))
}

async fn get_probe_file(
    State(app): State<App>,
    Path((name, file)): Path<(String, String)>,
) -> Response {
    file_in_record(&app, &name, Some(crate::jobs::PROBE_DIR), &file).await
}

/// The files of record `name` (or of its sub-record `sub`), names checked by [`safe_name`].
fn list_in_record(app: &App, name: &str, sub: Option<&str>) -> Response {
    let name = match safe_name(name) {
        Ok(n) => n,
        Err(r) => return error(StatusCode::BAD_REQUEST, r),
    };
    let mut parts = vec![name];
    parts.extend(sub);
    let Some(dir) = real_entry(&app.shared.records_dir, &parts, true) else {
        return error(
            StatusCode::NOT_FOUND,
            format!("no record {}", parts.join("/")),
        );
    };
    Json(list_dir(&dir, false)).into_response()
}

/// One file of record `name` (or of its sub-record `sub`), names checked by [`safe_name`].
async fn file_in_record(app: &App, name: &str, sub: Option<&str>, file: &str) -> Response {
    let (name, file) = match (safe_name(name), safe_name(file)) {
        (Ok(n), Ok(f)) => (n, f),
        (Err(r), _) | (_, Err(r)) => return error(StatusCode::BAD_REQUEST, r),
    };
    let mut parts = vec![name];
    parts.extend(sub);
    let record = parts.join("/");
    parts.push(file);
    match real_entry(&app.shared.records_dir, &parts, false) {
        Some(path) => send_file(&path).await,
        None => error(
            StatusCode::NOT_FOUND,
            format!("no file {file} in record {record}"),
        ),
    }
}

async fn send_file(path: &std::path::Path) -> Response {
    let kind = match path.extension().and_then(|e| e.to_str()) {
        Some("json") => "application/json",
        Some("csv") => "text/csv; charset=utf-8",
        Some("svg") => "image/svg+xml",
        Some("png") => "image/png",
        _ => "application/octet-stream",
    };
    match tokio::task::spawn_blocking({
        let path = path.to_path_buf();
        move || std::fs::read(path)
    })
    .await
    {
        Ok(Ok(bytes)) => ([(header::CONTENT_TYPE, kind)], bytes).into_response(),
        _ => error(
            StatusCode::NOT_FOUND,
            format!(
                "no file {}",
                path.file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default()
            ),
        ),
    }
}

fn to_sse(event: &Event) -> SseEvent {
    SseEvent::default()
        .event(event.name())
        .data(serde_json::to_string(event).unwrap_or_default())
}

async fn events(State(app): State<App>) -> Sse<impl Stream<Item = Result<SseEvent, Infallible>>> {
    let rx = app.shared.events.subscribe();
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        match rx.recv().await {
            Ok(ev) => Some((Ok(to_sse(&ev)), rx)),
            Err(broadcast::error::RecvError::Lagged(n)) => {
                Some((Ok(to_sse(&Event::Lagged { skipped: n })), rx))
            }
            Err(broadcast::error::RecvError::Closed) => None,
        }
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
