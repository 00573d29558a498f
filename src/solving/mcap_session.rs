//! A session as one MCAP file, for the tools robot engineers already use:
//! Foxglove and ROS 2 (`ros2 bag info`, `ros2 bag play`, RViz).
//!
//! Profile `ros2`, `ros2msg` schemas and CDR messages (the rosbag2 MCAP
//! storage plugin's layout), chunked with message and chunk indexes and
//! statistics, so that a reader can seek. Stamps are the frames' own capture
//! times (the fakenect names'), and messages are written in capture order.
//! What each topic holds is in docs/export.md.
//!
//! Frames follow REP 103 (x forward, y left, z up): groundcal's ground and
//! body frames (Y up, Z right; conventions.md) are turned by the fixed
//! [`base_link_from_robot`] on the way out, and the depth camera is
//! `camera_depth_optical_frame` (x right, y down, z forward), as in
//! libfreenect and the ROS drivers; the mount is `export`'s
//! (docs/export.md's formulas).

use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use crate::calib::geometry::{sensor_from_optical, Plane, Transform};
use crate::calib::sensor::{DepthModel, Intrinsics};
use crate::formats::export::{
    base_link_from_camera_optical, base_link_from_robot, quaternion_xyzw,
};
use crate::formats::output::{PlaneJson, ResultJson};
use crate::formats::recording::Recording;
use crate::platform::files::{AtomicFile, FileError};
use crate::platform::input::InputError;
use crate::solving::replay::Replay;
use groundcal_ros::msg::{
    self, CameraInfo, Header, Image, Message, PointCloud2, PoseFit, TfMessage, TransformStamped,
};

/// The recording a session is written from, carried whole as attachments
/// (`bag::own` reads it back): its text files and small dumps under
/// [`RECORDING_PREFIX`] by their paths in the recording, and [`FRAMES`],
/// the names of its depth frames in the order of the raw topic's messages.
pub mod recording_attachment {
    pub const RECORDING_PREFIX: &str = "groundcal/recording/";
    pub const FRAMES: &str = "frames.json";
}

/// The topics, in one place (docs/export.md describes each).
pub mod topic {
    /// Depth in millimetres, `16UC1` (REP 118), 0 where there is no reading.
    pub const DEPTH_MM: &str = "/camera/depth/image_raw";
    /// The Kinect's raw 11-bit values as read, `mono16`, 2047 for no reading:
    /// nothing of the recording is lost.
    pub const DEPTH_RAW: &str = "/camera/depth/raw_11bit";
    pub const CAMERA_INFO: &str = "/camera/depth/camera_info";
    pub const TF: &str = "/tf";
    pub const TF_STATIC: &str = "/tf_static";
    /// Per pose, the readings the ground fit took for the ground (the page's
    /// green cells: one reading per 8 × 8 pixels of the pose's first frame).
    pub const GROUND_INLIERS: &str = "/groundcal/ground/inliers";
    /// Per pose, the ground as measured: points of the fitted plane where
    /// the camera's rays meet it.
    pub const GROUND_MEASURED: &str = "/groundcal/ground/measured";
    /// Per pose, the ground the result predicts from the body pose.
    pub const GROUND_PREDICTED: &str = "/groundcal/ground/predicted";
    /// Per pose, θ and e_d and why a pose was set aside.
    pub const POSE_FIT: &str = "/groundcal/pose_fit";
}

/// The frames' names.
pub mod frame {
    /// The ground frame G (conventions.md), z up.
    pub const GROUND: &str = "ground";
    /// The robot body R, z up (`export`'s parent frame).
    pub const BODY: &str = crate::formats::export::PARENT_FRAME;
    /// The depth camera, x right, y down, z forward (`export`'s child frame).
    pub const OPTICAL: &str = crate::formats::export::CHILD_FRAME;

    /// A foot of the robot, 1 to 6.
    pub fn foot(k: usize) -> String {
        format!("foot_{k}")
    }
}

