//! The `groundcal serve` terminal page in a real browser: headless Chromium,
//! driven by Playwright (`tests/browser/serve.mjs`), types the token, presses
//! Calibrate, sees progress and the verdict, presses Accept; then the store's
//! `active.json` must hold the result. The server is the `groundcal serve`
//! binary on 127.0.0.1:0 with `config/sim.toml` (simulated robot and Kinect).
//! Screenshots land in `target/test-screenshots/serve-*.png`.
//!
//! Needs Node.js ≥ 20, `npm ci` in `tests/browser` and Debian's chromium. Under
//! `CI=true` a missing one fails the test; elsewhere the test warns and returns.

mod common;

use std::ffi::OsStr;
use std::fs;

const TOKEN: &str = "browser-token";

/// The screenshots `serve.mjs` saves, one per state of the page.
const SHOTS: [&str; 9] = [
    "1-idle",
    "1b-confirm-calibrate",
    "2-progress",
    "3-verdict",
    "3b-confirm",
    "4-accepted",
    "8-rollback",
    "7-aborted",
    "9-pad",
];

#[test]
fn terminal_page_calibrates_and_accepts_in_chromium() {
    if !common::browser_ready("serve_browser") {
        return;
    }

    let dir = common::temp_dir("serve-browser");
    // config/sim.toml keeps its store in state.sim beside the configuration.
    let state_dir = dir.join("state.sim");
    let (server, addr) = common::spawn_serve(&dir, TOKEN, &[], &[]);

    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    for step in SHOTS {
        let _ = fs::remove_file(shots.join(format!("serve-{step}.png")));
    }
    let url = format!("http://{addr}/");
    let seen = common::run_browser_script(
        "serve.mjs",
        &[OsStr::new(&url), OsStr::new(TOKEN), shots.as_os_str()],
    );
    let seen = &seen["seen"];
    let text = |key: &str| seen[key].as_str().unwrap_or_default().to_string();
    // Idle: no empty result or chart card.
    assert_eq!(
        seen["idleCards"],
        serde_json::json!(["run", "view-card", "active-card", "history-card"]),
        "{seen}"
    );
    // Calibrate asks first, saying how long the robot moves and to keep
    // clear; Cancel sent nothing and nothing started.
    let confirm = text("confirmCalibrate");
    assert!(
        confirm.contains("52 poses")
            && confirm.contains("about")
            && confirm.contains("Keep everyone clear"),
        "{seen}"
    );
    assert_eq!(seen["cancelled"]["posts"], 0, "{seen}");
    assert_eq!(seen["cancelled"]["confirmHidden"], true, "{seen}");
    assert_eq!(seen["cancelled"]["state"], "idle", "{seen}");
    // Progress: the step in words, the bar, the time so far and left, and
    // charts with axes and the gate.
    let step = text("step");
    assert!(
        ["moving the body (", "capturing the ground", "ground found"]
            .iter()
            .any(|words| step.contains(words)),
        "{seen}"
    );
    assert!(text("motion").contains("moving the body (rolled"), "{seen}");
    assert!(seen["bar"].as_f64().unwrap() > 0.0, "{seen}");
    assert!(
        text("times").contains("so far") && text("times").contains("left"),
        "{seen}"
    );
    assert!(seen["livePoints"].as_u64().unwrap() >= 6, "{seen}");
    assert_eq!(text("liveTitle"), "Fit per pose, so far", "{seen}");
    assert!(seen["gateLines"].as_u64().unwrap() >= 2, "{seen}");
    assert!(
        seen["axisLabels"]
            .as_array()
            .unwrap()
            .iter()
            .any(|l| l == "pose"),
        "{seen}"
    );
    // The verdict says the checks passed, not that anything was accepted,
    // with the six values and their σ.
    assert_eq!(text("verdict"), "Passed its checks", "{seen}");
    assert!(seen["points"].as_u64().unwrap() > 6, "{seen}");
    // Header, the six parameters and the depth scale.
    assert_eq!(seen["values"].as_array().unwrap().len(), 8, "{seen}");
    assert!(
        seen["values"][7].as_str().unwrap().starts_with("s"),
        "{seen}"
    );
    // The checks it passed, each with its figure and limit.
    let gates = seen["gates"].as_array().unwrap();
    assert!(gates.len() >= 6, "{seen}");
    assert!(
        gates.iter().any(|g| g
            .as_str()
            .unwrap()
            .starts_with("✓ ground angle θ, the worst pose: ")
            && g.as_str().unwrap().contains("at most 1.000°")),
        "{seen}"
    );
    assert!(text("gatesTitle").contains(" passed"), "{seen}");
    // Each σ with the one predicted before the robot moved.
    assert_eq!(seen["predicted"], 7, "{seen}");
    assert_eq!(
        seen["warp"]["words"], "The depth image shows no warp of its own.",
        "{seen}"
    );
    assert_eq!(seen["warp"]["shown"], serde_json::json!([]), "{seen}");
    assert!(text("notActiveYet").starts_with("Not active yet"), "{seen}");
    // Accept asks first, then shows Active and hides itself.
    assert!(
        text("confirmQuestion").contains("the active one?"),
        "{seen}"
    );
    assert!(text("activeLine").contains("Active since"), "{seen}");
    assert_eq!(seen["acceptHidden"], true, "{seen}");
    assert_eq!(seen["storedToken"], TOKEN, "{seen}");
    // The second result against the active (first) one, then Rollback.
    assert!(
        text("change").starts_with("Against the active calibration"),
        "{seen}"
    );
    assert!(
        text("rollbackQuestion").starts_with("Roll back to the calibration of "),
        "{seen}"
    );
    let rollback = &seen["afterRollback"];
    let history = rollback["history"].as_array().unwrap();
    assert_eq!(history.len(), 2, "{seen}");
    assert!(history[1].as_str().unwrap().ends_with("Active"), "{seen}");
    assert!(
        history[0].as_str().unwrap().ends_with("Roll back to this"),
        "{seen}"
    );
    assert!(
        rollback["active"]
            .as_str()
            .unwrap()
            .starts_with(rollback["first"].as_str().unwrap()),
        "{seen}"
    );
    // Without a token, Calibrate says so before asking anything.
    assert!(
        seen["noToken"]["message"]
            .as_str()
            .unwrap_or_default()
            .starts_with("Type the token first")
            && seen["noToken"]["confirmHidden"] == true
            && seen["noToken"]["tokenOpen"] == true,
        "{seen}"
    );
    // The second run's question takes its time from the first run here (a
    // simulator 50× faster than the robot), and the page says "starting"
    // from the moment it is confirmed.
    assert!(
        text("confirmSecond").contains(", as the last one took"),
        "{seen}"
    );
    assert_eq!(text("titleAtStart"), "starting", "{seen}");
    // A calibration replaced by a rollback says so, without an Accept.
    assert!(
        seen["replaced"]["line"]
            .as_str()
            .unwrap_or_default()
            .starts_with("It was the active calibration until")
            && seen["replaced"]["acceptHidden"] == true,
        "{seen}"
    );
    // Aborted: "aborting…" (or already "aborted: at home"), then "aborted:
    // at home", in words said once.
    assert!(
        ["aborting…", "aborted: at home"].contains(&text("aborting").as_str()),
        "{seen}"
    );
    assert!(
        text("aborted").contains("it stands at the home stance"),
        "{seen}"
    );
    // A pad shows two columns side by side.
    let columns = seen["padColumns"].as_array().unwrap();
    assert!(
        columns.len() == 2 && columns[1].as_u64() > columns[0].as_u64(),
        "{seen}"
    );

    let active: serde_json::Value = serde_json::from_str(
        &fs::read_to_string(state_dir.join("active.json")).expect("active.json written"),
    )
    .unwrap();
    assert!(
        active["robot_from_sensor"]["beta_deg"].is_number(),
        "{active}"
    );
    let id = active["id"].as_str().unwrap();
    // Rolled back: the first calibration is active again.
    assert_eq!(id, rollback["first"].as_str().unwrap());
    let stored: serde_json::Value = serde_json::from_str(
        &fs::read_to_string(state_dir.join(format!("history/{id}.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(stored["robot_from_sensor"], active["robot_from_sensor"]);

    for step in SHOTS {
        let bytes = fs::read(shots.join(format!("serve-{step}.png"))).expect("screenshot saved");
        assert!(
            bytes.len() > 1000 && bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "serve-{step}.png is not a PNG with content"
        );
    }
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "groundcal serve at SIGTERM: {stderr}");
    let _ = fs::remove_dir_all(&dir);
}

/// The daemon killed mid-run: the page says within 3 s that it has lost
/// contact (and disables the buttons that start anything; Abort says it
/// could not be sent); once the daemon is back, the page finds it again and
/// shows the run as interrupted.
#[test]
fn a_dead_daemon_does_not_look_alive_and_its_cut_off_run_is_named() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let dir = common::temp_dir("serve-lost");
    // Real time: the run must last until the daemon is killed.
    let (server, addr) = common::spawn_serve(&dir, TOKEN, &[], &[]);
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{addr}/");
    let restart = serde_json::json!([
        env!("CARGO_BIN_EXE_groundcal"),
        "serve",
        "--config",
        dir.join("groundcal.toml"),
        "--listen",
        addr,
    ])
    .to_string();
    let pid = server.id().to_string();
    let seen = common::run_browser_script(
        "serve-lost.mjs",
        &[
            OsStr::new(&url),
            OsStr::new(TOKEN),
            shots.as_os_str(),
            OsStr::new(&pid),
            OsStr::new(&restart),
        ],
    );
    let mut server = server;
    let _ = server.wait();
    if let Some(restarted) = seen["seen"]["restartedPid"].as_u64() {
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &restarted.to_string()])
            .status();
    }
    assert!(
        seen["seen"]["lostAfterMs"].as_u64().unwrap() <= 3000,
        "{seen}"
    );
    let reason = seen["seen"]["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("was cut off") && reason.contains("Nothing moves until"),
        "{seen}"
    );
    let abort = seen["seen"]["abortMessage"].as_str().unwrap_or_default();
    assert!(abort.starts_with("Abort could not be sent"), "{seen}");
    std::thread::sleep(std::time::Duration::from_millis(500));
    let _ = fs::remove_dir_all(&dir);
}

