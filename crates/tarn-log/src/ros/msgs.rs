//! The ROS 2 messages tarn reads and writes, with their CDR decoding and encoding and
//! their `ros2msg` definitions as `ros2 bag` stores them in an MCAP schema.

use nalgebra::{Quaternion, Translation3, UnitQuaternion};

use super::cdr::{CdrReader, CdrResult, CdrWriter, Endian, Wire};
use crate::geom::Pose;

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Time {
    /// Whole seconds since the Unix epoch (ROS field `sec`).
    pub sec: i32,
    /// Nanoseconds past `sec`, `0..1_000_000_000` (ROS field `nanosec`).
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds since the epoch.
    pub fn to_nanos(self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }

    /// The time `ns` nanoseconds after the epoch (negative before it; `nanosec` is always non-negative).
    pub fn from_nanos(ns: i64) -> Self {
        Time {
            sec: ns.div_euclid(1_000_000_000) as i32,
            nanosec: ns.rem_euclid(1_000_000_000) as u32,
        }
    }

    /// Seconds since the epoch, as a float.
    pub(crate) fn to_sec(self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }

    fn read(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Time {
            sec: r.i32()?,
            nanosec: r.u32()?,
        })
    }

    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// Acquisition time (ROS field `stamp`).
    pub stamp: Time,
    /// Coordinate frame of the data (ROS field `frame_id`).
    pub frame_id: String,
}

impl Header {
    /// A header for `frame_id` stamped `stamp_ns` nanoseconds.
    pub fn new(frame_id: &str, stamp_ns: i64) -> Self {
        Header {
            stamp: Time::from_nanos(stamp_ns),
            frame_id: frame_id.into(),
        }
    }

    fn read(r: &mut CdrReader) -> CdrResult<Self> {
        if r.wire() == Wire::Ros1 {
            // ROS 1 std_msgs/Header: uint32 seq, time stamp (uint32 secs, nsecs), frame_id.
            let _seq = r.u32()?;
            let sec = r.u32()?;
            return Ok(Header {
                stamp: Time {
                    sec: i32::try_from(sec)
                        .map_err(|_| r.err(format!("stamp {sec} s is past 2038")))?,
                    nanosec: r.u32()?,
                },
                frame_id: r.string()?,
            });
        }
        Ok(Header {
            stamp: Time::read(r)?,
            frame_id: r.string()?,
        })
    }

    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
}

/// `geometry_msgs/msg/TransformStamped`: the pose of `child_frame_id` in `header.frame_id`
/// (maps child coordinates to parent coordinates).
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// ROS field `header`: stamp and parent frame.
    pub header: Header,
    /// The child frame (ROS field `child_frame_id`).
    pub child_frame_id: String,
    /// ROS field `transform`: maps child coordinates to parent coordinates, metres.
    pub child_to_parent: Pose,
}

impl TransformStamped {
    /// The pose of `child` in `parent` at `stamp_ns` nanoseconds.
    pub fn new(parent: &str, child: &str, stamp_ns: i64, child_to_parent: Pose) -> Self {
        TransformStamped {
            header: Header::new(parent, stamp_ns),
            child_frame_id: child.into(),
            child_to_parent,
        }
    }
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// ROS field `transforms`.
    pub transforms: Vec<TransformStamped>,
}

