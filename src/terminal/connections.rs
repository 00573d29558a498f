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
//! event stream of a page is never taken for idle. Streams therefore have a
//! budget of their own, or they would take every slot and then nothing
//! could be evicted to make room for the operator's Abort:
//! - at most [`ConnectionLimits::max_streams`] are open at once, and at most
//!   [`ConnectionLimits::max_streams_per_client`] from one address; a new
//!   stream closes that client's oldest (or, over the whole budget, the
//!   oldest of all) so that a page that reconnects always gets its stream;
//! - the operator's page, which shows the token (a one-use ticket for the
//!   stream, `POST /api/stream-ticket`), has a budget of its own,
//!   [`ConnectionLimits::max_operator_streams`]: a stream opened without the
//!   token never closes one opened with it, however many addresses it
//!   comes from, so strangers cannot starve the operator's live view;
//! - the slots left, `max_connections` less both budgets, are for short
//!   requests (status, Abort) and can never be taken by streams.
//!
//! A page whose stream is closed reconnects with a back-off and meanwhile
//! polls the status (`page.js`).

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
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
    /// Live event streams open at once (each holds a connection).
    pub max_streams: usize,
    /// Live event streams open at once from one address: a few pages on one
    /// phone or pad.
    pub max_streams_per_client: usize,
    /// Live event streams of the operator's pages (opened with the token's
    /// ticket) open at once, beside `max_streams`.
    pub max_operator_streams: usize,
}

/// Whose a live event stream is, for the streams' budgets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StreamOwner {
    /// Anyone on the network: no token was shown.
    #[default]
    Anyone,
    /// A page that showed the token (`POST /api/stream-ticket`).
    Operator,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 256,
            request_timeout: Duration::from_secs(5),
            idle_timeout: Duration::from_secs(60),
            max_streams: 32,
            max_streams_per_client: 4,
            max_operator_streams: 8,
        }
    }
}

/// One open connection, as the registry sees it.
#[derive(Debug)]
struct Connection {
    opened: Instant,
    /// Who it is from, for the per-client budget of streams.
    client: IpAddr,
    /// Carries a live event stream (since when, µs since `opened`; 0: none).
    stream_since_us: AtomicU64,
    /// Its stream is the operator's ([`StreamOwner::Operator`]).
    operator_stream: AtomicBool,
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
    fn is_stream(&self) -> bool {
        self.stream_since_us.load(Ordering::Relaxed) > 0
    }

    /// When its stream started, to find the oldest.
    fn stream_started(&self) -> Instant {
        self.opened + Duration::from_micros(self.stream_since_us.load(Ordering::Relaxed))
    }

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

    /// How many live event streams are open (not counting those told to go).
    pub fn streams(&self) -> usize {
        self.lock()
            .values()
            .filter(|c| c.is_stream() && !c.leaving.load(Ordering::Relaxed))
            .count()
    }

    /// Marks `connection` as carrying a live event stream of `owner`, within
    /// that owner's budget (streams of the other owner are never touched):
    /// over the client's share its own oldest stream is told to close, else
    /// over the whole budget the oldest of all.
    fn start_stream(
        &self,
        connection: &Arc<Connection>,
        limits: &ConnectionLimits,
        owner: StreamOwner,
    ) {
        let operator = owner == StreamOwner::Operator;
        let budget = if operator {
            limits.max_operator_streams
        } else {
            limits.max_streams
        };
        let open = self.lock();
        let streams: Vec<&Arc<Connection>> = open
            .values()
            .filter(|c| {
                c.is_stream()
                    && c.operator_stream.load(Ordering::Relaxed) == operator
                    && !c.leaving.load(Ordering::Relaxed)
                    && !Arc::ptr_eq(c, connection)
            })
            .collect();
        let own: Vec<&&Arc<Connection>> = streams
            .iter()
            .filter(|c| c.client == connection.client)
            .collect();
        let victim = if own.len() >= limits.max_streams_per_client {
            own.into_iter()
                .min_by_key(|c| c.stream_started())
                .map(|c| (*c).clone())
        } else if streams.len() >= budget {
            streams
                .iter()
                .min_by_key(|c| c.stream_started())
                .map(|c| (*c).clone())
        } else {
            None
        };
        if let Some(victim) = victim {
            victim.leaving.store(true, Ordering::Relaxed);
            victim.evicted.notify_one();
        }
        connection
            .operator_stream
            .store(operator, Ordering::Relaxed);
        let since_open = Instant::now().saturating_duration_since(connection.opened);
        connection.stream_since_us.store(
            u64::try_from(since_open.as_micros())
                .unwrap_or(u64::MAX)
                .max(1),
            Ordering::Relaxed,
        );
    }

