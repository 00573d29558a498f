//! The Kinect driver (`groundcal_hal::kinect`) and `groundcal capture`
//! against libfreenect's own fakenect library, which plays a dump back as if
//! a Kinect were plugged in: the frames arrive byte for byte as in the dump.
//!
//! The dump is the first six depth frames (and their tilt snapshots) of the
//! shared sample recording. fakenect keeps its state in globals and exits
//! the process on a bad dump, so each run with it is a process of its own:
//! this test binary re-runs itself, or runs `groundcal capture`.
//!
//! Needs Debian's `libfreenect0.5` (the fakenect library, in
//! `/usr/lib/<arch>/fakenect/`). Without it the fakenect tests fail under
//! `CI=true` and warn and pass otherwise.

mod common;

use common::TempDir;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use groundcal::formats::recording::dump::{parse_entry_name, EntryKind, RawTiltState};
use groundcal::formats::recording::Recording;
use groundcal_hal::error::Error as _;
use groundcal_hal::kinect::{Kinect, LIBFREENECT_PACKAGE};
use groundcal_hal::{DepthSensor, ErrorKind, Led};

/// Depth frames in the dump; the tests take the first five.
const DUMP_FRAMES: usize = 6;
const CAPTURED: usize = 5;
/// The header of a fakenect depth file.
const PGM_HEADER: &[u8] = b"P5 640 480 65535\n";
/// A run with fakenect takes well under a second; this bounds a hang.
const RUN_TIMEOUT: Duration = Duration::from_secs(60);

/// Set in the re-run child: the fakenect library to open.
const CHILD_LIB_ENV: &str = "GROUNDCAL_TEST_FAKENECT_CHILD_LIB";

/// fakenect's library, or `None` after a loud warning (a failure under CI).
fn fakenect_library() -> Option<PathBuf> {
    if let Some(lib) = groundcal_hal::kinect::find_fakenect_library() {
        return Some(lib);
    }
    let message = format!(
        "libfreenect's fakenect library is not installed: install the Debian package \
         {LIBFREENECT_PACKAGE} (`apt-get install -y {LIBFREENECT_PACKAGE}`; it ships \
         /usr/lib/<arch>/fakenect/libfreenect.so.0.5)"
    );
    common::prerequisite_missing("the Kinect fakenect test", &message);
    None
}

/// One depth frame of the dump.
struct DumpFrame {
    timestamp: u32,
    bytes: Vec<u8>,
}

/// What a dump holds: its depth frames, and its tilt snapshots' bytes.
struct Dump {
    frames: Vec<DumpFrame>,
    tilt_states: HashSet<Vec<u8>>,
}

fn sample_kinect() -> PathBuf {
    common::shared().join("data/sample-12/kinect")
}

/// Reads a dump's INDEX.txt and files.
fn read_dump(dir: &Path) -> Dump {
    let index = std::fs::read_to_string(dir.join("INDEX.txt")).unwrap();
    let mut dump = Dump {
        frames: Vec::new(),
        tilt_states: HashSet::new(),
    };
    for name in index.lines() {
        let entry = parse_entry_name(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        let bytes = std::fs::read(dir.join(name)).unwrap();
        match entry.kind {
            EntryKind::Depth => dump.frames.push(DumpFrame {
                timestamp: entry.timestamp,
                bytes,
            }),
            EntryKind::Accelerometer => {
                dump.tilt_states.insert(bytes);
            }
            EntryKind::Rgb => panic!("{name}: no RGB expected"),
        }
    }
    dump
}

/// Copies the sample's INDEX.txt lines, and their files, up to its
/// `DUMP_FRAMES`-th depth frame, into `dir`.
fn make_dump(dir: &Path) -> Dump {
    std::fs::create_dir_all(dir).unwrap();
    let source = sample_kinect();
    let index = std::fs::read_to_string(source.join("INDEX.txt")).unwrap();
    let mut lines = String::new();
    let mut frames = 0;
    for name in index.lines() {
        std::fs::copy(source.join(name), dir.join(name)).unwrap();
        lines.push_str(name);
        lines.push('\n');
        if name.starts_with("d-") {
            frames += 1;
            if frames == DUMP_FRAMES {
                break;
            }
        }
    }
    assert_eq!(frames, DUMP_FRAMES, "the sample has too few frames");
    std::fs::write(dir.join("INDEX.txt"), lines).unwrap();
    let dump = read_dump(dir);
    assert!(
        !dump.tilt_states.is_empty(),
        "the sample has tilt snapshots"
    );
    dump
}

/// Runs `command` to its end within [`RUN_TIMEOUT`].
fn run_bounded(mut command: Command) -> Output {
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Drain the pipes on threads, so that a chatty child cannot block.
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let out = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut stdout, &mut v).map(|_| v)
    });
    let err = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut stderr, &mut v).map(|_| v)
    });
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > RUN_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{command:?} did not finish within {RUN_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: out.join().unwrap().unwrap(),
        stderr: err.join().unwrap().unwrap(),
    }
}

