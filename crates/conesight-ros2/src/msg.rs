//! The ROS 2 messages conesight reads and writes, as serde types in the field order of their
//! `.msg` definitions (CDR has no field names: the order is the format), and each one's
//! `ros2msg` definition text for MCAP schemas.
//!
//! Standard messages (`std_msgs`, `builtin_interfaces`, `geometry_msgs`, `sensor_msgs`) follow
//! ROS 2 Jazzy's definitions; ours are read from `ros2/conesight_msgs/msg/*.msg` at compile
//! time, so the package a team builds with colcon and the bytes written here cannot drift
//! (the Python tests decode our CDR with types that rosbags builds from those same files).

use dust_dds::infrastructure::type_support::DdsType;
use serde::{Deserialize, Serialize};

/// A ROS 2 message type: its name and its definition with its dependencies.
pub trait RosMessage: Serialize + for<'de> Deserialize<'de> {
    /// `package/msg/Type`.
    const TYPE: &'static str;
    /// Its fields as in its `.msg` file (comments and blank lines kept out).
    const FIELDS: &'static str;
    /// The types its fields use, depth first (each once, in the order a `ros2msg` schema
    /// lists them).
    fn dependencies() -> Vec<(&'static str, &'static str)>;
}

/// The `ros2msg` schema text of `M`: its fields, then each dependency after a line of 80 `=`
/// and `MSG: package/Type` (the rosbag2 MCAP profile's schema encoding).
pub fn definition<M: RosMessage>() -> String {
    let mut text = normalised_fields(M::TYPE, M::FIELDS);
    for (name, fields) in M::dependencies() {
        text.push_str(&"=".repeat(80));
        text.push('\n');
        text.push_str(&format!("MSG: {}\n", name.replace("/msg/", "/")));
        text.push_str(&normalised_fields(name, fields));
    }
    text
}

