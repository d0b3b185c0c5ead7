//! A simulated drive for the command-line robustness tests: the vehicle's path, the lidar's
//! mount, an organized scan of level ground, and the log's transforms. Shared by
//! `tests/robust_cli.rs`, `tests/plausibility.rs` and `tests/robot_logs.rs`.
#![allow(dead_code)]

use std::path::Path;

use nalgebra::{Point3, Vector3};
use tarn::geom::{pose_xyz_rpy, PointCloud, Pose};
use tarn_log::mcap_log::{LogWriter, WriteOptions};
use tarn_log::ros::{TfMessage, TransformStamped};

/// A log at `path` that starts with the lidar's mount ([`lidar_ext`]) on `/tf_static`.
pub fn log_with_mount(path: &Path) -> LogWriter {
    let mut w = LogWriter::create(path, &WriteOptions::default()).unwrap();
    let ext = TransformStamped::new("base_link", "lidar", 0, lidar_ext());
    w.write_tf(
        "/tf_static",
        &TfMessage {
            transforms: vec![ext],
        },
        0,
    )
    .unwrap();
    w
}

/// The vehicle's pose (base_link in map) at `ns` on `/tf`.
pub fn write_vehicle_tf(w: &mut LogWriter, ns: u64, pose: Pose) {
    let tf = TransformStamped::new("map", "base_link", ns as i64, pose);
    w.write_tf(
        "/tf",
        &TfMessage {
            transforms: vec![tf],
        },
        ns,
    )
    .unwrap();
}

/// The vehicle's pose at time `t` (s): 2 m/s along x, drifting in y and turning slowly.
pub fn base(t: f64) -> Pose {
    pose_xyz_rpy(2.0 * t, 0.2 * t, 0.0, 0.0, 0.0, 0.02 * t)
}

/// The lidar's mount on the vehicle.
pub fn lidar_ext() -> Pose {
    pose_xyz_rpy(0.2, 0.0, 1.8, 0.0, 0.0, 0.0)
}

/// A `rings` × `cols` scan of the plane z = 0 seen from `sensor_to_map`.
pub fn scan(sensor_to_map: &Pose, rings: usize, cols: usize) -> PointCloud {
    let o = sensor_to_map * Point3::origin();
    let mut xyz = Vec::with_capacity(rings * cols);
    for r in 0..rings {
        let el = (-25.0 + 23.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = (c as f64 * 360.0 / cols as f64).to_radians();
            let ds = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let d = sensor_to_map * ds;
            let t = -o.z / d.z;
            xyz.push(if t > 0.5 && t < 30.0 {
                let q = ds * t;
                [q.x as f32, q.y as f32, q.z as f32]
            } else {
                [f32::NAN; 3]
            });
        }
    }
    PointCloud::organized(rings, cols, xyz).unwrap()
}