fn describe(output: &Output) -> String {
    format!(
        "{}\n--- stdout\n{}\n--- stderr\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// The raw values of a fakenect depth file (little-endian after the header).
fn raw_values(file: &[u8]) -> Vec<u16> {
    assert!(file.starts_with(PGM_HEADER));
    file[PGM_HEADER.len()..]
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect()
}

#[test]
fn opening_a_library_that_is_not_there_is_device_missing_naming_the_package() {
    let path = Path::new("/nonexistent/groundcal/libfreenect.so.0.5");
    let err = Kinect::open(Some(path), 0).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::DeviceMissing);
    assert!(err.is_library_missing());
    let message = err.to_string();
    assert!(
        message.contains("apt-get install libfreenect0.5")
            && message.contains(&*path.to_string_lossy()),
        "{message}"
    );
}

/// In the parent: makes the dump and re-runs this test in a child process
/// with fakenect playing it. In the child: opens the Kinect through fakenect
/// and checks every frame, the motor, the LED and the end of the dump.
#[test]
fn the_kinect_delivers_a_fakenect_dump_byte_for_byte() {
    if let Some(lib) = std::env::var_os(CHILD_LIB_ENV) {
        return kinect_child(Path::new(&lib));
    }
    let Some(lib) = fakenect_library() else {
        return;
    };
    let tmp = TempDir::new("kinect-fakenect");
    let dump_dir = tmp.path().join("dump");
    make_dump(&dump_dir);
    let mut command = Command::new(std::env::current_exe().unwrap());
    command
        .args([
            "--exact",
            "the_kinect_delivers_a_fakenect_dump_byte_for_byte",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_LIB_ENV, &lib)
        .env("FAKENECT_PATH", &dump_dir)
        // Newer fakenect loops the dump unless told not to; 0.5 plays it once.
        .env("FAKENECT_LOOP", "0");
    let output = run_bounded(command);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success() && stdout.contains("test result: ok. 1 passed"),
        "the child run with fakenect failed: {}",
        describe(&output)
    );
}

fn kinect_child(lib: &Path) {
    let dump_dir = PathBuf::from(std::env::var_os("FAKENECT_PATH").unwrap());
    let dump = read_dump(&dump_dir);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let mut kinect = Kinect::open(Some(lib), 0).unwrap_or_else(|e| panic!("{e}"));
    assert!(kinect.is_fakenect(), "{} is fakenect", lib.display());
    assert_eq!(kinect.library(), lib);
    let info = kinect.info();
    assert_eq!(
        info.depth_model,
        groundcal_calib::depth::DepthModel::default()
    );
    assert_eq!(
        info.intrinsics,
        groundcal_calib::depth::Intrinsics::default()
    );

    runtime.block_on(async {
        let started = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64();
        for (k, expected) in dump.frames.iter().take(CAPTURED).enumerate() {
            let frame = kinect
                .next_frame()
                .await
                .unwrap_or_else(|e| panic!("frame {k}: {e}"));
            assert_eq!((frame.width, frame.height), (640, 480), "frame {k}");
            assert_eq!(frame.timestamp, expected.timestamp, "frame {k}: timestamp");
            assert!(
                frame.raw == raw_values(&expected.bytes),
                "frame {k}: values differ from the dump's"
            );
            assert!(
                (frame.time_s - started).abs() < 30.0,
                "frame {k}: host time {} is not now",
                frame.time_s
            );
        }

        // The accelerometer and motor as the dump's snapshots say (fakenect
        // keeps the last one it played).
        let tilt = kinect.tilt_state().await.unwrap();
        let raw = RawTiltState {
            accelerometer: tilt.accelerometer_g.map(|g| (g * 819.0).round() as i16),
            tilt_angle: (tilt.tilt_deg * 2.0).round() as i8,
            tilt_status: if tilt.stopped { 0 } else { 4 },
        }
        .encode()
        .to_vec();
        assert!(
            dump.tilt_states.contains(&raw),
            "tilt state {tilt:?} is none of the dump's"
        );
        assert_eq!(tilt.tilt_deg, -20.0);
        assert!(tilt.stopped);
        kinect.set_tilt(-20.0).await.unwrap();
        let err = kinect.set_tilt(40.0).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Refused, "{err}");
        kinect.set_led(Led::Green).await.unwrap();

        // The sixth frame, then the end of the dump.
        let sixth = kinect.next_frame().await.unwrap();
        assert_eq!(sixth.timestamp, dump.frames[CAPTURED].timestamp);
        assert!(sixth.raw == raw_values(&dump.frames[CAPTURED].bytes));
        let end = kinect.next_frame().await.unwrap_err();
        assert_eq!(end.kind(), ErrorKind::LinkLost, "{end}");
        assert!(end.to_string().contains("end"), "{end}");
        // The motor still answers after the stream has ended.
        kinect.tilt_state().await.unwrap();
    });
    let counts = kinect.frame_counts();
    assert_eq!((counts.received, counts.dropped), (DUMP_FRAMES as u64, 0));
    assert!(kinect.has_ended());
    let closing = Instant::now();
    drop(kinect);
    assert!(
        closing.elapsed() < Duration::from_secs(5),
        "closing took {:?}",
        closing.elapsed()
    );
}