/// `ground_from_robot` in REP 103's frames: the ground frame G has the
/// body's axes (X forward, Y up, Z right), so both turn by
/// [`base_link_from_robot`].
pub fn ground_from_base_link(ground_from_robot: &Transform) -> (Matrix3<f64>, Vector3<f64>) {
    let c = base_link_from_robot();
    (
        c * ground_from_robot.rotation.matrix() * c.transpose(),
        c * ground_from_robot.translation.vector,
    )
}

/// Why no MCAP file was written.
#[derive(Debug, thiserror::Error)]
pub enum McapError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    File(#[from] FileError),
    #[error("{path}: cannot write MCAP: {}", innermost(source))]
    Mcap {
        path: String,
        source: mcap::McapError,
    },
}

/// What an MCAP error comes down to: the system's own words for an I/O
/// error ("No space left on device"), not the library's wrapper around them.
fn innermost(error: &mcap::McapError) -> String {
    let mut cause: &dyn std::error::Error = error;
    while let Some(deeper) = cause.source() {
        cause = deeper;
    }
    cause.to_string()
}

/// What was written: messages per topic, and the file's size.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct McapSummary {
    pub messages: BTreeMap<String, u64>,
    pub bytes: u64,
}

/// Writes a replayed recording, with its result, as an MCAP file at `path`
/// (whole or not at all). The frames are read again, one at a time.
pub fn write_replay(
    path: &Path,
    recording: &Recording,
    replay: &Replay,
) -> Result<McapSummary, McapError> {
    writable_place(path)?;
    let mut file = AtomicFile::create(path)?;
    let mcap_error = |source| McapError::Mcap {
        path: path.display().to_string(),
        source,
    };
    let bytes = {
        let sink = BufWriter::with_capacity(1 << 20, file.file());
        let mut writer = SessionWriter::new(sink, replay.result.clone()).map_err(mcap_error)?;
        writer
            .write_recording(recording, replay)
            .map_err(|e| match e {
                WriteError::Input(e) => McapError::Input(e),
                WriteError::Mcap(e) => mcap_error(e),
            })?;
        writer.finish().map_err(mcap_error)?
    };
    let summary = McapSummary {
        messages: bytes.0,
        bytes: bytes.1,
    };
    file.commit()?;
    Ok(summary)
}

/// Refuses an MCAP path whose directory does not exist: it is a typing
/// mistake to say, not a directory to make (as any other unwritable path).
pub fn writable_place(path: &Path) -> Result<(), McapError> {
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    if dir.is_dir() {
        return Ok(());
    }
    Err(McapError::File(FileError {
        path: path.to_path_buf(),
        action: "create",
        source: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("its directory {} does not exist", dir.display()),
        ),
    }))
}

enum WriteError {
    Input(InputError),
    Mcap(mcap::McapError),
}

impl From<mcap::McapError> for WriteError {
    fn from(e: mcap::McapError) -> Self {
        WriteError::Mcap(e)
    }
}

impl From<InputError> for WriteError {
    fn from(e: InputError) -> Self {
        WriteError::Input(e)
    }
}

/// A channel and its count of messages.
struct Channel {
    id: u16,
    topic: &'static str,
    sequence: u32,
}

/// The ROS 2 QoS rosbag2 records for a latched topic (`/tf_static`):
/// transient local, so that a subscriber that joins late gets it.
const TRANSIENT_LOCAL_QOS: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  \
deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    \
nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    \
nsec: 4294967295\n  avoid_ros_namespace_conventions: false\n";

/// The largest dump other than a depth frame carried (a tilt state is 12
/// bytes, an RGB frame is not one of groundcal's).
const SMALL_DUMP_BYTES: u64 = 64 << 10;

/// Chunks of about 4 MiB: a reader seeks to a pose without reading the file.
const CHUNK_BYTES: u64 = 4 << 20;

struct SessionWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    result: ResultJson,
    channels: BTreeMap<&'static str, Channel>,
    /// The last stamp written, nanoseconds: poses without frames take it.
    last_stamp: u64,
    /// One message's CDR, its memory reused (an image is 600 kB).
    encoded: Vec<u8>,
}

