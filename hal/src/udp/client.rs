//! The upper computer's side of `hexapod-udp.md`, as a state machine without
//! I/O: requests, received datagrams and the time go in; datagrams to send and
//! events come out ([`Client::poll_transmit`], [`Client::poll_event`]). The
//! tokio task in [`super::link`] owns the socket and the clock and drives it;
//! tests drive it with a fake clock.
//!
//! What it guarantees:
//! - one exchange at a time; further requests wait in order;
//! - every new request gets the next `seq` (never reused, across sessions
//!   too, so a reply's `seq` alone identifies its request);
//! - a request with no reply is sent again, byte for byte, every retry
//!   interval, up to the retry limit; then it fails with link lost;
//! - replies from another address, duplicates and stale replies (another
//!   `seq`) are ignored;
//! - ACK 3 (unknown session: the lower computer restarted) starts a new
//!   session (HELLO with a new nonce) and then sends the request again as a new
//!   request; a request sent before any session first opens one;
//! - while the body is moving (an accepted SET_POSE or HOME, until a STATE
//!   says otherwise) and nothing else is in flight, a GET_STATE goes out every
//!   keep-alive interval, so that the lower computer's 1 s watchdog never
//!   fires because the caller was busy.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::proto::{self, AckStatus, Datagram, Message, SetPose, StatePayload, WelcomePayload};
use crate::controller::{BodyLimits, BodyState, MotionState, Welcome};
use groundcal_calib::geometry::PoseDegMm;

/// Timing of the protocol on the upper computer's side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientConfig {
    /// How long to wait for a reply before sending the request again.
    pub retry_interval: Duration,
    /// How many times a request is sent again before the link is lost.
    pub retry_limit: u32,
    /// The longest silence towards the lower computer while the body moves
    /// (its watchdog halts after 1 s; the spec asks for at most 200 ms).
    pub keepalive_interval: Duration,
    /// How many times in a row a request may meet an unknown session (and
    /// a new one be opened for it) before this is a protocol failure.
    pub max_session_renewals: u32,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            retry_interval: Duration::from_millis(100),
            retry_limit: 10,
            keepalive_interval: Duration::from_millis(150),
            max_session_renewals: 3,
        }
    }
}

/// What the caller asks of the lower computer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    Hello,
    SetPose {
        pose_id: u16,
        pose: PoseDegMm,
        duration_ms: u32,
    },
    GetState,
    Home {
        duration_ms: u32,
    },
    Halt,
    Bye,
}

impl Request {
    /// The message's name, for errors and logs.
    pub fn name(&self) -> &'static str {
        match self {
            Request::Hello => "HELLO",
            Request::SetPose { .. } => "SET_POSE",
            Request::GetState => "GET_STATE",
            Request::Home { .. } => "HOME",
            Request::Halt => "HALT",
            Request::Bye => "BYE",
        }
    }

    fn message(&self) -> Message {
        match *self {
            // HELLOs are built with their nonce by `Client::send_hello`.
            Request::Hello => Message::Hello { nonce: 0 },
            Request::SetPose {
                pose_id,
                pose,
                duration_ms,
            } => Message::SetPose(SetPose {
                pose_id,
                alpha_deg: pose.alpha_deg as f32,
                beta_deg: pose.beta_deg as f32,
                gamma_deg: pose.gamma_deg as f32,
                px_mm: pose.px_mm as f32,
                py_mm: pose.py_mm as f32,
                pz_mm: pose.pz_mm as f32,
                duration_ms,
            }),
            Request::GetState => Message::GetState,
            Request::Home { duration_ms } => Message::Home { duration_ms },
            Request::Halt => Message::Halt,
            Request::Bye => Message::Bye,
        }
    }
}

/// Names one submitted request in its [`Event::Completed`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RequestId(pub u64);

/// A successful answer.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// To HELLO.
    Welcome(Welcome),
    /// ACK 0, to SET_POSE, HOME, HALT and BYE.
    Accepted,
    /// To GET_STATE.
    State(BodyState),
}

/// Why a request failed.
#[derive(Debug, Clone, PartialEq)]
pub enum Failure {
    /// No reply after the retry limit.
    LinkLost {
        request: &'static str,
        sends: u32,
        waited: Duration,
    },
    /// A motion command not sent, or not sent again: it was asked for
    /// longer than [`MOTION_FRESH`] ago.
    NotSentInTime {
        request: &'static str,
        waited: Duration,
    },
    /// ACK 1, 2 or 4.
    Refused {
        request: &'static str,
        status: AckStatus,
    },
    /// An answer that does not fit the request.
    Protocol(String),
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::LinkLost {
                request,
                sends,
                waited,
            } => write!(
                f,
                "no answer to {request} after {sends} sends over {} ms",
                waited.as_millis()
            ),
            Failure::Refused { request, status } => {
                write!(f, "the lower computer refused {request}: {status}")
            }
            Failure::NotSentInTime { request, waited } => write!(
                f,
                "{request} not sent (or not sent again): asked for {} ms ago, more than {} ms \
                 (the lower computer's watchdog may have halted the body meanwhile)",
                waited.as_millis(),
                MOTION_FRESH.as_millis()
            ),
            Failure::Protocol(what) => f.write_str(what),
        }
    }
}

