//! The Kinect v1 through libfreenect, loaded at run time.
//!
//! [`Kinect::open`] loads libfreenect (`libfreenect.so.0.5`, else
//! `libfreenect.so`, or the file the caller names, such as libfreenect's
//! fakenect build that plays a recorded dump back), opens the device and
//! starts 640×480 11-bit depth. Nothing links against libfreenect: a program
//! built with this module runs where libfreenect is not installed, and
//! opening a Kinect there fails with [`ErrorKind::DeviceMissing`] naming the
//! package to install.
//!
//! libfreenect's event loop runs on its own OS thread, which makes every
//! libfreenect call after the device is open: `freenect_process_events`, the
//! tilt motor, the LED. The depth callback copies each frame into a bounded
//! queue; when the queue is full the oldest frame is dropped and counted
//! ([`Kinect::frame_counts`]). [`DepthSensor::next_frame`] takes the oldest
//! queued frame, or waits for the next; [`DepthSensor::begin_pose`] throws the
//! queued frames away, so that a pose's frames are all captured after the
//! pose began. Dropping the [`Kinect`] stops the thread, then stops depth,
//! closes the device and shuts libfreenect's context down, also when the
//! thread has panicked. (With fakenect, which sleeps inside
//! `freenect_process_events` until the dump's next entry is due, closing
//! waits for that sleep.)
//!
//! The futures wake through their wakers (no timer of any runtime): the
//! event thread itself times out a wait for a frame
//! ([`KinectOptions::frame_timeout`]) and a tilt
//! ([`KinectOptions::tilt_timeout`]).

mod error;
#[allow(unsafe_code)]
mod ffi;
mod queue;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

pub use error::{KinectError, LIBFREENECT_PACKAGE};
use ffi::{Command, Device, Library, LoadError};
use queue::{FrameQueue, ReplySender};

use crate::error::ErrorKind;
use crate::sensor::{DepthFrame, DepthSensor, Led, SensorInfo, TiltState};
use groundcal_calib::depth::{DepthModel, Intrinsics};

/// The libraries tried, in order, when none is named: Debian's
/// `libfreenect0.5` ships `libfreenect.so.0.5`, `libfreenect-dev` adds
/// `libfreenect.so`. The dynamic loader searches its usual directories.
pub const DEFAULT_LIBRARIES: &[&str] = freenect_sys::DEFAULT_SONAMES;

/// Where libfreenect's fakenect build (the library that plays a dump back)
/// may be installed for this program's own architecture, most likely first:
/// `$GROUNDCAL_FAKENECT_LIB_DIR` when set, else Debian's multiarch directory
/// (`libfreenect0.5` is co-installable, so an arm64 program on an x86-64
/// machine must not pick the x86-64 library), then the plain ones.
pub fn fakenect_library_candidates() -> Vec<PathBuf> {
    let dirs: Vec<PathBuf> = match std::env::var_os("GROUNDCAL_FAKENECT_LIB_DIR") {
        Some(dir) => vec![PathBuf::from(dir)],
        None => {
            let multiarch = format!("{}-linux-gnu", std::env::consts::ARCH);
            ["/usr/lib", "/usr/local/lib"]
                .iter()
                .flat_map(|lib| {
                    [
                        Path::new(lib).join(&multiarch).join("fakenect"),
                        Path::new(lib).join("fakenect"),
                    ]
                })
                .collect()
        }
    };
    dirs.into_iter()
        .flat_map(|dir| DEFAULT_LIBRARIES.iter().map(move |name| dir.join(name)))
        .collect()
}

/// The first of [`fakenect_library_candidates`] that exists.
pub fn find_fakenect_library() -> Option<PathBuf> {
    fakenect_library_candidates()
        .into_iter()
        .find(|path| path.is_file())
}

/// The tilt motor's range, degrees either side of level.
pub const MAX_TILT_DEG: f64 = 27.0;

/// The depth frame's size.
pub const FRAME_WIDTH: usize = ffi::WIDTH;
pub const FRAME_HEIGHT: usize = ffi::HEIGHT;

/// How the Kinect is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinectOptions {
    /// Frames kept for `next_frame`; the oldest is dropped when a frame
    /// arrives into a full queue. 8 frames are 0.27 s at 30 Hz (4.9 MB).
    pub frame_queue: usize,
    /// How long `next_frame` waits for a frame before it fails with
    /// [`ErrorKind::Timeout`]. The Kinect sends 30 frames a second; its
    /// first ones take up to a second or two after the stream starts.
    pub frame_timeout: Duration,
    /// How long `set_tilt` waits for the motor to stop
    /// ([`ErrorKind::Timeout`] after it).
    pub tilt_timeout: Duration,
}

