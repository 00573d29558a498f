//! The lower computer's side of `hexapod-udp.md`, without I/O: a datagram,
//! its source address and the time go in; the reply to send back (if any)
//! and a [`Receipt`] of what was done come out. The body itself is behind
//! the [`Body`] trait (the simulated hexapod in [`crate::sim::robot`]).
//!
//! The rules it keeps:
//! - a datagram with a wrong magic, version, length or CRC is dropped and
//!   counted, never answered;
//! - HELLO grants a new nonzero session, replacing any earlier one, except
//!   that a HELLO with the same `seq` and nonce from the same address as the
//!   one that opened the current session is a retransmission: same WELCOME;
//! - a request of another session gets ACK 3;
//! - the last reply of the session is kept: a request with its `seq` gets it
//!   again and is not acted on twice; a lower `seq` is stale and dropped;
//! - SET_POSE outside the limits gets ACK 1, a payload that is not a request
//!   of its type (or not finite numbers) ACK 4, motion refused by the body
//!   ACK 2;
//! - the watchdog: while the body moves and nothing valid has come from the
//!   session for the watchdog period, the body is halted.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::proto::{
    self, kind, AckStatus, Datagram, DecodeError, Message, StatePayload, WelcomePayload,
};
use crate::controller::{BodyLimits, BodyState, MotionState};
use groundcal_calib::geometry::PoseDegMm;

/// What the lower computer moves: the protocol asks, the body acts.
pub trait Body {
    /// The limits announced in WELCOME and checked for SET_POSE.
    fn limits(&self) -> BodyLimits;
    /// The firmware name announced in WELCOME.
    fn firmware(&self) -> String;
    /// Starts a motion to `pose` (limits already checked).
    fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
        now: Instant,
    ) -> Result<(), Refusal>;
    /// Starts a motion to the home stance.
    fn home(&mut self, duration_ms: u32, now: Instant) -> Result<(), Refusal>;
    /// Stops where the body is.
    fn halt(&mut self, now: Instant);
    /// The state and the feet now.
    fn state(&mut self, now: Instant) -> BodyState;
    /// The motion state now (without measuring the feet).
    fn motion(&mut self, now: Instant) -> MotionState;
}

/// The body cannot move in its present state (ACK 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refusal;

/// Why a commanded pose is not acceptable.
#[derive(Debug, Clone, PartialEq)]
pub enum PoseRejection {
    /// A value is NaN or infinite (ACK 4).
    NotFinite,
    /// Outside the limits (ACK 1), with which and why.
    OutsideLimits(String),
}

impl PoseRejection {
    pub fn status(&self) -> AckStatus {
        match self {
            PoseRejection::NotFinite => AckStatus::Malformed,
            PoseRejection::OutsideLimits(_) => AckStatus::OutsideLimits,
        }
    }
}

impl std::fmt::Display for PoseRejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PoseRejection::NotFinite => f.write_str("a value is not a finite number"),
            PoseRejection::OutsideLimits(why) => f.write_str(why),
        }
    }
}

/// The SET_POSE check of `hexapod-udp.md`: `|alpha|, |beta|, |gamma| ≤
/// max_tilt_deg`, `min_height_mm ≤ py ≤ max_height_mm`, `|px|, |pz| ≤
/// max_shift_mm`.
pub fn check_pose(limits: &BodyLimits, pose: &PoseDegMm) -> Result<(), PoseRejection> {
    if !pose.is_finite() {
        return Err(PoseRejection::NotFinite);
    }
    for (name, value) in [
        ("alpha", pose.alpha_deg),
        ("beta", pose.beta_deg),
        ("gamma", pose.gamma_deg),
    ] {
        if value.abs() > limits.max_tilt_deg {
            return Err(PoseRejection::OutsideLimits(format!(
                "{name} = {value}° is beyond ±{}°",
                limits.max_tilt_deg
            )));
        }
    }
    if pose.py_mm < limits.min_height_mm || pose.py_mm > limits.max_height_mm {
        return Err(PoseRejection::OutsideLimits(format!(
            "py = {} mm is outside {}..{} mm",
            pose.py_mm, limits.min_height_mm, limits.max_height_mm
        )));
    }
    for (name, value) in [("px", pose.px_mm), ("pz", pose.pz_mm)] {
        if value.abs() > limits.max_shift_mm {
            return Err(PoseRejection::OutsideLimits(format!(
                "{name} = {value} mm is beyond ±{} mm",
                limits.max_shift_mm
            )));
        }
    }
    Ok(())
}

