//! The calibration store: the active calibration that the robot's other
//! programs read, and the history of every result.
//!
//! Layout under the state directory (`/var/lib/groundcal` on the robot):
//!
//! ```text
//! active.json               the active calibration (format below)
//! history/<id>.json         every result ever made, accepted or not
//! running.json              a run (calibration or check) in progress, or
//!                           one that a stop cut off: kept until a person
//!                           starts the next one
//! check.json                the last check of a calibration that reached a
//!                           verdict (consistent or drift)
//! ```
//!
//! `active.json` is `{"format": "groundcal-active", "version": 1, "id": ...,
//! "activated": RFC 3339, "kinect_tilt_deg": ..., "robot_from_sensor": {...},
//! "sigma": {...}, "status": "accepted", "summary", "depth_scale",
//! "correlations", "created", "robot"}` with the keys of the result document
//! (cli.md): [`ActiveDocument`]. A history entry is the result document with
//! its `id`, `created` and an operator's rejection: [`StoredResult`]. Both
//! are serde types, read and written as such. Readers take `robot_from_sensor` and check
//! `kinect_tilt_deg` against the Kinect's tilt: a calibration holds for one
//! tilt. Every write goes to a temporary file of its own that is fsynced,
//! renamed over the old one, and the directory fsynced: a reader sees the old
//! file or the new one, never half of one, even across a power cut.
//!
//! Writers take turns: every change (add, accept or roll back, reject) holds
//! the store's lock from reading to writing, a mutex for this process's
//! threads and an exclusive `flock` on `store.lock` for other processes (the
//! kernel releases it when a process dies, even by SIGKILL). So two taps on
//! Accept, or two phones, cannot interleave, and the reply names what was
//! stored. Temporary files left by a process killed while saving are removed
//! when the daemon starts ([`Store::remove_stale_temporaries`]).

use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use serde::{Deserialize, Serialize};

use crate::formats::output::{
    MountJson, ResultJson, ResultStatus, RobotJson, SigmaJson, SummaryJson,
};

/// Why the store could not do something.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{}: {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error(transparent)]
    Write(#[from] crate::platform::files::FileError),
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
    #[error("no calibration {0} in the history")]
    NotFound(String),
    #[error("calibration {0} was rejected and cannot be made active")]
    Rejected(String),
    #[error("calibration {0} is the active one; roll back to another first")]
    Active(String),
}

fn io<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> StoreError + 'a {
    move |source| StoreError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
}

/// A directory's listing, or `None` when it does not exist (yet).
fn list(dir: &Path) -> Result<Option<fs::ReadDir>, StoreError> {
    match fs::read_dir(dir) {
        Ok(listing) => Ok(Some(listing)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(StoreError::Io {
            path: dir.to_path_buf(),
            action: "cannot list",
            source: e,
        }),
    }
}

/// The store's writers in this process, one at a time.
static WRITERS: Mutex<()> = Mutex::new(());

/// Held while a change is made: this process's turn, and the lock file's.
struct WriteTurn {
    _file: File,
    _turn: MutexGuard<'static, ()>,
}

/// A result kept in the history (`history/<id>.json`): the result document
/// (cli.md) with its id, when it was made, and an operator's rejection.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StoredResult {
    pub id: String,
    /// When it was made (RFC 3339).
    pub created: String,
    /// Set aside by an operator (`reject`), with its status before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator_rejection: Option<OperatorRejection>,
    /// It was the active calibration until another was made active (the
    /// last time it was replaced).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replaced: Option<Replacement>,
    #[serde(flatten)]
    pub result: ResultJson,
}

/// When, by whom and by which calibration an active calibration was replaced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Replacement {
    pub at: String,
    pub by: String,
    /// The calibration made active in its place.
    pub by_id: String,
}

/// An operator's rejection of a result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatorRejection {
    pub at: String,
    pub by: String,
    pub status_before: ResultStatus,
}

/// `active.json`: the calibration the robot's other programs read. The keys
/// of the result document that say where the sensor is and how sure that
/// is, with the store's id and when it was made active.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ActiveDocument {
    /// `groundcal-active`.
    pub format: String,
    /// 1.
    pub version: u32,
    pub id: String,
    /// When it was made active (RFC 3339).
    pub activated: String,
    /// Always `accepted`: nothing else becomes active.
    pub status: ResultStatus,
    pub robot_from_sensor: MountJson,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaJson>,
    /// The Kinect's motor tilt the calibration holds for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinect_tilt_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<SummaryJson>,
    /// The depth scale found (1 when it was not estimated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correlations: Option<[[f64; 6]; 6]>,
    /// When the calibration was made (RFC 3339).
    #[serde(default)]
    pub created: String,
    /// The robot it was made for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<RobotJson>,
    /// The Kinect's depth pattern it corrected, which checks against it
    /// take out of their frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_pattern: Option<crate::formats::output::DepthPatternJson>,
}

