//! A recording written by groundcal is a fakenect dump by libfreenect's own
//! reckoning: its `kinect/` is played by libfreenect's `fakenect` library into
//! libfreenect's `fakenect-record`, and what that records is byte for byte
//! what groundcal wrote. The other way round, the dump `fakenect-record`
//! writes is a valid depth part of a recording.
//!
//! Needs Debian's `libfreenect0.5` (the fakenect library, in
//! `/usr/lib/<arch>/fakenect/`) and `libfreenect-bin` (`fakenect-record` and
//! the `fakenect` wrapper script). Without them the test fails under `CI=true`
//! and warns and passes otherwise.

mod common;

use common::TempDir;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use groundcal::formats::recording::dump::{parse_index, EntryKind, RawTiltState};
use groundcal::formats::recording::writer::{entry_name, RecordingWriter};
use groundcal::formats::recording::Recording;

/// fakenect-record plays a few frames in well under a second; this bounds a hang.
const PLAYBACK_TIMEOUT: Duration = Duration::from_secs(60);

/// Seconds between entries of the dump: fakenect's playback waits for them.
const STEP_S: f64 = 0.01;

struct Fakenect {
    /// libfreenect-bin's `fakenect-record`.
    record: PathBuf,
    /// libfreenect0.5's directory holding fakenect's `libfreenect.so.0.5`.
    lib_dir: PathBuf,
}

fn find_in_path(program: &str) -> Option<PathBuf> {
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|dir| dir.join(program))
        .find(|p| p.is_file())
}

fn holds_libfreenect(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().any(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("libfreenect.so")
        })
    })
}

/// fakenect's library directory: `GROUNDCAL_FAKENECT_LIB_DIR`, else the one the
/// `fakenect` wrapper script puts in `LD_LIBRARY_PATH`, else the usual places.
fn find_fakenect_lib(record: Option<&Path>) -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("GROUNDCAL_FAKENECT_LIB_DIR") {
        return Some(PathBuf::from(dir)).filter(|d| holds_libfreenect(d));
    }
    let wrapper = record
        .and_then(|r| r.parent())
        .map(|bin| bin.join("fakenect"))
        .or_else(|| find_in_path("fakenect"));
    if let Some(text) = wrapper.and_then(|w| std::fs::read_to_string(w).ok()) {
        for (i, key) in text.match_indices("LD_LIBRARY_PATH=\"") {
            let rest = &text[i + key.len()..];
            let dir = PathBuf::from(rest.split([':', '"']).next().unwrap_or(""));
            if holds_libfreenect(&dir) {
                return Some(dir);
            }
        }
    }
    let mut candidates = vec![
        PathBuf::from("/usr/lib/fakenect"),
        PathBuf::from("/usr/local/lib/fakenect"),
    ];
    for lib in ["/usr/lib", "/usr/local/lib"] {
        if let Ok(entries) = std::fs::read_dir(lib) {
            candidates.extend(entries.flatten().map(|e| e.path().join("fakenect")));
        }
    }
    candidates.into_iter().find(|d| holds_libfreenect(d))
}

/// libfreenect's tools, or `None` after a loud warning (a failure under CI).
fn fakenect() -> Option<Fakenect> {
    let record = find_in_path("fakenect-record");
    let lib_dir = find_fakenect_lib(record.as_deref());
    let mut missing = Vec::new();
    if record.is_none() {
        missing.push("libfreenect-bin (fakenect-record)");
    }
    if lib_dir.is_none() {
        missing.push("libfreenect0.5 (the fakenect library, /usr/lib/<arch>/fakenect/)");
    }
    match (record, lib_dir) {
        (Some(record), Some(lib_dir)) => Some(Fakenect { record, lib_dir }),
        _ => {
            let message = format!(
                "libfreenect's fakenect is not installed: missing the Debian package(s) {}; \
                 install them with `apt-get install -y libfreenect0.5 libfreenect-bin`",
                missing.join(" and ")
            );
            common::prerequisite_missing("the fakenect round trip", &message);
            None
        }
    }
}

