//! The web dashboard served at `/`: one page (HTML, CSS and JavaScript embedded in the
//! binary, no network access beyond the daemon) with the emergency stop, the live traces,
//! the running experiment's a–u_s curve and modulus, the experiment form and queue, the
//! records and calibrations (docs/daemon-api.md, "The web dashboard").
//!
//! - `GET /?token=LOGIN` exchanges a one-time login token for the session cookie and
//!   answers 303 to `/` (see [`session`]); `GET /` shows the page to a browser with the
//!   cookie and a short "log in" page otherwise; `GET /assets/{file}` serves the script and
//!   the style sheet.
//! - `GET /v1/live` (token or cookie): the running experiment's points and newest fit, so a
//!   page opened mid-run draws the whole curve.
//! - `POST /v1/login-link` (bearer token only): a new one-time login address.
//!
//! Every page carries a content security policy that allows only the daemon's own scripts,
//! styles and connections, and may not be framed.

pub mod session;

use axum::Extension;
use axum::Json;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::http::{App, AuthorizedBy, error};

const INDEX_HTML: &str = include_str!("assets/index.html");
const LOGIN_HTML: &str = include_str!("assets/login.html");
const DASHBOARD_JS: &str = include_str!("assets/dashboard.js");
const DASHBOARD_CSS: &str = include_str!("assets/dashboard.css");
/// Where the page's CSRF token goes in `index.html`.
const CSRF_PLACEHOLDER: &str = "__TACTILE_CSRF__";

/// Security headers of every dashboard answer.
fn page_headers(content_type: &'static str) -> [(header::HeaderName, HeaderValue); 6] {
    [
        (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
        (
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static(
                "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'",
            ),
        ),
        (header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY")),
        (
            header::REFERRER_POLICY,
            HeaderValue::from_static("no-referrer"),
        ),
        (
            header::X_CONTENT_TYPE_OPTIONS,
            HeaderValue::from_static("nosniff"),
        ),
        (header::CACHE_CONTROL, HeaderValue::from_static("no-store")),
    ]
}

/// The `token` parameter of a query string, if it looks like one (64 hex digits).
fn login_param(query: Option<&str>) -> Option<&str> {
    query?
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| *k == "token")
        .map(|(_, v)| v)
}

/// `GET /`: the login exchange, the page, or the "log in" page.
pub async fn page(
    State(app): State<App>,
    RawQuery(query): RawQuery,
    Extension(by): Extension<AuthorizedBy>,
) -> Response {
    let auth = &app.access.dashboard;
    if let Some(login) = login_param(query.as_deref()) {
        if !auth.redeem(login) {
            return (
                StatusCode::FORBIDDEN,
                page_headers("text/html; charset=utf-8"),
                LOGIN_HTML.replace(
                    "__TACTILE_WHY__",
                    "This login address is not valid (each one works once).",
                ),
            )
                .into_response();
        }
        let cookie = match HeaderValue::from_str(&auth.set_cookie()) {
            Ok(c) => c,
            Err(_) => return error(StatusCode::INTERNAL_SERVER_ERROR, "session cookie"),
        };
        return (
            StatusCode::SEE_OTHER,
            page_headers("text/plain; charset=utf-8"),
            [
                (header::SET_COOKIE, cookie),
                (header::LOCATION, HeaderValue::from_static("/")),
            ],
            "logged in; continue at /\n",
        )
            .into_response();
    }
    // The guard decided whether the cookie counts (or the bearer token was sent).
    if by != AuthorizedBy::Public {
        return (
            StatusCode::OK,
            page_headers("text/html; charset=utf-8"),
            INDEX_HTML.replace(CSRF_PLACEHOLDER, auth.csrf()),
        )
            .into_response();
    }
    (
        StatusCode::UNAUTHORIZED,
        page_headers("text/html; charset=utf-8"),
        LOGIN_HTML.replace("__TACTILE_WHY__", "This browser is not logged in."),
    )
        .into_response()
}

/// `GET /assets/{file}`: the page's script and style sheet (no secrets: served to anyone
/// who passes the Host check).
pub async fn asset(Path(name): Path<String>) -> Response {
    let (kind, body) = match name.as_str() {
        "dashboard.js" => ("text/javascript; charset=utf-8", DASHBOARD_JS),
        "dashboard.css" => ("text/css; charset=utf-8", DASHBOARD_CSS),
        _ => return error(StatusCode::NOT_FOUND, format!("no asset {name}")),
    };
    (StatusCode::OK, page_headers(kind), body).into_response()
}

/// `GET /v1/live`.
pub async fn live(State(app): State<App>) -> Response {
    Json(app.shared.switch.live.snapshot()).into_response()
}

/// The login address for `token` on a daemon at `addr` (an unspecified listen address is
/// reached through loopback).
pub fn login_url(addr: std::net::SocketAddr, token: &str) -> String {
    let host = if addr.ip().is_unspecified() {
        std::net::SocketAddr::from(([127, 0, 0, 1], addr.port()))
    } else {
        addr
    };
    format!("http://{host}/?token={token}")
}

/// `POST /v1/login-link` (bearer token only: the guard refuses the cookie here).
pub async fn login_link(State(app): State<App>) -> Response {
    match app.access.dashboard.new_login() {
        Ok(login) => Json(serde_json::json!({
            "url": login_url(app.access.addr, &login)
        }))
        .into_response(),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_login_parameter_and_url() {
        assert_eq!(login_param(Some("a=1&token=abc")), Some("abc"));
        assert_eq!(login_param(Some("tokens=abc")), None);
        assert_eq!(login_param(None), None);
        assert_eq!(
            login_url("0.0.0.0:7878".parse().unwrap(), "t"),
            "http://127.0.0.1:7878/?token=t"
        );
        assert_eq!(
            login_url("127.0.0.1:9".parse().unwrap(), "t"),
            "http://127.0.0.1:9/?token=t"
        );
    }

    #[test]
    fn the_page_has_a_csrf_slot_and_only_local_assets() {
        assert!(INDEX_HTML.contains(CSRF_PLACEHOLDER));
        for text in [INDEX_HTML, LOGIN_HTML, DASHBOARD_JS, DASHBOARD_CSS] {
            assert!(!text.contains("https://"), "no outside resources");
            assert!(!text.contains("//cdn"), "no outside resources");
        }
    }
}
