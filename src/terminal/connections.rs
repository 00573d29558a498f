//! The daemon's connections, kept few and short so that a flood cannot lock
//! the operator out.
//!
//! A flood of connections that never finish their request (or sit idle)
//! would otherwise hold a descriptor each until the process runs out, and
//! then Status and Abort stop answering. So:
//! - at most [`ConnectionLimits::max_connections`] are open at once;
//! - a connection that has not sent a whole request within
//!   [`ConnectionLimits::request_timeout`] is closed, and so is one idle
//!   (no request in flight) for [`ConnectionLimits::idle_timeout`];
//! - when the limit is reached, the oldest connection that has never sent a
//!   whole request makes room for the new one (failing that, the oldest idle
//!   one). A phone that sends its request at once therefore always gets
//!   through, while connections that only take room are the first to go.
//!
//! A request in flight includes the streaming of its response, so the live
//! event stream of a page is never taken for idle.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::body::{Body, HttpBody};
use axum::extract::ConnectInfo;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::net::TcpStream;
use tokio::sync::{watch, Notify};
use tokio_stream::StreamExt;
use tower::Service;

/// How many connections, and for how long.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnectionLimits {
    /// Open at once; well below the unit's `LimitNOFILE` (4096) and below the
    /// usual 1024, leaving room for the session's files and sockets.
    pub max_connections: usize,
    /// From the connection (or the previous response) to a whole request.
    pub request_timeout: Duration,
    /// With no request in flight.
    pub idle_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 256,
            request_timeout: Duration::from_secs(5),
            idle_timeout: Duration::from_secs(60),
        }
    }
}

/// One open connection, as the registry sees it.
#[derive(Debug)]
struct Connection {
    opened: Instant,
    /// Whether a whole request has arrived on it.
    served: AtomicBool,
    /// Requests whose response is not yet fully sent.
    in_flight: AtomicUsize,
    /// When the last response finished (ms since `opened`).
    last_done_ms: AtomicU64,
    /// Told to close to make room for a newer connection.
    evicted: Notify,
    /// Already told: not to be chosen again while it closes.
    leaving: AtomicBool,
}

impl Connection {
    fn idle_for(&self, now: Instant) -> Duration {
        let since_open = now.saturating_duration_since(self.opened);
        since_open.saturating_sub(Duration::from_millis(
            self.last_done_ms.load(Ordering::Relaxed),
        ))
    }

    /// Why this connection should close now, if it should.
    fn expired(&self, now: Instant, limits: &ConnectionLimits) -> Option<&'static str> {
        if self.in_flight.load(Ordering::Relaxed) > 0 {
            return None;
        }
        let idle = self.idle_for(now);
        if !self.served.load(Ordering::Relaxed) && idle > limits.request_timeout {
            Some("no whole request in time")
        } else if idle > limits.idle_timeout {
            Some("idle")
        } else {
            None
        }
    }
}

/// The open connections.
#[derive(Debug, Default)]
pub struct Connections {
    next_id: AtomicU64,
    open: Mutex<BTreeMap<u64, Arc<Connection>>>,
    /// Told whenever a connection closes.
    closed: Notify,
}