/// One file of a dump: its kind, timestamp and bytes.
#[derive(Debug, Clone, PartialEq)]
struct Entry {
    name: String,
    kind: EntryKind,
    timestamp: u32,
    bytes: Vec<u8>,
}

fn read_dump(kinect: &Path) -> Vec<Entry> {
    let index_path = kinect.join("INDEX.txt");
    let text = std::fs::read_to_string(&index_path).unwrap();
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{}: last line unterminated",
        index_path.display()
    );
    assert!(
        !text.contains("\n\n") && !text.contains('\r'),
        "{}: blank line or CR",
        index_path.display()
    );
    parse_index(&index_path, &text)
        .unwrap_or_else(|e| panic!("{e}"))
        .into_iter()
        .map(|e| {
            let ext = match e.kind {
                EntryKind::Depth => "pgm",
                EntryKind::Accelerometer => "dump",
                EntryKind::Rgb => "ppm",
            };
            let kind_char = e.name.chars().next().unwrap();
            // Names are record.c's "%c-%f-%u.%s", as groundcal makes them.
            assert_eq!(entry_name(kind_char, e.time, e.timestamp, ext), e.name);
            Entry {
                bytes: std::fs::read(kinect.join(&e.name)).unwrap(),
                name: e.name,
                kind: e.kind,
                timestamp: e.timestamp,
            }
        })
        .collect()
}

/// Runs `fakenect-record out` with fakenect playing `dump`, to its end.
fn replay_through_fakenect(tools: &Fakenect, dump: &Path, out: &Path, log: &Path) {
    let mut ld_path = tools.lib_dir.clone().into_os_string();
    if let Some(old) = std::env::var_os("LD_LIBRARY_PATH").filter(|v| !v.is_empty()) {
        ld_path.push(":");
        ld_path.push(old);
    }
    let log_file = std::fs::File::create(log).unwrap();
    let mut child = Command::new(&tools.record)
        .arg(out)
        .env("FAKENECT_PATH", dump)
        .env("LD_LIBRARY_PATH", ld_path)
        // Newer fakenect loops the dump unless told not to; 0.5 ignores it.
        .env("FAKENECT_LOOP", "0")
        .stdin(Stdio::null())
        .stdout(log_file.try_clone().unwrap())
        .stderr(log_file)
        .spawn()
        .unwrap_or_else(|e| panic!("{}: cannot run: {e}", tools.record.display()));
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > PLAYBACK_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "fakenect-record did not stop within {PLAYBACK_TIMEOUT:?} of playing the dump; log:\n{}",
                std::fs::read_to_string(log).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let log_text = std::fs::read_to_string(log).unwrap_or_default();
    assert!(
        status.success(),
        "fakenect-record: {status}; log:\n{log_text}"
    );
    assert!(
        !log_text.contains("Error"),
        "fakenect-record reported an error; log:\n{log_text}"
    );
}

