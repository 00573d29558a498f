//! A ROS 2 bag (MCAP) made by another robot's stack, turned into what a
//! calibration needs: the depth camera's intrinsics, the feet in the body at
//! the home stance, and per still pose its feet and its depth frames.
//!
//! - Depth: `sensor_msgs/msg/Image`, `16UC1` millimetres (REP 118) or
//!   `32FC1` metres; 0, NaN and ∞ are no reading. Both are fitted in
//!   inverse depth as metric frames are (`DepthEncoding::Metric`).
//! - Intrinsics: the first `sensor_msgs/msg/CameraInfo` (its `K`).
//! - The feet: `/tf` and `/tf_static`, the body frame to each foot's frame
//!   through whatever links lie between (a hexapod's URDF chain), at each
//!   moment; REP 103 axes, turned to groundcal's body frame.
//! - Still poses: the spans in which no foot moves in the body by more than
//!   `still_mm` for at least `still_s` (the body moves with the feet planted,
//!   so a body that moves moves every foot in its frame). The first still
//!   span is the home stance (its feet fix the ground frame); each still span
//!   with depth frames is a pose, with its last `frames_per_pose` frames.
//! - The nominal mount: the body → camera transform in the TF tree, when
//!   there is one (the robot's own guess tells which plane is the ground).
//!
//! The file is read twice: the first pass reads the transforms, the camera
//! info and the images' headers; the second only the frames chosen.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::stream::{Limits, McapStream, ReadError, StreamMessage};
use crate::calib::geometry::{PoseDegMm, Transform};
use crate::calib::observe::NominalMount;
use crate::calib::sensor::Intrinsics;
use crate::formats::export::{base_link_from_robot, robot_from_sensor_from_ros};
use groundcal_ros::msg::{CameraInfo, Cdr, Header, Image, Message, TfMessage};
use groundcal_ros::CdrReader;

/// What to read from a bag, and how still is still.
#[derive(Debug, Clone, PartialEq)]
pub struct BagOptions {
    /// The depth images' topic.
    pub depth_topic: String,
    /// Their CameraInfo's topic.
    pub camera_info_topic: String,
    /// The body's frame (groundcal's robot frame in REP 103 axes).
    pub body_frame: String,
    /// The feet's frames, foot 1 first: three or more (a quadruped's four, a
    /// hexapod's six in conventions.md's order).
    pub foot_frames: Vec<String>,
    /// A pose is still while no foot moves in the body by more than this (mm)…
    pub still_mm: f64,
    /// …for at least this long (s).
    pub still_s: f64,
    /// The last frames of each still span that are fitted.
    pub frames_per_pose: usize,
    pub limits: Limits,
    /// The camera's stereo baseline as a person gave it (a flag, or the
    /// configuration's `[bag]`): before the bag's CameraInfo.
    pub baseline: Option<GivenBaseline>,
}

/// A stereo baseline given by a person, and where (`flag` or `config`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GivenBaseline {
    pub mm: f64,
    pub from: &'static str,
}

/// A disparity camera's own units: what its matcher measures, in which its
/// noise and fixed pattern arise. A Kinect's are its raw values (eighths of
/// a pixel); another camera's are pixels, `fx · baseline` of them per 1/m
/// of inverse depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraDisparity {
    pub baseline_mm: f64,
    /// Pixels of disparity per 1/m of inverse depth (`fx · baseline`, px·m).
    pub pixels_per_inverse_depth: f64,
    /// Where the baseline came from: `flag`, `config` or `camera_info`
    /// (the projection matrix's baseline term).
    pub from: &'static str,
}

impl Default for BagOptions {
    fn default() -> Self {
        Self {
            depth_topic: "/camera/depth/image_raw".into(),
            camera_info_topic: "/camera/depth/camera_info".into(),
            body_frame: crate::formats::export::PARENT_FRAME.into(),
            foot_frames: (1..=6).map(|k| format!("foot_{k}")).collect(),
            still_mm: 0.5,
            still_s: 0.3,
            frames_per_pose: 3,
            limits: Limits::default(),
            baseline: None,
        }
    }
}

/// The TF topics, both always read.
const TF_TOPICS: [&str; 2] = ["/tf", "/tf_static"];

