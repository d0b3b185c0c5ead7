//! What one time step of the vehicle brings to the mapper: its pose, its clouds and its
//! images, each with the pose and camera model needed to place it in the map.
//!
//! This is the mapper's input, whatever it was read from (a robot log, a simulator, a
//! vehicle's drivers). It sits below every stage of the data flow and imports only the
//! geometry (`geom`).
//!
//! Exports: [`Frame`], its [`SensorImage`]s, each an [`Image`] of [`Pixels`].

use crate::geom::{CameraModel, PointCloud, Pose};

/// Pixels of a decoded image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum Pixels {
    /// Colour (from `rgb8` or `bgr8`; always stored R, G, B).
    Rgb8(Vec<[u8; 3]>),
    /// Grey levels (from `mono8` or `8UC1`).
    Mono8(Vec<u8>),
    /// 16-bit grey levels (from `mono16` or `16UC1`).
    Mono16(Vec<u16>),
}

/// A decoded camera image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Columns, pixels.
    pub width: usize,
    /// Rows, pixels.
    pub height: usize,
    /// Pixel values, row major.
    pub pixels: Pixels,
    /// The optical frame of the camera (the message's `header.frame_id`).
    pub frame_id: String,
    /// Acquisition time, seconds.
    pub stamp: f64,
}

/// An image with what is needed to project it.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorImage {
    /// The pixels and their stamp and frame.
    pub image: Image,
    /// Latest `CameraInfo` seen on the matching info topic.
    pub camera: Option<CameraModel>,
    /// Pose of the image's (optical) frame in the map at the image's stamp; `None` when
    /// the transform was missing.
    pub frame_to_map: Option<Pose>,
}

/// One time step of the vehicle.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Stamp of the frame's scan, seconds.
    pub stamp: f64,
    /// `base_link → map` at `stamp`.
    pub base_to_map: Pose,
    /// Clouds with `frame_to_map` at their own stamps and `sensor_origin` at their frame's
    /// origin.
    pub lidar: Option<PointCloud>,
    /// The stereo cloud nearest the scan within `tolerance_s`, if any.
    pub stereo: Option<PointCloud>,
    /// The colour image nearest the scan within `tolerance_s`, if any.
    pub image: Option<SensorImage>,
    /// The short-wave infrared image nearest the scan within `tolerance_s`, if any.
    pub swir: Option<SensorImage>,
    /// The mid-wave infrared image nearest the scan within `tolerance_s`, if any.
    pub mwir: Option<SensorImage>,
    /// The stereo baseline (m) from the latest right-camera `CameraInfo`, when the log has
    /// one.
    pub stereo_baseline_m: Option<f64>,
    /// Latitude and longitude (degrees) of the latest usable GNSS fix read at or before
    /// the frame, when the log has one.
    pub geo: Option<(f64, f64)>,
}
