//! `groundcal sim-robot`: the simulated lower computer on a UDP socket — the
//! pure [`Server`] in front of the simulated hexapod ([`SimRobot`]), with
//! optional fault injection between the socket and the server, so that tests
//! can show the upper computer copes with what Wi-Fi does.
//!
//! Fault injection ([`FaultInjection`], from the environment variable
//! `GROUNDCAL_SIM_FAULTS`, e.g. `loss=0.2,dup=0.05,reorder=0.05,delay_ms=20`):
//! - `loss_in`, `loss_out` (or `loss` for both): the probability that a
//!   datagram towards / from the simulated robot is lost;
//! - `dup`: the probability that a datagram is delivered twice (each way);
//! - `reorder`: the probability that a datagram is held back until the next
//!   one in the same direction has passed (at most 250 ms);
//! - `delay_ms`: each datagram is delayed by a uniform 0 to this many ms;
//! - `restart_after_pose`: the simulated lower computer restarts (forgets the
//!   session and the last replies, the body stops where it is) when the upper
//!   computer moves on from this pose: at the first SET_POSE or HOME received
//!   after it reported the body settled at this pose id. That request meets
//!   the restarted lower computer and gets ACK 3;
//! - `partition=POSE:MS`: the network goes dark both ways for MS
//!   milliseconds, from the moment the robot starts its motion to pose POSE
//!   (a Wi-Fi drop-out in the middle of a pose);
//! - `seed`: the faults' own random stream (default: from `--seed`).
//!
//! With `GROUNDCAL_SIM_RECEIPTS=FILE`, every datagram the server handled is
//! logged to FILE as one JSON line (`event: "datagram"`, with type, session,
//! seq, pose id, outcome and ACK status), as are restarts and watchdog
//! halts; the last line, written at shutdown, is `event: "stats"` with
//! [`SimStats`]. The same stats go to stderr as one line `sim-robot: stats
//! {...}`.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::fs::File;
use std::future::Future;
use std::io::{self, BufWriter, Write};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use tokio::net::UdpSocket;

use super::recorded_robot::{RecordedRobot, RecordedScript, RecordedTally};
use super::robot::{SimRobot, SimRobotConfig};
use super::TruePose;
use crate::controller::MotionState;
use crate::udp::proto::{self, kind, Message};
use crate::udp::server::{Server, ServerConfig, ServerCounters};
use groundcal_calib::geometry::Transform;

/// The environment variable with the fault injection settings.
pub const FAULTS_ENV: &str = "GROUNDCAL_SIM_FAULTS";
/// The environment variable naming the receipts log file.
pub const RECEIPTS_ENV: &str = "GROUNDCAL_SIM_RECEIPTS";

/// How the network between upper and lower computer misbehaves (see the
/// module's notes). The default is a perfect network.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FaultInjection {
    /// Probability that a datagram to the robot is lost.
    pub loss_in: f64,
    /// Probability that a datagram from the robot is lost.
    pub loss_out: f64,
    /// Probability that a datagram is duplicated.
    pub duplicate: f64,
    /// Probability that a datagram is overtaken by the next one.
    pub reorder: f64,
    /// Each datagram is delayed by a uniform 0..=this.
    pub max_delay: Duration,
    /// Restart the lower computer when the upper computer moves on from this
    /// pose (see the module's notes).
    pub restart_after_pose: Option<u16>,
    /// Lose every datagram, both ways, for this long from the moment the
    /// robot accepts the motion to this pose.
    pub partition: Option<(u16, Duration)>,
    /// The faults' random stream; `None`: derived from the robot's seed.
    pub seed: Option<u64>,
}

