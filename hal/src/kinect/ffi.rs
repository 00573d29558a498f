//! Everything that touches libfreenect, and so every `unsafe` block of the
//! Kinect driver.
//!
//! The rules that make the rest safe:
//!
//! - the library stays loaded while anything may call into it: [`Device`]
//!   and [`EventLoop`] hold an `Arc<Library>`;
//! - a function is called only if the library has it: [`Library::load`]
//!   refuses a library that lacks any of [`REQUIRED`];
//! - after [`Device::start_depth`], libfreenect is called on one thread only,
//!   the event thread ([`EventLoop::run`]): `freenect_process_events`, the
//!   tilt motor, the LED, `freenect_stop_depth` at the end. The [`Device`]
//!   closes the device and shuts the context down when dropped, which the
//!   Kinect does only after joining that thread (panicked or not);
//! - the depth callback is `extern "C"`, catches every panic, and touches
//!   only the frame libfreenect lends it, for the time of the call.

use std::cell::RefCell;
use std::ffi::c_void;
use std::os::raw::c_int;
use std::path::Path;
use std::ptr::null_mut;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use freenect_sys as sys;

use super::error::KinectError;
use super::queue::{FrameQueue, ReplySender};
use crate::error::ErrorKind;
use crate::sensor::{DepthFrame, Led, TiltState};

/// The depth frame groundcal asks for: 640×480, 11-bit values in a `u16`.
pub(super) const WIDTH: usize = 640;
pub(super) const HEIGHT: usize = 480;
const FRAME_BYTES: usize = WIDTH * HEIGHT * 2;

/// libusb's `LIBUSB_ERROR_INTERRUPTED`: a signal, worth another go.
const LIBUSB_ERROR_INTERRUPTED: c_int = -10;
/// Interrupted event loops in a row before giving up.
const MAX_INTERRUPTED: u32 = 10;
/// How long one `freenect_process_events_timeout` may block, so that
/// commands and the stop request are seen promptly.
const EVENT_SLICE: Duration = Duration::from_millis(20);
/// How often the tilt motor is asked whether it has stopped.
const TILT_POLL: Duration = Duration::from_millis(100);
/// After `freenect_set_tilt_degs` the motor may report "stopped" for a while
/// before it starts; "stopped" counts only once it was seen moving, or after this.
const TILT_START: Duration = Duration::from_millis(600);

/// Functions the driver calls; a library without any of them is refused.
pub(super) const REQUIRED: &[&str] = &[
    "freenect_init",
    "freenect_shutdown",
    "freenect_num_devices",
    "freenect_open_device",
    "freenect_close_device",
    "freenect_find_depth_mode",
    "freenect_set_depth_mode",
    "freenect_get_current_depth_mode",
    "freenect_set_depth_callback",
    "freenect_start_depth",
    "freenect_stop_depth",
    "freenect_process_events_timeout",
    "freenect_update_tilt_state",
    "freenect_get_tilt_state",
    "freenect_get_tilt_degs",
    "freenect_get_tilt_status",
    "freenect_set_tilt_degs",
    "freenect_set_led",
];

/// A loaded libfreenect (or its fakenect build).
pub(super) struct Library {
    fns: sys::Freenect,
    /// Whether it looks like libfreenect's fakenect build, which plays the
    /// dump in `$FAKENECT_PATH` (and exits the process if that is unset).
    fakenect: bool,
}

impl std::fmt::Debug for Library {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Library")
            .field("fakenect", &self.fakenect)
            .finish_non_exhaustive()
    }
}

/// Why a library could not be used.
pub(super) enum LoadError {
    /// `dlopen` failed (the message is dlerror's).
    Open(String),
    /// It loaded but lacks these functions.
    Incomplete(Vec<&'static str>),
}

impl Library {
    /// Loads `name` (a path, or a soname the dynamic loader searches for).
    pub(super) fn load(name: &Path) -> Result<Self, LoadError> {
        // SAFETY: loading runs the library's initialisers. The caller names
        // a libfreenect (the default sonames, or a path the operator gave);
        // libfreenect's initialisers have no preconditions.
        let fns =
            unsafe { sys::Freenect::new(name) }.map_err(|e| LoadError::Open(e.to_string()))?;
        let missing: Vec<&'static str> =
            REQUIRED.iter().copied().filter(|f| !has(&fns, f)).collect();
        if !missing.is_empty() {
            return Err(LoadError::Incomplete(missing));
        }
        // The real libfreenect 0.5 has these; the fakenect build has neither.
        let fakenect = name.to_string_lossy().contains("fakenect")
            || (fns.freenect_set_flag.is_err() && fns.freenect_enabled_subdevices.is_err());
        Ok(Self { fns, fakenect })
    }

