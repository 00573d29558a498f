use std::future::Future;
use std::pin::pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll, Wake, Waker};
use std::time::Duration;

use super::queue::{reply, FrameQueue};
use super::*;
use crate::error::Error as _;

/// Counts its wakes.
struct CountingWaker(AtomicUsize);

impl Wake for CountingWaker {
    fn wake(self: Arc<Self>) {
        self.0.fetch_add(1, Ordering::SeqCst);
    }
}

fn waker() -> (Arc<CountingWaker>, Waker) {
    let w = Arc::new(CountingWaker(AtomicUsize::new(0)));
    (w.clone(), Waker::from(w))
}

fn frame(timestamp: u32) -> DepthFrame {
    DepthFrame {
        timestamp,
        time_s: f64::from(timestamp),
        width: 2,
        height: 1,
        raw: vec![timestamp as u16, 2047],
    }
}

#[test]
fn a_missing_library_is_device_missing_naming_the_package_and_the_path() {
    let path = Path::new("/nonexistent/groundcal-test/libfreenect.so.0.5");
    let err = Kinect::open(Some(path), 0).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::DeviceMissing);
    let message = err.to_string();
    assert!(
        message.contains("apt-get install libfreenect0.5")
            && message.contains("/nonexistent/groundcal-test/libfreenect.so.0.5"),
        "{message}"
    );
}

#[test]
fn a_library_that_is_not_libfreenect_is_refused_by_name() {
    // glibc's math library loads everywhere this runs, and is no libfreenect.
    let err = Kinect::open(Some(Path::new("libm.so.6")), 0).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::DeviceMissing);
    let message = err.to_string();
    assert!(
        message.contains("libm.so.6")
            && message.contains("freenect_init")
            && message.contains("libfreenect0.5"),
        "{message}"
    );
}

#[test]
fn the_queue_drops_the_oldest_frame_when_full_and_counts_it() {
    let queue = FrameQueue::new(3);
    for t in 1..=5 {
        queue.push(frame(t));
    }
    assert_eq!(queue.counts(), (5, 2));
    let (_, w) = waker();
    let mut cx = Context::from_waker(&w);
    for t in 3..=5 {
        match queue.poll_frame(&mut cx) {
            Poll::Ready(Ok(f)) => assert_eq!(f.timestamp, t),
            other => panic!("frame {t}: {other:?}"),
        }
    }
    assert!(queue.poll_frame(&mut cx).is_pending());
}

#[test]
fn a_waiting_task_is_woken_by_a_frame_then_by_the_end_after_the_queued_frames() {
    let queue = FrameQueue::new(4);
    let (count, w) = waker();
    let mut cx = Context::from_waker(&w);
    assert!(queue.poll_frame(&mut cx).is_pending());
    queue.push(frame(7));
    assert_eq!(count.0.load(Ordering::SeqCst), 1);
    queue.push(frame(8));
    queue.end(KinectError::link_lost("gone"));
    assert!(matches!(queue.poll_frame(&mut cx), Poll::Ready(Ok(f)) if f.timestamp == 7));
    assert!(matches!(queue.poll_frame(&mut cx), Poll::Ready(Ok(f)) if f.timestamp == 8));
    match queue.poll_frame(&mut cx) {
        Poll::Ready(Err(e)) => {
            assert_eq!(e.kind(), ErrorKind::LinkLost);
            assert_eq!(e.to_string(), "gone");
        }
        other => panic!("{other:?}"),
    }
    assert!(queue.has_ended());
}

#[test]
fn a_wait_longer_than_the_timeout_fails_with_timeout() {
    let queue = FrameQueue::new(2);
    let (count, w) = waker();
    let mut cx = Context::from_waker(&w);
    assert!(queue.poll_frame(&mut cx).is_pending());
    queue.check_timeout(Duration::from_secs(60));
    assert_eq!(count.0.load(Ordering::SeqCst), 0);
    std::thread::sleep(Duration::from_millis(5));
    queue.check_timeout(Duration::from_millis(1));
    assert_eq!(count.0.load(Ordering::SeqCst), 1);
    match queue.poll_frame(&mut cx) {
        Poll::Ready(Err(e)) => assert_eq!(e.kind(), ErrorKind::Timeout),
        other => panic!("{other:?}"),
    }
    // The next wait starts afresh.
    assert!(queue.poll_frame(&mut cx).is_pending());
    queue.push(frame(1));
    assert!(matches!(queue.poll_frame(&mut cx), Poll::Ready(Ok(_))));
}