impl<W: Write + Seek> SessionWriter<W> {
    fn new(sink: W, result: ResultJson) -> Result<Self, mcap::McapError> {
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!("groundcal {}", env!("CARGO_PKG_VERSION")))
            .compression(None)
            .chunk_size(Some(CHUNK_BYTES))
            // Every chunk carries the CRC of its records; a second CRC over
            // the whole data section (optional in MCAP: 0) would read every
            // byte again for nothing a reader lacks.
            .calculate_data_section_crc(false)
            .create(sink)?;
        Ok(Self {
            mcap,
            result,
            channels: BTreeMap::new(),
            last_stamp: 0,
            encoded: Vec::new(),
        })
    }

    fn channel<M: Message>(&mut self, topic: &'static str) -> Result<u16, mcap::McapError> {
        if let Some(channel) = self.channels.get(topic) {
            return Ok(channel.id);
        }
        let schema = self
            .mcap
            .add_schema(M::NAME, "ros2msg", M::schema().as_bytes())?;
        let mut metadata = BTreeMap::new();
        if topic == topic::TF_STATIC {
            metadata.insert(
                "offered_qos_profiles".to_string(),
                TRANSIENT_LOCAL_QOS.to_string(),
            );
        }
        let id = self.mcap.add_channel(schema, topic, "cdr", &metadata)?;
        self.channels.insert(
            topic,
            Channel {
                id,
                topic,
                sequence: 0,
            },
        );
        Ok(id)
    }

    fn write<M: Message>(
        &mut self,
        topic: &'static str,
        stamp: u64,
        message: &M,
    ) -> Result<(), mcap::McapError> {
        let mut encoded = std::mem::take(&mut self.encoded);
        message.encode_into(&mut encoded);
        let written = self.write_encoded::<M>(topic, stamp, &encoded);
        self.encoded = encoded;
        written
    }

    /// A message of type `M` already encoded.
    fn write_encoded<M: Message>(
        &mut self,
        topic: &'static str,
        stamp: u64,
        encoded: &[u8],
    ) -> Result<(), mcap::McapError> {
        let id = self.channel::<M>(topic)?;
        let sequence = match self.channels.get_mut(topic) {
            Some(channel) => {
                channel.sequence += 1;
                channel.sequence
            }
            None => 0,
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence,
            log_time: stamp,
            publish_time: stamp,
        };
        self.last_stamp = self.last_stamp.max(stamp);
        self.mcap.write_to_known_channel(&header, encoded)
    }

    /// A 16-bit depth image, encoded straight from its pixels.
    fn write_depth(
        &mut self,
        topic: &'static str,
        header: &Header,
        (width, height): (u32, u32),
        encoding: &str,
        pixels: impl ExactSizeIterator<Item = u16>,
    ) -> Result<(), mcap::McapError> {
        let mut encoded = std::mem::take(&mut self.encoded);
        msg::encode_u16_image(header, width, height, encoding, pixels, &mut encoded);
        let stamp = header.stamp.nanos().unwrap_or(0);
        let written = self.write_encoded::<Image>(topic, stamp, &encoded);
        self.encoded = encoded;
        written
    }

    fn write_recording(
        &mut self,
        recording: &Recording,
        replay: &Replay,
    ) -> Result<(), WriteError> {
        let session = &recording.session;
        let intrinsics = session.kinect.intrinsics;
        let millimetres = millimetre_table(&session.kinect.depth_model);
        // The capture times of INDEX.txt's names, parsed when the recording
        // was opened (every frame a pose names is there).
        let times: std::collections::HashMap<&str, f64> = recording
            .index
            .iter()
            .map(|entry| (entry.name.as_str(), entry.time))
            .collect();
        let stamps: Vec<Vec<u64>> = recording
            .poses
            .iter()
            .map(|pose| {
                pose.depth_frames
                    .iter()
                    .map(|name| times.get(name.as_str()).map_or(0, |&t| seconds_to_nanos(t)))
                    .collect()
            })
            .collect();
        let first_stamp = stamps.iter().flatten().copied().next().unwrap_or(0);
        self.last_stamp = first_stamp;

        // The mount, once, before everything.
        if let Some(robot_from_sensor) = self
            .result
            .robot_from_sensor
            .as_ref()
            .map(|m| m.pose().to_params())
        {
            let mount = base_link_from_camera_optical(&robot_from_sensor);
            let (rotation, translation) = (*mount.rotation.matrix(), mount.translation.vector);
            let message = TfMessage {
                transforms: vec![transform_stamped(
                    first_stamp,
                    frame::BODY,
                    frame::OPTICAL,
                    &rotation,
                    &translation,
                )],
            };
            self.write(topic::TF_STATIC, first_stamp, &message)?;
        }

        let mut file = Vec::new();
        let mut pixels = Vec::new();
        for (k, pose) in recording.poses.iter().enumerate() {
            let pose_stamps = &stamps[k];
            let start = pose_stamps.first().copied().unwrap_or(self.last_stamp);
            if let Some(Some(ground_from_robot)) = replay.ground_from_robot.get(k) {
                self.write(
                    topic::TF,
                    start,
                    &body_and_feet(start, ground_from_robot, &pose.feet_body_mm),
                )?;
            }
            for (name, &stamp) in pose.depth_frames.iter().zip(pose_stamps) {
                recording.read_depth_frame_into(name, &mut file, &mut pixels)?;
                let header = Header::new(stamp, frame::OPTICAL);
                let size = (intrinsics.width as u32, intrinsics.height as u32);
                let raw = pixels.iter().copied();
                self.write_depth(topic::DEPTH_RAW, &header, size, "mono16", raw)?;
                let depth = pixels
                    .iter()
                    .map(|&raw| millimetres[usize::from(raw.min(2047))]);
                self.write_depth(topic::DEPTH_MM, &header, size, "16UC1", depth)?;
                self.write(topic::CAMERA_INFO, stamp, &camera_info(header, &intrinsics))?;
            }
            let end = pose_stamps.last().copied().unwrap_or(start);
            self.write_pose_fit(
                pose.index,
                end,
                &intrinsics,
                replay.ground_points.get(k).and_then(Option::as_deref),
            )?;
        }
        self.attach_recording(recording)
    }

    /// The recording itself, as attachments ([`recording_attachment`]): its
    /// text files, its small dumps (tilt states), and the names of its
    /// depth frames in the order of the raw topic, whose messages hold
    /// their pixels. `replay` of the file reads it back whole.
    fn attach_recording(&mut self, recording: &Recording) -> Result<(), WriteError> {
        use recording_attachment::{FRAMES, RECORDING_PREFIX};
        let stamp = self.last_stamp;
        let mut attach = |name: String, media_type: &str, data: Vec<u8>| {
            self.mcap.attach(&mcap::Attachment {
                log_time: stamp,
                create_time: stamp,
                name: format!("{RECORDING_PREFIX}{name}"),
                media_type: media_type.into(),
                data: data.into(),
            })
        };
        for (name, text) in recording.named_text_files() {
            attach(name.to_string(), "text/plain", text.as_bytes().to_vec())?;
        }
        for entry in &recording.index {
            if entry.kind == crate::formats::recording::dump::EntryKind::Depth {
                continue;
            }
            // A small dump the INDEX names; one that is not there is not
            // carried (replay reads only the dumps a pose names).
            let path = recording.kinect_path(&entry.name);
            if let Ok(bytes) = crate::platform::input::read_bounded(&path, SMALL_DUMP_BYTES) {
                attach(
                    format!("kinect/{}", entry.name),
                    "application/octet-stream",
                    bytes,
                )?;
            }
        }
        let frames: Vec<&str> = recording
            .poses
            .iter()
            .flat_map(|pose| pose.depth_frames.iter().map(String::as_str))
            .collect();
        let frames = serde_json::to_vec(&frames).unwrap_or_default();
        attach(FRAMES.to_string(), "application/json", frames)?;
        Ok(())
    }

    /// The ground of one pose as found and as predicted, and its θ and e_d.
    fn write_pose_fit(
        &mut self,
        index: u32,
        stamp: u64,
        intrinsics: &Intrinsics,
        inliers: Option<&[Vector3<f64>]>,
    ) -> Result<(), mcap::McapError> {
        let Some(fit) = self.result.poses.iter().find(|p| p.index == index).cloned() else {
            return Ok(());
        };
        let header = Header::new(stamp, frame::OPTICAL);
        if let Some(inliers) = inliers {
            let points: Vec<[f32; 3]> = inliers.iter().map(optical_point).collect();
            self.write(
                topic::GROUND_INLIERS,
                stamp,
                &PointCloud2::xyz(header.clone(), &points),
            )?;
        }
        for (plane, topic) in [
            (&fit.plane, topic::GROUND_MEASURED),
            (&fit.predicted_plane, topic::GROUND_PREDICTED),
        ] {
            if let Some(plane) = plane.as_ref().and_then(plane_of) {
                let points = plane_points(&plane, intrinsics);
                self.write(topic, stamp, &PointCloud2::xyz(header.clone(), &points))?;
            }
        }
        let message = PoseFit {
            header,
            pose_index: index,
            used: fit.used,
            theta_deg: fit.theta_deg.unwrap_or(f64::NAN),
            e_d_mm: fit.e_d_mm.unwrap_or(f64::NAN),
            inliers: fit
                .inliers
                .map_or(0, |n| u32::try_from(n).unwrap_or(u32::MAX)),
            reason: fit.reason.or(fit.note).unwrap_or_default(),
        };
        self.write(topic::POSE_FIT, stamp, &message)
    }

    /// The result and the session as attachments, then the summary.
    fn finish(mut self) -> Result<(BTreeMap<String, u64>, u64), mcap::McapError> {
        let stamp = self.last_stamp;
        let result = serde_json::to_vec_pretty(&self.result).unwrap_or_default();
        self.mcap.attach(&mcap::Attachment {
            log_time: stamp,
            create_time: stamp,
            name: "result.json".into(),
            media_type: "application/json".into(),
            data: result.into(),
        })?;
        let mut metadata = BTreeMap::new();
        metadata.insert(
            "status".to_string(),
            self.result.status.as_str().to_string(),
        );
        metadata.insert(
            "groundcal".to_string(),
            env!("CARGO_PKG_VERSION").to_string(),
        );
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: "groundcal".into(),
            metadata,
        })?;
        self.mcap.finish()?;
        let counts = self
            .channels
            .values()
            .map(|c| (c.topic.to_string(), u64::from(c.sequence)))
            .collect();
        let mut sink = self.mcap.into_inner();
        sink.flush()?;
        let bytes = sink.stream_position()?;
        Ok((counts, bytes))
    }
}

