//! The upper computer's link to the lower computer: a tokio task that owns
//! the UDP socket and the clock and drives the pure [`Client`], and
//! [`UdpBodyController`], the [`BodyController`] over it.
//!
//! Keeping the watchdog fed is the link's job, not the caller's: while the
//! body moves (an accepted SET_POSE or HOME, until a STATE says it is no
//! longer moving) and the link has sent nothing for the keep-alive interval
//! (150 ms, below the spec's 200 ms), the client sends a GET_STATE of its own.
//! A caller that is busy elsewhere (fitting a plane, writing a file) cannot
//! make the robot halt. [`UdpBodyController::state`] still asks the lower
//! computer each time (fresh feet, fresh time); the keep-alives' answers are
//! in [`UdpBodyController::latest_state`].
//!
//! The socket is set up deliberately (socket2):
//! - send and receive buffers of 64 KiB: hundreds of our ≤104-byte datagrams,
//!   ample for one exchange at a time, and small enough that a backlog of
//!   stale replies cannot build up behind a slow reader;
//! - DSCP EF (46, "expedited forwarding") in IP_TOS / IPV6_TCLASS: the
//!   traffic is small, periodic and latency-bound like voice. On Wi-Fi, WMM
//!   maps EF to the voice access category (RFC 8325; older Linux kernels,
//!   which map by the top three bits, give it the video category), whose
//!   short contention window gets control datagrams out ahead of bulk
//!   traffic on the same radio;
//! - `SO_BINDTODEVICE` to the configured interface (the robot's Wi-Fi) when
//!   one is configured, so that the requests never leave through another
//!   route (Linux; needs CAP_NET_RAW);
//! - non-blocking, then handed to tokio.
//!
//! The socket is not connected: the client itself checks that replies come
//! from the lower computer's address.

use std::collections::HashMap;
use std::io;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, ToSocketAddrs};
use std::time::{Duration, Instant};

use socket2::{Domain, Protocol, Socket, Type};
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;

use super::client::{Client, ClientConfig, ClientStats, Event, Failure, Reply, Request};
use super::proto::AckStatus;
use crate::controller::{BodyController, BodyState, MotionState, Welcome};
use crate::error::{Error, ErrorKind};
use groundcal_calib::geometry::PoseDegMm;

/// DSCP "expedited forwarding" (RFC 3246), the class of our control traffic.
pub const DSCP_EF: u8 = 46;

/// How to reach the lower computer.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// The lower computer's address (port 7400 by default on the robot).
    pub peer: SocketAddr,
    /// The local address; default: any address of the peer's family, any port.
    pub bind: Option<SocketAddr>,
    /// Bind the socket to this network interface (`SO_BINDTODEVICE`).
    pub interface: Option<String>,
    /// The DSCP class of our datagrams; `None` leaves the system's default.
    pub dscp: Option<u8>,
    pub send_buffer_bytes: usize,
    pub recv_buffer_bytes: usize,
    /// Retries and keep-alives.
    pub client: ClientConfig,
    /// The longest one call may wait, session renewals and queueing behind
    /// a keep-alive included; beyond it the call fails with a timeout. The
    /// protocol itself declares the link lost well before (1.1 s with the
    /// defaults).
    pub request_timeout: Duration,
}

impl LinkConfig {
    /// The defaults, towards `peer`.
    pub fn new(peer: SocketAddr) -> Self {
        Self {
            peer,
            bind: None,
            interface: None,
            dscp: Some(DSCP_EF),
            send_buffer_bytes: 64 * 1024,
            recv_buffer_bytes: 64 * 1024,
            client: ClientConfig::default(),
            request_timeout: Duration::from_secs(10),
        }
    }

    /// The defaults, towards `host:port` (resolved now, IPv4 preferred).
    pub fn resolve(address: &str) -> Result<Self, UdpError> {
        let peer = resolve_ipv4_first(address).map_err(|what| UdpError::Setup {
            peer: address.to_string(),
            what,
            missing_device: false,
        })?;
        Ok(Self::new(peer))
    }
}

/// `host:port` to one socket address, IPv4 first: the robot's Wi-Fi is IPv4
/// (hexapod-udp.md allows both).
pub fn resolve_ipv4_first(address: &str) -> Result<SocketAddr, String> {
    let addresses: Vec<SocketAddr> = address
        .to_socket_addrs()
        .map_err(|e| format!("cannot resolve the address: {e}"))?
        .collect();
    addresses
        .iter()
        .find(|a| a.is_ipv4())
        .or(addresses.first())
        .copied()
        .ok_or_else(|| "the address resolves to nothing".to_string())
}