impl FaultInjection {
    /// Parses `key=value,...` (keys in the module's notes).
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut faults = Self::default();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| format!("\"{item}\" is not key=value"))?;
            let (key, value) = (key.trim(), value.trim());
            let probability = || {
                value
                    .parse::<f64>()
                    .ok()
                    .filter(|p| (0.0..=1.0).contains(p))
                    .ok_or_else(|| format!("{key}: \"{value}\" is not a probability in 0..1"))
            };
            let integer = || {
                value
                    .parse::<u64>()
                    .map_err(|_| format!("{key}: \"{value}\" is not a whole number"))
            };
            match key {
                "loss" => {
                    faults.loss_in = probability()?;
                    faults.loss_out = faults.loss_in;
                }
                "loss_in" => faults.loss_in = probability()?,
                "loss_out" => faults.loss_out = probability()?,
                "dup" => faults.duplicate = probability()?,
                "reorder" => faults.reorder = probability()?,
                "delay_ms" => faults.max_delay = Duration::from_millis(integer()?),
                "restart_after_pose" => {
                    let pose = u16::try_from(integer()?)
                        .map_err(|_| format!("{key}: \"{value}\" is not a pose id"))?;
                    faults.restart_after_pose = Some(pose);
                }
                "partition" => {
                    let bad = || format!("{key}: \"{value}\" is not POSE:MILLISECONDS");
                    let (pose, millis) = value.split_once(':').ok_or_else(bad)?;
                    let pose = pose.trim().parse::<u16>().map_err(|_| bad())?;
                    let millis = millis.trim().parse::<u64>().map_err(|_| bad())?;
                    faults.partition = Some((pose, Duration::from_millis(millis)));
                }
                "seed" => faults.seed = Some(integer()?),
                _ => {
                    return Err(format!(
                        "unknown key \"{key}\" (loss, loss_in, loss_out, dup, reorder, \
                         delay_ms, restart_after_pose, partition, seed)"
                    ))
                }
            }
        }
        Ok(faults)
    }

    /// The settings of [`FAULTS_ENV`], or none if it is unset.
    pub fn from_env() -> Result<Self, String> {
        match std::env::var(FAULTS_ENV) {
            Ok(text) => Self::parse(&text).map_err(|e| format!("{FAULTS_ENV}: {e}")),
            Err(std::env::VarError::NotPresent) => Ok(Self::default()),
            Err(e) => Err(format!("{FAULTS_ENV}: {e}")),
        }
    }

    /// The text [`FaultInjection::parse`] reads back.
    pub fn to_env_value(&self) -> String {
        let mut items = vec![
            format!("loss_in={}", self.loss_in),
            format!("loss_out={}", self.loss_out),
            format!("dup={}", self.duplicate),
            format!("reorder={}", self.reorder),
            format!("delay_ms={}", self.max_delay.as_millis()),
        ];
        if let Some(pose) = self.restart_after_pose {
            items.push(format!("restart_after_pose={pose}"));
        }
        if let Some((pose, dark)) = self.partition {
            items.push(format!("partition={pose}:{}", dark.as_millis()));
        }
        if let Some(seed) = self.seed {
            items.push(format!("seed={seed}"));
        }
        items.join(",")
    }
}

/// Everything the simulated lower computer needs.
#[derive(Debug, Clone)]
pub struct SimOptions {
    pub seed: u64,
    pub time_scale: f64,
    pub faults: FaultInjection,
    /// Log every handled datagram here (JSON lines).
    pub receipts: Option<PathBuf>,
    /// Share the body's true pose (e.g. with a simulated Kinect).
    pub true_pose: Option<TruePose>,
    /// Play a recorded session back instead of simulating the body
    /// ([`RecordedRobot`]).
    pub replay: Option<RecordedScript>,
}

impl SimOptions {
    pub fn new(seed: u64, time_scale: f64) -> Self {
        Self {
            seed,
            time_scale,
            faults: FaultInjection::default(),
            receipts: None,
            true_pose: None,
            replay: None,
        }
    }
}

/// What the injected faults did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultCounters {
    pub received: u64,
    pub lost_in: u64,
    pub replies: u64,
    pub lost_out: u64,
    pub duplicated: u64,
    pub reordered: u64,
    /// Lost to a partition, both ways.
    pub partitioned: u64,
}

