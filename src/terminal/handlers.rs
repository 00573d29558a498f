//! The API's endpoints (docs/api.md). The token was checked before any
//! write reaches them (`super::auth`).

use std::convert::Infallible;
use std::net::SocketAddr;

use axum::extract::{ConnectInfo, Path as UrlPath, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::sse::{Event as SseEvent, Sse};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::json;
use tokio::sync::oneshot;
use tokio_stream::StreamExt;

use super::api::{CheckStatus, EventJson, History, RunClock, RunState, Status, Task};
use super::state::{now, AppState};
use super::worker;
use crate::formats::store::{ActiveDocument, StoreError, StoredResult};

/// An error answer: a status and a sentence, as `{"error": "..."}`.
pub struct ApiError(pub StatusCode, pub String);

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

/// Who sent a request, for the status and the store: the page's own name for
/// itself (if any; percent-encoded UTF-8, as a header carries only ASCII)
/// and the address.
fn client_name(headers: &HeaderMap, addr: SocketAddr) -> String {
    headers
        .get("x-groundcal-client")
        .and_then(|v| v.to_str().ok())
        .map(|s| percent_encoding::percent_decode_str(s).decode_utf8_lossy())
        .map(|s| {
            s.trim()
                .chars()
                .filter(|c| !c.is_control())
                .take(64)
                .collect::<String>()
        })
        .filter(|s| !s.is_empty())
        .map(|s| format!("{s} ({})", addr.ip()))
        .unwrap_or_else(|| addr.to_string())
}

pub async fn get_status(State(state): State<AppState>) -> Json<Status> {
    Json(state.status())
}

/// `POST /api/stream-ticket` (with the token): a one-use ticket that opens
/// the operator's live stream, `GET /api/events?ticket=…`, within 30 s.
pub async fn post_stream_ticket(
    State(state): State<AppState>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let ticket = state.stream_ticket().map_err(|e| {
        ApiError(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot make a stream ticket: {e}"),
        )
    })?;
    Ok(Json(json!({ "ticket": ticket, "expires_in_s": 30 })))
}

/// `GET /api/events`: the live stream. With a valid `?ticket=` it is the
/// operator's, with a budget of streams that no stream opened without the
/// token can take (`super::connections`); an unknown or used ticket is
/// refused rather than quietly demoted.
pub async fn get_events(
    State(state): State<AppState>,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
) -> Result<Response, ApiError> {
    let ticket = query
        .as_deref()
        .and_then(|q| q.split('&').find_map(|pair| pair.strip_prefix("ticket=")));
    let owner = match ticket {
        None => super::connections::StreamOwner::Anyone,
        Some(t) if state.take_stream_ticket(t) => super::connections::StreamOwner::Operator,
        Some(_) => {
            return Err(ApiError(
                StatusCode::FORBIDDEN,
                "this stream ticket is unknown, used or expired: ask for a new one (POST /api/stream-ticket)".into(),
            ))
        }
    };
    let mut response = event_stream(&state).into_response();
    response.extensions_mut().insert(owner);
    Ok(response)
}

/// The live stream of events, with a heartbeat every second.
fn event_stream(
    state: &AppState,
) -> Sse<impl tokio_stream::Stream<Item = Result<SseEvent, Infallible>>> {
    // Each item: Some(Some(event)), Some(None) for nothing, None once the
    // service stops (which ends the stream, so graceful shutdown can finish).
    let stop = tokio_stream::wrappers::WatchStream::new(state.subscribe_stopping())
        .map(|stopping| if stopping { None } else { Some(None) });
    let events = tokio_stream::wrappers::BroadcastStream::new(state.subscribe_events())
        .filter_map(|e| e.ok())
        .map(|e| Some(Some(e)));
    // A page that hears nothing for two beats declares contact lost: a
    // stopped daemon or a link that dropped without closing cannot look alive.
    let beats = tokio_stream::wrappers::IntervalStream::new(tokio::time::interval(HEARTBEAT))
        .map(|_| Some(Some(EventJson::Heartbeat)));
    let stream = events
        .merge(beats)
        .merge(stop)
        .take_while(Option::is_some)
        .filter_map(|e| e.flatten())
        .map(|e| Ok(SseEvent::default().data(serde_json::to_string(&e).unwrap_or_default())));
    Sse::new(stream)
}

/// How often the event stream says the daemon is alive.
pub const HEARTBEAT: std::time::Duration = std::time::Duration::from_secs(1);

pub async fn get_history(State(state): State<AppState>) -> Result<Json<History>, ApiError> {
    let calibrations = state.store().history().map_err(store_error)?;
    Ok(Json(History { calibrations }))
}

pub async fn get_calibration(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<StoredResult>, ApiError> {
    state.store().get(&id).map(Json).map_err(store_error)
}

pub async fn get_active(State(state): State<AppState>) -> Result<Json<ActiveDocument>, ApiError> {
    match state.store().active().map_err(store_error)? {
        Some(a) => Ok(Json(a)),
        None => Err(ApiError(
            StatusCode::NOT_FOUND,
            "no calibration is active yet".into(),
        )),
    }
}

/// Accept a result, or roll back to an earlier one: both make it active,
/// and every open page is told. Refused while a check runs: its outcome
/// would otherwise be shown for a calibration it did not check (wait for
/// it, or abort it).
pub async fn post_activate(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<ActiveDocument>, ApiError> {
    let by = client_name(&headers, addr);
    let store = state.store().clone();
    let activated = {
        // The status is held from the test to the write: a check cannot
        // start in between (it takes the same lock to start).
        let status = state.status_mut();
        if status.state == RunState::Running && status.task == Task::Check {
            let checking = status
                .check
                .as_ref()
                .and_then(|c| c.calibration_id.clone())
                .unwrap_or_else(|| "the active calibration".into());
            return Err(ApiError(
                StatusCode::CONFLICT,
                format!(
                    "a check of calibration {checking} is running: wait for it to finish, or abort it, before you change the active calibration"
                ),
            ));
        }
        let activated = store.activate(&id, &now(), &by).map_err(store_error)?;
        drop(status);
        activated
    };
    // The result on the page that this replaced says so at once.
    let shown = state.status().result.map(|r| r.id);
    if let Some(shown) = shown.filter(|shown| *shown != activated.id) {
        if let Ok(stored) = store.get(&shown) {
            if let Some(result) = state.status_mut().result.as_mut() {
                if result.id == shown {
                    result.replaced = stored.replaced;
                }
            }
        }
    }
    state.publish(EventJson::Activated {
        id: activated.id.clone(),
        activated: activated.activated.clone(),
        by,
    });
    Ok(Json(activated))
}

pub async fn post_reject(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<StoredResult>, ApiError> {
    state
        .store()
        .reject(&id, &now(), &client_name(&headers, addr))
        .map(Json)
        .map_err(store_error)
}

pub async fn post_abort(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
) -> Result<Response, ApiError> {
    let abort = state.take_abort();
    match abort {
        Some(abort) => {
            let by = client_name(&headers, addr);
            let _ = abort.send(format!("stopped by the operator ({by})"));
            state.publish(EventJson::Aborting { by });
            Ok((StatusCode::ACCEPTED, Json(json!({ "aborting": true }))).into_response())
        }
        None => Err(ApiError(
            StatusCode::CONFLICT,
            "no calibration or check is running".into(),
        )),
    }
}

pub async fn post_start(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
) -> Result<Response, ApiError> {
    let by = client_name(&headers, addr);
    let started = start(&state, Starter::Person(by.clone()), Task::Calibration)?;
    Ok((
        StatusCode::ACCEPTED,
        Json(json!({ "state": "running", "by": by, "started": started })),
    )
        .into_response())
}

/// Checks the active calibration against the sensor now (`verify`).
pub async fn post_check(
    State(state): State<AppState>,
    headers: HeaderMap,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
) -> Result<Response, ApiError> {
    if state.store().active().map_err(store_error)?.is_none() {
        return Err(ApiError(
            StatusCode::CONFLICT,
            "no calibration is active yet: there is nothing to check".into(),
        ));
    }
    let by = client_name(&headers, addr);
    let started = start(&state, Starter::Person(by.clone()), Task::Check)?;
    Ok((
        StatusCode::ACCEPTED,
        Json(json!({ "state": "running", "task": "check", "by": by, "started": started })),
    )
        .into_response())
}

/// Who starts a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Starter {
    /// A person, on the page or through the API (as the request names itself).
    Person(String),
    /// The service's own start: only a check, and one that moves nothing
    /// (no person asked for it, and nobody may be watching the robot).
    ServiceStart,
}

impl Starter {
    /// The name the status and the store give the starter.
    pub fn name(&self) -> String {
        match self {
            Starter::Person(by) => by.clone(),
            Starter::ServiceStart => SERVICE_START.into(),
        }
    }
}

/// How the status names the service's own start as a check's starter.
pub const SERVICE_START: &str = "the service's start";

/// Starts a session on its own thread, unless one runs or the service
/// stops; returns when it started. A calibration replaces the last result
/// on the page; a check keeps it. A person's start ends the notice of an
/// interrupted run (they have seen it: the page shows it beside the
/// buttons); the service's own start leaves it.
pub fn start(state: &AppState, starter: Starter, task: Task) -> Result<String, ApiError> {
    let by = starter.name();
    let by_a_person = matches!(starter, Starter::Person(_));
    if !by_a_person && task != Task::Check {
        return Err(ApiError(
            StatusCode::FORBIDDEN,
            "only a person starts a calibration".into(),
        ));
    }
    if state.is_stopping() {
        return Err(ApiError(
            StatusCode::SERVICE_UNAVAILABLE,
            "the service is stopping".into(),
        ));
    }
    let started = now();
    let (abort_tx, abort_rx) = oneshot::channel::<String>();
    {
        let mut status = state.status_mut();
        if status.state == RunState::Running {
            let what = match status.task {
                Task::Calibration => "a calibration",
                Task::Check => "a check of the active calibration",
            };
            return Err(ApiError(
                StatusCode::CONFLICT,
                format!(
                    "{what} is already running, started by {} at {}",
                    status.by.as_deref().unwrap_or("someone"),
                    status.started.as_deref().unwrap_or("?")
                ),
            ));
        }
        let previous = std::mem::take(&mut *status);
        let interrupted = if by_a_person {
            None
        } else {
            previous.interrupted
        };
        let mut next = Status {
            // The count of changes goes on: a page orders its answers by it.
            instance: previous.instance,
            revision: previous.revision,
            state: RunState::Running,
            task,
            by: Some(by.clone()),
            started: Some(started.clone()),
            robot: "opening the hardware".into(),
            step: "opening the Kinect and connecting to the robot".into(),
            clock: Some(RunClock::start(std::time::Instant::now())),
            gates: previous.gates,
            hardware: previous.hardware,
            check: previous.check,
            verdict: previous.verdict,
            interrupted,
            startup_check: previous.startup_check,
            motion: previous.motion,
            active: previous.active,
            ..Status::default()
        };
        if task == Task::Check {
            next.step = "checking the sensor against the active calibration: opening the Kinect and connecting to the robot".into();
            next.result = previous.result;
            next.result_id = previous.result_id;
            next.check = Some(CheckStatus {
                calibration_id: next.active.as_ref().map(|a| a.id.clone()),
                outcome: "running".into(),
                by: by.clone(),
                started_by_service: !by_a_person,
                started: started.clone(),
                finished: None,
                reasons: Vec::new(),
                error: None,
                report: None,
            });
        }
        *status = next;
        state.set_abort(abort_tx);
    }
    // Written once the status is released: a write waits for the disk. A
    // run that moves the robot is marked, so that a stop that cuts it off is
    // said at the next start; it replaces the marker of an interrupted run,
    // which this person has now seen. The service's own check moves
    // nothing and leaves the marker as it is.
    let task_name = match task {
        Task::Calibration => "calibration",
        Task::Check => "check",
    };
    if by_a_person {
        if let Err(e) = state.store().mark_running(&by, &started, task_name) {
            tracing::warn!("cannot mark the {task_name} as running: {e}");
        }
    }
    // A finished worker of an earlier session is joined here.
    let worker_state = state.clone();
    let spawned = state.replace_worker(|| {
        std::thread::Builder::new()
            .name("groundcal-session".into())
            .spawn(move || match task {
                Task::Calibration => worker::run_session(worker_state, abort_rx),
                Task::Check => worker::run_check(worker_state, abort_rx, by_a_person),
            })
    });
    match spawned {
        Ok(()) => Ok(started),
        Err(e) => {
            if by_a_person {
                state.store().clear_running();
            }
            let mut status = state.status_mut();
            status.state = RunState::Idle;
            status.error = Some(format!("cannot start the session: {e}"));
            Err(ApiError(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("cannot start the session: {e}"),
            ))
        }
    }
}

/// `GET /api/view`: the latest picture of what the camera sees.
pub async fn get_view(State(state): State<AppState>) -> Json<super::api::ViewJson> {
    Json(state.view_json())
}
