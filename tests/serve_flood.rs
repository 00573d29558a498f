//! `groundcal serve` under floods, as the real process under the usual
//! 1,024-descriptor limit: connections that never finish their request, and
//! live event streams opened by a client without a token (each a request in
//! flight that never ends). The operator's status and Abort still answer
//! (within 1 s under streams), the robot is halted and sent home, and the
//! result of a calibration run through a flood is kept.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::Value;

const TOKEN: &str = "flood-token";
const FLOOD: usize = 1_100;
const DESCRIPTORS: u32 = 1_024;

/// The soft and hard limits on open files of a process, from /proc.
fn open_files_limit(pid: u32) -> (u64, u64) {
    let limits = std::fs::read_to_string(format!("/proc/{pid}/limits")).unwrap();
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max open files"))
        .unwrap();
    let numbers: Vec<u64> = line
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    (numbers[0], numbers[1])
}

fn set_open_files_limit(pid: u32, soft: u64, hard: u64) {
    let status = Command::new("prlimit")
        .args([
            "--pid",
            &pid.to_string(),
            &format!("--nofile={soft}:{hard}"),
        ])
        .status()
        .expect("prlimit (util-linux) runs");
    assert!(status.success(), "prlimit failed");
}

fn descriptors_of(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| d.count())
        .unwrap_or(0)
}

/// One request with its own timeouts; (status code, JSON body, time taken).
fn request(address: &str, method: &str, path: &str, token: bool) -> (u16, Value, Duration) {
    let start = Instant::now();
    let mut stream = TcpStream::connect(address).expect("the server accepts");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let auth = if token {
        format!("Authorization: Bearer {TOKEN}\r\n")
    } else {
        String::new()
    };
    write!(
        stream,
        "{method} {path} HTTP/1.1\r\nHost: {address}\r\nX-Groundcal-Client: operator\r\n{auth}Content-Length: 0\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = Vec::new();
    stream
        .read_to_end(&mut response)
        .expect("a response within 10 s");
    let response = String::from_utf8_lossy(&response).into_owned();
    let code = response
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("bad response: {response:?}"));
    let body = response.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    (
        code,
        serde_json::from_str(body).unwrap_or(Value::Null),
        start.elapsed(),
    )
}