/// The field and constant lines of a `.msg` text, comments and blank lines dropped, with
/// types of the same package named in full (`Keypoint[]` in `conesight_msgs/msg/Cone` is
/// `conesight_msgs/Keypoint[]`).
pub(crate) fn normalised_fields(type_name: &str, fields: &str) -> String {
    const PRIMITIVES: [&str; 16] = [
        "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
        "uint32", "int64", "uint64", "string", "wstring", "time",
    ];
    let package = type_name.split('/').next().unwrap_or_default();
    let mut out = String::new();
    for line in fields.lines() {
        let line = line.split('#').next().unwrap_or_default().trim();
        if line.is_empty() {
            continue;
        }
        let (field_type, rest) = line.split_once(' ').unwrap_or((line, ""));
        let base = field_type
            .split(['[', '<'])
            .next()
            .unwrap_or(field_type)
            .to_owned();
        let field_type = if !base.contains('/') && !PRIMITIVES.contains(&base.as_str()) {
            format!("{package}/{field_type}")
        } else {
            field_type.to_owned()
        };
        out.push_str(&format!("{field_type} {}\n", rest.trim()));
    }
    out
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct Time {
    /// Seconds since the Unix epoch.
    pub sec: i32,
    /// Nanoseconds past `sec`.
    pub nanosec: u32,
}

const TIME_FIELDS: &str = "int32 sec\nuint32 nanosec\n";

impl Time {
    /// `ns` since the Unix epoch (seconds past 2^31 saturate).
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    /// Nanoseconds since the Unix epoch (`None` before it).
    pub fn to_ns(self) -> Option<u64> {
        let sec = u64::try_from(self.sec).ok()?;
        (self.nanosec < 1_000_000_000).then(|| sec * 1_000_000_000 + u64::from(self.nanosec))
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// The frame the data is in.
    pub frame_id: String,
}

const HEADER_FIELDS: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";

fn header_dependencies() -> Vec<(&'static str, &'static str)> {
    vec![
        ("std_msgs/msg/Header", HEADER_FIELDS),
        ("builtin_interfaces/msg/Time", TIME_FIELDS),
    ]
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Point {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Metres.
    pub z: f64,
}

const POINT_FIELDS: &str = "float64 x\nfloat64 y\nfloat64 z\n";

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct Image {
    /// Acquisition time and the camera's optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `rgb8`, `bgr8`, `mono8`, `bayer_rggb8`, ...
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row (at least `width` times the pixel size).
    pub step: u32,
    /// `step * height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

impl RosMessage for Image {
    const TYPE: &'static str = "sensor_msgs/msg/Image";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n";
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        header_dependencies()
    }
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct CompressedImage {
    /// Acquisition time and the camera's optical frame.
    pub header: Header,
    /// `jpeg`, `png` (image_transport writes e.g. `rgb8; jpeg compressed bgr8`).
    pub format: String,
    /// The compressed file's bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

impl RosMessage for CompressedImage {
    const TYPE: &'static str = "sensor_msgs/msg/CompressedImage";
    const FIELDS: &'static str = "std_msgs/Header header\nstring format\nuint8[] data\n";
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        header_dependencies()
    }
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct RegionOfInterest {
    /// Left column.
    pub x_offset: u32,
    /// Top row.
    pub y_offset: u32,
    /// Rows (0: the whole image).
    pub height: u32,
    /// Columns (0: the whole image).
    pub width: u32,
    /// Whether the region is of the rectified image.
    pub do_rectify: bool,
}

const ROI_FIELDS: &str =
    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n";

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Acquisition time and the camera's optical frame.
    pub header: Header,
    /// Rows of the calibrated image.
    pub height: u32,
    /// Columns of the calibrated image.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`.
    pub distortion_model: String,
    /// Distortion coefficients, in the model's order.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major 3x3.
    pub k: [f64; 9],
    /// Rectification rotation, row-major 3x3.
    pub r: [f64; 9],
    /// Projection of the rectified image, row-major 3x4.
    pub p: [f64; 12],
    /// Horizontal binning (0 and 1: none).
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// The region of the image this calibration applies to.
    pub roi: RegionOfInterest,
}

impl RosMessage for CameraInfo {
    const TYPE: &'static str = "sensor_msgs/msg/CameraInfo";
    const FIELDS: &'static str = "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n";
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        let mut deps = header_dependencies();
        deps.push(("sensor_msgs/msg/RegionOfInterest", ROI_FIELDS));
        deps
    }
}

/// `conesight_msgs/msg/Keypoint` (`ros2/conesight_msgs/msg/Keypoint.msg`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Keypoint {
    /// Column, pixels, raw image.
    pub u_px: f64,
    /// Row, pixels, raw image.
    pub v_px: f64,
    /// The network's confidence, 0..1.
    pub confidence: f32,
}

const KEYPOINT_MSG: &str = include_str!("../../../ros2/conesight_msgs/msg/Keypoint.msg");
const CONE_MSG: &str = include_str!("../../../ros2/conesight_msgs/msg/Cone.msg");
const CONE_ARRAY_MSG: &str = include_str!("../../../ros2/conesight_msgs/msg/ConeArray.msg");

impl RosMessage for Keypoint {
    const TYPE: &'static str = "conesight_msgs/msg/Keypoint";
    const FIELDS: &'static str = KEYPOINT_MSG;
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        Vec::new()
    }
}

/// `Cone.cone_class` values (`CLASS_*` in Cone.msg).
pub mod cone_class {
    /// Small blue cone.
    pub const BLUE: u8 = 1;
    /// Small yellow cone.
    pub const YELLOW: u8 = 2;
    /// Small orange cone.
    pub const ORANGE: u8 = 3;
    /// Large orange cone.
    pub const LARGE_ORANGE: u8 = 4;
}

/// `Cone.ranging` values (`RANGING_*` in Cone.msg).
pub mod ranging {
    /// Keypoints and PnP alone.
    pub const KEYPOINTS: u8 = 1;
    /// Keypoints and PnP with the box height.
    pub const KEYPOINTS_AND_BOX: u8 = 2;
    /// The box alone.
    pub const BOX: u8 = 3;
    /// Keypoints and PnP alone; the box disagreed beyond the gate.
    pub const KEYPOINTS_BOX_REFUSED: u8 = 4;
}

/// `conesight_msgs/msg/Cone` (`ros2/conesight_msgs/msg/Cone.msg`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Cone {
    /// One of [`cone_class`].
    pub cone_class: u8,
    /// The detector's confidence.
    pub score: f32,
    /// Base centre in the vehicle frame, metres.
    pub position: Point,
    /// Covariance of `position`, row-major 3x3, m^2.
    pub covariance: [f64; 9],
    /// Base centre in the camera's optical frame, metres.
    pub position_in_camera: Point,
    /// Distance from the camera, metres.
    pub range_m: f64,
    /// One of [`ranging`].
    pub ranging: u8,
    /// Keypoint reprojection error after the fit, pixels.
    pub reprojection_rms_px: f64,
    /// Cone axis tilt from the camera's vertical, radians.
    pub tilt_rad: f64,
    /// The 7 keypoints, or none.
    pub keypoints: Vec<Keypoint>,
    /// Box, pixels.
    pub box_x_min_px: f32,
    /// Box, pixels.
    pub box_y_min_px: f32,
    /// Box, pixels.
    pub box_x_max_px: f32,
    /// Box, pixels.
    pub box_y_max_px: f32,
}