/// The lower computer's protocol settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServerConfig {
    /// Halt a moving body after this long without a valid datagram from the
    /// session's upper computer.
    pub watchdog: Duration,
    /// Picks the session numbers.
    pub seed: u64,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            watchdog: Duration::from_secs(1),
            seed: 0,
        }
    }
}

/// What became of one received datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// A HELLO that opened a new session.
    NewSession,
    /// A HELLO answered again with its WELCOME.
    HelloRetransmission,
    /// A new request, acted on.
    New,
    /// The last request again: answered with the same reply, not acted on.
    Retransmission,
    /// A `seq` below the last one: dropped.
    Stale,
    /// Another session's request: ACK 3.
    UnknownSession,
    /// Not a datagram of version 1, or not a request: dropped.
    Dropped(&'static str),
}

impl Outcome {
    pub fn name(&self) -> &'static str {
        match self {
            Outcome::NewSession => "new_session",
            Outcome::HelloRetransmission => "hello_retransmission",
            Outcome::New => "new",
            Outcome::Retransmission => "retransmission",
            Outcome::Stale => "stale",
            Outcome::UnknownSession => "unknown_session",
            Outcome::Dropped(_) => "dropped",
        }
    }
}

/// What the server did with a datagram, for logs and tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Receipt {
    /// The type code, when the header was readable.
    pub kind: Option<u8>,
    pub session: u32,
    pub seq: u32,
    /// SET_POSE's pose id.
    pub pose_id: Option<u16>,
    pub outcome: Outcome,
    /// The status, when the reply is an ACK.
    pub ack: Option<AckStatus>,
}

/// The result of [`Server::handle`].
#[derive(Debug, Clone, PartialEq)]
pub struct Handled {
    /// The datagram to send back to the source address.
    pub reply: Option<Vec<u8>>,
    pub receipt: Receipt,
}

/// Counters of what the server received and did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ServerCounters {
    pub received: u64,
    pub dropped_length: u64,
    pub dropped_magic: u64,
    pub dropped_version: u64,
    pub dropped_crc: u64,
    pub dropped_type: u64,
    /// Replies (WELCOME, ACK, STATE) sent to the lower computer.
    pub dropped_not_request: u64,
    pub malformed_payload: u64,
    pub sessions: u64,
    pub hello_retransmissions: u64,
    pub new_requests: u64,
    pub retransmissions: u64,
    pub stale: u64,
    pub unknown_session: u64,
    pub watchdog_halts: u64,
}

#[derive(Debug, Clone)]
struct Session {
    id: u32,
    /// The HELLO that opened it: source, seq and nonce.
    hello: (SocketAddr, u32, u32),
    welcome: Vec<u8>,
    /// The last request's seq and the reply sent to it.
    last: Option<(u32, Vec<u8>)>,
    /// BYE was received: only a retransmitted BYE is still answered.
    ended: bool,
}

/// The lower computer's protocol state.
#[derive(Debug)]
pub struct Server {
    config: ServerConfig,
    rng: ChaCha8Rng,
    session: Option<Session>,
    /// The last valid datagram of the current session (the watchdog's food).
    last_heard: Option<Instant>,
    counters: ServerCounters,
}

impl Server {
    pub fn new(config: ServerConfig) -> Self {
        Self {
            config,
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            session: None,
            last_heard: None,
            counters: ServerCounters::default(),
        }
    }

    pub fn counters(&self) -> &ServerCounters {
        &self.counters
    }

    /// The current session, if one is open.
    pub fn session(&self) -> Option<u32> {
        self.session.as_ref().filter(|s| !s.ended).map(|s| s.id)
    }

    /// Handles one received datagram.
    pub fn handle(
        &mut self,
        bytes: &[u8],
        from: SocketAddr,
        now: Instant,
        body: &mut impl Body,
    ) -> Handled {
        self.counters.received += 1;
        match proto::decode(bytes) {
            Ok(datagram) => self.handle_datagram(&datagram, from, now, body),
            Err(error) => self.handle_malformed(&error, now),
        }
    }

