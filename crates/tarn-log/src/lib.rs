//! # tarn-log
//!
//! Robot logs for [`tarn`], without a ROS installation, and the offline builds made from
//! them. The core library maps frames; this crate reads them from logs:
//!
//! - [`ros`]: CDR in both byte orders; `TFMessage`, `PointCloud2`, `Image`, `CameraInfo`,
//!   `NavSatFix`; their `ros2msg` schemas; conversions to [`tarn::geom::PointCloud`],
//!   [`tarn::sensor::Image`] and [`tarn::geom::CameraModel`].
//! - [`mcap_log`]: [`mcap_log::LogReader`] streams messages from chunked or unchunked,
//!   zstd / lz4 / uncompressed files, with or without summary; [`mcap_log::LogWriter`]
//!   writes `ros2`-profile logs; [`mcap_log::summarize`], [`mcap_log::recode`].
//! - [`log`]: every log storage behind [`log::MessageSource`]: MCAP, rosbag2 directories,
//!   and with the `bags` feature rosbag2 `.db3` files and ROS 1 `.bag` files (`bags`);
//!   [`log::open`], [`log::summarize`].
//! - [`tf`]: [`tf::TfBuffer`], interpolating transforms, never extrapolating.
//! - [`frames`]: [`frames::FrameStream`], the time-synchronized [`tarn::sensor::Frame`]s a
//!   map is built from, with [`frames::FrameStats`] and progress in bytes.
//! - [`ros_export`]: the map as a ROS 2 MCAP (`grid_map_msgs/GridMap`,
//!   `nav_msgs/OccupancyGrid`).
//! - [`build`]: offline builds of a log or a cloud through the online mapper, and their
//!   reports; the config file of a build ([`build::LogBuildConfig`]).

#![warn(missing_docs)]

#[cfg(feature = "bags")]
pub mod bags;
pub mod build;
pub mod frames;
pub mod log;
pub mod mcap_log;
pub mod ros;
pub mod ros_export;
pub mod tf;

// The core's modules under their own names, so that paths here read as they do in the core.
pub(crate) use tarn::{
    calib, cues, error, files, geom, grid, hazard, interrupt, mapper, project, sensor, water,
};

/// The README's examples are compiled and run as doctests (here, where both the core and
/// the log reader are in reach), so they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct ReadmeDoctests;
