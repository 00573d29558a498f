//! The ROS 2 messages groundcal writes and reads, with their definitions.
//!
//! The definitions are the `.msg` files' fields (comments left out) of ROS 2
//! Humble, Iron and Jazzy, which agree for these types. An MCAP `ros2msg`
//! schema is the message's own definition followed by each type it uses, in
//! a block of its own:
//!
//! ```text
//! std_msgs/Header header
//! ...
//! ================================================================================
//! MSG: std_msgs/Header
//! builtin_interfaces/Time stamp
//! string frame_id
//! ```

use crate::cdr::{CdrError, CdrReader, CdrWriter};

/// A type that is encoded in CDR: a message or a field of one.
pub trait Cdr: Sized {
    fn write(&self, w: &mut CdrWriter);
    fn read(r: &mut CdrReader) -> Result<Self, CdrError>;
}

/// A ROS 2 message type.
pub trait Message: Cdr {
    /// Its full name, `package/msg/Type`.
    const NAME: &'static str;
    /// Its fields, as in its `.msg` file.
    const FIELDS: &'static str;
    /// Every message type it uses, directly or not: `package/Type` and the
    /// fields.
    const USES: &'static [(&'static str, &'static str)];

    /// The `ros2msg` schema an MCAP channel of this type carries.
    fn schema() -> String {
        let mut text = String::from(Self::FIELDS);
        for (name, fields) in Self::USES {
            text.push_str(&"=".repeat(80));
            text.push_str("\nMSG: ");
            text.push_str(name);
            text.push('\n');
            text.push_str(fields);
        }
        text
    }

    /// The message in CDR, header included.
    fn encode(&self) -> Vec<u8> {
        let mut buffer = Vec::new();
        self.encode_into(&mut buffer);
        buffer
    }

    /// [`Message::encode`] into `buffer`, emptied first (its memory reused).
    fn encode_into(&self, buffer: &mut Vec<u8>) {
        let mut w = CdrWriter::reusing(std::mem::take(buffer));
        self.write(&mut w);
        *buffer = w.finish();
    }

    /// A message from CDR; bytes left over are an error (a message of some
    /// other type).
    fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        let message = Self::read(&mut r)?;
        // Up to 3 bytes of padding may close a message.
        if r.remaining() > 3 {
            return Err(CdrError {
                offset: bytes.len() - r.remaining(),
                what: format!(
                    "{} bytes left after a whole {}: not a message of this type",
                    r.remaining(),
                    Self::NAME
                ),
            });
        }
        Ok(message)
    }
}

const TIME: (&str, &str) = ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n");
const HEADER: (&str, &str) = (
    "std_msgs/Header",
    "builtin_interfaces/Time stamp\nstring frame_id\n",
);
const VECTOR3: (&str, &str) = ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n");
const QUATERNION: (&str, &str) = (
    "geometry_msgs/Quaternion",
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
);
const TRANSFORM: (&str, &str) = (
    "geometry_msgs/Transform",
    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
);
const TRANSFORM_STAMPED: (&str, &str) = (
    "geometry_msgs/TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
);
const REGION_OF_INTEREST: (&str, &str) = (
    "sensor_msgs/RegionOfInterest",
    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
);
const POINT_FIELD: (&str, &str) = (
    "sensor_msgs/PointField",
    "uint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\nuint8 UINT16 = 4\nuint8 INT32 = 5\n\
     uint8 UINT32 = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n\
     string name\nuint32 offset\nuint8 datatype\nuint32 count\n",
);

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch (an MCAP log time).
    pub fn from_nanos(nanos: u64) -> Self {
        Self {
            sec: i32::try_from(nanos / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (nanos % 1_000_000_000) as u32,
        }
    }

    /// Nanoseconds since the epoch; `None` before it.
    pub fn nanos(&self) -> Option<u64> {
        u64::try_from(self.sec)
            .ok()
            .map(|s| s * 1_000_000_000 + u64::from(self.nanosec))
    }
}

impl Cdr for Time {
    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            sec: r.i32("stamp.sec")?,
            nanosec: r.u32("stamp.nanosec")?,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    pub fn new(stamp_nanos: u64, frame_id: &str) -> Self {
        Self {
            stamp: Time::from_nanos(stamp_nanos),
            frame_id: frame_id.to_owned(),
        }
    }
}

impl Cdr for Header {
    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            stamp: Time::read(r)?,
            frame_id: r.string("header.frame_id")?,
        })
    }
}

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    /// `16UC1` (depth in millimetres, REP 118), `32FC1` (metres), `mono16`….
    pub encoding: String,
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    pub data: Vec<u8>,
}

