//! `groundcal capture`: records N depth frames from the sensor as a
//! recording (recording.md) whose `kinect/` is a fakenect dump, each frame
//! byte for byte as the sensor delivered it.
//!
//! The loop, [`capture`], is generic over [`DepthSensor`]; [`run`] drives it
//! with the Kinect through libfreenect.
//!
//! A capture has no robot, so its `session.json` says so with these values
//! (the format asks for a home stance; nothing reads it from a capture):
//!
//! - `robot`: `"none"`, `schedule` and `frames_per_pose` absent, no
//!   `nominal_mount`;
//! - `home.commanded`: the zero pose; `home.feet_body_mm`: six feet at the
//!   origin (no feet were measured);
//! - `kinect.tilt_deg`: the motor's angle once the first frame is in (0 if
//!   the sensor could not tell, with a warning); `depth_model` and
//!   `intrinsics`: the sensor's own ([`DepthSensor::info`]);
//! - `poses.jsonl` is empty: the frames are in `kinect/INDEX.txt`, named by
//!   no pose.
//!
//! The dump holds the frames in the order they came, named
//! `d-<host time>-<sensor timestamp>.pgm`, and after the first frame one
//! tilt snapshot `a-<same time>-<same timestamp>.dump` (as `fakenect-record`
//! stamps its snapshots with the last frame's timestamp), read as soon as the
//! first frame has arrived. Times in the names never decrease (a host clock stepping
//! back is clamped): fakenect's playback waits for their differences.

use std::fmt;
use std::path::{Path, PathBuf};

use groundcal_calib::geometry::PoseDegMm;
use groundcal_hal::kinect::Kinect;
use groundcal_hal::{DepthSensor, TiltState};

use crate::cli::ExitStatus;
use crate::formats::depth_image::DepthImage;
use crate::formats::recording::dump::RawTiltState;
use crate::formats::recording::session::{Home, KinectInfo, Session};
use crate::formats::recording::writer::{RecordingWriter, WriteError};
use crate::setup::config::SensorSource;

/// What a capture wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureSummary {
    /// The recording's directory.
    pub dir: PathBuf,
    /// The depth frames' names in `kinect/`, in capture order.
    pub frames: Vec<String>,
    /// The tilt snapshot's name in `kinect/`, if the sensor gave one.
    pub tilt_snapshot: Option<String>,
}

/// Why a capture failed.
#[derive(Debug)]
pub enum CaptureError<E> {
    /// The sensor failed, after `captured` frames had been written (the
    /// recording keeps them).
    Sensor { error: E, captured: usize },
    /// The recording could not be written.
    Write(WriteError),
    /// The sensor delivered a frame that cannot go into a fakenect dump.
    BadFrame(String),
}

impl<E: fmt::Display> fmt::Display for CaptureError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sensor { error, captured: 0 } => write!(f, "the sensor failed: {error}"),
            Self::Sensor { error, captured } => write!(
                f,
                "the sensor failed after {captured} frame(s), which the recording keeps: {error}"
            ),
            Self::Write(e) => write!(f, "{e}"),
            Self::BadFrame(m) => f.write_str(m),
        }
    }
}

impl<E: fmt::Debug + fmt::Display> std::error::Error for CaptureError<E> {}

/// The `session.json` of a capture (see the module's documentation).
pub fn capture_session(sensor: &impl DepthSensor, tilt_deg: f64) -> Session {
    let info = sensor.info();
    Session {
        format: "groundcal-recording".into(),
        version: 1,
        robot: "none".into(),
        home: Home {
            commanded: PoseDegMm {
                alpha_deg: 0.0,
                beta_deg: 0.0,
                gamma_deg: 0.0,
                px_mm: 0.0,
                py_mm: 0.0,
                pz_mm: 0.0,
            },
            feet_body_mm: vec![[0.0; 3]; 6],
        },
        kinect: KinectInfo {
            tilt_deg,
            depth_model: info.depth_model,
            intrinsics: info.intrinsics,
        },
        frames_per_pose: None,
        schedule: None,
        nominal_mount: None,
        gates: None,
        noise: None,
    }
}

/// The raw 12-byte state `fakenect-record` would have written for `state`.
pub fn raw_tilt_state(state: &TiltState) -> RawTiltState {
    RawTiltState::from_state(state)
}