#[test]
fn a_reply_dropped_unsent_resolves_to_none() {
    let (_, w) = waker();
    let mut cx = Context::from_waker(&w);
    let (sender, receiver) = reply::<u32>();
    let mut receiver = pin!(receiver);
    assert!(receiver.as_mut().poll(&mut cx).is_pending());
    sender.send(5);
    assert_eq!(receiver.as_mut().poll(&mut cx), Poll::Ready(Some(5)));

    let (sender, receiver) = reply::<u32>();
    let mut receiver = pin!(receiver);
    assert!(receiver.as_mut().poll(&mut cx).is_pending());
    drop(sender);
    assert_eq!(receiver.as_mut().poll(&mut cx), Poll::Ready(None));
}

#[test]
fn the_default_library_without_a_kinect_is_device_missing_or_absent() {
    // With libfreenect installed and no Kinect plugged in, libfreenect finds
    // no device (or cannot start USB at all in a container); without it,
    // the library is missing. Either way nothing panics or hangs.
    match Kinect::open(None, 0) {
        Ok(kinect) => {
            // A Kinect (or fakenect on the loader's path) is really there.
            drop(kinect);
        }
        Err(e) => assert!(
            matches!(e.kind(), ErrorKind::DeviceMissing | ErrorKind::Other),
            "{e}"
        ),
    }
}

// ---------------------------------------------------------------------------
// With libfreenect's fakenect (Debian's libfreenect0.5). fakenect keeps its
// state in globals and exits the process on a bad dump, so each run is a
// child process: the test re-runs itself with `CHILD_ENV` set to the case.

const CHILD_ENV: &str = "GROUNDCAL_HAL_TEST_FAKENECT_CHILD";
const CHILD_LIB_ENV: &str = "GROUNDCAL_HAL_TEST_FAKENECT_LIB";

/// fakenect's library, or `None` after a loud warning (a failure under CI).
fn fakenect_library() -> Option<std::path::PathBuf> {
    let found = super::find_fakenect_library();
    if found.is_none() {
        let message = format!(
            "libfreenect's fakenect library is not installed: install the Debian package \
             {LIBFREENECT_PACKAGE} (`apt-get install -y {LIBFREENECT_PACKAGE}`)"
        );
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("{message}");
        }
        use std::io::Write;
        let bar = "!".repeat(78);
        let _ = writeln!(
            std::io::stderr(),
            "\n{bar}\nWARNING: Kinect fakenect test NOT RUN: {message}\n{bar}\n"
        );
    }
    found
}

/// A dump of `frames` depth frames `gap_s` apart, every pixel of frame k
/// equal to 500 + k, in a fresh directory.
fn synthetic_dump(tag: &str, frames: u32, gap_s: f64) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "groundcal-hal-fakenect-{tag}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut index = String::new();
    for k in 0..frames {
        let name = format!("d-{:.6}-{}.pgm", 1000.0 + gap_s * f64::from(k), 100 + k);
        let mut bytes = b"P5 640 480 65535\n".to_vec();
        let value = (500 + k) as u16;
        bytes.extend((0..FRAME_WIDTH * FRAME_HEIGHT).flat_map(|_| value.to_le_bytes()));
        std::fs::write(dir.join(&name), bytes).unwrap();
        index.push_str(&name);
        index.push('\n');
    }
    std::fs::write(dir.join("INDEX.txt"), index).unwrap();
    dir
}