/// How the depth values are stored once read: millimetres for `16UC1`,
/// tenths of a millimetre for `32FC1` (to 6.55 m; farther is beyond the
/// trusted range and counts as no reading).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthUnits {
    Millimetres,
    TenthsOfMillimetre,
}

impl DepthUnits {
    pub fn metres_per_unit(self) -> f64 {
        match self {
            DepthUnits::Millimetres => 1e-3,
            DepthUnits::TenthsOfMillimetre => 1e-4,
        }
    }
}

/// One still pose of the bag.
#[derive(Debug, Clone)]
pub struct BagPose {
    /// From 1, in time order.
    pub index: u32,
    /// The still span, nanoseconds.
    pub start: u64,
    pub end: u64,
    /// The feet in groundcal's body frame (mm), averaged over the span.
    pub feet_body_mm: Vec<[f64; 3]>,
    /// The stamps of the frames fitted (the span's last ones).
    pub stamps: Vec<u64>,
}

/// A bag, read.
#[derive(Debug, Clone)]
pub struct BagSession {
    pub path: PathBuf,
    pub intrinsics: Intrinsics,
    pub units: DepthUnits,
    /// The images' frame (their `header.frame_id`).
    pub camera_frame: String,
    pub home_feet_mm: Vec<[f64; 3]>,
    pub poses: Vec<BagPose>,
    /// From the TF tree's body → camera transform, when it has one.
    pub nominal_mount: Option<NominalMount>,
    /// The camera's own disparity, when its baseline is known (given, or in
    /// its CameraInfo); otherwise it is judged as a Kinect.
    pub disparity: Option<CameraDisparity>,
    /// What the operator should know (lens distortion ignored, frames left out).
    pub notes: Vec<String>,
    /// Depth images on the depth topic.
    pub images_seen: usize,
    /// BLAKE3 of the bytes of the file up to the end of its data (hex).
    pub digest: String,
    /// Where the chosen frames are, for [`BagSession::read_frames`].
    frames: FramePlan,
}

/// What the second pass over a bag reads: the chosen frames' stamps (and
/// their pose), the chunks that hold them, and the declarations seen.
#[derive(Debug, Clone)]
struct FramePlan {
    chosen: HashMap<u64, usize>,
    needed: BTreeSet<u64>,
    stream: McapStream,
    depth_topic: String,
}

/// A reader that hashes what passes through it.
struct Hashing<R> {
    inner: R,
    hasher: blake3::Hasher,
}

impl<R: std::io::Read> std::io::Read for Hashing<R> {
    fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buffer)?;
        self.hasher.update(&buffer[..n]);
        Ok(n)
    }
}

/// Why a bag could not be used; names the file and what was wrong (with
/// the control characters of anything the bag said escaped).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{}: {}",
    crate::platform::input::printable(path),
    crate::platform::input::printable(what)
)]
pub struct BagError {
    pub path: String,
    pub what: String,
}

/// The transforms of the TF tree: per child frame, its parent and the
/// transform at each stamp (`/tf_static`'s hold at every moment).
#[derive(Debug, Default)]
struct TfTree {
    edges: HashMap<String, TfEdge>,
}

#[derive(Debug)]
struct TfEdge {
    parent: String,
    /// (stamp, parent_from_child), in stamp order once sorted.
    samples: Vec<(u64, Isometry3<f64>)>,
}

impl TfTree {
    /// Adds a message's transforms; one that is not a rigid transform (a
    /// NaN or infinite value, a zero quaternion) is an error naming it.
    fn add(&mut self, message: &TfMessage, is_static: bool) -> Result<(), String> {
        for t in &message.transforms {
            let [x, y, z, w] = t.transform.rotation;
            let named = [
                ("translation.x", t.transform.translation[0]),
                ("translation.y", t.transform.translation[1]),
                ("translation.z", t.transform.translation[2]),
                ("rotation.x", x),
                ("rotation.y", y),
                ("rotation.z", z),
                ("rotation.w", w),
            ];
            if let Some((field, value)) = named.iter().find(|(_, v)| !v.is_finite()) {
                return Err(format!(
                    "the transform of frame \"{}\" from \"{}\": {field} = {value} is not a number a rigid transform can have",
                    t.child_frame_id, t.header.frame_id
                ));
            }
            if x * x + y * y + z * z + w * w < 1e-12 {
                return Err(format!(
                    "the transform of frame \"{}\" from \"{}\": its rotation is the zero quaternion",
                    t.child_frame_id, t.header.frame_id
                ));
            }
            let rotation = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
            let [tx, ty, tz] = t.transform.translation;
            let pose = Isometry3::from_parts(Translation3::new(tx, ty, tz), rotation);
            let stamp = if is_static {
                0
            } else {
                t.header.stamp.nanos().unwrap_or(0)
            };
            let edge = self
                .edges
                .entry(t.child_frame_id.clone())
                .or_insert_with(|| TfEdge {
                    parent: t.header.frame_id.clone(),
                    samples: Vec::new(),
                });
            // A frame that changes parent keeps its first (TF forbids it).
            if edge.parent == t.header.frame_id {
                edge.samples.push((stamp, pose));
            }
        }
        Ok(())
    }

