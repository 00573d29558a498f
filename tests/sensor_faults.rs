//! The depth sensor as it fails: its stream stalls, the device disappears
//! (as libfreenect's fakenect does at the end of its dump), frames arrive
//! corrupt or all invalid. The session (the one `calibrate` and `serve` run)
//! against the simulated robot and a simulated Kinect with these faults
//! injected at one pose: it skips what it can, and otherwise aborts with the
//! reason, the robot halted and sent home. Nothing hangs: the stalled stream
//! fails after the sensor timeout.

mod common;

use std::time::{Duration, Instant};

use groundcal::hardware::{self, HardwareError, Selection};
use groundcal::session::{self, Event, Plan, SessionError, SessionOutcome};
use groundcal::setup::config::Config;
use groundcal_hal::{DepthFrame, DepthSensor, ErrorKind, Led, SensorInfo, TiltState};

/// What goes wrong, from pose `at` on.
#[derive(Debug, Clone, Copy)]
enum Fault {
    /// No frame ever comes.
    Stall,
    /// The device is gone.
    Vanish,
    /// This many frames with a few hundred values instead of 640×480.
    Corrupt(usize),
    /// Every pixel says "no reading".
    AllInvalid,
}

/// The simulated Kinect with a fault at one pose.
struct FaultySensor {
    inner: hardware::Sensor,
    fault: Fault,
    at: u16,
    pose: u16,
    corrupted: usize,
}

impl DepthSensor for FaultySensor {
    type Error = HardwareError;

    fn info(&self) -> SensorInfo {
        self.inner.info()
    }

    async fn set_tilt(&mut self, degrees: f64) -> Result<(), HardwareError> {
        self.inner.set_tilt(degrees).await
    }

    async fn tilt_state(&mut self) -> Result<TiltState, HardwareError> {
        self.inner.tilt_state().await
    }

    async fn set_led(&mut self, led: Led) -> Result<(), HardwareError> {
        if matches!(self.fault, Fault::Stall) && self.pose >= self.at {
            // A stalled device answers nothing at all.
            std::future::pending::<()>().await;
        }
        self.inner.set_led(led).await
    }

    fn begin_pose(&mut self, pose_id: u16) {
        self.pose = pose_id;
        self.inner.begin_pose(pose_id);
    }

    async fn next_frame(&mut self) -> Result<DepthFrame, HardwareError> {
        if self.pose < self.at {
            return self.inner.next_frame().await;
        }
        match self.fault {
            Fault::Stall => std::future::pending().await,
            Fault::Vanish => Err(HardwareError {
                kind: ErrorKind::DeviceMissing,
                message: "the Kinect is gone (end of the fakenect dump)".into(),
            }),
            Fault::Corrupt(count) if self.corrupted < count => {
                self.corrupted += 1;
                let mut frame = self.inner.next_frame().await?;
                frame.raw.truncate(300);
                Ok(frame)
            }
            Fault::Corrupt(_) => self.inner.next_frame().await,
            Fault::AllInvalid if self.pose == self.at => {
                let mut frame = self.inner.next_frame().await?;
                frame.raw.fill(2047);
                Ok(frame)
            }
            Fault::AllInvalid => self.inner.next_frame().await,
        }
    }
}

