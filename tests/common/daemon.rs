//! The daemon and the robot around a test: `serve` and `sim-robot` in their
//! own processes, HTTP to them, the browser's prerequisites, a live
//! calibration and what the lower computer received, the store's contents.

use super::*;

/// `groundcal serve` as systemd would run it: the binary, on the simulation
/// configuration copied into `dir` (token `token`, state in `dir/state`),
/// listening on 127.0.0.1:0, with these further arguments and environment
/// variables. Returns the process and the address it printed once listening.
pub fn spawn_serve(
    dir: &Path,
    token: &str,
    args: &[&str],
    env: &[(&str, &OsStr)],
) -> (Child, String) {
    spawn_serve_with(dir, token, &[], args, env)
}

/// [`spawn_serve`] on the simulation configuration with these replacements.
pub fn spawn_serve_with(
    dir: &Path,
    token: &str,
    replacements: &[(&str, &str)],
    args: &[&str],
    env: &[(&str, &OsStr)],
) -> (Child, String) {
    let config = sim_config(dir, replacements);
    std::fs::write(dir.join("token.sim"), format!("{token}\n")).expect("token written");
    let config = config.to_str().expect("a UTF-8 temporary path");
    let mut full = vec!["serve", "--config", config, "--listen", "127.0.0.1:0"];
    full.extend_from_slice(args);
    spawn_server(&full, env)
}

/// Sends SIGTERM to a child process and waits for it; returns (exit code,
/// stderr).
pub fn terminate(child: Child) -> (i32, String) {
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let output = child.wait_with_output().expect("the process exits");
    (
        output.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// One HTTP/1.1 request on its own connection, by hand (the server must
/// speak plain HTTP, not only to one client library); returns the status
/// code and the body as JSON (a string when it is not JSON).
pub fn http(
    address: &str,
    method: &str,
    path: &str,
    token: Option<&str>,
) -> (u16, serde_json::Value) {
    use std::io::Write;
    let mut stream = std::net::TcpStream::connect(address).expect("the server accepts");
    let auth = token
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default();
    let text = format!(
        "{method} {path} HTTP/1.1\r\nHost: {address}\r\nX-Groundcal-Client: test\r\n{auth}Content-Length: 0\r\nConnection: close\r\n\r\n"
    );
    stream.write_all(text.as_bytes()).expect("request sent");
    let mut response = Vec::new();
    stream.read_to_end(&mut response).expect("response read");
    let response = String::from_utf8_lossy(&response).into_owned();
    let code: u16 = response
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("bad response: {response}"));
    let body = response
        .split_once("\r\n\r\n")
        .map(|(_, b)| b)
        .unwrap_or("");
    let json =
        serde_json::from_str(body).unwrap_or_else(|_| serde_json::Value::String(body.to_string()));
    (code, json)
}

/// Debian's Chromium, which Playwright drives.
pub const CHROMIUM: &str = "/usr/bin/chromium";
/// What the project's test script runs before the browser tests.
pub(super) const BROWSER_SETUP: &str =
    "apt-get install -y chromium && npm ci --prefix tests/browser";

/// What is missing to run the browser tests, in words that say what to install.
pub(super) fn missing_browser_prerequisites() -> Vec<String> {
    let mut missing = Vec::new();
    match Command::new("node").arg("--version").output() {
        Ok(out) if out.status.success() => {
            let version = String::from_utf8_lossy(&out.stdout).trim().to_string();
            let major: u32 = version
                .trim_start_matches('v')
                .split('.')
                .next()
                .and_then(|m| m.parse().ok())
                .unwrap_or(0);
            if major < 20 {
                missing.push(format!(
                    "Node.js ≥ 20 (found {version}; playwright-core needs 20)"
                ));
            }
        }
        _ => missing.push("Node.js ≥ 20 (`node` is not on PATH)".to_string()),
    }
    if !root()
        .join("tests/browser/node_modules/playwright-core/package.json")
        .is_file()
    {
        missing.push("playwright-core (run `npm ci --prefix tests/browser`)".to_string());
    }
    if !Path::new(CHROMIUM).is_file() {
        missing.push(format!(
            "Chromium at {CHROMIUM} (`apt-get install -y chromium`)"
        ));
    }
    missing
}

/// Whether the browser tests can run. Under `CI=true` a missing prerequisite
/// fails the test; elsewhere `test` warns loudly and should return.
pub fn browser_ready(test: &str) -> bool {
    let missing = missing_browser_prerequisites();
    if missing.is_empty() {
        return true;
    }
    let message = format!(
        "the browser test cannot run; missing: {}. The setup the test script runs: {BROWSER_SETUP}",
        missing.join("; ")
    );
    prerequisite_missing(test, &message);
    false
}

/// The simulation configuration pointed at the lower computer at `address`,
/// with `robot_keys` (TOML lines of `[robot]`, e.g. `retries = 30`) and a
/// short settle delay (a recorded robot holds still at once), written into
/// `dir`; its schedule path is absolute. Without the simulator's
/// `[calibration.noise]`: a recording played back live is not the
/// simulator's, and its replay assumes the recording's noise (none stored:
/// the solve's default floors), so the live run must too.
pub fn config_towards(address: &str, dir: &Path, robot_keys: &str) -> PathBuf {
    let text = std::fs::read_to_string(root().join("config/sim.toml"))
        .expect("config/sim.toml")
        .replace(
            "\naddress = \"sim\"\n",
            &format!("\naddress = \"{address}\"\n{robot_keys}\n"),
        )
        .replace("settle_ms = 300", "settle_ms = 30")
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            &format!(
                "schedule = \"{}\"",
                root().join("config/schedules/octopus-52.toml").display()
            ),
        );
    let path = dir.join("groundcal.toml");
    std::fs::write(&path, without_table(&text, "[calibration.noise]"))
        .expect("configuration written");
    path
}

