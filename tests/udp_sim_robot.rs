//! The upper computer's UDP link (`groundcal_hal::udp`) against the simulated
//! lower computer in a separate process (`groundcal sim-robot`), over
//! loopback, through 20 % loss each way, 5 % duplicates, 5 % reordering and
//! up to 20 ms of delay: all 52 poses of `octopus-52` are visited, each
//! SET_POSE is one new request whose retransmissions reuse its `seq` (the
//! simulated robot's receipts log says so), the robot settles at every pose,
//! a restart of the lower computer after pose 20 is recovered without help,
//! and the watchdog never fires.
//!
//! The same scenarios also run against the simulated lower computer on a
//! thread of this process, with its own runtime and socket.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::ffi::OsStr;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use groundcal::setup::schedule::{Limits, Schedule};
use groundcal_hal::sim::lower_computer::{
    FaultInjection, SimOptions, SimServer, FAULTS_ENV, RECEIPTS_ENV,
};
use groundcal_hal::udp::client::ClientStats;
use groundcal_hal::udp::{LinkConfig, UdpBodyController};
use groundcal_hal::{BodyController, MotionState};
use serde_json::Value;

const FAULTS: &str = "loss=0.2,dup=0.05,reorder=0.05,delay_ms=20,seed=3";
const SEED: u64 = 7;
/// Motions of 2 s take 20 ms.
const TIME_SCALE: f64 = 100.0;
const MOTION_MS: u32 = 2000;
/// GET_STATE polling while waiting for a pose (the caller's; the link adds
/// keep-alives of its own).
const POLL: Duration = Duration::from_millis(20);

fn schedule() -> Schedule {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/schedules/octopus-52.toml");
    Schedule::read(&path).expect("the schedule reads")
}

fn receipts_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-receipts.jsonl"))
}

/// The simulated lower computer, as a process or on a thread.
enum Robot {
    Process(Child),
    Thread {
        stop: tokio::sync::oneshot::Sender<()>,
        thread: std::thread::JoinHandle<()>,
    },
}

impl Robot {
    /// `groundcal sim-robot` on a free loopback port.
    fn process(faults: &str, receipts: &Path) -> (Self, SocketAddr) {
        let (seed, time_scale) = (SEED.to_string(), TIME_SCALE.to_string());
        let (child, address) = common::spawn_sim_robot(
            &["--seed", &seed, "--time-scale", &time_scale],
            &[
                (FAULTS_ENV, OsStr::new(faults)),
                (RECEIPTS_ENV, receipts.as_os_str()),
            ],
        );
        (Robot::Process(child), address.parse().expect("an address"))
    }

    /// The same server on a thread with its own runtime.
    fn thread(faults: &str, receipts: &Path) -> (Self, SocketAddr) {
        let options = SimOptions {
            faults: FaultInjection::parse(faults).expect("faults parse"),
            receipts: Some(receipts.to_path_buf()),
            ..SimOptions::new(SEED, TIME_SCALE)
        };
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let (bound, address) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("a runtime");
            runtime.block_on(async move {
                let server = SimServer::bind("127.0.0.1:0".parse().unwrap(), options)
                    .await
                    .expect("binds");
                bound.send(server.local_addr()).expect("the test waits");
                server
                    .run(async {
                        let _ = stopped.await;
                    })
                    .await
                    .expect("serves");
            });
        });
        let address = address.recv().expect("the server binds");
        (Robot::Thread { stop, thread }, address)
    }

    /// Stops the server (SIGTERM for the process) and waits for it.
    fn stop(self) {
        match self {
            Robot::Process(child) => {
                common::stop_sim_robot(child);
            }
            Robot::Thread { stop, thread } => {
                let _ = stop.send(());
                thread.join().expect("the server thread ends cleanly");
            }
        }
    }
}

