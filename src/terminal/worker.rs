//! The session thread: opens the hardware, runs the same session as
//! `groundcal calibrate` (or `groundcal verify`) on a runtime of its own (so
//! the hardware never crosses threads), forwards its events, and keeps the
//! result in the store (or the check's outcome in the status and the journal).

use tokio::sync::oneshot;

use super::api::{CheckStatus, EventJson, RunState};
use super::state::{now, AppState};
use crate::formats::output::ResultJson;
use crate::formats::store::StoredResult;
use crate::hardware;
use crate::session::{self, Event};
use crate::solving::verify::{calibration_in_store, check_schedule, VerifyJson};

/// The session's own runtime, on this thread.
fn session_runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the session's runtime: {e}"))
}

/// Runs `work` while the session's loop beats: if that runtime is blocked
/// (a stuck device call, a deadlock), the beat stops and so does the systemd
/// watchdog.
async fn beating<T>(state: &AppState, work: impl std::future::Future<Output = T>) -> T {
    let beat = async {
        let mut tick = tokio::time::interval(crate::platform::systemd::heartbeat_period());
        loop {
            tick.tick().await;
            state.beat();
        }
    };
    tokio::select! {
        result = work => result,
        never = beat => never,
    }
}

/// The abort as a future of its reason.
async fn abort_reason(abort: oneshot::Receiver<String>) -> String {
    abort
        .await
        .unwrap_or_else(|_| "the service went away".to_string())
}

/// The session thread: opens the hardware, runs the session, keeps the result.
pub fn run_session(state: AppState, abort: oneshot::Receiver<String>) {
    // The live picture holds the sensor: it is closed before the session opens it.
    state.stop_preview();
    let runtime = match session_runtime() {
        Ok(r) => r,
        Err(e) => return finish(&state, Err(e)),
    };
    let outcome = runtime.block_on(async {
        let work = async {
            let (mut sensor, mut controller) = hardware::open(state.config(), state.selection())
                .await
                .map_err(|e| e.to_string())?;
            let replay = match &sensor {
                hardware::Sensor::Playback(r) => Some(r.recording().clone()),
                _ => None,
            };
            let plan = session::Plan::from_config(
                state.config(),
                state.schedule().clone(),
                replay.as_ref(),
                None,
            )?;
            let (tx, rx) = tokio::sync::mpsc::unbounded_channel::<Event>();
            let session = async {
                let r = session::run(
                    &mut sensor,
                    &mut controller,
                    &plan,
                    &tx,
                    abort_reason(abort),
                )
                .await;
                drop(tx);
                r
            };
            tokio::join!(session, forward(&state, rx))
                .0
                .map_err(|e| e.to_string())
        };
        // The session's own runtime beats from the moment it opens the hardware.
        beating(&state, work).await
    });
    state.clear_heartbeat();
    finish(&state, outcome.map(|o| o.result));
}

/// Publishes the session's events until it ends; its pictures go to
/// `GET /api/view`, and the stream only says that a new one is there.
async fn forward(state: &AppState, mut events: tokio::sync::mpsc::UnboundedReceiver<Event>) {
    while let Some(e) = events.recv().await {
        let json = EventJson::from(&e);
        if let Event::GroundSeen { index, view } = e {
            state.keep_view(index, *view);
        }
        state.publish(json);
    }
}

/// Why a check ended without a verdict.
enum CheckFailure {
    /// A check that must not move anything would have had to (the robot
    /// not at its home stance, the motor not at the tilt).
    WouldMove(String),
    Other(String),
}

impl From<String> for CheckFailure {
    fn from(e: String) -> Self {
        CheckFailure::Other(e)
    }
}

/// The check thread: the active calibration against the sensor now, as
/// `groundcal verify`. A person's check visits the configuration's `[verify]
/// poses`; the service's own (`by_a_person` false) moves nothing: it reads
/// the stance the robot stands in, or waits for a person.
pub fn run_check(state: AppState, abort: oneshot::Receiver<String>, by_a_person: bool) {
    state.stop_preview();
    let runtime = match session_runtime() {
        Ok(r) => r,
        Err(e) => return finish_check(&state, Err(CheckFailure::Other(e)), by_a_person),
    };
    let outcome = runtime.block_on(async {
        let work = async {
            let calibration = calibration_in_store(state.store())?
                .ok_or_else(|| "no calibration is active: there is nothing to check".to_string())?;
            calibration.same_robot(
                state.config().robot.name.as_deref(),
                "the configuration's [robot] name",
            )?;
            // The check is bound to the calibration it was started for.
            let expected = state
                .status()
                .check
                .and_then(|c| c.calibration_id);
            if calibration.id != expected {
                return Err(CheckFailure::Other(format!(
                    "the active calibration changed to {} before the check began; press Check again",
                    calibration.id.as_deref().unwrap_or("one without an id")
                )));
            }
            let (mut sensor, mut controller) = hardware::open(state.config(), state.selection())
                .await
                .map_err(|e| e.to_string())?;
            let config = state.config();
            let tilted = if by_a_person { config.verify.poses } else { 0 };
            let schedule = check_schedule(
                state.schedule().home,
                tilted,
                config.verify.tilt_deg(&config.robot.limits),
            );
            let mut plan = session::Plan::for_check(config, schedule, &calibration, None)?;
            plan.stand_still = !by_a_person;
            let (tx, rx) = tokio::sync::mpsc::unbounded_channel::<Event>();
            let session = async {
                let r = session::verify(
                    &mut sensor,
                    &mut controller,
                    &plan,
                    &tx,
                    abort_reason(abort),
                    &calibration.mount,
                )
                .await;
                drop(tx);
                r
            };
            let outcome = tokio::join!(session, forward(&state, rx)).0.map_err(|e| match e {
                session::SessionError::WouldMove(why) => CheckFailure::WouldMove(why),
                other => CheckFailure::Other(other.to_string()),
            })?;
            Ok::<_, CheckFailure>((
                VerifyJson::new(
                    &outcome.report,
                    &outcome.poses,
                    &calibration.mount,
                    calibration.tilt_deg,
                ),
                calibration.source,
            ))
        };
        beating(&state, work).await
    });
    state.clear_heartbeat();
    finish_check(&state, outcome, by_a_person);
}

