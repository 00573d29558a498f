//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// The keys of `robot_from_sensor`'s six parameters, in order.
pub const MOUNT_KEYS: [&str; 6] = [
    "alpha_deg",
    "beta_deg",
    "gamma_deg",
    "px_mm",
    "py_mm",
    "pz_mm",
];

/// config/sim.toml's `[sim] mount`: the simulated robot's true mount (at the
/// configured tilt of -20°), what a calibration must find.
pub const SIM_MOUNT: [f64; 6] = [0.8, -33.0, 1.5, 510.0, 370.0, 15.0];

/// `shared/` beside the project (CI clones main with shared/ beside it).
pub fn shared() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared")
}

/// A file of the project's test data.
pub fn test_data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Runs the real `groundcal` binary; returns (exit code, stdout, stderr).
pub fn groundcal(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args(args)
        .output()
        .expect("groundcal runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs the real `groundcal` binary, killed if it has not ended within
/// `limit` (a read that hangs must fail a test, not hang it); returns (exit
/// code, stdout, stderr), the code -1 when it was killed.
pub fn groundcal_within(args: &[&str], limit: std::time::Duration) -> (i32, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("groundcal runs");
    let started = std::time::Instant::now();
    let killed = loop {
        match child.try_wait().expect("groundcal can be waited for") {
            Some(_) => break false,
            None if started.elapsed() > limit => {
                let _ = child.kill();
                break true;
            }
            None => std::thread::sleep(std::time::Duration::from_millis(20)),
        }
    };
    let out = child.wait_with_output().expect("groundcal's output");
    let code = if killed {
        -1
    } else {
        out.status.code().unwrap_or(-1)
    };
    (
        code,
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `groundcal` with its stdout's reader gone before anything is
/// printed (as `groundcal … | head -c0` would); returns how it ended and its
/// stderr, which names a panic if there was one.
pub fn groundcal_with_reader_gone(args: &[&str]) -> (std::process::ExitStatus, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("groundcal runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("groundcal ends");
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `groundcal … --json` and parses stdout.
pub fn groundcal_json(args: &[&str]) -> (i32, serde_json::Value) {
    let (code, stdout, stderr) = groundcal(args);
    let value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!("stdout is not one JSON document ({e}): {stdout}\nstderr: {stderr}")
    });
    (code, value)
}

/// The project's root directory.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh directory of its own under the system's temporary directory,
/// removed with everything in it when the guard drops, so a test run leaves
/// nothing behind: the simulated recordings are tens of MB each, and a CI
/// machine's disk ran out on what earlier tests had left.
pub fn temp_dir(tag: &str) -> TempDir {
    TempDir::new(tag)
}

/// A fresh directory of its own, removed on drop (see [`temp_dir`]).
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("groundcal-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temporary directory");
        Self(dir)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The `robot_from_sensor` of a result JSON (cli.md).
pub fn mount_of(result: &serde_json::Value) -> groundcal::calib::geometry::PoseDegMm {
    let m = &result["robot_from_sensor"];
    let get = |k: &str| {
        m[k].as_f64()
            .unwrap_or_else(|| panic!("robot_from_sensor.{k} in {result}"))
    };
    groundcal::calib::geometry::PoseDegMm {
        alpha_deg: get("alpha_deg"),
        beta_deg: get("beta_deg"),
        gamma_deg: get("gamma_deg"),
        px_mm: get("px_mm"),
        py_mm: get("py_mm"),
        pz_mm: get("pz_mm"),
    }
}

/// Rotation angle (degrees) and translation distance (mm) between two mounts.
pub fn distance(
    a: &groundcal::calib::geometry::PoseDegMm,
    b: &groundcal::calib::geometry::PoseDegMm,
) -> (f64, f64) {
    let (pa, pb) = (a.to_params(), b.to_params());
    let r = pa.rotation_matrix().transpose() * pb.rotation_matrix();
    // atan2(sin θ, cos θ) from the skew part and the trace: exact near zero,
    // where acos of the trace alone loses precision or, just past 1, is NaN.
    let sin = 0.5
        * nalgebra::Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        )
        .norm();
    let cos = 0.5 * (r.trace() - 1.0);
    (
        sin.atan2(cos).to_degrees(),
        (pa.translation - pb.translation).norm() * 1e3,
    )
}

/// A system package or tool a test needs is missing: under `CI=true` that is
/// a failure (CI must install it); elsewhere the test says loudly that it did
/// not run, on the stream itself (the harness swallows what a passing test
/// prints with `eprintln!`), and the caller returns.
pub fn prerequisite_missing(test: &str, message: &str) {
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!("{message}");
    }
    use std::io::Write;
    let bar = "!".repeat(78);
    let _ = writeln!(
        std::io::stderr(),
        "\n{bar}\nWARNING: {test} NOT RUN: {message}\n{bar}\n"
    );
}

/// The Python with the MCAP packages: `target/mcap-python` (scripts/test
/// makes it), or `GROUNDCAL_MCAP_PYTHON`.
pub fn mcap_python(test: &str) -> Option<PathBuf> {
    let python = std::env::var_os("GROUNDCAL_MCAP_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/mcap-python/bin/python"));
    let works = Command::new(&python)
        .args(["-c", "import mcap, mcap_ros2"])
        .output()
        .is_ok_and(|o| o.status.success());
    if works {
        return Some(python);
    }
    prerequisite_missing(
        test,
        &format!(
            "{} cannot import mcap and mcap_ros2; scripts/test installs them: \
             python3 -m venv target/mcap-python && target/mcap-python/bin/pip install -r tests/mcap/requirements.txt",
            python.display()
        ),
    );
    None
}

/// Runs `node tests/browser/SCRIPT ARGS…` (Playwright driving Chromium);
/// asserts it succeeded and returns the JSON line it printed.
pub fn run_browser_script(script: &str, args: &[&OsStr]) -> serde_json::Value {
    let out = Command::new("node")
        .arg(root().join("tests/browser").join(script))
        .args(args)
        .current_dir(root())
        .output()
        .expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{script} failed in Chromium ({}):\n{stderr}\n{stdout}",
        out.status
    );
    serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("{script} printed no JSON ({e}): {stdout}"))
}