/// What a calibration's robot side does: HELLO, the schedule checked against
/// the WELCOME's limits, home, every pose until settled, home, BYE.
async fn visit_schedule(address: SocketAddr, schedule: &Schedule) -> ClientStats {
    // 30 retries: at 20 % loss each way an exchange fails with p = 0.36;
    // the default 10 would lose the link in about one run of 250.
    let mut link = LinkConfig::new(address);
    link.client.retry_limit = 30;
    let mut c = UdpBodyController::connect(&link)
        .await
        .expect("the link opens");
    let welcome = c.hello().await.expect("HELLO is answered");
    let limits = Limits {
        max_tilt_deg: welcome.limits.max_tilt_deg,
        min_height_mm: welcome.limits.min_height_mm,
        max_height_mm: welcome.limits.max_height_mm,
        max_shift_mm: welcome.limits.max_shift_mm,
    };
    schedule
        .validate(&limits)
        .expect("octopus-52 is within the limits");
    c.home(MOTION_MS).await.expect("HOME");
    let home = c
        .wait_while_moving(POLL, Duration::from_secs(5))
        .await
        .expect("home");
    assert_eq!(home.state, MotionState::Idle);
    for (k, pose) in schedule.poses.iter().enumerate() {
        let id = (k + 1) as u16;
        c.set_pose(id, pose, MOTION_MS)
            .await
            .unwrap_or_else(|e| panic!("pose {id}: {e}"));
        let state = c
            .wait_while_moving(POLL, Duration::from_secs(5))
            .await
            .unwrap_or_else(|e| panic!("pose {id}: {e}"));
        assert_eq!(
            (state.state, state.pose_id),
            (MotionState::Settled, id),
            "pose {id}"
        );
    }
    c.home(MOTION_MS).await.expect("HOME");
    let home = c
        .wait_while_moving(POLL, Duration::from_secs(5))
        .await
        .expect("home");
    assert_eq!(home.state, MotionState::Idle);
    c.bye().await.expect("BYE");
    c.link().stats()
}

/// What the robot received of one pose's SET_POSEs.
#[derive(Debug, Default)]
struct SetPoseReceipts {
    /// The (life, seq) of every copy in a known session.
    seqs: BTreeSet<(u64, u64)>,
    /// Copies taken as new requests.
    new: usize,
    /// New requests accepted (ACK 0): acted on.
    accepted: usize,
}

/// The simulated robot's receipts log, read back.
struct Receipts {
    lines: Vec<Value>,
}

impl Receipts {
    fn read(path: &Path) -> Self {
        let text = std::fs::read_to_string(path).expect("the receipts log exists");
        let lines = text
            .lines()
            .map(|l| serde_json::from_str(l).expect("JSON lines"))
            .collect();
        Self { lines }
    }

    fn stats(&self) -> &Value {
        self.lines
            .iter()
            .rev()
            .find(|l| l["event"] == "stats")
            .expect("a stats line at shutdown")
    }

    fn events(&self, event: &str) -> usize {
        self.lines.iter().filter(|l| l["event"] == event).count()
    }

    /// Per pose id, what the robot received of its SET_POSEs.
    fn set_poses(&self) -> BTreeMap<u64, SetPoseReceipts> {
        let mut out: BTreeMap<u64, SetPoseReceipts> = BTreeMap::new();
        for l in &self.lines {
            if l["event"] != "datagram" || l["kind"] != "SET_POSE" {
                continue;
            }
            let pose = l["pose_id"].as_u64().expect("a pose id");
            let entry = out.entry(pose).or_default();
            if l["outcome"] != "unknown_session" {
                let seq = (
                    l["life"].as_u64().unwrap_or(0),
                    l["seq"].as_u64().unwrap_or(0),
                );
                entry.seqs.insert(seq);
            }
            if l["outcome"] == "new" {
                entry.new += 1;
                if l["ack"] == 0 {
                    entry.accepted += 1;
                }
            }
        }
        out
    }

    fn sum_over_lives(&self, counter: &str) -> u64 {
        self.stats()["lives"]
            .as_array()
            .expect("lives")
            .iter()
            .map(|l| l[counter].as_u64().unwrap_or(0))
            .sum()
    }
}

enum Start {
    Process,
    Thread,
}