    /// When the watchdog would fire if nothing is heard, while the body moves.
    pub fn watchdog_deadline(&self) -> Option<Instant> {
        self.last_heard.map(|t| t + self.config.watchdog)
    }

    /// Halts a moving body whose upper computer fell silent; true if it did.
    pub fn poll_watchdog(&mut self, now: Instant, body: &mut impl Body) -> bool {
        if body.motion(now) != MotionState::Moving {
            return false;
        }
        let silent = match self.last_heard {
            Some(t) => now.saturating_duration_since(t) >= self.config.watchdog,
            None => true,
        };
        if silent {
            body.halt(now);
            self.counters.watchdog_halts += 1;
        }
        silent
    }

    fn handle_malformed(&mut self, error: &DecodeError, now: Instant) -> Handled {
        let dropped = |reason| Handled {
            reply: None,
            receipt: Receipt {
                kind: error.header().map(|h| h.kind),
                session: error.header().map_or(0, |h| h.session),
                seq: error.header().map_or(0, |h| h.seq),
                pose_id: None,
                outcome: Outcome::Dropped(reason),
                ack: None,
            },
        };
        let header = match (error, error.header()) {
            (DecodeError::UnknownType { .. }, _) => {
                self.counters.dropped_type += 1;
                return dropped("type");
            }
            (_, Some(h)) if kind::is_request(h.kind) => h,
            (_, Some(_)) => {
                self.counters.dropped_not_request += 1;
                return dropped("not a request");
            }
            (_, None) => {
                let counter = match error.reason() {
                    "magic" => &mut self.counters.dropped_magic,
                    "version" => &mut self.counters.dropped_version,
                    "crc" => &mut self.counters.dropped_crc,
                    _ => &mut self.counters.dropped_length,
                };
                *counter += 1;
                return dropped(error.reason());
            }
        };
        // A request intact but for its payload: ACK 4, under the usual
        // session and seq rules (a HELLO has no session yet).
        self.counters.malformed_payload += 1;
        let ack = |session| {
            proto::encode(&Datagram {
                session,
                seq: header.seq,
                message: Message::Ack(AckStatus::Malformed),
            })
        };
        if header.kind == kind::HELLO {
            return Handled {
                reply: Some(ack(0)),
                receipt: Receipt {
                    kind: Some(header.kind),
                    session: header.session,
                    seq: header.seq,
                    pose_id: None,
                    outcome: Outcome::New,
                    ack: Some(AckStatus::Malformed),
                },
            };
        }
        self.in_session(header.kind, header.session, header.seq, None, now, |_| {
            (ack(header.session), Some(AckStatus::Malformed))
        })
    }

    fn handle_datagram(
        &mut self,
        datagram: &Datagram,
        from: SocketAddr,
        now: Instant,
        body: &mut impl Body,
    ) -> Handled {
        let kind = datagram.message.kind();
        if !kind::is_request(kind) {
            self.counters.dropped_not_request += 1;
            return Handled {
                reply: None,
                receipt: Receipt {
                    kind: Some(kind),
                    session: datagram.session,
                    seq: datagram.seq,
                    pose_id: None,
                    outcome: Outcome::Dropped("not a request"),
                    ack: None,
                },
            };
        }
        if let Message::Hello { nonce } = datagram.message {
            return self.hello(datagram.seq, nonce, from, now, body);
        }
        let pose_id = match datagram.message {
            Message::SetPose(p) => Some(p.pose_id),
            _ => None,
        };
        let session = datagram.session;
        let seq = datagram.seq;
        let message = datagram.message;
        self.in_session(kind, session, seq, pose_id, now, |server| {
            server.act(&message, session, seq, now, body)
        })
    }