/// What happened, for the I/O layer.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A submitted request is answered, or failed.
    Completed {
        id: RequestId,
        result: Result<Reply, Failure>,
    },
    /// A session began: asked for (HELLO), or opened automatically (before a
    /// first request, or after the lower computer forgot the last one).
    SessionStarted { welcome: Welcome, automatic: bool },
    /// A STATE arrived (answer to the caller or to a keep-alive).
    State(BodyState),
    /// A keep-alive GET_STATE failed; nobody waits for it, so it is said here.
    KeepAliveFailed(Failure),
}

/// A datagram to send.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Transmit {
    pub destination: SocketAddr,
    pub bytes: Vec<u8>,
}

/// Counters, for logs and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ClientStats {
    /// Datagrams sent for the first time (one per exchange).
    pub requests: u64,
    /// Datagrams sent again unchanged.
    pub retransmissions: u64,
    /// Replies that completed an exchange.
    pub replies: u64,
    /// Replies whose `seq` is not the one in flight (duplicates, late ones).
    pub stale: u64,
    /// Datagrams from an address other than the lower computer's.
    pub foreign: u64,
    /// Datagrams that do not decode (CRC, length, ...).
    pub malformed: u64,
    /// Requests (not replies) received: not ours to answer.
    pub unexpected: u64,
    /// Sessions opened after an ACK 3.
    pub renewals: u64,
    /// Keep-alive GET_STATEs started.
    pub keepalives: u64,
    /// Exchanges that ran out of retries.
    pub links_lost: u64,
}

/// A caller's request (or a keep-alive, without id) on its way.
#[derive(Debug, Clone)]
struct Job {
    id: Option<RequestId>,
    request: Request,
    /// Sessions opened for it so far after ACK 3.
    renewals: u32,
    /// When the caller asked for it (none for the client's own
    /// keep-alives and a caller's HELLO, which move nothing).
    issued: Option<Instant>,
}

/// A motion command is not sent, nor sent again, once this long has passed
/// since it was asked for: the lower computer's watchdog (1 s,
/// hexapod-udp.md) may have halted the body meanwhile, and the caller
/// decided to move before the wait (a process stopped and resumed, a request
/// ahead of it retried over a lossy link). A retransmission is acted on if
/// the first send was lost, so it is held to the same bound. The caller
/// learns why and ends the run (HALT and HOME are never held back). Longer
/// than the default retries' 1.1 s, so that a link that only loses
/// datagrams still ends as lost.
pub const MOTION_FRESH: Duration = Duration::from_millis(1500);

impl Job {
    /// How long ago a motion command was asked for, when that is longer
    /// than [`MOTION_FRESH`] (none for any other request).
    fn stale_motion(&self, now: Instant) -> Option<Duration> {
        let waited = now.saturating_duration_since(self.issued?);
        (matches!(self.request, Request::SetPose { .. }) && waited > MOTION_FRESH).then_some(waited)
    }
}

/// Why a HELLO is in flight.
#[derive(Debug, Clone)]
enum HelloFor {
    /// The caller asked for it.
    Caller(RequestId),
    /// A request that needs a session first.
    Job(Job),
}

#[derive(Debug, Clone)]
enum Exchange {
    Hello { nonce: u32, purpose: HelloFor },
    Request(Job),
}

/// The one datagram in flight.
#[derive(Debug, Clone)]
struct InFlight {
    seq: u32,
    bytes: Vec<u8>,
    sends: u32,
    first_sent: Instant,
    deadline: Instant,
    exchange: Exchange,
}

/// The upper computer's protocol state.
#[derive(Debug)]
pub struct Client {
    peer: SocketAddr,
    config: ClientConfig,
    rng: ChaCha8Rng,
    session: Option<u32>,
    next_seq: u32,
    next_id: u64,
    queue: VecDeque<(RequestId, Request, Instant)>,
    in_flight: Option<InFlight>,
    /// The body is (believed) moving: keep-alives are due.
    motion_expected: bool,
    last_sent: Option<Instant>,
    last_state: Option<BodyState>,
    transmits: VecDeque<Transmit>,
    events: VecDeque<Event>,
    stats: ClientStats,
}

impl Client {
    /// A client of the lower computer at `peer`. `seed` picks the nonces and
    /// the first `seq`; give each run of the program a different one, so
    /// that a restarted upper computer is not taken for its former life.
    pub fn new(peer: SocketAddr, config: ClientConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Anywhere in the lower half, so that 2^31 requests fit before `seq`
        // would wrap.
        let next_seq = rng.next_u32() >> 1;
        Self {
            peer,
            config,
            rng,
            session: None,
            next_seq,
            next_id: 0,
            queue: VecDeque::new(),
            in_flight: None,
            motion_expected: false,
            last_sent: None,
            last_state: None,
            transmits: VecDeque::new(),
            events: VecDeque::new(),
            stats: ClientStats::default(),
        }
    }

