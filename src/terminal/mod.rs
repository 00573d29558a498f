//! `groundcal serve`: the daemon behind the phone/pad terminal on the robot's
//! Wi-Fi. An HTTP API (docs/api.md) and one embedded page; one calibration at
//! a time, run by the same session as `groundcal calibrate`; results kept in
//! the calibration store.
//!
//! The session runs on a thread of its own (with its own single-threaded
//! runtime) so that the hardware never has to cross threads; the HTTP side
//! sees it through a shared status, a broadcast of its events (server-sent
//! events) and an abort channel.

use std::collections::VecDeque;
use std::convert::Infallible;
use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use axum::extract::{ConnectInfo, Path as UrlPath, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Serialize;
use serde_json::{json, Value};
use tokio::sync::{broadcast, oneshot, watch};
use tokio_stream::StreamExt;

use crate::config::Config;
use crate::hardware::{self, Selection};
use crate::schedule::Schedule;
use crate::session::{self, Event};
use crate::store::{Store, StoreError};

/// The page, embedded: no CDN, works offline.
pub const PAGE: &str = include_str!("page.html");

/// How many recent events the status keeps.
const RECENT: usize = 30;

/// A serializable mirror of [`session::Event`] for the API.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum EventJson {
    Started {
        poses: usize,
        schedule: String,
    },
    Connected {
        firmware: String,
    },
    AtHome,
    SensorReady {
        tilt_deg: f64,
    },
    Moving {
        index: u16,
        of: usize,
    },
    Capturing {
        index: u16,
        of: usize,
    },
    PoseDone {
        index: u16,
        of: usize,
        ok: bool,
        inliers: Option<usize>,
        plane: Option<[f64; 4]>,
        error: Option<String>,
    },
    /// θ and e_d per pose against the mount the poses so far give.
    Provisional {
        poses: Vec<ProvisionalPoseJson>,
    },
    Solving,
    Finished {
        accepted: bool,
    },
    Aborted {
        reason: String,
    },
    /// Not a session event: the result was kept in the store under `id`.
    Stored {
        id: String,
        status: String,
    },
    /// Not a session event: the session ended without a result.
    Failed {
        error: String,
    },
}

/// One pose of a provisional solve.
#[derive(Debug, Clone, Serialize)]
pub struct ProvisionalPoseJson {
    pub index: u16,
    pub theta_deg: f64,
    pub e_d_mm: f64,
    pub used: bool,
}

impl From<&Event> for EventJson {
    fn from(e: &Event) -> Self {
        match e {
            Event::Started { poses, schedule } => EventJson::Started {
                poses: *poses,
                schedule: schedule.clone(),
            },
            Event::Connected { firmware } => EventJson::Connected {
                firmware: firmware.clone(),
            },
            Event::AtHome => EventJson::AtHome,
            Event::SensorReady { tilt_deg } => EventJson::SensorReady {
                tilt_deg: *tilt_deg,
            },
            Event::Moving { index, of, .. } => EventJson::Moving {
                index: *index,
                of: *of,
            },
            Event::Capturing { index, of } => EventJson::Capturing {
                index: *index,
                of: *of,
            },
            Event::PoseDone { index, of, outcome } => match outcome {
                Ok(fit) => EventJson::PoseDone {
                    index: *index,
                    of: *of,
                    ok: true,
                    inliers: Some(fit.inliers),
                    plane: Some(fit.plane),
                    error: None,
                },
                Err(e) => EventJson::PoseDone {
                    index: *index,
                    of: *of,
                    ok: false,
                    inliers: None,
                    plane: None,
                    error: Some(e.clone()),
                },
            },
            Event::Provisional { poses } => EventJson::Provisional {
                poses: poses
                    .iter()
                    .map(|p| ProvisionalPoseJson {
                        index: p.index,
                        theta_deg: p.theta_deg,
                        e_d_mm: p.e_d_mm,
                        used: p.used,
                    })
                    .collect(),
            },
            Event::Solving => EventJson::Solving,
            Event::Finished { accepted } => EventJson::Finished {
                accepted: *accepted,
            },
            Event::Aborted { reason } => EventJson::Aborted {
                reason: reason.clone(),
            },
        }
    }
}

