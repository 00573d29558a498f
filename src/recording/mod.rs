//! Reading groundcal's input files (`shared/spec/recording.md`).
//!
//! Readers are strict: every defect is an [`InputError`] naming the file, the
//! line where known, and what was expected. Nothing half-read is returned.

pub mod dump;
pub mod planes;
pub mod poses;
pub mod session;
pub mod writer;

use std::fmt;
use std::path::{Path, PathBuf};

use crate::depth_image::{parse_fakenect_pgm_into, DepthImage};
use dump::{parse_index, DumpEntry, EntryKind};
use poses::{parse_poses, PoseRecord};
use session::Session;

/// A defect in an input file.
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    pub path: PathBuf,
    /// 1-based line, where known.
    pub line: Option<usize>,
    pub message: String,
}

impl InputError {
    pub fn new(path: &Path, line: Option<usize>, message: impl Into<String>) -> Self {
        Self {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.path.display(), line, self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for InputError {}

/// Parses strict TOML, turning toml's error into one that names the file and
/// the line (some of toml's errors carry no message of their own: the whole
/// report is used then).
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    path: &Path,
    text: &str,
) -> Result<T, InputError> {
    toml::from_str(text).map_err(|e| {
        let line = e
            .span()
            .map(|span| text[..span.start.min(text.len())].lines().count().max(1));
        let message = if e.message().trim().is_empty() {
            e.to_string()
        } else {
            e.message().to_string()
        };
        InputError::new(path, line, message)
    })
}

/// Reads a whole file, refusing ones too large to be an input of this kind.
pub fn read_bounded(path: &Path, max_bytes: u64) -> Result<Vec<u8>, InputError> {
    let mut bytes = Vec::new();
    read_bounded_into(path, max_bytes, &mut bytes)?;
    Ok(bytes)
}

/// [`read_bounded`] into a buffer that is reused from file to file
/// ([`crate::files::read_bounded_into`]), errors as the recording's.
pub fn read_bounded_into(
    path: &Path,
    max_bytes: u64,
    bytes: &mut Vec<u8>,
) -> Result<(), InputError> {
    use crate::files::ReadError;
    crate::files::read_bounded_into(path, max_bytes, bytes).map_err(|e| match e {
        ReadError::File(f) => {
            InputError::new(path, None, format!("cannot {}: {}", f.action, f.source))
        }
        ReadError::TooLarge { max_bytes, .. } => InputError::new(
            path,
            None,
            format!("larger than {max_bytes} bytes: not an input of this kind"),
        ),
    })
}

/// Largest `session.json`, `poses.jsonl` or `INDEX.txt` accepted.
const MAX_TEXT_BYTES: u64 = 64 << 20;

/// A recording (recording.md), checked when opened: its text files parsed,
/// every frame a pose names present in `INDEX.txt` and on disk with the size
/// of a depth frame. Frames themselves are read one pose at a time.
#[derive(Debug, Clone)]
pub struct Recording {
    pub dir: PathBuf,
    pub session: Session,
    pub poses: Vec<PoseRecord>,
    /// `poses.jsonl` ended in a line cut off part-way, which was left out.
    pub truncated_tail: bool,
    pub index: Vec<DumpEntry>,
    /// The raw text files, for the input digest.
    texts: [Vec<u8>; 3],
}

fn read_text(path: &Path) -> Result<(Vec<u8>, String), InputError> {
    let bytes = read_bounded(path, MAX_TEXT_BYTES)?;
    let text = String::from_utf8(bytes.clone())
        .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))?;
    Ok((bytes, text))
}