/// The simulated lower computer's record of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SimStats {
    /// The server's counters, one entry per life (restarts add lives).
    pub lives: Vec<ServerCounters>,
    pub faults: FaultCounters,
    pub restarts: u32,
    /// What a recorded robot's lower computer was asked (`--replay` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replay: Option<RecordedTally>,
}

impl SimStats {
    /// Watchdog halts over all lives.
    pub fn watchdog_halts(&self) -> u64 {
        self.lives.iter().map(|c| c.watchdog_halts).sum()
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Direction {
    ToRobot,
    FromRobot,
}

#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Scheduled {
    due: Instant,
    order: u64,
    direction: Direction,
    address: SocketAddr,
    bytes: Vec<u8>,
}

#[derive(Debug)]
struct Held {
    release_by: Instant,
    scheduled: Scheduled,
}

/// The misbehaving network, in both directions: loss, duplicates, delay and
/// reordering on the way to a queue of datagrams due at given times.
#[derive(Debug)]
struct Impairment {
    faults: FaultInjection,
    rng: ChaCha8Rng,
    queue: BinaryHeap<Reverse<Scheduled>>,
    held: [Option<Held>; 2],
    order: u64,
    counters: FaultCounters,
    /// The network is dark until then (a partition).
    dark_until: Option<Instant>,
}

/// The longest a reordered datagram waits for another to overtake it.
const MAX_HOLD: Duration = Duration::from_millis(250);

impl Impairment {
    fn new(faults: FaultInjection, seed: u64) -> Self {
        Self {
            faults,
            rng: ChaCha8Rng::seed_from_u64(faults.seed.unwrap_or(seed ^ 0xfa17_5eed)),
            queue: BinaryHeap::new(),
            held: [None, None],
            order: 0,
            counters: FaultCounters::default(),
            dark_until: None,
        }
    }

    /// Whether the network is dark now (and counts the datagram lost if so).
    fn partitioned(&mut self, now: Instant) -> bool {
        let dark = self.dark_until.is_some_and(|until| now < until);
        if dark {
            self.counters.partitioned += 1;
        }
        dark
    }

    fn submit(&mut self, direction: Direction, bytes: Vec<u8>, address: SocketAddr, now: Instant) {
        let loss = match direction {
            Direction::ToRobot => {
                self.counters.received += 1;
                self.faults.loss_in
            }
            Direction::FromRobot => {
                self.counters.replies += 1;
                self.faults.loss_out
            }
        };
        if self.partitioned(now) {
            return;
        }
        if self.rng.gen_bool(loss) {
            match direction {
                Direction::ToRobot => self.counters.lost_in += 1,
                Direction::FromRobot => self.counters.lost_out += 1,
            }
            return;
        }
        let copies = if self.rng.gen_bool(self.faults.duplicate) {
            self.counters.duplicated += 1;
            2
        } else {
            1
        };
        let slot = direction as usize;
        for _ in 0..copies {
            let max_us = self.faults.max_delay.as_micros() as u64;
            let delay = Duration::from_micros(self.rng.gen_range(0..=max_us));
            self.order += 1;
            let scheduled = Scheduled {
                due: now + delay,
                order: self.order,
                direction,
                address,
                bytes: bytes.clone(),
            };
            if self.held[slot].is_none() && self.rng.gen_bool(self.faults.reorder) {
                self.counters.reordered += 1;
                self.held[slot] = Some(Held {
                    release_by: now + MAX_HOLD,
                    scheduled,
                });
                continue;
            }
            let due = scheduled.due;
            self.queue.push(Reverse(scheduled));
            // The held datagram goes right after this one: overtaken.
            if let Some(mut held) = self.held[slot].take() {
                self.order += 1;
                held.scheduled.order = self.order;
                held.scheduled.due = due.max(held.scheduled.due);
                self.queue.push(Reverse(held.scheduled));
            }
        }
    }

