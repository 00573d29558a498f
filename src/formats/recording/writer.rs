//! Writing a recording as a session goes (`shared/spec/recording.md`).
//!
//! The depth part is written exactly as libfreenect's `fakenect-record` (its
//! `fakenect/record.c`) writes a dump, so that libfreenect's own `fakenect`
//! library plays it back:
//!
//! - names are `sprintf("%c-%f-%u.%s", type, time, timestamp, ext)`: `d-….pgm`
//!   for depth, `a-….dump` for the tilt state (Rust's `{:.6}` rounds like C's
//!   `%f`, ties to even on the exact binary value);
//! - a depth file is `"P5 %d %d 65535\n"` and the raw little-endian 11-bit
//!   values; an accelerometer file is the raw 12-byte `freenect_raw_tilt_state`;
//! - each name is appended to `INDEX.txt` with `"%s\n"`.
//!   (record.c appends the name before it writes the file; here the file
//!   comes first, so that `INDEX.txt` never names a file not yet written.)
//!
//! Durability: a recording cut off by a crash or a power loss is valid up to
//! its last complete pose. A frame's file is written before its name goes into
//! `INDEX.txt`; [`RecordingWriter::write_pose`] first fsyncs the frames written
//! since the last pose, `kinect/` and `INDEX.txt`, then appends the pose's line
//! to `poses.jsonl` and fsyncs it. The reader drops an unterminated last line
//! of `poses.jsonl`, and frames after the last pose are named by no pose, so
//! they do no harm. After a write to `INDEX.txt` or `poses.jsonl` fails, or an
//! fsync does, the writer refuses to go on (a torn line would be followed by
//! more), leaving the recording valid up to its last complete pose.

use std::collections::{HashMap, HashSet};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use super::dump::{EntryKind, RawTiltState};
use super::poses::PoseRecord;
use super::session::{check_feet, Session};
use crate::formats::depth_image::{encode_fakenect_pgm, DepthImage};

/// Largest 11-bit raw value; 2047 means no reading.
const RAW11_MAX: u16 = 2047;
/// Frames kept open unsynced before they are synced early (bounds open files
/// when many frames are written between two poses).
const MAX_UNSYNCED: usize = 64;

/// Why a recording could not be written; the message starts with the file.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The writer refused: bad input, or a state that cannot be written.
    #[error("{}: {message}", path.display())]
    Refused { path: PathBuf, message: String },
    /// A file could not be replaced whole.
    #[error(transparent)]
    File(#[from] crate::platform::files::FileError),
    /// The file system failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
}

impl WriteError {
    fn refused(path: &Path, message: impl Into<String>) -> Self {
        Self::Refused {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    fn io<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |source| Self::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }

    /// The file or directory the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Refused { path, .. } | Self::Io { path, .. } => path,
            Self::File(e) => &e.path,
        }
    }
}

/// Writes a recording directory as a session goes: `session.json` first, then
/// frames and tilt states into `kinect/`, and a line of `poses.jsonl` once a
/// pose's frames are on disk.
#[derive(Debug)]
pub struct RecordingWriter {
    dir: PathBuf,
    kinect: PathBuf,
    width: usize,
    height: usize,
    index_path: PathBuf,
    index: File,
    poses_path: PathBuf,
    poses: File,
    /// Every name in `INDEX.txt`, with its kind.
    names: HashMap<String, EntryKind>,
    /// Depth frames some pose already lists.
    used_frames: HashSet<String>,
    /// Pose indices written.
    pose_indices: HashSet<u32>,
    /// Files of the dump written since the last sync.
    unsynced: Vec<(PathBuf, File)>,
    /// Set after a failure that leaves a file in a state not to be appended to.
    broken: Option<String>,
}

