//! The standard ROS 2 messages a bag holds: their definitions (the `ros2msg` schemas embedded in
//! the MCAP file, each type followed by the types it uses, as rosbag2 writes them) and their CDR
//! encoding. Layouts are those of Humble's current interfaces, which Iron and Jazzy share
//! (visualization_msgs/Marker with its texture and mesh_file fields).

use cdm_math::Vec3;

use crate::cdr::Cdr;

/// A ROS 2 type: its name as a topic's type (`pkg/msg/Type`) and its schema text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MsgType {
    PoseStamped,
    TfMessage,
    MarkerArray,
    String,
}

impl MsgType {
    pub const ALL: [MsgType; 4] = [
        MsgType::PoseStamped,
        MsgType::TfMessage,
        MsgType::MarkerArray,
        MsgType::String,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MsgType::PoseStamped => "geometry_msgs/msg/PoseStamped",
            MsgType::TfMessage => "tf2_msgs/msg/TFMessage",
            MsgType::MarkerArray => "visualization_msgs/msg/MarkerArray",
            MsgType::String => "std_msgs/msg/String",
        }
    }

    /// The type's RIHS01 hash (ROS 2 Iron's type description hash; the same for Humble's
    /// current interfaces and Jazzy), as `rosbags` computes it (checked by the tests).
    pub fn hash(self) -> &'static str {
        match self {
            MsgType::PoseStamped => {
                "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
            }
            MsgType::TfMessage => {
                "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
            }
            MsgType::MarkerArray => {
                "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
            }
            MsgType::String => {
                "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
            }
        }
    }

    /// The `ros2msg` schema: the type's fields, then each type it uses after a line of 80 `=`
    /// and `MSG: pkg/Type`.
    pub fn schema(self) -> String {
        let (top, uses): (&str, &[&str]) = match self {
            MsgType::PoseStamped => (
                "std_msgs/Header header\ngeometry_msgs/Pose pose",
                &[HEADER, TIME, POSE, POINT, QUATERNION],
            ),
            MsgType::TfMessage => (
                "geometry_msgs/TransformStamped[] transforms",
                &[
                    TRANSFORM_STAMPED,
                    HEADER,
                    TIME,
                    TRANSFORM,
                    VECTOR3,
                    QUATERNION,
                ],
            ),
            MsgType::MarkerArray => (
                "visualization_msgs/Marker[] markers",
                &[
                    MARKER,
                    HEADER,
                    TIME,
                    POSE,
                    POINT,
                    QUATERNION,
                    VECTOR3,
                    COLOR,
                    DURATION,
                    COMPRESSED_IMAGE,
                    UV_COORDINATE,
                    MESH_FILE,
                ],
            ),
            MsgType::String => ("string data", &[]),
        };
        let mut text = top.to_owned();
        for u in uses {
            text.push('\n');
            text.push_str(&"=".repeat(80));
            text.push_str("\nMSG: ");
            text.push_str(u);
        }
        text
    }
}

const HEADER: &str = "std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id";
const TIME: &str = "builtin_interfaces/Time\nint32 sec\nuint32 nanosec";
const DURATION: &str = "builtin_interfaces/Duration\nint32 sec\nuint32 nanosec";
const POSE: &str =
    "geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation";
const POINT: &str = "geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z";
const VECTOR3: &str = "geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z";
const QUATERNION: &str = "geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w";
const TRANSFORM_STAMPED: &str = "geometry_msgs/TransformStamped\nstd_msgs/Header header\n\
    string child_frame_id\ngeometry_msgs/Transform transform";
const TRANSFORM: &str = "geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\n\
    geometry_msgs/Quaternion rotation";
const COLOR: &str = "std_msgs/ColorRGBA\nfloat32 r\nfloat32 g\nfloat32 b\nfloat32 a";
const COMPRESSED_IMAGE: &str =
    "sensor_msgs/CompressedImage\nstd_msgs/Header header\nstring format\nuint8[] data";
