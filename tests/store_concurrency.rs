//! The calibration store under concurrent writers and kills: `active.json`,
//! which every other program on the robot reads, is always a complete old or
//! complete new file; every reply names what was stored; a kill while saving
//! leaves temporaries that the next start removes.
//!
//! Other processes are this test binary run again in the writer's role
//! (`writer_process`, which does nothing unless the environment asks for it).

use std::path::Path;

mod common;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Barrier};
use std::time::Duration;

use groundcal::formats::store::Store;
use rand::{Rng, SeedableRng};
use serde_json::{json, Value};

/// The environment variable that puts this binary in the writer's role: the
/// store's directory, the two ids, and how many changes (0: until killed).
const CHILD: &str = "GROUNDCAL_STORE_WRITER";

fn temp_dir(tag: &str) -> common::TempDir {
    common::temp_dir(&format!("store-{tag}"))
}

/// An accepted result with this α.
fn accepted(alpha_deg: f64) -> groundcal::formats::output::ResultJson {
    groundcal::formats::output::ResultJson::parse(json!({
        "status": "accepted",
        "robot_from_sensor": groundcal::formats::output::MountJson::from_params(
            &groundcal::calib::geometry::PoseDegMm::from_values([alpha_deg, -33.0, 0.0, 500.0, 370.0, 0.0])
                .to_params(),
        ),
    }))
    .unwrap()
}

/// A store with two accepted calibrations, and their ids.
fn store_with_two(dir: &Path) -> (Store, String, String) {
    let store = Store::new(dir);
    let a = store.add(&accepted(1.0), "2026-12-01T10:00:00Z").unwrap();
    let b = store.add(&accepted(2.0), "2026-12-01T11:00:00Z").unwrap();
    (store, a, b)
}

/// What a reader of `active.json` sees: nothing yet, or a complete active
/// calibration of one of the ids. Anything else is a failure, named.
fn check_active(path: &Path, ids: &[&str]) -> Result<(), String> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(format!("cannot read: {e}")),
    };
    let value: Value = serde_json::from_slice(&bytes)
        .map_err(|e| format!("not JSON ({e}): {} bytes", bytes.len()))?;
    let id = value["id"].as_str().unwrap_or_default();
    if value["format"] != "groundcal-active" || !ids.contains(&id) {
        return Err(format!("not an active calibration of {ids:?}: {value}"));
    }
    Ok(())
}

fn temporaries(dir: &Path) -> usize {
    [dir.to_path_buf(), dir.join("history")]
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flatten()
        .filter(|e| {
            let name = e
                .as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .into_owned();
            name.starts_with('.') && name.contains(".tmp-")
        })
        .count()
}

/// Starts this binary as a writer: `changes` activations alternating between
/// the two ids (0: until killed).
fn spawn_writer(dir: &Path, a: &str, b: &str, changes: usize) -> Child {
    Command::new(std::env::current_exe().unwrap())
        .args([
            "writer_process",
            "--exact",
            "--nocapture",
            "--test-threads",
            "1",
        ])
        .env(CHILD, format!("{}|{a}|{b}|{changes}", dir.display()))
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap()
}

/// The writer's role (a no-op in an ordinary test run).
#[test]
fn writer_process() {
    let Ok(spec) = std::env::var(CHILD) else {
        return;
    };
    let parts: Vec<&str> = spec.split('|').collect();
    let store = Store::new(Path::new(parts[0]));
    let changes: usize = parts[3].parse().unwrap();
    let mut n = 0;
    while changes == 0 || n < changes {
        let id = parts[1 + n % 2];
        let stored = store.activate(id, "by another process", "a test").unwrap();
        assert_eq!(stored.id, id);
        n += 1;
    }
}

#[test]
fn simultaneous_accepts_and_rollbacks_never_corrupt_the_active_calibration() {
    let dir = temp_dir("simultaneous");
    let (store, a, b) = store_with_two(&dir);
    let active = store.active_path();
    let ids = [a.clone(), b.clone()];
    let done = Arc::new(AtomicBool::new(false));
    let reads = Arc::new(AtomicUsize::new(0));

    // A reader, as the robot's other programs are, polling all the while.
    let reader = {
        let (done, reads, active, ids) = (done.clone(), reads.clone(), active.clone(), ids.clone());
        std::thread::spawn(move || -> Result<(), String> {
            let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
            while !done.load(Ordering::Relaxed) {
                check_active(&active, &ids)?;
                reads.fetch_add(1, Ordering::Relaxed);
            }
            Ok(())
        })
    };
    // Two other processes writing at the same time.
    let children: Vec<Child> = (0..2).map(|_| spawn_writer(&dir, &a, &b, 150)).collect();

    // 300 pairs of simultaneous writes in this process: one thread accepts
    // one calibration while the other rolls back to the other.
    let pairs = 300;
    let barrier = Arc::new(Barrier::new(2));
    let writers: Vec<_> = [a.clone(), b.clone()]
        .into_iter()
        .map(|id| {
            let (store, barrier) = (store.clone(), barrier.clone());
            std::thread::spawn(move || -> Result<(), String> {
                for _ in 0..pairs {
                    barrier.wait();
                    let stored = store
                        .activate(&id, "now", "a test")
                        .map_err(|e| e.to_string())?;
                    if stored.id != id {
                        return Err(format!("asked for {id}, the reply names {}", stored.id));
                    }
                }
                Ok(())
            })
        })
        .collect();
    for writer in writers {
        writer.join().unwrap().unwrap();
    }
    for mut child in children {
        assert!(child.wait().unwrap().success(), "a writer process failed");
    }
    done.store(true, Ordering::Relaxed);
    reader.join().unwrap().unwrap();
    let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
    check_active(&active, &ids).unwrap();
    assert_eq!(temporaries(&dir), 0, "temporary files were left behind");
    println!(
        "{pairs} simultaneous pairs here and 2 × 150 writes in other processes: {} reads, all complete",
        reads.load(Ordering::Relaxed)
    );
    assert!(reads.load(Ordering::Relaxed) > 100);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_kill_while_saving_leaves_the_old_or_the_new_file_and_a_start_cleans_up() {
    let dir = temp_dir("killed");
    let (store, a, b) = store_with_two(&dir);
    store.activate(&a, "first", "a test").unwrap();
    let ids = [a.as_str(), b.as_str()];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut left = 0;
    let kills = 200;
    for _ in 0..kills {
        let mut child = spawn_writer(&dir, &a, &b, 0);
        std::thread::sleep(Duration::from_micros(rng.gen_range(2_000..25_000)));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        check_active(&store.active_path(), &ids).unwrap();
        left = left.max(temporaries(&dir));
    }
    // The next start removes what the kills left; the store works on.
    let removed = store.remove_stale_temporaries().unwrap();
    assert_eq!(temporaries(&dir), 0);
    store.activate(&b, "after the kills", "a test").unwrap();
    assert_eq!(store.active().unwrap().unwrap().id, b);
    println!("{kills} kills while saving: every read complete; {removed} temporaries removed at the start (at most {left} at once)");
    let _ = std::fs::remove_dir_all(&dir);
}
