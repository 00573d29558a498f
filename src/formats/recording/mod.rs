//! Reading groundcal's input files (`shared/spec/recording.md`).
//!
//! Readers are strict: every defect is an [`InputError`] naming the file, the
//! line where known, and what was expected. Nothing half-read is returned.

pub mod dump;
pub mod planes;
pub mod poses;
pub mod session;
pub mod writer;

use std::path::{Path, PathBuf};

use crate::formats::depth_image::{fakenect_pixels_start, parse_fakenect_pgm_into, DepthImage};
use dump::{parse_index, DumpEntry, EntryKind};
use poses::{parse_poses, PoseRecord};
use session::Session;

pub use crate::platform::input::{read_bounded, read_bounded_into, InputError};

/// Largest `session.json` accepted: a few kilobytes in any recording.
const MAX_SESSION_BYTES: u64 = 1 << 20;
/// Largest `poses.jsonl` accepted: [`poses::MAX_POSES`] records of at most
/// [`poses::MAX_FILES_PER_POSE`] names each of each kind fit in about 20 MB.
const MAX_POSES_BYTES: u64 = 32 << 20;
/// Largest `INDEX.txt` accepted: [`dump::MAX_INDEX_ENTRIES`] names of about
/// 40 bytes. These bounds keep a hostile recording's open under 256 MB
/// (docs/reliability.md).
const MAX_INDEX_BYTES: u64 = 16 << 20;

/// A recording (recording.md), checked when opened: its text files parsed,
/// every frame a pose names present in `INDEX.txt` and on disk with the size
/// of a depth frame. Frames themselves are read one pose at a time.
#[derive(Debug, Clone)]
pub struct Recording {
    pub dir: PathBuf,
    pub session: Session,
    pub poses: Vec<PoseRecord>,
    /// `poses.jsonl` ends part-way through a record, which was left out
    /// (only a recording opened with [`Recording::open_cut_off`]).
    pub cut_off: Option<poses::CutOff>,
    pub index: Vec<DumpEntry>,
    /// The text files, for the input digest.
    texts: [String; 3],
}

/// A text file of at most `max_bytes`, kept once (its bytes are the text's).
fn read_text(path: &Path, max_bytes: u64) -> Result<String, InputError> {
    let bytes = read_bounded(path, max_bytes)?;
    String::from_utf8(bytes)
        .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))
}

impl Recording {
    /// Opens and checks a recording directory. One whose `poses.jsonl` ends
    /// part-way through a record (a power cut while recording) is refused,
    /// naming the line and the byte: see [`Recording::open_cut_off`].
    pub fn open(dir: &Path) -> Result<Self, InputError> {
        let recording = Self::open_cut_off(dir)?;
        match recording.cut_off {
            Some(cut) => Err(InputError::new(
                &dir.join("poses.jsonl"),
                Some(cut.line),
                format!(
                    "{}; `groundcal replay --cut-off` replays the poses before it",
                    cut.describe()
                ),
            )),
            None => Ok(recording),
        }
    }