    pub(super) fn is_fakenect(&self) -> bool {
        self.fakenect
    }
}

/// Whether the library has the function `name` (one of [`REQUIRED`]).
fn has(fns: &sys::Freenect, name: &str) -> bool {
    match name {
        "freenect_init" => fns.freenect_init.is_ok(),
        "freenect_shutdown" => fns.freenect_shutdown.is_ok(),
        "freenect_num_devices" => fns.freenect_num_devices.is_ok(),
        "freenect_open_device" => fns.freenect_open_device.is_ok(),
        "freenect_close_device" => fns.freenect_close_device.is_ok(),
        "freenect_find_depth_mode" => fns.freenect_find_depth_mode.is_ok(),
        "freenect_set_depth_mode" => fns.freenect_set_depth_mode.is_ok(),
        "freenect_get_current_depth_mode" => fns.freenect_get_current_depth_mode.is_ok(),
        "freenect_set_depth_callback" => fns.freenect_set_depth_callback.is_ok(),
        "freenect_start_depth" => fns.freenect_start_depth.is_ok(),
        "freenect_stop_depth" => fns.freenect_stop_depth.is_ok(),
        "freenect_process_events_timeout" => fns.freenect_process_events_timeout.is_ok(),
        "freenect_update_tilt_state" => fns.freenect_update_tilt_state.is_ok(),
        "freenect_get_tilt_state" => fns.freenect_get_tilt_state.is_ok(),
        "freenect_get_tilt_degs" => fns.freenect_get_tilt_degs.is_ok(),
        "freenect_get_tilt_status" => fns.freenect_get_tilt_status.is_ok(),
        "freenect_set_tilt_degs" => fns.freenect_set_tilt_degs.is_ok(),
        "freenect_set_led" => fns.freenect_set_led.is_ok(),
        _ => false,
    }
}

/// An open libfreenect context and device, streaming 11-bit depth once
/// started. Dropping it stops depth (unless the event thread did), closes
/// the device and shuts the context down.
#[derive(Debug)]
pub(super) struct Device {
    lib: Arc<Library>,
    ctx: *mut sys::freenect_context,
    dev: *mut sys::freenect_device,
    depth_started: bool,
    /// Set by the event thread once it has stopped depth itself.
    depth_stopped: Arc<AtomicBool>,
}

// SAFETY: the pointers are libfreenect's handles, which are not tied to the
// thread that made them. They are used by one thread at a time: the owner
// until `start_depth`, then the event thread until it is joined, then the
// owner again in `Drop` (see the module's rules).
unsafe impl Send for Device {}

impl Device {
    /// `freenect_init`, then opens device `index` (camera and motor, not
    /// audio) in 640×480 11-bit depth, its callback set, not yet started.
    pub(super) fn open(lib: Arc<Library>, index: u32) -> Result<Self, KinectError> {
        let fns = &lib.fns;
        let mut ctx: *mut sys::freenect_context = null_mut();
        // SAFETY: `freenect_init` is present (REQUIRED); it writes a context
        // to `ctx`; a null USB context asks libfreenect to make its own.
        let code = unsafe { fns.freenect_init(&mut ctx, null_mut()) };
        if code < 0 || ctx.is_null() {
            return Err(KinectError::call(
                ErrorKind::Other,
                "freenect_init",
                code,
                "libfreenect could not start (its USB library failed)",
            ));
        }
        // From here on, dropping `device` shuts the context down.
        let mut device = Device {
            lib: lib.clone(),
            ctx,
            dev: null_mut(),
            depth_started: false,
            depth_stopped: Arc::new(AtomicBool::new(false)),
        };
        if let Ok(set_log_level) = &fns.freenect_set_log_level {
            // SAFETY: a live context; the level is one of the header's.
            unsafe { set_log_level(ctx, sys::freenect_loglevel::FREENECT_LOG_WARNING) };
        }
        if let Ok(select) = &fns.freenect_select_subdevices {
            // SAFETY: a live context, before any device is opened, as the
            // header asks. The audio device is not needed.
            unsafe {
                select(
                    ctx,
                    sys::freenect_device_flags::FREENECT_DEVICE_MOTOR
                        | sys::freenect_device_flags::FREENECT_DEVICE_CAMERA,
                )
            };
        }
        // SAFETY: a live context.
        let count = unsafe { fns.freenect_num_devices(ctx) };
        if count < 0 {
            return Err(KinectError::call(
                ErrorKind::Other,
                "freenect_num_devices",
                count,
                "libfreenect could not list the Kinects",
            ));
        }
        let index_c = c_int::try_from(index).unwrap_or(c_int::MAX);
        if index_c >= count {
            return Err(KinectError::new(
                ErrorKind::DeviceMissing,
                format!(
                    "no Kinect at index {index}: libfreenect finds {count} Kinect(s); \
                     check that it is plugged in and on its own power supply"
                ),
            ));
        }
        let mut dev: *mut sys::freenect_device = null_mut();
        // SAFETY: a live context; libfreenect writes the device to `dev`.
        let code = unsafe { fns.freenect_open_device(ctx, &mut dev, index_c) };
        if code < 0 || dev.is_null() {
            return Err(KinectError::new(
                ErrorKind::DeviceMissing,
                format!(
                    "cannot open Kinect {index}: freenect_open_device returned {code}; another \
                     program may have it open, or this user may not access its USB devices \
                     (the udev rules of Debian's libfreenect0.5 grant the plugdev and video groups)"
                ),
            ));
        }
        device.dev = dev;

        // SAFETY: plain function of two enum values, present (REQUIRED).
        let mode = unsafe {
            fns.freenect_find_depth_mode(
                sys::freenect_resolution::FREENECT_RESOLUTION_MEDIUM,
                sys::freenect_depth_format::FREENECT_DEPTH_11BIT,
            )
        };
        check_mode(&mode, "freenect_find_depth_mode")?;
        // SAFETY: a live device; the mode is one libfreenect itself returned.
        let code = unsafe { fns.freenect_set_depth_mode(dev, mode) };
        if code < 0 {
            return Err(KinectError::call(
                ErrorKind::Protocol,
                "freenect_set_depth_mode",
                code,
                "the Kinect refused 640×480 11-bit depth",
            ));
        }
        // SAFETY: a live device.
        let current = unsafe { fns.freenect_get_current_depth_mode(dev) };
        check_mode(&current, "freenect_get_current_depth_mode")?;
        // SAFETY: a live device; the callback has the header's signature,
        // never unwinds, and is called on the event thread only.
        unsafe { fns.freenect_set_depth_callback(dev, Some(depth_callback)) };
        Ok(device)
    }