/// Keeps `FLOOD` connections open that send half a request and nothing more,
/// replacing the oldest with a new one, until stopped. Returns how many it
/// opened in all.
fn flood(address: String, stop: Arc<AtomicBool>, opened: Arc<AtomicUsize>) {
    let mut open = std::collections::VecDeque::new();
    while !stop.load(Ordering::Relaxed) {
        match TcpStream::connect_timeout(&address.parse().unwrap(), Duration::from_secs(1)) {
            Ok(mut s) => {
                let _ = s.write_all(b"GET /api/status HTTP/1.1\r\nHost: x\r\n");
                open.push_back(s);
                opened.fetch_add(1, Ordering::Relaxed);
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
        if open.len() > FLOOD {
            open.pop_front();
        }
        if opened.load(Ordering::Relaxed) > FLOOD {
            // Full: keep the flood standing with a new one every few ms.
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

fn wait_until(address: &str, done: impl Fn(&Value) -> bool, within: Duration) -> (Value, Duration) {
    let start = Instant::now();
    let mut slowest = Duration::ZERO;
    loop {
        let (code, status, took) = request(address, "GET", "/api/status", false);
        assert_eq!(code, 200, "{status}");
        slowest = slowest.max(took);
        if done(&status) {
            return (status, slowest);
        }
        assert!(start.elapsed() < within, "not done in {within:?}: {status}");
        std::thread::sleep(Duration::from_millis(300));
    }
}

#[test]
fn a_flood_of_half_open_connections_does_not_lock_the_operator_out() {
    // The flooder needs more descriptors than the server is given.
    let me = std::process::id();
    let (soft, hard) = open_files_limit(me);
    if soft < 4 * FLOOD as u64 {
        set_open_files_limit(me, (4 * FLOOD as u64).min(hard), hard);
    }
    let dir = common::TempDir::new("serve-flood");
    let (mut server, address) = common::spawn_serve(dir.path(), TOKEN, &[], &[]);
    let pid = server.id();
    set_open_files_limit(pid, u64::from(DESCRIPTORS), u64::from(DESCRIPTORS));
    assert_eq!(open_files_limit(pid).0, u64::from(DESCRIPTORS));
    // Its log, read as it comes so that the pipe never fills.
    let stderr = server.stderr.take().unwrap();
    let log = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::BufReader::new(stderr).read_to_string(&mut text);
        text
    });

    let stop = Arc::new(AtomicBool::new(false));
    let opened = Arc::new(AtomicUsize::new(0));
    let flooder = {
        let (address, stop, opened) = (address.clone(), stop.clone(), opened.clone());
        std::thread::spawn(move || flood(address, stop, opened))
    };
    let flooded = Instant::now();
    while opened.load(Ordering::Relaxed) < FLOOD {
        assert!(
            flooded.elapsed() < Duration::from_secs(60),
            "the flood did not start"
        );
        std::thread::sleep(Duration::from_millis(10));
    }

    // A calibration started and run to its end through the flood.
    let (code, body, took) = request(&address, "POST", "/api/calibrations", true);
    assert_eq!(code, 202, "{body}");
    let mut slowest = took;
    let mut most_descriptors = 0;
    let (status, slowest_status) = wait_until(
        &address,
        |s| s["state"] == "idle" && (s["result_id"].is_string() || s["error"].is_string()),
        Duration::from_secs(180),
    );
    slowest = slowest.max(slowest_status);
    most_descriptors = most_descriptors.max(descriptors_of(pid));
    assert!(status["error"].is_null(), "the result was lost: {status}");
    let id = status["result_id"].as_str().unwrap().to_string();
    let (code, kept, _) = request(&address, "GET", &format!("/api/calibrations/{id}"), false);
    assert_eq!(code, 200, "{kept}");
    assert_eq!(kept["status"], "accepted", "{kept}");

    // Another one, aborted through the flood.
    let (code, body, _) = request(&address, "POST", "/api/calibrations", true);
    assert_eq!(code, 202, "{body}");
    std::thread::sleep(Duration::from_millis(500));
    let (code, body, took) = request(&address, "POST", "/api/calibrations/current/abort", true);
    assert_eq!(code, 202, "{body}");
    slowest = slowest.max(took);
    let (status, slowest_status) =
        wait_until(&address, |s| s["state"] == "idle", Duration::from_secs(60));
    slowest = slowest.max(slowest_status);
    most_descriptors = most_descriptors.max(descriptors_of(pid));
    let robot = status["robot"].as_str().unwrap_or_default();
    assert!(robot.contains("aborted"), "{status}");

    stop.store(true, Ordering::Relaxed);
    flooder.join().unwrap();
    let total = opened.load(Ordering::Relaxed);
    eprintln!(
        "flood: {total} half-open connections opened ({FLOOD} standing); the operator's slowest answer {slowest:?}; \
         at most {most_descriptors} descriptors of {DESCRIPTORS} in use"
    );
    assert!(
        slowest < Duration::from_secs(3),
        "the operator waited {slowest:?}"
    );
    assert!(most_descriptors < DESCRIPTORS as usize / 2);
    let (code, stderr) = common::terminate(server);
    let stderr = stderr + &log.join().unwrap();
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("Too many open files"), "{stderr}");
}

/// Keeps `count` live event streams open (no token needed to read), opening
/// a new one every few ms and dropping its own oldest, as a client that
/// reconnects whatever the server closes. Returns how many it opened.
fn stream_flood(address: String, count: usize, stop: Arc<AtomicBool>, opened: Arc<AtomicUsize>) {
    let mut open = std::collections::VecDeque::new();
    while !stop.load(Ordering::Relaxed) {
        match TcpStream::connect_timeout(&address.parse().unwrap(), Duration::from_secs(1)) {
            Ok(mut s) => {
                let _ = write!(
                    s,
                    "GET /api/events HTTP/1.1\r\nHost: {address}\r\nAccept: text/event-stream\r\n\r\n"
                );
                open.push_back(s);
                opened.fetch_add(1, Ordering::Relaxed);
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
        if open.len() > count {
            open.pop_front();
        }
        if opened.load(Ordering::Relaxed) > count {
            std::thread::sleep(Duration::from_millis(3));
        }
    }
}

/// A flood running on its own thread until dropped.
struct Flood {
    stop: Arc<AtomicBool>,
    opened: Arc<AtomicUsize>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Flood {
    fn start(
        target: usize,
        run: impl FnOnce(Arc<AtomicBool>, Arc<AtomicUsize>) + Send + 'static,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let opened = Arc::new(AtomicUsize::new(0));
        let thread = {
            let (stop, opened) = (stop.clone(), opened.clone());
            std::thread::spawn(move || run(stop, opened))
        };
        let started = Instant::now();
        while opened.load(Ordering::Relaxed) < target {
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "the flood did not start"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        Flood {
            stop,
            opened,
            thread: Some(thread),
        }
    }

    fn opened(&self) -> usize {
        self.opened.load(Ordering::Relaxed)
    }
}

impl Drop for Flood {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// During a calibration against a lower computer in its own process, under
/// `streams` event streams and `half_open` half-open connections: status
/// answers 200 and Abort 202 within 1 s each, the run ends aborted with
/// the robot at home, and HALT then HOME reached the lower computer.
fn abort_gets_through(tag: &str, streams: usize, half_open: usize) {
    let me = std::process::id();
    let (soft, hard) = open_files_limit(me);
    let wanted = 4 * (streams + half_open) as u64 + 256;
    if soft < wanted {
        set_open_files_limit(me, wanted.min(hard), hard);
    }
    let dir = common::TempDir::new(tag);
    // The simulator at 50×: 52 poses still run for seconds, long enough to
    // flood, ask and abort while the body moves.
    let (mut server, address, robot, receipts) =
        common::spawn_serve_towards_sim_robot(dir.path(), TOKEN, &[]);
    let pid = server.id();
    set_open_files_limit(pid, u64::from(DESCRIPTORS), u64::from(DESCRIPTORS));
    let stderr = server.stderr.take().unwrap();
    let log = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::BufReader::new(stderr).read_to_string(&mut text);
        text
    });

    let (code, body, _) = request(&address, "POST", "/api/calibrations", true);
    assert_eq!(code, 202, "{body}");
    let streaming = (streams > 0).then(|| {
        let a = address.clone();
        Flood::start(streams, move |stop, opened| {
            stream_flood(a, streams, stop, opened)
        })
    });
    let half_opening = (half_open > 0).then(|| {
        let a = address.clone();
        Flood::start(half_open, move |stop, opened| flood(a, stop, opened))
    });
    // The body is moving through its poses by now.
    std::thread::sleep(Duration::from_millis(1500));
    let mut slowest = Duration::ZERO;
    let mut most_descriptors = 0;
    for _ in 0..5 {
        let (code, status, took) = request(&address, "GET", "/api/status", false);
        assert_eq!(code, 200, "{status}");
        assert_eq!(status["state"], "running", "{status}");
        slowest = slowest.max(took);
        most_descriptors = most_descriptors.max(descriptors_of(pid));
        std::thread::sleep(Duration::from_millis(200));
    }
    let (code, body, abort_took) =
        request(&address, "POST", "/api/calibrations/current/abort", true);
    assert_eq!(code, 202, "{body}");
    let (status, slowest_status) =
        wait_until(&address, |s| s["state"] == "idle", Duration::from_secs(60));
    slowest = slowest.max(slowest_status);
    most_descriptors = most_descriptors.max(descriptors_of(pid));
    let stream_count = streaming.as_ref().map_or(0, Flood::opened);
    let half_open_count = half_opening.as_ref().map_or(0, Flood::opened);
    drop(streaming);
    drop(half_opening);
    eprintln!(
        "{tag}: {stream_count} streams and {half_open_count} half-open connections opened ({streams} and {half_open} standing); \
         status at worst {slowest:?}, Abort {abort_took:?}; at most {most_descriptors} descriptors of {DESCRIPTORS}"
    );
    assert!(slowest < Duration::from_secs(1), "status took {slowest:?}");
    assert!(
        abort_took < Duration::from_secs(1),
        "Abort took {abort_took:?}"
    );
    assert_eq!(status["abort"]["state"], "aborted", "{status}");
    assert_eq!(status["abort"]["robot_left"], "home", "{status}");
    let (code, stderr) = common::terminate(server);
    let stderr = stderr + &log.join().unwrap();
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("Too many open files"), "{stderr}");
    common::stop_sim_robot(robot);
    let kinds = common::received_kinds(&receipts);
    let halt = kinds
        .iter()
        .rposition(|k| k == "HALT")
        .unwrap_or_else(|| panic!("no HALT reached the lower computer: {kinds:?}"));
    assert!(
        kinds[halt..].iter().any(|k| k == "HOME"),
        "no HOME after the HALT: {:?}",
        &kinds[halt..]
    );
}

#[test]
fn event_streams_opened_without_a_token_do_not_lock_out_abort() {
    abort_gets_through("serve-stream-flood", 600, 0);
}

#[test]
fn event_streams_and_half_open_connections_together_do_not_lock_out_abort() {
    abort_gets_through("serve-both-floods", 600, FLOOD);
}

/// The operator's page opens its live stream with the token's one-use
/// ticket; ten other loopback addresses then hold eight streams each,
/// opened without the token and reopened as fast as they are closed. For
/// 10 s the operator's stream is never closed and hears every heartbeat;
/// a used ticket opens nothing.
#[test]
fn streams_opened_without_the_token_never_close_the_operators() {
    let dir = common::TempDir::new("flood-operator-stream");
    let (server, address) = common::spawn_serve(dir.path(), TOKEN, &[], &[]);
    let (code, body, _) = request(&address, "POST", "/api/stream-ticket", true);
    assert_eq!(code, 200, "{body}");
    let ticket = body["ticket"].as_str().unwrap().to_string();
    let (code, _, _) = request(&address, "POST", "/api/stream-ticket", false);
    assert_eq!(code, 401, "a ticket needs the token");

    let mut operator = TcpStream::connect(&address).unwrap();
    operator
        .set_read_timeout(Some(Duration::from_secs(3)))
        .unwrap();
    write!(
        operator,
        "GET /api/events?ticket={ticket} HTTP/1.1\r\nHost: {address}\r\nAccept: text/event-stream\r\n\r\n"
    )
    .unwrap();

    let stop = Arc::new(AtomicBool::new(false));
    let opened = Arc::new(AtomicUsize::new(0));
    let strangers: Vec<_> = (2..12u8)
        .map(|n| {
            let (address, stop, opened) = (address.clone(), stop.clone(), opened.clone());
            std::thread::spawn(move || {
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                    .unwrap();
                runtime.block_on(async move {
                    use tokio::io::AsyncWriteExt;
                    let mut open = std::collections::VecDeque::new();
                    while !stop.load(Ordering::Relaxed) {
                        let socket = tokio::net::TcpSocket::new_v4().unwrap();
                        socket
                            .bind(format!("127.0.0.{n}:0").parse().unwrap())
                            .unwrap();
                        if let Ok(mut s) = socket.connect(address.parse().unwrap()).await {
                            let request = format!(
                                "GET /api/events HTTP/1.1\r\nHost: {address}\r\nAccept: text/event-stream\r\n\r\n"
                            );
                            let _ = s.write_all(request.as_bytes()).await;
                            open.push_back(s);
                            opened.fetch_add(1, Ordering::Relaxed);
                        }
                        if open.len() > 8 {
                            open.pop_front();
                        }
                        tokio::time::sleep(Duration::from_millis(5)).await;
                    }
                });
            })
        })
        .collect();

    let started = Instant::now();
    let mut heard = Vec::new();
    let mut heartbeats = 0;
    let mut buffer = [0u8; 4096];
    while started.elapsed() < Duration::from_secs(10) {
        match operator.read(&mut buffer) {
            Ok(0) => panic!(
                "the operator's stream was closed after {:?} ({} strangers' streams opened)",
                started.elapsed(),
                opened.load(Ordering::Relaxed)
            ),
            Ok(n) => {
                heard.extend_from_slice(&buffer[..n]);
                heartbeats = String::from_utf8_lossy(&heard)
                    .matches("\"type\":\"heartbeat\"")
                    .count();
            }
            Err(e) => panic!("the operator's stream fell silent: {e}"),
        }
    }
    stop.store(true, Ordering::Relaxed);
    for s in strangers {
        s.join().unwrap();
    }
    let strangers_opened = opened.load(Ordering::Relaxed);
    eprintln!("operator's stream: {heartbeats} heartbeats in 10 s, {strangers_opened} strangers' streams opened");
    assert!(heartbeats >= 8, "{heartbeats} heartbeats");
    assert!(strangers_opened >= 200, "{strangers_opened}");
    // The ticket was used: it opens nothing again.
    let (code, _, _) = request(
        &address,
        "GET",
        &format!("/api/events?ticket={ticket}"),
        false,
    );
    assert_eq!(code, 403);
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
}