impl RecordingWriter {
    /// Starts a recording in `dir`, which must not exist or be empty: creates
    /// `kinect/`, writes `session.json` atomically (temporary file, fsync,
    /// rename, fsync of the directory), and creates an empty `poses.jsonl`
    /// and `kinect/INDEX.txt`.
    ///
    /// The session is checked with the reader's own checks first, so that a
    /// recording is never started that could not be read back.
    pub fn create(dir: &Path, session: &Session) -> Result<Self, WriteError> {
        let session_path = dir.join("session.json");
        let mut text = serde_json::to_string_pretty(session).map_err(|e| {
            WriteError::refused(&session_path, format!("cannot encode the session: {e}"))
        })?;
        text.push('\n');
        Session::parse(&session_path, &text).map_err(|e| {
            WriteError::refused(
                &session_path,
                format!("the session would not read back: {}", e.message),
            )
        })?;
        let (width, height) = (
            session.kinect.intrinsics.width,
            session.kinect.intrinsics.height,
        );

        match std::fs::metadata(dir) {
            Ok(meta) if !meta.is_dir() => {
                return Err(WriteError::refused(
                    dir,
                    "exists and is not a directory (a recording is written into a new or empty directory)",
                ))
            }
            Ok(_) => {
                let mut entries =
                    std::fs::read_dir(dir).map_err(WriteError::io(dir, "list the directory"))?;
                if entries.next().is_some() {
                    return Err(WriteError::refused(
                        dir,
                        "is not empty: a recording is written into a new or empty directory, never over another",
                    ));
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                std::fs::create_dir_all(dir).map_err(WriteError::io(dir, "create the directory"))?;
                if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
                    sync_dir(parent)?;
                }
            }
            Err(e) => return Err(WriteError::io(dir, "inspect the directory")(e)),
        }

        let kinect = dir.join("kinect");
        std::fs::create_dir(&kinect).map_err(WriteError::io(&kinect, "create the directory"))?;

        // session.json: complete or absent, never half-written.
        crate::platform::files::write_atomically(&session_path, text.as_bytes())?;

        let poses_path = dir.join("poses.jsonl");
        let poses = create_new(&poses_path)?;
        poses
            .sync_all()
            .map_err(WriteError::io(&poses_path, "fsync"))?;
        let index_path = kinect.join("INDEX.txt");
        let index = create_new(&index_path)?;
        index
            .sync_all()
            .map_err(WriteError::io(&index_path, "fsync"))?;
        sync_dir(&kinect)?;
        sync_dir(dir)?;

        Ok(Self {
            dir: dir.to_path_buf(),
            kinect,
            width,
            height,
            index_path,
            index,
            poses_path,
            poses,
            names: HashMap::new(),
            used_frames: HashSet::new(),
            pose_indices: HashSet::new(),
            unsynced: Vec::new(),
            broken: None,
        })
    }

    /// The recording's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// How many poses have been written.
    pub fn pose_count(&self) -> usize {
        self.pose_indices.len()
    }

    /// Writes a depth frame as `kinect/d-<time_s as %f>-<timestamp>.pgm` and
    /// appends its name to `INDEX.txt`; returns the name.
    ///
    /// `time_s` is the capture time in seconds (fakenect's playback waits for
    /// the differences), `timestamp` the Kinect's frame timestamp. The image
    /// must have the session's size and hold raw 11-bit values (≤ 2047).
    /// libfreenect's fakenect plays only 640×480 frames.
    pub fn write_depth_frame(
        &mut self,
        time_s: f64,
        timestamp: u32,
        image: &DepthImage,
    ) -> Result<String, WriteError> {
        let name = entry_name('d', time_s, timestamp, "pgm");
        let path = self.kinect.join(&name);
        self.check_entry(&path, time_s, &name)?;
        if image.width != self.width || image.height != self.height {
            return Err(WriteError::refused(
                &path,
                format!(
                    "the frame is {}×{}, the session's intrinsics say {}×{}",
                    image.width, image.height, self.width, self.height
                ),
            ));
        }
        if image.pixels.len() != image.width * image.height {
            return Err(WriteError::refused(
                &path,
                format!(
                    "the frame has {} values, a {}×{} frame has {}",
                    image.pixels.len(),
                    image.width,
                    image.height,
                    image.width * image.height
                ),
            ));
        }
        if let Some(i) = image.pixels.iter().position(|&v| v > RAW11_MAX) {
            return Err(WriteError::refused(
                &path,
                format!(
                    "pixel ({}, {}) is {}, above {RAW11_MAX}: a fakenect dump holds raw 11-bit values",
                    i % image.width,
                    i / image.width,
                    image.pixels[i]
                ),
            ));
        }
        self.write_entry(path, name, EntryKind::Depth, &encode_fakenect_pgm(image))
    }