    /// Starts the depth stream (frames then arrive through the event loop).
    pub(super) fn start_depth(&mut self) -> Result<(), KinectError> {
        // SAFETY: a live device; no event thread runs yet.
        let code = unsafe { self.lib.fns.freenect_start_depth(self.dev) };
        if code < 0 {
            return Err(KinectError::call(
                ErrorKind::LinkLost,
                "freenect_start_depth",
                code,
                "the Kinect's depth stream would not start",
            ));
        }
        self.depth_started = true;
        Ok(())
    }

    /// What the event thread needs; valid while this device lives.
    pub(super) fn event_loop(&self) -> EventLoop {
        EventLoop {
            lib: self.lib.clone(),
            ctx: self.ctx,
            dev: self.dev,
            depth_stopped: self.depth_stopped.clone(),
        }
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        let fns = &self.lib.fns;
        // SAFETY (all three): live handles, and no other thread calls
        // libfreenect any more (the event thread has been joined, or was
        // never started).
        if !self.dev.is_null() {
            if self.depth_started && !self.depth_stopped.load(Ordering::Acquire) {
                unsafe { fns.freenect_stop_depth(self.dev) };
            }
            unsafe { fns.freenect_close_device(self.dev) };
        }
        unsafe { fns.freenect_shutdown(self.ctx) };
    }
}

fn check_mode(mode: &sys::freenect_frame_mode, function: &str) -> Result<(), KinectError> {
    // SAFETY: every member of the union is a 32-bit integer; reading any is defined.
    let format = unsafe { mode.__bindgen_anon_1.dummy };
    let ok = mode.is_valid != 0
        && format as u32 == sys::freenect_depth_format::FREENECT_DEPTH_11BIT
        && usize::try_from(mode.width) == Ok(WIDTH)
        && usize::try_from(mode.height) == Ok(HEIGHT)
        && usize::try_from(mode.bytes) == Ok(FRAME_BYTES);
    if ok {
        Ok(())
    } else {
        Err(KinectError::new(
            ErrorKind::Protocol,
            format!(
                "{function}: libfreenect's depth mode is {}×{}, {} bytes, format {format}, valid {}; \
                 expected 640×480 11-bit depth in {FRAME_BYTES} bytes",
                mode.width, mode.height, mode.bytes, mode.is_valid
            ),
        ))
    }
}

/// A request to the event thread, answered through its reply.
#[derive(Debug)]
pub(super) enum Command {
    SetTilt {
        degrees: f64,
        timeout: Duration,
        reply: ReplySender<Result<(), KinectError>>,
    },
    TiltState {
        reply: ReplySender<Result<TiltState, KinectError>>,
    },
    SetLed {
        led: Led,
        reply: ReplySender<Result<(), KinectError>>,
    },
    /// Panics the event thread, for the tests of the clean-up after it.
    #[cfg(test)]
    Panic,
}

/// A tilt in progress: the event thread polls the motor until it stops.
struct PendingTilt {
    target: f64,
    started: Instant,
    deadline: Instant,
    last_poll: Instant,
    seen_moving: bool,
    reply: ReplySender<Result<(), KinectError>>,
}

/// The event thread's handles (copies of the [`Device`]'s).
pub(super) struct EventLoop {
    lib: Arc<Library>,
    ctx: *mut sys::freenect_context,
    dev: *mut sys::freenect_device,
    depth_stopped: Arc<AtomicBool>,
}

// SAFETY: see `Device`: from `start_depth` until it is joined, the event
// thread is the only one that calls libfreenect with these handles.
unsafe impl Send for EventLoop {}

thread_local! {
    /// Where the depth callback puts frames: set by the event thread for
    /// itself, the only thread on which libfreenect calls the callback.
    static SINK: RefCell<Option<Arc<FrameQueue>>> = const { RefCell::new(None) };
}

/// Marks the stream ended when the event thread leaves, by return or panic.
struct EndGuard(Arc<FrameQueue>);

impl Drop for EndGuard {
    fn drop(&mut self) {
        let message = if std::thread::panicking() {
            "libfreenect's event thread panicked; the Kinect is closed"
        } else {
            "the Kinect has been closed"
        };
        self.0.end(KinectError::link_lost(message));
    }
}

impl EventLoop {
    /// The event thread: processes libfreenect's events, runs commands,
    /// times out waiting callers, until `stop`; then stops depth.
    pub(super) fn run(
        self,
        queue: Arc<FrameQueue>,
        commands: Receiver<Command>,
        stop: Arc<AtomicBool>,
        frame_timeout: Duration,
    ) {
        SINK.with(|sink| *sink.borrow_mut() = Some(queue.clone()));
        let _guard = EndGuard(queue.clone());
        let mut tilt: Option<PendingTilt> = None;
        let mut streaming = true;
        let mut interrupted = 0;
        while !stop.load(Ordering::Acquire) {
            loop {
                match commands.try_recv() {
                    Ok(command) => self.command(command, &mut tilt),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        stop.store(true, Ordering::Release);
                        break;
                    }
                }
            }
            self.poll_tilt(&mut tilt);
            if !streaming {
                // The stream has ended; the motor and the LED may still answer.
                match commands.recv_timeout(TILT_POLL) {
                    Ok(command) => self.command(command, &mut tilt),
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => break,
                }
                continue;
            }
            queue.check_timeout(frame_timeout);
            let mut timeout = sys::timeval {
                tv_sec: 0,
                tv_usec: EVENT_SLICE.as_micros() as _,
            };
            // SAFETY: live context (see `Device`); the timeval outlives the call.
            let code = unsafe {
                self.lib
                    .fns
                    .freenect_process_events_timeout(self.ctx, &mut timeout)
            };
            if code >= 0 {
                interrupted = 0;
            } else if code == LIBUSB_ERROR_INTERRUPTED && interrupted < MAX_INTERRUPTED {
                interrupted += 1;
            } else {
                streaming = false;
                let hint = if self.lib.is_fakenect() {
                    " (fakenect: the dump has been played to its end)"
                } else {
                    " (the Kinect was unplugged or lost power?)"
                };
                queue.end(KinectError::link_lost(format!(
                    "libfreenect's event loop stopped: freenect_process_events returned {code}{hint}"
                )));
            }
        }
        if let Some(pending) = tilt.take() {
            pending.reply.send(Err(KinectError::link_lost(
                "the Kinect was closed while its tilt motor was moving",
            )));
        }
        // SAFETY: live device; this thread is the only caller (see `Device`).
        unsafe { self.lib.fns.freenect_stop_depth(self.dev) };
        self.depth_stopped.store(true, Ordering::Release);
        SINK.with(|sink| *sink.borrow_mut() = None);
    }