    fn next_due(&self) -> Option<Instant> {
        let queued = self.queue.peek().map(|Reverse(s)| s.due);
        let held = self.held.iter().flatten().map(|h| h.release_by).min();
        match (queued, held) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn pop_due(&mut self, now: Instant) -> Option<Scheduled> {
        for slot in &mut self.held {
            if slot.as_ref().is_some_and(|h| h.release_by <= now) {
                if let Some(held) = slot.take() {
                    self.queue.push(Reverse(held.scheduled));
                }
            }
        }
        if self.queue.peek().is_some_and(|Reverse(s)| s.due <= now) {
            self.queue.pop().map(|Reverse(s)| s)
        } else {
            None
        }
    }
}

/// One JSON line of the receipts log.
#[derive(Serialize)]
struct ReceiptLine<'a> {
    event: &'a str,
    t_ms: f64,
    /// Wall-clock time, milliseconds since the Unix epoch: a test lines the
    /// datagrams up with what it did to the upper computer (a SIGCONT).
    unix_ms: f64,
    life: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    from: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    kind: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    session: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    seq: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pose_id: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    outcome: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ack: Option<u8>,
}

impl<'a> ReceiptLine<'a> {
    fn event(event: &'a str, t_ms: f64, life: u32) -> Self {
        let unix_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64() * 1000.0);
        Self {
            event,
            t_ms,
            unix_ms,
            life,
            from: None,
            kind: None,
            session: None,
            seq: None,
            pose_id: None,
            outcome: None,
            ack: None,
        }
    }
}

/// The simulated lower computer, bound and ready to serve.
#[derive(Debug)]
pub struct SimServer {
    socket: UdpSocket,
    local: SocketAddr,
    options: SimOptions,
    receipts: Option<BufWriter<File>>,
}