/// A TOML text without one table: its header and its keys, up to the next
/// blank line.
pub(super) fn without_table(text: &str, header: &str) -> String {
    let mut inside = false;
    let mut kept = String::new();
    for line in text.lines() {
        if line.trim() == header {
            inside = true;
        } else if inside && line.trim().is_empty() {
            inside = false;
        }
        if !inside {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    assert!(
        kept.len() < text.len(),
        "{header} is not in the configuration"
    );
    kept
}

/// What a live calibration against a recorded robot gave.
pub struct LiveRun {
    pub code: i32,
    pub stdout: String,
    /// What `calibrate` said.
    pub stderr: String,
    /// What `sim-robot` said (its stats line last).
    pub robot_stderr: String,
    /// The datagrams the lower computer handled (JSON lines).
    pub receipts: PathBuf,
}

/// `groundcal calibrate --json` of `recording`, live: its frames played back
/// as the sensor, against `groundcal sim-robot --replay` in its own process
/// (time-scaled 50×) through the network `faults`, with `robot_keys` in the
/// configuration's `[robot]`. The configuration and receipts go into `work`.
pub fn calibrate_live(recording: &Path, work: &Path, faults: &str, robot_keys: &str) -> LiveRun {
    let receipts = work.join("receipts.jsonl");
    let (robot, address) = spawn_sim_robot(
        &[
            "--time-scale",
            "50",
            "--replay",
            recording.to_str().expect("a UTF-8 path"),
        ],
        &[
            ("GROUNDCAL_SIM_FAULTS", OsStr::new(faults)),
            ("GROUNDCAL_SIM_RECEIPTS", receipts.as_os_str()),
        ],
    );
    let config = config_towards(&address, work, robot_keys);
    let sensor = format!("replay:{}", recording.display());
    let (code, stdout, stderr) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().expect("a UTF-8 path"),
        "--sensor",
        &sensor,
        "--json",
    ]);
    let robot_stderr = stop_sim_robot(robot);
    LiveRun {
        code,
        stdout,
        stderr,
        robot_stderr,
        receipts,
    }
}

/// `groundcal serve` on the simulation configuration, its robot a
/// `groundcal sim-robot` in its own process (time-scaled 50×) that logs every
/// datagram it handles to `dir/receipts.jsonl`, line by line. Returns the
/// daemon, its address, the lower computer and the receipts' path.
pub fn spawn_serve_towards_sim_robot(
    dir: &Path,
    token: &str,
    replacements: &[(&str, &str)],
) -> (Child, String, Child, PathBuf) {
    spawn_serve_towards_sim_robot_at(dir, token, "50", replacements)
}

