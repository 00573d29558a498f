//! The systemd notification protocol (`sd_notify`): READY=1 once the hardware
//! is open and HTTP listens, WATCHDOG=1 from the session loop, STATUS= for
//! `systemctl status`. A datagram to the Unix socket named by `NOTIFY_SOCKET`
//! (a path, or `@name` for the abstract namespace); nothing when it is unset.

use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

/// A handle to systemd's notification socket, if the service has one.
#[derive(Debug)]
pub struct Notifier {
    socket: Option<(UnixDatagram, String)>,
}

impl Notifier {
    /// From the environment (`NOTIFY_SOCKET`).
    pub fn from_env() -> Self {
        let socket = std::env::var("NOTIFY_SOCKET")
            .ok()
            .filter(|s| !s.is_empty())
            .and_then(|path| UnixDatagram::unbound().ok().map(|socket| (socket, path)));
        Self { socket }
    }

    /// Whether systemd is listening.
    pub fn enabled(&self) -> bool {
        self.socket.is_some()
    }

    fn send(&self, message: &str) {
        let Some((socket, path)) = &self.socket else {
            return;
        };
        let sent = if let Some(name) = path.strip_prefix('@') {
            send_abstract(socket, name, message)
        } else {
            socket.send_to(message.as_bytes(), path).map(|_| ())
        };
        if let Err(e) = sent {
            tracing::warn!(%e, "cannot notify systemd");
        }
    }

    /// The service is up.
    pub fn ready(&self, status: &str) {
        self.send(&format!("READY=1\nSTATUS={status}"));
    }

    /// The service is alive (to be sent more often than `WatchdogSec`).
    pub fn watchdog(&self) {
        self.send("WATCHDOG=1");
    }

    /// A line for `systemctl status`.
    pub fn status(&self, status: &str) {
        self.send(&format!("STATUS={status}"));
    }

    /// The service is stopping.
    pub fn stopping(&self) {
        self.send("STOPPING=1");
    }
}

#[cfg(target_os = "linux")]
fn send_abstract(socket: &UnixDatagram, name: &str, message: &str) -> std::io::Result<()> {
    use std::os::linux::net::SocketAddrExt;
    let address = std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes())?;
    socket
        .send_to_addr(message.as_bytes(), &address)
        .map(|_| ())
}

#[cfg(not(target_os = "linux"))]
fn send_abstract(_socket: &UnixDatagram, _name: &str, _message: &str) -> std::io::Result<()> {
    Err(std::io::Error::other("abstract sockets are Linux only"))
}

/// Half of the watchdog interval systemd asks for (`WATCHDOG_USEC`), if any.
/// Like `sd_watchdog_enabled(3)`, a `WATCHDOG_PID` that names another
/// process means the watchdog is not ours to feed (a child inherited it).
pub fn watchdog_interval() -> Option<Duration> {
    watchdog_interval_from(
        std::env::var("WATCHDOG_USEC").ok().as_deref(),
        std::env::var("WATCHDOG_PID").ok().as_deref(),
        std::process::id(),
    )
}

fn watchdog_interval_from(usec: Option<&str>, pid: Option<&str>, own_pid: u32) -> Option<Duration> {
    let usec: u64 = usec?.parse().ok()?;
    if let Some(pid) = pid {
        if pid.parse::<u32>().ok()? != own_pid {
            return None;
        }
    }
    (usec > 0).then(|| Duration::from_micros(usec / 2))
}

/// Whether the watchdog may be fed: no session is running, or the running
/// session's loop beat within `within`. A session stuck (a blocked call, a
/// deadlock) stops the feeding, and systemd restarts the service.
pub fn session_alive(last_beat: Option<Instant>, now: Instant, within: Duration) -> bool {
    last_beat.is_none_or(|beat| now.saturating_duration_since(beat) <= within)
}

/// How often a session's loop beats: twice per watchdog feeding interval
/// (itself half of `WatchdogSec`), at most every 500 ms.
pub fn heartbeat_period() -> Duration {
    let most = Duration::from_millis(500);
    watchdog_interval().map_or(most, |every| (every / 2).min(most))
}

/// Feeds systemd's watchdog while the session is alive (see
/// [`session_alive`]); `last_beat` says when its loop last beat. None when
/// the service runs without a watchdog.
pub fn spawn_watchdog_feed(
    last_beat: impl Fn() -> Option<Instant> + Send + 'static,
) -> Option<tokio::task::JoinHandle<()>> {
    let every = watchdog_interval()?;
    Some(tokio::spawn(async move {
        let notifier = Notifier::from_env();
        let mut tick = tokio::time::interval(every);
        loop {
            tick.tick().await;
            if session_alive(last_beat(), Instant::now(), every * 2) {
                notifier.watchdog();
            } else {
                // systemd restarts the service after WatchdogSec; the lower
                // computer halts the robot once polling stops (1 s).
                tracing::error!("the session loop is stuck; not feeding the watchdog");
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_watchdog_is_fed_only_by_the_process_it_names() {
        let half = Some(Duration::from_secs(5));
        assert_eq!(watchdog_interval_from(Some("10000000"), None, 42), half);
        assert_eq!(
            watchdog_interval_from(Some("10000000"), Some("42"), 42),
            half
        );
        assert_eq!(
            watchdog_interval_from(Some("10000000"), Some("43"), 42),
            None
        );
        assert_eq!(
            watchdog_interval_from(Some("10000000"), Some("x"), 42),
            None
        );
        assert_eq!(watchdog_interval_from(Some("0"), None, 42), None);
        assert_eq!(watchdog_interval_from(None, Some("42"), 42), None);
    }

    #[test]
    fn a_stuck_session_stops_the_watchdog_feeding() {
        let now = Instant::now();
        let within = Duration::from_secs(10);
        assert!(session_alive(None, now, within), "idle: fed");
        assert!(session_alive(
            Some(now - Duration::from_secs(3)),
            now,
            within
        ));
        assert!(!session_alive(
            Some(now - Duration::from_secs(11)),
            now,
            within
        ));
    }

    #[test]
    fn messages_reach_a_fake_notify_socket() {
        let path = std::env::temp_dir().join(format!("groundcal-notify-{}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let listener = UnixDatagram::bind(&path).unwrap();
        listener
            .set_read_timeout(Some(Duration::from_secs(2)))
            .unwrap();
        let notifier = Notifier {
            socket: Some((
                UnixDatagram::unbound().unwrap(),
                path.to_string_lossy().into_owned(),
            )),
        };
        notifier.ready("listening on 127.0.0.1:8080");
        notifier.watchdog();
        let mut buf = [0u8; 256];
        let n = listener.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"READY=1\nSTATUS=listening on 127.0.0.1:8080");
        let n = listener.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"WATCHDOG=1");
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn without_a_socket_nothing_is_sent() {
        let notifier = Notifier { socket: None };
        assert!(!notifier.enabled());
        notifier.ready("x");
    }
}