    fn hello(
        &mut self,
        seq: u32,
        nonce: u32,
        from: SocketAddr,
        now: Instant,
        body: &mut impl Body,
    ) -> Handled {
        let receipt = |session, outcome| Receipt {
            kind: Some(kind::HELLO),
            session,
            seq,
            pose_id: None,
            outcome,
            ack: None,
        };
        if let Some(s) = self
            .session
            .as_ref()
            .filter(|s| s.hello == (from, seq, nonce))
        {
            self.counters.hello_retransmissions += 1;
            self.last_heard = Some(now);
            return Handled {
                reply: Some(s.welcome.clone()),
                receipt: receipt(s.id, Outcome::HelloRetransmission),
            };
        }
        let previous = self.session.as_ref().map(|s| s.id);
        let id = loop {
            let candidate = self.rng.next_u32();
            if candidate != 0 && Some(candidate) != previous {
                break candidate;
            }
        };
        let limits = body.limits();
        let welcome = proto::encode(&Datagram {
            session: id,
            seq,
            message: Message::Welcome(WelcomePayload {
                session: id,
                nonce,
                max_tilt_deg: limits.max_tilt_deg as f32,
                min_height_mm: limits.min_height_mm as f32,
                max_height_mm: limits.max_height_mm as f32,
                max_shift_mm: limits.max_shift_mm as f32,
                firmware: WelcomePayload::firmware_field(&body.firmware()),
            }),
        });
        self.session = Some(Session {
            id,
            hello: (from, seq, nonce),
            welcome: welcome.clone(),
            last: None,
            ended: false,
        });
        self.last_heard = Some(now);
        self.counters.sessions += 1;
        Handled {
            reply: Some(welcome),
            receipt: receipt(id, Outcome::NewSession),
        }
    }

    /// The session and seq rules around a request; `act` runs only for a new
    /// one and returns its reply.
    fn in_session(
        &mut self,
        kind: u8,
        session: u32,
        seq: u32,
        pose_id: Option<u16>,
        now: Instant,
        act: impl FnOnce(&mut Self) -> (Vec<u8>, Option<AckStatus>),
    ) -> Handled {
        let receipt = |outcome, ack| Receipt {
            kind: Some(kind),
            session,
            seq,
            pose_id,
            outcome,
            ack,
        };
        let current = self.session.as_ref().filter(|s| s.id == session);
        let last = current.and_then(|s| s.last.as_ref());
        let ended = current.is_some_and(|s| s.ended);
        match (current, last) {
            (Some(_), Some((last_seq, reply))) if seq == *last_seq => {
                let reply = reply.clone();
                self.counters.retransmissions += 1;
                self.last_heard = Some(now);
                let ack = proto::decode(&reply).ok().and_then(|d| match d.message {
                    Message::Ack(status) => Some(status),
                    _ => None,
                });
                return Handled {
                    reply: Some(reply),
                    receipt: receipt(Outcome::Retransmission, ack),
                };
            }
            (Some(_), Some((last_seq, _))) if seq < *last_seq && !ended => {
                self.counters.stale += 1;
                return Handled {
                    reply: None,
                    receipt: receipt(Outcome::Stale, None),
                };
            }
            (Some(_), _) if !ended => {}
            _ => {
                self.counters.unknown_session += 1;
                let reply = proto::encode(&Datagram {
                    session,
                    seq,
                    message: Message::Ack(AckStatus::UnknownSession),
                });
                return Handled {
                    reply: Some(reply),
                    receipt: receipt(Outcome::UnknownSession, Some(AckStatus::UnknownSession)),
                };
            }
        }
        self.counters.new_requests += 1;
        self.last_heard = Some(now);
        let (reply, ack) = act(self);
        if let Some(s) = self.session.as_mut() {
            s.last = Some((seq, reply.clone()));
        }
        Handled {
            reply: Some(reply),
            receipt: receipt(Outcome::New, ack),
        }
    }