impl Image {
    /// A 16-bit single-channel image, little-endian, row by row.
    pub fn u16(header: Header, width: u32, height: u32, encoding: &str, pixels: &[u16]) -> Self {
        let mut data = Vec::with_capacity(2 * pixels.len());
        for pixel in pixels {
            data.extend_from_slice(&pixel.to_le_bytes());
        }
        Self {
            header,
            height,
            width,
            encoding: encoding.to_owned(),
            is_bigendian: false,
            step: 2 * width,
            data,
        }
    }
}

/// A 16-bit single-channel image (`mono16`, `16UC1`) encoded straight from
/// its pixels into `buffer` (emptied first): the bytes of
/// `Image::u16(…).encode()` without the image's own copy of the pixels.
/// `pixels` gives them row by row, `width × height` of them.
pub fn encode_u16_image(
    header: &Header,
    width: u32,
    height: u32,
    encoding: &str,
    pixels: impl ExactSizeIterator<Item = u16>,
    buffer: &mut Vec<u8>,
) {
    let mut w = CdrWriter::reusing(std::mem::take(buffer));
    header.write(&mut w);
    w.u32(height);
    w.u32(width);
    w.string(encoding);
    w.bool(false);
    w.u32(2 * width);
    w.u16_le_byte_sequence(pixels);
    *buffer = w.finish();
}

impl Cdr for Image {
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.encoding);
        w.bool(self.is_bigendian);
        w.u32(self.step);
        w.byte_sequence(&self.data);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            encoding: r.string("encoding")?,
            // uint8 in the definition; any non-zero is big-endian.
            is_bigendian: r.u8("is_bigendian")? != 0,
            step: r.u32("step")?,
            data: r.byte_sequence("data")?.to_vec(),
        })
    }
}

impl Message for Image {
    const NAME: &'static str = "sensor_msgs/msg/Image";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 height\nuint32 width\n\
        string encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n";
    const USES: &'static [(&'static str, &'static str)] = &[HEADER, TIME];
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

impl Cdr for RegionOfInterest {
    fn write(&self, w: &mut CdrWriter) {
        w.u32(self.x_offset);
        w.u32(self.y_offset);
        w.u32(self.height);
        w.u32(self.width);
        w.bool(self.do_rectify);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            x_offset: r.u32("roi.x_offset")?,
            y_offset: r.u32("roi.y_offset")?,
            height: r.u32("roi.height")?,
            width: r.u32("roi.width")?,
            do_rectify: r.bool("roi.do_rectify")?,
        })
    }
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    /// The intrinsic matrix, row-major.
    pub k: [f64; 9],
    pub r: [f64; 9],
    /// The projection matrix, row-major.
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

impl CameraInfo {
    /// A pinhole camera without lens distortion (a Kinect's depth frames as
    /// libfreenect gives them).
    pub fn pinhole(
        header: Header,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
    ) -> Self {
        Self {
            header,
            height,
            width,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        }
    }
}

impl Cdr for CameraInfo {
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.distortion_model);
        w.f64_sequence(&self.d);
        w.f64_array(&self.k);
        w.f64_array(&self.r);
        w.f64_array(&self.p);
        w.u32(self.binning_x);
        w.u32(self.binning_y);
        self.roi.write(w);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            distortion_model: r.string("distortion_model")?,
            d: r.f64_sequence("d")?,
            k: r.f64_array("k")?,
            r: r.f64_array("r")?,
            p: r.f64_array("p")?,
            binning_x: r.u32("binning_x")?,
            binning_y: r.u32("binning_y")?,
            roi: RegionOfInterest::read(r)?,
        })
    }
}

impl Message for CameraInfo {
    const NAME: &'static str = "sensor_msgs/msg/CameraInfo";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 height\nuint32 width\n\
        string distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\n\
        uint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n";
    const USES: &'static [(&'static str, &'static str)] = &[HEADER, TIME, REGION_OF_INTEREST];
}

/// `geometry_msgs/msg/Transform`: a translation (metres) and a unit
/// quaternion `(x, y, z, w)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Transform {
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

impl Cdr for Transform {
    fn write(&self, w: &mut CdrWriter) {
        w.f64_array(&self.translation);
        w.f64_array(&self.rotation);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            translation: r.f64_array("transform.translation")?,
            rotation: r.f64_array("transform.rotation")?,
        })
    }
}

/// `geometry_msgs/msg/TransformStamped`: `child_frame_id`'s pose in
/// `header.frame_id` (parent_from_child).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

