//! # tarn
//!
//! 2.5-D terrain maps for off-road ground vehicles from stereo and lidar, and the water
//! hazards in them (after Matthies, Bellutta & McHenry, "Detecting water hazards for
//! autonomous off-road navigation", SPIE 2003).
//!
//! Data flows one way, and a module imports only from modules to its left (enforced by
//! `tests/module_graph.rs`): `error`, `interrupt`, `files`, `geom`, `optics` (the ground
//! floor) → `sensor` (a frame's clouds and images) → `grid` → `classify` → `cues` →
//! `calib` → `project` → `water` → `hazard` → `mapper` (one frame through every stage) →
//! `rig` (sensor datasheets) → `io` (clouds in, maps out). Robot logs and offline builds
//! are the `tarn-log` crate's.
//!
//! Each of these modules is one stage, and names everything it offers itself
//! (`tarn::io::read_ply`, `tarn::cues::LidarCueModel`, `tarn::geom::CameraModel`): the files
//! a stage is split into are private, and each stage's documentation lists what it exports.

#![warn(missing_docs)]

pub mod calib;
pub mod classify;
pub mod cues;
pub mod error;
pub mod files;
pub mod geom;
pub mod grid;
pub mod hazard;
pub mod interrupt;
pub mod io;
pub mod mapper;
pub mod optics;
pub mod project;
pub mod rig;
pub mod sensor;
pub mod water;

pub use error::{Error, Result};