/// A failure of the link, classified for the session.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UdpError {
    #[error("no answer from the lower computer at {peer} in time: {what}")]
    Timeout { peer: String, what: String },
    #[error("the link to the lower computer at {peer} is lost: {what}")]
    LinkLost { peer: String, what: String },
    #[error("the lower computer at {peer} refused {request}: {status}")]
    Refused {
        peer: String,
        request: &'static str,
        status: AckStatus,
    },
    #[error("the lower computer at {peer} does not follow the protocol: {what}")]
    Protocol { peer: String, what: String },
    #[error("cannot open the link to the lower computer at {peer}: {what}")]
    Setup {
        peer: String,
        what: String,
        /// The configured network interface does not exist.
        missing_device: bool,
    },
}

impl UdpError {
    /// The ACK status of a refusal.
    pub fn status(&self) -> Option<AckStatus> {
        match self {
            UdpError::Refused { status, .. } => Some(*status),
            _ => None,
        }
    }

    fn from_failure(peer: SocketAddr, failure: Failure) -> Self {
        let peer = peer.to_string();
        match failure {
            Failure::LinkLost { .. } => UdpError::LinkLost {
                peer,
                what: failure.to_string(),
            },
            Failure::Refused { request, status } => UdpError::Refused {
                peer,
                request,
                status,
            },
            Failure::NotSentInTime { .. } => UdpError::Timeout {
                peer,
                what: failure.to_string(),
            },
            Failure::Protocol(what) => UdpError::Protocol { peer, what },
        }
    }
}

impl Error for UdpError {
    fn kind(&self) -> ErrorKind {
        match self {
            UdpError::Timeout { .. } => ErrorKind::Timeout,
            UdpError::LinkLost { .. } => ErrorKind::LinkLost,
            UdpError::Refused { .. } => ErrorKind::Refused,
            UdpError::Protocol { .. } => ErrorKind::Protocol,
            UdpError::Setup {
                missing_device: true,
                ..
            } => ErrorKind::DeviceMissing,
            UdpError::Setup { .. } => ErrorKind::Other,
        }
    }
}

/// Opens the UDP socket as [`LinkConfig`] says (see the module's notes).
pub fn open_socket(config: &LinkConfig) -> Result<std::net::UdpSocket, UdpError> {
    let fail = |step: &str, e: io::Error| UdpError::Setup {
        peer: config.peer.to_string(),
        what: format!("{step}: {e}"),
        missing_device: e.raw_os_error() == Some(19), // ENODEV
    };
    let bind = config.bind.unwrap_or(match config.peer {
        SocketAddr::V4(_) => SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), 0),
        SocketAddr::V6(_) => SocketAddr::new(IpAddr::V6(Ipv6Addr::UNSPECIFIED), 0),
    });
    let socket = Socket::new(Domain::for_address(bind), Type::DGRAM, Some(Protocol::UDP))
        .map_err(|e| fail("socket", e))?;
    socket
        .set_send_buffer_size(config.send_buffer_bytes)
        .map_err(|e| fail("SO_SNDBUF", e))?;
    socket
        .set_recv_buffer_size(config.recv_buffer_bytes)
        .map_err(|e| fail("SO_RCVBUF", e))?;
    if let Some(dscp) = config.dscp {
        let traffic_class = u32::from(dscp & 0x3f) << 2;
        match bind {
            SocketAddr::V4(_) => socket
                .set_tos_v4(traffic_class)
                .map_err(|e| fail("IP_TOS", e))?,
            SocketAddr::V6(_) => socket
                .set_tclass_v6(traffic_class)
                .map_err(|e| fail("IPV6_TCLASS", e))?,
        }
    }
    if let Some(interface) = &config.interface {
        bind_to_device(&socket, interface)
            .map_err(|e| fail(&format!("SO_BINDTODEVICE {interface}"), e))?;
    }
    socket
        .set_nonblocking(true)
        .map_err(|e| fail("O_NONBLOCK", e))?;
    socket
        .bind(&bind.into())
        .map_err(|e| fail(&format!("bind {bind}"), e))?;
    Ok(socket.into())
}

#[cfg(any(target_os = "linux", target_os = "android"))]
fn bind_to_device(socket: &Socket, interface: &str) -> io::Result<()> {
    socket.bind_device(Some(interface.as_bytes()))
}