impl TfMessage {
    /// Decodes a CDR payload (encapsulation header included). Fails on a cut or malformed
    /// payload, or a transform that is not finite or whose quaternion is not unit.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        Self::decode_wire(buf, Wire::Cdr)
    }

    /// Decodes a message serialized as `wire` (CDR, or ROS 1 from a `.bag`).
    pub fn decode_wire(buf: &[u8], wire: Wire) -> CdrResult<Self> {
        let mut r = CdrReader::for_wire(buf, wire)?;
        // Each TransformStamped is at least 4+4+4+4+7*8 bytes.
        let n = r.seq_len(72, "transforms")?;
        let mut transforms = Vec::with_capacity(n);
        for _ in 0..n {
            let header = Header::read(&mut r)?;
            let child_frame_id = r.string()?;
            let at = r.position();
            let t = [r.f64()?, r.f64()?, r.f64()?];
            let [x, y, z, w] = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
            let q = Quaternion::new(w, x, y, z);
            let norm = q.norm();
            let fault = if t.iter().any(|v| !v.is_finite()) {
                Some(format!(
                    "its translation is not finite ({}, {}, {})",
                    t[0], t[1], t[2]
                ))
            } else if !norm.is_finite() {
                Some(format!(
                    "its rotation is not finite (x {x}, y {y}, z {z}, w {w})"
                ))
            } else if (norm - 1.0).abs() >= 1e-3 {
                Some(format!("its quaternion is not unit (norm {norm})"))
            } else {
                None
            };
            if let Some(fault) = fault {
                return Err(super::cdr::CdrError {
                    offset: at,
                    message: format!("transform {} → {child_frame_id}: {fault}", header.frame_id),
                });
            }
            transforms.push(TransformStamped {
                header,
                child_frame_id,
                child_to_parent: Pose::from_parts(
                    Translation3::new(t[0], t[1], t[2]),
                    // Keep the bits of an already-unit quaternion (so a decode/encode
                    // round trip is exact); normalize one that is only nearly unit.
                    if (norm - 1.0).abs() < 1e-12 {
                        UnitQuaternion::new_unchecked(q)
                    } else {
                        UnitQuaternion::from_quaternion(q)
                    },
                ),
            });
        }
        Ok(TfMessage { transforms })
    }

    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::new(endian);
        w.u32(self.transforms.len() as u32);
        for t in &self.transforms {
            t.header.write(&mut w);
            w.string(&t.child_frame_id);
            let v = t.child_to_parent.translation.vector;
            let q = t.child_to_parent.rotation.quaternion().coords; // x y z w
            for x in [v.x, v.y, v.z, q.x, q.y, q.z, q.w] {
                w.f64(x);
            }
        }
        w.finish()
    }
}

/// `sensor_msgs/msg/PointField` datatypes.
pub mod datatype {
    /// `int8`.
    pub const INT8: u8 = 1;
    /// `uint8`.
    pub const UINT8: u8 = 2;
    /// `int16`.
    pub const INT16: u8 = 3;
    /// `uint16`.
    pub const UINT16: u8 = 4;
    /// `int32`.
    pub const INT32: u8 = 5;
    /// `uint32`.
    pub const UINT32: u8 = 6;
    /// `float32`.
    pub const FLOAT32: u8 = 7;
    /// `float64`.
    pub const FLOAT64: u8 = 8;

    /// Size in bytes of one element, `None` for an unknown datatype.
    pub fn size(dt: u8) -> Option<usize> {
        match dt {
            INT8 | UINT8 => Some(1),
            INT16 | UINT16 => Some(2),
            INT32 | UINT32 | FLOAT32 => Some(4),
            FLOAT64 => Some(8),
            _ => None,
        }
    }
}

/// `sensor_msgs/msg/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// Field name, such as `x` or `intensity` (ROS field `name`).
    pub name: String,
    /// Byte offset of the field in a point (ROS field `offset`).
    pub offset: u32,
    /// Element type, one of the [`datatype`] constants (ROS field `datatype`).
    pub datatype: u8,
    /// Number of elements (ROS field `count`).
    pub count: u32,
}

/// `sensor_msgs/msg/PointCloud2`, with its raw data.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2Msg {
    /// ROS field `header`: stamp and sensor frame.
    pub header: Header,
    /// Rows of points, 1 for an unordered cloud (ROS field `height`).
    pub height: u32,
    /// Points per row (ROS field `width`).
    pub width: u32,
    /// Layout of one point (ROS field `fields`).
    pub fields: Vec<PointField>,
    /// Whether the data is big endian (ROS field `is_bigendian`).
    pub is_bigendian: bool,
    /// Bytes per point (ROS field `point_step`).
    pub point_step: u32,
    /// Bytes per row (ROS field `row_step`).
    pub row_step: u32,
    /// Raw point bytes, `row_step * height` of them (ROS field `data`).
    pub data: Vec<u8>,
    /// Whether the cloud has no invalid points (ROS field `is_dense`).
    pub is_dense: bool,
}