    /// Writes a tilt state snapshot as `kinect/a-<time_s as %f>-<timestamp>.dump`
    /// (the raw 12-byte `freenect_raw_tilt_state`) and appends its name to
    /// `INDEX.txt`; returns the name. `fakenect-record` stamps it with the
    /// timestamp of the last frame.
    pub fn write_tilt_state(
        &mut self,
        time_s: f64,
        timestamp: u32,
        state: &RawTiltState,
    ) -> Result<String, WriteError> {
        let name = entry_name('a', time_s, timestamp, "dump");
        let path = self.kinect.join(&name);
        self.check_entry(&path, time_s, &name)?;
        self.write_entry(path, name, EntryKind::Accelerometer, &state.encode())
    }

    /// Appends one pose to `poses.jsonl`, after making its frames durable:
    /// fsyncs the files written since the last pose, `kinect/` and
    /// `INDEX.txt`, then writes the line and fsyncs `poses.jsonl`.
    ///
    /// The pose is checked as the reader checks it, and every frame it lists
    /// must be a depth frame this writer wrote that no earlier pose lists.
    pub fn write_pose(&mut self, pose: &PoseRecord) -> Result<(), WriteError> {
        self.check_not_broken(&self.poses_path)?;
        let refuse =
            |m: String| WriteError::refused(&self.poses_path, format!("pose {}: {m}", pose.index));
        if pose.index == 0 {
            return Err(refuse(
                "index must count from 1 (0 is the home stance)".into(),
            ));
        }
        if self.pose_indices.contains(&pose.index) {
            return Err(refuse("this index was already written".into()));
        }
        if !pose.commanded.is_finite() {
            return Err(refuse(
                "commanded has a value that is not a finite number".into(),
            ));
        }
        check_feet(&pose.feet_body_mm).map_err(|e| refuse(format!("feet_body_mm: {e}")))?;
        let mut listed = HashSet::new();
        for name in &pose.depth_frames {
            match self.names.get(name) {
                None => {
                    return Err(refuse(format!(
                        "depth frame \"{name}\" was not written by this recording"
                    )))
                }
                Some(EntryKind::Depth) => {}
                Some(_) => return Err(refuse(format!("\"{name}\" is not a depth frame"))),
            }
            if self.used_frames.contains(name) || !listed.insert(name.as_str()) {
                return Err(refuse(format!(
                    "depth frame \"{name}\" already belongs to a pose"
                )));
            }
        }
        for name in &pose.accelerometer {
            match self.names.get(name) {
                None => {
                    return Err(refuse(format!(
                        "accelerometer reading \"{name}\" was not written by this recording"
                    )))
                }
                Some(EntryKind::Accelerometer) => {}
                Some(_) => {
                    return Err(refuse(format!(
                        "\"{name}\" is not an accelerometer reading"
                    )))
                }
            }
        }
        let mut line = serde_json::to_string(pose)
            .map_err(|e| refuse(format!("cannot encode the pose: {e}")))?;
        line.push('\n');

        self.sync_dump()?;
        let result = self
            .poses
            .write_all(line.as_bytes())
            .map_err(WriteError::io(&self.poses_path, "append to"))
            .and_then(|()| {
                self.poses
                    .sync_data()
                    .map_err(WriteError::io(&self.poses_path, "fsync"))
            });
        self.break_on_error(result)?;
        self.pose_indices.insert(pose.index);
        self.used_frames.extend(pose.depth_frames.iter().cloned());
        Ok(())
    }