/// [`spawn_serve_towards_sim_robot`] with the lower computer at
/// `robot_time_scale` times real time.
pub fn spawn_serve_towards_sim_robot_at(
    dir: &Path,
    token: &str,
    robot_time_scale: &str,
    replacements: &[(&str, &str)],
) -> (Child, String, Child, PathBuf) {
    let receipts = dir.join("receipts.jsonl");
    let (robot, robot_address) = spawn_sim_robot(
        &["--time-scale", robot_time_scale],
        &[("GROUNDCAL_SIM_RECEIPTS", receipts.as_os_str())],
    );
    let address_line = format!("\naddress = \"{robot_address}\"\n");
    let mut all = vec![("\naddress = \"sim\"\n", address_line.as_str())];
    all.extend_from_slice(replacements);
    let (serve, address) = spawn_serve_with(dir, token, &all, &[], &[]);
    (serve, address, robot, receipts)
}

/// The datagrams the lower computer handled (its receipts log), in order:
/// (kind, wall-clock milliseconds since the Unix epoch).
pub fn received_at(receipts: &Path) -> Vec<(String, f64)> {
    std::fs::read_to_string(receipts)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "datagram")
        .filter_map(|v| Some((v["kind"].as_str()?.to_string(), v["unix_ms"].as_f64()?)))
        .collect()
}

/// The motion commands among datagrams: SET_POSE, HOME and HALT.
pub const MOTION: [&str; 3] = ["SET_POSE", "HOME", "HALT"];

/// An active calibration of the simulated robot in the store in
/// `state_dir` (`calibrate --config config/sim.toml`, accepted); its id.
pub fn active_calibration_in_store(state_dir: &Path) -> String {
    let sim = root().join("config/sim.toml");
    let (code, out, err) = groundcal(&["calibrate", "--config", sim.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let result = groundcal::formats::output::ResultJson::parse(serde_json::from_str(&out).unwrap())
        .expect("a result document");
    let store = groundcal::formats::store::Store::new(state_dir);
    let id = store.add(&result, "2026-12-01T00:00:00Z").unwrap();
    store
        .activate(&id, "2026-12-01T00:00:01Z", "a test")
        .unwrap();
    id
}

/// config/sim.toml's `[sim] mount`, the simulated robot's true mount.
pub const TRUE_MOUNT_LINE: &str = "mount = { alpha_deg = 0.8, beta_deg = -33.0, gamma_deg = 1.5, px_mm = 510.0, py_mm = 370.0, pz_mm = 15.0 }";

/// [`TRUE_MOUNT_LINE`] knocked: pitched 0.3° down about the body's sideways
/// axis (β of the fixed angles is the turn about it, α ≈ 0.8°).
pub fn knocked_mount_line() -> String {
    TRUE_MOUNT_LINE.replace("beta_deg = -33.0", "beta_deg = -33.3")
}

/// Waits (at most 60 s) until the daemon at `addr`'s status satisfies `done`.
pub fn wait_for_status(addr: &str, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let (code, status) = http(addr, "GET", "/api/status", None);
        if code == 200 && done(&status) {
            return status;
        }
        assert!(std::time::Instant::now() < deadline, "{status:#}");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// The kinds of the datagrams the lower computer handled (its receipts
/// log), in order.
pub fn received_kinds(receipts: &Path) -> Vec<String> {
    std::fs::read_to_string(receipts)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "datagram")
        .filter_map(|v| v["kind"].as_str().map(String::from))
        .collect()
}

/// Two accepted calibrations of the simulated robot (`calibrate --config
/// config/sim.toml`) added to the store in `state_dir`, none active;
/// returns their ids, oldest first.
pub fn two_calibrations_in_store(state_dir: &Path) -> (String, String) {
    let sim = root().join("config/sim.toml");
    let store = groundcal::formats::store::Store::new(state_dir);
    let mut ids = Vec::new();
    for created in ["2026-12-01T00:00:00Z", "2026-12-01T01:00:00Z"] {
        let (code, out, err) =
            groundcal(&["calibrate", "--config", sim.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "{err}");
        let result =
            groundcal::formats::output::ResultJson::parse(serde_json::from_str(&out).unwrap())
                .expect("a result document");
        ids.push(store.add(&result, created).unwrap());
    }
    (ids[0].clone(), ids[1].clone())
}
