//! ROS 2 messages without a ROS installation: CDR encoding and the message types tarn
//! reads from and writes to logs.

pub mod cdr;
pub mod convert;
pub mod msgs;

pub use cdr::{CdrError, Endian, Wire};
pub use convert::{
    camera_from_info, camera_to_info, cloud_to_pointcloud2, decode_image, encode_image,
    organize_by_ring, pointcloud2_to_cloud,
};
pub use msgs::{
    schema_name, schema_text, CameraInfoMsg, Header, ImageMsg, NavSatFixMsg, PointCloud2Msg,
    PointField, TfMessage, Time, TransformStamped,
};