    fn sort(&mut self) {
        for edge in self.edges.values_mut() {
            edge.samples.sort_by_key(|(stamp, _)| *stamp);
        }
    }

    /// The child frames on the way from `frame` up to `ancestor`, `frame`
    /// first; `None` when `ancestor` is not above it.
    fn chain(&self, frame: &str, ancestor: &str) -> Option<Vec<&str>> {
        let mut chain = Vec::new();
        let (mut at, mut edge) = match self.edges.get_key_value(frame) {
            Some((key, edge)) => (key.as_str(), Some(edge)),
            None if frame == ancestor => return Some(chain),
            None => return None,
        };
        while at != ancestor {
            let here = edge?;
            chain.push(at);
            at = here.parent.as_str();
            edge = self.edges.get(at);
            if chain.len() > 64 {
                return None; // a loop
            }
        }
        Some(chain)
    }

    /// `ancestor_from_frame` at `stamp` along `chain` (each edge's latest
    /// transform at or before it, or its first).
    fn at(&self, chain: &[&str], stamp: u64) -> Isometry3<f64> {
        let mut pose = Isometry3::identity();
        for child in chain.iter().rev() {
            let samples = &self.edges[*child].samples;
            let k = samples.partition_point(|(s, _)| *s <= stamp);
            pose *= samples[k.saturating_sub(1)].1;
        }
        pose
    }

    /// Every stamp at which one of the chains changes.
    fn stamps(&self, chains: &[Vec<&str>]) -> BTreeSet<u64> {
        chains
            .iter()
            .flatten()
            .flat_map(|child| self.edges[*child].samples.iter().map(|(s, _)| *s))
            .collect()
    }
}

/// A depth image's header, size and encoding (the first pass does not copy
/// its pixels).
struct ImageHead {
    /// The chunk it is in, if any.
    chunk: Option<u64>,
    stamp: u64,
    frame_id: String,
    width: u32,
    height: u32,
    encoding: String,
}

fn image_head(data: &[u8]) -> Result<ImageHead, String> {
    let mut r = CdrReader::new(data).map_err(|e| e.to_string())?;
    let header = Header::read(&mut r).map_err(|e| e.to_string())?;
    let height = r.u32("height").map_err(|e| e.to_string())?;
    let width = r.u32("width").map_err(|e| e.to_string())?;
    let encoding = r.string("encoding").map_err(|e| e.to_string())?;
    Ok(ImageHead {
        chunk: None,
        stamp: header.stamp.nanos().unwrap_or(0),
        frame_id: header.frame_id,
        width,
        height,
        encoding,
    })
}

