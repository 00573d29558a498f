//! `groundcal serve` under a fake systemd: the binary runs with
//! `NOTIFY_SOCKET` naming a Unix datagram socket the test listens on and
//! `WATCHDOG_USEC` set, as `Type=notify` with `WatchdogSec=` would. It must
//! say READY=1 once HTTP listens (and not before), feed the watchdog while
//! idle and all through a calibration, and say STOPPING=1 at SIGTERM.

mod common;

use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

use common::{http, spawn_serve, temp_dir, terminate};

const TOKEN: &str = "notify-token";
/// `WatchdogSec=0.4s`: groundcal feeds it every 200 ms.
const WATCHDOG_USEC: &str = "400000";

/// systemd's side of `NOTIFY_SOCKET`: a Unix datagram socket in `dir`.
fn fake_systemd(dir: &std::path::Path) -> (UnixDatagram, std::path::PathBuf) {
    let path = dir.join("notify.sock");
    let socket = UnixDatagram::bind(&path).expect("the fake systemd socket");
    socket
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    (socket, path)
}

/// Waits (at most 10 s) for the first notification.
fn first_notification(socket: &UnixDatagram, into: &mut Vec<(Instant, String)>) -> String {
    let start = Instant::now();
    while into.is_empty() && start.elapsed() < Duration::from_secs(10) {
        drain(socket, into);
    }
    into.first().expect("a notification within 10 s").1.clone()
}

/// The notifications received so far, one string per datagram.
fn drain(socket: &UnixDatagram, into: &mut Vec<(Instant, String)>) {
    let mut buffer = [0u8; 4096];
    while let Ok(n) = socket.recv(&mut buffer) {
        into.push((
            Instant::now(),
            String::from_utf8_lossy(&buffer[..n]).into_owned(),
        ));
    }
}

fn watchdogs(messages: &[(Instant, String)]) -> Vec<Instant> {
    messages
        .iter()
        .filter(|(_, m)| m == "WATCHDOG=1")
        .map(|(t, _)| *t)
        .collect()
}

/// The longest gap between feedings from `from` on.
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
    let (socket, socket_path) = fake_systemd(&dir);

    let (server, address) = spawn_serve(
        &dir,
        TOKEN,
        &[],
        &[
            ("NOTIFY_SOCKET", socket_path.as_os_str()),
            ("WATCHDOG_USEC", std::ffi::OsStr::new(WATCHDOG_USEC)),
        ],
    );

    // READY=1 comes first, naming the address HTTP listens on, and the
    // address answers.
    let mut messages = Vec::new();
    let first = first_notification(&socket, &mut messages);
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
            .starts_with("ready: sim"),
        "{status}"
    );

    // Fed while idle: about every 200 ms.
    let idle_from = Instant::now();
    while idle_from.elapsed() < Duration::from_secs(1) {
        drain(&socket, &mut messages);
    }
    let idle_until = Instant::now();
    let fed = watchdogs(&messages);
    assert!(
        fed.iter().filter(|&&t| t >= idle_from).count() >= 3,
        "{messages:?}"
    );
    assert!(longest_gap(&fed, idle_from, idle_until) < Duration::from_millis(400));

    // Fed all through a calibration (the session loop beats).
    let (code, body) = http(&address, "POST", "/api/calibrations", Some(TOKEN));
    assert_eq!(code, 202, "{body}");
    let running_from = Instant::now();
    let mut ran = false;
    let finished = loop {
        drain(&socket, &mut messages);
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
    let fed = watchdogs(&messages);
    let gap = longest_gap(&fed, running_from, running_until);
    assert!(
        gap < Duration::from_millis(400),
        "the watchdog went unfed for {gap:?} during the calibration"
    );

    // SIGTERM: STOPPING=1, and a clean exit.
    let (code, stderr) = terminate(server);
    drain(&socket, &mut messages);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        messages.iter().any(|(_, m)| m == "STOPPING=1"),
        "{messages:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A Kinect that does not open does not stop the service: READY still comes
/// (the page must stay up to say what is wrong), and the status says why.
#[test]
fn a_missing_kinect_is_reported_not_fatal() {
    let dir = temp_dir("serve-notify-no-kinect");
    let (socket, socket_path) = fake_systemd(&dir);
    let (server, address) = spawn_serve(
        &dir,
        TOKEN,
        &[
            "--sensor",
            "kinect",
            "--freenect-lib",
            "/nonexistent/libfreenect.so.0.5",
        ],
        &[("NOTIFY_SOCKET", socket_path.as_os_str())],
    );
    let first = first_notification(&socket, &mut Vec::new());
    assert!(first.starts_with("READY=1"), "{first:?}");
    let (_, status) = http(&address, "GET", "/api/status", None);
    let hardware = status["hardware"].as_str().unwrap();
    assert!(
        hardware.starts_with("not ready:") && hardware.contains("libfreenect"),
        "{status}"
    );
    let (code, stderr) = terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