    /// Makes everything written durable and closes the recording; returns its
    /// directory. Frames after the last pose stay in the dump (fakenect plays
    /// them), named by no pose.
    pub fn finish(mut self) -> Result<PathBuf, WriteError> {
        self.check_not_broken(&self.dir)?;
        self.sync_dump()?;
        let result = self
            .poses
            .sync_all()
            .map_err(WriteError::io(&self.poses_path, "fsync"));
        self.break_on_error(result)?;
        sync_dir(&self.dir)?;
        Ok(self.dir)
    }

    fn check_not_broken(&self, path: &Path) -> Result<(), WriteError> {
        match &self.broken {
            Some(why) => Err(WriteError::refused(
                path,
                format!(
                    "the recording cannot go on after an earlier failure ({why}); it is valid up to its last complete pose"
                ),
            )),
            None => Ok(()),
        }
    }

    fn break_on_error<T>(&mut self, result: Result<T, WriteError>) -> Result<T, WriteError> {
        if let Err(e) = &result {
            self.broken.get_or_insert_with(|| e.to_string());
        }
        result
    }

    fn check_entry(&self, path: &Path, time_s: f64, name: &str) -> Result<(), WriteError> {
        self.check_not_broken(path)?;
        if !(time_s.is_finite() && time_s >= 0.0) {
            return Err(WriteError::refused(
                path,
                format!("time {time_s} s is not a finite, non-negative number of seconds"),
            ));
        }
        if self.names.contains_key(name) {
            return Err(WriteError::refused(
                path,
                "a file of this name (same type, time to the microsecond and timestamp) was already written",
            ));
        }
        Ok(())
    }

    /// Writes a dump file, then its line of `INDEX.txt`.
    fn write_entry(
        &mut self,
        path: PathBuf,
        name: String,
        kind: EntryKind,
        bytes: &[u8],
    ) -> Result<String, WriteError> {
        let mut file = create_new(&path)?;
        if let Err(e) = file.write_all(bytes) {
            // Not yet in INDEX.txt: nothing refers to it.
            drop(file);
            let _ = std::fs::remove_file(&path);
            return Err(WriteError::io(&path, "write")(e));
        }
        self.unsynced.push((path, file));
        // One write per line, as record.c's fprintf("%s\n").
        let line = format!("{name}\n");
        let result = self
            .index
            .write_all(line.as_bytes())
            .map_err(WriteError::io(&self.index_path, "append to"));
        self.break_on_error(result)?;
        self.names.insert(name.clone(), kind);
        if self.unsynced.len() >= MAX_UNSYNCED {
            self.sync_files()?;
        }
        Ok(name)
    }

    fn sync_files(&mut self) -> Result<(), WriteError> {
        for (path, file) in std::mem::take(&mut self.unsynced) {
            let result = file.sync_all().map_err(WriteError::io(&path, "fsync"));
            self.break_on_error(result)?;
        }
        Ok(())
    }

    /// Frames, then the directory entries, then `INDEX.txt`.
    fn sync_dump(&mut self) -> Result<(), WriteError> {
        self.sync_files()?;
        let result = sync_dir(&self.kinect).and_then(|()| {
            self.index
                .sync_data()
                .map_err(WriteError::io(&self.index_path, "fsync"))
        });
        self.break_on_error(result)
    }
}

/// A dump file's name as `record.c` makes it: `sprintf("%c-%f-%u.%s")`.
pub fn entry_name(kind: char, time_s: f64, timestamp: u32, extension: &str) -> String {
    format!("{kind}-{time_s:.6}-{timestamp}.{extension}")
}

fn create_new(path: &Path) -> Result<File, WriteError> {
    OpenOptions::new()
        .append(true)
        .create_new(true)
        .open(path)
        .map_err(WriteError::io(path, "create"))
}

