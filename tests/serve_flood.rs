//! `groundcal serve` under a flood of connections that never finish their
//! request, as the real process under the usual 1,024-descriptor limit: the
//! operator's status and Abort still answer within 3 s, and the result of a
//! calibration run through the flood is kept.

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
    let (mut server, address) = common::spawn_serve(&dir.0, TOKEN, &[], &[]);
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