    fn command(&self, command: Command, tilt: &mut Option<PendingTilt>) {
        match command {
            Command::SetTilt {
                degrees,
                timeout,
                reply,
            } => {
                // SAFETY: live device, event thread (see `Device`).
                let code = unsafe { self.lib.fns.freenect_set_tilt_degs(self.dev, degrees) };
                if code < 0 {
                    reply.send(Err(KinectError::call(
                        ErrorKind::LinkLost,
                        "freenect_set_tilt_degs",
                        code,
                        "the tilt motor did not take the command",
                    )));
                    return;
                }
                let now = Instant::now();
                if let Some(old) = tilt.replace(PendingTilt {
                    target: degrees,
                    started: now,
                    deadline: now + timeout,
                    last_poll: now,
                    seen_moving: false,
                    reply,
                }) {
                    old.reply.send(Err(KinectError::new(
                        ErrorKind::Refused,
                        format!("superseded by a tilt to {degrees}°"),
                    )));
                }
            }
            Command::TiltState { reply } => reply.send(self.tilt_state()),
            #[cfg(test)]
            Command::Panic => panic!("the event thread panics, as a test asked"),
            Command::SetLed { led, reply } => {
                let option = match led {
                    Led::Off => sys::freenect_led_options::LED_OFF,
                    Led::Green => sys::freenect_led_options::LED_GREEN,
                    Led::Red => sys::freenect_led_options::LED_RED,
                    Led::Yellow => sys::freenect_led_options::LED_YELLOW,
                    Led::BlinkGreen => sys::freenect_led_options::LED_BLINK_GREEN,
                    Led::BlinkRedYellow => sys::freenect_led_options::LED_BLINK_RED_YELLOW,
                };
                // SAFETY: live device, event thread (see `Device`).
                let code = unsafe { self.lib.fns.freenect_set_led(self.dev, option) };
                reply.send(if code < 0 {
                    Err(KinectError::call(
                        ErrorKind::LinkLost,
                        "freenect_set_led",
                        code,
                        "the LED did not take the command",
                    ))
                } else {
                    Ok(())
                });
            }
        }
    }

