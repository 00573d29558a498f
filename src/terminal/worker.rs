//! The session thread: opens the hardware, runs the same session as
//! `groundcal calibrate` on a runtime of its own (so the hardware never
//! crosses threads), forwards its events, and keeps the result in the store.

use serde_json::Value;
use tokio::sync::oneshot;

use super::api::{EventJson, RunState};
use super::state::{now, AppState};
use crate::hardware;
use crate::session::{self, Event};

/// The session thread: opens the hardware, runs the session, keeps the result.
pub fn run_session(state: AppState, abort: oneshot::Receiver<String>) {
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
                    state.publish(EventJson::from(&e));
                }
            };
            tokio::join!(session, forward).0.map_err(|e| e.to_string())
        };
        // The session's own runtime beats from the moment it opens the
        // hardware: if that runtime is blocked (a stuck device call, a
        // deadlock), the beat stops and so does the systemd watchdog.
        let beat = async {
            let mut tick = tokio::time::interval(crate::systemd::heartbeat_period());
            loop {
                tick.tick().await;
                state.beat();
            }
        };
        tokio::select! {
            result = work => result,
            never = beat => never,
        }
    });
    state.clear_heartbeat();
    let result = outcome.and_then(|o| {
        serde_json::to_value(&o.result).map_err(|e| format!("cannot encode the result: {e}"))
    });
    finish(&state, result);
}

fn finish(state: &AppState, result: Result<Value, String>) {
    state.store().clear_running();
    state.take_abort();
    // The provisional charts end with the session: the result replaces them.
    state.status_mut().provisional = None;
    match result {
        Ok(value) => {
            let status_text = value
                .get("status")
                .and_then(Value::as_str)
                .unwrap_or("unknown")
                .to_string();
            match state.store().add(&value, &now()) {
                Ok(id) => {
                    let mut stored = value;
                    if let Value::Object(m) = &mut stored {
                        m.insert("id".into(), Value::String(id.clone()));
                    }
                    {
                        let mut status = state.status_mut();
                        status.result = Some(stored);
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
                        let mut status = state.status_mut();
                        status.result = Some(value);
                        status.error = Some(error.clone());
                        status.state = RunState::Idle;
                    }
                    state.publish(EventJson::Failed { error });
                }
            }
        }
        Err(error) => {
            {
                let mut status = state.status_mut();
                status.error = Some(error.clone());
                status.state = RunState::Idle;
            }
            state.publish(EventJson::Failed { error });
        }
    }
}