impl Recording {
    /// Opens and checks a recording directory.
    pub fn open(dir: &Path) -> Result<Self, InputError> {
        if !dir.is_dir() {
            return Err(InputError::new(
                dir,
                None,
                "not a directory (expected a recording: session.json, poses.jsonl, kinect/)",
            ));
        }
        let session_path = dir.join("session.json");
        let (session_bytes, session_text) = read_text(&session_path)?;
        let session = Session::parse(&session_path, &session_text)?;
        let poses_path = dir.join("poses.jsonl");
        let (poses_bytes, poses_text) = read_text(&poses_path)?;
        let poses_file = parse_poses(&poses_path, &poses_text)?;
        let index_path = dir.join("kinect").join("INDEX.txt");
        let (index_bytes, index_text) = read_text(&index_path)?;
        let index = parse_index(&index_path, &index_text)?;

        let intrinsics = session.kinect.intrinsics;
        let frame_bytes = fakenect_frame_len(intrinsics.width, intrinsics.height);
        let names: std::collections::HashMap<&str, &DumpEntry> =
            index.iter().map(|e| (e.name.as_str(), e)).collect();
        for pose in &poses_file.poses {
            let at = |m: String| {
                InputError::new(
                    &poses_path,
                    Some(pose.line),
                    format!("pose {}: {m}", pose.index),
                )
            };
            // Every file a pose names is in the INDEX, of the kind it says.
            for (names_listed, kind, what, a_what) in [
                (
                    &pose.depth_frames,
                    EntryKind::Depth,
                    "depth frame",
                    "a depth frame",
                ),
                (
                    &pose.accelerometer,
                    EntryKind::Accelerometer,
                    "accelerometer reading",
                    "an accelerometer reading",
                ),
            ] {
                for name in names_listed {
                    match names.get(name.as_str()) {
                        None => {
                            return Err(at(format!("{what} \"{name}\" is not in kinect/INDEX.txt")))
                        }
                        Some(entry) if entry.kind != kind => {
                            return Err(at(format!("\"{name}\" is not {a_what}")))
                        }
                        Some(_) => {}
                    }
                }
            }
            for name in &pose.depth_frames {
                let frame_path = dir.join("kinect").join(name);
                let len = std::fs::metadata(&frame_path)
                    .map_err(|e| {
                        InputError::new(
                            &frame_path,
                            None,
                            format!("depth frame of pose {} cannot be read: {e}", pose.index),
                        )
                    })?
                    .len();
                if len != frame_bytes as u64 {
                    return Err(InputError::new(
                        &frame_path,
                        None,
                        format!(
                            "a {}×{} depth frame is {frame_bytes} bytes, this one is {len} (truncated or corrupt)",
                            intrinsics.width, intrinsics.height
                        ),
                    ));
                }
            }
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            session,
            poses: poses_file.poses,
            truncated_tail: poses_file.truncated_tail,
            index,
            texts: [session_bytes, poses_bytes, index_bytes],
        })
    }

    /// The path of a file of the dump.
    pub fn kinect_path(&self, name: &str) -> PathBuf {
        self.dir.join("kinect").join(name)
    }

    /// Reads one depth frame, with its bytes (for the digest).
    pub fn read_depth_frame(&self, name: &str) -> Result<(DepthImage, Vec<u8>), InputError> {
        let mut bytes = Vec::new();
        let mut pixels = Vec::new();
        self.read_depth_frame_into(name, &mut bytes, &mut pixels)?;
        let intrinsics = self.session.kinect.intrinsics;
        let image = DepthImage {
            width: intrinsics.width,
            height: intrinsics.height,
            pixels,
        };
        Ok((image, bytes))
    }

    /// [`Recording::read_depth_frame`] into buffers reused from frame to
    /// frame: the file's bytes, and its pixels (the session's size).
    pub fn read_depth_frame_into(
        &self,
        name: &str,
        bytes: &mut Vec<u8>,
        pixels: &mut Vec<u16>,
    ) -> Result<(), InputError> {
        let path = self.kinect_path(name);
        let intrinsics = self.session.kinect.intrinsics;
        read_bounded_into(
            &path,
            fakenect_frame_len(intrinsics.width, intrinsics.height) as u64,
            bytes,
        )?;
        let (width, height) = parse_fakenect_pgm_into(&path, bytes, pixels)
            .map_err(|e| InputError::new(&path, None, e.to_string()))?;
        if width != intrinsics.width || height != intrinsics.height {
            return Err(InputError::new(
                &path,
                None,
                format!(
                    "frame is {}×{}, session.json says {}×{}",
                    width, height, intrinsics.width, intrinsics.height
                ),
            ));
        }
        Ok(())
    }

    /// Reads one accelerometer reading (`a-…` file: a raw tilt state).
    pub fn read_tilt_state(&self, name: &str) -> Result<dump::RawTiltState, InputError> {
        let path = self.kinect_path(name);
        let bytes = read_bounded(&path, dump::RAW_TILT_STATE_BYTES as u64 + 1)?;
        dump::RawTiltState::parse(&path, &bytes)
    }

    /// The text files' bytes (session.json, poses.jsonl, INDEX.txt).
    pub fn text_files(&self) -> [&[u8]; 3] {
        [&self.texts[0], &self.texts[1], &self.texts[2]]
    }
}

/// Size of a fakenect depth file: the header and two bytes per pixel.
pub fn fakenect_frame_len(width: usize, height: usize) -> usize {
    format!("P5 {width} {height} 65535\n").len() + 2 * width * height
}