/// An image's depth values in `units`, row by row; 0 for no reading.
fn depth_values(image: &Image, units: DepthUnits) -> Result<Vec<u16>, String> {
    let (width, height) = (image.width as usize, image.height as usize);
    let bytes_per_pixel = match image.encoding.as_str() {
        "16UC1" => 2,
        "32FC1" => 4,
        other => {
            return Err(format!(
                "a depth image encoded \"{other}\": groundcal reads 16UC1 (mm) and 32FC1 (m)"
            ))
        }
    };
    let step = image.step as usize;
    if step < width * bytes_per_pixel || image.data.len() < step * height {
        return Err(format!(
            "a {width}×{height} {} image of {} bytes with rows of {step}: too short",
            image.encoding,
            image.data.len()
        ));
    }
    let mut values = Vec::with_capacity(width * height);
    if image.encoding == "16UC1" && units == DepthUnits::Millimetres {
        // As they are: millimetres, 0 for no reading.
        for row in image.data.chunks_exact(step).take(height) {
            values.extend(row[..2 * width].chunks_exact(2).map(|pixel| {
                let pixel = [pixel[0], pixel[1]];
                if image.is_bigendian {
                    u16::from_be_bytes(pixel)
                } else {
                    u16::from_le_bytes(pixel)
                }
            }));
        }
        return Ok(values);
    }
    for row in image.data.chunks_exact(step).take(height) {
        for pixel in row[..width * bytes_per_pixel].chunks_exact(bytes_per_pixel) {
            let value = match (bytes_per_pixel, image.is_bigendian) {
                (2, false) => f64::from(u16::from_le_bytes([pixel[0], pixel[1]])) * 1e-3,
                (2, true) => f64::from(u16::from_be_bytes([pixel[0], pixel[1]])) * 1e-3,
                (_, false) => {
                    f64::from(f32::from_le_bytes([pixel[0], pixel[1], pixel[2], pixel[3]]))
                }
                (_, true) => {
                    f64::from(f32::from_be_bytes([pixel[0], pixel[1], pixel[2], pixel[3]]))
                }
            };
            let unit = (value / units.metres_per_unit()).round();
            values.push(if unit.is_finite() && (1.0..=65535.0).contains(&unit) {
                unit as u16
            } else {
                0
            });
        }
    }
    Ok(values)
}

/// The feet in groundcal's body frame (mm) from `body_from_foot`s.
fn feet_in_body(tree: &TfTree, chains: &[Vec<&str>], stamp: u64) -> Vec<[f64; 3]> {
    let robot_from_base_link = base_link_from_robot().transpose();
    chains
        .iter()
        .map(|chain| {
            let p = tree.at(chain, stamp).translation.vector;
            let p = robot_from_base_link * p * 1e3;
            [p.x, p.y, p.z]
        })
        .collect()
}

fn largest_move(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(a, b)| Vector3::from(*a).metric_distance(&Vector3::from(*b)))
        .fold(0.0, f64::max)
}

/// A span of moments in which no foot moved by more than `still_mm` from
/// where it was at the span's first moment.
struct Span {
    start: u64,
    end: u64,
    feet_sum: Vec<[f64; 3]>,
    moments: usize,
    first: Vec<[f64; 3]>,
}