#[cfg(not(any(target_os = "linux", target_os = "android")))]
fn bind_to_device(_: &Socket, _: &str) -> io::Result<()> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "binding to an interface needs Linux",
    ))
}

struct Command {
    request: Request,
    /// When the caller asked: a motion command too old by the time the
    /// link's task sends it is not sent ([`crate::udp::client::MOTION_FRESH`]).
    issued: Instant,
    reply: oneshot::Sender<Result<Reply, Failure>>,
}

/// The running link: a handle to the task that owns the socket.
#[derive(Debug)]
pub struct Link {
    peer: SocketAddr,
    local: SocketAddr,
    request_timeout: Duration,
    commands: mpsc::Sender<Command>,
    states: watch::Receiver<Option<BodyState>>,
    stats: watch::Receiver<ClientStats>,
    task: JoinHandle<()>,
}

impl Link {
    /// Opens the socket and starts the task (on the current tokio runtime).
    pub async fn open(config: &LinkConfig) -> Result<Self, UdpError> {
        let socket = open_socket(config)?;
        let socket = UdpSocket::from_std(socket).map_err(|e| UdpError::Setup {
            peer: config.peer.to_string(),
            what: format!("tokio: {e}"),
            missing_device: false,
        })?;
        let local = socket.local_addr().map_err(|e| UdpError::Setup {
            peer: config.peer.to_string(),
            what: format!("local address: {e}"),
            missing_device: false,
        })?;
        let client = Client::new(config.peer, config.client, run_seed(local));
        let (commands, receiver) = mpsc::channel(16);
        let (state_sender, states) = watch::channel(None);
        let (stats_sender, stats) = watch::channel(ClientStats::default());
        let task = tokio::spawn(drive(socket, client, receiver, state_sender, stats_sender));
        Ok(Self {
            peer: config.peer,
            local,
            request_timeout: config.request_timeout,
            commands,
            states,
            stats,
            task,
        })
    }

