//! groundcal's own session MCAP (`replay --mcap`, `calibrate --record-mcap`)
//! read back as the recording it was written from, so that `replay
//! SESSION.mcap` gives what `replay` of that recording gives.
//!
//! The file carries the recording whole: its text files (`session.json`,
//! `poses.jsonl`, `kinect/INDEX.txt`) and its small dumps (the tilt states)
//! as attachments under [`RECORDING_PREFIX`], the order of its depth frames
//! as `frames.json`, and the frames themselves as the raw 11-bit topic
//! (`/camera/depth/raw_11bit`, `mono16`). Read back, they are written into a
//! directory of their own, removed when the [`OwnRecording`] drops, and
//! that directory is replayed as any recording is. A bag from another stack
//! has none of these attachments and is read as a bag.

use std::path::{Path, PathBuf};

use super::stream::{Limits, McapStream, ReadError};
use super::BagError;
use crate::formats::depth_image::{encode_fakenect_pgm, DepthImage};
use crate::solving::mcap_session::recording_attachment::{FRAMES, RECORDING_PREFIX};
use crate::solving::mcap_session::topic::DEPTH_RAW as RAW_TOPIC;
use groundcal_ros::msg::Message;

/// The recording a session MCAP carried, in a directory of its own that is
/// removed when this drops.
#[derive(Debug)]
pub struct OwnRecording {
    dir: PathBuf,
}