    /// Reads the motor and accelerometer now:
    /// (state, tilt in degrees, status code).
    fn read_tilt(&self) -> Result<(sys::freenect_raw_tilt_state, f64, u32), KinectError> {
        let fns = &self.lib.fns;
        // SAFETY: live device, event thread (see `Device`).
        let code = unsafe { fns.freenect_update_tilt_state(self.dev) };
        if code < 0 {
            return Err(KinectError::call(
                ErrorKind::LinkLost,
                "freenect_update_tilt_state",
                code,
                "the Kinect's motor did not answer",
            ));
        }
        // SAFETY: live device; libfreenect returns a pointer into the device.
        let ptr = unsafe { fns.freenect_get_tilt_state(self.dev) };
        if ptr.is_null() {
            return Err(KinectError::new(
                ErrorKind::Protocol,
                "freenect_get_tilt_state returned no state",
            ));
        }
        // SAFETY: non-null, points to the device's live, aligned state,
        // written only by this thread (inside libfreenect's calls).
        let mut state = unsafe { ptr.read() };
        // SAFETY: both read the copy through a valid pointer, nothing more.
        let degrees = unsafe { fns.freenect_get_tilt_degs(&mut state) };
        let status = unsafe { fns.freenect_get_tilt_status(&mut state) };
        Ok((state, degrees, status))
    }

