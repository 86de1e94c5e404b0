//! The daemon's connections: an accept loop with stated limits, so that no client without
//! the token can hold the daemon's sockets, file descriptors or memory and delay an
//! authenticated request such as the emergency stop.
//!
//! - At most [`MAX_CONNECTIONS`] connections are open at once. When a new one arrives at
//!   the cap, the oldest connection that has not yet sent an authorised request is closed
//!   to make room; if every open connection has authenticated (token holders), the new one
//!   is refused. A flood of idle or half-sent connections therefore only ever evicts itself.
//! - A request's header must arrive within [`HEADER_READ_TIMEOUT`] of the connection
//!   waiting for it (which is also the idle timeout between keep-alive requests), and its
//!   body within [`BODY_READ_TIMEOUT`] (see `http::Body`).
//! - Accept errors (out of file descriptors) back off for a moment instead of spinning.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::TcpListener;
use tokio::sync::{Notify, oneshot};
use tower::ServiceExt;

/// Most connections open at once.
pub const MAX_CONNECTIONS: usize = 512;
/// Longest wait for a complete request header (and idle time between requests).
pub const HEADER_READ_TIMEOUT: Duration = Duration::from_secs(10);
/// Longest wait for a request body (bodies are at most `api::MAX_BODY_BYTES`).
pub const BODY_READ_TIMEOUT: Duration = Duration::from_secs(10);
/// Pause after a failed accept (e.g. EMFILE), so the loop does not spin.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(20);

/// One open connection, as the request handlers see it (a request extension).
#[derive(Debug, Default)]
pub struct Connection {
    authenticated: AtomicBool,
    close: Notify,
}

impl Connection {
    /// Marks the connection as a token holder's: it is no longer evicted for newcomers.
    pub fn authenticate(&self) {
        self.authenticated.store(true, Ordering::Relaxed);
    }

    fn is_authenticated(&self) -> bool {
        self.authenticated.load(Ordering::Relaxed)
    }
}

/// Open connections by age (ids increase).
#[derive(Debug, Default)]
struct Registry {
    next_id: u64,
    open: BTreeMap<u64, Arc<Connection>>,
}

impl Registry {
    /// Makes room for one more connection; false if none can be evicted.
    fn make_room(&mut self, cap: usize) -> bool {
        if self.open.len() < cap {
            return true;
        }
        let victim = self
            .open
            .iter()
            .find(|(_, c)| !c.is_authenticated())
            .map(|(id, _)| *id);
        match victim.and_then(|id| self.open.remove(&id)) {
            Some(c) => {
                c.close.notify_one();
                true
            }
            None => false,
        }
    }
}

/// Counters of the accept loop (for the status report and the tests).
#[derive(Debug, Default)]
pub struct ConnectionStats {
    pub evicted: std::sync::atomic::AtomicU64,
    pub refused: std::sync::atomic::AtomicU64,
    pub open: std::sync::atomic::AtomicU64,
}

/// Serves `router` on `listener` until `shutdown` fires.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    max_connections: usize,
    stats: Arc<ConnectionStats>,
    mut shutdown: oneshot::Receiver<()>,
) {
    let registry = Arc::new(Mutex::new(Registry::default()));
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(HEADER_READ_TIMEOUT)
        .keep_alive(true);
    loop {
        let stream = tokio::select! {
            _ = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    tracing::warn!(error = %e, "accept failed; backing off");
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            },
        };
        let admitted = {
            let Ok(mut reg) = registry.lock() else { break };
            let before = reg.open.len();
            if reg.make_room(max_connections) {
                if reg.open.len() < before {
                    stats.evicted.fetch_add(1, Ordering::Relaxed);
                }
                let id = reg.next_id;
                reg.next_id += 1;
                let conn = Arc::new(Connection::default());
                reg.open.insert(id, Arc::clone(&conn));
                stats.open.store(reg.open.len() as u64, Ordering::Relaxed);
                Some((id, conn))
            } else {
                None
            }
        };
        let Some((id, conn)) = admitted else {
            stats.refused.fetch_add(1, Ordering::Relaxed);
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let tagged = {
            let conn = Arc::clone(&conn);
            router
                .clone()
                .map_request(move |mut req: axum::http::Request<Incoming>| {
                    req.extensions_mut().insert(Arc::clone(&conn));
                    req
                })
        };
        let serving = http.serve_connection(TokioIo::new(stream), TowerToHyperService::new(tagged));
        let registry = Arc::clone(&registry);
        let stats = Arc::clone(&stats);
        tokio::spawn(async move {
            tokio::select! {
                _ = serving => {}
                _ = conn.close.notified() => {}
            }
            if let Ok(mut reg) = registry.lock() {
                reg.open.remove(&id);
                stats.open.store(reg.open.len() as u64, Ordering::Relaxed);
            }
        });
    }
    // Close every connection (live feeds never end by themselves).
    if let Ok(reg) = registry.lock() {
        for c in reg.open.values() {
            c.close.notify_one();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_oldest_unauthenticated_connection_makes_room() {
        let mut reg = Registry::default();
        for id in 0..3 {
            reg.open.insert(id, Arc::new(Connection::default()));
        }
        reg.open[&0].authenticate();
        assert!(reg.make_room(3));
        assert_eq!(reg.open.keys().copied().collect::<Vec<_>>(), vec![0, 2]);
        reg.open[&2].authenticate();
        reg.open.insert(3, Arc::new(Connection::default()));
        reg.open[&3].authenticate();
        // Everyone open holds the token: the newcomer is refused.
        assert!(!reg.make_room(3));
        assert_eq!(reg.open.len(), 3);
        assert!(reg.make_room(4));
    }
}
