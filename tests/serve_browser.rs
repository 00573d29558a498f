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
const SHOTS: [&str; 8] = [
    "1-idle",
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
        serde_json::json!(["run", "active-card", "history-card"]),
        "{seen}"
    );
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
    assert_eq!(text("verdict"), "Passed checks", "{seen}");
    assert!(seen["points"].as_u64().unwrap() > 6, "{seen}");
    // Header, the six parameters and the depth scale.
    assert_eq!(seen["values"].as_array().unwrap().len(), 8, "{seen}");
    assert!(
        seen["values"][7].as_str().unwrap().starts_with("s"),
        "{seen}"
    );
    // Each σ with the one predicted before the robot moved.
    assert_eq!(seen["predicted"], 7, "{seen}");
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
        text("rollbackQuestion").starts_with("Roll back to calibration"),
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
    // Aborted: "aborting…", then "at home", in words said once.
    assert_eq!(text("aborting"), "aborting…", "{seen}");
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
/// contact (and disables its buttons); once the daemon is back, the page
/// finds it again and shows the run as interrupted.
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
    assert!(reason.contains("was interrupted"), "{seen}");
    std::thread::sleep(std::time::Duration::from_millis(500));
    let _ = fs::remove_dir_all(&dir);
}

/// config/sim.toml's `[sim] mount`, the simulated robot's true mount.
const TRUE_MOUNT: &str = "mount = { alpha_deg = 0.8, beta_deg = -33.0, gamma_deg = 1.5, px_mm = 510.0, py_mm = 370.0, pz_mm = 15.0 }";

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
    let result: serde_json::Value = serde_json::from_str(&out).unwrap();
    let store = groundcal::store::Store::new(&dir.join("state.sim"));
    let id = store.add(&result, "2026-12-01T00:00:00Z").unwrap();
    store.activate(&id, "2026-12-01T00:00:01Z").unwrap();

    // Then the sensor is knocked: pitched 0.3° down about the body's
    // sideways axis (β of the fixed angles is the turn about it, α ≈ 0.8°).
    let knocked = TRUE_MOUNT.replace("beta_deg = -33.0", "beta_deg = -33.3");
    let (server, addr) = common::spawn_serve_with(&dir, TOKEN, &[(TRUE_MOUNT, &knocked)], &[], &[]);

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
                && text("banner").contains("Calibrate again"),
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
        for step in ["10-drift", "11-checked"] {
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