impl Connections {
    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<Connection>>> {
        self.open.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// How many are open.
    pub fn count(&self) -> usize {
        self.lock().len()
    }

    /// Registers a new connection, making room if the limit is reached.
    /// `None`: every open connection is in use, and the new one is refused.
    fn admit(&self, limits: &ConnectionLimits) -> Option<(u64, Arc<Connection>)> {
        let mut open = self.lock();
        if open.len() >= limits.max_connections {
            let now = Instant::now();
            let staying = || open.values().filter(|c| !c.leaving.load(Ordering::Relaxed));
            let never_served = staying()
                .find(|c| !c.served.load(Ordering::Relaxed))
                .cloned();
            let victim = never_served.or_else(|| {
                staying()
                    .filter(|c| c.in_flight.load(Ordering::Relaxed) == 0)
                    .max_by_key(|c| c.idle_for(now))
                    .cloned()
            });
            match victim {
                // It leaves the registry when its task ends; until then the
                // new one may exceed the limit by the few being closed.
                Some(victim) => {
                    victim.leaving.store(true, Ordering::Relaxed);
                    victim.evicted.notify_one();
                }
                None => return None,
            }
        }
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let connection = Arc::new(Connection {
            opened: Instant::now(),
            served: AtomicBool::new(false),
            in_flight: AtomicUsize::new(0),
            last_done_ms: AtomicU64::new(0),
            evicted: Notify::new(),
            leaving: AtomicBool::new(false),
        });
        open.insert(id, connection.clone());
        Some((id, connection))
    }

    fn remove(&self, id: u64) {
        self.lock().remove(&id);
        self.closed.notify_waiters();
    }

    /// Waits until every connection has closed.
    pub async fn all_closed(&self) {
        loop {
            let closed = self.closed.notified();
            if self.count() == 0 {
                return;
            }
            closed.await;
        }
    }
}

/// Marks a request in flight until dropped (with its response's body).
struct InFlight(Arc<Connection>);

impl InFlight {
    fn new(connection: &Arc<Connection>) -> Self {
        connection.served.store(true, Ordering::Relaxed);
        connection.in_flight.fetch_add(1, Ordering::Relaxed);
        Self(connection.clone())
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        let since_open = Instant::now().saturating_duration_since(self.0.opened);
        self.0.last_done_ms.store(
            u64::try_from(since_open.as_millis()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
        self.0.in_flight.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Accepts a connection from the listener: registers it, then serves it on a
/// task of its own until it closes, is closed for its timeouts or to make
/// room, or the service stops (`stopping` becomes true: the connection
/// finishes its request and closes).
pub fn spawn(
    stream: TcpStream,
    peer: SocketAddr,
    app: Router,
    connections: Arc<Connections>,
    limits: ConnectionLimits,
    mut stopping: watch::Receiver<bool>,
) {
    let Some((id, connection)) = connections.admit(&limits) else {
        tracing::warn!(%peer, "refused a connection: all {} are in use", limits.max_connections);
        return;
    };
    tokio::spawn(async move {
        let tracked = connection.clone();
        let service = hyper::service::service_fn(move |mut request: hyper::Request<Incoming>| {
            let in_flight = InFlight::new(&tracked);
            request.extensions_mut().insert(ConnectInfo(peer));
            let mut app = app.clone();
            async move {
                let response = app.call(request).await?;
                // A body of known size goes out at once, with its length. A
                // stream (the live events) stays in flight while it is sent,
                // so that it is never taken for idle.
                if HttpBody::size_hint(response.body()).exact().is_some() {
                    return Ok(response);
                }
                Ok::<_, std::convert::Infallible>(response.map(|body| {
                    Body::from_stream(body.into_data_stream().map(move |chunk| {
                        let _ = &in_flight;
                        chunk
                    }))
                }))
            }
        });
        let served = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(limits.request_timeout)
            .serve_connection(TokioIo::new(stream), service);
        let mut served = std::pin::pin!(served);
        let mut check = tokio::time::interval(Duration::from_millis(250));
        loop {
            tokio::select! {
                _ = served.as_mut() => break,
                _ = connection.evicted.notified() => {
                    tracing::debug!(%peer, "closed a connection to make room");
                    break;
                }
                _ = check.tick() => {
                    if let Some(why) = connection.expired(Instant::now(), &limits) {
                        tracing::debug!(%peer, why, "closed a connection");
                        break;
                    }
                }
                changed = stopping.changed() => {
                    if changed.is_err() || *stopping.borrow() {
                        served.as_mut().graceful_shutdown();
                        let _ = tokio::time::timeout(limits.request_timeout, served.as_mut()).await;
                        break;
                    }
                }
            }
        }
        connections.remove(id);
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(max: usize) -> ConnectionLimits {
        ConnectionLimits {
            max_connections: max,
            ..ConnectionLimits::default()
        }
    }

    #[test]
    fn a_full_house_makes_room_by_closing_the_oldest_that_never_sent_a_request() {
        let connections = Connections::default();
        let (_, operator) = connections.admit(&limits(3)).unwrap();
        let _request = InFlight::new(&operator);
        let (_, first_idle) = connections.admit(&limits(3)).unwrap();
        let (_, second_idle) = connections.admit(&limits(3)).unwrap();
        // Full: the oldest that never sent a request is told to go.
        assert!(connections.admit(&limits(3)).is_some());
        let told = |c: &Arc<Connection>| {
            let notified = c.evicted.notified();
            let mut notified = std::pin::pin!(notified);
            // A stored permit completes at once.
            std::future::Future::poll(
                notified.as_mut(),
                &mut std::task::Context::from_waker(std::task::Waker::noop()),
            )
            .is_ready()
        };
        assert!(told(&first_idle));
        assert!(!told(&second_idle));
        assert!(!told(&operator));
    }

    #[test]
    fn a_house_full_of_requests_in_flight_refuses_the_newcomer() {
        let connections = Connections::default();
        let (_, a) = connections.admit(&limits(1)).unwrap();
        let request = InFlight::new(&a);
        assert!(connections.admit(&limits(1)).is_none());
        drop(request);
        assert!(connections.admit(&limits(1)).is_some());
    }

    #[test]
    fn silence_closes_a_connection_but_a_stream_in_flight_stays() {
        let connections = Connections::default();
        let (_, c) = connections.admit(&limits(4)).unwrap();
        let l = ConnectionLimits::default();
        let later = |d: Duration| c.opened + d;
        assert_eq!(c.expired(later(Duration::from_secs(1)), &l), None);
        assert_eq!(
            c.expired(later(Duration::from_secs(6)), &l),
            Some("no whole request in time")
        );
        let stream = InFlight::new(&c);
        assert_eq!(c.expired(later(Duration::from_secs(600)), &l), None);
        drop(stream);
        // Served: only the idle timeout applies, from the end of the response.
        let done = Duration::from_millis(c.last_done_ms.load(Ordering::Relaxed));
        assert_eq!(c.expired(later(done + Duration::from_secs(30)), &l), None);
        assert_eq!(
            c.expired(later(done + Duration::from_secs(61)), &l),
            Some("idle")
        );
    }
}