impl SimServer {
    /// Binds the socket (port 0: any free port) and opens the receipts log.
    pub async fn bind(address: SocketAddr, options: SimOptions) -> io::Result<Self> {
        if !(options.time_scale.is_finite() && options.time_scale > 0.0) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("time scale {} is not a positive number", options.time_scale),
            ));
        }
        let receipts = match &options.receipts {
            Some(path) => Some(BufWriter::new(File::create(path).map_err(|e| {
                io::Error::new(e.kind(), format!("{}: {e}", path.display()))
            })?)),
            None => None,
        };
        let socket = UdpSocket::bind(address).await?;
        let local = socket.local_addr()?;
        Ok(Self {
            socket,
            local,
            options,
            receipts,
        })
    }

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// Serves until `shutdown` completes.
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> io::Result<SimStats> {
        let epoch = now();
        match self.options.replay.clone() {
            Some(script) => {
                let robot = RecordedRobot::new(script, epoch);
                self.serve(robot, epoch, shutdown).await
            }
            None => {
                let true_pose = self
                    .options
                    .true_pose
                    .clone()
                    .unwrap_or_else(|| TruePose::new(Transform::identity()));
                let config = SimRobotConfig::reference(self.options.seed, self.options.time_scale);
                let robot = SimRobot::new(config, true_pose, epoch);
                self.serve(robot, epoch, shutdown).await
            }
        }
    }

    async fn serve<B: ServedBody>(
        mut self,
        mut robot: B,
        epoch: Instant,
        shutdown: impl Future<Output = ()>,
    ) -> io::Result<SimStats> {
        let seed = self.options.seed;
        let mut life: u32 = 0;
        let server_config = |life: u32| ServerConfig {
            seed: seed ^ (u64::from(life) << 48) ^ 0x5e55_1017,
            ..ServerConfig::default()
        };
        let mut server = Server::new(server_config(life));
        let mut impairment = Impairment::new(self.options.faults, seed);
        let mut stats = SimStats::default();
        let mut restart_armed = false;
        let mut buffer = [0u8; 2048];
        tokio::pin!(shutdown);
        loop {
            let now_std = now();
            // Wake for the next due datagram, and every 10 ms while the body
            // moves (the true pose follows, the watchdog is checked).
            let moving = robot_moving(&mut robot, now_std);
            let tick = moving.then(|| now_std + Duration::from_millis(10));
            let wake = [impairment.next_due(), tick].into_iter().flatten().min();
            let sleep = tokio::time::sleep_until(
                wake.map_or_else(far_future, tokio::time::Instant::from_std),
            );
            tokio::select! {
                biased;
                () = &mut shutdown => break,
                received = self.socket.recv_from(&mut buffer) => match received {
                    Ok((n, from)) => impairment.submit(Direction::ToRobot, buffer[..n].to_vec(), from, now()),
                    Err(e) => {
                        tracing::debug!("receive failed: {e}");
                        tokio::time::sleep(Duration::from_millis(5)).await;
                    }
                },
                () = sleep, if wake.is_some() => {}
            }
            let now_std = now();
            while let Some(item) = impairment.pop_due(now_std) {
                match item.direction {
                    Direction::FromRobot => {
                        if let Err(e) = self.socket.send_to(&item.bytes, item.address).await {
                            tracing::debug!("send to {} failed: {e}", item.address);
                        }
                    }
                    Direction::ToRobot => {
                        let restart_now = restart_armed
                            && self
                                .options
                                .faults
                                .restart_after_pose
                                .is_some_and(|pose| moves_on_from(&item.bytes, pose));
                        if restart_now {
                            restart_armed = false;
                            stats.lives.push(*server.counters());
                            stats.restarts += 1;
                            life += 1;
                            server = Server::new(server_config(life));
                            robot.restart(now_std);
                            tracing::info!("simulated lower computer restarted");
                            self.log(&ReceiptLine::event("restart", ms(epoch, now_std), life));
                        }
                        let handled = server.handle(&item.bytes, item.address, now_std, &mut robot);
                        let r = handled.receipt;
                        self.log(&ReceiptLine {
                            from: Some(item.address.to_string()),
                            kind: r.kind.map(kind::name),
                            session: Some(r.session),
                            seq: Some(r.seq),
                            pose_id: r.pose_id,
                            outcome: Some(match r.outcome {
                                crate::udp::server::Outcome::Dropped(reason) => reason,
                                other => other.name(),
                            }),
                            ack: r.ack.map(|a| a.code()),
                            ..ReceiptLine::event("datagram", ms(epoch, now_std), life)
                        });
                        if let Some((pose, dark)) = self.options.faults.partition {
                            let starts = impairment.dark_until.is_none()
                                && r.pose_id == Some(pose)
                                && r.kind == Some(kind::SET_POSE)
                                && matches!(r.outcome, crate::udp::server::Outcome::New);
                            if starts {
                                impairment.dark_until = Some(now_std + dark);
                                tracing::info!("the network goes dark for {dark:?}");
                                self.log(&ReceiptLine::event(
                                    "partition",
                                    ms(epoch, now_std),
                                    life,
                                ));
                            }
                        }
                        if let Some(reply) = handled.reply {
                            if let Some(pose) = self.options.faults.restart_after_pose {
                                if stats.restarts == 0 && settled_at(&reply, pose) {
                                    restart_armed = true;
                                }
                            }
                            impairment.submit(Direction::FromRobot, reply, item.address, now_std);
                        }
                    }
                }
            }
            if server.poll_watchdog(now_std, &mut robot) {
                tracing::warn!("watchdog: no word from the upper computer for 1 s; halted");
                self.log(&ReceiptLine::event(
                    "watchdog_halt",
                    ms(epoch, now_std),
                    life,
                ));
            }
            robot.advance(now_std);
        }
        stats.lives.push(*server.counters());
        stats.faults = impairment.counters;
        stats.replay = robot.recorded_tally();
        #[derive(Serialize)]
        struct StatsLine<'a> {
            event: &'a str,
            #[serde(flatten)]
            stats: &'a SimStats,
        }
        if let Some(mut file) = self.receipts.take() {
            let line = serde_json::to_string(&StatsLine {
                event: "stats",
                stats: &stats,
            })
            .map_err(io::Error::other)?;
            writeln!(file, "{line}")?;
            file.flush()?;
        }
        Ok(stats)
    }

    fn log(&mut self, line: &ReceiptLine<'_>) {
        if let Some(file) = &mut self.receipts {
            // Flushed line by line: a test reads what reached the lower
            // computer while it runs (after a crash of the upper computer).
            let written = serde_json::to_string(line)
                .map_err(io::Error::other)
                .and_then(|text| writeln!(file, "{text}"))
                .and_then(|()| file.flush());
            if let Err(e) = written {
                tracing::warn!("receipts log: {e}; no more receipts");
                self.receipts = None;
            }
        }
    }
}