/// `running.json`: who started the run in progress, when, and what it
/// was (`calibration` or `check`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunningMarker {
    pub by: String,
    pub started: String,
    /// Markers written before checks had them were calibrations'.
    #[serde(default = "calibration")]
    pub task: String,
}

fn calibration() -> String {
    "calibration".into()
}

/// The largest file of the store read (a result with its pattern's cells is
/// about 100 kB): anything larger is not the store's.
const MAX_STORE_FILE_BYTES: u64 = 16 << 20;

/// A file of the store, read with a bound and only as a regular file; None
/// when it does not exist.
fn read_store_file(path: &Path) -> Result<Option<String>, StoreError> {
    use crate::platform::files::ReadError;
    let mut bytes = Vec::new();
    match crate::platform::files::read_bounded_into(path, MAX_STORE_FILE_BYTES, &mut bytes) {
        Ok(()) => {}
        Err(ReadError::File(f)) if f.source.kind() == std::io::ErrorKind::NotFound => {
            return Ok(None)
        }
        Err(ReadError::File(f)) => {
            return Err(StoreError::Io {
                path: path.to_path_buf(),
                action: f.action,
                source: f.source,
            })
        }
        Err(e @ ReadError::TooLarge { .. }) => {
            return Err(StoreError::Invalid {
                path: path.to_path_buf(),
                message: e.to_string(),
            })
        }
    }
    String::from_utf8(bytes)
        .map(Some)
        .map_err(|_| StoreError::Invalid {
            path: path.to_path_buf(),
            message: "not UTF-8 text".into(),
        })
}

/// One entry of the history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    pub id: String,
    pub status: String,
    pub created: String,
    pub active: bool,
    /// Rejected by an operator (`reject`), not by its checks.
    #[serde(default)]
    pub operator_rejected: bool,
    /// It was active until another was made active (when, by whom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replaced: Option<Replacement>,
}

/// The store in a state directory.
#[derive(Debug, Clone)]
pub struct Store {
    dir: PathBuf,
}