impl RosMessage for Cone {
    const TYPE: &'static str = "conesight_msgs/msg/Cone";
    const FIELDS: &'static str = CONE_MSG;
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        vec![
            ("geometry_msgs/msg/Point", POINT_FIELDS),
            ("conesight_msgs/msg/Keypoint", KEYPOINT_MSG),
        ]
    }
}

/// `conesight_msgs/msg/ConeArray` (`ros2/conesight_msgs/msg/ConeArray.msg`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ConeArray {
    /// The frame's acquisition time; the vehicle frame.
    pub header: Header,
    /// The camera's optical frame.
    pub camera_frame_id: String,
    /// The camera's frame counter.
    pub frame_sequence: u64,
    /// The cones.
    pub cones: Vec<Cone>,
}

impl RosMessage for ConeArray {
    const TYPE: &'static str = "conesight_msgs/msg/ConeArray";
    const FIELDS: &'static str = CONE_ARRAY_MSG;
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        let mut deps = header_dependencies();
        deps.push(("conesight_msgs/msg/Cone", CONE_MSG));
        deps.push(("geometry_msgs/msg/Point", POINT_FIELDS));
        deps.push(("conesight_msgs/msg/Keypoint", KEYPOINT_MSG));
        deps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn definitions_name_every_type_in_full_and_drop_comments() {
        let text = definition::<ConeArray>();
        assert!(text.starts_with("std_msgs/Header header\nstring camera_frame_id\n"));
        assert!(text.contains("conesight_msgs/Cone[] cones\n"), "{text}");
        assert!(text.contains("MSG: conesight_msgs/Cone\nuint8 CLASS_BLUE=1\n"));
        assert!(text.contains("conesight_msgs/Keypoint[] keypoints\n"));
        assert!(text.contains("MSG: builtin_interfaces/Time\nint32 sec\n"));
        assert!(!text.contains('#'));
        assert_eq!(
            definition::<Image>().matches("MSG: ").count(),
            2,
            "Header and Time"
        );
    }

