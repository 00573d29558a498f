//! `groundcal serve`'s HTTP API, in process: the real server on 127.0.0.1:0
//! with the built-in simulated robot and Kinect, spoken to with hand-written
//! HTTP/1.1 requests.

mod common;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use groundcal::hardware::Selection;
use groundcal::setup::config::Config;
use groundcal::terminal::{serve, AppState};
use serde_json::Value;

const TOKEN: &str = "s3cret-token";

fn temp_dir(tag: &str) -> common::TempDir {
    common::temp_dir(&format!("serve-http-{tag}"))
}

/// One request on its own connection (`common::http`, off the runtime).
async fn request(addr: SocketAddr, method: &str, path: &str, token: Option<&str>) -> (u16, Value) {
    let (method, path, token) = (
        method.to_string(),
        path.to_string(),
        token.map(str::to_string),
    );
    tokio::task::spawn_blocking(move || {
        common::http(&addr.to_string(), &method, &path, token.as_deref())
    })
    .await
    .expect("the request ran")
}

async fn wait_idle(addr: SocketAddr) -> Value {
    let start = Instant::now();
    loop {
        let (code, status) = request(addr, "GET", "/api/status", None).await;
        assert_eq!(code, 200);
        if status["state"] == "idle"
            && (status["result_id"].is_string() || status["error"].is_string())
        {
            return status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(180),
            "the calibration did not finish: {status}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn calibrate_accept_and_activate_over_http() {
    let dir = temp_dir("cycle");
    let state_dir = dir.join("state");
    let (config, schedule) = Config::embedded_sim();
    assert!(
        config.serve.is_some(),
        "the built-in config has a [serve] table"
    );
    let state = AppState::new(
        config,
        schedule,
        Selection::default(),
        format!("{TOKEN}\n"),
        &state_dir,
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(serve(listener, state, async move {
        let _ = stopped.await;
    }));

    // The page and the idle status.
    let (code, page) = request(addr, "GET", "/", None).await;
    assert_eq!(code, 200);
    assert!(page.as_str().unwrap().contains("Calibrate"));
    let (code, status) = request(addr, "GET", "/api/status", None).await;
    assert_eq!((code, status["state"].as_str()), (200, Some("idle")));

    // Nothing moves without the token.
    let (code, body) = request(addr, "POST", "/api/calibrations", None).await;
    assert_eq!(code, 401, "{body}");
    assert!(body["error"].as_str().unwrap().contains("token"));
    assert_eq!(
        request(addr, "POST", "/api/calibrations", Some("wrong"))
            .await
            .0,
        401
    );
    assert_eq!(
        request(addr, "POST", "/api/calibrations/current/abort", None)
            .await
            .0,
        401
    );
    assert_eq!(
        request(addr, "POST", "/api/calibrations/current/abort", Some(TOKEN))
            .await
            .0,
        409
    );
    assert_eq!(request(addr, "GET", "/api/active", None).await.0, 404);
    assert_eq!(
        request(addr, "GET", "/api/calibrations/no-such-id", None)
            .await
            .0,
        404
    );
    assert_eq!(
        request(addr, "GET", "/api/calibrations/..%2Factive", None)
            .await
            .0,
        404
    );
    assert_eq!(request(addr, "GET", "/api/nothing", None).await.0, 404);

    // Subscribe to the events before starting.
    let mut events = TcpStream::connect(addr).await.unwrap();
    events
        .write_all(
            format!(
                "GET /api/events HTTP/1.1\r\nHost: {addr}\r\nAccept: text/event-stream\r\n\r\n"
            )
            .as_bytes(),
        )
        .await
        .unwrap();
    let mut seen = String::new();
    let mut buf = [0u8; 4096];
    while !seen.contains("\r\n\r\n") {
        let n = tokio::time::timeout(Duration::from_secs(10), events.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert!(n > 0);
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(seen.starts_with("HTTP/1.1 200"), "{seen}");
    assert!(seen.contains("text/event-stream"), "{seen}");

    // Start; a second start is refused with who is running.
    let (code, body) = request(addr, "POST", "/api/calibrations", Some(TOKEN)).await;
    assert_eq!(code, 202, "{body}");
    let (code, body) = request(addr, "POST", "/api/calibrations", Some(TOKEN)).await;
    assert_eq!(code, 409, "{body}");
    let error = body["error"].as_str().unwrap();
    assert!(
        error.contains("already running") && error.contains("test"),
        "{error}"
    );

    // The event stream reports progress, pose by pose, then the stored result.
    let start = Instant::now();
    while !(seen.contains("\"type\":\"pose_done\"") && seen.contains("\"type\":\"stored\"")) {
        assert!(
            start.elapsed() < Duration::from_secs(180),
            "events so far: {seen}"
        );
        let n = tokio::time::timeout(Duration::from_secs(60), events.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert!(n > 0, "the event stream ended early: {seen}");
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(seen.contains("\"type\":\"started\""), "{seen}");
    assert!(seen.contains("\"type\":\"moving\""), "{seen}");

    let status = wait_idle(addr).await;
    assert!(status["error"].is_null(), "{status}");
    let id = status["result_id"].as_str().unwrap().to_string();
    let result = &status["result"];
    assert_eq!(result["status"], "accepted", "{result}");
    assert!(status["recent_events"].as_array().unwrap().len() > 3);

    // The history has it; accepting needs the token and makes it active.
    let (code, history) = request(addr, "GET", "/api/calibrations", None).await;
    assert_eq!(code, 200);
    assert_eq!(history["calibrations"][0]["id"], id.as_str());
    let (code, stored) = request(addr, "GET", &format!("/api/calibrations/{id}"), None).await;
    assert_eq!(code, 200);
    assert_eq!(stored["robot_from_sensor"], result["robot_from_sensor"]);
    assert_eq!(
        request(
            addr,
            "POST",
            &format!("/api/calibrations/{id}/accept"),
            None
        )
        .await
        .0,
        401
    );
    let (code, active) = request(
        addr,
        "POST",
        &format!("/api/calibrations/{id}/accept"),
        Some(TOKEN),
    )
    .await;
    assert_eq!(code, 200, "{active}");
    let on_disk: Value =
        serde_json::from_str(&std::fs::read_to_string(state_dir.join("active.json")).unwrap())
            .unwrap();
    assert_eq!(on_disk["id"], id.as_str());
    assert_eq!(on_disk["robot_from_sensor"], result["robot_from_sensor"]);
    let (code, active) = request(addr, "GET", "/api/active", None).await;
    assert_eq!((code, &active["id"]), (200, &Value::String(id.clone())));
    // The active one cannot be rejected; rollback to it works; an unknown id is 404.
    assert_eq!(
        request(
            addr,
            "POST",
            &format!("/api/calibrations/{id}/reject"),
            Some(TOKEN)
        )
        .await
        .0,
        409
    );
    assert_eq!(
        request(addr, "POST", &format!("/api/rollback/{id}"), Some(TOKEN))
            .await
            .0,
        200
    );
    assert_eq!(
        request(addr, "POST", "/api/rollback/nope", Some(TOKEN))
            .await
            .0,
        404
    );

    // A second calibration, aborted by the operator: the robot is sent home
    // and no result is kept. The status's count of changes goes on through
    // the start of a run (the page orders its answers by it; when a start
    // counted anew, the page dropped the new run's status as older).
    let (_, before) = request(addr, "GET", "/api/status", None).await;
    assert_eq!(
        request(addr, "POST", "/api/calibrations", Some(TOKEN))
            .await
            .0,
        202
    );
    let (_, after) = request(addr, "GET", "/api/status", None).await;
    assert_eq!(after["instance"], before["instance"], "{after}");
    assert!(
        after["revision"].as_u64() > before["revision"].as_u64(),
        "{before}\n{after}"
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (code, body) = request(addr, "POST", "/api/calibrations/current/abort", Some(TOKEN)).await;
    assert_eq!(code, 202, "{body}");
    let status = wait_idle(addr).await;
    let error = status["error"].as_str().unwrap_or_default();
    assert!(error.contains("aborted"), "{status}");
    assert!(
        status["robot"].as_str().unwrap().contains("home"),
        "{status}"
    );

    // Reject marks a history entry without deleting it, and it can no longer be made active.
    let extra = groundcal::formats::output::ResultJson::parse(serde_json::json!({
        "status": "accepted",
        "robot_from_sensor": groundcal::formats::output::MountJson::from_params(
            &groundcal::calib::geometry::PoseDegMm::from_values([9.0, -33.0, 0.0, 500.0, 370.0, 0.0])
                .to_params(),
        ),
        "poses": [],
    }))
    .unwrap();
    let other = groundcal::formats::store::Store::new(&state_dir)
        .add(&extra, "2000-01-01T00:00:00Z")
        .unwrap();
    let (code, body) = request(
        addr,
        "POST",
        &format!("/api/calibrations/{other}/reject"),
        Some(TOKEN),
    )
    .await;
    assert_eq!(code, 200, "{body}");
    assert_eq!(body["status"], "rejected");
    assert_eq!(
        request(
            addr,
            "POST",
            &format!("/api/calibrations/{other}/accept"),
            Some(TOKEN)
        )
        .await
        .0,
        409
    );
    let (_, history) = request(addr, "GET", "/api/calibrations", None).await;
    assert_eq!(history["calibrations"].as_array().unwrap().len(), 2);

    // Graceful shutdown ends the event stream too.
    let _ = stop.send(());
    tokio::time::timeout(Duration::from_secs(30), server)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The response's head (status line and headers), lower-cased, of a GET.
fn head_of(addr: SocketAddr, path: &str) -> String {
    raw_head(addr, "GET", path, &format!("Host: {addr}\r\n"))
}

/// The head of the response to one hand-written request with these header
/// lines, lower-cased.
fn raw_head(addr: SocketAddr, method: &str, path: &str, headers: &str) -> String {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    let request = format!(
        "{method} {path} HTTP/1.1\r\n{headers}Content-Length: 0\r\nConnection: close\r\n\r\n"
    );
    stream.write_all(request.as_bytes()).unwrap();
    let mut response = Vec::new();
    stream.read_to_end(&mut response).unwrap();
    let response = String::from_utf8_lossy(&response).to_lowercase();
    response
        .split_once("\r\n\r\n")
        .map(|(head, _)| head.to_string())
        .unwrap_or(response)
}

/// The daemon on the built-in simulation, in process on 127.0.0.1:0 with its
/// store in `dir`; stops when the sender is used or dropped.
async fn serve_simulation(
    dir: &std::path::Path,
) -> (
    SocketAddr,
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<std::io::Result<()>>,
) {
    serve_simulation_at(dir, None).await
}

/// [`serve_simulation`] with the simulator this many times faster than
/// real time (None: the built-in configuration's own).
async fn serve_simulation_at(
    dir: &std::path::Path,
    time_scale: Option<f64>,
) -> (
    SocketAddr,
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<std::io::Result<()>>,
) {
    let (mut config, schedule) = Config::embedded_sim();
    if let (Some(sim), Some(scale)) = (&mut config.sim, time_scale) {
        sim.time_scale = scale;
    }
    let state = AppState::new(
        config,
        schedule,
        Selection::default(),
        TOKEN.into(),
        &dir.join("state"),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(serve(listener, state, async move {
        let _ = stopped.await;
    }));
    (addr, stop, server)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_other_site_can_frame_the_page() {
    let dir = temp_dir("headers");
    let (addr, stop, server) = serve_simulation(&dir).await;
    for path in ["/", "/page.js", "/api/status", "/no/such/endpoint"] {
        let head = tokio::task::spawn_blocking(move || head_of(addr, path))
            .await
            .unwrap();
        // The page's code is its own files: nothing inline may run.
        assert!(
            head.contains("script-src 'self'") && !head.contains("unsafe-inline"),
            "{path}: {head}"
        );
        for header in [
            "x-frame-options: deny",
            "content-security-policy: frame-ancestors 'none'",
            "x-content-type-options: nosniff",
            "referrer-policy: no-referrer",
        ] {
            assert!(head.contains(header), "{path} lacks {header}:\n{head}");
        }
    }
    let _ = stop.send(());
    let _ = server.await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A page elsewhere cannot use the daemon: not through a name of its own that
/// resolves to the robot (DNS rebinding), and not by writing from its origin.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_elsewhere_can_neither_read_nor_write() {
    let dir = temp_dir("origin");
    let (addr, stop, server) = serve_simulation(&dir).await;
    let ask = |method: &'static str, path: &'static str, headers: String| {
        tokio::task::spawn_blocking(move || raw_head(addr, method, path, &headers))
    };
    let status_of = |head: &str| head.split(' ').nth(1).unwrap_or_default().to_string();
    let auth = format!("Authorization: Bearer {TOKEN}\r\n");
    // A name that is not this daemon's: refused, even for reading.
    let head = ask("GET", "/api/status", "Host: evil.example:8080\r\n".into())
        .await
        .unwrap();
    assert_eq!(status_of(&head), "421", "{head}");
    // The daemon's own address: served.
    let head = ask("GET", "/api/status", format!("Host: {addr}\r\n"))
        .await
        .unwrap();
    assert_eq!(status_of(&head), "200", "{head}");
    // A write with the token from another site's page: refused.
    let head = ask(
        "POST",
        "/api/calibrations/current/abort",
        format!("Host: {addr}\r\nOrigin: http://evil.example\r\n{auth}"),
    )
    .await
    .unwrap();
    assert_eq!(status_of(&head), "403", "{head}");
    // The daemon's own host under another scheme is another origin.
    let head = ask(
        "POST",
        "/api/calibrations/current/abort",
        format!("Host: {addr}\r\nOrigin: https://{addr}\r\n{auth}"),
    )
    .await
    .unwrap();
    assert_eq!(status_of(&head), "403", "{head}");
    // A request that names no host, or an empty one, is refused.
    for host in ["", "Host: \r\n", "Host:    \r\n"] {
        let head = ask("GET", "/api/status", host.into()).await.unwrap();
        assert_eq!(status_of(&head), "400", "{host:?}: {head}");
    }
    // The same write from the daemon's own page reaches the endpoint (no
    // calibration runs: 409).
    let head = ask(
        "POST",
        "/api/calibrations/current/abort",
        format!("Host: {addr}\r\nOrigin: http://{addr}\r\n{auth}"),
    )
    .await
    .unwrap();
    assert_eq!(status_of(&head), "409", "{head}");
    let _ = stop.send(());
    let _ = server.await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn serve_refuses_a_missing_config_or_token_before_listening() {
    use groundcal::cli::serve::{run, ServeOptions};
    use groundcal::cli::ExitStatus;
    let dir = temp_dir("refuse");
    let missing = ServeOptions {
        config: dir.join("nope.toml"),
        ..ServeOptions::default()
    };
    assert_eq!(run(&missing), ExitStatus::BadInput);
    // config/sim.toml names token.sim next to it; a copy without that file is refused.
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.toml")).unwrap();
    let schedule = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/schedules/octopus-52.toml"
    );
    let text = text.replace("schedules/octopus-52.toml", schedule);
    let config = dir.join("sim.toml");
    std::fs::write(&config, text).unwrap();
    let options = ServeOptions {
        config,
        ..ServeOptions::default()
    };
    assert_eq!(run(&options), ExitStatus::BadInput);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A check is bound to the calibration it checks: while it runs, a rollback
/// to another calibration is refused (409, naming the one being checked),
/// and afterwards the check's outcome stays with its own calibration's id,
/// which is no longer the active one.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_check_holds_the_active_calibration_until_it_ends() {
    let dir = temp_dir("check-bound");
    let state_dir = dir.join("state");
    let (a, b) = tokio::task::spawn_blocking({
        let state_dir = state_dir.clone();
        move || common::two_calibrations_in_store(&state_dir)
    })
    .await
    .unwrap();
    groundcal::formats::store::Store::new(&state_dir)
        .activate(&a, "2026-12-01T02:00:00Z", "a test")
        .unwrap();
    // Real time: the check lasts a few seconds.
    let (addr, stop, server) = serve_simulation_at(&dir, Some(1.0)).await;

    let (code, body) = request(addr, "POST", "/api/check", Some(TOKEN)).await;
    assert_eq!(code, 202, "{body}");
    let (_, status) = request(addr, "GET", "/api/status", None).await;
    assert_eq!(status["state"], "running", "{status}");
    assert_eq!(status["check"]["calibration_id"], a.as_str(), "{status}");
    let (code, body) = request(addr, "POST", &format!("/api/rollback/{b}"), Some(TOKEN)).await;
    assert_eq!(code, 409, "{body}");
    let said = body["error"].as_str().unwrap();
    assert!(
        said.contains(&format!("a check of calibration {a} is running")),
        "{said}"
    );
    let (_, active) = request(addr, "GET", "/api/active", None).await;
    assert_eq!(
        active["id"],
        a.as_str(),
        "the active calibration changed: {active}"
    );

    // Once the check has ended, the rollback goes through; the check's
    // outcome still names the calibration it checked.
    let start = Instant::now();
    loop {
        let (_, status) = request(addr, "GET", "/api/status", None).await;
        if status["state"] == "idle" && status["check"]["outcome"] != "running" {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "{status}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let (code, body) = request(addr, "POST", &format!("/api/rollback/{b}"), Some(TOKEN)).await;
    assert_eq!(code, 200, "{body}");
    let (_, status) = request(addr, "GET", "/api/status", None).await;
    assert_eq!(status["active"]["id"], b.as_str(), "{status}");
    assert_eq!(status["check"]["calibration_id"], a.as_str(), "{status}");
    let _ = stop.send(());
    server.await.unwrap().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Waits until `GET /api/view` answers a picture that `wanted` accepts.
async fn wait_view(addr: SocketAddr, wanted: impl Fn(&Value) -> bool) -> Value {
    let start = Instant::now();
    loop {
        let (code, view) = request(addr, "GET", "/api/view", None).await;
        assert_eq!(code, 200, "{view}");
        if view["view"].is_object() && wanted(&view) {
            return view;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no such picture came: {view}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Ground cells and cells with a reading in a picture.
fn ground_and_readings(view: &Value) -> (usize, usize) {
    let count = |key: &str, f: fn(u64) -> bool| {
        view["view"][key]
            .as_array()
            .unwrap()
            .iter()
            .filter(|v| f(v.as_u64().unwrap()))
            .count()
    };
    (count("ground", |g| g == 1), count("depth_cm", |d| d > 0))
}

/// The page's picture (issue 21): at rest the daemon shows what the camera
/// sees with the ground coloured, without the robot; during a calibration
/// the pictures are the session's own, pose by pose; afterwards the picture
/// at rest comes back. The sensor is never held by both at once (a session
/// that could not open it would fail).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_picture_shows_the_ground_at_rest_and_at_each_pose() {
    let dir = temp_dir("view");
    let (addr, stop, server) = serve_simulation(&dir).await;

    let at_rest = wait_view(addr, |v| v["pose"].is_null()).await;
    let (ground, readings) = ground_and_readings(&at_rest);
    assert_eq!(at_rest["view"]["width"], 80, "{at_rest}");
    assert_eq!(at_rest["view"]["height"], 60, "{at_rest}");
    assert!(
        readings > 4000 && ground * 10 > readings * 9,
        "at rest on the flat floor, {ground} of {readings} cells coloured"
    );
    assert!(at_rest["view"]["no_ground"].is_null(), "{at_rest}");
    let seq = at_rest["seq"].as_u64().unwrap();
    let later = wait_view(addr, |v| v["seq"].as_u64().unwrap() > seq).await;
    assert!(later["age_ms"].as_u64().unwrap() < 2000, "{later}");

    let (code, body) = request(addr, "POST", "/api/calibrations", Some(TOKEN)).await;
    assert_eq!(code, 202, "{body}");
    let during = wait_view(addr, |v| v["pose"].as_u64().is_some()).await;
    let (ground, readings) = ground_and_readings(&during);
    assert!(
        ground * 10 > readings * 8,
        "pose {}: {ground} of {readings} cells coloured",
        during["pose"]
    );
    let status = wait_idle(addr).await;
    assert!(status["result_id"].is_string(), "{status}");
    let seq = during["seq"].as_u64().unwrap();
    let (_, after) = request(addr, "GET", "/api/view", None).await;
    assert!(
        after["seq"].as_u64().unwrap() > seq,
        "one picture per pose: {after}"
    );
    wait_view(addr, |v| v["pose"].is_null()).await;

    let _ = stop.send(());
    server.await.unwrap().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The check at the service's start moves nothing: when the lower computer
/// (its own process) reports the body away from its home stance (another
/// client left it at a pose), the check is not made, the status says why
/// and that it waits for a person, and groundcal sends no SET_POSE, HOME or
/// HALT.
#[test]
fn the_check_at_start_waits_for_a_person_when_the_robot_stands_elsewhere() {
    use groundcal_hal::udp::{LinkConfig, UdpBodyController};
    use groundcal_hal::{BodyController, MotionState};
    let dir = temp_dir("start-elsewhere");
    common::active_calibration_in_store(&dir.join("state.sim"));
    let receipts = dir.join("receipts.jsonl");
    let (robot, robot_address) = common::spawn_sim_robot(
        &["--time-scale", "50"],
        &[("GROUNDCAL_SIM_RECEIPTS", receipts.as_os_str())],
    );
    // Another upper computer leaves the body rolled 5° at a pose.
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let link = LinkConfig::new(robot_address.parse().unwrap());
        let mut other = UdpBodyController::connect(&link).await.unwrap();
        other.hello().await.unwrap();
        let pose =
            groundcal::calib::geometry::PoseDegMm::from_values([0.0, 0.0, 5.0, 0.0, 600.0, 0.0]);
        other.set_pose(1, &pose, 200).await.unwrap();
        let start = Instant::now();
        while other.state().await.unwrap().state != MotionState::Settled {
            assert!(start.elapsed() < Duration::from_secs(10));
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    let mark = std::fs::read_to_string(&receipts).unwrap().lines().count();
    let address_line = format!("\naddress = \"{robot_address}\"\n");
    let (server, addr) = common::spawn_serve_with(
        dir.path(),
        TOKEN,
        &[("\naddress = \"sim\"\n", address_line.as_str())],
        &[],
        &[],
    );
    let status = common::wait_for_status(&addr, |s| {
        s["startup_check"] != "off" && s["startup_check"] != "started"
            || s["check"]["outcome"] == "failed"
    });
    assert_eq!(status["startup_check"], "held_not_standing", "{status:#}");
    let error = status["check"]["error"].as_str().unwrap_or_default();
    assert!(
        error.contains(
            "does not report the robot standing at its home stance (holding a pose away from home)"
        ) && error.contains("waits for a person"),
        "{status:#}"
    );
    let since: Vec<String> = std::fs::read_to_string(&receipts)
        .unwrap()
        .lines()
        .skip(mark)
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["event"] == "datagram")
        .filter_map(|v| v["kind"].as_str().map(String::from))
        .collect();
    assert!(since.iter().any(|k| k == "GET_STATE"), "{since:?}");
    assert!(
        !since.iter().any(|k| common::MOTION.contains(&k.as_str())),
        "the check at start moved the robot: {since:?}"
    );
    let (code, stderr) = common::terminate(server);
    assert_eq!(code, 0, "{stderr}");
    common::stop_sim_robot(robot);
}