/// Makes a directory's entries durable (Unix; elsewhere nothing to do).
fn sync_dir(dir: &Path) -> Result<(), WriteError> {
    #[cfg(unix)]
    {
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(WriteError::io(dir, "fsync the directory"))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::recording::dump::parse_entry_name;
    use crate::formats::recording::Recording;

    fn sample() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/sample-12")
    }

    /// A fresh directory under the system's temporary one, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> Self {
            use std::sync::atomic::{AtomicUsize, Ordering};
            static COUNT: AtomicUsize = AtomicUsize::new(0);
            let path = std::env::temp_dir().join(format!(
                "groundcal-writer-{tag}-{}-{}",
                std::process::id(),
                COUNT.fetch_add(1, Ordering::Relaxed)
            ));
            let _ = std::fs::remove_dir_all(&path);
            Self(path)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// Writes the sample's dump entries in order, up to and including the
    /// frames of its first `poses` poses, and those poses.
    fn copy_sample(writer: &mut RecordingWriter, source: &Recording, poses: usize) {
        let last = source.poses[poses - 1].depth_frames.last().unwrap();
        let mut next_pose = 0;
        for entry in &source.index {
            let name = match entry.kind {
                EntryKind::Depth => {
                    let (image, _) = source.read_depth_frame(&entry.name).unwrap();
                    writer
                        .write_depth_frame(entry.time, entry.timestamp, &image)
                        .unwrap()
                }
                EntryKind::Accelerometer => {
                    let path = source.kinect_path(&entry.name);
                    let state = RawTiltState::parse(&path, &std::fs::read(&path).unwrap()).unwrap();
                    writer
                        .write_tilt_state(entry.time, entry.timestamp, &state)
                        .unwrap()
                }
                EntryKind::Rgb => unreachable!("the sample has no RGB"),
            };
            assert_eq!(name, entry.name, "names are made as record.c makes them");
            let pose = &source.poses[next_pose];
            if pose.depth_frames.last() == Some(&name) {
                writer.write_pose(pose).unwrap();
                next_pose += 1;
            }
            if &name == last {
                break;
            }
        }
        assert_eq!(next_pose, poses);
    }

    #[test]
    fn sample_frames_round_trip_byte_for_byte() {
        let source = Recording::open(&sample()).unwrap();
        let dir = TempDir::new("round-trip");
        let mut writer = RecordingWriter::create(&dir.0, &source.session).unwrap();
        copy_sample(&mut writer, &source, 4);
        assert_eq!(writer.pose_count(), 4);
        assert_eq!(writer.finish().unwrap(), dir.0);

        let copy = Recording::open(&dir.0).unwrap();
        assert_eq!(copy.session, source.session);
        assert_eq!(copy.poses, source.poses[..4]);
        assert!(copy.cut_off.is_none());
        assert_eq!(copy.index, source.index[..copy.index.len()]);
        for entry in &copy.index {
            let ours = std::fs::read(copy.kinect_path(&entry.name)).unwrap();
            let theirs = std::fs::read(source.kinect_path(&entry.name)).unwrap();
            assert!(ours == theirs, "{} differs from the sample's", entry.name);
        }
        for pose in &copy.poses {
            for name in &pose.depth_frames {
                assert_eq!(
                    copy.read_depth_frame(name).unwrap(),
                    source.read_depth_frame(name).unwrap()
                );
            }
        }
        let index_text = std::fs::read_to_string(dir.0.join("kinect/INDEX.txt")).unwrap();
        let sample_text = std::fs::read_to_string(sample().join("kinect/INDEX.txt")).unwrap();
        assert!(index_text.ends_with('\n') && sample_text.starts_with(&index_text));
        assert!(!dir.0.join(".session.json.tmp").exists());
    }

    #[test]
    fn a_writer_dropped_mid_pose_leaves_the_completed_poses() {
        let source = Recording::open(&sample()).unwrap();
        let dir = TempDir::new("dropped");
        {
            let mut writer = RecordingWriter::create(&dir.0, &source.session).unwrap();
            copy_sample(&mut writer, &source, 2);
            // Pose 3's first frame is written, then the writer is lost.
            let name = &source.poses[2].depth_frames[0];
            let entry = parse_entry_name(name).unwrap();
            let (image, _) = source.read_depth_frame(name).unwrap();
            writer
                .write_depth_frame(entry.time, entry.timestamp, &image)
                .unwrap();
        }
        let cut = Recording::open(&dir.0).unwrap();
        assert_eq!(cut.poses, source.poses[..2]);
        assert!(cut.cut_off.is_none());
        assert_eq!(
            cut.index.last().unwrap().name,
            source.poses[2].depth_frames[0]
        );

        // Power lost while the pose's line was being written.
        let line = serde_json::to_string(&source.poses[2]).unwrap();
        let mut poses = OpenOptions::new()
            .append(true)
            .open(dir.0.join("poses.jsonl"))
            .unwrap();
        poses.write_all(&line.as_bytes()[..line.len() / 2]).unwrap();
        drop(poses);
        let refused = Recording::open(&dir.0).unwrap_err();
        assert_eq!(refused.line, Some(3), "{refused}");
        let torn = Recording::open_cut_off(&dir.0).unwrap();
        assert_eq!(torn.poses, source.poses[..2]);
        assert_eq!(torn.cut_off.map(|c| c.line), Some(3));
    }

    #[test]
    fn names_are_those_of_c_printf() {
        assert_eq!(
            entry_name('d', 1_700_000_000.001, 2_001_000, "pgm"),
            "d-1700000000.001000-2001000.pgm"
        );
        // %f rounds the exact binary value, ties to even: 0.0078125 is a tie.
        assert_eq!(entry_name('a', 0.0078125, 0, "dump"), "a-0.007812-0.dump");
        assert_eq!(entry_name('a', 0.0234375, 7, "dump"), "a-0.023438-7.dump");
        assert_eq!(
            entry_name('d', 12.5, u32::MAX, "pgm"),
            "d-12.500000-4294967295.pgm"
        );
    }

    #[test]
    fn files_are_those_of_record_c() {
        let source = Recording::open(&sample()).unwrap();
        let dir = TempDir::new("files");
        let mut writer = RecordingWriter::create(&dir.0, &source.session).unwrap();
        let image = DepthImage {
            width: 640,
            height: 480,
            pixels: (0..640 * 480).map(|i| (i % 2048) as u16).collect(),
        };
        let d = writer.write_depth_frame(1.25, 9, &image).unwrap();
        let state = RawTiltState {
            accelerometer: [-300, 819, 5],
            tilt_angle: -40,
            tilt_status: 4,
        };
        let a = writer.write_tilt_state(1.5, 9, &state).unwrap();
        writer.finish().unwrap();
        let bytes = std::fs::read(dir.0.join("kinect").join(&d)).unwrap();
        assert!(bytes.starts_with(b"P5 640 480 65535\n"));
        assert_eq!(bytes.len(), 17 + 640 * 480 * 2);
        assert_eq!(&bytes[17 + 2 * 1027..17 + 2 * 1028], &1027u16.to_le_bytes());
        let bytes = std::fs::read(dir.0.join("kinect").join(&a)).unwrap();
        assert_eq!(bytes, [0xd4, 0xfe, 0x33, 0x03, 5, 0, 0xd8, 0, 4, 0, 0, 0]);
        assert_eq!(
            std::fs::read_to_string(dir.0.join("kinect/INDEX.txt")).unwrap(),
            format!("{d}\n{a}\n")
        );
        assert_eq!(std::fs::read(dir.0.join("poses.jsonl")).unwrap(), b"");
    }

    #[test]
    fn bad_input_is_refused_naming_the_file() {
        let source = Recording::open(&sample()).unwrap();
        let session = &source.session;

        // Not over another recording.
        let err = RecordingWriter::create(&sample(), session).unwrap_err();
        assert!(err.to_string().contains("is not empty"), "{err}");
        assert_eq!(err.path(), sample());

        // Nor a session the reader would refuse.
        let dir = TempDir::new("bad-session");
        let mut bad = session.clone();
        bad.home.feet_body_mm.pop();
        let err = RecordingWriter::create(&dir.0, &bad).unwrap_err();
        assert!(
            err.to_string().contains("session.json") && err.to_string().contains("six feet"),
            "{err}"
        );
        assert!(!dir.0.exists(), "nothing is created for a refused session");

        let dir = TempDir::new("bad");
        let mut writer = RecordingWriter::create(&dir.0, session).unwrap();
        let (image, _) = source
            .read_depth_frame(&source.poses[0].depth_frames[0])
            .unwrap();
        let message = |e: WriteError| e.to_string();

        let small = DepthImage {
            width: 2,
            height: 2,
            pixels: vec![0; 4],
        };
        let e = message(writer.write_depth_frame(1.0, 1, &small).unwrap_err());
        assert!(e.contains("d-1.000000-1.pgm") && e.contains("2×2"), "{e}");
        let mut over = image.clone();
        over.pixels[641] = 2048;
        let e = message(writer.write_depth_frame(1.0, 1, &over).unwrap_err());
        assert!(e.contains("pixel (1, 1) is 2048"), "{e}");
        let mut short = image.clone();
        short.pixels.pop();
        let e = message(writer.write_depth_frame(1.0, 1, &short).unwrap_err());
        assert!(e.contains("307199 values"), "{e}");
        for t in [-1.0, f64::NAN, f64::INFINITY] {
            let e = message(writer.write_depth_frame(t, 1, &image).unwrap_err());
            assert!(e.contains("not a finite, non-negative"), "{e}");
        }

        let d = writer.write_depth_frame(1.0, 1, &image).unwrap();
        let e = message(writer.write_depth_frame(1.0000001, 1, &image).unwrap_err());
        assert!(e.contains(&d) && e.contains("already written"), "{e}");
        let state = RawTiltState {
            accelerometer: [0, 819, 0],
            tilt_angle: 0,
            tilt_status: 0,
        };
        let a = writer.write_tilt_state(1.0, 1, &state).unwrap();

        let mut pose = source.poses[0].clone();
        pose.depth_frames = vec!["d-9.000000-9.pgm".into()];
        let e = message(writer.write_pose(&pose).unwrap_err());
        assert!(
            e.contains("poses.jsonl") && e.contains("was not written"),
            "{e}"
        );
        pose.depth_frames = vec![a];
        let e = message(writer.write_pose(&pose).unwrap_err());
        assert!(e.contains("not a depth frame"), "{e}");
        pose.depth_frames = vec![d.clone(), d.clone()];
        assert!(message(writer.write_pose(&pose).unwrap_err()).contains("already belongs"));
        pose.depth_frames = vec![d.clone()];
        pose.feet_body_mm.pop();
        assert!(message(writer.write_pose(&pose).unwrap_err()).contains("six feet"));
        pose.feet_body_mm = source.poses[0].feet_body_mm.clone();
        pose.index = 0;
        assert!(message(writer.write_pose(&pose).unwrap_err()).contains("count from 1"));
        pose.index = 1;
        writer.write_pose(&pose).unwrap();
        let e = message(writer.write_pose(&pose).unwrap_err());
        assert!(e.contains("already written"), "{e}");
        pose.index = 2;
        let e = message(writer.write_pose(&pose).unwrap_err());
        assert!(e.contains("already belongs"), "{e}");
        // A pose whose capture failed lists no frame.
        pose.depth_frames.clear();
        writer.write_pose(&pose).unwrap();
        writer.finish().unwrap();

        let written = Recording::open(&dir.0).unwrap();
        assert_eq!(written.poses.len(), 2);
        assert_eq!(written.poses[0].depth_frames, [d]);
    }
}