/// Reads a bag and finds its still poses.
pub fn read_bag(path: &Path, options: &BagOptions) -> Result<BagSession, BagError> {
    let fail = |what: String| BagError {
        path: path.display().to_string(),
        what,
    };
    let open = || {
        crate::platform::files::open_regular(path)
            .map_err(|e| fail(format!("cannot {}: {}", e.action, e.source)))
    };
    let wanted = |topic: &str| {
        topic == options.depth_topic
            || topic == options.camera_info_topic
            || TF_TOPICS.contains(&topic)
    };
    let stream_failed = |e: ReadError<String>| match e {
        ReadError::Stream(e) => fail(e.to_string()),
        ReadError::Stopped(what) => fail(what),
    };

    // First pass: transforms, camera info, the images' heads.
    let mut tree = TfTree::default();
    let mut camera_info: Option<CameraInfo> = None;
    let mut heads: Vec<ImageHead> = Vec::new();
    let check_type = |m: &StreamMessage<'_>, name: &str| -> Result<(), String> {
        if m.encoding != "cdr" || (!m.schema.is_empty() && m.schema != name) {
            return Err(format!(
                "{}: a message of type \"{}\" encoded \"{}\" where {name} in CDR was expected",
                m.topic, m.schema, m.encoding
            ));
        }
        Ok(())
    };
    let mut hashing = Hashing {
        inner: std::io::BufReader::new(open()?),
        hasher: blake3::Hasher::new(),
    };
    let mut stream = McapStream::new(options.limits);
    stream
        .read(
            &mut hashing,
            wanted,
            |_| false,
            |m| -> Result<(), String> {
                if TF_TOPICS.contains(&m.topic) {
                    check_type(&m, TfMessage::NAME)?;
                    let message = TfMessage::decode(m.data)
                        .map_err(|e| format!("{} at {} ns: {e}", m.topic, m.log_time))?;
                    tree.add(&message, m.topic == "/tf_static")
                        .map_err(|e| format!("{} at {} ns: {e}", m.topic, m.log_time))?;
                } else if m.topic == options.camera_info_topic {
                    check_type(&m, CameraInfo::NAME)?;
                    if camera_info.is_none() {
                        camera_info = Some(
                            CameraInfo::decode(m.data)
                                .map_err(|e| format!("{} at {} ns: {e}", m.topic, m.log_time))?,
                        );
                    }
                } else {
                    check_type(&m, Image::NAME)?;
                    let mut head = image_head(m.data)
                        .map_err(|e| format!("{} at {} ns: {e}", m.topic, m.log_time))?;
                    head.chunk = m.chunk;
                    heads.push(head);
                }
                Ok(())
            },
        )
        .map_err(stream_failed)?;
    tree.sort();

    let Some(info) = camera_info else {
        return Err(fail(format!(
            "no CameraInfo on {} (give the topic with --camera-info-topic)",
            options.camera_info_topic
        )));
    };
    let Some(first) = heads.first() else {
        return Err(fail(format!(
            "no depth image on {} (give the topic with --depth-topic)",
            options.depth_topic
        )));
    };
    let intrinsics = Intrinsics {
        fx: info.k[0],
        fy: info.k[4],
        cx: info.k[2],
        cy: info.k[5],
        width: info.width as usize,
        height: info.height as usize,
    };
    // Each of K's four numbers named when it cannot be a camera's.
    for (field, value, positive) in [
        ("K[0] (fx)", intrinsics.fx, true),
        ("K[4] (fy)", intrinsics.fy, true),
        ("K[2] (cx)", intrinsics.cx, false),
        ("K[5] (cy)", intrinsics.cy, false),
    ] {
        if !value.is_finite() || (positive && value <= 0.0) {
            return Err(fail(format!(
                "{}: {field} = {value} is not a camera's {}",
                options.camera_info_topic,
                if positive {
                    "focal length (a positive number of pixels)"
                } else {
                    "principal point (a number of pixels)"
                }
            )));
        }
    }
    if intrinsics.width == 0 || intrinsics.height == 0 {
        return Err(fail(format!(
            "{}: K = {:?} for {}×{} is not a camera",
            options.camera_info_topic, info.k, info.width, info.height
        )));
    }
    let mut notes = Vec::new();
    if info.d.iter().any(|&d| d != 0.0) {
        notes.push(format!(
            "{} gives lens distortion ({}, D = {:?}); the depth images are taken as they are, as a Kinect's are",
            options.camera_info_topic, info.distortion_model, info.d
        ));
    }
    let disparity = camera_disparity(&info, &intrinsics, options, &mut notes)
        .map_err(|what| fail(format!("{}: {what}", options.camera_info_topic)))?;
    let units = match first.encoding.as_str() {
        "16UC1" => DepthUnits::Millimetres,
        "32FC1" => DepthUnits::TenthsOfMillimetre,
        other => {
            return Err(fail(format!(
                "{}: images encoded \"{other}\": groundcal reads 16UC1 (mm) and 32FC1 (m)",
                options.depth_topic
            )))
        }
    };
    let camera_frame = first.frame_id.clone();
    for head in &heads {
        if head.encoding != first.encoding
            || head.width as usize != intrinsics.width
            || head.height as usize != intrinsics.height
        {
            return Err(fail(format!(
                "{}: an image at {} ns is {}×{} {}, where the first is {} and CameraInfo says {}×{}",
                options.depth_topic,
                head.stamp,
                head.width,
                head.height,
                head.encoding,
                first.encoding,
                intrinsics.width,
                intrinsics.height
            )));
        }
    }

    // The feet over time.
    if options.foot_frames.len() < crate::calib::body::MIN_FEET {
        return Err(fail(format!(
            "{} foot frames cannot fix a body: give at least {} (--foot-frames)",
            options.foot_frames.len(),
            crate::calib::body::MIN_FEET
        )));
    }
    let mut chains = Vec::with_capacity(options.foot_frames.len());
    for foot in &options.foot_frames {
        chains.push(tree.chain(foot, &options.body_frame).ok_or_else(|| {
            fail(format!(
                "no TF path from {} to {foot} in /tf and /tf_static (give the frames with --body-frame and --foot-frames)",
                options.body_frame
            ))
        })?);
    }
    let mut moments = tree.stamps(&chains);
    moments.extend(heads.iter().map(|h| h.stamp));
    let mut spans: Vec<Span> = Vec::new();
    for &moment in &moments {
        let feet = feet_in_body(&tree, &chains, moment);
        match spans.last_mut() {
            Some(span) if largest_move(&span.first, &feet) <= options.still_mm => {
                span.end = moment;
                span.moments += 1;
                for (sum, foot) in span.feet_sum.iter_mut().zip(&feet) {
                    for (s, f) in sum.iter_mut().zip(foot) {
                        *s += f;
                    }
                }
            }
            _ => spans.push(Span {
                start: moment,
                end: moment,
                feet_sum: feet.clone(),
                moments: 1,
                first: feet,
            }),
        }
    }
    let still_ns = (options.still_s * 1e9) as u64;
    let mut still = spans
        .into_iter()
        .filter(|s| s.end - s.start >= still_ns)
        .map(|s| {
            let n = s.moments as f64;
            let feet: Vec<[f64; 3]> = s.feet_sum.iter().map(|f| f.map(|x| x / n)).collect();
            (s.start, s.end, feet)
        });
    let Some(home) = still.next() else {
        return Err(fail(format!(
            "the feet never stay still (within {} mm for {} s) in the body: no home stance",
            options.still_mm, options.still_s
        )));
    };
    let home_feet_mm = home.2.clone();
    let mut poses = Vec::new();
    for (start, end, feet_body_mm) in std::iter::once(home).chain(still) {
        let mut stamps: Vec<u64> = heads
            .iter()
            .map(|h| h.stamp)
            .filter(|s| (start..=end).contains(s))
            .collect();
        stamps.sort_unstable();
        stamps.dedup();
        if stamps.is_empty() {
            continue;
        }
        let keep = stamps.len().saturating_sub(options.frames_per_pose.max(1));
        stamps.drain(..keep);
        poses.push(BagPose {
            index: poses.len() as u32 + 1,
            start,
            end,
            feet_body_mm,
            stamps,
        });
    }
    if poses.is_empty() {
        return Err(fail(format!(
            "no depth image on {} was taken while the feet stood still",
            options.depth_topic
        )));
    }

    // The chosen frames are read in a second pass (`read_frames`), a pose
    // at a time, so that a bag's frames are never all in memory.
    let chosen: HashMap<u64, usize> = poses
        .iter()
        .enumerate()
        .flat_map(|(k, pose)| pose.stamps.iter().map(move |&s| (s, k)))
        .collect();
    // Only the chunks that hold a chosen image are decompressed again.
    let needed: BTreeSet<u64> = heads
        .iter()
        .filter(|h| chosen.contains_key(&h.stamp))
        .filter_map(|h| h.chunk)
        .collect();

    let nominal_mount = tree.chain(&camera_frame, &options.body_frame).map(|chain| {
        let base_link_from_optical = tree.at(&chain, heads[0].stamp);
        let transform = Transform::from_parts(
            base_link_from_optical.translation,
            base_link_from_optical.rotation.to_rotation_matrix(),
        );
        let mount = PoseDegMm::from_params(&robot_from_sensor_from_ros(&transform));
        NominalMount::from_values(mount.values())
    });
    Ok(BagSession {
        path: path.to_path_buf(),
        intrinsics,
        units,
        disparity,
        camera_frame,
        home_feet_mm,
        poses,
        nominal_mount,
        notes,
        images_seen: heads.len(),
        digest: hashing.hasher.finalize().to_hex().to_string(),
        frames: FramePlan {
            chosen,
            needed,
            stream,
            depth_topic: options.depth_topic.clone(),
        },
    })
}