/// A body the simulated lower computer can serve: the simulated hexapod or a
/// played-back recording.
trait ServedBody: crate::udp::server::Body {
    /// Brings the motion up to `now`.
    fn advance(&mut self, now: Instant);
    /// A lower computer restart (fault injection).
    fn restart(&mut self, now: Instant);
    /// What a recorded robot was asked, if it is one.
    fn recorded_tally(&self) -> Option<RecordedTally> {
        None
    }
}

impl ServedBody for SimRobot {
    fn advance(&mut self, now: Instant) {
        SimRobot::advance(self, now);
    }
    fn restart(&mut self, now: Instant) {
        SimRobot::restart(self, now);
    }
}

impl ServedBody for RecordedRobot {
    fn advance(&mut self, now: Instant) {
        RecordedRobot::advance(self, now);
    }
    fn restart(&mut self, now: Instant) {
        RecordedRobot::restart(self, now);
    }
    fn recorded_tally(&self) -> Option<RecordedTally> {
        Some(self.tally().clone())
    }
}

fn robot_moving(robot: &mut impl ServedBody, now: Instant) -> bool {
    robot.motion(now) == MotionState::Moving
}

/// Whether a datagram moves the body away from `pose`: a SET_POSE of another
/// pose, or a HOME (whatever its session; late copies of the SET_POSE of
/// `pose` itself do not count).
fn moves_on_from(bytes: &[u8], pose: u16) -> bool {
    match proto::decode(bytes) {
        Ok(d) => match d.message {
            Message::SetPose(p) => p.pose_id != pose,
            Message::Home { .. } => true,
            _ => false,
        },
        Err(_) => false,
    }
}

/// Whether a reply is a STATE saying the body settled at `pose`.
fn settled_at(reply: &[u8], pose: u16) -> bool {
    matches!(
        proto::decode(reply),
        Ok(proto::Datagram { message: Message::State(s), .. })
            if s.state == MotionState::Settled && s.pose_id == pose
    )
}

fn ms(epoch: Instant, now: Instant) -> f64 {
    now.saturating_duration_since(epoch).as_secs_f64() * 1000.0
}

fn now() -> Instant {
    tokio::time::Instant::now().into_std()
}

fn far_future() -> tokio::time::Instant {
    tokio::time::Instant::now() + Duration::from_secs(86_400)
}

/// Binds `socket_addr` and serves the simulated lower computer until
/// `shutdown` completes.
pub async fn serve(
    socket_addr: SocketAddr,
    seed: u64,
    time_scale: f64,
    faults: FaultInjection,
    shutdown: impl Future<Output = ()>,
) -> io::Result<SimStats> {
    let options = SimOptions {
        faults,
        ..SimOptions::new(seed, time_scale)
    };
    let server = SimServer::bind(socket_addr, options).await?;
    tracing::info!("simulated lower computer on {}", server.local_addr());
    server.run(shutdown).await
}