    /// The lower computer's address.
    pub fn peer(&self) -> SocketAddr {
        self.peer
    }

    /// The current session, if one is open.
    pub fn session(&self) -> Option<u32> {
        self.session
    }

    /// The last STATE received.
    pub fn last_state(&self) -> Option<&BodyState> {
        self.last_state.as_ref()
    }

    /// Whether the body is believed to be moving (keep-alives are sent).
    pub fn motion_expected(&self) -> bool {
        self.motion_expected
    }

    pub fn stats(&self) -> &ClientStats {
        &self.stats
    }

    /// Whether nothing is in flight or waiting.
    pub fn is_idle(&self) -> bool {
        self.in_flight.is_none() && self.queue.is_empty()
    }

    /// Queues a request; it is answered by an [`Event::Completed`] with the
    /// returned id.
    pub fn submit(&mut self, request: Request, now: Instant) -> RequestId {
        self.submit_issued(request, now, now)
    }

    /// [`Client::submit`] of a request the caller asked for at `issued`
    /// (before it reached the client): a motion command is not sent once it
    /// is older than [`MOTION_FRESH`].
    pub fn submit_issued(&mut self, request: Request, issued: Instant, now: Instant) -> RequestId {
        let id = RequestId(self.next_id);
        self.next_id += 1;
        self.queue.push_back((id, request, issued));
        self.start_next(now);
        id
    }