impl BagSession {
    /// Reads the chosen frames again, in file order, and hands each pose's
    /// (its index in [`BagSession::poses`] and its frames, in the bag's
    /// units) to `each` as soon as they are all read: a pose's frames are
    /// freed by `each`, never all of a bag's at once. A pose whose frames did
    /// not all come is handed what came, at the end. Returns how many frames
    /// were read.
    pub fn read_frames(
        &self,
        mut each: impl FnMut(usize, Vec<Vec<u16>>) -> Result<(), String>,
    ) -> Result<usize, BagError> {
        let fail = |what: String| BagError {
            path: self.path.display().to_string(),
            what,
        };
        let plan = &self.frames;
        let mut stream = plan.stream.clone();
        let mut pending: Vec<Option<Vec<Vec<u16>>>> = vec![Some(Vec::new()); self.poses.len()];
        let mut read = 0;
        let file = crate::platform::files::open_regular(&self.path)
            .map_err(|e| fail(format!("cannot {}: {}", e.action, e.source)))?;
        stream
            .read(
                std::io::BufReader::new(file),
                |topic| topic == plan.depth_topic,
                |chunk| !plan.needed.contains(&chunk),
                |m| -> Result<(), String> {
                    let head = image_head(m.data).map_err(|e| format!("{}: {e}", m.topic))?;
                    let Some(&k) = plan.chosen.get(&head.stamp) else {
                        return Ok(());
                    };
                    let wanted = self.poses[k].stamps.len();
                    // Handed on already, or two images of one stamp: the first.
                    let Some(frames) = pending[k].as_mut() else {
                        return Ok(());
                    };
                    if frames.len() >= wanted {
                        return Ok(());
                    }
                    let image = Image::decode(m.data)
                        .map_err(|e| format!("{} at {} ns: {e}", m.topic, m.log_time))?;
                    let values = depth_values(&image, self.units)
                        .map_err(|e| format!("{} at {} ns: {e}", m.topic, head.stamp))?;
                    frames.push(values);
                    read += 1;
                    if frames.len() == wanted {
                        let frames = pending[k].take().unwrap_or_default();
                        each(k, frames)?;
                    }
                    Ok(())
                },
            )
            .map_err(|e| match e {
                ReadError::Stream(e) => fail(e.to_string()),
                ReadError::Stopped(what) => fail(what),
            })?;
        for (k, frames) in pending.into_iter().enumerate() {
            if let Some(frames) = frames {
                each(k, frames).map_err(fail)?;
            }
        }
        Ok(read)
    }
}