/// SIGINT or SIGTERM (Ctrl-C where there are no Unix signals), with the
/// handlers installed now, when called inside the runtime, not when the
/// future is first polled: a signal right after the address is printed then
/// stops the server cleanly, where the default action killed it.
pub fn shutdown_signal() -> impl std::future::Future<Output = ()> + Send + 'static {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let handlers = (
            signal(SignalKind::interrupt()),
            signal(SignalKind::terminate()),
        );
        async move {
            match handlers {
                (Ok(mut interrupt), Ok(mut terminate)) => {
                    tokio::select! {
                        _ = interrupt.recv() => {}
                        _ = terminate.recv() => {}
                    }
                }
                _ => {
                    let _ = tokio::signal::ctrl_c().await;
                }
            }
        }
    }
    #[cfg(not(unix))]
    {
        async {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// The whole `sim-robot` process on a runtime of its own: binds, calls
/// `on_bound` with the address (before any datagram is served), serves until
/// SIGINT or SIGTERM, and returns the stats.
pub fn run_until_signal(
    listen: SocketAddr,
    options: SimOptions,
    on_bound: impl FnOnce(SocketAddr),
) -> io::Result<SimStats> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let server = SimServer::bind(listen, options).await?;
        // Signal handlers first, so that a signal right after the address
        // is printed is not lost.
        let shutdown = shutdown_signal();
        on_bound(server.local_addr());
        server.run(shutdown).await
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_and_print_back() {
        let f = FaultInjection::parse(
            "loss=0.2, dup=0.05,reorder=0.05,delay_ms=20,restart_after_pose=20,seed=3",
        )
        .unwrap();
        assert_eq!(f.loss_in, 0.2);
        assert_eq!(f.loss_out, 0.2);
        assert_eq!(f.max_delay, Duration::from_millis(20));
        assert_eq!(f.restart_after_pose, Some(20));
        assert_eq!(FaultInjection::parse(&f.to_env_value()).unwrap(), f);
        assert_eq!(
            FaultInjection::parse("").unwrap(),
            FaultInjection::default()
        );
        assert!(FaultInjection::parse("loss=2")
            .unwrap_err()
            .contains("loss"));
        assert!(FaultInjection::parse("jitter=1")
            .unwrap_err()
            .contains("jitter"));
        assert!(FaultInjection::parse("loss").is_err());
    }

    #[test]
    fn impairment_passes_a_perfect_network_through_in_order() {
        let mut i = Impairment::new(FaultInjection::default(), 1);
        let t0 = Instant::now();
        let a: SocketAddr = "127.0.0.1:1".parse().unwrap();
        for n in 0..5u8 {
            i.submit(Direction::ToRobot, vec![n], a, t0);
        }
        let out: Vec<u8> = std::iter::from_fn(|| i.pop_due(t0).map(|s| s.bytes[0])).collect();
        assert_eq!(out, vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn impairment_rates_are_close_to_the_settings() {
        let faults = FaultInjection::parse("loss=0.2,dup=0.05,reorder=0.05,delay_ms=20").unwrap();
        let mut i = Impairment::new(faults, 7);
        let t0 = Instant::now();
        let a: SocketAddr = "127.0.0.1:1".parse().unwrap();
        let n = 20_000;
        let mut delivered = 0;
        let mut overtaken = 0;
        let mut last = None;
        for k in 0..n {
            let now = t0 + Duration::from_millis(k * 30);
            i.submit(
                Direction::ToRobot,
                (k as u32).to_le_bytes().to_vec(),
                a,
                now,
            );
            while let Some(s) = i.pop_due(now + Duration::from_millis(29)) {
                assert!(s.due <= now + Duration::from_millis(29));
                let v = u32::from_le_bytes([s.bytes[0], s.bytes[1], s.bytes[2], s.bytes[3]]);
                if last.is_some_and(|l| v < l) {
                    overtaken += 1;
                }
                last = Some(v);
                delivered += 1;
            }
        }
        let c = i.counters;
        let loss = c.lost_in as f64 / n as f64;
        assert!((loss - 0.2).abs() < 0.02, "{loss}");
        let dup = c.duplicated as f64 / (n - c.lost_in) as f64;
        assert!((dup - 0.05).abs() < 0.01, "{dup}");
        assert!(overtaken > n / 40, "{overtaken} reordered");
        assert!(delivered > n * 8 / 10);
    }
}
