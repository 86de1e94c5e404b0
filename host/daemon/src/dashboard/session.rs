//! The dashboard's browser session: one-time login addresses, the session cookie and the
//! CSRF token.
//!
//! - A login address (`http://127.0.0.1:PORT/?token=LOGIN`) carries a random one-time token
//!   (32 bytes from the kernel). The daemon makes one at start (printed on stderr) and one
//!   for each `POST /v1/login-link` (bearer token only); at most [`MAX_PENDING_LOGINS`]
//!   are outstanding. Exchanging it removes it: the address works once.
//! - The session cookie `tactile_session_PORT` (HttpOnly, SameSite=Strict, Path=/) holds
//!   SHA-256 of a fixed label and the daemon's bearer token, so it stays valid across
//!   daemon restarts (the page reconnects by itself) and becomes invalid when the token
//!   file is replaced. The port is in the name because browsers do not separate cookies by
//!   port.
//! - The CSRF token, derived the same way with another label, is written into the page
//!   only for a request that already carries the cookie. A request authorised by the
//!   cookie alone may read (GET); a change (POST, DELETE) needs in addition an `Origin`
//!   header naming the daemon and `X-Tactile-CSRF` with that token. A foreign page, even
//!   one on another port of 127.0.0.1 (which browsers count as the same site and so send
//!   the cookie to), gets neither past the checks.
//! - A browser marks where each request comes from (`Sec-Fetch-Site`): the cookie counts
//!   only for `same-origin` and `none` (what the user opened), so another site cannot even
//!   embed the daemon's plots or open its feed with it.

use std::sync::Mutex;

use axum::http::HeaderMap;
use sha2::{Digest, Sha256};

use crate::token::{TokenError, random_hex, tokens_equal};

/// Most one-time login addresses outstanding; a new one beyond it retires the oldest.
pub const MAX_PENDING_LOGINS: usize = 16;
/// The header a cookie-authorised change must carry.
pub const CSRF_HEADER: &str = "x-tactile-csrf";

fn derive(label: &str, token: &str) -> String {
    Sha256::digest(format!("tactile dashboard {label}\n{token}").as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The dashboard's credentials for one daemon.
#[derive(Debug)]
pub struct DashboardAuth {
    cookie_name: String,
    session: String,
    csrf: String,
    logins: Mutex<Vec<String>>,
}

impl DashboardAuth {
    /// For a daemon with bearer `token` listening on `port`.
    pub fn new(token: &str, port: u16) -> Self {
        Self {
            cookie_name: format!("tactile_session_{port}"),
            session: derive("session", token),
            csrf: derive("csrf", token),
            logins: Mutex::new(Vec::new()),
        }
    }

    fn logins(&self) -> std::sync::MutexGuard<'_, Vec<String>> {
        // A poisoned lock still holds a valid list.
        self.logins.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A fresh one-time login token.
    pub fn new_login(&self) -> Result<String, TokenError> {
        let login = random_hex()?;
        let mut pending = self.logins();
        if pending.len() >= MAX_PENDING_LOGINS {
            pending.remove(0);
        }
        pending.push(login.clone());
        Ok(login)
    }

    /// Exchanges a login token: true (and it is gone) if it was outstanding.
    pub fn redeem(&self, candidate: &str) -> bool {
        let mut pending = self.logins();
        // Compare with every entry (constant time each) before removing.
        let found = pending.iter().enumerate().fold(None, |hit, (k, l)| {
            if tokens_equal(l, candidate) {
                Some(k)
            } else {
                hit
            }
        });
        match found {
            Some(k) => {
                pending.remove(k);
                true
            }
            None => false,
        }
    }

    /// The `Set-Cookie` value that opens a session.
    pub fn set_cookie(&self) -> String {
        format!(
            "{}={}; Path=/; HttpOnly; SameSite=Strict",
            self.cookie_name, self.session
        )
    }

    /// The request carries the session cookie.
    pub fn has_session(&self, headers: &HeaderMap) -> bool {
        headers
            .get_all(axum::http::header::COOKIE)
            .iter()
            .filter_map(|h| h.to_str().ok())
            .flat_map(|h| h.split(';'))
            .filter_map(|c| c.trim().split_once('='))
            .any(|(name, value)| name == self.cookie_name && tokens_equal(value, &self.session))
    }

    /// `Sec-Fetch-Site` is absent (not a browser, or an old one) or says the request comes
    /// from the daemon's own origin (`same-origin`) or from the user (`none`: an address
    /// typed or bookmarked).
    pub fn fetch_site_ok(&self, headers: &HeaderMap) -> bool {
        match headers.get("sec-fetch-site").map(|h| h.to_str()) {
            None => true,
            Some(Ok(v)) => v.eq_ignore_ascii_case("same-origin") || v.eq_ignore_ascii_case("none"),
            Some(Err(_)) => false,
        }
    }

    /// The CSRF token the page sends with every change.
    pub fn csrf(&self) -> &str {
        &self.csrf
    }

    /// The request carries the CSRF header with the right token.
    pub fn csrf_ok(&self, headers: &HeaderMap) -> bool {
        headers
            .get(CSRF_HEADER)
            .and_then(|h| h.to_str().ok())
            .is_some_and(|v| tokens_equal(v.trim(), &self.csrf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    #[test]
    fn a_login_token_works_once() {
        let auth = DashboardAuth::new(&"a".repeat(64), 7878);
        let login = auth.new_login().unwrap();
        assert_eq!(login.len(), 64);
        assert!(!auth.redeem(&"0".repeat(64)));
        assert!(auth.redeem(&login));
        assert!(!auth.redeem(&login), "a used login token is refused");
    }

    #[test]
    fn the_oldest_pending_login_is_retired() {
        let auth = DashboardAuth::new(&"a".repeat(64), 7878);
        let first = auth.new_login().unwrap();
        for _ in 0..MAX_PENDING_LOGINS {
            auth.new_login().unwrap();
        }
        assert!(!auth.redeem(&first));
    }

    #[test]
    fn cookie_and_csrf_depend_on_the_token_and_port() {
        let a = DashboardAuth::new(&"a".repeat(64), 7878);
        let b = DashboardAuth::new(&"b".repeat(64), 7878);
        assert_ne!(a.set_cookie(), b.set_cookie());
        assert_ne!(a.csrf(), b.csrf());
        assert_ne!(a.csrf(), a.session);
        let cookie = a.set_cookie();
        assert!(cookie.starts_with("tactile_session_7878="));
        assert!(cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"));
        let pair = cookie.split(';').next().unwrap().to_string();
        let mut h = HeaderMap::new();
        h.insert(
            axum::http::header::COOKIE,
            HeaderValue::from_str(&format!("other=1; {pair}")).unwrap(),
        );
        assert!(a.has_session(&h));
        assert!(!b.has_session(&h));
        let c = DashboardAuth::new(&"a".repeat(64), 7879);
        assert!(!c.has_session(&h), "another port's cookie name");
        h.insert(CSRF_HEADER, HeaderValue::from_str(a.csrf()).unwrap());
        assert!(a.csrf_ok(&h));
        assert!(!b.csrf_ok(&h));
        assert!(a.fetch_site_ok(&h));
        for (site, ok) in [
            ("same-origin", true),
            ("none", true),
            ("same-site", false),
            ("cross-site", false),
        ] {
            h.insert("sec-fetch-site", HeaderValue::from_static(site));
            assert_eq!(a.fetch_site_ok(&h), ok, "{site}");
        }
    }
}
