//! The bench daemon (`tactile daemon`, docs/daemon-api.md): one long-lived process owns
//! the device link and the frame source, keeps the heartbeats going, reconnects by USB
//! serial number when the controller is unplugged and plugged back (recording the gap),
//! runs queued experiments one at a time and writes their records, and serves a local HTTP
//! API with a live feed (Server-Sent Events) to any number of clients.
//!
//! - [`api`]: request/response bodies and live-feed events (shared with the clients);
//! - [`token`]: the bearer token in a 0600 file;
//! - [`http`]: routes, Host/Origin/token checks, body limits, the SSE feed;
//! - [`dashboard`]: the web page at `/`, its login, session cookie and CSRF rules;
//!   [`live_curve`]: the running experiment's curve for a page that opens mid-run;
//! - [`guarded_transport`]: the link's transport with the emergency-stop path and the
//!   live-feed tap;
//! - [`device_thread`]: the thread that owns the link; [`jobs`]: experiments and
//!   calibrations; [`live_radius`] and [`fit_worker`]: live a–u_s points and the running fit;
//! - [`shared`]: state shared between the HTTP side and the device thread;
//! - [`listener`]: the accept loop and its limits (connection cap, header and body
//!   timeouts);
//! - [`server`]: start/stop; [`client`]: the blocking HTTP client of `tactile status|stop|
//!   run|watch`.
//!
//! The HTTP API is documented with curl examples in docs/daemon-api.md.

pub mod api;
pub mod client;
pub mod dashboard;
pub mod device_thread;
pub mod fit_worker;
pub mod guarded_transport;
pub mod http;
pub mod jobs;
pub mod listener;
pub mod live_curve;
pub mod live_radius;
pub mod server;
pub mod shared;
#[cfg(feature = "sim")]
pub mod sim;
pub mod terminal_view;
pub mod token;

pub use api::{Event, ExperimentRequest, Job, JobState, StatusReport};
pub use client::{Client, ClientError};
pub use device_thread::{DeviceConfig, DeviceSource};
pub use server::{DaemonError, DaemonHandle, DaemonOptions, start};