impl Store {
    /// The store in `dir` (created on first write).
    pub fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
        }
    }

    pub fn active_path(&self) -> PathBuf {
        self.dir.join("active.json")
    }

    fn history_dir(&self) -> PathBuf {
        self.dir.join("history")
    }

    /// Waits for the store's turn: every other writer, in this process or
    /// another, has finished.
    fn turn(&self) -> Result<WriteTurn, StoreError> {
        // A writer that panicked left nothing half-written (writes are atomic).
        let turn = WRITERS
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        fs::create_dir_all(&self.dir).map_err(io(&self.dir, "cannot create the directory"))?;
        let path = self.dir.join("store.lock");
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(io(&path, "cannot open the lock file"))?;
        file.lock().map_err(io(&path, "cannot lock"))?;
        Ok(WriteTurn {
            _file: file,
            _turn: turn,
        })
    }

    /// Removes the temporary files of writes that never finished (a process
    /// killed while saving), and returns how many. The daemon calls it at
    /// start; it waits for the store's turn, so no write in progress is hit.
    pub fn remove_stale_temporaries(&self) -> Result<usize, StoreError> {
        let _turn = self.turn()?;
        let mut removed = 0;
        for dir in [self.dir.clone(), self.history_dir()] {
            let Some(listing) = list(&dir)? else {
                continue;
            };
            for item in listing {
                let item = item.map_err(io(&dir, "cannot list"))?;
                let name = item.file_name().to_string_lossy().into_owned();
                if crate::platform::files::is_temporary(&name) {
                    let path = item.path();
                    fs::remove_file(&path).map_err(io(&path, "cannot remove"))?;
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }

    fn entry_path(&self, id: &str) -> Result<PathBuf, StoreError> {
        // Ids are ours (a timestamp and a counter); refuse anything that could
        // name a file outside the history.
        if id.is_empty()
            || !id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(StoreError::NotFound(id.to_string()));
        }
        Ok(self.history_dir().join(format!("{id}.json")))
    }

    /// The marker of a calibration in progress (`running.json`): written
    /// when one starts, removed when it ends. Found at start, it says that the
    /// service stopped (a kill, a crash, a power cut) while one was running.
    fn running_path(&self) -> PathBuf {
        self.dir.join("running.json")
    }

    /// Marks a run (`task`: `calibration` or `check`) as running: who
    /// started it and when. It replaces the marker of a run that a stop cut
    /// off: a person has now started the next one.
    pub fn mark_running(&self, by: &str, started: &str, task: &str) -> Result<(), StoreError> {
        let marker = RunningMarker {
            by: by.to_string(),
            started: started.to_string(),
            task: task.to_string(),
        };
        let bytes = serde_json::to_vec(&marker).map_err(|e| StoreError::Invalid {
            path: self.running_path(),
            message: e.to_string(),
        })?;
        crate::platform::files::write_atomically(&self.running_path(), &bytes)?;
        Ok(())
    }

    /// The run has ended, whatever its outcome (or a person has seen that
    /// it was cut off and started the next). Durable: a marker that came back
    /// after a power cut would hold the robot for nothing, one that vanished
    /// early would let it move with nobody there.
    pub fn clear_running(&self) {
        if fs::remove_file(self.running_path()).is_ok() {
            let _ = File::open(&self.dir).and_then(|d| d.sync_all());
        }
    }

    /// The run that was in progress when the service last stopped, if any.
    /// It is not removed: it stays, through any number of restarts, until a
    /// person starts the next run ([`Store::mark_running`]).
    pub fn interrupted(&self) -> Option<RunningMarker> {
        // A marker that cannot be read still says that a run was cut off.
        let unreadable = || RunningMarker {
            by: "?".into(),
            started: "?".into(),
            task: calibration(),
        };
        match read_store_file(&self.running_path()) {
            Ok(None) => None,
            Ok(Some(text)) => Some(serde_json::from_str(&text).unwrap_or_else(|_| unreadable())),
            Err(_) => Some(unreadable()),
        }
    }

    /// `check.json`: the last check that reached a verdict.
    fn check_path(&self) -> PathBuf {
        self.dir.join("check.json")
    }

    /// Keeps the last check that reached a verdict (the caller's document:
    /// the store does not look into it), atomically: a knock found before a
    /// crash is still known after it.
    pub fn save_check<T: Serialize>(&self, check: &T) -> Result<(), StoreError> {
        let bytes = serde_json::to_vec_pretty(check).map_err(|e| StoreError::Invalid {
            path: self.check_path(),
            message: e.to_string(),
        })?;
        crate::platform::files::write_atomically(&self.check_path(), &bytes)?;
        Ok(())
    }

    /// The last check kept by [`Store::save_check`], if any.
    pub fn last_check<T: serde::de::DeserializeOwned>(&self) -> Result<Option<T>, StoreError> {
        let path = self.check_path();
        let Some(text) = read_store_file(&path)? else {
            return Ok(None);
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| StoreError::Invalid {
                path,
                message: e.to_string(),
            })
    }

    /// Keeps a result in the history and returns its id.
    pub fn add(&self, result: &ResultJson, created: &str) -> Result<String, StoreError> {
        let _turn = self.turn()?;
        let stamp: String = created.chars().filter(|c| c.is_ascii_digit()).collect();
        let mut n = 1;
        let id = loop {
            let id = format!("{stamp}-{n}");
            if !self.entry_path(&id)?.exists() {
                break id;
            }
            n += 1;
        };
        let entry = StoredResult {
            id: id.clone(),
            created: created.to_string(),
            operator_rejection: None,
            replaced: None,
            result: result.clone(),
        };
        let bytes = serde_json::to_vec_pretty(&entry).map_err(|e| StoreError::Invalid {
            path: self.history_dir(),
            message: e.to_string(),
        })?;
        crate::platform::files::write_atomically(&self.entry_path(&id)?, &bytes)?;
        Ok(id)
    }

    /// A result of the history.
    pub fn get(&self, id: &str) -> Result<StoredResult, StoreError> {
        let path = self.entry_path(id)?;
        let text = read_store_file(&path)?.ok_or_else(|| StoreError::NotFound(id.to_string()))?;
        serde_json::from_str(&text).map_err(|e| StoreError::Invalid {
            path,
            message: e.to_string(),
        })
    }

    /// The active calibration, if any.
    pub fn active(&self) -> Result<Option<ActiveDocument>, StoreError> {
        let path = self.active_path();
        let Some(text) = read_store_file(&path)? else {
            return Ok(None);
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| StoreError::Invalid {
                path,
                message: e.to_string(),
            })
    }

    /// Makes a result of the history the active calibration (accept, or roll
    /// back to an earlier one), at `now` by `by`. Rejected results never
    /// become active. The calibration it replaces is marked so in the
    /// history ([`StoredResult::replaced`]): a page that still shows it must
    /// not offer to make it active as if it never had been.
    pub fn activate(&self, id: &str, now: &str, by: &str) -> Result<ActiveDocument, StoreError> {
        let _turn = self.turn()?;
        let entry = self.get(id)?;
        let previous = self.active()?.map(|a| a.id).filter(|p| p != id);
        let result = entry.result;
        let mount = match (result.status, result.robot_from_sensor) {
            (ResultStatus::Accepted, Some(mount)) => mount,
            _ => return Err(StoreError::Rejected(id.to_string())),
        };
        let active = ActiveDocument {
            format: "groundcal-active".into(),
            version: 1,
            id: id.to_string(),
            activated: now.to_string(),
            status: ResultStatus::Accepted,
            robot_from_sensor: mount,
            sigma: result.sigma,
            kinect_tilt_deg: result.kinect_tilt_deg,
            summary: result.summary,
            depth_scale: result.depth_scale,
            correlations: result.correlations,
            created: entry.created,
            robot: result.robot,
            depth_pattern: result.depth_pattern.filter(|p| p.corrected),
        };
        let bytes = serde_json::to_vec_pretty(&active).map_err(|e| StoreError::Invalid {
            path: self.active_path(),
            message: e.to_string(),
        })?;
        crate::platform::files::write_atomically(&self.active_path(), &bytes)?;
        if let Some(previous) = previous {
            // Said in the history after the switch: a kill in between leaves
            // the right calibration active and only this remark missing.
            if let Ok(mut replaced) = self.get(&previous) {
                replaced.replaced = Some(Replacement {
                    at: now.to_string(),
                    by: by.to_string(),
                    by_id: id.to_string(),
                });
                let bytes =
                    serde_json::to_vec_pretty(&replaced).map_err(|e| StoreError::Invalid {
                        path: self.history_dir(),
                        message: e.to_string(),
                    })?;
                crate::platform::files::write_atomically(&self.entry_path(&previous)?, &bytes)?;
            }
        }
        Ok(active)
    }

    /// Marks a result of the history as rejected by the operator (`by`), with
    /// its status before; nothing is deleted. The active calibration cannot be
    /// rejected: roll back to another first.
    pub fn reject(&self, id: &str, now: &str, by: &str) -> Result<StoredResult, StoreError> {
        let _turn = self.turn()?;
        let mut entry = self.get(id)?;
        if self.active()?.is_some_and(|a| a.id == id) {
            return Err(StoreError::Active(id.to_string()));
        }
        entry.operator_rejection = Some(OperatorRejection {
            at: now.to_string(),
            by: by.to_string(),
            status_before: entry.result.status,
        });
        entry.result.status = ResultStatus::Rejected;
        let path = self.entry_path(id)?;
        let bytes = serde_json::to_vec_pretty(&entry).map_err(|e| StoreError::Invalid {
            path: path.clone(),
            message: e.to_string(),
        })?;
        crate::platform::files::write_atomically(&path, &bytes)?;
        Ok(entry)
    }

    /// The history, newest first.
    pub fn history(&self) -> Result<Vec<HistoryEntry>, StoreError> {
        let dir = self.history_dir();
        let active_id = self.active()?.map(|a| a.id);
        let mut entries = Vec::new();
        let Some(listing) = list(&dir)? else {
            return Ok(entries);
        };
        for item in listing {
            let item = item.map_err(io(&dir, "cannot list"))?;
            let name = item.file_name().to_string_lossy().into_owned();
            let Some(id) = name.strip_suffix(".json") else {
                continue;
            };
            if name.starts_with('.') {
                continue;
            }
            let Ok(stored) = self.get(id) else { continue };
            entries.push(HistoryEntry {
                id: id.to_string(),
                status: stored.result.status.as_str().to_string(),
                created: stored.created,
                active: active_id.as_deref() == Some(id),
                operator_rejected: stored.operator_rejection.is_some(),
                replaced: stored.replaced,
            });
        }
        entries.sort_by(|a, b| b.id.cmp(&a.id));
        Ok(entries)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A result document with this status and α.
    fn result(status: &str, alpha_deg: f64) -> ResultJson {
        let pose = crate::calib::geometry::PoseDegMm::from_values([
            alpha_deg, -33.0, 0.0, 500.0, 370.0, 0.0,
        ]);
        ResultJson::parse(serde_json::json!({
            "status": status,
            "robot_from_sensor": MountJson::from_params(&pose.to_params()),
        }))
        .unwrap()
    }

    fn temp_store(tag: &str) -> (Store, PathBuf) {
        let dir =
            std::env::temp_dir().join(format!("groundcal-store-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        (Store::new(&dir), dir)
    }

    #[test]
    fn accept_roll_back_and_refuse_rejected() {
        let (store, dir) = temp_store("cycle");
        let a = store
            .add(&result("accepted", 1.0), "2026-11-23T20:00:00Z")
            .unwrap();
        let b = store
            .add(&result("accepted", 2.0), "2026-11-23T21:00:00Z")
            .unwrap();
        let r = store
            .add(&result("rejected", 3.0), "2026-11-23T22:00:00Z")
            .unwrap();
        assert!(store.active().unwrap().is_none());
        store.activate(&b, "now", "t").unwrap();
        assert_eq!(
            store.active().unwrap().unwrap().robot_from_sensor.alpha_deg,
            2.0
        );
        store.activate(&a, "later", "t").unwrap();
        assert_eq!(store.active().unwrap().unwrap().id, a);
        assert!(matches!(
            store.activate(&r, "x", "t"),
            Err(StoreError::Rejected(_))
        ));
        assert_eq!(
            store.active().unwrap().unwrap().id,
            a,
            "a refused activation leaves the active one"
        );
        let history = store.history().unwrap();
        assert_eq!(history.len(), 3);
        assert_eq!(history.iter().filter(|h| h.active).count(), 1);
        // No temporary files are left behind.
        assert!(fs::read_dir(&dir).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .starts_with('.')));
        let _ = fs::remove_dir_all(&dir);
    }

    /// A run cut off stays said through any number of restarts (each a new
    /// `Store` reading it), until a person starts the next run.
    #[test]
    fn an_interrupted_run_is_remembered_until_the_next_one_starts() {
        let (store, dir) = temp_store("interrupted");
        assert!(store.interrupted().is_none());
        store
            .mark_running("phone (10.0.0.7)", "2026-12-04T10:00:00Z", "calibration")
            .unwrap();
        for _restart in 0..3 {
            let again = Store::new(&dir);
            let cut = again.interrupted().expect("still interrupted");
            assert_eq!(cut.by, "phone (10.0.0.7)");
            assert_eq!(cut.task, "calibration");
        }
        store
            .mark_running("pad (10.0.0.8)", "2026-12-04T11:00:00Z", "check")
            .unwrap();
        assert_eq!(store.interrupted().unwrap().task, "check");
        store.clear_running();
        assert!(Store::new(&dir).interrupted().is_none());
        let _ = fs::remove_dir_all(&dir);
    }

    /// A calibration replaced by another (a rollback) says so in the
    /// history: when, by whom, by which.
    #[test]
    fn the_calibration_a_rollback_replaces_is_marked_replaced() {
        let (store, dir) = temp_store("replaced");
        let a = store
            .add(&result("accepted", 1.0), "2026-11-23T20:00:00Z")
            .unwrap();
        let b = store
            .add(&result("accepted", 2.0), "2026-11-23T21:00:00Z")
            .unwrap();
        store.activate(&b, "2026-11-24T08:00:00Z", "phone").unwrap();
        assert!(store.get(&b).unwrap().replaced.is_none());
        store
            .activate(&a, "2026-11-24T09:00:00Z", "pad (10.0.0.8)")
            .unwrap();
        let replaced = store.get(&b).unwrap().replaced.unwrap();
        assert_eq!(
            (
                replaced.at.as_str(),
                replaced.by.as_str(),
                replaced.by_id.as_str()
            ),
            ("2026-11-24T09:00:00Z", "pad (10.0.0.8)", a.as_str())
        );
        let history = store.history().unwrap();
        assert!(history.iter().any(|h| h.id == b && h.replaced.is_some()));
        assert!(history.iter().any(|h| h.id == a && h.replaced.is_none()));
        let _ = fs::remove_dir_all(&dir);
    }

    /// The last check's document survives a restart, as written.
    #[test]
    fn the_last_check_is_kept() {
        let (store, dir) = temp_store("check");
        assert!(store.last_check::<serde_json::Value>().unwrap().is_none());
        let check = serde_json::json!({"calibration_id": "20261204-1", "outcome": "drift"});
        store.save_check(&check).unwrap();
        let read: serde_json::Value = Store::new(&dir).last_check().unwrap().unwrap();
        assert_eq!(read, check);
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn ids_cannot_escape_the_history() {
        let (store, dir) = temp_store("escape");
        assert!(matches!(
            store.get("../active"),
            Err(StoreError::NotFound(_))
        ));
        assert!(matches!(
            store.activate("/etc/passwd", "x", "t"),
            Err(StoreError::NotFound(_))
        ));
        let _ = fs::remove_dir_all(&dir);
    }
}
