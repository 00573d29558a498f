//! The daemon's state, shared by every request and the session thread: the
//! configuration, the store, the status, the live events, and the handles
//! that abort and join a running session.

use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Instant, SystemTime};

use tokio::sync::{broadcast, oneshot, watch};

use super::api::{
    ActiveRef, CheckStatus, EventJson, Interrupted, MotionPlan, MotionPlans, RunState, Status, Task,
};
use super::preview::{PreviewThread, ViewSlot};
use crate::formats::store::Store;
use crate::hardware::Selection;
use crate::setup::config::Config;
use crate::setup::schedule::Schedule;

/// How many recent events the status keeps.
const RECENT: usize = 30;

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
    /// The latest picture of what the camera sees.
    view: Arc<Mutex<ViewSlot>>,
    /// The thread taking pictures while no session runs.
    preview: Mutex<Option<PreviewThread>>,
    /// One-use tickets for the operator's live stream, and when each was
    /// given ([`AppState::stream_ticket`]).
    stream_tickets: Mutex<std::collections::VecDeque<(String, Instant)>>,
}

/// How long a stream ticket may wait for its stream.
const STREAM_TICKET_LIFE: std::time::Duration = std::time::Duration::from_secs(30);
/// Tickets kept at once: a few pages reconnecting; the oldest goes first.
const STREAM_TICKETS: usize = 64;

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
        // A run cut off by a stop of the service (a kill, a crash, a power
        // cut) is said, not forgotten, at this start and every later one,
        // until a person starts the next run.
        let interrupted = store.interrupted().map(|cut| {
            let task = if cut.task == "check" {
                Task::Check
            } else {
                Task::Calibration
            };
            tracing::warn!(
                "the {} started by {} at {} was interrupted: the service stopped before it finished. The robot's own watchdog halts the body once groundcal falls silent; nothing moves until a person asks for it on the page",
                cut.task, cut.by, cut.started
            );
            Interrupted {
                by: cut.by,
                started: cut.started,
                task,
            }
        });
        // The last verdict of a check, as it was before the stop.
        let verdict = match store.last_check::<CheckStatus>() {
            Ok(verdict) => verdict,
            Err(e) => {
                tracing::warn!("cannot read the last check: {e}");
                None
            }
        };
        if let Some(v) = verdict.as_ref().filter(|v| v.outcome == "drift") {
            tracing::warn!(
                "the last check of calibration {} found drift: {}",
                v.calibration_id.as_deref().unwrap_or("?"),
                v.reasons.join("; ")
            );
        }
        let active = match store.active() {
            Ok(active) => active.as_ref().map(ActiveRef::of),
            Err(e) => {
                tracing::warn!("cannot read the active calibration: {e}");
                None
            }
        };
        let motion = motion_plans(&config, &schedule);
        let gates = config.calibration.gates;
        AppState(Arc::new(Shared {
            config,
            schedule,
            selection,
            token: token.trim().to_string(),
            store,
            status: Mutex::new(Status {
                instance: instance_number(),
                state: RunState::Idle,
                robot: "idle".into(),
                step: "idle".into(),
                gates: Some(gates),
                interrupted,
                check: verdict.clone(),
                verdict,
                active,
                motion: Some(motion),
                ..Status::default()
            }),
            events,
            heartbeat: Mutex::new(None),
            view: Arc::default(),
            preview: Mutex::new(None),
            stream_tickets: Mutex::default(),
            abort: Mutex::new(None),
            worker: Mutex::new(None),
            shutdown,
        }))
    }

    /// A snapshot of the status.
    pub fn status(&self) -> Status {
        lock(&self.0.status).at(Instant::now())
    }

    /// The status, to change it: its revision counts the change.
    pub(super) fn status_mut(&self) -> MutexGuard<'_, Status> {
        let mut status = lock(&self.0.status);
        status.revision += 1;
        status
    }

    /// Records how the hardware check at start went (shown on the page).
    pub fn set_hardware(&self, words: String) {
        self.status_mut().hardware = words;
    }

    /// Records what became of the check at the service's start.
    pub fn set_startup_check(&self, startup: super::api::StartupCheck) {
        self.status_mut().startup_check = startup;
    }

    /// Aborts a running session (if any) and waits until it has stopped the robot.
    pub async fn stop_session(&self, reason: &str) {
        if let Some(abort) = self.take_abort() {
            let _ = abort.send(reason.to_string());
        }
        let worker = lock(&self.0.worker).take();
        if let Some(worker) = worker {
            let _ = tokio::task::spawn_blocking(move || worker.join()).await;
        }
    }

    pub(super) fn config(&self) -> &Config {
        &self.0.config
    }

    pub(super) fn schedule(&self) -> &Schedule {
        &self.0.schedule
    }

    pub(super) fn selection(&self) -> &Selection {
        &self.0.selection
    }

    /// The token that writes must carry (trimmed; never empty once read).
    pub(super) fn token(&self) -> &str {
        &self.0.token
    }

    pub(super) fn store(&self) -> &Store {
        &self.0.store
    }

    /// Shows an event in the status and sends it to every live stream.
    pub(super) fn publish(&self, event: EventJson) {
        {
            let mut status = self.status_mut();
            status.apply(&event);
            if !matches!(
                event,
                EventJson::Provisional { .. } | EventJson::GroundSeen { .. }
            ) {
                status.recent_events.push_back(event.clone());
            }
            while status.recent_events.len() > RECENT {
                status.recent_events.pop_front();
            }
        }
        let _ = self.0.events.send(event);
    }

    pub(super) fn subscribe_events(&self) -> broadcast::Receiver<EventJson> {
        self.0.events.subscribe()
    }

    /// Whether the service is stopping (no new calibration may start).
    pub(super) fn is_stopping(&self) -> bool {
        *self.0.shutdown.borrow()
    }

    /// Becomes true when the service stops: the live streams end on it.
    pub(super) fn subscribe_stopping(&self) -> watch::Receiver<bool> {
        self.0.shutdown.subscribe()
    }

    pub(super) fn mark_stopping(&self) {
        let _ = self.0.shutdown.send(true);
    }

    pub(super) fn set_abort(&self, abort: oneshot::Sender<String>) {
        *lock(&self.0.abort) = Some(abort);
    }

    /// The running session's abort, taken: only one abort is ever sent.
    pub(super) fn take_abort(&self) -> Option<oneshot::Sender<String>> {
        lock(&self.0.abort).take()
    }

    /// Keeps the new session thread. The previous one has finished its
    /// session (the status went idle before a new one could start); it may
    /// still be sending its last event, so it is let go rather than joined
    /// here, where a join would block a thread of the async runtime.
    pub(super) fn replace_worker(
        &self,
        start: impl FnOnce() -> std::io::Result<std::thread::JoinHandle<()>>,
    ) -> std::io::Result<()> {
        let handle = start()?;
        let previous = lock(&self.0.worker).replace(handle);
        // Joined only if already done; otherwise it ends by itself.
        if let Some(previous) = previous.filter(|p| p.is_finished()) {
            let _ = previous.join();
        }
        Ok(())
    }

    /// Starts the live picture at rest (unless `[serve]
    /// preview_interval_ms` is 0, or it already runs).
    pub fn start_preview(&self) {
        let interval = self
            .0
            .config
            .serve
            .as_ref()
            .map_or(0, |s| s.preview_interval_ms);
        // Checked under the preview's lock: a session marks itself running
        // before it stops the preview, so the two never hold the sensor at once.
        let mut preview = lock(&self.0.preview);
        let idle = self.status_mut().state == RunState::Idle;
        if interval == 0 || preview.is_some() || !idle || self.is_stopping() {
            return;
        }
        match PreviewThread::start(
            self.0.config.clone(),
            self.0.selection.clone(),
            self.0.schedule.home,
            std::time::Duration::from_millis(interval),
            Arc::clone(&self.0.view),
        ) {
            Ok(thread) => *preview = Some(thread),
            Err(e) => tracing::warn!("cannot start the live picture: {e}"),
        }
    }

    /// Stops the live picture and waits until it has closed the sensor: a
    /// session opens it next. Blocks: call it from a thread of its own.
    pub(super) fn stop_preview(&self) {
        let running = lock(&self.0.preview).take();
        if let Some(thread) = running {
            thread.stop();
        }
    }

    /// Keeps a picture of what the camera sees (at pose `pose`, or at rest).
    pub(super) fn keep_view(&self, pose: Option<u16>, view: crate::calib::ground_view::GroundView) {
        lock(&self.0.view).keep(pose, view);
    }

    /// The latest picture, as `GET /api/view` answers.
    pub(super) fn view_json(&self) -> super::api::ViewJson {
        let live_at_rest = self
            .0
            .config
            .serve
            .as_ref()
            .is_some_and(|s| s.preview_interval_ms > 0);
        lock(&self.0.view).json(live_at_rest)
    }

    /// A run of `task` went through all its poses: how long it took since
    /// it started, for the next confirmation's "about how long".
    pub(super) fn note_run_took(&self, task: Task) {
        let mut status = self.status_mut();
        let Some(took) = status.clock.map(|c| c.started.elapsed().as_secs_f64()) else {
            return;
        };
        if let Some(motion) = status.motion.as_mut() {
            match task {
                Task::Calibration => motion.calibration.last_s = Some(took),
                Task::Check => motion.check.last_s = Some(took),
            }
        }
    }

    /// A new one-use ticket for a live stream of the operator's page (one
    /// that has shown the token): 128 bits from the kernel's random source.
    /// An `EventSource` cannot send the token itself, and a token in a URL
    /// would outlive the page in histories.
    pub(super) fn stream_ticket(&self) -> std::io::Result<String> {
        use std::io::Read;
        let mut bytes = [0u8; 16];
        std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
        let ticket: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let mut tickets = lock(&self.0.stream_tickets);
        while tickets.len() >= STREAM_TICKETS {
            tickets.pop_front();
        }
        tickets.push_back((ticket.clone(), Instant::now()));
        Ok(ticket)
    }

    /// Whether `ticket` was given and not yet used nor expired; it is used now.
    pub(super) fn take_stream_ticket(&self, ticket: &str) -> bool {
        let mut tickets = lock(&self.0.stream_tickets);
        tickets.retain(|(_, given)| given.elapsed() < STREAM_TICKET_LIFE);
        match tickets.iter().position(|(t, _)| {
            t.len() == ticket.len() && blake3::hash(t.as_bytes()) == blake3::hash(ticket.as_bytes())
        }) {
            Some(k) => {
                tickets.remove(k);
                true
            }
            None => false,
        }
    }

    /// The session's loop beats: it is alive now.
    pub(super) fn beat(&self) {
        *lock(&self.0.heartbeat) = Some(Instant::now());
    }

    /// No session runs: nothing to beat.
    pub(super) fn clear_heartbeat(&self) {
        *lock(&self.0.heartbeat) = None;
    }

    pub(super) fn last_beat(&self) -> Option<Instant> {
        *lock(&self.0.heartbeat)
    }
}