impl Default for KinectOptions {
    fn default() -> Self {
        Self {
            frame_queue: 8,
            frame_timeout: Duration::from_secs(5),
            tilt_timeout: Duration::from_secs(15),
        }
    }
}

/// Frames the depth callback received, and how many of them were dropped
/// because the queue was full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameCounts {
    pub received: u64,
    pub dropped: u64,
}

/// A Kinect v1, streaming depth (see the module's documentation).
#[derive(Debug)]
pub struct Kinect {
    library: PathBuf,
    fakenect: bool,
    info: SensorInfo,
    options: KinectOptions,
    queue: Arc<FrameQueue>,
    commands: Option<Sender<Command>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Dropped only after the thread has been joined.
    device: Option<Device>,
}

impl Kinect {
    /// Opens Kinect `device_index` (0 for the first) through libfreenect:
    /// `library` is the file to load, or `None` for [`DEFAULT_LIBRARIES`].
    pub fn open(library: Option<&Path>, device_index: u32) -> Result<Self, KinectError> {
        Self::open_with(library, device_index, KinectOptions::default())
    }

    /// [`Kinect::open`] with other options.
    ///
    /// With libfreenect's fakenect build (which plays the dump in
    /// `$FAKENECT_PATH` and exits the whole program when that is unset or a
    /// file of the dump is missing), the dump is checked first and an error
    /// returned instead.
    pub fn open_with(
        library: Option<&Path>,
        device_index: u32,
        options: KinectOptions,
    ) -> Result<Self, KinectError> {
        let (lib, path) = load_library(library)?;
        let fakenect = lib.is_fakenect();
        if fakenect {
            check_fakenect_dump(&path)?;
        }
        let mut device = Device::open(Arc::new(lib), device_index)?;
        let queue = Arc::new(FrameQueue::new(options.frame_queue));
        let stop = Arc::new(AtomicBool::new(false));
        let (commands, receiver) = mpsc::channel();
        device.start_depth()?;
        let event_loop = device.event_loop();
        let thread = {
            let (queue, stop) = (queue.clone(), stop.clone());
            let frame_timeout = options.frame_timeout;
            std::thread::Builder::new()
                .name("freenect-events".into())
                .spawn(move || event_loop.run(queue, receiver, stop, frame_timeout))
        }
        .map_err(|e| {
            KinectError::new(
                ErrorKind::Other,
                format!("cannot start libfreenect's event thread: {e}"),
            )
        })?;
        Ok(Self {
            library: path,
            fakenect,
            info: SensorInfo {
                depth_model: DepthModel::default(),
                intrinsics: Intrinsics::default(),
            },
            options,
            queue,
            commands: Some(commands),
            stop,
            thread: Some(thread),
            device: Some(device),
        })
    }

    /// The library that was loaded (as named: a path, or a soname).
    pub fn library(&self) -> &Path {
        &self.library
    }

    /// Whether the library is libfreenect's fakenect build (a dump played back).
    pub fn is_fakenect(&self) -> bool {
        self.fakenect
    }

    /// Frames received and dropped so far.
    pub fn frame_counts(&self) -> FrameCounts {
        let (received, dropped) = self.queue.counts();
        FrameCounts { received, dropped }
    }

    /// Throws the queued frames away; returns how many there were.
    pub fn discard_queued_frames(&mut self) -> usize {
        self.queue.clear()
    }

    /// Whether the stream has ended (the Kinect is gone, or fakenect's dump
    /// has been played to its end); queued frames may remain.
    pub fn has_ended(&self) -> bool {
        self.queue.has_ended()
    }

    /// Sends a command to the event thread and waits for its answer.
    async fn request<T>(
        &self,
        make: impl FnOnce(ReplySender<Result<T, KinectError>>) -> Command,
    ) -> Result<T, KinectError> {
        let gone = || KinectError::link_lost("libfreenect's event thread has stopped");
        let (sender, reply) = queue::reply();
        let commands = self.commands.as_ref().ok_or_else(gone)?;
        commands.send(make(sender)).map_err(|_| gone())?;
        reply.await.unwrap_or_else(|| Err(gone()))
    }
}

impl DepthSensor for Kinect {
    type Error = KinectError;

