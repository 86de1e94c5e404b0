//! The blocking client of the daemon's API (ureq, plain HTTP on loopback), used by
//! `tactile status|stop|run|watch` and the tests.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::time::Duration;

use serde::de::DeserializeOwned;

use super::api::{ApiError, Event, ExperimentRequest, Job, StatusReport, StopReport};

#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot reach the daemon at {addr}: {reason} (is `tactile daemon` running?)")]
    Unreachable { addr: String, reason: String },
    #[error("daemon answered {status}: {message}{}", fields_text(fields))]
    Api {
        status: u16,
        message: String,
        fields: Vec<super::api::FieldError>,
    },
    #[error("unexpected answer from the daemon: {0}")]
    Decode(String),
    #[error(transparent)]
    Token(#[from] super::token::TokenError),
}

/// `; field: reason` for each field the daemon refused.
fn fields_text(fields: &[super::api::FieldError]) -> String {
    fields
        .iter()
        .map(|f| format!("; {}: {}", f.field, f.reason))
        .collect()
}

/// An HTTP answer: status and body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawResponse {
    pub status: u16,
    pub body: String,
}

/// A connection to one daemon.
#[derive(Debug, Clone)]
pub struct Client {
    addr: String,
    token: String,
    agent: ureq::Agent,
    stream_agent: ureq::Agent,
}

impl Client {
    /// `addr` is `host:port`.
    pub fn new(addr: &str, token: &str) -> Self {
        let make = |timeout: Option<Duration>| -> ureq::Agent {
            ureq::Agent::config_builder()
                .http_status_as_error(false)
                .timeout_global(timeout)
                .build()
                .into()
        };
        Self {
            addr: addr.to_string(),
            token: token.to_string(),
            agent: make(Some(Duration::from_secs(30))),
            stream_agent: make(None),
        }
    }

    /// Reads the token from `token_file` (the daemon's, or a copy only the user can read).
    pub fn from_token_file(addr: &str, token_file: &Path) -> Result<Self, ClientError> {
        let token = super::token::read_token(token_file)?;
        Ok(Self::new(addr, &token))
    }

    pub fn addr(&self) -> &str {
        &self.addr
    }

    fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    fn unreachable(&self, e: ureq::Error) -> ClientError {
        ClientError::Unreachable {
            addr: self.addr.clone(),
            reason: e.to_string(),
        }
    }

    /// Any request, with the token and optional extra headers; no status interpretation
    /// (tests use it to send what a client should not).
    pub fn raw(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
        headers: &[(&str, &str)],
        with_token: bool,
    ) -> Result<RawResponse, ClientError> {
        let url = self.url(path);
        let auth = format!("Bearer {}", self.token);
        let result = match method {
            "GET" | "DELETE" => {
                let mut req = if method == "GET" {
                    self.agent.get(&url)
                } else {
                    self.agent.delete(&url)
                };
                if with_token {
                    req = req.header("Authorization", &auth);
                }
                for (k, v) in headers {
                    req = req.header(*k, *v);
                }
                req.call()
            }
            _ => {
                let mut req = self.agent.post(&url);
                if with_token {
                    req = req.header("Authorization", &auth);
                }
                let has_type = headers
                    .iter()
                    .any(|(k, _)| k.eq_ignore_ascii_case("content-type"));
                if !has_type {
                    req = req.header("Content-Type", "application/json");
                }
                for (k, v) in headers {
                    req = req.header(*k, *v);
                }
                req.send(body.unwrap_or(""))
            }
        };
        let mut response = result.map_err(|e| self.unreachable(e))?;
        let status = response.status().as_u16();
        let body = response
            .body_mut()
            .with_config()
            .limit(256 * 1024 * 1024)
            .read_to_string()
            .map_err(|e| ClientError::Decode(e.to_string()))?;
        Ok(RawResponse { status, body })
    }

    fn call<T: DeserializeOwned>(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
    ) -> Result<T, ClientError> {
        let r = self.raw(method, path, body, &[], true)?;
        if !(200..300).contains(&r.status) {
            let (message, fields) = match serde_json::from_str::<ApiError>(&r.body) {
                Ok(e) => (e.error, e.fields),
                Err(_) => (r.body.clone(), Vec::new()),
            };
            return Err(ClientError::Api {
                status: r.status,
                message,
                fields,
            });
        }
        serde_json::from_str(&r.body).map_err(|e| ClientError::Decode(format!("{path}: {e}")))
    }