/// A check's outcome, to the status, the journal and the live stream; a
/// verdict also to the store, where it outlives any stop.
fn finish_check(
    state: &AppState,
    outcome: Result<(VerifyJson, String), CheckFailure>,
    by_a_person: bool,
) {
    if by_a_person {
        state.store().clear_running();
    }
    state.take_abort();
    let mut held_not_standing = false;
    let (outcome_words, reasons, error, report) = match outcome {
        Ok((report, source)) => {
            if report.drifted() {
                tracing::warn!(
                    "check of the active calibration ({source}): drift: {}; calibrate again",
                    report.reasons.join("; ")
                );
            } else {
                let checks: Vec<String> = report
                    .checks
                    .iter()
                    .map(|c| {
                        format!(
                            "{} {:.3} of {:.3} {}",
                            c.name, c.measured, c.threshold, c.unit
                        )
                    })
                    .collect();
                tracing::info!(
                    "check of the active calibration ({source}): consistent ({})",
                    checks.join(", ")
                );
            }
            let words = if report.drifted() {
                "drift"
            } else {
                "consistent"
            };
            (words, report.reasons.clone(), None, Some(report))
        }
        Err(CheckFailure::WouldMove(e)) => {
            tracing::warn!("the check at the service's start was not made: {e}");
            held_not_standing = !by_a_person;
            ("failed", Vec::new(), Some(e), None)
        }
        Err(CheckFailure::Other(e)) => {
            tracing::warn!("check of the active calibration failed: {e}");
            ("failed", Vec::new(), Some(e), None)
        }
    };
    // Which calibration was checked, by whom, and when it started: the
    // running check's entry in the status.
    let previous = state.status_mut().check.clone();
    let check = CheckStatus {
        calibration_id: previous.as_ref().and_then(|c| c.calibration_id.clone()),
        outcome: outcome_words.into(),
        by: previous.as_ref().map_or_else(String::new, |c| c.by.clone()),
        started_by_service: !by_a_person,
        started: previous.map_or_else(String::new, |c| c.started),
        finished: Some(now()),
        reasons: reasons.clone(),
        error,
        report,
    };
    let verdict = (check.outcome != "failed").then(|| check.clone());
    // Kept before the status shows it, outside the status's lock (a write
    // waits for the disk): shown first, a knock the page had already told
    // was lost to a crash in between (tests/serve_browser.rs, killed the
    // moment the status said "drift").
    if let Some(verdict) = &verdict {
        if let Err(e) = state.store().save_check(verdict) {
            tracing::warn!("cannot keep the check's verdict in the store: {e}");
        }
    }
    {
        let mut status = state.status_mut();
        if let Some(v) = &verdict {
            status.verdict = Some(v.clone());
        }
        status.check = Some(check);
        if held_not_standing {
            status.startup_check = super::api::StartupCheck::HeldNotStanding;
        }
        status.state = RunState::Idle;
        status.provisional = None;
    }
    if verdict.is_some() && by_a_person {
        state.note_run_took(super::api::Task::Check);
    }
    state.publish(EventJson::Checked {
        outcome: outcome_words.into(),
        reasons,
    });
    state.start_preview();
}

fn finish(state: &AppState, result: Result<ResultJson, String>) {
    state.store().clear_running();
    state.take_abort();
    // The provisional charts end with the session: the result replaces them.
    state.status_mut().provisional = None;
    match result {
        Ok(result) => {
            state.note_run_took(super::api::Task::Calibration);
            let status_text = result.status.as_str().to_string();
            let created = now();
            match state.store().add(&result, &created) {
                Ok(id) => {
                    {
                        let mut status = state.status_mut();
                        // The pattern's cells stay in the store: the status is
                        // polled every second, the cells are drawn once.
                        status.result = Some(StoredResult {
                            id: id.clone(),
                            created,
                            operator_rejection: None,
                            replaced: None,
                            result: result.without_pattern_cells(),
                        });
                        status.result_id = Some(id.clone());
                        status.state = RunState::Idle;
                    }
                    state.publish(EventJson::Stored {
                        id,
                        status: status_text,
                    });
                }
                Err(e) => {
                    let error = format!("the result could not be kept: {e}");
                    {
                        // Shown, but with no id: it cannot be accepted.
                        let mut status = state.status_mut();
                        status.result = Some(StoredResult {
                            id: String::new(),
                            created,
                            operator_rejection: None,
                            replaced: None,
                            result,
                        });
                        status.error = Some(error.clone());
                        status.state = RunState::Idle;
                    }
                    state.publish(EventJson::Failed { error });
                }
            }
        }
        Err(error) => {
            tracing::warn!("the calibration stopped without a result: {error}");
            {
                let mut status = state.status_mut();
                status.error = Some(error.clone());
                status.state = RunState::Idle;
            }
            state.publish(EventJson::Failed { error });
        }
    }
    state.start_preview();
}