impl PointCloud2Msg {
    /// Decodes a CDR payload (encapsulation header included). Fails on a cut or malformed payload.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        Self::decode_wire(buf, Wire::Cdr)
    }

    /// Decodes a message serialized as `wire` (CDR, or ROS 1 from a `.bag`).
    pub fn decode_wire(buf: &[u8], wire: Wire) -> CdrResult<Self> {
        let mut r = CdrReader::for_wire(buf, wire)?;
        let header = Header::read(&mut r)?;
        let height = r.u32()?;
        let width = r.u32()?;
        let n = r.seq_len(13, "fields")?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            fields.push(PointField {
                name: r.string()?,
                offset: r.u32()?,
                datatype: r.u8()?,
                count: r.u32()?,
            });
        }
        let is_bigendian = r.bool()?;
        let point_step = r.u32()?;
        let row_step = r.u32()?;
        let data = r.bytes("data")?.to_vec();
        let is_dense = r.bool()?;
        Ok(PointCloud2Msg {
            header,
            height,
            width,
            fields,
            is_bigendian,
            point_step,
            row_step,
            data,
            is_dense,
        })
    }

    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::with_capacity(endian, self.data.len() + 256);
        self.header.write(&mut w);
        w.u32(self.height);
        w.u32(self.width);
        w.u32(self.fields.len() as u32);
        for f in &self.fields {
            w.string(&f.name);
            w.u32(f.offset);
            w.u8(f.datatype);
            w.u32(f.count);
        }
        w.bool(self.is_bigendian);
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.bytes(&self.data);
        w.bool(self.is_dense);
        w.finish()
    }
}

/// `sensor_msgs/msg/Image`, with its raw data.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMsg {
    /// ROS field `header`: stamp and camera frame.
    pub header: Header,
    /// Rows, pixels (ROS field `height`).
    pub height: u32,
    /// Columns, pixels (ROS field `width`).
    pub width: u32,
    /// Pixel encoding, such as `rgb8` or `mono8` (ROS field `encoding`).
    pub encoding: String,
    /// Non-zero when multi-byte pixels are big endian (ROS field `is_bigendian`).
    pub is_bigendian: u8,
    /// Bytes per row (ROS field `step`).
    pub step: u32,
    /// Raw pixel bytes, `step * height` of them (ROS field `data`).
    pub data: Vec<u8>,
}