/// `groundcal sim-robot --listen 127.0.0.1:0 ARGS…` in its own process, with
/// these environment variables (faults, receipts); returns the process and
/// the address it printed.
pub fn spawn_sim_robot(args: &[&str], env: &[(&str, &OsStr)]) -> (Child, String) {
    let mut full = vec!["sim-robot", "--listen", "127.0.0.1:0"];
    full.extend_from_slice(args);
    spawn_server(&full, env)
}

/// The `groundcal` binary with these arguments and environment variables,
/// once it has printed `listening on ADDR`; returns it and the address.
fn spawn_server(args: &[&str], env: &[(&str, &OsStr)]) -> (Child, String) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_groundcal"));
    command
        .args(args)
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let child = command
        .spawn()
        .unwrap_or_else(|e| panic!("groundcal {} does not start: {e}", args[0]));
    listening(child)
}

/// Reads the `listening on ADDR` line a server prints once it is bound;
/// returns the process and the address, or kills it and says what it said.
fn listening(mut child: Child) -> (Child, String) {
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("stdout is piped"))
        .read_line(&mut line)
        .expect("the server writes its address");
    match line.trim().strip_prefix("listening on ") {
        Some(address) => (child, address.to_string()),
        None => {
            let mut stderr = String::new();
            if let Some(mut e) = child.stderr.take() {
                let _ = e.read_to_string(&mut stderr);
            }
            let _ = child.kill();
            panic!("the server said {line:?} on stdout, stderr: {stderr}");
        }
    }
}

/// Stops a `sim-robot` process with SIGTERM; asserts it exits 0 with its
/// stats line and returns its stderr.
pub fn stop_sim_robot(child: Child) -> String {
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let output = child.wait_with_output().expect("sim-robot exits");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(
        output.status.success(),
        "sim-robot exited with {}: {stderr}",
        output.status
    );
    assert!(stderr.contains("sim-robot: stats {"), "{stderr}");
    stderr
}

/// The robot's configuration (`config/groundcal.toml`) on the paper's
/// schedule, written into `dir`: what the shipped designed schedules were
/// designed against (`plan --design` compares with the configured one).
pub fn robot_config_on_the_papers_schedule(dir: &Path) -> PathBuf {
    let shipped = "schedule = \"schedules/designed-52.toml\"";
    let text = std::fs::read_to_string(root().join("config/groundcal.toml"))
        .expect("config/groundcal.toml");
    assert!(
        text.contains(shipped),
        "config/groundcal.toml lacks {shipped}"
    );
    let paper = root().join("config/schedules/octopus-52.toml");
    let path = dir.join("groundcal-octopus-52.toml");
    std::fs::create_dir_all(dir).expect("configuration directory");
    std::fs::write(
        &path,
        text.replace(shipped, &format!("schedule = \"{}\"", paper.display())),
    )
    .expect("configuration written");
    path
}