/// The sensor knocked since its calibration: `serve` checks the active
/// calibration at start, finds the drift, says it in the status and the
/// journal, and the page shows a banner that advises a new calibration;
/// Check (with the token) checks again.
#[test]
fn a_knocked_sensor_is_caught_at_start_and_on_check() {
    let dir = common::temp_dir("serve-knocked");
    // The active calibration: a calibration of the simulated robot, accepted.
    let sim = common::root().join("config/sim.toml");
    let (code, out, err) =
        common::groundcal(&["calibrate", "--config", sim.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let result = groundcal::formats::output::ResultJson::parse(serde_json::from_str(&out).unwrap())
        .expect("a result document");
    let store = groundcal::formats::store::Store::new(&dir.join("state.sim"));
    let id = store.add(&result, "2026-12-01T00:00:00Z").unwrap();
    store
        .activate(&id, "2026-12-01T00:00:01Z", "a test")
        .unwrap();

    // Then the sensor is knocked: pitched 0.3° down about the body's
    // sideways axis (β of the fixed angles is the turn about it, α ≈ 0.8°).
    let knocked = common::knocked_mount_line();
    let (server, addr) = common::spawn_serve_with(
        &dir,
        TOKEN,
        &[(common::TRUE_MOUNT_LINE, &knocked)],
        &[],
        &[],
    );

    // The status: the check at start, then its outcome.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let check = loop {
        let (code, status) = common::http(&addr, "GET", "/api/status", None);
        assert_eq!(code, 200);
        let check = status["check"].clone();
        if check["outcome"].is_string() && check["outcome"] != "running" {
            break check;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no check at start: {status:#}"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    assert_eq!(check["outcome"], "drift", "{check:#}");
    assert_eq!(check["by"], "the service's start", "{check:#}");
    let reasons = check["reasons"].to_string();
    assert!(
        reasons.contains("pitched 0.") && reasons.contains("down"),
        "{reasons}"
    );
    assert!(
        check["report"]["checks"].as_array().unwrap().len() >= 3,
        "{check:#}"
    );

    // Check needs the token.
    let (code, _) = common::http(&addr, "POST", "/api/check", None);
    assert_eq!(code, 401);

    if common::browser_ready("serve_browser") {
        let shots = common::root().join("target/test-screenshots");
        fs::create_dir_all(&shots).expect("screenshot directory");
        let url = format!("http://{addr}/");
        let seen = common::run_browser_script(
            "serve-check.mjs",
            &[OsStr::new(&url), OsStr::new(TOKEN), shots.as_os_str()],
        );
        let seen = &seen["seen"];
        let text = |key: &str| seen[key].as_str().unwrap_or_default().to_string();
        assert!(
            text("banner").starts_with("The sensor has moved since it was calibrated: the ground says the sensor is pitched 0.")
                && text("banner").contains("Meanwhile the robot still uses the active calibration")
                && text("banner").contains("Check that the sensor's mount is tight"),
            "{seen}"
        );
        assert!(text("checkline").contains("the sensor has moved"), "{seen}");
        assert!(
            seen["checks"].to_string().contains("ground tilt θ")
                && seen["checks"].to_string().contains("too far"),
            "{seen}"
        );
        assert_eq!(seen["checkEnabled"], true, "{seen}");
        assert!(text("secondCheckline").contains("terminal page"), "{seen}");
        assert!(!text("secondBanner").is_empty(), "{seen}");
        assert!(
            text("confirmCheck").contains("Keep everyone clear"),
            "{seen}"
        );
        // Recalibrated and accepted: the banner of the old calibration goes.
        assert_eq!(seen["bannerBeforeAccept"], true, "{seen}");
        assert!(
            seen["bannerGoneAfterMs"].as_u64().unwrap() <= 2000,
            "{seen}"
        );
        assert!(
            text("checklineAfterAccept").starts_with("Not checked since it became active"),
            "{seen}"
        );
        for step in ["10-drift", "11-checked", "15-recalibrated"] {
            let bytes =
                fs::read(shots.join(format!("serve-{step}.png"))).expect("screenshot saved");
            assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "serve-{step}.png");
        }
    }

    // The journal (stderr under systemd) names the drift and its direction.
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let line = stderr
        .lines()
        .find(|l| l.contains("check of the active calibration") && l.contains("drift"))
        .unwrap_or_else(|| panic!("no journal line of the drift: {stderr}"));
    assert!(
        line.contains("pitched 0.") && line.contains("down"),
        "{line}"
    );
    let _ = fs::remove_dir_all(&dir);
}

/// Sends a signal to a process (by `kill`).
fn signal(pid: u32, name: &str) {
    let _ = std::process::Command::new("kill")
        .args([&format!("-{name}"), &pid.to_string()])
        .status();
}

/// A daemon that may be stopped: continued and killed if the test fails.
struct Stoppable(Option<std::process::Child>);

impl Drop for Stoppable {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            signal(child.id(), "CONT");
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// What `serve-silent.mjs` saw when the daemon fell silent: contact lost
/// within 3 s, Abort kept pending (never "aborting…") with Abort and its
/// note on the 390×844 screen, the page found the daemon again once it
/// spoke, and ended on "aborted" (`aborted`, in the page's language).
fn assert_silence_is_told(seen: &serde_json::Value, no_contact: &str, aborted: &str) {
    let seen = &seen["seen"];
    assert!(seen["lostAfterMs"].as_u64().unwrap() <= 3000, "{seen}");
    assert_eq!(seen["contact"], no_contact, "{seen}");
    assert_eq!(seen["abortEnabled"], true, "{seen}");
    assert!(seen["pendingKept"].is_string(), "{seen}");
    for part in seen["onScreen"].as_array().unwrap() {
        assert_eq!(part["visible"], true, "{part} is off the screen: {seen}");
    }
    assert!(seen["foundAfterMs"].as_u64().is_some(), "{seen}");
    assert!(
        seen["ended"]
            .as_str()
            .unwrap_or_default()
            .starts_with(aborted),
        "{seen}"
    );
}

/// The drift banner and the disabled Abort as the page drew them before the
/// run: legible in sunlight (WCAG AA's 4.5:1 at least), a disabled button
/// unlike a live one.
fn assert_legible(seen: &serde_json::Value) {
    let seen = &seen["seen"];
    let ratio = |key: &str| seen["contrast"][key].as_f64().unwrap_or(0.0);
    assert!(ratio("drift") >= 4.5, "{seen}");
    assert!(ratio("disabledAbort") >= 4.5, "{seen}");
    assert_eq!(seen["contrast"]["disabledLooksLive"], false, "{seen}");
}

/// A hung daemon (SIGSTOP: its sockets stay open, the kernel still accepts
/// connections, nothing answers) with Abort pressed meanwhile, on a phone
/// that also shows the drift banner: the page says within 3 s that contact
/// is lost, and keeps the Abort pending with Abort and its note on screen.
/// When the daemon runs again (SIGCONT) the run does not go on: the lower
/// computer (its own process) gets HALT and HOME within 1 s and no SET_POSE
/// after it, and the page ends on "aborted" with the stall named.
#[test]
fn an_abort_pressed_while_the_daemon_was_stopped_is_carried_out_when_it_resumes() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let dir = common::temp_dir("serve-sigstop");
    let active = common::active_calibration_in_store(&dir.join("state.sim"));
    // The sensor knocked since: the check at start (which moves nothing)
    // finds the drift, and its banner stands while the run goes on.
    let knocked = common::knocked_mount_line();
    let (server, addr, robot, receipts) = common::spawn_serve_towards_sim_robot_at(
        &dir,
        TOKEN,
        "5",
        &[(common::TRUE_MOUNT_LINE, knocked.as_str())],
    );
    common::wait_for_status(&addr, |s| {
        s["verdict"]["outcome"] == "drift" && s["verdict"]["calibration_id"] == active.as_str()
    });
    let pid = server.id();
    let mut server = Stoppable(Some(server));
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{addr}/");
    let cut = format!("sigstop:{pid}");
    let seen = common::run_browser_script(
        "serve-silent.mjs",
        &[
            OsStr::new(&url),
            OsStr::new(TOKEN),
            shots.as_os_str(),
            OsStr::new(&cut),
            OsStr::new("12-sigstop"),
        ],
    );
    eprintln!("SIGSTOP: {}", seen["seen"]);
    signal(pid, "CONT");
    assert_silence_is_told(&seen, "no contact", "aborted");
    assert_legible(&seen);
    let seen = &seen["seen"];
    assert!(
        seen["abortMessage"]
            .as_str()
            .unwrap_or_default()
            .starts_with("Abort could not be sent yet"),
        "{seen}"
    );
    assert!(
        seen["endedStep"]
            .as_str()
            .unwrap_or_default()
            .contains("the service stalled for"),
        "{seen}"
    );
    // What the lower computer got once the daemon ran again.
    let resumed = seen["resumedAtUnixMs"].as_f64().unwrap();
    let after: Vec<(String, f64)> = common::received_at(&receipts)
        .into_iter()
        .filter(|(_, t)| *t >= resumed)
        .collect();
    let first = |kind: &str| {
        after
            .iter()
            .find(|(k, _)| k == kind)
            .map(|(_, t)| t - resumed)
    };
    assert!(
        !after.iter().any(|(k, _)| k == "SET_POSE"),
        "a SET_POSE after SIGCONT: {after:?}"
    );
    let (halt, home) = (first("HALT"), first("HOME"));
    assert!(
        halt.is_some_and(|t| t <= 1000.0) && home.is_some_and(|t| t <= 1000.0),
        "HALT at {halt:?} ms, HOME at {home:?} ms after SIGCONT: {after:?}"
    );
    eprintln!("after SIGCONT: HALT at {halt:?} ms, HOME at {home:?} ms");
    let (code, stderr) = common::terminate(server.0.take().unwrap());
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("the service stalled for"), "{stderr}");
    common::stop_sim_robot(robot);
    let _ = fs::remove_dir_all(&dir);
}

/// A TCP proxy between the page and the daemon that can stop forwarding
/// without closing anything, as a Wi-Fi link that drops: "freeze" and
/// "thaw" lines on its control port.
struct Proxy {
    address: String,
    control: String,
}

fn spawn_proxy(target: String) -> Proxy {
    use std::io::{BufRead, Read, Write};
    use std::net::{TcpListener, TcpStream};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let control = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let control_address = control.local_addr().unwrap().to_string();
    let frozen = Arc::new(AtomicBool::new(false));
    {
        let frozen = frozen.clone();
        std::thread::spawn(move || {
            for stream in control.incoming().flatten() {
                let mut line = String::new();
                let _ = std::io::BufReader::new(stream).read_line(&mut line);
                frozen.store(line.trim() == "freeze", Ordering::SeqCst);
            }
        });
    }
    // Copies one way; while frozen, what arrives is held, not forwarded.
    fn pump(mut from: TcpStream, mut to: TcpStream, frozen: Arc<AtomicBool>) {
        let mut buffer = [0u8; 16 * 1024];
        loop {
            let n = match from.read(&mut buffer) {
                Ok(0) | Err(_) => break,
                Ok(n) => n,
            };
            while frozen.load(Ordering::SeqCst) {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            if to.write_all(&buffer[..n]).is_err() {
                break;
            }
        }
        let _ = to.shutdown(std::net::Shutdown::Write);
    }
    std::thread::spawn(move || {
        for client in listener.incoming().flatten() {
            let Ok(server) = TcpStream::connect(&target) else {
                continue;
            };
            let (c2, s2) = (client.try_clone().unwrap(), server.try_clone().unwrap());
            let (f1, f2) = (frozen.clone(), frozen.clone());
            std::thread::spawn(move || pump(client, server, f1));
            std::thread::spawn(move || pump(s2, c2, f2));
        }
    });
    Proxy {
        address,
        control: control_address,
    }
}

/// A link that drops without closing (the test's proxy stops forwarding):
/// the page says within 3 s that it has no contact, and keeps Abort
/// pending while the daemon itself runs on; when the link returns the
/// pending Abort is sent and the run ends aborted. In Chinese, with the
/// drift banner up: its direction, the check's figures and the hardware
/// line in Chinese words (the daemon's own English marked so).
#[test]
fn a_link_that_drops_without_closing_is_declared_lost() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let dir = common::temp_dir("serve-dropped-link");
    let active = common::active_calibration_in_store(&dir.join("state.sim"));
    let knocked = common::knocked_mount_line();
    // 5× real time: the run lasts well beyond the cut.
    let slow = ("time_scale = 50.0", "time_scale = 5.0");
    let (mut server, addr) = common::spawn_serve_with(
        &dir,
        TOKEN,
        &[slow, (common::TRUE_MOUNT_LINE, knocked.as_str())],
        &[],
        &[],
    );
    common::wait_for_status(&addr, |s| s["verdict"]["outcome"] == "drift");
    // A knock found before a crash is still known after it: killed, and
    // started again without a check at start, the status (and below, the
    // page) still show the drift for that calibration.
    server.kill().unwrap();
    let _ = server.wait();
    let (server, addr) = common::spawn_serve_with(
        &dir,
        TOKEN,
        &[
            slow,
            (common::TRUE_MOUNT_LINE, knocked.as_str()),
            ("at_start = true", "at_start = false"),
        ],
        &[],
        &[],
    );
    let status = common::wait_for_status(&addr, |s| s["state"] == "idle");
    assert_eq!(status["verdict"]["outcome"], "drift", "{status:#}");
    assert_eq!(
        status["verdict"]["calibration_id"],
        active.as_str(),
        "{status:#}"
    );
    assert_eq!(status["check"]["outcome"], "drift", "{status:#}");
    let proxy = spawn_proxy(addr);
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{}/", proxy.address);
    let cut = format!("proxy:{}", proxy.control);
    let seen = common::run_browser_script(
        "serve-silent.mjs",
        &[
            OsStr::new(&url),
            OsStr::new(TOKEN),
            shots.as_os_str(),
            OsStr::new(&cut),
            OsStr::new("13-dropped-link-zh"),
            OsStr::new("zh"),
        ],
    );
    eprintln!("dropped link: {}", seen["seen"]);
    assert_silence_is_told(&seen, "失去联系", "已中止");
    assert_legible(&seen);
    let seen = &seen["seen"];
    let text = |key: &str| seen[key].as_str().unwrap_or_default().to_string();
    // The knock's direction, in Chinese: pitched down.
    assert!(
        text("driftBefore").contains("地面表明传感器比当前标定所说的向下多俯了 0."),
        "{seen}"
    );
    for english in [
        "ground tilt",
        "height e_d",
        "gravity",
        "yaw",
        "forward",
        "sideways",
        "the service's start",
    ] {
        assert!(!text("checksBefore").contains(english), "{english}: {seen}");
        assert!(
            !text("checklineBefore").contains(english),
            "{english}: {seen}"
        );
    }
    assert!(text("hardwareBefore").ends_with("（英文原文）"), "{seen}");
    // The pending Abort went out when the link returned: the operator's.
    assert!(text("endedStep").contains("终端页面"), "{seen}");
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let _ = fs::remove_dir_all(&dir);
}

/// A phone and a pad on one daemon: an accept on one, and a rollback on the
/// other, show on both within 2 s (the store's changes are events, and the
/// status names the active calibration).
#[test]
fn an_accept_or_a_rollback_on_one_device_shows_on_the_other() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let dir = common::temp_dir("serve-two-devices");
    let (first, second) = common::two_calibrations_in_store(&dir.join("state.sim"));
    let (server, addr) = common::spawn_serve(&dir, TOKEN, &[], &[]);
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{addr}/");
    let seen = common::run_browser_script(
        "serve-two.mjs",
        &[
            OsStr::new(&url),
            OsStr::new(TOKEN),
            shots.as_os_str(),
            OsStr::new(&first),
            OsStr::new(&second),
        ],
    );
    eprintln!("two devices: {}", seen["seen"]);
    let seen = &seen["seen"];
    assert!(seen["padAfterMs"].as_u64().unwrap() <= 2000, "{seen}");
    assert!(seen["phoneAfterMs"].as_u64().unwrap() <= 2000, "{seen}");
    assert!(
        seen["phoneActive"].as_str().unwrap().starts_with(&second),
        "{seen}"
    );
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let _ = fs::remove_dir_all(&dir);
}

/// Nothing moves without a person. A clean start with `[verify] at_start`
/// (the robot's shipped setting) and an active calibration checks it
/// without moving: in 10 s the lower computer (its own process) gets no
/// SET_POSE, HOME or HALT. Then a calibration is started and the daemon
/// killed mid-run; started again, killed again, started, stopped cleanly
/// (SIGTERM), started again: each time the status still says the run was
/// interrupted and the check at start is held, and for 10 s after the last
/// start the lower computer gets no motion command. The page shows
/// "Interrupted"; only when a person presses Check and confirms does the
/// lower computer hear from groundcal.
#[test]
fn after_a_crash_nothing_moves_until_a_person_confirms() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let ten_seconds = std::time::Duration::from_secs(10);
    let dir = common::temp_dir("serve-crash-restart");
    let (first, _) = common::two_calibrations_in_store(&dir.join("state.sim"));
    groundcal::formats::store::Store::new(&dir.join("state.sim"))
        .activate(&first, "2026-12-01T02:00:00Z", "a test")
        .unwrap();
    let slow = [("time_scale = 50.0", "time_scale = 5.0")];
    let booted = std::time::Instant::now();
    let (server, addr, robot, receipts) = common::spawn_serve_towards_sim_robot(&dir, TOKEN, &slow);
    // A clean start checks the active calibration at once, moving nothing.
    let status = common::wait_for_status(&addr, |s| {
        s["startup_check"] == "started"
            && s["state"] == "idle"
            && s["check"]["outcome"] != "running"
    });
    assert!(
        status["check"]["outcome"] == "consistent" || status["check"]["outcome"] == "drift",
        "{status:#}"
    );
    // The simulated Kinect cannot see this lower computer's body: the page's
    // hardware line says so, not only the journal.
    assert!(
        status["hardware"]
            .as_str()
            .unwrap_or_default()
            .contains("sees only the in-process simulated body"),
        "{status:#}"
    );
    std::thread::sleep(ten_seconds.saturating_sub(booted.elapsed()));
    let kinds = common::received_kinds(&receipts);
    assert!(
        !kinds.iter().any(|k| common::MOTION.contains(&k.as_str())),
        "the check at start moved the robot: {kinds:?}"
    );
    assert!(kinds.iter().any(|k| k == "GET_STATE"), "{kinds:?}");

    let (code, body) = common::http(&addr, "POST", "/api/calibrations", Some(TOKEN));
    assert_eq!(code, 202, "{body}");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while common::received_kinds(&receipts)
        .iter()
        .filter(|k| *k == "SET_POSE")
        .count()
        < 2
    {
        assert!(std::time::Instant::now() < deadline, "the body never moved");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let mut server = server;
    server.kill().unwrap();
    let _ = server.wait();
    std::thread::sleep(std::time::Duration::from_millis(300));
    let mark = std::fs::read_to_string(&receipts).unwrap().lines().count();

    // Started again, as systemd would after the crash; stopped again with
    // nobody confirming (a kill, then a clean stop), and started again.
    let robot_address = std::fs::read_to_string(dir.join("groundcal.toml"))
        .unwrap()
        .lines()
        .find(|l| l.starts_with("address = "))
        .unwrap()
        .to_string();
    let robot_line = format!("\n{robot_address}\n");
    let start = || {
        common::spawn_serve_with(
            &dir,
            TOKEN,
            &[("\naddress = \"sim\"\n", robot_line.as_str()), slow[0]],
            &[],
            &[],
        )
    };
    let held = |addr: &str| {
        let status = common::wait_for_status(addr, |s| s["startup_check"] != "off");
        assert_eq!(status["startup_check"], "held_for_a_person", "{status:#}");
        assert!(status["interrupted"]["by"].is_string(), "{status:#}");
        assert_eq!(status["interrupted"]["task"], "calibration", "{status:#}");
    };
    let (mut server, addr) = start();
    held(&addr);
    server.kill().unwrap();
    let _ = server.wait();
    let (server, addr) = start();
    held(&addr);
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let last_start = std::time::Instant::now();
    let (server, addr) = start();
    held(&addr);
    std::thread::sleep(ten_seconds.saturating_sub(last_start.elapsed()));
    let since_crash: Vec<String> = std::fs::read_to_string(&receipts)
        .unwrap()
        .lines()
        .skip(mark)
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "datagram")
        .filter_map(|v| v["kind"].as_str().map(String::from))
        .collect();
    assert!(
        !since_crash
            .iter()
            .any(|k| common::MOTION.contains(&k.as_str()) || k == "HELLO"),
        "the lower computer was spoken to with nobody there: {since_crash:?}"
    );
    held(&addr);

    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{addr}/");
    let mark = std::fs::read_to_string(&receipts)
        .unwrap()
        .lines()
        .count()
        .to_string();
    let seen = common::run_browser_script(
        "serve-crash.mjs",
        &[
            OsStr::new(&url),
            OsStr::new(TOKEN),
            shots.as_os_str(),
            receipts.as_os_str(),
            OsStr::new(&mark),
        ],
    );
    eprintln!("after the crash: {}", seen["seen"]);
    let seen = &seen["seen"];
    let reasons = seen["reasons"].to_string();
    assert!(
        reasons.contains("was cut off") && reasons.contains("the check at start was held"),
        "{seen}"
    );
    assert_eq!(
        seen["beforeConfirm"].as_array().map(Vec::len),
        Some(0),
        "{seen}"
    );
    assert!(
        seen["confirm"]
            .as_str()
            .unwrap()
            .contains("Keep everyone clear"),
        "{seen}"
    );
    assert!(seen["heardAfterMs"].as_u64().is_some(), "{seen}");
    // The person's Check ended the notice: the next start checks again.
    let status = common::wait_for_status(&addr, |s| {
        s["state"] == "idle" && s["check"]["outcome"] != "running"
    });
    assert!(status["interrupted"].is_null(), "{status:#}");
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("not checking the active calibration at start"),
        "{stderr}"
    );
    let (server, addr) = start();
    let status = common::wait_for_status(&addr, |s| s["startup_check"] != "off");
    assert_eq!(status["startup_check"], "started", "{status:#}");
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    common::stop_sim_robot(robot);
    let _ = fs::remove_dir_all(&dir);
}