/// Re-runs `test` in a child with `case`, the fakenect library and `env`.
fn run_child(test: &str, case: &str, lib: &Path, env: &[(&str, Option<&Path>)]) {
    let mut command = std::process::Command::new(std::env::current_exe().unwrap());
    command
        .args(["--exact", test, "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, case)
        .env(CHILD_LIB_ENV, lib)
        .env("FAKENECT_LOOP", "0")
        .stdin(std::process::Stdio::null());
    for (key, value) in env {
        match value {
            Some(v) => command.env(key, v),
            None => command.env_remove(key),
        };
    }
    let mut child = command
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("the child run of {test} ({case}) hung");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let output = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success() && stdout.contains("test result: ok. 1 passed"),
        "the child run of {test} ({case}) failed: {}\n--- stdout\n{stdout}\n--- stderr\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
}

fn block_on<F: Future>(future: F) -> F::Output {
    struct Unpark(std::thread::Thread);
    impl Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
    }
    let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = Context::from_waker(&waker);
    let mut future = pin!(future);
    loop {
        if let Poll::Ready(v) = future.as_mut().poll(&mut cx) {
            return v;
        }
        std::thread::park();
    }
}

#[test]
fn the_kinect_is_send() {
    fn send<T: Send>() {}
    send::<Kinect>();
}

#[test]
fn fakenect_without_a_dump_is_an_error_not_an_exit() {
    const TEST: &str = "kinect::tests::fakenect_without_a_dump_is_an_error_not_an_exit";
    if let Ok(case) = std::env::var(CHILD_ENV) {
        let lib = std::path::PathBuf::from(std::env::var_os(CHILD_LIB_ENV).unwrap());
        let err = Kinect::open(Some(&lib), 0).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::DeviceMissing, "{err}");
        let expected = match case.as_str() {
            "unset" => "set FAKENECT_PATH",
            "missing-frame" => "is not in the dump",
            other => panic!("case {other}"),
        };
        assert!(err.to_string().contains(expected), "{err}");
        return;
    }
    let Some(lib) = fakenect_library() else {
        return;
    };
    run_child(TEST, "unset", &lib, &[("FAKENECT_PATH", None)]);
    let dump = synthetic_dump("missing-frame", 2, 0.01);
    let index = std::fs::read_to_string(dump.join("INDEX.txt")).unwrap();
    std::fs::remove_file(dump.join(index.lines().nth(1).unwrap())).unwrap();
    run_child(
        TEST,
        "missing-frame",
        &lib,
        &[("FAKENECT_PATH", Some(&dump))],
    );
    let _ = std::fs::remove_dir_all(&dump);
}

#[test]
fn a_panicked_event_thread_ends_the_stream_and_the_kinect_still_closes() {
    const TEST: &str =
        "kinect::tests::a_panicked_event_thread_ends_the_stream_and_the_kinect_still_closes";
    if std::env::var_os(CHILD_ENV).is_some() {
        let lib = std::path::PathBuf::from(std::env::var_os(CHILD_LIB_ENV).unwrap());
        let mut kinect = Kinect::open(Some(&lib), 0).unwrap_or_else(|e| panic!("{e}"));
        let first = block_on(kinect.next_frame()).unwrap();
        assert_eq!(first.timestamp, 100);
        assert!(first.raw.iter().all(|&v| v == 500));
        kinect
            .commands
            .as_ref()
            .unwrap()
            .send(ffi::Command::Panic)
            .unwrap();
        // Frames already queued may come first; then the end, saying why.
        let err = loop {
            match block_on(kinect.next_frame()) {
                Ok(_) => continue,
                Err(e) => break e,
            }
        };
        assert_eq!(err.kind(), ErrorKind::LinkLost, "{err}");
        assert!(err.to_string().contains("panicked"), "{err}");
        let err = block_on(kinect.tilt_state()).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::LinkLost, "{err}");
        // Dropping joins the panicked thread, then stops depth, closes the
        // device and shuts the context down, promptly.
        let closing = std::time::Instant::now();
        drop(kinect);
        assert!(closing.elapsed() < Duration::from_secs(5));
        return;
    }
    let Some(lib) = fakenect_library() else {
        return;
    };
    // Frames 0.3 s apart: the stream is still going when the thread panics.
    let dump = synthetic_dump("panic", 4, 0.3);
    run_child(TEST, "panic", &lib, &[("FAKENECT_PATH", Some(&dump))]);
    let _ = std::fs::remove_dir_all(&dump);
}

#[test]
fn a_wait_given_up_does_not_time_out_the_next_one() {
    let queue = FrameQueue::new(2);
    let (count, w) = waker();
    let mut cx = Context::from_waker(&w);
    {
        let mut wait = pin!(queue.next_frame());
        assert!(wait.as_mut().poll(&mut cx).is_pending());
        std::thread::sleep(Duration::from_millis(5));
        // The caller gives up (a select!, a timeout of its own).
    }
    queue.check_timeout(Duration::from_millis(1));
    assert_eq!(count.0.load(Ordering::SeqCst), 0, "nobody waits");
    let mut wait = pin!(queue.next_frame());
    assert!(wait.as_mut().poll(&mut cx).is_pending());
    queue.push(frame(3));
    assert!(matches!(wait.as_mut().poll(&mut cx), Poll::Ready(Ok(f)) if f.timestamp == 3));
}