    /// Opens and checks a recording directory as [`Recording::open`] does,
    /// but takes one whose last record is cut off part-way: without that
    /// pose, and with [`Recording::cut_off`] saying where it was cut.
    pub fn open_cut_off(dir: &Path) -> Result<Self, InputError> {
        if !dir.is_dir() {
            return Err(InputError::new(
                dir,
                None,
                "not a directory (expected a recording: session.json, poses.jsonl, kinect/)",
            ));
        }
        let session_path = dir.join("session.json");
        let session_text = read_text(&session_path, MAX_SESSION_BYTES)?;
        let session = Session::parse(&session_path, &session_text)?;
        let poses_path = dir.join("poses.jsonl");
        let poses_text = read_text(&poses_path, MAX_POSES_BYTES)?;
        let poses_file = parse_poses(&poses_path, &poses_text)?;
        let index_path = dir.join("kinect").join("INDEX.txt");
        let index_text = read_text(&index_path, MAX_INDEX_BYTES)?;
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
            cut_off: poses_file.cut_off,
            index,
            texts: [session_text, poses_text, index_text],
        })
    }

    /// The recording's text files as read, by their paths in it.
    pub fn named_text_files(&self) -> [(&'static str, &str); 3] {
        [
            ("session.json", &self.texts[0]),
            ("poses.jsonl", &self.texts[1]),
            ("kinect/INDEX.txt", &self.texts[2]),
        ]
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

    /// A depth frame's pixels, read from its file straight into `pixels`
    /// (reused from frame to frame), the file's bytes added to `digest` when
    /// one is given.
    ///
    /// The same pixels and errors as [`Recording::read_depth_frame_into`]
    /// without the file's copy: a replay reads about 100 MB of frames, and
    /// copying and converting them again cost a fifth of its time
    /// (docs/performance.md). A file that is not a plain dump of the
    /// session's size is read whole and explained by the parser.
    pub fn read_depth_pixels_into(
        &self,
        name: &str,
        pixels: &mut Vec<u16>,
        mut digest: Option<&mut blake3::Hasher>,
    ) -> Result<(), InputError> {
        let path = self.kinect_path(name);
        let intrinsics = self.session.kinect.intrinsics;
        if read_dump_pixels(
            &path,
            intrinsics.width,
            intrinsics.height,
            pixels,
            digest.as_deref_mut(),
        ) {
            return Ok(());
        }
        let mut bytes = Vec::new();
        self.read_depth_frame_into(name, &mut bytes, pixels)?;
        if let Some(digest) = digest {
            digest.update(&bytes);
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
        [
            self.texts[0].as_bytes(),
            self.texts[1].as_bytes(),
            self.texts[2].as_bytes(),
        ]
    }
}

/// Size of a fakenect depth file: the header and two bytes per pixel.
/// [`Recording::read_depth_pixels_into`]'s direct path: true when the file
/// was a dump of exactly `width` × `height` and its pixels are in `pixels`
/// (and its bytes in `digest`); false (nothing added to `digest`) for anything
/// else, including an error, which the whole-file reader then reports.
fn read_dump_pixels(
    path: &Path,
    width: usize,
    height: usize,
    pixels: &mut Vec<u16>,
    digest: Option<&mut blake3::Hasher>,
) -> bool {
    use std::io::Read;
    let Ok(mut file) = crate::platform::files::open_regular(path) else {
        return false;
    };
    // The header is about 18 bytes; 64 hold it with room.
    let mut head = [0u8; 64];
    let mut filled = 0;
    while filled < head.len() {
        match file.read(&mut head[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return false,
        }
    }
    let Some((w, h, start)) = fakenect_pixels_start(&head[..filled]) else {
        return false;
    };
    if (w, h) != (width, height) {
        return false;
    }
    if pixels.len() != w * h {
        pixels.clear();
        pixels.resize(w * h, 0);
    }
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(pixels.as_mut_slice());
    let early = &head[start..filled];
    if early.len() > bytes.len() {
        return false;
    }
    bytes[..early.len()].copy_from_slice(early);
    if file.read_exact(&mut bytes[early.len()..]).is_err() {
        return false;
    }
    // Nothing may follow the pixels.
    let mut more = [0u8; 1];
    if !matches!(file.read(&mut more), Ok(0)) {
        return false;
    }
    if let Some(digest) = digest {
        digest.update(&head[..start]);
        digest.update(bytes);
    }
    // Fakenect writes the host's order, which the format takes as little-endian.
    if cfg!(target_endian = "big") {
        for pixel in pixels.iter_mut() {
            *pixel = u16::from_le(*pixel);
        }
    }
    true
}

pub fn fakenect_frame_len(width: usize, height: usize) -> usize {
    format!("P5 {width} {height} 65535\n").len() + 2 * width * height
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dump(width: usize, height: usize) -> Vec<u8> {
        let mut bytes = format!("P5 {width} {height} 65535\n").into_bytes();
        for i in 0..width * height {
            bytes.extend_from_slice(&((i * 37 % 2048) as u16).to_le_bytes());
        }
        bytes
    }

    /// A test's own directory for its files, removed when dropped (the
    /// files were left in /tmp after every run).
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(test: &str) -> Self {
            let dir = std::env::temp_dir()
                .join(format!("groundcal-recording-{test}-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }

        fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, bytes).unwrap();
            path
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn a_dump_read_straight_into_its_pixels_is_the_parsers_and_the_files_digest() {
        let bytes = dump(40, 30);
        let scratch = Scratch::new("plain");
        let path = scratch.file("plain.pgm", &bytes);
        let (mut pixels, mut digest) = (vec![7u16; 3], blake3::Hasher::new());
        assert!(read_dump_pixels(
            &path,
            40,
            30,
            &mut pixels,
            Some(&mut digest)
        ));
        let parsed = crate::formats::depth_image::parse_fakenect_pgm(&path, &bytes).unwrap();
        assert_eq!(pixels, parsed.pixels);
        assert_eq!(digest.finalize(), blake3::hash(&bytes));
        // Again into the same buffer, now of the right size.
        let mut digest = blake3::Hasher::new();
        assert!(read_dump_pixels(
            &path,
            40,
            30,
            &mut pixels,
            Some(&mut digest)
        ));
        assert_eq!(pixels, parsed.pixels);
    }

    #[test]
    fn anything_but_a_plain_dump_of_the_sessions_size_is_left_to_the_parser() {
        let scratch = Scratch::new("not-plain");
        let good = dump(40, 30);
        let mut trailing = good.clone();
        trailing.push(0);
        let mut byte_maxval = b"P5 40 30 255\n".to_vec();
        byte_maxval.extend_from_slice(&good[b"P5 40 30 65535\n".len()..]);
        let cases: [(&str, &[u8]); 6] = [
            ("cut", &good[..good.len() - 1]),
            ("header-only", &good[..b"P5 40 30 65535\n".len()]),
            ("trailing", &trailing),
            ("maxval", &byte_maxval),
            ("magic", b"P6 40 30 65535\n"),
            ("empty", b""),
        ];
        for (name, bytes) in cases {
            let path = scratch.file(&format!("{name}.pgm"), bytes);
            let (mut pixels, mut digest) = (Vec::new(), blake3::Hasher::new());
            assert!(
                !read_dump_pixels(&path, 40, 30, &mut pixels, Some(&mut digest)),
                "{name}"
            );
            assert_eq!(
                digest.finalize(),
                blake3::Hasher::new().finalize(),
                "{name}"
            );
        }
        let path = scratch.file("other-size.pgm", &good);
        let (mut pixels, mut digest) = (Vec::new(), blake3::Hasher::new());
        assert!(!read_dump_pixels(
            &path,
            30,
            40,
            &mut pixels,
            Some(&mut digest)
        ));
        assert!(!read_dump_pixels(
            &path.with_extension("missing"),
            40,
            30,
            &mut pixels,
            Some(&mut digest)
        ));
    }
}