/// Captures `frames` depth frames from `sensor` into a new recording `out`
/// (which must not exist or be empty). Warnings go to stderr.
pub async fn capture<S: DepthSensor>(
    sensor: &mut S,
    frames: usize,
    out: &Path,
) -> Result<CaptureSummary, CaptureError<S::Error>> {
    let mut names = Vec::with_capacity(frames);
    if frames == 0 {
        let session = capture_session(sensor, 0.0);
        let writer = RecordingWriter::create(out, &session).map_err(CaptureError::Write)?;
        let dir = writer.finish().map_err(CaptureError::Write)?;
        return Ok(CaptureSummary {
            dir,
            frames: names,
            tilt_snapshot: None,
        });
    }
    // The tilt motor and accelerometer as the frames begin.
    let first = sensor
        .next_frame()
        .await
        .map_err(|error| CaptureError::Sensor { error, captured: 0 })?;
    let tilt = match sensor.tilt_state().await {
        Ok(state) => Some(state),
        Err(e) => {
            eprintln!(
                "groundcal: capture: warning: cannot read the tilt motor ({e}); \
                 session.json says tilt 0°"
            );
            None
        }
    };
    let session = capture_session(sensor, tilt.map_or(0.0, |t| t.tilt_deg));
    let (width, height) = (
        session.kinect.intrinsics.width,
        session.kinect.intrinsics.height,
    );
    let mut writer = RecordingWriter::create(out, &session).map_err(CaptureError::Write)?;
    let mut tilt_snapshot = None;
    let mut last_time = 0.0_f64;
    let mut next = Some(first);
    for k in 0..frames {
        let frame = match next.take() {
            Some(frame) => frame,
            None => match sensor.next_frame().await {
                Ok(frame) => frame,
                Err(error) => {
                    // What was captured stays, durable.
                    let _ = writer.finish();
                    return Err(CaptureError::Sensor { error, captured: k });
                }
            },
        };
        if frame.width != width || frame.height != height || frame.raw.len() != width * height {
            return Err(CaptureError::BadFrame(format!(
                "frame {}: the sensor delivered {}×{} ({} values), its intrinsics say {width}×{height}",
                k + 1,
                frame.width,
                frame.height,
                frame.raw.len()
            )));
        }
        let time = if frame.time_s.is_finite() {
            frame.time_s.max(last_time)
        } else {
            last_time
        };
        last_time = time;
        let image = DepthImage {
            width: frame.width,
            height: frame.height,
            pixels: frame.raw,
        };
        let name = writer
            .write_depth_frame(time, frame.timestamp, &image)
            .map_err(CaptureError::Write)?;
        names.push(name);
        if k == 0 {
            if let Some(state) = &tilt {
                let name = writer
                    .write_tilt_state(time, frame.timestamp, &raw_tilt_state(state))
                    .map_err(CaptureError::Write)?;
                tilt_snapshot = Some(name);
            }
        }
    }
    let dir = writer.finish().map_err(CaptureError::Write)?;
    Ok(CaptureSummary {
        dir,
        frames: names,
        tilt_snapshot,
    })
}

/// The arguments of `groundcal capture`: the sensor and the frames to record.
#[derive(Debug, clap::Args)]
pub struct CaptureArgs {
    /// The configuration (sensor, library); the flags override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The sensor: kinect (libfreenect); default the configuration's, else kinect.
    #[arg(long)]
    pub sensor: Option<SensorSource>,
    /// The libfreenect library file to load (e.g. libfreenect's fakenect, to play a dump back).
    #[arg(long, value_name = "PATH")]
    pub freenect_lib: Option<PathBuf>,
    /// How many depth frames to record.
    #[arg(long)]
    pub frames: usize,
    /// The new recording's directory (must not exist, or be empty).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: CaptureArgs) -> ExitStatus {
    // The configuration's sensor and library, the flags overriding them.
    let sensor_config = match &args.config {
        Some(path) => match crate::setup::config::Config::load(path) {
            Ok((config, _)) => Some(config.sensor),
            Err(e) => return super::usage_error(e.to_string()),
        },
        None => None,
    };
    let source = args
        .sensor
        .or_else(|| sensor_config.as_ref().map(|s| s.source.clone()))
        .unwrap_or(SensorSource::Kinect);
    let library = args
        .freenect_lib
        .or_else(|| sensor_config.and_then(|s| s.freenect_lib));
    match source {
        SensorSource::Kinect => run(library.as_deref(), args.frames, &args.out),
        other => super::usage_error(format!(
            "--sensor: \"{other}\" cannot capture (yet); use kinect"
        )),
    }
}