/// What the camera sees, on the page (issue 21): with boxes and a wall in
/// view, the picture is drawn as the daemon serves it, the floor coloured
/// and the boxes not, at phone and pad size; and the page in Simplified
/// Chinese at phone size, through a whole calibration. The Kinect's depth
/// carries waves of ±1.2 raw units, more than the site's gate (15 mm here)
/// lets a correction be relied on: the calibration is rejected, and the result card draws the
/// warp it found, cell by cell, saying it cannot be relied on (screenshot
/// `serve-warp.png`).
#[test]
fn the_page_shows_what_the_camera_sees_and_speaks_chinese() {
    if !common::browser_ready("serve_browser") {
        return;
    }
    let dir = common::temp_dir("serve-view");
    let (server, addr) = common::spawn_serve_with(
        &dir,
        TOKEN,
        &[
            ("world = \"flat\"", "world = \"clutter\""),
            (
                common::SIM_NO_PATTERN_LINE,
                "depth_distortion = { shape = \"waves\", amplitude_raw = 1.2 }",
            ),
            // A gate stricter than the default (45 mm), as a site may set.
            (
                "min_used_fraction = 0.7",
                "min_used_fraction = 0.7\npattern_max_mm = 15.0",
            ),
        ],
        &[],
        &[],
    );
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let url = format!("http://{addr}/");
    let seen = common::run_browser_script(
        "serve-view.mjs",
        &[OsStr::new(&url), OsStr::new(TOKEN), shots.as_os_str()],
    );
    eprintln!("the picture and Chinese: {}", seen["seen"]);
    let seen = &seen["seen"];
    for device in ["phone", "pad"] {
        assert_eq!(seen[device]["wrong"], 0, "{seen}");
        assert!(seen[device]["green"].as_u64().unwrap() >= 500, "{seen}");
        assert!(seen[device]["grey"].as_u64().unwrap() >= 300, "{seen}");
    }
    assert_eq!(seen["zh"]["missing"], serde_json::json!([]), "{seen}");
    assert_eq!(seen["zh"]["calibrate"], "标定", "{seen}");
    assert!(
        seen["zhVerdict"].as_str().unwrap().contains("检查"),
        "{seen}"
    );
    // The Kinect's own warp (waves of ±1.2 raw units, about 17 mm at 2 m, within the ground fit's band),
    // drawn as the calibration found it, in both languages, and the words
    // say the gate `pattern_max_mm` (15 mm) did not trust its correction.
    for (key, words) in [
        ("zhWarp", "超过了校正所检验的 15 毫米，因此标定不能依赖这一校正"),
        ("warp", "more than the 15\u{a0}mm its correction is checked for, so the calibration cannot rely on it"),
    ] {
        let warp = &seen[key];
        assert_eq!(warp["corrected"], true, "{warp}");
        assert_eq!(warp["wrong"], 0, "{warp}");
        // Most cells warped by more than 0.5 mm at 2 m, coloured so.
        assert!(
            warp["farther"].as_u64().unwrap() + warp["nearer"].as_u64().unwrap() > 3000,
            "{warp}"
        );
        assert!(warp["words"].as_str().unwrap().contains(words), "{warp}");
    }
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    let _ = fs::remove_dir_all(&dir);
}
