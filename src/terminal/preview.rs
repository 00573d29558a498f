//! The live picture at rest: while no session runs, the daemon opens the
//! depth sensor alone (never the robot, never the tilt motor) and fits the
//! ground in one frame a second, so that the page shows what the camera sees
//! before anyone presses Calibrate. A session stops it and waits until the
//! sensor is closed before opening the hardware; while it runs, its own fits
//! make the pictures ([`crate::session::Event::GroundSeen`]).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use tokio::sync::watch;

use super::api::ViewJson;
use crate::calib::geometry::PoseDegMm;
use crate::calib::ground_view::GroundView;
use crate::calib::observe::ground_prior;
use crate::calib::plane::{fit_ground, FitBuffers, PlaneFitSettings};
use crate::calib::sensor::{DepthCamera, DepthEncoding, DepthRange};
use crate::hardware::{self, Selection, Sensor};
use crate::setup::config::Config;
use groundcal_hal::DepthSensor;

/// The longest a frame may take before the sensor counts as stalled.
const FRAME_TIMEOUT: Duration = Duration::from_secs(5);
/// How long to wait before opening a sensor again after it failed.
const RETRY: Duration = Duration::from_secs(5);

/// The latest picture, and why there is none when there is none.
#[derive(Debug, Default)]
pub struct ViewSlot {
    /// Counts pictures, so that a page redraws only a new one.
    seq: u64,
    latest: Option<Seen>,
    unavailable: Option<String>,
}

#[derive(Debug)]
struct Seen {
    at: Instant,
    taken: SystemTime,
    pose: Option<u16>,
    view: Arc<GroundView>,
}

impl ViewSlot {
    /// Keeps a new picture (of pose `pose`, or at rest).
    pub fn keep(&mut self, pose: Option<u16>, view: GroundView) {
        self.seq += 1;
        self.unavailable = None;
        self.latest = Some(Seen {
            at: Instant::now(),
            taken: SystemTime::now(),
            pose,
            view: Arc::new(view),
        });
    }

    /// Says why no new picture can be taken (the last one stays, with its age).
    pub fn unavailable(&mut self, why: String) {
        self.unavailable = Some(why);
    }

    /// What `GET /api/view` answers (`live_at_rest`: whether pictures are
    /// taken while no session runs).
    pub fn json(&self, live_at_rest: bool) -> ViewJson {
        ViewJson {
            live_at_rest,
            seq: self.seq,
            age_ms: self
                .latest
                .as_ref()
                .map(|s| s.at.elapsed().as_millis().min(u128::from(u64::MAX)) as u64),
            taken: self
                .latest
                .as_ref()
                .map(|s| humantime::format_rfc3339_millis(s.taken).to_string()),
            pose: self.latest.as_ref().and_then(|s| s.pose),
            view: self.latest.as_ref().map(|s| Arc::clone(&s.view)),
            unavailable: self.unavailable.clone(),
        }
    }
}

/// The picture-taking thread, and how to stop it.
pub struct PreviewThread {
    stop: watch::Sender<bool>,
    thread: std::thread::JoinHandle<()>,
}

impl PreviewThread {
    /// Starts taking a picture every `interval` into `slot`, the body
    /// standing at `home`.
    pub fn start(
        config: Config,
        selection: Selection,
        home: PoseDegMm,
        interval: Duration,
        slot: Arc<Mutex<ViewSlot>>,
    ) -> std::io::Result<Self> {
        let (stop, stopped) = watch::channel(false);
        let thread = std::thread::Builder::new()
            .name("groundcal-preview".into())
            .spawn(move || {
                let runtime = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(r) => r,
                    Err(e) => {
                        return keep_unavailable(&slot, format!("no live picture: {e}"));
                    }
                };
                runtime.block_on(async {
                    let mut stopped = stopped;
                    tokio::select! {
                        () = look(&config, &selection, &home, interval, &slot) => {}
                        _ = stopped.wait_for(|stop| *stop) => {}
                    }
                });
            })?;
        Ok(Self { stop, thread })
    }

    /// Stops taking pictures and waits until the sensor is closed (a
    /// blocking wait: from a thread of its own, never the async runtime's).
    pub fn stop(self) {
        let _ = self.stop.send(true);
        let _ = self.thread.join();
    }
}

fn keep_unavailable(slot: &Mutex<ViewSlot>, why: String) {
    slot.lock()
        .unwrap_or_else(|p| p.into_inner())
        .unavailable(why);
}

/// Opens the sensor and takes pictures until stopped; opens it again (after
/// a pause) when it fails.
async fn look(
    config: &Config,
    selection: &Selection,
    home: &PoseDegMm,
    interval: Duration,
    slot: &Mutex<ViewSlot>,
) {
    loop {
        let why = match hardware::open_sensor(config, selection) {
            Ok(Sensor::Kinect(kinect)) if kinect.is_fakenect() => {
                // fakenect plays its dump once: the session needs every frame.
                return keep_unavailable(
                    slot,
                    "no live picture from a recorded Kinect (fakenect): it plays its frames once"
                        .into(),
                );
            }
            Ok(mut sensor) => {
                match take_pictures(config, home, &mut sensor, interval, slot).await {
                    Ok(never) => match never {},
                    Err(e) => e,
                }
            }
            Err(e) => format!("the depth sensor cannot be opened: {e}"),
        };
        tracing::debug!("live picture: {why}");
        keep_unavailable(slot, why);
        tokio::time::sleep(RETRY).await;
    }
}

/// Takes a picture every `interval` until the sensor fails (its error).
async fn take_pictures(
    config: &Config,
    home: &PoseDegMm,
    sensor: &mut Sensor,
    interval: Duration,
    slot: &Mutex<ViewSlot>,
) -> Result<std::convert::Infallible, String> {
    let info = sensor.info();
    let camera = DepthCamera::new(
        DepthEncoding::Raw11(info.depth_model),
        info.intrinsics,
        DepthRange::default(),
    );
    // At rest the body stands at its home stance.
    let home = home.to_params().to_transform();
    let prior = ground_prior(config.calibration.nominal_mount.as_ref(), &home);
    let settings = PlaneFitSettings {
        method: config.calibration.ground_fit,
        ..Default::default()
    };
    // A recording's frames are those of its first pose.
    let pose = match sensor {
        Sensor::Playback(p) => p.first_pose().unwrap_or(1),
        _ => 0,
    };
    let mut buffers = FitBuffers::default();
    let mut tick = tokio::time::interval(interval);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        // Only frames captured after this moment (a Kinect drops its queue).
        sensor.begin_pose(pose);
        let frame = match tokio::time::timeout(FRAME_TIMEOUT, sensor.next_frame()).await {
            Ok(Ok(frame)) => frame,
            Ok(Err(e)) => return Err(format!("the depth sensor failed: {e}")),
            Err(_) => {
                return Err(format!(
                    "the depth sensor sent no frame within {} s",
                    FRAME_TIMEOUT.as_secs()
                ))
            }
        };
        // Under a millisecond: this thread's runtime has nothing else to do.
        let fit = fit_ground(&[&frame.raw], &camera, &prior, &settings, &mut buffers)
            .map_err(|e| format!("no ground found: {e}"));
        let view = GroundView::of(&frame.raw, &camera, fit.as_ref().map_err(String::as_str));
        slot.lock()
            .unwrap_or_else(|p| p.into_inner())
            .keep(None, view);
    }
}