/// The camera's own disparity: its baseline as a person gave it, else as
/// its CameraInfo's projection matrix gives it (a stereo pair's second
/// camera: `P[3] = −fx·baseline`), else unknown (judged as a Kinect, and
/// the notes say so). Where both are known and differ by more than 1 %, the
/// notes say that too.
fn camera_disparity(
    info: &CameraInfo,
    intrinsics: &Intrinsics,
    options: &BagOptions,
    notes: &mut Vec<String>,
) -> Result<Option<CameraDisparity>, String> {
    let from_projection = if info.p[3] == 0.0 {
        None
    } else {
        let mm = (info.p[3] / info.p[0]).abs() * 1e3;
        crate::calib::depth::check_baseline_mm(mm).map_err(|why| {
            format!(
                "P[3] = {} with P[0] = {} gives a baseline of {why}",
                info.p[3], info.p[0]
            )
        })?;
        Some(mm)
    };
    let (mm, from) = match (options.baseline, from_projection) {
        (Some(given), projected) => {
            if let Some(projected) = projected.filter(|p| (p - given.mm).abs() > 0.01 * given.mm) {
                notes.push(format!(
                    "the camera's baseline is taken as {:.1} mm (the {}), where its CameraInfo's projection matrix says {projected:.1} mm",
                    given.mm,
                    if given.from == "flag" {
                        "flag --baseline-mm"
                    } else {
                        "configuration's [bag] baseline_mm"
                    },
                ));
            }
            (given.mm, given.from)
        }
        (None, Some(projected)) => (projected, "camera_info"),
        (None, None) => {
            notes.push(
                "the depth camera's baseline is not known (not in its CameraInfo, nor given as [bag] baseline_mm or --baseline-mm): its depth pattern is reported and gated as a Kinect v1's".into(),
            );
            return Ok(None);
        }
    };
    Ok(Some(CameraDisparity {
        baseline_mm: mm,
        pixels_per_inverse_depth: intrinsics.fx * mm * 1e-3,
        from,
    }))
}