    fn tilt_state(&self) -> Result<TiltState, KinectError> {
        let (state, tilt_deg, status) = self.read_tilt()?;
        let g = f64::from(sys::FREENECT_COUNTS_PER_G);
        Ok(TiltState {
            tilt_deg,
            accelerometer_g: [
                f64::from(state.accelerometer_x) / g,
                f64::from(state.accelerometer_y) / g,
                f64::from(state.accelerometer_z) / g,
            ],
            stopped: status != sys::freenect_tilt_status_code::TILT_STATUS_MOVING,
        })
    }

    fn poll_tilt(&self, tilt: &mut Option<PendingTilt>) {
        let Some(pending) = tilt.as_mut() else { return };
        let now = Instant::now();
        if now.duration_since(pending.last_poll) < TILT_POLL {
            return;
        }
        pending.last_poll = now;
        let outcome = match self.read_tilt() {
            Err(e) => Some(Err(e)),
            Ok((_, degrees, status)) => {
                use sys::freenect_tilt_status_code::{TILT_STATUS_LIMIT, TILT_STATUS_MOVING};
                if status == TILT_STATUS_MOVING {
                    pending.seen_moving = true;
                }
                let settled = status != TILT_STATUS_MOVING
                    && (pending.seen_moving || now.duration_since(pending.started) >= TILT_START);
                if settled && status == TILT_STATUS_LIMIT && (degrees - pending.target).abs() > 2.0
                {
                    Some(Err(KinectError::new(
                        ErrorKind::Refused,
                        format!(
                            "the tilt motor stopped at its limit at {degrees:.1}°, short of {:.1}° \
                             (is something blocking the Kinect?)",
                            pending.target
                        ),
                    )))
                } else if settled {
                    Some(Ok(()))
                } else if now >= pending.deadline {
                    Some(Err(KinectError::new(
                        ErrorKind::Timeout,
                        format!(
                            "the tilt motor had not stopped {:.1} s after it was sent to {:.1}° (at {degrees:.1}°)",
                            now.duration_since(pending.started).as_secs_f64(),
                            pending.target
                        ),
                    )))
                } else {
                    None
                }
            }
        };
        if let Some(result) = outcome {
            if let Some(done) = tilt.take() {
                done.reply.send(result);
            }
        }
    }
}

/// libfreenect's depth callback: copies the frame into the queue.
extern "C" fn depth_callback(_dev: *mut sys::freenect_device, data: *mut c_void, timestamp: u32) {
    let time_s = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    // Nothing may unwind into C: a panic here loses the frame, nothing else.
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        if data.is_null() {
            return;
        }
        // SAFETY: libfreenect lends the frame buffer of the depth mode set
        // by `Device::open` (checked: 640×480 11-bit, FRAME_BYTES bytes) for
        // the time of this call; it is only read here, as bytes (no
        // alignment needed).
        let bytes = unsafe { std::slice::from_raw_parts(data.cast::<u8>(), FRAME_BYTES) };
        // libfreenect unpacks 11-bit depth into native-endian u16.
        let raw: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|b| u16::from_ne_bytes([b[0], b[1]]))
            .collect();
        let frame = DepthFrame {
            timestamp,
            time_s,
            width: WIDTH,
            height: HEIGHT,
            raw,
        };
        let _ = SINK.try_with(|sink| {
            if let Some(queue) = sink.borrow().as_ref() {
                queue.push(frame);
            }
        });
    }));
}