fn seconds_to_nanos(seconds: f64) -> u64 {
    (seconds * 1e9).round().clamp(0.0, u64::MAX as f64) as u64
}

/// Millimetres per raw value (0 for no reading and for values the model
/// gives no depth of 1 mm to 65.535 m).
fn millimetre_table(model: &DepthModel) -> Vec<u16> {
    (0..2048u16)
        .map(|raw| {
            model
                .depth_m(raw)
                .map(|z| (z * 1e3).round())
                .filter(|mm| (1.0..=65535.0).contains(mm))
                .map_or(0, |mm| mm as u16)
        })
        .collect()
}

fn transform_stamped(
    stamp: u64,
    parent: &str,
    child: &str,
    rotation: &Matrix3<f64>,
    translation: &Vector3<f64>,
) -> TransformStamped {
    TransformStamped {
        header: Header::new(stamp, parent),
        child_frame_id: child.to_string(),
        transform: msg::Transform {
            translation: [translation.x, translation.y, translation.z],
            rotation: quaternion_xyzw(rotation),
        },
    }
}

/// The body in the ground, and the feet in the body, at one pose.
fn body_and_feet(
    stamp: u64,
    ground_from_robot: &Transform,
    feet_body_mm: &[[f64; 3]],
) -> TfMessage {
    let (rotation, translation) = ground_from_base_link(ground_from_robot);
    let mut transforms = vec![transform_stamped(
        stamp,
        frame::GROUND,
        frame::BODY,
        &rotation,
        &translation,
    )];
    let c = base_link_from_robot();
    for (k, foot) in feet_body_mm.iter().enumerate() {
        let position = c * Vector3::new(foot[0], foot[1], foot[2]) / 1e3;
        transforms.push(transform_stamped(
            stamp,
            frame::BODY,
            &frame::foot(k + 1),
            &Matrix3::identity(),
            &position,
        ));
    }
    TfMessage { transforms }
}

