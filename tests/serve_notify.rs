//! `groundcal serve` under a fake systemd: the binary runs with
//! `NOTIFY_SOCKET` naming a Unix datagram socket the test listens on and
//! `WATCHDOG_USEC` set, as `Type=notify` with `WatchdogSec=` would. It must
//! say READY=1 once HTTP listens (and not before), feed the watchdog while
//! idle and all through a calibration, and say STOPPING=1 at SIGTERM.

mod common;

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{http, spawn_serve, temp_dir, terminate};

const TOKEN: &str = "notify-token";
/// `WatchdogSec=1s`: groundcal feeds it every 500 ms, and must never leave
/// it unfed for the whole second (on a loaded machine too).
const WATCHDOG_USEC: &str = "1000000";
const WATCHDOG_SEC: Duration = Duration::from_secs(1);

/// systemd's side of `NOTIFY_SOCKET`: a Unix datagram socket in a directory,
/// read by a thread of its own that stamps each datagram when it arrives.
struct FakeSystemd {
    path: PathBuf,
    received: Arc<Mutex<Vec<(Instant, String)>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl FakeSystemd {
    fn bind(dir: &Path) -> Self {
        let path = dir.join("notify.sock");
        let socket = UnixDatagram::bind(&path).expect("the fake systemd socket");
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let received = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (received, stop) = (Arc::clone(&received), Arc::clone(&stop));
            std::thread::spawn(move || {
                let mut buffer = [0u8; 4096];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(n) = socket.recv(&mut buffer) {
                        let text = String::from_utf8_lossy(&buffer[..n]).into_owned();
                        received.lock().unwrap().push((Instant::now(), text));
                    }
                }
            })
        };
        Self {
            path,
            received,
            stop,
            thread: Some(thread),
        }
    }

    /// Every notification so far, with when it arrived.
    fn messages(&self) -> Vec<(Instant, String)> {
        self.received.lock().unwrap().clone()
    }

    /// Waits (at most 10 s) for the first notification.
    fn first(&self) -> String {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if let Some((_, m)) = self.messages().first() {
                return m.clone();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("no notification within 10 s");
    }
}

impl Drop for FakeSystemd {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn watchdogs(messages: &[(Instant, String)]) -> Vec<Instant> {
    messages
        .iter()
        .filter(|(_, m)| m == "WATCHDOG=1")
        .map(|(t, _)| *t)
        .collect()
}

/// The longest gap between feedings from `from` to `until`.
fn longest_gap(feedings: &[Instant], from: Instant, until: Instant) -> Duration {
    let mut last = from;
    let mut longest = Duration::ZERO;
    for &t in feedings.iter().filter(|&&t| t >= from && t <= until) {
        longest = longest.max(t - last);
        last = t;
    }
    longest.max(until.saturating_duration_since(last))
}

#[test]
fn ready_once_listening_watchdog_fed_through_a_calibration_stopping_at_sigterm() {
    let dir = temp_dir("serve-notify");
    let systemd = FakeSystemd::bind(&dir);
    let (server, address) = spawn_serve(
        &dir,
        TOKEN,
        &[],
        &[
            ("NOTIFY_SOCKET", systemd.path.as_os_str()),
            ("WATCHDOG_USEC", std::ffi::OsStr::new(WATCHDOG_USEC)),
        ],
    );

    // READY=1 comes first, naming the address HTTP listens on, and the
    // address answers.
    let first = systemd.first();
    assert!(
        first.starts_with("READY=1\n") && first.contains(&format!("STATUS=listening on {address}")),
        "{first:?}"
    );
    let (code, status) = http(&address, "GET", "/api/status", None);
    assert_eq!((code, status["state"].as_str()), (200, Some("idle")));
    // The hardware was opened (and closed) before READY.
    assert!(
        status["hardware"]
            .as_str()
            .unwrap()
            .starts_with("opened: sim"),
        "{status}"
    );

    // Fed while idle: every 500 ms.
    let idle_from = Instant::now();
    std::thread::sleep(Duration::from_millis(1600));
    let idle_until = Instant::now();
    let fed = watchdogs(&systemd.messages());
    assert!(
        fed.iter().filter(|&&t| t >= idle_from).count() >= 2,
        "{:?}",
        systemd.messages()
    );
    assert!(longest_gap(&fed, idle_from, idle_until) < WATCHDOG_SEC);

    // Fed all through a calibration (the session loop beats).
    let (code, body) = http(&address, "POST", "/api/calibrations", Some(TOKEN));
    assert_eq!(code, 202, "{body}");
    let running_from = Instant::now();
    let mut ran = false;
    let finished = loop {
        let (_, status) = http(&address, "GET", "/api/status", None);
        ran |= status["state"] == "running";
        if status["state"] == "idle" && status["result_id"].is_string() {
            break status;
        }
        assert!(
            running_from.elapsed() < Duration::from_secs(180),
            "the calibration did not finish: {status}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let running_until = Instant::now();
    assert!(ran, "the calibration was never seen running");
    assert_eq!(finished["result"]["status"], "accepted", "{finished}");
    let gap = longest_gap(&watchdogs(&systemd.messages()), running_from, running_until);
    assert!(
        gap < WATCHDOG_SEC,
        "the watchdog went unfed for {gap:?} during the calibration"
    );

    // SIGTERM: STOPPING=1, and a clean exit.
    let (code, stderr) = terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let stopping = |m: &[(Instant, String)]| m.iter().any(|(_, m)| m == "STOPPING=1");
    let start = Instant::now();
    while !stopping(&systemd.messages()) && start.elapsed() < Duration::from_secs(2) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(stopping(&systemd.messages()), "{:?}", systemd.messages());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A Kinect that does not open does not stop the service: READY still comes
/// (the page must stay up to say what is wrong), and the status says why.
#[test]
fn a_missing_kinect_is_reported_not_fatal() {
    let dir = temp_dir("serve-notify-no-kinect");
    let systemd = FakeSystemd::bind(&dir);
    let (server, address) = spawn_serve(
        &dir,
        TOKEN,
        &[
            "--sensor",
            "kinect",
            "--freenect-lib",
            "/nonexistent/libfreenect.so.0.5",
        ],
        &[("NOTIFY_SOCKET", systemd.path.as_os_str())],
    );
    let first = systemd.first();
    assert!(first.starts_with("READY=1"), "{first:?}");
    let (_, status) = http(&address, "GET", "/api/status", None);
    let hardware = status["hardware"].as_str().unwrap();
    assert!(
        hardware.starts_with("not opened:") && hardware.contains("libfreenect"),
        "{status}"
    );
    let (code, stderr) = terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