impl OwnRecording {
    /// The recording's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for OwnRecording {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The recording in `path`, when it is one of groundcal's own sessions
/// (`None` for another stack's bag). Two passes: the attachments (no chunk
/// decompressed), then the raw frames.
pub fn own_recording(path: &Path) -> Result<Option<OwnRecording>, BagError> {
    let fail = |what: String| BagError {
        path: path.display().to_string(),
        what,
    };
    let open = || {
        crate::platform::files::open_regular(path)
            .map(|f| std::io::BufReader::with_capacity(1 << 20, f))
            .map_err(|e| fail(e.to_string()))
    };
    // Only a file groundcal wrote can carry a recording: its Header record
    // says so, and another stack's bag is not read an extra time.
    if !written_by_groundcal(path) {
        return Ok(None);
    }
    let mut stream = McapStream::new(Limits::default());
    stream.keep_attachments(RECORDING_PREFIX);
    stream
        .read(open()?, |_| false, |_| true, |_| Ok::<(), String>(()))
        .map_err(|e| fail(read_error(e)))?;
    let files: Vec<(String, Vec<u8>)> = stream
        .take_attachments()
        .into_iter()
        .map(|(name, data)| (name[RECORDING_PREFIX.len()..].to_string(), data))
        .collect();
    if files.is_empty() {
        return Ok(None);
    }
    let frames: Vec<String> = files
        .iter()
        .find(|(name, _)| name == FRAMES)
        .ok_or_else(|| {
            fail(format!(
                "the attachment {RECORDING_PREFIX}{FRAMES} is missing"
            ))
        })
        .and_then(|(_, data)| {
            serde_json::from_slice(data)
                .map_err(|e| fail(format!("{RECORDING_PREFIX}{FRAMES}: {e}")))
        })?;

    let dir = std::env::temp_dir().join(format!(
        "groundcal-mcap-recording-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    let recording = OwnRecording { dir };
    let kinect = recording.dir.join("kinect");
    std::fs::create_dir_all(&kinect).map_err(|e| fail(format!("{}: {e}", kinect.display())))?;
    for (name, data) in &files {
        if name == FRAMES {
            continue;
        }
        let target = match name.as_str() {
            "session.json" | "poses.jsonl" | "kinect/INDEX.txt" => recording.dir.join(name),
            other => match other.strip_prefix("kinect/") {
                Some(dump) if plain_name(dump) => kinect.join(dump),
                _ => {
                    return Err(fail(format!(
                        "an attachment {RECORDING_PREFIX}{other}, not a recording's file"
                    )))
                }
            },
        };
        std::fs::write(&target, data).map_err(|e| fail(format!("{}: {e}", target.display())))?;
    }
    if let Some(name) = frames.iter().find(|name| !plain_name(name)) {
        return Err(fail(format!(
            "{RECORDING_PREFIX}{FRAMES} names \"{name}\", not a frame's file"
        )));
    }

    let mut written = 0usize;
    McapStream::new(Limits::default())
        .read(
            open()?,
            |topic| topic == RAW_TOPIC,
            |_| false,
            |message| {
                let Some(name) = frames.get(written) else {
                    return Err(format!(
                        "more raw frames than the {} {FRAMES} names",
                        frames.len()
                    ));
                };
                let image = groundcal_ros::msg::Image::decode(message.data)
                    .map_err(|e| format!("raw frame {}: {e}", written + 1))?;
                let pixels =
                    raw_pixels(&image).map_err(|e| format!("raw frame {}: {e}", written + 1))?;
                let frame = DepthImage {
                    width: image.width as usize,
                    height: image.height as usize,
                    pixels,
                };
                let target = kinect.join(name);
                std::fs::write(&target, encode_fakenect_pgm(&frame))
                    .map_err(|e| format!("{}: {e}", target.display()))?;
                written += 1;
                Ok(())
            },
        )
        .map_err(|e| fail(read_error(e)))?;
    if written != frames.len() {
        return Err(fail(format!(
            "{written} raw frames on {RAW_TOPIC}, where {FRAMES} names {}",
            frames.len()
        )));
    }
    Ok(Some(recording))
}

/// Whether the file's first record, MCAP's Header (opcode 1: profile, then
/// library, each a u32 length and its bytes), names groundcal as the
/// library that wrote it.
fn written_by_groundcal(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 8 + 9 + 4096];
    let Ok(mut file) = crate::platform::files::open_regular(path) else {
        return false;
    };
    let mut read = 0;
    while read < head.len() {
        match file.read(&mut head[read..]) {
            Ok(0) | Err(_) => break,
            Ok(n) => read += n,
        }
    }
    let body = &head[..read];
    if body.len() < 17 || body[8] != 0x01 {
        return false;
    }
    let string_at = |at: usize| -> Option<(&[u8], usize)> {
        let length = u32::from_le_bytes(body.get(at..at + 4)?.try_into().ok()?) as usize;
        Some((body.get(at + 4..at + 4 + length)?, at + 4 + length))
    };
    string_at(17)
        .and_then(|(_, next)| string_at(next))
        .is_some_and(|(library, _)| library.starts_with(b"groundcal"))
}

/// A file name with no directory in it.
fn plain_name(name: &str) -> bool {
    !name.is_empty() && !name.contains('/') && !name.contains('\\') && name != "." && name != ".."
}

/// A `mono16` image's pixels, row by row.
fn raw_pixels(image: &groundcal_ros::msg::Image) -> Result<Vec<u16>, String> {
    let (width, height) = (image.width as usize, image.height as usize);
    if image.encoding != "mono16" {
        return Err(format!("encoding \"{}\", not mono16", image.encoding));
    }
    if image.step as usize != 2 * width || image.data.len() != 2 * width * height {
        return Err(format!(
            "{} bytes in rows of {}, not a {width}×{height} mono16 image",
            image.data.len(),
            image.step
        ));
    }
    Ok(image
        .data
        .chunks_exact(2)
        .map(|b| {
            let pair = [b[0], b[1]];
            if image.is_bigendian {
                u16::from_be_bytes(pair)
            } else {
                u16::from_le_bytes(pair)
            }
        })
        .collect())
}

fn read_error(e: ReadError<String>) -> String {
    match e {
        ReadError::Stream(e) => e.to_string(),
        ReadError::Stopped(what) => what,
    }
}