impl ImageMsg {
    /// Decodes a CDR payload (encapsulation header included). Fails on a cut or malformed payload.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        Self::decode_wire(buf, Wire::Cdr)
    }

    /// Decodes a message serialized as `wire` (CDR, or ROS 1 from a `.bag`).
    pub fn decode_wire(buf: &[u8], wire: Wire) -> CdrResult<Self> {
        let mut r = CdrReader::for_wire(buf, wire)?;
        Ok(ImageMsg {
            header: Header::read(&mut r)?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?,
            is_bigendian: r.u8()?,
            step: r.u32()?,
            data: r.bytes("data")?.to_vec(),
        })
    }

    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::with_capacity(endian, self.data.len() + 128);
        self.header.write(&mut w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.encoding);
        w.u8(self.is_bigendian);
        w.u32(self.step);
        w.bytes(&self.data);
        w.finish()
    }
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RegionOfInterest {
    /// Left column of the region, pixels (ROS field `x_offset`).
    pub x_offset: u32,
    /// Top row of the region, pixels (ROS field `y_offset`).
    pub y_offset: u32,
    /// Rows, pixels; 0 with `width` 0 means the full image (ROS field `height`).
    pub height: u32,
    /// Columns, pixels (ROS field `width`).
    pub width: u32,
    /// Whether the region is to be rectified (ROS field `do_rectify`).
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfoMsg {
    /// ROS field `header`: stamp and camera optical frame.
    pub header: Header,
    /// Image rows, pixels (ROS field `height`).
    pub height: u32,
    /// Image columns, pixels (ROS field `width`).
    pub width: u32,
    /// Distortion model name, such as `plumb_bob` (ROS field `distortion_model`).
    pub distortion_model: String,
    /// Distortion coefficients of that model (ROS field `d`).
    pub d: Vec<f64>,
    /// Intrinsic matrix, row major, pixels (ROS field `k`).
    pub k: [f64; 9],
    /// Rectification rotation, row major (ROS field `r`).
    pub r: [f64; 9],
    /// 3×4 projection matrix, row major, pixels (ROS field `p`).
    pub p: [f64; 12],
    /// Horizontal binning, 0 or 1 for none (ROS field `binning_x`).
    pub binning_x: u32,
    /// Vertical binning, 0 or 1 for none (ROS field `binning_y`).
    pub binning_y: u32,
    /// Region of interest (ROS field `roi`).
    pub roi: RegionOfInterest,
}

impl CameraInfoMsg {
    /// Decodes a CDR payload (encapsulation header included). Fails on a cut or malformed payload.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        Self::decode_wire(buf, Wire::Cdr)
    }

    /// Decodes a message serialized as `wire` (CDR, or ROS 1 from a `.bag`).
    pub fn decode_wire(buf: &[u8], wire: Wire) -> CdrResult<Self> {
        let mut r = CdrReader::for_wire(buf, wire)?;
        Ok(CameraInfoMsg {
            header: Header::read(&mut r)?,
            height: r.u32()?,
            width: r.u32()?,
            distortion_model: r.string()?,
            d: r.f64_seq("d")?,
            k: r.f64_array()?,
            r: r.f64_array()?,
            p: r.f64_array()?,
            binning_x: r.u32()?,
            binning_y: r.u32()?,
            roi: RegionOfInterest {
                x_offset: r.u32()?,
                y_offset: r.u32()?,
                height: r.u32()?,
                width: r.u32()?,
                do_rectify: r.bool()?,
            },
        })
    }

    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::new(endian);
        self.header.write(&mut w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.distortion_model);
        w.f64_seq(&self.d);
        w.f64_array(&self.k);
        w.f64_array(&self.r);
        w.f64_array(&self.p);
        w.u32(self.binning_x);
        w.u32(self.binning_y);
        w.u32(self.roi.x_offset);
        w.u32(self.roi.y_offset);
        w.u32(self.roi.height);
        w.u32(self.roi.width);
        w.bool(self.roi.do_rectify);
        w.finish()
    }
}

/// `sensor_msgs/msg/NavSatFix`: where a GNSS receiver puts the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct NavSatFixMsg {
    /// ROS field `header`: stamp and the receiver's frame.
    pub header: Header,
    /// Fix status (ROS field `status.status`): −1 no fix, 0 fix, 1 SBAS, 2 GBAS.
    pub status: i8,
    /// Satellite systems used (ROS field `status.service`, a bit mask).
    pub service: u16,
    /// Degrees north of the equator (ROS field `latitude`).
    pub latitude: f64,
    /// Degrees east of Greenwich (ROS field `longitude`).
    pub longitude: f64,
    /// Metres above the WGS 84 ellipsoid (ROS field `altitude`).
    pub altitude: f64,
    /// Position covariance, m², east-north-up, row major (ROS field `position_covariance`).
    pub position_covariance: [f64; 9],
    /// How the covariance is known, 0 unknown to 3 known (ROS field
    /// `position_covariance_type`).
    pub position_covariance_type: u8,
}

impl NavSatFixMsg {
    /// Decodes a message serialized as `wire` (CDR, or ROS 1 from a `.bag`). Fails on a cut
    /// or malformed payload; the values are not checked ([`Self::position`] does).
    pub fn decode_wire(buf: &[u8], wire: Wire) -> CdrResult<Self> {
        let mut r = CdrReader::for_wire(buf, wire)?;
        Ok(NavSatFixMsg {
            header: Header::read(&mut r)?,
            status: r.u8()? as i8,
            service: r.u16()?,
            latitude: r.f64()?,
            longitude: r.f64()?,
            altitude: r.f64()?,
            position_covariance: r.f64_array()?,
            position_covariance_type: r.u8()?,
        })
    }

    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::new(endian);
        self.header.write(&mut w);
        w.u8(self.status as u8);
        w.u16(self.service);
        w.f64(self.latitude);
        w.f64(self.longitude);
        w.f64(self.altitude);
        w.f64_array(&self.position_covariance);
        w.u8(self.position_covariance_type);
        w.finish()
    }

    /// Latitude and longitude (degrees) when the receiver has a fix and both are on the
    /// globe; otherwise why not.
    pub fn position(&self) -> std::result::Result<(f64, f64), String> {
        if self.status < 0 {
            return Err(format!("no fix (status {})", self.status));
        }
        let (lat, lon) = (self.latitude, self.longitude);
        if !((-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon)) {
            return Err(format!(
                "latitude {lat}, longitude {lon}: not a place on the globe"
            ));
        }
        Ok((lat, lon))
    }
}