    /// Acts on a new request of the current session.
    fn act(
        &mut self,
        message: &Message,
        session: u32,
        seq: u32,
        now: Instant,
        body: &mut impl Body,
    ) -> (Vec<u8>, Option<AckStatus>) {
        let status = match *message {
            Message::SetPose(p) => {
                let pose = PoseDegMm {
                    alpha_deg: f64::from(p.alpha_deg),
                    beta_deg: f64::from(p.beta_deg),
                    gamma_deg: f64::from(p.gamma_deg),
                    px_mm: f64::from(p.px_mm),
                    py_mm: f64::from(p.py_mm),
                    pz_mm: f64::from(p.pz_mm),
                };
                match check_pose(&body.limits(), &pose) {
                    Err(rejection) => rejection.status(),
                    Ok(()) => match body.set_pose(p.pose_id, &pose, p.duration_ms, now) {
                        Ok(()) => AckStatus::Accepted,
                        Err(Refusal) => AckStatus::RefusedInState,
                    },
                }
            }
            Message::Home { duration_ms } => match body.home(duration_ms, now) {
                Ok(()) => AckStatus::Accepted,
                Err(Refusal) => AckStatus::RefusedInState,
            },
            Message::Halt => {
                body.halt(now);
                AckStatus::Accepted
            }
            Message::Bye => {
                if let Some(s) = self.session.as_mut() {
                    s.ended = true;
                }
                AckStatus::Accepted
            }
            Message::GetState => {
                let state = body.state(now);
                let reply = proto::encode(&Datagram {
                    session,
                    seq,
                    message: Message::State(state_payload(&state)),
                });
                return (reply, None);
            }
            // HELLO and replies do not reach here.
            _ => AckStatus::Malformed,
        };
        let reply = proto::encode(&Datagram {
            session,
            seq,
            message: Message::Ack(status),
        });
        (reply, Some(status))
    }
}