    pub fn status(&self) -> Result<StatusReport, ClientError> {
        self.call("GET", "/v1/status", None)
    }

    /// Emergency stop.
    pub fn stop(&self) -> Result<StopReport, ClientError> {
        self.call("POST", "/v1/stop", Some(""))
    }

    pub fn set_pressure(&self, kpa: f64) -> Result<serde_json::Value, ClientError> {
        self.call("POST", "/v1/pressure", Some(&format!("{{\"kpa\":{kpa}}}")))
    }

    pub fn vent(&self, open: bool) -> Result<serde_json::Value, ClientError> {
        self.call("POST", "/v1/vent", Some(&format!("{{\"open\":{open}}}")))
    }

    pub fn submit(&self, request: &ExperimentRequest) -> Result<Job, ClientError> {
        let body =
            serde_json::to_string(request).map_err(|e| ClientError::Decode(e.to_string()))?;
        self.call("POST", "/v1/experiments", Some(&body))
    }

    pub fn calibrate(&self) -> Result<Job, ClientError> {
        self.call("POST", "/v1/calibrations", Some(""))
    }

    pub fn job(&self, id: u64) -> Result<Job, ClientError> {
        self.call("GET", &format!("/v1/experiments/{id}"), None)
    }

    pub fn jobs(&self) -> Result<Vec<Job>, ClientError> {
        self.call("GET", "/v1/experiments", None)
    }

    pub fn cancel(&self, id: u64) -> Result<Job, ClientError> {
        self.call("DELETE", &format!("/v1/experiments/{id}"), None)
    }

    /// A new one-time login address of the web dashboard.
    pub fn login_link(&self) -> Result<String, ClientError> {
        let v: serde_json::Value = self.call("POST", "/v1/login-link", Some(""))?;
        v.get("url")
            .and_then(|u| u.as_str())
            .map(String::from)
            .ok_or_else(|| ClientError::Decode("/v1/login-link: no url".into()))
    }

    pub fn records(&self) -> Result<serde_json::Value, ClientError> {
        self.call("GET", "/v1/records", None)
    }

    /// Opens the live feed.
    pub fn events(&self) -> Result<EventStream, ClientError> {
        let response = self
            .stream_agent
            .get(&self.url("/v1/events"))
            .header("Authorization", &format!("Bearer {}", self.token))
            .header("Accept", "text/event-stream")
            .call()
            .map_err(|e| self.unreachable(e))?;
        let status = response.status().as_u16();
        if status != 200 {
            return Err(ClientError::Api {
                status,
                message: "the live feed was refused".into(),
                fields: Vec::new(),
            });
        }
        let reader: Box<dyn Read + Send> = Box::new(response.into_body().into_reader());
        Ok(EventStream {
            reader: BufReader::new(reader),
        })
    }
}

/// The live feed: Server-Sent Events decoded into [`Event`]s.
pub struct EventStream {
    reader: BufReader<Box<dyn Read + Send>>,
}

impl std::fmt::Debug for EventStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventStream").finish_non_exhaustive()
    }
}

impl Iterator for EventStream {
    type Item = Result<Event, ClientError>;

    /// The next event; `None` when the daemon closed the feed.
    fn next(&mut self) -> Option<Self::Item> {
        let mut data = String::new();
        loop {
            let mut line = String::new();
            match self.reader.read_line(&mut line) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(e) => return Some(Err(ClientError::Decode(e.to_string()))),
            }
            let line = line.trim_end_matches(['\r', '\n']);
            if line.is_empty() {
                if data.is_empty() {
                    continue; // keep-alive comment block or stray blank line
                }
                return Some(
                    serde_json::from_str(&data).map_err(|e| ClientError::Decode(e.to_string())),
                );
            }
            if let Some(d) = line.strip_prefix("data:") {
                if !data.is_empty() {
                    data.push('\n');
                }
                data.push_str(d.strip_prefix(' ').unwrap_or(d));
            }
        }
    }
}