    /// libfreenect's zero-plane model with its usual constants and the
    /// default intrinsics (conventions.md); the device's own factory
    /// constants are not read.
    fn info(&self) -> SensorInfo {
        self.info
    }

    async fn set_tilt(&mut self, degrees: f64) -> Result<(), KinectError> {
        if !(degrees.is_finite() && degrees.abs() <= MAX_TILT_DEG) {
            return Err(KinectError::new(
                ErrorKind::Refused,
                format!("tilt {degrees}° is outside the Kinect's range of ±{MAX_TILT_DEG}°"),
            ));
        }
        let timeout = self.options.tilt_timeout;
        self.request(|reply| Command::SetTilt {
            degrees,
            timeout,
            reply,
        })
        .await
    }

    async fn tilt_state(&mut self) -> Result<TiltState, KinectError> {
        self.request(|reply| Command::TiltState { reply }).await
    }

    async fn set_led(&mut self, led: Led) -> Result<(), KinectError> {
        self.request(|reply| Command::SetLed { led, reply }).await
    }

    /// Throws the queued frames away: the frames that follow were all
    /// captured after this call.
    fn begin_pose(&mut self, _pose_id: u16) {
        self.queue.clear();
    }

    /// The oldest queued frame, else the next to arrive.
    async fn next_frame(&mut self) -> Result<DepthFrame, KinectError> {
        self.queue.next_frame().await
    }
}

impl Drop for Kinect {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        drop(self.commands.take());
        if let Some(thread) = self.thread.take() {
            // A panicked thread has left depth running; the device's drop
            // stops it.
            let _ = thread.join();
        }
        drop(self.device.take());
    }
}

/// Loads the named library, or the first of the default ones that loads.
fn load_library(library: Option<&Path>) -> Result<(Library, PathBuf), KinectError> {
    let install = format!(
        "install Debian's package {LIBFREENECT_PACKAGE} (`apt-get install {LIBFREENECT_PACKAGE}`)"
    );
    let candidates: Vec<PathBuf> = match library {
        Some(path) => vec![path.to_path_buf()],
        None => DEFAULT_LIBRARIES.iter().map(PathBuf::from).collect(),
    };
    let mut tried = Vec::new();
    for candidate in candidates {
        match Library::load(&candidate) {
            Ok(lib) => return Ok((lib, candidate)),
            Err(LoadError::Incomplete(missing)) => {
                return Err(KinectError::missing_library(format!(
                    "{} is not a usable libfreenect 0.5: it lacks {}; {install}",
                    candidate.display(),
                    missing.join(", ")
                )))
            }
            Err(LoadError::Open(why)) => tried.push(format!("{} ({why})", candidate.display())),
        }
    }
    Err(KinectError::missing_library(match library {
        Some(path) => format!(
            "cannot load libfreenect from {}: {install}, or give the path of an installed \
             libfreenect.so (the package's fakenect build, which plays dumps back, is \
             /usr/lib/<arch>/fakenect/libfreenect.so.0.5); tried {}",
            path.display(),
            tried.join("; ")
        ),
        None => format!(
            "libfreenect is not installed, so the Kinect cannot be used: {install}, or give \
             the path of a libfreenect.so; tried {}",
            tried.join("; ")
        ),
    }))
}

/// fakenect exits the program when `$FAKENECT_PATH` is unset or a file of
/// the dump is missing; this says so as an error instead.
fn check_fakenect_dump(library: &Path) -> Result<(), KinectError> {
    let missing = |m: String| KinectError::new(ErrorKind::DeviceMissing, m);
    let Some(dir) = std::env::var_os("FAKENECT_PATH").filter(|d| !d.is_empty()) else {
        return Err(missing(format!(
            "{} is libfreenect's fakenect, which plays back a dump recorded by fakenect-record: \
             set FAKENECT_PATH to the dump's directory (the one holding INDEX.txt)",
            library.display()
        )));
    };
    let dir = PathBuf::from(dir);
    let index = dir.join("INDEX.txt");
    let text = std::fs::read_to_string(&index).map_err(|e| {
        missing(format!(
            "FAKENECT_PATH: {}: cannot read the dump's index: {e}",
            index.display()
        ))
    })?;
    // fakenect stops at the first empty line, as at the end of the file.
    for (n, name) in text.lines().take_while(|l| !l.is_empty()).enumerate() {
        if !dir.join(name).is_file() {
            return Err(missing(format!(
                "FAKENECT_PATH: {}:{}: \"{name}\" is not in the dump (fakenect would exit the \
                 program when it reached it)",
                index.display(),
                n + 1
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