    /// Registers a new connection from `client`, making room if the limit
    /// is reached. `None`: every open connection is in use, and the new one
    /// is refused.
    fn admit(&self, limits: &ConnectionLimits, client: IpAddr) -> Option<(u64, Arc<Connection>)> {
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
            client,
            stream_since_us: AtomicU64::new(0),
            operator_stream: AtomicBool::new(false),
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

/// Marks a connection's live stream until dropped (with the stream).
struct StreamSlot(Arc<Connection>);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.stream_since_us.store(0, Ordering::Relaxed);
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
    let Some((id, connection)) = connections.admit(&limits, peer.ip()) else {
        tracing::warn!(%peer, "refused a connection: all {} are in use", limits.max_connections);
        return;
    };
    tokio::spawn(async move {
        let tracked = connection.clone();
        let registry = connections.clone();
        let service = hyper::service::service_fn(move |mut request: hyper::Request<Incoming>| {
            let in_flight = InFlight::new(&tracked);
            request.extensions_mut().insert(ConnectInfo(peer));
            let mut app = app.clone();
            let (tracked, registry) = (tracked.clone(), registry.clone());
            async move {
                let response = app.call(request).await?;
                // A body of known size goes out at once, with its length. A
                // stream (the live events) stays in flight while it is sent,
                // so that it is never taken for idle, and takes a place in
                // the streams' budget.
                if HttpBody::size_hint(response.body()).exact().is_some() {
                    return Ok(response);
                }
                let owner = response
                    .extensions()
                    .get::<StreamOwner>()
                    .copied()
                    .unwrap_or_default();
                registry.start_stream(&tracked, &limits, owner);
                let streaming = StreamSlot(tracked);
                Ok::<_, std::convert::Infallible>(response.map(|body| {
                    Body::from_stream(body.into_data_stream().map(move |chunk| {
                        let _ = (&in_flight, &streaming);
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

    const LOCAL: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

    fn told(c: &Arc<Connection>) -> bool {
        let notified = c.evicted.notified();
        let mut notified = std::pin::pin!(notified);
        // A stored permit completes at once.
        std::future::Future::poll(
            notified.as_mut(),
            &mut std::task::Context::from_waker(std::task::Waker::noop()),
        )
        .is_ready()
    }

    #[test]
    fn streams_keep_to_their_budget_per_client_and_in_all() {
        let connections = Connections::default();
        let l = ConnectionLimits {
            max_streams: 3,
            max_streams_per_client: 2,
            ..ConnectionLimits::default()
        };
        let client = |n: u8| IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, n));
        let stream = |ip| {
            let (_, c) = connections.admit(&l, ip).unwrap();
            let _request = InFlight::new(&c);
            connections.start_stream(&c, &l, StreamOwner::Anyone);
            std::thread::sleep(Duration::from_millis(2));
            c
        };
        // One client's third stream closes its own oldest.
        let a1 = stream(client(1));
        let a2 = stream(client(1));
        let a3 = stream(client(1));
        assert!(told(&a1) && !told(&a2) && !told(&a3));
        assert_eq!(connections.streams(), 2);
        // Over the whole budget, the oldest of all goes, whoever it is.
        let b1 = stream(client(2));
        assert_eq!(connections.streams(), 3);
        let c1 = stream(client(3));
        assert!(told(&a2) && !told(&a3) && !told(&b1) && !told(&c1));
        assert_eq!(connections.streams(), 3);
        // A stream that ended frees its place.
        a3.stream_since_us.store(0, Ordering::Relaxed);
        assert_eq!(connections.streams(), 2);
    }

    /// Streams opened without the token, from any number of addresses,
    /// never close the operator's; the operator's pages keep to a budget of
    /// their own.
    #[test]
    fn strangers_streams_never_close_the_operators() {
        let connections = Connections::default();
        let l = ConnectionLimits {
            max_streams: 4,
            max_streams_per_client: 2,
            max_operator_streams: 2,
            ..ConnectionLimits::default()
        };
        let stream = |n: u8, owner| {
            let ip = IpAddr::V4(std::net::Ipv4Addr::new(127, 0, 0, n));
            let (_, c) = connections.admit(&l, ip).unwrap();
            let _request = InFlight::new(&c);
            connections.start_stream(&c, &l, owner);
            std::thread::sleep(Duration::from_millis(2));
            c
        };
        let operator = stream(1, StreamOwner::Operator);
        let strangers: Vec<_> = (0..40)
            .map(|k| stream(2 + (k % 10) as u8, StreamOwner::Anyone))
            .collect();
        assert!(
            !told(&operator),
            "a stranger's stream closed the operator's"
        );
        assert!(strangers.iter().filter(|c| !told(c)).count() <= l.max_streams);
        // The operator's own pages share its budget: a third closes the oldest.
        let second = stream(1, StreamOwner::Operator);
        let third = stream(1, StreamOwner::Operator);
        assert!(told(&operator) && !told(&second) && !told(&third));
    }

    fn limits(max: usize) -> ConnectionLimits {
        ConnectionLimits {
            max_connections: max,
            ..ConnectionLimits::default()
        }
    }

    #[test]
    fn a_full_house_makes_room_by_closing_the_oldest_that_never_sent_a_request() {
        let connections = Connections::default();
        let (_, operator) = connections.admit(&limits(3), LOCAL).unwrap();
        let _request = InFlight::new(&operator);
        let (_, first_idle) = connections.admit(&limits(3), LOCAL).unwrap();
        let (_, second_idle) = connections.admit(&limits(3), LOCAL).unwrap();
        // Full: the oldest that never sent a request is told to go.
        assert!(connections.admit(&limits(3), LOCAL).is_some());
        assert!(told(&first_idle));
        assert!(!told(&second_idle));
        assert!(!told(&operator));
    }

    #[test]
    fn a_house_full_of_requests_in_flight_refuses_the_newcomer() {
        let connections = Connections::default();
        let (_, a) = connections.admit(&limits(1), LOCAL).unwrap();
        let request = InFlight::new(&a);
        assert!(connections.admit(&limits(1), LOCAL).is_none());
        drop(request);
        assert!(connections.admit(&limits(1), LOCAL).is_some());
    }

    #[test]
    fn silence_closes_a_connection_but_a_stream_in_flight_stays() {
        let connections = Connections::default();
        let (_, c) = connections.admit(&limits(4), LOCAL).unwrap();
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