#[test]
fn fakenect_plays_our_recording_into_fakenect_record_unchanged() {
    let Some(tools) = fakenect() else { return };
    let source = Recording::open(&common::shared().join("data/sample-12")).unwrap();
    let tmp = TempDir::new("fakenect");

    // Our recording: three poses of two frames, each frame followed by a tilt
    // state stamped with its timestamp, as record.c does.
    let ours = tmp.path().join("ours");
    let mut writer = RecordingWriter::create(&ours, &source.session).unwrap();
    let mut t = 1_700_000_000.0;
    let mut states = Vec::new();
    for (p, pose) in source.poses.iter().take(3).enumerate() {
        let mut names = Vec::new();
        for (f, sample_name) in pose.depth_frames.iter().enumerate() {
            let k = (2 * p + f) as i16;
            let (image, _) = source.read_depth_frame(sample_name).unwrap();
            let timestamp = 1_000_000 + 33_367 * k as u32;
            t += STEP_S;
            names.push(writer.write_depth_frame(t, timestamp, &image).unwrap());
            let state = RawTiltState {
                accelerometer: [10 * k - 25, 819 - 3 * k, -7 * k],
                tilt_angle: -40 + k as i8,
                tilt_status: if k % 2 == 0 { 0 } else { 4 },
            };
            t += STEP_S;
            writer.write_tilt_state(t, timestamp, &state).unwrap();
            states.push(state.encode().to_vec());
        }
        let mut record = pose.clone();
        record.depth_frames = names;
        writer.write_pose(&record).unwrap();
    }
    writer.finish().unwrap();
    let ours_dump = read_dump(&ours.join("kinect"));
    let our_depth: Vec<&Entry> = ours_dump
        .iter()
        .filter(|e| e.kind == EntryKind::Depth)
        .collect();
    assert_eq!(our_depth.len(), 6);

    // Played by libfreenect's fakenect into libfreenect's fakenect-record,
    // which stops by itself at the end of the dump.
    let rerecorded = tmp.path().join("rerecorded");
    replay_through_fakenect(
        &tools,
        &ours.join("kinect"),
        &rerecorded,
        &tmp.path().join("fakenect-record.log"),
    );
    let theirs = read_dump(&rerecorded);
    assert!(
        theirs.iter().all(|e| e.kind != EntryKind::Rgb),
        "fakenect-record wrote RGB though the dump has none"
    );
    let their_depth: Vec<&Entry> = theirs
        .iter()
        .filter(|e| e.kind == EntryKind::Depth)
        .collect();
    assert_eq!(
        their_depth.len(),
        our_depth.len(),
        "fakenect-record recorded {} depth frames of our {}: {:?}",
        their_depth.len(),
        our_depth.len(),
        theirs.iter().map(|e| &e.name).collect::<Vec<_>>()
    );
    for (k, (mine, theirs)) in our_depth.iter().zip(&their_depth).enumerate() {
        assert_eq!(
            mine.timestamp, theirs.timestamp,
            "depth frame {k}: timestamp"
        );
        assert!(
            mine.bytes == theirs.bytes,
            "depth frame {k}: {} re-recorded as {} differs",
            mine.name,
            theirs.name
        );
    }
    // The tilt states reach fakenect-record in order, each stamped (as
    // record.c does) with the last depth frame's timestamp.
    let mut last_depth = None;
    let mut next_state = 0;
    for e in &theirs {
        match e.kind {
            EntryKind::Depth => last_depth = Some(e.timestamp),
            _ => {
                assert_eq!(
                    e.bytes.len(),
                    12,
                    "{}: not a freenect_raw_tilt_state",
                    e.name
                );
                assert_eq!(Some(e.timestamp), last_depth, "{}: stamp", e.name);
                if states.get(next_state) == Some(&e.bytes) {
                    next_state += 1;
                }
            }
        }
    }
    assert_eq!(
        next_state,
        states.len(),
        "our tilt states, in order, in fakenect-record's dump"
    );

    // And the other way: fakenect-record's dump is a valid depth part.
    let back = tmp.path().join("back");
    std::fs::create_dir(&back).unwrap();
    std::fs::copy(ours.join("session.json"), back.join("session.json")).unwrap();
    std::fs::rename(&rerecorded, back.join("kinect")).unwrap();
    let ours_read = Recording::open(&ours).unwrap();
    let mut depth_names = their_depth.iter().map(|e| e.name.clone());
    let lines: Vec<String> = ours_read
        .poses
        .iter()
        .map(|pose| {
            let mut record = pose.clone();
            record.depth_frames = pose
                .depth_frames
                .iter()
                .map(|_| depth_names.next().unwrap())
                .collect();
            serde_json::to_string(&record).unwrap() + "\n"
        })
        .collect();
    std::fs::write(back.join("poses.jsonl"), lines.concat()).unwrap();
    let back_read = Recording::open(&back).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back_read.poses.len(), 3);
    for (mine, theirs) in ours_read.poses.iter().zip(&back_read.poses) {
        for (a, b) in mine.depth_frames.iter().zip(&theirs.depth_frames) {
            assert_eq!(
                ours_read.read_depth_frame(a).unwrap().0,
                back_read.read_depth_frame(b).unwrap().0
            );
        }
    }
}