/// `groundcal capture --sensor kinect [--freenect-lib PATH] --frames N --out DIR`:
/// opens the first Kinect through libfreenect (`freenect_lib`, or the usual
/// sonames), captures `frames` frames into the recording `out`.
///
/// Exit status: 0 done; 1 the library or the Kinect is missing or failed,
/// or the disk did; 2 `frames` is 0 or `out` exists and is not an empty
/// directory.
pub fn run(freenect_lib: Option<&Path>, frames: usize, out: &Path) -> ExitStatus {
    if frames == 0 {
        eprintln!("groundcal: capture: --frames must be at least 1");
        return ExitStatus::BadInput;
    }
    if let Some(status) = check_out(out) {
        return status;
    }
    let mut kinect = match Kinect::open(freenect_lib, 0) {
        Ok(k) => k,
        Err(e) => {
            let hint = if e.is_library_missing() && freenect_lib.is_none() {
                " (--freenect-lib PATH names the library file)"
            } else {
                ""
            };
            eprintln!("groundcal: capture: cannot open the Kinect: {e}{hint}");
            return ExitStatus::RuntimeFailure;
        }
    };
    let status = run_with(&mut kinect, frames, out);
    let counts = kinect.frame_counts();
    if counts.dropped > 0 {
        eprintln!(
            "groundcal: capture: warning: {} of {} frames from the Kinect were dropped \
             (the disk was slower than the sensor); the recording holds consecutive frames \
             only where none were",
            counts.dropped, counts.received
        );
    }
    status
}

/// Captures with any sensor, on a runtime of its own; prints the outcome.
pub fn run_with<S: DepthSensor>(sensor: &mut S, frames: usize, out: &Path) -> ExitStatus {
    if let Some(status) = check_out(out) {
        return status;
    }
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("groundcal: capture: cannot start the async runtime: {e}");
            return ExitStatus::RuntimeFailure;
        }
    };
    match runtime.block_on(capture(sensor, frames, out)) {
        Ok(summary) => {
            println!(
                "captured {} depth frame(s) into {} (kinect/ is a fakenect dump: \
                 FAKENECT_PATH={} plays it back)",
                summary.frames.len(),
                summary.dir.display(),
                summary.dir.join("kinect").display()
            );
            ExitStatus::Success
        }
        Err(e) => {
            eprintln!("groundcal: capture: {e}");
            ExitStatus::RuntimeFailure
        }
    }
}