fn scenario(name: &str, start: Start, restart_after_pose: Option<u16>) {
    let schedule = schedule();
    assert_eq!(schedule.poses.len(), 52);
    let faults = match restart_after_pose {
        Some(pose) => format!("{FAULTS},restart_after_pose={pose}"),
        None => FAULTS.to_string(),
    };
    let receipts = receipts_path(name);
    let (robot, address) = match start {
        Start::Process => Robot::process(&faults, &receipts),
        Start::Thread => Robot::thread(&faults, &receipts),
    };
    let started = Instant::now();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime");
    let client = runtime.block_on(visit_schedule(address, &schedule));
    let elapsed = started.elapsed();
    robot.stop();
    let receipts = Receipts::read(&receipts);
    let stats = receipts.stats();
    let faults = &stats["faults"];
    let rate = |lost: &str, of: &str| {
        faults[lost].as_f64().unwrap_or(0.0) / faults[of].as_f64().unwrap_or(1.0).max(1.0)
    };
    let (loss_in, loss_out) = (rate("lost_in", "received"), rate("lost_out", "replies"));
    eprintln!(
        "{name}: {:.1} s; loss to the robot {:.1} % of {}, from it {:.1} % of {}; \
         {} duplicated, {} reordered; client: {} requests, {} retransmissions, \
         {} stale replies, {} keep-alives, {} new sessions; server: {} retransmissions \
         answered again, {} stale dropped, {} restarts",
        elapsed.as_secs_f64(),
        loss_in * 100.0,
        faults["received"],
        loss_out * 100.0,
        faults["replies"],
        faults["duplicated"],
        faults["reordered"],
        client.requests,
        client.retransmissions,
        client.stale,
        client.keepalives,
        client.renewals,
        receipts.sum_over_lives("retransmissions"),
        receipts.sum_over_lives("stale"),
        stats["restarts"],
    );

    // The faults really happened (about 200 datagrams each way: ±3 % is one
    // standard deviation).
    assert!(
        (0.1..0.32).contains(&loss_in),
        "loss to the robot {loss_in}"
    );
    assert!(
        (0.1..0.32).contains(&loss_out),
        "loss from the robot {loss_out}"
    );
    assert!(client.retransmissions > 0);
    assert!(faults["duplicated"].as_u64() > Some(0));
    // The watchdog never fired.
    assert_eq!(receipts.sum_over_lives("watchdog_halts"), 0);
    assert_eq!(receipts.events("watchdog_halt"), 0);
    // Every pose: one new request, acted on once, its retransmissions on the
    // same seq.
    let set_poses = receipts.set_poses();
    for id in 1..=52u64 {
        let r = set_poses
            .get(&id)
            .unwrap_or_else(|| panic!("pose {id} never reached the robot"));
        assert_eq!(r.accepted, 1, "pose {id} acted on {} times", r.accepted);
        assert_eq!(r.new, 1, "pose {id} sent as {} new requests", r.new);
        assert_eq!(
            r.seqs.len(),
            1,
            "pose {id} under several seqs: {:?}",
            r.seqs
        );
    }
    match restart_after_pose {
        None => {
            assert_eq!(stats["restarts"], 0);
            assert_eq!(client.renewals, 0);
        }
        Some(_) => {
            assert_eq!(stats["restarts"], 1);
            assert_eq!(receipts.events("restart"), 1);
            assert_eq!(client.renewals, 1, "one new session after the restart");
        }
    }
    assert!(elapsed < Duration::from_secs(60), "{elapsed:?}");
}

#[test]
fn lossy_network_with_the_robot_on_a_thread() {
    scenario("thread-lossy", Start::Thread, None);
}

#[test]
fn restart_with_the_robot_on_a_thread() {
    scenario("thread-restart", Start::Thread, Some(20));
}

#[test]
fn lossy_network_with_the_robot_in_a_process() {
    scenario("process-lossy", Start::Process, None);
}

#[test]
fn restart_with_the_robot_in_a_process() {
    scenario("process-restart", Start::Process, Some(20));
}

/// A SIGTERM sent the moment the lower computer prints its address stops
/// it cleanly (exit 0, its stats on stderr): its handlers are installed
/// before the address is printed. They were installed when the server
/// first waited for a signal, after it, and a test that stopped the robot
/// at once (a schedule refused before the robot moves) saw it killed by
/// the signal's default action on a loaded CI machine.
#[test]
fn a_signal_as_soon_as_the_address_is_printed_stops_the_lower_computer_cleanly() {
    for _ in 0..40 {
        let (child, _address) = common::spawn_sim_robot(&[], &[]);
        // SAFETY: kill(2) on our own child's pid, with no memory involved.
        #[allow(unsafe_code)]
        let sent = unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        assert_eq!(sent, 0, "the signal was sent");
        let output = child.wait_with_output().expect("sim-robot exits");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            output.status.success() && stderr.contains("sim-robot: stats {"),
            "sim-robot exited with {}: {stderr}",
            output.status
        );
    }
}