/// A whole simulated calibration with `fault` from pose `at`; the outcome,
/// the reason given when it aborted, and how long it took.
async fn calibrate_with(
    fault: Fault,
    at: u16,
) -> (
    Result<SessionOutcome, SessionError>,
    Option<String>,
    Duration,
) {
    let (config, schedule) = Config::embedded_sim();
    let (sensor, mut controller) = hardware::open(&config, &Selection::default())
        .await
        .expect("the simulated hardware opens");
    let mut sensor = FaultySensor {
        inner: sensor,
        fault,
        at,
        pose: 0,
        corrupted: 0,
    };
    let mut plan = Plan::from_config(&config, schedule, None, None).unwrap();
    plan.sensor_timeout = Duration::from_secs(1);
    let (events, mut received) = tokio::sync::mpsc::unbounded_channel();
    let start = Instant::now();
    let outcome = session::run(
        &mut sensor,
        &mut controller,
        &plan,
        &events,
        std::future::pending(),
    )
    .await;
    let took = start.elapsed();
    drop(events);
    let mut reason = None;
    while let Some(event) = received.recv().await {
        if let Event::Aborted {
            reason: r,
            robot_left,
        } = event
        {
            // Every sensor fault leaves the robot halted at home, and the
            // event says so in a type, not only in words.
            assert_eq!(robot_left, groundcal::session::RobotLeft::Home, "{r}");
            reason = Some(r);
        }
    }
    (outcome, reason, took)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_stream_aborts_after_the_timeout_and_the_robot_goes_home() {
    // Without a bound on the wait this would hang: the test says so instead.
    let (outcome, reason, took) =
        tokio::time::timeout(Duration::from_secs(60), calibrate_with(Fault::Stall, 5))
            .await
            .expect("the session hung on a stalled stream");
    match outcome {
        Err(SessionError::Sensor { kind, message }) => {
            assert_eq!(kind, ErrorKind::Timeout);
            assert!(
                message.contains("pose 5: waiting for a depth frame"),
                "{message}"
            );
        }
        other => panic!("{other:?}"),
    }
    let reason = reason.expect("the abort was announced");
    assert!(reason.contains("halted and sent home"), "{reason}");
    // Poses 1-4 at the simulator's pace, then one timeout for the frame and
    // one for the red LED: not a hang.
    assert!(took < Duration::from_secs(20), "{took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_device_that_disappears_aborts_with_its_words_and_the_robot_goes_home() {
    let (outcome, reason, _) = calibrate_with(Fault::Vanish, 5).await;
    match outcome {
        Err(SessionError::Sensor { kind, message }) => {
            assert_eq!(kind, ErrorKind::DeviceMissing);
            assert!(message.contains("the Kinect is gone"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    let reason = reason.expect("the abort was announced");
    assert!(reason.contains("halted and sent home"), "{reason}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_few_corrupt_frames_are_skipped_and_many_abort() {
    let (outcome, _, _) = calibrate_with(Fault::Corrupt(2), 5).await;
    let result = outcome.expect("two corrupt frames are skipped").result;
    assert!(result.accepted(), "{:?}", result.reasons);
    assert_eq!(result.poses.len(), 52);

    let (outcome, reason, _) = calibrate_with(Fault::Corrupt(100), 5).await;
    match outcome {
        Err(SessionError::Sensor { kind, message }) => {
            assert_eq!(kind, ErrorKind::Protocol);
            assert!(
                message.contains("corrupt frames at pose 5") && message.contains("300 values"),
                "{message}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(reason.unwrap_or_default().contains("halted and sent home"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pose_whose_frames_are_all_invalid_is_set_aside_with_why() {
    let (outcome, _, _) = calibrate_with(Fault::AllInvalid, 5).await;
    let result = outcome
        .expect("one blind pose does not stop a calibration")
        .result;
    let pose = result.poses.iter().find(|p| p.index == 5).unwrap();
    assert!(!pose.used);
    let why = pose.reason.as_deref().unwrap_or_default();
    assert!(why.contains("no ground found"), "{why}");
    assert!(result.accepted(), "{:?}", result.reasons);
}

/// A played-back frame is read off the session's thread: a read that waits
/// on a busy disk must not hold it up, or its stall watch stops ticking (and
/// an Abort could not arrive). On one thread, as `serve`'s session has the
/// runtime's attention, with one blocking worker kept busy until a task on
/// that thread lets it go: a read made on the blocking pool waits for it and
/// so lets the task run; a read made on the thread itself never does (CI of
/// f31804b1: a live calibration of the sample ended "the service stalled
/// for 2.0 s" while a release build wrote to the disk).
#[test]
fn recorded_frames_are_read_off_the_sessions_thread() {
    use groundcal::formats::recording::Recording;
    use groundcal::hardware::playback_sensor::PlaybackSensor;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::sync::{mpsc, Arc, Mutex};

    let sample = common::shared().join("data/sample-12");
    let expected = Recording::open(&sample).unwrap();
    let mut sensor = PlaybackSensor::new(Recording::open(&sample).unwrap());
    let pose = sensor.first_pose().unwrap();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .max_blocking_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (release, gate) = mpsc::channel::<()>();
    let gate = Arc::new(Mutex::new(gate));
    let armed = Arc::new(AtomicBool::new(false));
    let turns = Arc::new(AtomicUsize::new(0));
    runtime.block_on(async {
        let (counted, armed_beside) = (Arc::clone(&turns), Arc::clone(&armed));
        tokio::spawn(async move {
            loop {
                if armed_beside.swap(false, Ordering::SeqCst) {
                    counted.fetch_add(1, Ordering::SeqCst);
                    let _ = release.send(());
                }
                tokio::task::yield_now().await;
            }
        });
        sensor.begin_pose(pose);
        for name in &expected.poses[0].depth_frames {
            // The one blocking worker, busy until the task beside lets it go.
            let held = Arc::clone(&gate);
            let busy = tokio::task::spawn_blocking(move || {
                let _ = held.lock().unwrap().recv();
            });
            let before = turns.load(Ordering::SeqCst);
            armed.store(true, Ordering::SeqCst);
            let frame = tokio::time::timeout(Duration::from_secs(30), sensor.next_frame())
                .await
                .expect("the read waits for the worker, which the task lets go")
                .expect("a frame");
            assert!(
                turns.load(Ordering::SeqCst) > before,
                "{name}: nothing else ran on the thread during its read"
            );
            // A read on the thread itself left the worker waiting.
            armed.store(true, Ordering::SeqCst);
            busy.await.unwrap();
            assert_eq!(
                frame.raw,
                expected.read_depth_frame(name).unwrap().0.pixels,
                "{name}"
            );
        }
    });
}