/// config/sim.toml with its schedule path made absolute and these
/// replacements (each must occur), written into `dir` as `groundcal.toml`.
pub fn sim_config(dir: &Path, replacements: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(root().join("config/sim.toml"))
        .expect("config/sim.toml")
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            &format!(
                "schedule = \"{}\"",
                root().join("config/schedules/octopus-52.toml").display()
            ),
        );
    for (from, to) in replacements {
        assert!(text.contains(from), "config/sim.toml has no {from}");
        text = text.replace(from, to);
    }
    let path = dir.join("groundcal.toml");
    std::fs::write(&path, text).expect("config written");
    path
}

/// [`sim_config`] as a real robot's configuration: without the noise
/// table nobody has measured on a real robot (`[calibration.noise]`).
pub fn sim_config_unmeasured(dir: &Path, replacements: &[(&str, &str)]) -> PathBuf {
    let path = sim_config(dir, replacements);
    let text = std::fs::read_to_string(&path).expect("the configuration written");
    let (before, rest) = text
        .split_once("[calibration.noise]")
        .expect("config/sim.toml has a noise table");
    let after = &rest[rest
        .find("[calibration.gates]")
        .expect("and gates after it")..];
    std::fs::write(&path, format!("{before}{after}")).expect("configuration written");
    path
}

/// A configuration written by [`sim_config`] moved onto another of
/// `config/schedules/` (its name without `.toml`), such as the robot's
/// `designed-52`.
pub fn on_schedule(config: &Path, schedule: &str) {
    let text = std::fs::read_to_string(config).expect("the configuration written");
    let paper = format!(
        "schedule = \"{}\"",
        root().join("config/schedules/octopus-52.toml").display()
    );
    assert!(text.contains(&paper), "{text}");
    let other = root().join(format!("config/schedules/{schedule}.toml"));
    std::fs::write(
        config,
        text.replace(&paper, &format!("schedule = \"{}\"", other.display())),
    )
    .expect("configuration written");
}

/// The line of config/sim.toml that names the simulated Kinect's depth model.
pub const SIM_DEPTH_MODEL_LINE: &str =
    "depth_model = { kind = \"inverse-linear\", a = 3.3309495161, b = -0.0030711016 }";

/// config/sim.toml's `[sim]` line that gives its Kinect no fixed pattern.
pub const SIM_NO_PATTERN_LINE: &str = "depth_distortion = { shape = \"none\" }";

/// config/sim.toml, unmeasured ([`sim_config_unmeasured`]), with the
/// simulated Kinect's depth carrying `pattern` (a `depth_distortion = {…}`
/// line, or "") and, with `zero_plane`, libfreenect's zero-plane model.
pub fn sim_config_with_pattern(dir: &Path, pattern: &str, zero_plane: bool) -> PathBuf {
    std::fs::create_dir_all(dir).expect("configuration directory");
    // "" keeps config/sim.toml's "none" (a missing line is the default,
    // the measured pattern).
    let mut replacements = if pattern.is_empty() {
        vec![]
    } else {
        vec![(SIM_NO_PATTERN_LINE, pattern)]
    };
    if zero_plane {
        replacements.push((SIM_DEPTH_MODEL_LINE, ""));
    }
    sim_config_unmeasured(dir, &replacements)
}

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
const BROWSER_SETUP: &str = "apt-get install -y chromium && npm ci --prefix tests/browser";

/// What is missing to run the browser tests, in words that say what to install.
fn missing_browser_prerequisites() -> Vec<String> {
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
fn without_table(text: &str, header: &str) -> String {
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

/// The shipped 52-pose schedule (config/schedules/octopus-52.toml).
pub fn octopus_52() -> groundcal::setup::schedule::Schedule {
    groundcal::setup::schedule::Schedule::read(&root().join("config/schedules/octopus-52.toml"))
        .expect("the shipped schedule")
}

/// The simulated Kinect's renderer for a depth model and a seed, and the
/// camera that reads its raw frames.
pub fn sim_renderer(
    model: groundcal::calib::sensor::DepthModel,
    seed: u64,
) -> (
    groundcal_hal::sim::kinect::DepthRenderer,
    groundcal::calib::sensor::DepthCamera,
) {
    use groundcal::calib::sensor::{DepthCamera, DepthEncoding, DepthRange};
    let config = groundcal_hal::sim::kinect::SimKinectConfig {
        depth_model: model,
        seed,
        ..groundcal_hal::sim::kinect::SimKinectConfig::independent_noise()
    };
    let renderer =
        groundcal_hal::sim::kinect::DepthRenderer::new(&config).expect("a valid simulated Kinect");
    let camera = DepthCamera::new(
        DepthEncoding::Raw11(model),
        config.intrinsics,
        DepthRange::default(),
    );
    (renderer, camera)
}