impl Cdr for TransformStamped {
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        self.transform.write(w);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.string("child_frame_id")?,
            transform: Transform::read(r)?,
        })
    }
}

/// `tf2_msgs/msg/TFMessage`, what `/tf` and `/tf_static` carry.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

impl Cdr for TfMessage {
    fn write(&self, w: &mut CdrWriter) {
        w.length(self.transforms.len());
        for transform in &self.transforms {
            transform.write(w);
        }
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        // A transform takes at least 64 bytes.
        let count = r.length("transforms", 64)?;
        let transforms = (0..count)
            .map(|_| TransformStamped::read(r))
            .collect::<Result<_, _>>()?;
        Ok(Self { transforms })
    }
}

impl Message for TfMessage {
    const NAME: &'static str = "tf2_msgs/msg/TFMessage";
    const FIELDS: &'static str = "geometry_msgs/TransformStamped[] transforms\n";
    const USES: &'static [(&'static str, &'static str)] = &[
        TRANSFORM_STAMPED,
        HEADER,
        TIME,
        TRANSFORM,
        VECTOR3,
        QUATERNION,
    ];
}

/// `sensor_msgs/msg/PointField`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

impl PointField {
    pub const FLOAT32: u8 = 7;
}

impl Cdr for PointField {
    fn write(&self, w: &mut CdrWriter) {
        w.string(&self.name);
        w.u32(self.offset);
        w.u8(self.datatype);
        w.u32(self.count);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            name: r.string("fields.name")?,
            offset: r.u32("fields.offset")?,
            datatype: r.u8("fields.datatype")?,
            count: r.u32("fields.count")?,
        })
    }
}

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Vec<u8>,
    pub is_dense: bool,
}

impl PointCloud2 {
    /// An unordered cloud of points `x, y, z` (metres, float32).
    pub fn xyz(header: Header, points: &[[f32; 3]]) -> Self {
        let fields = ["x", "y", "z"]
            .iter()
            .enumerate()
            .map(|(k, name)| PointField {
                name: (*name).into(),
                offset: 4 * k as u32,
                datatype: PointField::FLOAT32,
                count: 1,
            })
            .collect();
        let mut data = Vec::with_capacity(12 * points.len());
        for point in points {
            for value in point {
                data.extend_from_slice(&value.to_le_bytes());
            }
        }
        Self {
            header,
            height: 1,
            width: points.len() as u32,
            fields,
            is_bigendian: false,
            point_step: 12,
            row_step: 12 * points.len() as u32,
            data,
            is_dense: true,
        }
    }
}

impl Cdr for PointCloud2 {
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.height);
        w.u32(self.width);
        w.length(self.fields.len());
        for field in &self.fields {
            field.write(w);
        }
        w.bool(self.is_bigendian);
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.byte_sequence(&self.data);
        w.bool(self.is_dense);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        let header = Header::read(r)?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        // A field takes at least 13 bytes.
        let count = r.length("fields", 13)?;
        let fields = (0..count)
            .map(|_| PointField::read(r))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            header,
            height,
            width,
            fields,
            is_bigendian: r.bool("is_bigendian")?,
            point_step: r.u32("point_step")?,
            row_step: r.u32("row_step")?,
            data: r.byte_sequence("data")?.to_vec(),
            is_dense: r.bool("is_dense")?,
        })
    }
}

impl Message for PointCloud2 {
    const NAME: &'static str = "sensor_msgs/msg/PointCloud2";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 height\nuint32 width\n\
        sensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\n\
        uint8[] data\nbool is_dense\n";
    const USES: &'static [(&'static str, &'static str)] = &[HEADER, TIME, POINT_FIELD];
}

/// `groundcal_msgs/msg/PoseFit`: one pose of a calibration as the solve saw
/// it, to plot θ and e_d and to read why a pose was set aside.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseFit {
    pub header: Header,
    /// The pose's index in the schedule, from 1.
    pub pose_index: u32,
    /// Whether the solve used it.
    pub used: bool,
    /// The angle between the measured and the predicted ground, degrees
    /// (NaN without a plane).
    pub theta_deg: f64,
    /// The measured height less the predicted one, millimetres (NaN without
    /// a plane).
    pub e_d_mm: f64,
    /// Readings on the ground.
    pub inliers: u32,
    /// Why it was not used, or a remark; empty otherwise.
    pub reason: String,
}

impl Cdr for PoseFit {
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.pose_index);
        w.bool(self.used);
        w.f64(self.theta_deg);
        w.f64(self.e_d_mm);
        w.u32(self.inliers);
        w.string(&self.reason);
    }
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            pose_index: r.u32("pose_index")?,
            used: r.bool("used")?,
            theta_deg: r.f64("theta_deg")?,
            e_d_mm: r.f64("e_d_mm")?,
            inliers: r.u32("inliers")?,
            reason: r.string("reason")?,
        })
    }
}