    pub fn peer(&self) -> SocketAddr {
        self.peer
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The last STATE received (answer to the caller or to a keep-alive).
    pub fn latest_state(&self) -> Option<BodyState> {
        *self.states.borrow()
    }

    /// The client's counters (retransmissions, stale replies, ...).
    pub fn stats(&self) -> ClientStats {
        *self.stats.borrow()
    }

    /// Sends one request and waits for its answer.
    pub async fn request(&self, request: Request) -> Result<Reply, UdpError> {
        let lost = |what: &str| UdpError::LinkLost {
            peer: self.peer.to_string(),
            what: what.to_string(),
        };
        let issued = now();
        let (reply, answer) = oneshot::channel();
        self.commands
            .send(Command {
                request,
                issued,
                reply,
            })
            .await
            .map_err(|_| lost("the link's task has ended"))?;
        match tokio::time::timeout(self.request_timeout, answer).await {
            Err(_) => Err(UdpError::Timeout {
                peer: self.peer.to_string(),
                what: format!(
                    "{} not answered within {} ms",
                    request.name(),
                    self.request_timeout.as_millis()
                ),
            }),
            Ok(Err(_)) => Err(lost("the link's task has ended")),
            Ok(Ok(result)) => result.map_err(|f| UdpError::from_failure(self.peer, f)),
        }
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// A seed that differs between runs, for nonces and the first `seq`.
fn run_seed(local: SocketAddr) -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    nanos ^ (u64::from(std::process::id()) << 32) ^ u64::from(local.port())
}

fn now() -> Instant {
    tokio::time::Instant::now().into_std()
}

/// The link's task: socket, clock and client.
async fn drive(
    socket: UdpSocket,
    mut client: Client,
    mut commands: mpsc::Receiver<Command>,
    states: watch::Sender<Option<BodyState>>,
    stats: watch::Sender<ClientStats>,
) {
    let mut waiting: HashMap<_, oneshot::Sender<Result<Reply, Failure>>> = HashMap::new();
    // Larger than any valid datagram, so that an oversized one is seen
    // (and rejected) rather than silently cut.
    let mut buffer = [0u8; 2048];
    loop {
        while let Some(transmit) = client.poll_transmit() {
            if let Err(e) = socket.send_to(&transmit.bytes, transmit.destination).await {
                // As if lost: the retransmission will try again.
                tracing::debug!("send to {} failed: {e}", transmit.destination);
            }
        }
        while let Some(event) = client.poll_event() {
            match event {
                Event::Completed { id, result } => {
                    if let Some(reply) = waiting.remove(&id) {
                        // The caller may have given up (timeout); nothing to do.
                        let _ = reply.send(result);
                    }
                }
                Event::SessionStarted { welcome, automatic } => {
                    if automatic {
                        tracing::info!(
                            "new session {} with the lower computer ({})",
                            welcome.session,
                            welcome.firmware
                        );
                    }
                }
                Event::State(state) => {
                    states.send_replace(Some(state));
                }
                Event::KeepAliveFailed(failure) => {
                    tracing::warn!("keep-alive to the lower computer failed: {failure}");
                }
            }
        }
        stats.send_if_modified(|s| {
            let changed = s != client.stats();
            *s = *client.stats();
            changed
        });
        let deadline = client.poll_timeout();
        let sleep = tokio::time::sleep_until(
            deadline.map_or_else(far_future, tokio::time::Instant::from_std),
        );
        tokio::select! {
            command = commands.recv() => match command {
                Some(Command { request, issued, reply }) => {
                    let id = client.submit_issued(request, issued, now());
                    waiting.insert(id, reply);
                }
                // The controller is gone.
                None => break,
            },
            received = socket.recv_from(&mut buffer) => match received {
                Ok((n, from)) => client.handle_datagram(&buffer[..n], from, now()),
                Err(e) => {
                    tracing::debug!("receive failed: {e}");
                    // Do not spin on a persistent error.
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
            },
            () = sleep, if deadline.is_some() => client.handle_timeout(now()),
        }
    }
}

fn far_future() -> tokio::time::Instant {
    tokio::time::Instant::now() + Duration::from_secs(86_400)
}

/// The lower computer over UDP (`hexapod-udp.md`).
#[derive(Debug)]
pub struct UdpBodyController {
    link: Link,
    welcome: Option<Welcome>,
}

impl UdpBodyController {
    /// Opens the link; the session starts with [`BodyController::hello`] (or
    /// with the first request).
    pub async fn connect(config: &LinkConfig) -> Result<Self, UdpError> {
        Ok(Self {
            link: Link::open(config).await?,
            welcome: None,
        })
    }

    pub fn link(&self) -> &Link {
        &self.link
    }

    /// The WELCOME of the last HELLO asked for.
    pub fn welcome(&self) -> Option<&Welcome> {
        self.welcome.as_ref()
    }

    /// The last STATE received, without asking (keep-alives keep it fresh
    /// while the body moves).
    pub fn latest_state(&self) -> Option<BodyState> {
        self.link.latest_state()
    }

    /// Polls the state every `poll` until the body no longer moves; a
    /// timeout error after `timeout`.
    pub async fn wait_while_moving(
        &mut self,
        poll: Duration,
        timeout: Duration,
    ) -> Result<BodyState, UdpError> {
        let give_up = tokio::time::Instant::now() + timeout;
        loop {
            let state = self.state().await?;
            if state.state != MotionState::Moving {
                return Ok(state);
            }
            if tokio::time::Instant::now() + poll > give_up {
                return Err(UdpError::Timeout {
                    peer: self.link.peer.to_string(),
                    what: format!(
                        "the body still moves after {} ms (pose {})",
                        timeout.as_millis(),
                        state.pose_id
                    ),
                });
            }
            tokio::time::sleep(poll).await;
        }
    }

    async fn accepted(&self, request: Request) -> Result<(), UdpError> {
        match self.link.request(request).await? {
            Reply::Accepted => Ok(()),
            other => Err(self.unexpected(request, &other)),
        }
    }

    fn unexpected(&self, request: Request, reply: &Reply) -> UdpError {
        UdpError::Protocol {
            peer: self.link.peer.to_string(),
            what: format!("{reply:?} in answer to {}", request.name()),
        }
    }
}

impl BodyController for UdpBodyController {
    type Error = UdpError;

    async fn hello(&mut self) -> Result<Welcome, UdpError> {
        match self.link.request(Request::Hello).await? {
            Reply::Welcome(welcome) => {
                self.welcome = Some(welcome.clone());
                Ok(welcome)
            }
            other => Err(self.unexpected(Request::Hello, &other)),
        }
    }

    async fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
    ) -> Result<(), UdpError> {
        self.accepted(Request::SetPose {
            pose_id,
            pose: *pose,
            duration_ms,
        })
        .await
    }

    async fn state(&mut self) -> Result<BodyState, UdpError> {
        match self.link.request(Request::GetState).await? {
            Reply::State(state) => Ok(state),
            other => Err(self.unexpected(Request::GetState, &other)),
        }
    }

    async fn home(&mut self, duration_ms: u32) -> Result<(), UdpError> {
        self.accepted(Request::Home { duration_ms }).await
    }

    async fn halt(&mut self) -> Result<(), UdpError> {
        self.accepted(Request::Halt).await
    }

    async fn bye(&mut self) -> Result<(), UdpError> {
        self.accepted(Request::Bye).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use socket2::SockRef;

    #[test]
    fn the_socket_is_set_up_as_configured() {
        let mut config = LinkConfig::new("127.0.0.1:7400".parse().unwrap());
        let socket = open_socket(&config).unwrap();
        let s = SockRef::from(&socket);
        assert_eq!(s.tos_v4().unwrap(), u32::from(DSCP_EF) << 2);
        // Linux doubles the value asked for (bookkeeping overhead).
        assert!(s.recv_buffer_size().unwrap() >= 64 * 1024);
        assert!(s.send_buffer_size().unwrap() >= 64 * 1024);
        assert!(socket.local_addr().unwrap().port() != 0);
        // Non-blocking: a receive with nothing there returns at once.
        let mut buf = [0u8; 8];
        assert_eq!(
            socket.recv_from(&mut buf).unwrap_err().kind(),
            io::ErrorKind::WouldBlock
        );
        config.interface = Some("no-such-if0".into());
        let e = open_socket(&config).unwrap_err();
        // ENODEV, or EPERM where the process lacks CAP_NET_RAW.
        assert!(e.to_string().contains("SO_BINDTODEVICE no-such-if0"), "{e}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn binds_to_the_configured_interface() {
        let mut config = LinkConfig::new("127.0.0.1:7400".parse().unwrap());
        config.interface = Some("lo".into());
        match open_socket(&config) {
            Ok(socket) => {
                let device = SockRef::from(&socket).device().unwrap();
                assert_eq!(device.as_deref(), Some(&b"lo"[..]));
            }
            // Without CAP_NET_RAW the kernel refuses; say so rather than fail.
            Err(e) if e.to_string().contains("Operation not permitted") => {
                eprintln!("skipped: {e}");
            }
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn errors_have_their_kinds() {
        let peer = "x".to_string();
        let refused = UdpError::Refused {
            peer: peer.clone(),
            request: "SET_POSE",
            status: AckStatus::OutsideLimits,
        };
        assert_eq!(refused.kind(), ErrorKind::Refused);
        assert!(refused.to_string().contains("ACK 1"), "{refused}");
        assert_eq!(refused.status(), Some(AckStatus::OutsideLimits));
        let lost = UdpError::from_failure(
            "127.0.0.1:1".parse().unwrap(),
            Failure::LinkLost {
                request: "GET_STATE",
                sends: 11,
                waited: Duration::from_millis(1100),
            },
        );
        assert_eq!(lost.kind(), ErrorKind::LinkLost);
        assert_eq!(
            UdpError::Timeout {
                peer: peer.clone(),
                what: String::new()
            }
            .kind(),
            ErrorKind::Timeout
        );
        assert_eq!(
            UdpError::Protocol {
                peer,
                what: String::new()
            }
            .kind(),
            ErrorKind::Protocol
        );
    }

    /// With nobody listening, a request is sent 11 times over 1.1 s and then
    /// fails with link lost (on tokio's paused clock).
    #[tokio::test(start_paused = true)]
    async fn a_silent_peer_means_link_lost() {
        // A bound socket that never answers.
        let silent = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let config = LinkConfig::new(silent.local_addr().unwrap());
        let mut controller = UdpBodyController::connect(&config).await.unwrap();
        let started = tokio::time::Instant::now();
        let e = controller.hello().await.unwrap_err();
        assert_eq!(e.kind(), ErrorKind::LinkLost, "{e}");
        assert_eq!(started.elapsed(), Duration::from_millis(1100));
        assert_eq!(controller.link().stats().retransmissions, 10);
        silent.set_nonblocking(true).unwrap();
        let mut buf = [0u8; 64];
        let mut received = 0;
        while silent.recv_from(&mut buf).is_ok() {
            received += 1;
        }
        assert_eq!(received, 11);
    }
}