/// What `GET /api/status` shows.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    /// `idle` or `running`.
    pub state: &'static str,
    /// Who started the current (or last) calibration.
    pub by: Option<String>,
    pub started: Option<String>,
    /// Pose i of N.
    pub pose: Option<u16>,
    pub of: Option<usize>,
    /// The robot's state in words (from the last event).
    pub robot: String,
    pub recent_events: VecDeque<EventJson>,
    /// The current or last result, with its store id.
    pub result: Option<Value>,
    pub result_id: Option<String>,
    /// Why the last session produced no result.
    pub error: Option<String>,
    /// Whether the hardware opened when the service started, in words (it
    /// is opened again for each calibration).
    pub hardware: String,
    /// The latest provisional θ and e_d per pose of a running session (kept
    /// here rather than among the recent events: it is replaced, not added).
    pub provisional: Option<Vec<ProvisionalPoseJson>>,
}

struct Shared {
    config: Config,
    schedule: Schedule,
    selection: Selection,
    token: String,
    store: Store,
    status: Mutex<Status>,
    events: broadcast::Sender<EventJson>,
    abort: Mutex<Option<oneshot::Sender<String>>>,
    worker: Mutex<Option<std::thread::JoinHandle<()>>>,
    shutdown: watch::Sender<bool>,
    /// When the running session's loop last beat (None: no session).
    heartbeat: Mutex<Option<Instant>>,
}

/// The daemon's state, shared by every request.
#[derive(Clone)]
pub struct AppState(Arc<Shared>);

impl AppState {
    /// `token` is required for everything that moves the robot or changes the
    /// active calibration; results are kept in the store in `state_dir`.
    pub fn new(
        config: Config,
        schedule: Schedule,
        selection: Selection,
        token: String,
        state_dir: &Path,
    ) -> Self {
        let (events, _) = broadcast::channel(1024);
        let (shutdown, _) = watch::channel(false);
        let store = Store::new(state_dir);
        // Saves cut short by a kill leave temporary files; nothing else does.
        match store.remove_stale_temporaries() {
            Ok(0) => {}
            Ok(n) => tracing::warn!(
                "removed {n} temporary files of saves that never finished in {}",
                state_dir.display()
            ),
            Err(e) => tracing::warn!("cannot clean the store: {e}"),
        }
        AppState(Arc::new(Shared {
            config,
            schedule,
            selection,
            token: token.trim().to_string(),
            store,
            status: Mutex::new(Status {
                state: "idle",
                robot: "idle".into(),
                ..Status::default()
            }),
            events,
            heartbeat: Mutex::new(None),
            abort: Mutex::new(None),
            worker: Mutex::new(None),
            shutdown,
        }))
    }

    /// A snapshot of the status.
    pub fn status(&self) -> Status {
        lock(&self.0.status).clone()
    }

    /// Records how the hardware check at start went (shown on the page).
    pub fn set_hardware(&self, words: String) {
        lock(&self.0.status).hardware = words;
    }

    /// Aborts a running session (if any) and waits until it has stopped the robot.
    pub async fn stop_session(&self, reason: &str) {
        if let Some(abort) = lock(&self.0.abort).take() {
            let _ = abort.send(reason.to_string());
        }
        let worker = lock(&self.0.worker).take();
        if let Some(worker) = worker {
            let _ = tokio::task::spawn_blocking(move || worker.join()).await;
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn now() -> String {
    humantime::format_rfc3339_seconds(SystemTime::now()).to_string()
}

/// Reads the token file (relative to the configuration's directory when relative).
pub fn read_token(config_path: &Path, token_file: &Path) -> Result<String, String> {
    let path = resolve(config_path, token_file);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("{}: cannot read the token: {e}", path.display()))?;
    let token = text.trim().to_string();
    if token.is_empty() {
        return Err(format!("{}: the token file is empty", path.display()));
    }
    Ok(token)
}

/// A path of the configuration, relative to the configuration file's directory.
pub fn resolve(config_path: &Path, path: &Path) -> PathBuf {
    match config_path.parent() {
        Some(dir) if path.is_relative() => dir.join(path),
        _ => path.to_path_buf(),
    }
}

struct ApiError(StatusCode, String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.0, Json(json!({ "error": self.1 }))).into_response()
    }
}