impl Message for PoseFit {
    const NAME: &'static str = "groundcal_msgs/msg/PoseFit";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 pose_index\nbool used\n\
        float64 theta_deg\nfloat64 e_d_mm\nuint32 inliers\nstring reason\n";
    const USES: &'static [(&'static str, &'static str)] = &[HEADER, TIME];
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip<M: Message + PartialEq + std::fmt::Debug>(message: &M) {
        let bytes = message.encode();
        assert_eq!(&M::decode(&bytes).unwrap(), message);
        // Every cut of the message is an error, never a panic or a message.
        for cut in 0..bytes.len().saturating_sub(3) {
            assert!(
                M::decode(&bytes[..cut]).is_err(),
                "{} cut at {cut}",
                M::NAME
            );
        }
    }

    #[test]
    fn every_message_decodes_to_itself_and_a_cut_one_is_an_error() {
        let header = Header::new(1_700_000_000_123_456_789, "camera_depth_optical_frame");
        round_trip(&Image::u16(
            header.clone(),
            3,
            2,
            "16UC1",
            &[1, 2, 3, 500, 0, 65535],
        ));
        round_trip(&CameraInfo::pinhole(
            header.clone(),
            640,
            480,
            570.34,
            570.34,
            320.0,
            240.0,
        ));
        round_trip(&TfMessage {
            transforms: vec![
                TransformStamped {
                    header: header.clone(),
                    child_frame_id: "base_link".into(),
                    transform: Transform {
                        translation: [0.1, -0.2, 0.6],
                        rotation: [0.0, 0.0, 0.3826834, 0.9238795],
                    },
                };
                2
            ],
        });
        round_trip(&PointCloud2::xyz(
            header.clone(),
            &[[1.0, 2.0, 3.0], [-1.5, 0.0, 2.5]],
        ));
        round_trip(&PoseFit {
            header,
            pose_index: 31,
            used: false,
            theta_deg: 0.0123,
            e_d_mm: -0.4,
            inliers: 120_345,
            reason: "θ 4.1σ: an outlier".into(),
        });
    }

    #[test]
    fn an_image_encoded_from_its_pixels_is_the_images_own_bytes() {
        let header = Header::new(12_345_678_901, "camera_depth_optical_frame");
        let pixels = [1u16, 2, 3, 500, 0, 65535, 7, 2047, 8, 9];
        let whole = Image::u16(header.clone(), 5, 2, "16UC1", &pixels).encode();
        // A used, larger buffer: emptied, then reused.
        let mut buffer = vec![0xAA; 4096];
        encode_u16_image(&header, 5, 2, "16UC1", pixels.iter().copied(), &mut buffer);
        assert_eq!(buffer, whole);
        let mut again = Vec::new();
        Image::u16(header, 5, 2, "16UC1", &pixels).encode_into(&mut again);
        assert_eq!(again, whole);
    }

    #[test]
    fn a_schema_lists_what_its_type_uses() {
        let schema = Image::schema();
        assert!(schema.starts_with("std_msgs/Header header\n"));
        let blocks: Vec<&str> = schema.split(&"=".repeat(80)).collect();
        assert_eq!(blocks.len(), 3);
        assert!(blocks[1].starts_with("\nMSG: std_msgs/Header\n"));
        assert!(blocks[2].starts_with("\nMSG: builtin_interfaces/Time\n"));
        // Every type named in a field is defined in the schema.
        for message in [
            Image::schema(),
            CameraInfo::schema(),
            TfMessage::schema(),
            PointCloud2::schema(),
            PoseFit::schema(),
        ] {
            for line in message
                .lines()
                .filter(|l| !l.starts_with("MSG:") && !l.starts_with('='))
            {
                let kind = line
                    .split_whitespace()
                    .next()
                    .unwrap_or("")
                    .trim_end_matches("[]");
                if let Some((package, name)) = kind.split_once('/') {
                    let name = name.split('[').next().unwrap();
                    assert!(
                        message.contains(&format!("MSG: {package}/{name}\n")),
                        "{kind} in {message}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_message_of_another_type_is_refused() {
        let bytes = Image::u16(Header::default(), 2, 2, "16UC1", &[1; 4]).encode();
        assert!(PoseFit::decode(&bytes).is_err());
        let e = Header::read(&mut CdrReader::new(&bytes).unwrap()).map(|_| ());
        assert!(e.is_ok());
    }
}