    #[test]
    fn time_round_trips_nanoseconds() {
        let ns = 1_700_000_000_123_456_789;
        assert_eq!(Time::from_ns(ns).to_ns(), Some(ns));
        assert_eq!(
            Time {
                sec: -1,
                nanosec: 0
            }
            .to_ns(),
            None
        );
    }
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Quaternion {
    /// Vector part x.
    pub x: f64,
    /// Vector part y.
    pub y: f64,
    /// Vector part z.
    pub z: f64,
    /// Scalar part.
    pub w: f64,
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Pose {
    /// Position, metres.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `std_msgs/msg/ColorRGBA`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct ColorRgba {
    /// Red, 0..1.
    pub r: f32,
    /// Green, 0..1.
    pub g: f32,
    /// Blue, 0..1.
    pub b: f32,
    /// Opacity, 0..1.
    pub a: f32,
}

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds past `sec`.
    pub nanosec: u32,
}

/// `visualization_msgs/msg/UVCoordinate`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct UvCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}

/// `visualization_msgs/msg/MeshFile`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize, DdsType)]
pub struct MeshFile {
    /// The mesh's file name.
    pub filename: String,
    /// Its bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `visualization_msgs/msg/Marker` (the same fields in Humble and Jazzy).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct Marker {
    /// Stamp and frame.
    pub header: Header,
    /// Namespace of the id.
    pub ns: String,
    /// Id within `ns`.
    pub id: i32,
    /// `marker_type::*`.
    pub r#type: i32,
    /// 0 add/modify, 2 delete, 3 delete all.
    pub action: i32,
    /// Pose of the shape.
    pub pose: Pose,
    /// Size, metres.
    pub scale: Vector3,
    /// Colour.
    pub color: ColorRgba,
    /// How long it stays without an update (0: for ever).
    pub lifetime: Duration,
    /// Follows its frame.
    pub frame_locked: bool,
    /// For lists of points.
    pub points: Vec<Point>,
    /// For lists of points.
    pub colors: Vec<ColorRgba>,
    /// Texture.
    pub texture_resource: String,
    /// Texture.
    pub texture: CompressedImage,
    /// Texture.
    pub uv_coordinates: Vec<UvCoordinate>,
    /// Text of a text marker.
    pub text: String,
    /// Mesh.
    pub mesh_resource: String,
    /// Mesh.
    pub mesh_file: MeshFile,
    /// Mesh.
    pub mesh_use_embedded_materials: bool,
}

/// `Marker.type` and `Marker.action` values.
pub mod marker_type {
    /// A cylinder.
    pub const CYLINDER: i32 = 3;
    /// Text facing the viewer.
    pub const TEXT_VIEW_FACING: i32 = 9;
    /// Add or modify.
    pub const ADD: i32 = 0;
    /// Delete every marker of the namespace.
    pub const DELETEALL: i32 = 3;
}

const MARKER_FIELDS: &str = "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\nint32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\nint32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\nint32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\nstd_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\nvisualization_msgs/UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\nvisualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials\n";

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, DdsType)]
pub struct MarkerArray {
    /// The markers.
    pub markers: Vec<Marker>,
}

impl RosMessage for MarkerArray {
    const TYPE: &'static str = "visualization_msgs/msg/MarkerArray";
    const FIELDS: &'static str = "visualization_msgs/Marker[] markers\n";
    fn dependencies() -> Vec<(&'static str, &'static str)> {
        vec![
            ("visualization_msgs/msg/Marker", MARKER_FIELDS),
            ("std_msgs/msg/Header", HEADER_FIELDS),
            ("builtin_interfaces/msg/Time", TIME_FIELDS),
            (
                "geometry_msgs/msg/Pose",
                "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
            ),
            ("geometry_msgs/msg/Point", POINT_FIELDS),
            (
                "geometry_msgs/msg/Quaternion",
                "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
            ),
            ("geometry_msgs/msg/Vector3", POINT_FIELDS),
            (
                "std_msgs/msg/ColorRGBA",
                "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
            ),
            ("builtin_interfaces/msg/Duration", TIME_FIELDS),
            ("sensor_msgs/msg/CompressedImage", CompressedImage::FIELDS),
            (
                "visualization_msgs/msg/UVCoordinate",
                "float32 u\nfloat32 v\n",
            ),
            (
                "visualization_msgs/msg/MeshFile",
                "string filename\nuint8[] data\n",
            ),
        ]
    }
}
