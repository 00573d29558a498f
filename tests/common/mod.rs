//! Helpers shared by the integration tests: running groundcal and finding
//! its files here; configurations for a test in [`configs`], the daemon and
//! the simulated robot in their own processes in [`daemon`].
#![allow(dead_code)]

use std::ffi::OsStr;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

mod configs;
mod daemon;
// Each test binary uses some of these: the rest is not an error.
#[allow(unused_imports)]
pub use configs::*;
#[allow(unused_imports)]
pub use daemon::*;

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
/// machine's disk ran out on what earlier tests had left. Each call gets a
/// directory of its own even with the same tag: two tests of one process
/// calling one helper shared a directory, and the first to finish removed
/// it under the other (CI of f9edc7c1, `mcap_session`).
pub fn temp_dir(tag: &str) -> TempDir {
    TempDir::new(tag)
}

/// A fresh directory of its own, removed on drop (see [`temp_dir`]).
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        static MADE: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let made = MADE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir =
            std::env::temp_dir().join(format!("groundcal-{tag}-{}-{made}", std::process::id()));
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

/// A result's reasons, in order.
pub fn reasons_of(result: &serde_json::Value) -> Vec<&str> {
    result["reasons"]
        .as_array()
        .map(|reasons| {
            reasons
                .iter()
                .filter_map(serde_json::Value::as_str)
                .collect()
        })
        .unwrap_or_default()
}

/// A result's check of one gate (`gate_checks[]` by its key), or null when
/// the result has none.
pub fn gate_check<'a>(result: &'a serde_json::Value, gate: &str) -> &'a serde_json::Value {
    static NONE: serde_json::Value = serde_json::Value::Null;
    result["gate_checks"]
        .as_array()
        .and_then(|checks| checks.iter().find(|c| c["gate"] == gate))
        .unwrap_or(&NONE)
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