    /// The next datagram to send.
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        self.transmits.pop_front()
    }

    /// The next event.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When [`Client::handle_timeout`] should next be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        match &self.in_flight {
            Some(f) => Some(f.deadline),
            None => self.keepalive_due(),
        }
    }

    fn keepalive_due(&self) -> Option<Instant> {
        if self.motion_expected && self.session.is_some() && self.queue.is_empty() {
            // Motion is expected only after a request was sent.
            self.last_sent.map(|t| t + self.config.keepalive_interval)
        } else {
            None
        }
    }

    /// Retransmits, declares the link lost, or sends a keep-alive, as due.
    pub fn handle_timeout(&mut self, now: Instant) {
        if let Some(flight) = &mut self.in_flight {
            if now < flight.deadline {
                return;
            }
            let stale = match &flight.exchange {
                Exchange::Request(job) => job.stale_motion(now).map(|w| (job.request.name(), w)),
                Exchange::Hello { .. } => None,
            };
            if let Some((request, waited)) = stale {
                let Some(flight) = self.in_flight.take() else {
                    return;
                };
                self.finish(
                    flight.exchange,
                    Err(Failure::NotSentInTime { request, waited }),
                );
                self.start_next(now);
                return;
            }
            if flight.sends <= self.config.retry_limit {
                flight.sends += 1;
                flight.deadline = now + self.config.retry_interval;
                self.transmits.push_back(Transmit {
                    destination: self.peer,
                    bytes: flight.bytes.clone(),
                });
                self.stats.retransmissions += 1;
                self.last_sent = Some(now);
                return;
            }
            let Some(flight) = self.in_flight.take() else {
                return;
            };
            self.stats.links_lost += 1;
            // The body's state is unknown now; the watchdog is the safety.
            self.motion_expected = false;
            let request = match &flight.exchange {
                Exchange::Hello { .. } => "HELLO",
                Exchange::Request(job) => job.request.name(),
            };
            let failure = Failure::LinkLost {
                request,
                sends: flight.sends,
                waited: now.saturating_duration_since(flight.first_sent),
            };
            self.finish(flight.exchange, Err(failure));
            self.start_next(now);
            return;
        }
        if let Some(due) = self.keepalive_due() {
            if now >= due {
                self.stats.keepalives += 1;
                self.send_request(
                    Job {
                        id: None,
                        request: Request::GetState,
                        renewals: 0,
                        issued: None,
                    },
                    now,
                );
            }
        }
    }

    /// A datagram received from `from`.
    pub fn handle_datagram(&mut self, bytes: &[u8], from: SocketAddr, now: Instant) {
        if from != self.peer {
            self.stats.foreign += 1;
            return;
        }
        let datagram = match proto::decode(bytes) {
            Ok(d) => d,
            Err(e) => {
                // A reply to the exchange in flight that is intact up to its
                // payload is the lower computer's mistake, not the network's:
                // retrying would get the same answer.
                let ours = e.header().is_some_and(|h| {
                    proto::kind::is_reply(h.kind)
                        && self.in_flight.as_ref().is_some_and(|f| f.seq == h.seq)
                });
                if ours {
                    if let Some(flight) = self.in_flight.take() {
                        self.stats.replies += 1;
                        let what = format!("malformed reply: {e}");
                        self.finish(flight.exchange, Err(Failure::Protocol(what)));
                        self.start_next(now);
                    }
                } else {
                    self.stats.malformed += 1;
                }
                return;
            }
        };
        if !proto::kind::is_reply(datagram.message.kind()) {
            self.stats.unexpected += 1;
            return;
        }
        let matches = self.in_flight.as_ref().is_some_and(|f| {
            f.seq == datagram.seq
                && match (&f.exchange, &datagram.message) {
                    // A WELCOME for another HELLO with this seq (a former
                    // life's) is not ours.
                    (Exchange::Hello { nonce, .. }, Message::Welcome(w)) => w.nonce == *nonce,
                    _ => true,
                }
        });
        if !matches {
            self.stats.stale += 1;
            return;
        }
        let Some(flight) = self.in_flight.take() else {
            return;
        };
        self.stats.replies += 1;
        match flight.exchange {
            Exchange::Hello { purpose, .. } => self.on_hello_reply(purpose, &datagram, now),
            Exchange::Request(job) => self.on_request_reply(job, &datagram, now),
        }
        self.start_next(now);
    }

    fn on_hello_reply(&mut self, purpose: HelloFor, datagram: &Datagram, now: Instant) {
        let welcome = match datagram.message {
            Message::Welcome(w) if w.session != 0 => welcome_from(&w),
            Message::Welcome(_) => {
                let what = "the lower computer granted session 0".to_string();
                self.finish_hello(purpose, Err(Failure::Protocol(what)));
                return;
            }
            other => {
                let what = format!("{} in answer to HELLO", describe(&other));
                self.finish_hello(purpose, Err(Failure::Protocol(what)));
                return;
            }
        };
        self.session = Some(welcome.session);
        self.events.push_back(Event::SessionStarted {
            welcome: welcome.clone(),
            automatic: matches!(purpose, HelloFor::Job(_)),
        });
        match purpose {
            HelloFor::Caller(id) => self.events.push_back(Event::Completed {
                id,
                result: Ok(Reply::Welcome(welcome)),
            }),
            HelloFor::Job(job) => self.send_request(job, now),
        }
    }

    fn on_request_reply(&mut self, mut job: Job, datagram: &Datagram, now: Instant) {
        let request = job.request;
        let result = match (request, datagram.message) {
            // The session is gone either way.
            (Request::Bye, Message::Ack(AckStatus::Accepted | AckStatus::UnknownSession)) => {
                self.session = None;
                self.motion_expected = false;
                Ok(Reply::Accepted)
            }
            (_, Message::Ack(AckStatus::UnknownSession)) => {
                self.session = None;
                if job.renewals >= self.config.max_session_renewals {
                    Err(Failure::Protocol(format!(
                        "the lower computer forgot the session {} times in a row",
                        job.renewals + 1
                    )))
                } else {
                    // The lower computer restarted: a new session, then the
                    // request again, as a new request.
                    job.renewals += 1;
                    self.stats.renewals += 1;
                    self.motion_expected = false;
                    self.send_hello(HelloFor::Job(job), now);
                    return;
                }
            }
            (Request::SetPose { .. } | Request::Home { .. }, Message::Ack(AckStatus::Accepted)) => {
                self.motion_expected = true;
                Ok(Reply::Accepted)
            }
            (Request::Halt, Message::Ack(AckStatus::Accepted)) => {
                self.motion_expected = false;
                Ok(Reply::Accepted)
            }
            (_, Message::Ack(status)) if status != AckStatus::Accepted => Err(Failure::Refused {
                request: request.name(),
                status,
            }),
            (Request::GetState, Message::State(s)) => {
                let state = body_state_from(&s);
                self.motion_expected = state.state == MotionState::Moving;
                self.last_state = Some(state);
                self.events.push_back(Event::State(state));
                Ok(Reply::State(state))
            }
            (_, other) => Err(Failure::Protocol(format!(
                "{} in answer to {}",
                describe(&other),
                request.name()
            ))),
        };
        self.finish(Exchange::Request(job), result);
    }

    /// Reports the end of an exchange to whoever waits for it.
    fn finish(&mut self, exchange: Exchange, result: Result<Reply, Failure>) {
        match exchange {
            Exchange::Hello { purpose, .. } => self.finish_hello(purpose, result),
            Exchange::Request(job) => match job.id {
                Some(id) => self.events.push_back(Event::Completed { id, result }),
                None => {
                    if let Err(failure) = result {
                        self.events.push_back(Event::KeepAliveFailed(failure));
                    }
                }
            },
        }
    }

    fn finish_hello(&mut self, purpose: HelloFor, result: Result<Reply, Failure>) {
        let job = match purpose {
            HelloFor::Caller(id) => Job {
                id: Some(id),
                request: Request::Hello,
                renewals: 0,
                issued: None,
            },
            HelloFor::Job(job) => job,
        };
        self.finish(Exchange::Request(job), result);
    }

    /// Starts the next queued request if nothing is in flight.
    fn start_next(&mut self, now: Instant) {
        if self.in_flight.is_some() {
            return;
        }
        let Some((id, request, issued)) = self.queue.pop_front() else {
            return;
        };
        let job = Job {
            id: Some(id),
            request,
            renewals: 0,
            issued: Some(issued),
        };
        match (request, self.session) {
            (Request::Hello, _) => self.send_hello(HelloFor::Caller(id), now),
            (_, None) => self.send_hello(HelloFor::Job(job), now),
            (_, Some(_)) => self.send_request(job, now),
        }
    }

    fn take_seq(&mut self) -> u32 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    fn send_hello(&mut self, purpose: HelloFor, now: Instant) {
        let nonce = self.rng.next_u32();
        let datagram = Datagram {
            session: 0,
            seq: self.take_seq(),
            message: Message::Hello { nonce },
        };
        self.send_new(datagram, Exchange::Hello { nonce, purpose }, now);
    }

    fn send_request(&mut self, job: Job, now: Instant) {
        if let Some(waited) = job.stale_motion(now) {
            let request = job.request.name();
            self.finish(
                Exchange::Request(job),
                Err(Failure::NotSentInTime { request, waited }),
            );
            self.start_next(now);
            return;
        }
        let Some(session) = self.session else {
            self.send_hello(HelloFor::Job(job), now);
            return;
        };
        let datagram = Datagram {
            session,
            seq: self.take_seq(),
            message: job.request.message(),
        };
        self.send_new(datagram, Exchange::Request(job), now);
    }

    fn send_new(&mut self, datagram: Datagram, exchange: Exchange, now: Instant) {
        let bytes = proto::encode(&datagram);
        self.transmits.push_back(Transmit {
            destination: self.peer,
            bytes: bytes.clone(),
        });
        self.stats.requests += 1;
        self.last_sent = Some(now);
        self.in_flight = Some(InFlight {
            seq: datagram.seq,
            bytes,
            sends: 1,
            first_sent: now,
            deadline: now + self.config.retry_interval,
            exchange,
        });
    }
}

