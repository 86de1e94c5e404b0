//! The web dashboard's HTTP side, request by request (every header written by hand):
//! the one-time login address sets an HttpOnly, SameSite=Strict cookie and redirects (303)
//! to `/`, and works once; the page and its assets are served with a content security
//! policy; the cookie lets a browser read, but a change made with it needs the daemon's
//! own Origin and the page's CSRF token, so a foreign page (even on another port of
//! 127.0.0.1, to which the browser sends the cookie) changes nothing; new login addresses
//! are given to bearer-token holders only.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use daemon::Client;
use daemon::sim::start_sim_daemon;
use system_tests::{start_test_daemon, temp_dir};

/// An answer: status, headers (names lower case) and body.
struct Answer {
    status: u16,
    headers: Vec<(String, String)>,
    body: String,
}

impl Answer {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
}

/// One request on its own connection (`Connection: close`), headers exactly as given.
fn request(addr: &str, method: &str, path: &str, headers: &[(&str, &str)], body: &str) -> Answer {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    // Generous: a loaded 2-core machine may starve the daemon for a while; answers take
    // milliseconds otherwise.
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let mut text = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        text.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        text.push_str(&format!("{k}: {v}\r\n"));
    }
    text.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    let _ = s.write_all(text.as_bytes());
    let mut raw = Vec::new();
    let _ = s.read_to_end(&mut raw);
    let raw = String::from_utf8_lossy(&raw).to_string();
    let (head, body) = raw.split_once("\r\n\r\n").unwrap();
    let mut lines = head.lines();
    let status = lines
        .next()
        .unwrap()
        .split_whitespace()
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    Answer {
        status,
        headers,
        body: body.to_string(),
    }
}