/// MCAP schema names (as `ros2 bag` writes them).
pub mod schema_name {
    /// `tf2_msgs/msg/TFMessage`.
    pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
    /// `sensor_msgs/msg/PointCloud2`.
    pub const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";
    /// `sensor_msgs/msg/Image`.
    pub const IMAGE: &str = "sensor_msgs/msg/Image";
    /// `sensor_msgs/msg/CameraInfo`.
    pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
    /// `sensor_msgs/msg/NavSatFix`.
    pub const NAV_SAT_FIX: &str = "sensor_msgs/msg/NavSatFix";
}

const SEP: &str =
    "================================================================================\n";

pub(crate) const TIME_DEF: &str = "int32 sec\nuint32 nanosec\n";
pub(crate) const HEADER_DEF: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";

/// A ros2msg schema text: the main definition, then each dependency after a separator line.
pub(crate) fn with_deps(main: &str, deps: &[(&str, &str)]) -> String {
    let mut s = String::from(main);
    for (name, def) in deps {
        s.push_str(SEP);
        s.push_str("MSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(def);
    }
    s
}

/// The `ros2msg` schema text for one of the four message types: the main definition, then
/// each dependency after a line of 80 `=` and a `MSG: pkg/Type` line, as `ros2 bag` writes.
pub fn schema_text(schema: &str) -> Option<String> {
    let header = ("std_msgs/Header", HEADER_DEF);
    let time = ("builtin_interfaces/Time", TIME_DEF);
    Some(match schema {
        schema_name::TF_MESSAGE => with_deps(
            "geometry_msgs/TransformStamped[] transforms\n",
            &[
                (
                    "geometry_msgs/TransformStamped",
                    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
                ),
                header,
                time,
                (
                    "geometry_msgs/Transform",
                    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
                ),
                ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
                (
                    "geometry_msgs/Quaternion",
                    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
                ),
            ],
        ),
        schema_name::POINT_CLOUD2 => with_deps(
            "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
            &[
                header,
                time,
                (
                    "sensor_msgs/PointField",
                    "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\nuint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
                ),
            ],
        ),
        schema_name::IMAGE => with_deps(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
            &[header, time],
        ),
        schema_name::CAMERA_INFO => with_deps(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
            &[
                header,
                time,
                (
                    "sensor_msgs/RegionOfInterest",
                    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
                ),
            ],
        ),
        schema_name::NAV_SAT_FIX => with_deps(
            "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\nfloat64 altitude\nfloat64[9] position_covariance\nuint8 COVARIANCE_TYPE_UNKNOWN = 0\nuint8 COVARIANCE_TYPE_APPROXIMATED = 1\nuint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2\nuint8 COVARIANCE_TYPE_KNOWN = 3\nuint8 position_covariance_type\n",
            &[
                header,
                time,
                (
                    "sensor_msgs/NavSatStatus",
                    "int8 STATUS_NO_FIX = -1\nint8 STATUS_FIX = 0\nint8 STATUS_SBAS_FIX = 1\nint8 STATUS_GBAS_FIX = 2\nint8 status\nuint16 SERVICE_GPS = 1\nuint16 SERVICE_GLONASS = 2\nuint16 SERVICE_COMPASS = 4\nuint16 SERVICE_GALILEO = 8\nuint16 service\n",
                ),
            ],
        ),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::pose_xyz_rpy;
    use proptest::prelude::*;

    fn hdr(ns: i64, f: &str) -> Header {
        Header {
            stamp: Time::from_nanos(ns),
            frame_id: f.into(),
        }
    }

    /// A ROS 1 serialized CameraInfo: header with seq, packed, strings without NUL.
    #[test]
    fn ros1_wire_decodes_header_seq_and_packed_fields() {
        let mut b = Vec::new();
        let u32s = |b: &mut Vec<u8>, v: u32| b.extend_from_slice(&v.to_le_bytes());
        let string = |b: &mut Vec<u8>, s: &str| {
            b.extend_from_slice(&(s.len() as u32).to_le_bytes());
            b.extend_from_slice(s.as_bytes());
        };
        u32s(&mut b, 7); // seq
        u32s(&mut b, 1700); // secs
        u32s(&mut b, 250); // nsecs
        string(&mut b, "cam");
        u32s(&mut b, 480);
        u32s(&mut b, 640);
        string(&mut b, "plumb_bob");
        u32s(&mut b, 5);
        for i in 0..(5 + 9 + 9 + 12) {
            b.extend_from_slice(&(i as f64).to_le_bytes());
        }
        for v in [1u32, 1, 0, 0, 0, 0] {
            u32s(&mut b, v);
        }
        b.push(0);
        let m = CameraInfoMsg::decode_wire(&b, Wire::Ros1).unwrap();
        assert_eq!(
            m.header.stamp,
            Time {
                sec: 1700,
                nanosec: 250
            }
        );
        assert_eq!(m.header.frame_id, "cam");
        assert_eq!((m.height, m.width), (480, 640));
        assert_eq!(m.d, vec![0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m.k[0], 5.0);
        assert_eq!(m.p[11], 34.0);
        // The same bytes are not CDR (no encapsulation header), and a cut payload is an
        // error, not a panic.
        assert!(CameraInfoMsg::decode(&b).is_err());
        assert!(CameraInfoMsg::decode_wire(&b[..b.len() - 3], Wire::Ros1).is_err());
    }

    #[test]
    fn time_nanos_round_trip() {
        for ns in [
            0i64,
            1,
            999_999_999,
            1_000_000_000,
            1_700_000_000_123_456_789,
        ] {
            assert_eq!(Time::from_nanos(ns).to_nanos(), ns);
        }
    }

    #[test]
    fn tf_round_trip_both_endians() {
        let m = TfMessage {
            transforms: vec![
                TransformStamped {
                    header: hdr(5, "map"),
                    child_frame_id: "base_link".into(),
                    child_to_parent: pose_xyz_rpy(1.0, -2.0, 3.0, 0.1, -0.2, 0.3),
                },
                TransformStamped {
                    header: hdr(6, "base_link"),
                    child_frame_id: "lidar".into(),
                    child_to_parent: pose_xyz_rpy(0.5, 0.0, 1.8, 0.0, 0.0, 0.0),
                },
            ],
        };
        for e in [Endian::Little, Endian::Big] {
            let d = TfMessage::decode(&m.encode(e)).unwrap();
            assert_eq!(d.transforms.len(), 2);
            for (a, b) in d.transforms.iter().zip(&m.transforms) {
                assert_eq!(a.header, b.header);
                assert_eq!(a.child_frame_id, b.child_frame_id);
                assert!(
                    (a.child_to_parent.to_homogeneous() - b.child_to_parent.to_homogeneous())
                        .norm()
                        < 1e-12
                );
            }
        }
    }

    #[test]
    fn nav_sat_fix_round_trips_and_says_where_it_is_not_usable() {
        let m = NavSatFixMsg {
            header: hdr(1_700_000_000_123_456_789, "gps"),
            status: 0,
            service: 1,
            latitude: 34.2,
            longitude: -118.17,
            altitude: 350.0,
            position_covariance: [0.5, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 2.0],
            position_covariance_type: 2,
        };
        for e in [Endian::Little, Endian::Big] {
            let d = NavSatFixMsg::decode_wire(&m.encode(e), Wire::Cdr).unwrap();
            assert_eq!(d, m);
            // Cut anywhere: an error, never a panic.
            let b = m.encode(e);
            for n in 0..b.len() {
                assert!(
                    NavSatFixMsg::decode_wire(&b[..n], Wire::Cdr).is_err(),
                    "{n}"
                );
            }
        }
        assert_eq!(m.position(), Ok((34.2, -118.17)));
        let no_fix = NavSatFixMsg {
            status: -1,
            ..m.clone()
        };
        assert!(no_fix.position().unwrap_err().contains("no fix"));
        for (lat, lon) in [
            (91.0, 0.0),
            (0.0, 180.5),
            (f64::NAN, 0.0),
            (0.0, f64::INFINITY),
        ] {
            let off = NavSatFixMsg {
                latitude: lat,
                longitude: lon,
                ..m.clone()
            };
            assert!(
                off.position().unwrap_err().contains("not a place"),
                "{lat} {lon}"
            );
        }
        assert!(schema_text(schema_name::NAV_SAT_FIX).is_some());
    }

    /// A rejected transform says what is wrong with it: its translation, its rotation's
    /// finiteness, or its quaternion's norm.
    #[test]
    fn a_bad_transform_is_rejected_with_what_is_wrong() {
        let tf = |v: [f64; 7]| {
            let mut w = CdrWriter::new(Endian::Little);
            w.u32(1);
            hdr(0, "map").write(&mut w);
            w.string("base_link");
            for x in v {
                w.f64(x);
            }
            TfMessage::decode(&w.finish()).unwrap_err().message
        };
        let nan = f64::NAN;
        for (v, want) in [
            (
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0],
                "quaternion is not unit (norm 2)",
            ),
            (
                [nan, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
                "translation is not finite (NaN, 0, 0)",
            ),
            (
                [0.0, 0.0, 0.0, 0.0, 0.0, nan, 1.0],
                "rotation is not finite",
            ),
        ] {
            let e = tf(v);
            assert!(e.contains(want) && e.contains("map → base_link"), "{e}");
        }
    }

    #[test]
    fn camera_info_round_trip() {
        let m = CameraInfoMsg {
            header: hdr(42, "camera_optical"),
            height: 480,
            width: 640,
            distortion_model: "plumb_bob".into(),
            d: vec![0.1, -0.01, 0.001, 0.002, 0.0],
            k: [500.0, 0.0, 320.0, 0.0, 501.0, 240.0, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [
                500.0, 0.0, 320.0, 0.0, 0.0, 501.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0,
            ],
            binning_x: 1,
            binning_y: 2,
            roi: RegionOfInterest {
                x_offset: 1,
                y_offset: 2,
                height: 3,
                width: 4,
                do_rectify: true,
            },
        };
        for e in [Endian::Little, Endian::Big] {
            assert_eq!(CameraInfoMsg::decode(&m.encode(e)).unwrap(), m);
        }
    }

    #[test]
    fn schema_texts_exist_and_name_dependencies() {
        let s = schema_text(schema_name::POINT_CLOUD2).unwrap();
        assert!(s.contains("\nMSG: sensor_msgs/PointField\n"));
        assert!(s.contains("\nMSG: builtin_interfaces/Time\n"));
        assert!(schema_text("foo_msgs/msg/Bar").is_none());
    }

    proptest! {
        #[test]
        fn image_and_cloud_round_trip(
            big in any::<bool>(), h in 0u32..4, w in 0u32..5, frame in "[a-z_]{0,10}",
            ns in 0i64..2_000_000_000_000_000_000, data in proptest::collection::vec(any::<u8>(), 0..64),
        ) {
            let e = if big { Endian::Big } else { Endian::Little };
            let im = ImageMsg { header: hdr(ns, &frame), height: h, width: w, encoding: "mono8".into(),
                is_bigendian: big as u8, step: w, data: data.clone() };
            prop_assert_eq!(ImageMsg::decode(&im.encode(e)).unwrap(), im);
            let pc = PointCloud2Msg { header: hdr(ns, &frame), height: h, width: w,
                fields: vec![PointField { name: "x".into(), offset: 0, datatype: datatype::FLOAT32, count: 1 },
                             PointField { name: "i".into(), offset: 4, datatype: datatype::UINT16, count: 1 }],
                is_bigendian: big, point_step: 6, row_step: 6 * w, data, is_dense: !big };
            prop_assert_eq!(PointCloud2Msg::decode(&pc.encode(e)).unwrap(), pc);
        }
    }
}