const UV_COORDINATE: &str = "visualization_msgs/UVCoordinate\nfloat32 u\nfloat32 v";
const MESH_FILE: &str = "visualization_msgs/MeshFile\nstring filename\nuint8[] data";
const MARKER: &str = "visualization_msgs/Marker\n\
int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
int32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
std_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\n\
visualization_msgs/UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\n\
visualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials";

/// builtin_interfaces/Time of a time in nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    pub sec: i32,
    pub nanosec: u32,
}

impl Stamp {
    pub fn from_ns(ns: u64) -> Self {
        Stamp {
            sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// std_msgs/ColorRGBA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rgba(pub [f32; 4]);

/// `Marker.type` and `Marker.action` values used here.
pub const CUBE: i32 = 1;
pub const SPHERE: i32 = 2;
pub const CYLINDER: i32 = 3;
pub const LINE_STRIP: i32 = 4;
pub const LINE_LIST: i32 = 5;
pub const ADD: i32 = 0;
pub const DELETE: i32 = 2;

/// The fields of a visualization_msgs/Marker this crate sets (the rest are empty or zero).
#[derive(Debug, Clone, PartialEq)]
pub struct Marker<'a> {
    pub ns: &'a str,
    pub id: i32,
    pub kind: i32,
    pub action: i32,
    pub position: Vec3,
    pub scale: Vec3,
    pub color: Rgba,
    pub points: &'a [Vec3],
}

fn header(c: &mut Cdr, stamp: Stamp, frame: &str) {
    c.i32(stamp.sec);
    c.u32(stamp.nanosec);
    c.string(frame);
}

fn vec3(c: &mut Cdr, v: &Vec3) {
    c.f64(v.x);
    c.f64(v.y);
    c.f64(v.z);
}

/// The identity rotation: telemetry holds positions, not attitudes.
fn identity(c: &mut Cdr) {
    for q in [0.0, 0.0, 0.0, 1.0] {
        c.f64(q);
    }
}

/// geometry_msgs/PoseStamped: a position in `frame`, identity orientation.
pub fn pose_stamped(stamp: Stamp, frame: &str, p: &Vec3) -> Vec<u8> {
    let mut c = Cdr::new();
    header(&mut c, stamp, frame);
    vec3(&mut c, p);
    identity(&mut c);
    c.into_bytes()
}

/// tf2_msgs/TFMessage: one translation per (child frame, position) in `parent`.
pub fn tf_message<'a>(
    stamp: Stamp,
    parent: &str,
    children: impl ExactSizeIterator<Item = (&'a str, Vec3)>,
) -> Vec<u8> {
    let mut c = Cdr::new();
    c.seq_len(children.len());
    for (child, p) in children {
        header(&mut c, stamp, parent);
        c.string(child);
        vec3(&mut c, &p);
        identity(&mut c);
    }
    c.into_bytes()
}

/// visualization_msgs/MarkerArray of markers in `frame`.
pub fn marker_array(stamp: Stamp, frame: &str, markers: &[Marker<'_>]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.seq_len(markers.len());
    for m in markers {
        header(&mut c, stamp, frame);
        c.string(m.ns);
        c.i32(m.id);
        c.i32(m.kind);
        c.i32(m.action);
        vec3(&mut c, &m.position);
        identity(&mut c);
        vec3(&mut c, &m.scale);
        for v in m.color.0 {
            c.f32(v);
        }
        c.i32(0); // lifetime: 0 = forever
        c.u32(0);
        c.bool(false); // frame_locked
        c.seq_len(m.points.len());
        for p in m.points {
            vec3(&mut c, p);
        }
        c.seq_len(0); // colors
        c.string(""); // texture_resource
        header(&mut c, Stamp { sec: 0, nanosec: 0 }, ""); // texture: CompressedImage
        c.string("");
        c.seq_len(0);
        c.seq_len(0); // uv_coordinates
        c.string(""); // text
        c.string(""); // mesh_resource
        c.string(""); // mesh_file
        c.seq_len(0);
        c.bool(false); // mesh_use_embedded_materials
    }
    c.into_bytes()
}

/// std_msgs/String.
pub fn string(text: &str) -> Vec<u8> {
    let mut c = Cdr::new();
    c.string(text);
    c.into_bytes()
}