/// `out` must not exist, or be an empty directory (checked before the
/// sensor is opened; the writer checks again).
fn check_out(out: &Path) -> Option<ExitStatus> {
    let refuse = |why: &str| {
        eprintln!("groundcal: capture: --out {}: {why}", out.display());
        Some(ExitStatus::BadInput)
    };
    if out.exists() && !out.is_dir() {
        return refuse("exists and is not a directory");
    }
    match std::fs::read_dir(out).map(|mut entries| entries.next().is_some()) {
        Ok(true) => refuse(
            "is not empty: a recording is written into a new or empty directory, never over another",
        ),
        Ok(false) => None,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            eprintln!("groundcal: capture: --out {}: {e}", out.display());
            Some(ExitStatus::RuntimeFailure)
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use groundcal_hal::error::ErrorKind;
    use groundcal_hal::{DepthFrame, Led, SensorInfo};

    use super::*;
    use crate::formats::recording::Recording;

    /// The stream has ended.
    #[derive(Debug)]
    struct Ended;

    impl fmt::Display for Ended {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("no more frames")
        }
    }

    impl std::error::Error for Ended {}

    impl groundcal_hal::Error for Ended {
        fn kind(&self) -> ErrorKind {
            ErrorKind::LinkLost
        }
    }

    /// Serves the frames it was given, then ends.
    struct Scripted {
        frames: VecDeque<DepthFrame>,
        tilt: Option<TiltState>,
    }

    impl DepthSensor for Scripted {
        type Error = Ended;

        fn info(&self) -> SensorInfo {
            SensorInfo {
                depth_model: Default::default(),
                intrinsics: Default::default(),
            }
        }

        async fn set_tilt(&mut self, _degrees: f64) -> Result<(), Ended> {
            Ok(())
        }

        async fn tilt_state(&mut self) -> Result<TiltState, Ended> {
            self.tilt.ok_or(Ended)
        }

        async fn set_led(&mut self, _led: Led) -> Result<(), Ended> {
            Ok(())
        }

        async fn next_frame(&mut self) -> Result<DepthFrame, Ended> {
            self.frames.pop_front().ok_or(Ended)
        }
    }

    fn frame(timestamp: u32, time_s: f64) -> DepthFrame {
        DepthFrame {
            timestamp,
            time_s,
            width: 640,
            height: 480,
            raw: (0..640 * 480)
                .map(|i| ((i as u32 * 7 + timestamp) % 2048) as u16)
                .collect(),
        }
    }

    /// A fresh directory name under the system's temporary one, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> Self {
            let path = std::env::temp_dir()
                .join(format!("groundcal-capture-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&path);
            Self(path)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn block_on<F: std::future::Future>(future: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap()
            .block_on(future)
    }

    #[test]
    fn frames_are_written_byte_for_byte_in_order_with_one_tilt_snapshot() {
        let tilt = TiltState {
            tilt_deg: -20.0,
            accelerometer_g: [-300.0 / 819.0, 819.0 / 819.0, 5.0 / 819.0],
            stopped: true,
        };
        let frames = vec![frame(100, 10.0), frame(200, 9.5), frame(300, 11.0)];
        let mut sensor = Scripted {
            frames: frames.clone().into(),
            tilt: Some(tilt),
        };
        let dir = TempDir::new("ok");
        let summary = block_on(capture(&mut sensor, 3, &dir.0)).unwrap();
        assert_eq!(summary.dir, dir.0);
        // The host clock stepped back for the second frame: its name keeps
        // the first one's time, so that playback never waits backwards.
        assert_eq!(
            summary.frames,
            [
                "d-10.000000-100.pgm",
                "d-10.000000-200.pgm",
                "d-11.000000-300.pgm"
            ]
        );
        assert_eq!(
            summary.tilt_snapshot.as_deref(),
            Some("a-10.000000-100.dump")
        );
        let recording = Recording::open(&dir.0).unwrap();
        assert_eq!(recording.session.kinect.tilt_deg, -20.0);
        assert!(recording.poses.is_empty());
        let names: Vec<&str> = recording.index.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "d-10.000000-100.pgm",
                "a-10.000000-100.dump",
                "d-10.000000-200.pgm",
                "d-11.000000-300.pgm"
            ]
        );
        for (name, original) in summary.frames.iter().zip(&frames) {
            let bytes = std::fs::read(recording.kinect_path(name)).unwrap();
            let mut expected = b"P5 640 480 65535\n".to_vec();
            expected.extend(original.raw.iter().flat_map(|v| v.to_le_bytes()));
            assert!(bytes == expected, "{name}");
        }
        let a = std::fs::read(recording.kinect_path("a-10.000000-100.dump")).unwrap();
        assert_eq!(a, [0xd4, 0xfe, 0x33, 0x03, 5, 0, 0xd8, 0, 0, 0, 0, 0]);
    }

    #[test]
    fn a_sensor_that_ends_early_leaves_the_frames_it_gave() {
        let mut sensor = Scripted {
            frames: vec![frame(1, 1.0), frame(2, 2.0)].into(),
            tilt: None,
        };
        let dir = TempDir::new("ends");
        match block_on(capture(&mut sensor, 3, &dir.0)) {
            Err(e @ CaptureError::Sensor { captured: 2, .. }) => {
                assert!(e.to_string().contains("after 2 frame(s)"), "{e}");
            }
            other => panic!("{other:?}"),
        }
        let recording = Recording::open(&dir.0).unwrap();
        // No tilt state: none is written, and the session says 0°.
        assert_eq!(recording.index.len(), 2);
        assert_eq!(recording.session.kinect.tilt_deg, 0.0);
    }

    #[test]
    fn frames_of_the_wrong_size_are_refused() {
        let mut small = frame(1, 1.0);
        small.width = 320;
        small.raw.truncate(320 * 480);
        let mut sensor = Scripted {
            frames: vec![small].into(),
            tilt: None,
        };
        let dir = TempDir::new("small");
        let err = block_on(capture(&mut sensor, 1, &dir.0)).unwrap_err();
        assert!(err.to_string().contains("320×480"), "{err}");
    }

    #[test]
    fn tilt_states_convert_back_to_the_raw_counts_exactly() {
        for (counts, half_degrees, status) in [([-300, 819, 5], -40, 0), ([0, 0, 0], 54, 4)] {
            let raw = RawTiltState {
                accelerometer: counts,
                tilt_angle: half_degrees,
                tilt_status: status,
            };
            let state = TiltState {
                tilt_deg: f64::from(half_degrees) / 2.0,
                accelerometer_g: counts.map(|c| f64::from(c) / 819.0),
                stopped: status == 0,
            };
            assert_eq!(raw_tilt_state(&state), raw);
        }
    }
}