#[test]
fn login_cookie_csrf_and_assets() {
    let dir = temp_dir("daemon-web-dashboard");
    let (daemon, token_file) = start_test_daemon(&dir, 500);
    let addr = daemon.addr.to_string();
    let client = Client::from_token_file(&addr, &token_file).unwrap();
    let t0 = Instant::now();
    // The first status poll fills in the vent state (1-2 s unloaded).
    while client.status().unwrap().vent_open.is_none() {
        assert!(t0.elapsed() < Duration::from_secs(30), "never connected");
        std::thread::sleep(Duration::from_millis(50));
    }

    // Not logged in: the page says how to log in; the API still wants credentials.
    let r = request(&addr, "GET", "/", &[], "");
    assert_eq!(r.status, 401);
    assert!(r.body.contains("tactile dashboard"), "{}", r.body);
    assert!(
        !r.body.contains("tactile-csrf"),
        "no CSRF token without the cookie"
    );
    assert_eq!(request(&addr, "GET", "/v1/live", &[], "").status, 401);

    // The printed login address: 303 to the clean address with the session cookie.
    let login_path = daemon
        .login_url
        .strip_prefix(&format!("http://{addr}"))
        .unwrap()
        .to_string();
    assert!(login_path.starts_with("/?token="), "{login_path}");
    // A foreign Host is refused before the token is looked at (and does not use it up).
    let r = request(&addr, "GET", &login_path, &[("Host", "evil.example")], "");
    assert_eq!(r.status, 403);
    let r = request(&addr, "GET", &login_path, &[], "");
    assert_eq!(r.status, 303, "{}", r.body);
    assert_eq!(r.header("location"), Some("/"));
    let set_cookie = r.header("set-cookie").unwrap().to_string();
    let attributes: Vec<&str> = set_cookie.split(';').map(str::trim).collect();
    for flag in ["HttpOnly", "SameSite=Strict", "Path=/"] {
        assert!(attributes.contains(&flag), "{set_cookie}");
    }
    assert!(
        attributes[0].starts_with(&format!("tactile_session_{}=", daemon.addr.port())),
        "{set_cookie}"
    );
    let cookie = attributes[0].to_string();
    // Once only.
    let r = request(&addr, "GET", &login_path, &[], "");
    assert_eq!(r.status, 403);
    assert!(r.header("set-cookie").is_none());

    // With the cookie: the page, its CSRF token, the policy.
    let r = request(&addr, "GET", "/", &[("Cookie", &cookie)], "");
    assert_eq!(r.status, 200);
    assert!(r.header("content-type").unwrap().starts_with("text/html"));
    let csp = r.header("content-security-policy").unwrap();
    assert!(csp.contains("script-src 'self'") && csp.contains("frame-ancestors 'none'"));
    assert_eq!(r.header("x-frame-options"), Some("DENY"));
    let csrf = r
        .body
        .split("name=\"tactile-csrf\" content=\"")
        .nth(1)
        .and_then(|rest| rest.split('"').next())
        .unwrap()
        .to_string();
    assert_eq!(csrf.len(), 64, "{csrf}");
    assert!(csrf.bytes().all(|b| b.is_ascii_hexdigit()));

    // Assets: served, typed, behind the Host check.
    let r = request(&addr, "GET", "/assets/dashboard.js", &[], "");
    assert_eq!(r.status, 200);
    assert!(
        r.header("content-type")
            .unwrap()
            .starts_with("text/javascript")
    );
    assert!(r.body.contains("EventSource"));
    let r = request(&addr, "GET", "/assets/dashboard.css", &[], "");
    assert_eq!(r.status, 200);
    assert!(r.header("content-type").unwrap().starts_with("text/css"));
    assert_eq!(
        request(&addr, "GET", "/assets/../v1/status", &[], "").status,
        404
    );
    assert_eq!(request(&addr, "GET", "/assets/x.js", &[], "").status, 404);
    assert_eq!(
        request(
            &addr,
            "GET",
            "/assets/dashboard.js",
            &[("Host", "evil.example")],
            ""
        )
        .status,
        403
    );

    // The cookie reads.
    let r = request(&addr, "GET", "/v1/status", &[("Cookie", &cookie)], "");
    assert_eq!(r.status, 200, "{}", r.body);
    let r = request(&addr, "GET", "/v1/live", &[("Cookie", &cookie)], "");
    assert_eq!(r.status, 200, "{}", r.body);
    assert!(r.body.contains("\"points\""), "{}", r.body);

    // What another site embeds or fetches (the browser says so in Sec-Fetch-Site) gets
    // nothing with the cookie, not even a read.
    for site in ["same-site", "cross-site"] {
        let r = request(
            &addr,
            "GET",
            "/v1/status",
            &[("Cookie", &cookie), ("Sec-Fetch-Site", site)],
            "",
        );
        assert_eq!(r.status, 403, "{site}: {}", r.body);
    }
    let r = request(
        &addr,
        "GET",
        "/",
        &[("Cookie", &cookie), ("Sec-Fetch-Site", "none")],
        "",
    );
    assert_eq!(r.status, 200, "an address the user opened");
    // A link from another site to the page: shown as not logged in (no CSRF token).
    let r = request(
        &addr,
        "GET",
        "/",
        &[("Cookie", &cookie), ("Sec-Fetch-Site", "same-site")],
        "",
    );
    assert_eq!(r.status, 401);
    assert!(!r.body.contains("tactile-csrf"));

    // A change with the cookie alone, or with a foreign Origin, or without the CSRF token,
    // or without an Origin: refused, and nothing changes.
    let own_origin = format!("http://{addr}");
    let other_port = format!("http://127.0.0.1:{}", daemon.addr.port() + 1);
    let stops = client.status().unwrap().emergency_stops;
    let jobs = client.jobs().unwrap().len();
    let refused: [&[(&str, &str)]; 5] = [
        &[("Cookie", &cookie)],
        &[("Cookie", &cookie), ("Origin", &other_port)],
        &[
            ("Cookie", &cookie),
            ("Origin", &other_port),
            ("X-Tactile-CSRF", &csrf),
        ],
        &[("Cookie", &cookie), ("Origin", &own_origin)],
        &[("Cookie", &cookie), ("X-Tactile-CSRF", &csrf)],
    ];
    for headers in refused {
        let r = request(&addr, "POST", "/v1/stop", headers, "");
        assert_eq!(r.status, 403, "{headers:?}: {}", r.body);
        let mut with_type = headers.to_vec();
        with_type.push(("Content-Type", "application/json"));
        let r = request(
            &addr,
            "POST",
            "/v1/experiments",
            &with_type,
            r#"{"pressure_kpa":6}"#,
        );
        assert_eq!(r.status, 403, "{headers:?}: {}", r.body);
        let r = request(&addr, "DELETE", "/v1/experiments/1", headers, "");
        assert_eq!(r.status, 403, "{headers:?}: {}", r.body);
    }
    // A wrong CSRF token with the right Origin.
    let r = request(
        &addr,
        "POST",
        "/v1/stop",
        &[
            ("Cookie", &cookie),
            ("Origin", &own_origin),
            ("X-Tactile-CSRF", &"0".repeat(64)),
        ],
        "",
    );
    assert_eq!(r.status, 403);
    assert_eq!(client.status().unwrap().emergency_stops, stops);
    assert_eq!(client.jobs().unwrap().len(), jobs);

    // The page's own request: cookie, Origin and CSRF token.
    let page = [
        ("Cookie", cookie.as_str()),
        ("Origin", own_origin.as_str()),
        ("X-Tactile-CSRF", csrf.as_str()),
    ];
    let r = request(&addr, "POST", "/v1/stop", &page, "");
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(client.status().unwrap().emergency_stops, stops + 1);

    // New login addresses: for the bearer token only, each working once.
    let r = request(&addr, "POST", "/v1/login-link", &page, "");
    assert_eq!(r.status, 403, "{}", r.body);
    let url = client.login_link().unwrap();
    let path = url.strip_prefix(&own_origin).unwrap();
    assert_eq!(request(&addr, "GET", path, &[], "").status, 303);
    assert_eq!(request(&addr, "GET", path, &[], "").status, 403);
    // The first address stays used up.
    assert_eq!(request(&addr, "GET", &login_path, &[], "").status, 403);

    drop(daemon);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The session cookie is derived from the token file: a daemon restarted with the same
/// token accepts the cookie a browser already holds (the page reconnects by itself).
#[test]
fn the_session_survives_a_restart_with_the_same_token() {
    let dir = temp_dir("daemon-web-dashboard-restart");
    let token_file = dir.join("token");
    let start = || {
        start_sim_daemon(
            None,
            "127.0.0.1:0".parse().unwrap(),
            &dir.join("records"),
            &token_file,
            500,
        )
        .unwrap()
    };
    let first = start();
    let login = first.login_url.clone();
    let addr = first.addr.to_string();
    let path = login.strip_prefix(&format!("http://{addr}")).unwrap();
    let r = request(&addr, "GET", path, &[], "");
    assert_eq!(r.status, 303);
    let cookie_value = r
        .header("set-cookie")
        .unwrap()
        .split(';')
        .next()
        .unwrap()
        .split_once('=')
        .unwrap()
        .1
        .to_string();
    drop(first);
    let second = start();
    let addr = second.addr.to_string();
    let cookie = format!("tactile_session_{}={cookie_value}", second.addr.port());
    let r = request(&addr, "GET", "/", &[("Cookie", &cookie)], "");
    assert_eq!(r.status, 200);
    // A new daemon prints a new login address; the old one is not valid there.
    assert_ne!(second.login_url, login);
    let old = login.split("/?").nth(1).unwrap();
    assert_eq!(
        request(&addr, "GET", &format!("/?{old}"), &[], "").status,
        403
    );
    drop(second);
    std::fs::remove_dir_all(&dir).unwrap();
}