fn describe(message: &Message) -> String {
    match message {
        Message::Ack(status) => status.to_string(),
        other => other.name().to_string(),
    }
}

/// The caller's view of a WELCOME.
pub fn welcome_from(w: &WelcomePayload) -> Welcome {
    Welcome {
        session: w.session,
        limits: BodyLimits {
            max_tilt_deg: f64::from(w.max_tilt_deg),
            min_height_mm: f64::from(w.min_height_mm),
            max_height_mm: f64::from(w.max_height_mm),
            max_shift_mm: f64::from(w.max_shift_mm),
        },
        firmware: w.firmware_text(),
    }
}

/// The caller's view of a STATE.
pub fn body_state_from(s: &StatePayload) -> BodyState {
    BodyState {
        state: s.state,
        pose_id: s.pose_id,
        time_us: s.time_us,
        feet_mm: s.feet_mm.map(|f| f.map(f64::from)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::udp::proto::{decode, encode, StatePayload};

    const PEER: &str = "192.0.2.10:7400";

    fn peer() -> SocketAddr {
        PEER.parse().unwrap()
    }

    /// A client with a fake clock starting at `t0`.
    struct Harness {
        client: Client,
        t0: Instant,
        now: Instant,
    }

    impl Harness {
        fn new() -> Self {
            let t0 = Instant::now();
            Self {
                client: Client::new(peer(), ClientConfig::default(), 42),
                t0,
                now: t0,
            }
        }

        fn advance_ms(&mut self, ms: u64) {
            self.now += Duration::from_millis(ms);
            self.client.handle_timeout(self.now);
        }

        fn sent(&mut self) -> Vec<Datagram> {
            let mut out = Vec::new();
            while let Some(t) = self.client.poll_transmit() {
                assert_eq!(t.destination, peer());
                out.push(decode(&t.bytes).expect("the client sends valid datagrams"));
            }
            out
        }

        fn sent_bytes(&mut self) -> Vec<Vec<u8>> {
            std::iter::from_fn(|| self.client.poll_transmit().map(|t| t.bytes)).collect()
        }

        fn events(&mut self) -> Vec<Event> {
            std::iter::from_fn(|| self.client.poll_event()).collect()
        }

        fn reply(&mut self, to: &Datagram, session: u32, message: Message) {
            let bytes = encode(&Datagram {
                session,
                seq: to.seq,
                message,
            });
            self.client.handle_datagram(&bytes, peer(), self.now);
        }

        fn welcome(&mut self, hello: &Datagram, session: u32) {
            let Message::Hello { nonce } = hello.message else {
                panic!("not a HELLO: {hello:?}");
            };
            self.reply(
                hello,
                session,
                Message::Welcome(welcome_payload(session, nonce)),
            );
        }

        /// HELLO → WELCOME with `session`.
        fn open(&mut self, session: u32) {
            let id = self.client.submit(Request::Hello, self.now);
            let hello = self.sent().pop().unwrap();
            self.welcome(&hello, session);
            let events = self.events();
            assert!(
                events.iter().any(|e| matches!(e,
                    Event::Completed { id: i, result: Ok(Reply::Welcome(w)) }
                        if *i == id && w.session == session)),
                "{events:?}"
            );
        }
    }

    fn welcome_payload(session: u32, nonce: u32) -> WelcomePayload {
        WelcomePayload {
            session,
            nonce,
            max_tilt_deg: 25.0,
            min_height_mm: 500.0,
            max_height_mm: 800.0,
            max_shift_mm: 100.0,
            firmware: WelcomePayload::firmware_field("test"),
        }
    }

    fn state(state: MotionState, pose_id: u16) -> Message {
        Message::State(StatePayload {
            state,
            pose_id,
            time_us: 1,
            feet_mm: [[1.0, -600.0, 2.0]; 6],
        })
    }

    fn pose() -> PoseDegMm {
        PoseDegMm {
            alpha_deg: 0.0,
            beta_deg: 2.0,
            gamma_deg: 20.0,
            px_mm: 0.0,
            py_mm: 615.0,
            pz_mm: 0.0,
        }
    }

    fn set_pose(pose_id: u16) -> Request {
        Request::SetPose {
            pose_id,
            pose: pose(),
            duration_ms: 1000,
        }
    }

    /// A SET_POSE that waits behind another request (or in a process that
    /// was stopped) longer than [`MOTION_FRESH`] is not sent: it ends as not
    /// sent in time, and the next request goes; one that waits less goes.
    /// A retransmission of one already sent goes whatever its age.
    #[test]
    fn a_motion_command_too_old_to_send_is_not_sent() {
        for (wait_ms, sent) in [(1400, true), (1600, false), (3000, false)] {
            let mut h = Harness::new();
            h.open(7);
            let state_id = h.client.submit(Request::GetState, h.now);
            let get_state = h.sent().pop().unwrap();
            let pose_id = h.client.submit_issued(set_pose(3), h.now, h.now);
            let after = h.client.submit(Request::GetState, h.now);
            assert!(h.sent().is_empty(), "queued behind the GET_STATE");
            // The process stood still (no timeout handled), then the answer.
            h.now += Duration::from_millis(wait_ms);
            h.reply(&get_state, 7, state(MotionState::Idle, 0));
            let out = h.sent();
            let events = completed(&h.events());
            assert_eq!(events[0].0, state_id, "{wait_ms} ms: {events:?}");
            if sent {
                assert!(
                    matches!(
                        out[..],
                        [Datagram {
                            message: Message::SetPose { .. },
                            ..
                        }]
                    ),
                    "{out:?}"
                );
                continue;
            }
            let (id, Err(Failure::NotSentInTime { request, waited })) = &events[1] else {
                panic!("{wait_ms} ms: {events:?}");
            };
            assert_eq!((*id, *request), (pose_id, "SET_POSE"));
            assert_eq!(*waited, Duration::from_millis(wait_ms));
            assert!(events[1]
                .1
                .as_ref()
                .unwrap_err()
                .to_string()
                .contains("not sent"));
            // The next request goes instead.
            assert!(
                matches!(
                    out[..],
                    [Datagram {
                        message: Message::GetState,
                        ..
                    }]
                ),
                "{out:?}"
            );
            let _ = after;
        }
        // Sent in time and not answered: sent again within the bound, not
        // after the process stood still (were the first send lost, the
        // lower computer would act on the second).
        let mut h = Harness::new();
        h.open(7);
        let id = h.client.submit_issued(set_pose(4), h.now, h.now);
        let first = h.sent().pop().unwrap();
        h.advance_ms(100);
        assert_eq!(h.sent(), vec![first], "a retransmission within the bound");
        h.advance_ms(3000);
        assert!(h.sent().is_empty(), "nothing sent after the stand-still");
        let events = completed(&h.events());
        assert!(
            matches!(events[..], [(i, Err(Failure::NotSentInTime { request: "SET_POSE", .. }))] if i == id),
            "{events:?}"
        );
    }

    fn completed(events: &[Event]) -> Vec<(RequestId, Result<Reply, Failure>)> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Completed { id, result } => Some((*id, result.clone())),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn hello_opens_a_session_and_requests_count_up() {
        let mut h = Harness::new();
        h.open(77);
        assert_eq!(h.client.session(), Some(77));
        let id = h.client.submit(set_pose(1), h.now);
        let first = h.sent().pop().unwrap();
        assert_eq!(first.session, 77);
        h.reply(&first, 77, Message::Ack(AckStatus::Accepted));
        assert_eq!(completed(&h.events()), vec![(id, Ok(Reply::Accepted))]);
        h.client.submit(Request::GetState, h.now);
        let second = h.sent().pop().unwrap();
        assert_eq!(second.seq, first.seq + 1);
        assert_eq!(second.message, Message::GetState);
    }

    #[test]
    fn a_request_without_a_session_opens_one_first() {
        let mut h = Harness::new();
        let id = h.client.submit(Request::GetState, h.now);
        let hello = h.sent().pop().unwrap();
        assert!(matches!(hello.message, Message::Hello { .. }));
        assert_eq!(hello.session, 0);
        h.welcome(&hello, 5);
        let get = h.sent().pop().unwrap();
        assert_eq!((get.session, get.seq), (5, hello.seq + 1));
        h.reply(&get, 5, state(MotionState::Idle, 0));
        let events = h.events();
        assert!(matches!(
            events[0],
            Event::SessionStarted {
                automatic: true,
                ..
            }
        ));
        assert!(matches!(
            completed(&events)[..],
            [(i, Ok(Reply::State(_)))] if i == id
        ));
    }

    #[test]
    fn retransmits_the_same_bytes_every_interval_then_loses_the_link() {
        let mut h = Harness::new();
        h.open(1);
        let id = h.client.submit(set_pose(3), h.now);
        let original = h.sent_bytes();
        assert_eq!(original.len(), 1);
        for retry in 1..=10 {
            h.advance_ms(99);
            assert!(h.sent_bytes().is_empty(), "retry {retry} too early");
            h.advance_ms(1);
            assert_eq!(h.sent_bytes(), original, "retry {retry}");
        }
        h.advance_ms(100);
        assert!(h.sent_bytes().is_empty());
        match &completed(&h.events())[..] {
            [(
                i,
                Err(Failure::LinkLost {
                    sends: 11, waited, ..
                }),
            )] => {
                assert_eq!(*i, id);
                assert_eq!(*waited, Duration::from_millis(1100));
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(h.client.stats().retransmissions, 10);
        assert!(h.now > h.t0);
    }

    #[test]
    fn ignores_duplicates_stale_replies_and_other_addresses() {
        let mut h = Harness::new();
        h.open(9);
        h.client.submit(Request::GetState, h.now);
        let first = h.sent().pop().unwrap();
        h.reply(&first, 9, state(MotionState::Idle, 0));
        h.events();
        h.client.submit(set_pose(1), h.now);
        let second = h.sent().pop().unwrap();
        // The first reply again (a duplicate): ignored.
        h.reply(&first, 9, state(MotionState::Idle, 0));
        // The right seq from another address: ignored.
        let bytes = encode(&Datagram {
            session: 9,
            seq: second.seq,
            message: Message::Ack(AckStatus::Accepted),
        });
        h.client
            .handle_datagram(&bytes, "192.0.2.11:7400".parse().unwrap(), h.now);
        // Garbage: ignored.
        h.client.handle_datagram(&bytes[..7], peer(), h.now);
        assert!(h.events().is_empty());
        assert_eq!(h.client.stats().stale, 1);
        assert_eq!(h.client.stats().foreign, 1);
        assert_eq!(h.client.stats().malformed, 1);
        h.client.handle_datagram(&bytes, peer(), h.now);
        assert!(matches!(
            completed(&h.events())[..],
            [(_, Ok(Reply::Accepted))]
        ));
        // And its duplicate after completion: ignored.
        h.client.handle_datagram(&bytes, peer(), h.now);
        assert!(h.events().is_empty());
        assert_eq!(h.client.stats().stale, 2);
    }

    #[test]
    fn unknown_session_renews_it_and_resends_as_a_new_request() {
        let mut h = Harness::new();
        h.open(100);
        let id = h.client.submit(set_pose(21), h.now);
        let before = h.sent().pop().unwrap();
        h.reply(&before, 100, Message::Ack(AckStatus::UnknownSession));
        let hello = h.sent().pop().unwrap();
        let Message::Hello { nonce } = hello.message else {
            panic!("{hello:?}");
        };
        assert_eq!(hello.seq, before.seq + 1);
        assert!(h.events().is_empty(), "the caller still waits");
        // A WELCOME with the wrong nonce is not ours.
        h.reply(
            &hello,
            200,
            Message::Welcome(welcome_payload(200, nonce.wrapping_add(1))),
        );
        assert!(h.sent().is_empty());
        h.welcome(&hello, 200);
        let again = h.sent().pop().unwrap();
        assert_eq!((again.session, again.seq), (200, hello.seq + 1));
        assert_eq!(again.message, before.message);
        h.reply(&again, 200, Message::Ack(AckStatus::Accepted));
        let events = h.events();
        assert!(matches!(
            events[0],
            Event::SessionStarted {
                automatic: true,
                ..
            }
        ));
        assert_eq!(completed(&events), vec![(id, Ok(Reply::Accepted))]);
        assert_eq!(h.client.stats().renewals, 1);
    }

    #[test]
    fn each_hello_has_a_new_nonce() {
        let mut h = Harness::new();
        let mut nonces = Vec::new();
        for session in 1..=5 {
            h.client.submit(Request::Hello, h.now);
            let hello = h.sent().pop().unwrap();
            let Message::Hello { nonce } = hello.message else {
                panic!()
            };
            nonces.push(nonce);
            h.welcome(&hello, session);
        }
        nonces.sort();
        nonces.dedup();
        assert_eq!(nonces.len(), 5);
    }

    #[test]
    fn a_lower_computer_that_keeps_forgetting_is_a_protocol_failure() {
        let mut h = Harness::new();
        h.open(1);
        let id = h.client.submit(Request::GetState, h.now);
        let mut session = 1;
        for _ in 0..=3 {
            let request = h.sent().pop().unwrap();
            h.reply(&request, session, Message::Ack(AckStatus::UnknownSession));
            if let Some(hello) = h.sent().pop() {
                session += 1;
                h.welcome(&hello, session);
            }
        }
        assert!(matches!(
            completed(&h.events())[..],
            [(i, Err(Failure::Protocol(_)))] if i == id
        ));
    }

    #[test]
    fn refusals_carry_the_status() {
        let mut h = Harness::new();
        h.open(1);
        let id = h.client.submit(set_pose(1), h.now);
        let request = h.sent().pop().unwrap();
        h.reply(&request, 1, Message::Ack(AckStatus::OutsideLimits));
        assert_eq!(
            completed(&h.events()),
            vec![(
                id,
                Err(Failure::Refused {
                    request: "SET_POSE",
                    status: AckStatus::OutsideLimits
                })
            )]
        );
    }

    #[test]
    fn a_wrong_kind_of_answer_is_a_protocol_failure() {
        let mut h = Harness::new();
        h.open(1);
        h.client.submit(set_pose(1), h.now);
        let request = h.sent().pop().unwrap();
        h.reply(&request, 1, state(MotionState::Moving, 1));
        assert!(matches!(
            completed(&h.events())[..],
            [(_, Err(Failure::Protocol(_)))]
        ));
        // A malformed reply with the right seq, too.
        h.client.submit(Request::GetState, h.now);
        let request = h.sent().pop().unwrap();
        let mut bytes = encode(&Datagram {
            session: 1,
            seq: request.seq,
            message: Message::Ack(AckStatus::Accepted),
        });
        bytes[16] = 99;
        let n = bytes.len() - 4;
        bytes.truncate(n);
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        h.client.handle_datagram(&bytes, peer(), h.now);
        assert!(matches!(
            completed(&h.events())[..],
            [(_, Err(Failure::Protocol(_)))]
        ));
    }

    #[test]
    fn keeps_the_watchdog_fed_while_moving() {
        let mut h = Harness::new();
        h.open(1);
        h.client.submit(set_pose(1), h.now);
        let request = h.sent().pop().unwrap();
        h.reply(&request, 1, Message::Ack(AckStatus::Accepted));
        h.events();
        assert!(h.client.motion_expected());
        // Nothing is sent before the keep-alive interval, then a GET_STATE.
        h.advance_ms(149);
        assert!(h.sent().is_empty());
        h.advance_ms(1);
        let keepalive = h.sent().pop().unwrap();
        assert_eq!(keepalive.message, Message::GetState);
        h.advance_ms(20);
        h.reply(&keepalive, 1, state(MotionState::Moving, 1));
        assert!(matches!(h.events()[..], [Event::State(_)]));
        // Measured from the last send.
        h.advance_ms(129);
        assert!(h.sent().is_empty());
        h.advance_ms(1);
        let keepalive = h.sent().pop().unwrap();
        h.reply(&keepalive, 1, state(MotionState::Settled, 1));
        h.events();
        assert!(!h.client.motion_expected());
        h.advance_ms(1000);
        assert!(h.sent().is_empty(), "no keep-alive once settled");
    }

    #[test]
    fn a_request_waits_for_the_keepalive_in_flight() {
        let mut h = Harness::new();
        h.open(1);
        h.client.submit(Request::Home { duration_ms: 500 }, h.now);
        let request = h.sent().pop().unwrap();
        h.reply(&request, 1, Message::Ack(AckStatus::Accepted));
        h.advance_ms(150);
        let keepalive = h.sent().pop().unwrap();
        let id = h.client.submit(Request::Halt, h.now);
        assert!(h.sent().is_empty(), "one exchange at a time");
        h.reply(&keepalive, 1, state(MotionState::Moving, 0));
        let halt = h.sent().pop().unwrap();
        assert_eq!(halt.message, Message::Halt);
        assert_eq!(halt.seq, keepalive.seq + 1);
        h.reply(&halt, 1, Message::Ack(AckStatus::Accepted));
        assert!(completed(&h.events()).contains(&(id, Ok(Reply::Accepted))));
        assert!(!h.client.motion_expected());
    }

    #[test]
    fn bye_succeeds_even_if_its_ack_was_lost_and_the_session_forgotten() {
        let mut h = Harness::new();
        h.open(4);
        let id = h.client.submit(Request::Bye, h.now);
        let bye = h.sent().pop().unwrap();
        h.reply(&bye, 4, Message::Ack(AckStatus::UnknownSession));
        assert_eq!(completed(&h.events()), vec![(id, Ok(Reply::Accepted))]);
        assert_eq!(h.client.session(), None);
        assert!(h.sent().is_empty(), "no new session for a BYE");
    }
}