fn camera_info(header: Header, intrinsics: &Intrinsics) -> CameraInfo {
    CameraInfo::pinhole(
        header,
        intrinsics.width as u32,
        intrinsics.height as u32,
        intrinsics.fx,
        intrinsics.fy,
        intrinsics.cx,
        intrinsics.cy,
    )
}

fn plane_of(json: &PlaneJson) -> Option<Plane> {
    Plane::from_coefficients(json.a, json.b, json.c, json.d_m).ok()
}

/// A point of the sensor frame in the optical frame.
fn optical_point(point: &Vector3<f64>) -> [f32; 3] {
    let p = sensor_from_optical().transpose() * point;
    [p.x as f32, p.y as f32, p.z as f32]
}

/// Where the rays of a 32 × 24 grid of pixels meet a plane of the sensor
/// frame, up to 8 m away: the plane as the camera sees it.
fn plane_points(plane: &Plane, intrinsics: &Intrinsics) -> Vec<[f32; 3]> {
    let mut points = Vec::new();
    let optical_from_sensor = sensor_from_optical().transpose();
    let normal = optical_from_sensor * plane.normal;
    for row in 0..24 {
        for column in 0..32 {
            let u = (column as f64 + 0.5) * intrinsics.width as f64 / 32.0;
            let v = (row as f64 + 0.5) * intrinsics.height as f64 / 24.0;
            let ray = Vector3::new(
                (u - intrinsics.cx) / intrinsics.fx,
                (v - intrinsics.cy) / intrinsics.fy,
                1.0,
            );
            // n·(z·ray) + d = 0.
            let along = normal.dot(&ray);
            if along.abs() < 1e-9 {
                continue;
            }
            let z = -plane.d / along;
            if z > 0.0 && z <= 8.0 {
                let p = ray * z;
                points.push([p.x as f32, p.y as f32, p.z as f32]);
            }
        }
    }
    points
}