/// About how long a calibration and a check move the robot: each pose's
/// motion, settle and capture (30 frames a second), plus walking home and
/// back; at the simulator's speed when the robot is simulated.
fn motion_plans(config: &Config, schedule: &Schedule) -> MotionPlans {
    let c = &config.calibration;
    let scale = match (&config.robot.address, &config.sim) {
        (crate::setup::config::RobotAddress::Sim, Some(sim)) if sim.time_scale > 0.0 => {
            sim.time_scale
        }
        _ => 1.0,
    };
    let per_pose_s =
        (f64::from(c.motion_ms) + c.settle_ms as f64) / 1000.0 + c.frames_per_pose as f64 / 30.0;
    let plan = |poses: usize| MotionPlan {
        poses,
        about_s: (poses + 2) as f64 * per_pose_s / scale,
        simulated: scale != 1.0,
        last_s: None,
    };
    MotionPlans {
        calibration: plan(schedule.poses.len()),
        check: plan(1 + config.verify.poses),
    }
}

/// A lock that survives a panicked holder: every value kept here stays
/// valid between statements.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Now, as the API writes times (RFC 3339, seconds).
pub(super) fn now() -> String {
    humantime::format_rfc3339_seconds(SystemTime::now()).to_string()
}

/// A number that names this run of the service: its start in milliseconds
/// since the Unix epoch, times 1000, plus its process id's last three
/// digits (two starts in one millisecond, or a clock before the epoch,
/// still differ). Below 2⁵³ until the year 2255: exact in a page's numbers.
fn instance_number() -> u64 {
    let millis = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |since| since.as_millis() as u64);
    millis.saturating_mul(1000) + u64::from(std::process::id() % 1000)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Duration;

    /// Starting a session never waits for the previous session's thread:
    /// a join there would block a thread of the async runtime (here the
    /// previous thread cannot end until after the new one is kept).
    #[test]
    fn a_new_session_thread_is_kept_without_joining_the_previous_one() {
        let dir = std::env::temp_dir().join(format!("groundcal-state-{}", std::process::id()));
        let (config, schedule) = Config::embedded_sim();
        let state = AppState::new(config, schedule, Selection::default(), "t".into(), &dir);
        let (release, released) = mpsc::channel::<()>();
        state
            .replace_worker(|| {
                std::thread::Builder::new().spawn(move || {
                    let _ = released.recv();
                })
            })
            .unwrap();
        let (done, finished) = mpsc::channel();
        let replacing = state.clone();
        std::thread::spawn(move || {
            let kept = replacing.replace_worker(|| std::thread::Builder::new().spawn(|| {}));
            let _ = done.send(kept.is_ok());
        });
        let kept = finished.recv_timeout(Duration::from_secs(10));
        let _ = release.send(());
        assert_eq!(
            kept,
            Ok(true),
            "the new session thread waited for the previous one"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Each change of the status counts: a page orders its answers by the
    /// count (`revision`), within one run of the service (`instance`), and
    /// reading the status changes neither.
    #[test]
    fn the_status_counts_its_changes_and_reading_it_does_not() {
        let dir = std::env::temp_dir().join(format!("groundcal-revision-{}", std::process::id()));
        let (config, schedule) = Config::embedded_sim();
        let state = AppState::new(config, schedule, Selection::default(), "t".into(), &dir);
        let first = state.status();
        assert_eq!(state.status().revision, first.revision);
        state.publish(EventJson::Aborting { by: "pad".into() });
        let aborting = state.status();
        assert!(aborting.revision > first.revision);
        state.publish(EventJson::WalkingHome);
        let later = state.status();
        assert!(later.revision > aborting.revision);
        assert_eq!(later.instance, first.instance);
        assert!(first.instance > 1_700_000_000_000_000, "{}", first.instance);
        assert!(first.instance < 1 << 53, "{}", first.instance);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