#[test]
fn capture_records_a_fakenect_dump_byte_for_byte() {
    let Some(lib) = fakenect_library() else {
        return;
    };
    let tmp = TempDir::new("capture");
    let dump_dir = tmp.path().join("dump");
    let dump = make_dump(&dump_dir);
    let out = tmp.path().join("recording");
    let mut command = Command::new(env!("CARGO_BIN_EXE_groundcal"));
    command
        .arg("capture")
        .arg("--freenect-lib")
        .arg(&lib)
        .args(["--frames", &CAPTURED.to_string(), "--out"])
        .arg(&out)
        .env("FAKENECT_PATH", &dump_dir)
        .env("FAKENECT_LOOP", "0");
    let output = run_bounded(command);
    assert!(
        output.status.success(),
        "groundcal capture: {}",
        describe(&output)
    );

    let recording = Recording::open(&out).unwrap_or_else(|e| panic!("{e}"));
    assert!(recording.poses.is_empty());
    assert_eq!(recording.session.robot, "none");
    assert_eq!(recording.session.kinect.tilt_deg, -20.0);
    let written = read_dump(&out.join("kinect"));
    assert_eq!(written.frames.len(), CAPTURED);
    for (k, (ours, theirs)) in written.frames.iter().zip(&dump.frames).enumerate() {
        assert_eq!(ours.timestamp, theirs.timestamp, "frame {k}: timestamp");
        assert!(
            ours.bytes == theirs.bytes,
            "frame {k}: file differs from the dump's"
        );
    }
    assert_eq!(written.tilt_states.len(), 1);
    assert!(written.tilt_states.is_subset(&dump.tilt_states));
    // Names' times never decrease (fakenect's playback waits for them).
    let index = recording.index.iter().map(|e| e.time).collect::<Vec<_>>();
    assert!(index.windows(2).all(|w| w[0] <= w[1]), "{index:?}");
}

#[test]
fn capture_without_libfreenect_exits_1_naming_the_package() {
    let tmp = TempDir::new("missing");
    let out = tmp.path().join("recording");
    let (code, _, stderr) = common::groundcal(&[
        "capture",
        "--freenect-lib",
        "/nonexistent/groundcal/libfreenect.so.0.5",
        "--frames",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("apt-get install libfreenect0.5")
            && stderr.contains("/nonexistent/groundcal/libfreenect.so.0.5"),
        "{stderr}"
    );
    assert!(
        !out.exists(),
        "nothing is written when the sensor cannot be opened"
    );
}

#[test]
fn capture_refuses_bad_arguments_with_exit_2() {
    let tmp = TempDir::new("usage");
    let full = tmp.path().join("full");
    std::fs::create_dir_all(&full).unwrap();
    std::fs::write(full.join("keep.txt"), "mine").unwrap();
    let (code, _, stderr) =
        common::groundcal(&["capture", "--frames", "3", "--out", full.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("not empty") && stderr.contains("--out"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(full.join("keep.txt")).unwrap(),
        "mine"
    );

    let out = tmp.path().join("none");
    let (code, _, stderr) =
        common::groundcal(&["capture", "--frames", "0", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--frames"), "{stderr}");
}