#[cfg(test)]
mod tests {

    /// A full disk is said in the system's words, not the library's.
    #[test]
    fn a_write_error_says_what_the_system_said() {
        let e = McapError::Mcap {
            path: "/tmp/x.mcap".into(),
            source: mcap::McapError::Io(std::io::Error::from_raw_os_error(28)),
        };
        let said = e.to_string();
        assert!(
            said.starts_with("/tmp/x.mcap: cannot write MCAP: No space left on device"),
            "{said}"
        );
    }

    use super::*;
    use crate::calib::geometry::PoseParams;

    #[test]
    fn the_body_in_the_ground_turns_like_the_mount() {
        // A body 0.6 m up, turned 10° about the up axis: in ROS's ground it
        // is 0.6 m up z, turned 10° about z.
        let ground_from_robot =
            PoseParams::new(10f64.to_radians(), 0.0, 0.0, Vector3::new(0.0, 0.6, 0.0))
                .to_transform();
        let (rotation, translation) = ground_from_base_link(&ground_from_robot);
        assert!((translation - Vector3::new(0.0, 0.0, 0.6)).amax() < 1e-12);
        let expected = crate::calib::geometry::rot_z(10f64.to_radians());
        assert!((rotation - expected).amax() < 1e-12, "{rotation}");
    }

    #[test]
    fn millimetres_follow_the_depth_model_and_no_reading_is_zero() {
        let table = millimetre_table(&DepthModel::default());
        // conventions.md's check values for the zero-plane model.
        assert_eq!(table[400], 498);
        assert_eq!(table[700], 885);
        assert_eq!(table[2047], 0);
    }
}