fn store_error(e: StoreError) -> ApiError {
    match e {
        StoreError::NotFound(_) => ApiError(StatusCode::NOT_FOUND, e.to_string()),
        StoreError::Rejected(_) | StoreError::Active(_) => {
            ApiError(StatusCode::CONFLICT, e.to_string())
        }
        _ => ApiError(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

fn authorize(state: &AppState, headers: &HeaderMap) -> Result<(), ApiError> {
    let given = headers
        .get("authorization")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim);
    let expected = state.0.token.as_bytes();
    let ok = match given {
        Some(g) if !expected.is_empty() && g.len() == expected.len() => {
            g.bytes()
                .zip(expected)
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
        }
        _ => false,
    };
    if ok {
        Ok(())
    } else {
        Err(ApiError(
            StatusCode::UNAUTHORIZED,
            "a valid token is required: send `Authorization: Bearer TOKEN` (the token is in the file serve.token_file)".into(),
        ))
    }
}

fn client_name(headers: &HeaderMap, addr: SocketAddr) -> String {
    headers
        .get("x-groundcal-client")
        .and_then(|v| v.to_str().ok())
        .map(|s| s.trim().chars().take(64).collect::<String>())
        .filter(|s| !s.is_empty())
        .map(|s| format!("{s} ({})", addr.ip()))
        .unwrap_or_else(|| addr.to_string())
}

/// The router of the API and the page.
pub fn router(state: AppState) -> Router {
    Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route("/api/status", get(get_status))
        .route("/api/events", get(get_events))
        .route("/api/calibrations", get(get_history).post(post_start))
        .route("/api/calibrations/current/abort", post(post_abort))
        .route("/api/calibrations/{id}", get(get_calibration))
        .route("/api/calibrations/{id}/accept", post(post_activate))
        .route("/api/calibrations/{id}/reject", post(post_reject))
        .route("/api/rollback/{id}", post(post_activate))
        .route("/api/active", get(get_active))
        .fallback(|| async {
            ApiError(
                StatusCode::NOT_FOUND,
                "no such endpoint (see docs/api.md)".into(),
            )
        })
        .layer(axum::middleware::map_response(protective_headers))
        .with_state(state)
}

/// Headers on every response: no other site may show the page in a frame
/// (where a click on it could be a click on Calibrate), browsers must not
/// guess content types, and no address leaks to other sites.
async fn protective_headers(mut response: Response) -> Response {
    use axum::http::header::{
        HeaderValue, CONTENT_SECURITY_POLICY, REFERRER_POLICY, X_CONTENT_TYPE_OPTIONS,
        X_FRAME_OPTIONS,
    };
    let headers = response.headers_mut();
    headers.insert(X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    headers.insert(
        CONTENT_SECURITY_POLICY,
        HeaderValue::from_static("frame-ancestors 'none'"),
    );
    headers.insert(X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    headers.insert(REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    response
}

/// Whether the watchdog may be fed: no session is running, or the running
/// session's loop beat within `within`. A session stuck (a blocked call, a
/// deadlock) stops the feeding, and systemd restarts the service.
fn session_alive(last_beat: Option<Instant>, now: Instant, within: Duration) -> bool {
    last_beat.is_none_or(|beat| now.saturating_duration_since(beat) <= within)
}

/// How often the session's loop beats: twice per watchdog feeding interval
/// (itself half of `WatchdogSec`), at most every 500 ms.
fn heartbeat_period() -> Duration {
    let most = Duration::from_millis(500);
    crate::systemd::watchdog_interval().map_or(most, |every| (every / 2).min(most))
}

/// Serves until `shutdown` completes; then aborts a running session, waits
/// for it to stop the robot, and returns. Notifies systemd (READY, WATCHDOG,
/// STOPPING) when it is listening.
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let notifier = crate::systemd::Notifier::from_env();
    let address = listener.local_addr()?;
    notifier.ready(&format!("listening on {address}"));
    let watchdog = crate::systemd::watchdog_interval().map(|every| {
        let state = state.clone();
        tokio::spawn(async move {
            let notifier = crate::systemd::Notifier::from_env();
            let mut tick = tokio::time::interval(every);
            loop {
                tick.tick().await;
                let last_beat = *lock(&state.0.heartbeat);
                if session_alive(last_beat, Instant::now(), every * 2) {
                    notifier.watchdog();
                } else {
                    // systemd restarts the service after WatchdogSec; the lower
                    // computer halts the robot once polling stops (1 s).
                    tracing::error!("the session loop is stuck; not feeding the watchdog");
                }
            }
        })
    });
    let app = router(state.clone());
    let stopping = state.clone();
    let graceful = async move {
        shutdown.await;
        crate::systemd::Notifier::from_env().stopping();
        stopping.stop_session("the service is stopping").await;
        let _ = stopping.0.shutdown.send(true);
    };
    let served = axum::serve(
        listener,
        app.into_make_service_with_connect_info::<SocketAddr>(),
    )
    .with_graceful_shutdown(graceful)
    .await;
    if let Some(w) = watchdog {
        w.abort();
    }
    served
}

async fn get_status(State(state): State<AppState>) -> Json<Status> {
    Json(state.status())
}

async fn get_events(
    State(state): State<AppState>,
) -> Sse<impl tokio_stream::Stream<Item = Result<SseEvent, Infallible>>> {
    // Each item: Some(Some(event)), Some(None) for nothing, None once the
    // service stops (which ends the stream, so graceful shutdown can finish).
    let stop = tokio_stream::wrappers::WatchStream::new(state.0.shutdown.subscribe())
        .map(|stopping| if stopping { None } else { Some(None) });
    let events = tokio_stream::wrappers::BroadcastStream::new(state.0.events.subscribe())
        .filter_map(|e| e.ok())
        .map(|e| Some(Some(e)));
    let stream = events
        .merge(stop)
        .take_while(Option::is_some)
        .filter_map(|e| e.flatten())
        .map(|e| Ok(SseEvent::default().data(serde_json::to_string(&e).unwrap_or_default())));
    Sse::new(stream).keep_alive(KeepAlive::default())
}

async fn get_history(State(state): State<AppState>) -> Result<Json<Value>, ApiError> {
    let history = state.0.store.history().map_err(store_error)?;
    Ok(Json(json!({ "calibrations": history })))
}

async fn get_calibration(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ApiError> {
    state.0.store.get(&id).map(Json).map_err(store_error)
}

async fn get_active(State(state): State<AppState>) -> Result<Json<Value>, ApiError> {
    match state.0.store.active().map_err(store_error)? {
        Some(a) => Ok(Json(a)),
        None => Err(ApiError(
            StatusCode::NOT_FOUND,
            "no calibration is active yet".into(),
        )),
    }
}

/// Accept a result, or roll back to an earlier one: both make it active.
async fn post_activate(
    State(state): State<AppState>,
    headers: HeaderMap,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ApiError> {
    authorize(&state, &headers)?;
    state
        .0
        .store
        .activate(&id, &now())
        .map(Json)
        .map_err(store_error)
}

async fn post_reject(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ApiError> {
    authorize(&state, &headers)?;
    state
        .0
        .store
        .reject(&id, &now(), &client_name(&headers, addr))
        .map(Json)
        .map_err(store_error)
}

async fn post_abort(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
) -> Result<Response, ApiError> {
    authorize(&state, &headers)?;
    let abort = lock(&state.0.abort).take();
    match abort {
        Some(abort) => {
            let _ = abort.send(format!(
                "aborted by the operator ({})",
                client_name(&headers, addr)
            ));
            Ok((StatusCode::ACCEPTED, Json(json!({ "aborting": true }))).into_response())
        }
        None => Err(ApiError(
            StatusCode::CONFLICT,
            "no calibration is running".into(),
        )),
    }
}

async fn post_start(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
) -> Result<Response, ApiError> {
    authorize(&state, &headers)?;
    if *state.0.shutdown.borrow() {
        return Err(ApiError(
            StatusCode::SERVICE_UNAVAILABLE,
            "the service is stopping".into(),
        ));
    }
    let by = client_name(&headers, addr);
    let (abort_tx, abort_rx) = oneshot::channel::<String>();
    {
        let mut status = lock(&state.0.status);
        if status.state == "running" {
            return Err(ApiError(
                StatusCode::CONFLICT,
                format!(
                    "a calibration is already running, started by {} at {}",
                    status.by.as_deref().unwrap_or("someone"),
                    status.started.as_deref().unwrap_or("?")
                ),
            ));
        }
        *status = Status {
            state: "running",
            by: Some(by.clone()),
            started: Some(now()),
            robot: "opening the hardware".into(),
            hardware: std::mem::take(&mut status.hardware),
            ..Status::default()
        };
        *lock(&state.0.abort) = Some(abort_tx);
    }
    // A finished worker of an earlier session is joined here.
    if let Some(old) = lock(&state.0.worker).take() {
        let _ = old.join();
    }
    let worker_state = state.clone();
    let spawned = std::thread::Builder::new()
        .name("groundcal-session".into())
        .spawn(move || run_session(worker_state, abort_rx));
    match spawned {
        Ok(handle) => {
            *lock(&state.0.worker) = Some(handle);
            let started = lock(&state.0.status).started.clone();
            Ok((
                StatusCode::ACCEPTED,
                Json(json!({ "state": "running", "by": by, "started": started })),
            )
                .into_response())
        }
        Err(e) => {
            let mut status = lock(&state.0.status);
            status.state = "idle";
            status.error = Some(format!("cannot start the session: {e}"));
            Err(ApiError(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("cannot start the session: {e}"),
            ))
        }
    }
}

fn publish(state: &AppState, event: EventJson) {
    {
        let mut status = lock(&state.0.status);
        match &event {
            EventJson::Started { poses, .. } => {
                status.of = Some(*poses);
                status.robot = "schedule checked".into();
            }
            EventJson::Connected { firmware } => status.robot = format!("connected ({firmware})"),
            EventJson::AtHome => status.robot = "at the home stance".into(),
            EventJson::SensorReady { tilt_deg } => {
                status.robot = format!("Kinect tilted to {tilt_deg}°")
            }
            EventJson::Moving { index, of } => {
                status.pose = Some(*index);
                status.of = Some(*of);
                status.robot = "moving".into();
            }
            EventJson::Capturing { index, of } => {
                status.pose = Some(*index);
                status.of = Some(*of);
                status.robot = "capturing".into();
            }
            EventJson::PoseDone { index, .. } => status.pose = Some(*index),
            EventJson::Solving => status.robot = "back home; solving".into(),
            EventJson::Finished { accepted } => {
                status.robot = format!(
                    "finished ({})",
                    if *accepted { "accepted" } else { "rejected" }
                )
            }
            EventJson::Aborted { reason } => status.robot = format!("aborted: {reason}"),
            EventJson::Stored { .. } | EventJson::Failed { .. } => {}
            EventJson::Provisional { poses } => status.provisional = Some(poses.clone()),
        }
        if !matches!(event, EventJson::Provisional { .. }) {
            status.recent_events.push_back(event.clone());
        }
        while status.recent_events.len() > RECENT {
            status.recent_events.pop_front();
        }
    }
    let _ = state.0.events.send(event);
}

/// The session thread: opens the hardware, runs the session, keeps the result.
fn run_session(state: AppState, abort: oneshot::Receiver<String>) {
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            return finish(
                &state,
                Err(format!("cannot start the session's runtime: {e}")),
            )
        }
    };
    let outcome = runtime.block_on(async {
        let shared = &state.0;
        let work = async {
            let (mut sensor, mut controller) = hardware::open(&shared.config, &shared.selection)
                .await
                .map_err(|e| e.to_string())?;
            let replay = match &sensor {
                hardware::Sensor::Replay(r) => Some(r.recording().clone()),
                _ => None,
            };
            let plan = crate::cli::calibrate::plan(
                &shared.config,
                shared.schedule.clone(),
                replay.as_ref(),
                None,
            )?;
            let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<Event>();
            let abort = async move {
                abort
                    .await
                    .unwrap_or_else(|_| "the service went away".to_string())
            };
            let session = async {
                let r = session::run(&mut sensor, &mut controller, &plan, &tx, abort).await;
                drop(tx);
                r
            };
            let forward = async {
                while let Some(e) = rx.recv().await {
                    publish(&state, EventJson::from(&e));
                }
            };
            tokio::join!(session, forward).0.map_err(|e| e.to_string())
        };
        // The session's own runtime beats from the moment it opens the
        // hardware: if that runtime is blocked (a stuck device call, a
        // deadlock), the beat stops and so does the systemd watchdog.
        let beat = async {
            let mut tick = tokio::time::interval(heartbeat_period());
            loop {
                tick.tick().await;
                *lock(&state.0.heartbeat) = Some(Instant::now());
            }
        };
        tokio::select! {
            result = work => result,
            never = beat => never,
        }
    });
    *lock(&state.0.heartbeat) = None;
    let result = outcome.and_then(|o| {
        serde_json::to_value(&o.result).map_err(|e| format!("cannot encode the result: {e}"))
    });
    finish(&state, result);
}

fn finish(state: &AppState, result: Result<Value, String>) {
    lock(&state.0.abort).take();
    // The provisional charts end with the session: the result replaces them.
    lock(&state.0.status).provisional = None;
    match result {
        Ok(value) => {
            let status_text = value
                .get("status")
                .and_then(Value::as_str)
                .unwrap_or("unknown")
                .to_string();
            match state.0.store.add(&value, &now()) {
                Ok(id) => {
                    let mut stored = value;
                    if let Value::Object(m) = &mut stored {
                        m.insert("id".into(), Value::String(id.clone()));
                    }
                    {
                        let mut status = lock(&state.0.status);
                        status.result = Some(stored);
                        status.result_id = Some(id.clone());
                        status.state = "idle";
                    }
                    publish(
                        state,
                        EventJson::Stored {
                            id,
                            status: status_text,
                        },
                    );
                }
                Err(e) => {
                    let error = format!("the result could not be kept: {e}");
                    {
                        let mut status = lock(&state.0.status);
                        status.result = Some(value);
                        status.error = Some(error.clone());
                        status.state = "idle";
                    }
                    publish(state, EventJson::Failed { error });
                }
            }
        }
        Err(error) => {
            {
                let mut status = lock(&state.0.status);
                status.error = Some(error.clone());
                status.state = "idle";
            }
            publish(state, EventJson::Failed { error });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stuck_session_stops_the_watchdog_feeding() {
        let now = Instant::now();
        let within = Duration::from_secs(10);
        assert!(session_alive(None, now, within), "idle: fed");
        assert!(session_alive(
            Some(now - Duration::from_secs(3)),
            now,
            within
        ));
        assert!(!session_alive(
            Some(now - Duration::from_secs(11)),
            now,
            within
        ));
    }
}