/// STATE's payload of a body state.
pub fn state_payload(state: &BodyState) -> StatePayload {
    StatePayload {
        state: state.state,
        pose_id: state.pose_id,
        time_us: state.time_us,
        feet_mm: state.feet_mm.map(|f| f.map(|v| v as f32)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::udp::proto::{decode, encode};

    /// A body that records what it was asked and moves for a fixed time.
    #[derive(Debug, Default)]
    struct FakeBody {
        calls: Vec<String>,
        motion_until: Option<Instant>,
        halted: bool,
        fault: bool,
    }

    impl Body for FakeBody {
        fn limits(&self) -> BodyLimits {
            BodyLimits {
                max_tilt_deg: 25.0,
                min_height_mm: 500.0,
                max_height_mm: 800.0,
                max_shift_mm: 100.0,
            }
        }
        fn firmware(&self) -> String {
            "fake".into()
        }
        fn set_pose(
            &mut self,
            pose_id: u16,
            _: &PoseDegMm,
            duration_ms: u32,
            now: Instant,
        ) -> Result<(), Refusal> {
            if self.fault {
                return Err(Refusal);
            }
            self.calls.push(format!("set_pose {pose_id}"));
            self.motion_until = Some(now + Duration::from_millis(u64::from(duration_ms)));
            self.halted = false;
            Ok(())
        }
        fn home(&mut self, duration_ms: u32, now: Instant) -> Result<(), Refusal> {
            self.calls.push("home".into());
            self.motion_until = Some(now + Duration::from_millis(u64::from(duration_ms)));
            Ok(())
        }
        fn halt(&mut self, _: Instant) {
            self.calls.push("halt".into());
            self.motion_until = None;
            self.halted = true;
        }
        fn state(&mut self, now: Instant) -> BodyState {
            BodyState {
                state: self.motion(now),
                pose_id: 0,
                time_us: 0,
                feet_mm: [[0.0; 3]; 6],
            }
        }
        fn motion(&mut self, now: Instant) -> MotionState {
            match self.motion_until {
                Some(t) if now < t => MotionState::Moving,
                Some(_) => MotionState::Settled,
                None if self.halted => MotionState::Halted,
                None => MotionState::Idle,
            }
        }
    }

    struct Harness {
        server: Server,
        body: FakeBody,
        now: Instant,
        from: SocketAddr,
    }

    impl Harness {
        fn new() -> Self {
            Self {
                server: Server::new(ServerConfig::default()),
                body: FakeBody::default(),
                now: Instant::now(),
                from: "192.0.2.1:50000".parse().unwrap(),
            }
        }

        fn send(&mut self, session: u32, seq: u32, message: Message) -> Handled {
            let bytes = encode(&Datagram {
                session,
                seq,
                message,
            });
            self.server
                .handle(&bytes, self.from, self.now, &mut self.body)
        }

        fn reply(&mut self, session: u32, seq: u32, message: Message) -> Option<Datagram> {
            self.send(session, seq, message)
                .reply
                .map(|r| decode(&r).expect("replies decode"))
        }

        fn hello(&mut self, seq: u32, nonce: u32) -> u32 {
            match self.reply(0, seq, Message::Hello { nonce }) {
                Some(Datagram {
                    session,
                    message: Message::Welcome(w),
                    ..
                }) => {
                    assert_eq!(w.session, session);
                    assert_eq!(w.nonce, nonce);
                    assert_ne!(session, 0);
                    session
                }
                other => panic!("{other:?}"),
            }
        }

        fn advance_ms(&mut self, ms: u64) -> bool {
            self.now += Duration::from_millis(ms);
            self.server.poll_watchdog(self.now, &mut self.body)
        }
    }

    fn set_pose(pose_id: u16, py_mm: f32) -> Message {
        Message::SetPose(proto::SetPose {
            pose_id,
            alpha_deg: 0.0,
            beta_deg: 2.0,
            gamma_deg: 20.0,
            px_mm: 0.0,
            py_mm,
            pz_mm: 0.0,
            duration_ms: 10_000,
        })
    }

    fn ack(d: Option<Datagram>) -> Option<AckStatus> {
        match d?.message {
            Message::Ack(s) => Some(s),
            _ => None,
        }
    }

    #[test]
    fn hello_grants_new_sessions_and_retransmissions_get_the_same_welcome() {
        let mut h = Harness::new();
        let first = h.send(0, 10, Message::Hello { nonce: 1 });
        let again = h.send(0, 10, Message::Hello { nonce: 1 });
        assert_eq!(first.reply, again.reply);
        assert_eq!(again.receipt.outcome, Outcome::HelloRetransmission);
        let s1 = decode(first.reply.as_deref().unwrap()).unwrap().session;
        // Another nonce, or another address, is a new session.
        let s2 = h.hello(10, 2);
        assert_ne!(s1, s2);
        h.from = "192.0.2.2:50000".parse().unwrap();
        let s3 = h.hello(10, 2);
        assert_ne!(s2, s3);
        assert_eq!(h.server.session(), Some(s3));
        assert_eq!(h.server.counters().sessions, 3);
    }

    #[test]
    fn another_sessions_requests_get_ack_3() {
        let mut h = Harness::new();
        assert_eq!(
            ack(h.reply(5, 1, Message::GetState)),
            Some(AckStatus::UnknownSession)
        );
        let old = h.hello(1, 1);
        let new = h.hello(2, 2);
        let reply = h.reply(old, 3, Message::GetState).unwrap();
        assert_eq!(reply.message, Message::Ack(AckStatus::UnknownSession));
        assert_eq!((reply.session, reply.seq), (old, 3));
        assert!(matches!(
            h.reply(new, 3, Message::GetState).unwrap().message,
            Message::State(_)
        ));
    }

    #[test]
    fn a_retransmitted_set_pose_is_answered_but_not_acted_on_twice() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        let first = h.send(s, 2, set_pose(1, 615.0));
        assert_eq!(first.receipt.outcome, Outcome::New);
        assert_eq!(first.receipt.pose_id, Some(1));
        let again = h.send(s, 2, set_pose(1, 615.0));
        assert_eq!(again.receipt.outcome, Outcome::Retransmission);
        assert_eq!(first.reply, again.reply);
        assert_eq!(h.body.calls, vec!["set_pose 1"]);
        // A new request, then the old one late: stale, no reply.
        assert!(h.reply(s, 3, Message::GetState).is_some());
        let late = h.send(s, 2, set_pose(1, 615.0));
        assert_eq!(late.receipt.outcome, Outcome::Stale);
        assert!(late.reply.is_none());
        assert_eq!(h.body.calls, vec!["set_pose 1"]);
        assert_eq!(h.server.counters().retransmissions, 1);
        assert_eq!(h.server.counters().stale, 1);
    }

    #[test]
    fn limits_and_state_refusals() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        assert_eq!(
            ack(h.reply(s, 2, set_pose(1, 850.0))),
            Some(AckStatus::OutsideLimits)
        );
        assert_eq!(
            ack(h.reply(s, 3, set_pose(1, f32::NAN))),
            Some(AckStatus::Malformed)
        );
        h.body.fault = true;
        assert_eq!(
            ack(h.reply(s, 4, set_pose(1, 615.0))),
            Some(AckStatus::RefusedInState)
        );
        assert!(h.body.calls.is_empty());
    }

    #[test]
    fn check_pose_names_the_limit() {
        let limits = FakeBody::default().limits();
        let mut pose = PoseDegMm {
            alpha_deg: 0.0,
            beta_deg: 0.0,
            gamma_deg: 25.0,
            px_mm: -100.0,
            py_mm: 500.0,
            pz_mm: 100.0,
        };
        assert_eq!(check_pose(&limits, &pose), Ok(()));
        pose.gamma_deg = -25.5;
        assert!(
            matches!(check_pose(&limits, &pose), Err(PoseRejection::OutsideLimits(w)) if w.contains("gamma"))
        );
        pose.gamma_deg = 0.0;
        pose.pz_mm = 101.0;
        assert!(
            matches!(check_pose(&limits, &pose), Err(PoseRejection::OutsideLimits(w)) if w.contains("pz"))
        );
    }

    #[test]
    fn malformed_datagrams_are_dropped_and_counted() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        let good = encode(&Datagram {
            session: s,
            seq: 2,
            message: Message::GetState,
        });
        let mut bad_crc = good.clone();
        bad_crc[8] ^= 1;
        let mut bad_magic = good.clone();
        bad_magic[1] = 0;
        for bytes in [&bad_crc[..], &bad_magic[..], &good[..5], &[][..]] {
            let handled = h.server.handle(bytes, h.from, h.now, &mut h.body);
            assert!(handled.reply.is_none());
            assert!(matches!(handled.receipt.outcome, Outcome::Dropped(_)));
        }
        let c = h.server.counters();
        assert_eq!(
            (c.dropped_crc, c.dropped_magic, c.dropped_length),
            (1, 1, 2)
        );
        // A reply sent to the lower computer: dropped too.
        assert!(h
            .send(s, 3, Message::Ack(AckStatus::Accepted))
            .reply
            .is_none());
    }

    #[test]
    fn a_malformed_payload_gets_ack_4_once() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        let mut bytes = encode(&Datagram {
            session: s,
            seq: 2,
            message: Message::Home { duration_ms: 10 },
        });
        // A HOME with a 3-byte payload, length and CRC consistent.
        bytes.truncate(bytes.len() - 5);
        bytes[12] = 3;
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        let first = h.server.handle(&bytes, h.from, h.now, &mut h.body);
        assert_eq!(first.receipt.ack, Some(AckStatus::Malformed));
        let again = h.server.handle(&bytes, h.from, h.now, &mut h.body);
        assert_eq!(again.receipt.outcome, Outcome::Retransmission);
        assert_eq!(first.reply, again.reply);
        assert!(h.body.calls.is_empty());
    }

    #[test]
    fn the_watchdog_halts_a_moving_body_after_one_second_of_silence() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        h.reply(s, 2, set_pose(1, 615.0));
        // Fed every 200 ms, even by retransmissions: no halt.
        let mut seq = 3;
        for i in 0..8 {
            assert!(!h.advance_ms(200));
            if i % 2 == 0 {
                seq += 1;
            }
            h.reply(s, seq, Message::GetState);
        }
        // Stale datagrams and other sessions do not feed it.
        assert!(!h.advance_ms(500));
        h.reply(s, 1, Message::GetState);
        h.reply(s.wrapping_add(1), 99, Message::GetState);
        assert!(!h.advance_ms(499));
        assert!(h.advance_ms(1));
        assert_eq!(h.body.calls.last().map(String::as_str), Some("halt"));
        assert_eq!(h.server.counters().watchdog_halts, 1);
        // A still body is never halted.
        assert!(!h.advance_ms(5000));
    }

    #[test]
    fn bye_ends_the_session_but_its_retransmission_is_still_acked() {
        let mut h = Harness::new();
        let s = h.hello(1, 1);
        assert_eq!(ack(h.reply(s, 2, Message::Bye)), Some(AckStatus::Accepted));
        assert_eq!(h.server.session(), None);
        assert_eq!(ack(h.reply(s, 2, Message::Bye)), Some(AckStatus::Accepted));
        assert_eq!(
            ack(h.reply(s, 3, Message::GetState)),
            Some(AckStatus::UnknownSession)
        );
    }
}
