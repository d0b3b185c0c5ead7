//! Reading and writing the outside world's files: point clouds, logs, exports.
//!
//! ROS 2 logs (MCAP, CDR), without a ROS installation:
//! - [`ros`]: CDR in both byte orders; `TFMessage`, `PointCloud2`, `Image`, `CameraInfo`;
//!   their `ros2msg` schemas; conversions to [`crate::geom::PointCloud`], [`crate::sensor::Image`]
//!   and [`crate::geom::camera::CameraModel`].
//! - [`mcap_log`]: [`mcap_log::LogReader`] streams messages from chunked or unchunked,
//!   zstd / lz4 / uncompressed files, with or without summary; [`mcap_log::LogWriter`]
//!   writes `ros2`-profile logs; [`mcap_log::summarize`], [`mcap_log::recode`].
//! - [`log`]: every log storage behind [`log::MessageSource`]: MCAP, rosbag2 directories,
//!   and with the `bags` feature rosbag2 `.db3` files and ROS 1 `.bag` files ([`bags`]);
//!   [`log::open`], [`log::summarize`].
//! - [`tf`]: [`tf::TfBuffer`], interpolating transforms, never extrapolating.
//! - [`frames`]: [`frames::FrameStream`], the time-synchronized [`frames::Frame`]s a map
//!   is built from, with [`frames::FrameStats`] and progress in bytes.
//!
//! Measured with `cargo bench --bench mcap_read -- --warm-up-time 1 --measurement-time 4`
//! (2 shared cores, 60 clouds of 32 × 1024 points with intensity plus 100 Hz TF): the
//! frame stream read a zstd log at 276 MiB/s of file (8.4 k messages/s, 60 clouds in
//! about 80 ms) and an uncompressed one at 1.2 GiB/s (24 k messages/s). Peak RSS of the
//! frame stream (`examples/mcap_memory.rs`) was 8588 kB for a 100-scan log and 8648 kB
//! for a 1000-scan log.

#[cfg(feature = "bags")]
pub mod bags;
pub mod export;
pub mod frames;
pub mod geotiff;
pub mod kitti;
pub mod log;
pub mod mapfile;
pub mod mcap_log;
pub mod ply;
pub mod raster;
#[cfg(feature = "render")]
pub mod render;
pub mod ros;
pub mod ros_export;
pub mod tf;

use std::path::Path;

use crate::error::{Error, Result};
use crate::geom::PointCloud;

/// Reads a point cloud, choosing the reader by the file's extension (case-insensitive):
/// `.ply` → [`ply::read`], `.bin` → [`kitti::read`] (an unorganized KITTI scan).
pub fn read_point_cloud(path: &Path) -> Result<PointCloud> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("ply") => ply::read(path),
        Some("bin") => kitti::read(path),
        _ => Err(Error::format(
            path,
            "file name",
            format!("not an input tarn reads ({})", log::SUPPORTED),
        )),
    }
}

/// Rearranges a column-major lidar scan (point `column * rings + ring`, as the Ouster and
/// RELLIS-3D files store it) into an organized cloud of `rings` rows × `n / rings` columns
/// (row = ring, so row 0 is ring 0). Every per-point channel moves with its point; the pose,
/// sensor origin and stamp are kept.
pub fn organize_column_major(cloud: &PointCloud, rings: usize) -> Result<PointCloud> {
    let n = cloud.len();
    if rings == 0 || n % rings != 0 {
        return Err(Error::invalid(
            "lidar ring count",
            format!("{n} points cannot be split into {rings} rings of equal length"),
        ));
    }
    let cols = n / rings;
    // Point (ring r, column c) of the result comes from index c * rings + r.
    fn permute<T: Copy>(v: &[T], rings: usize, cols: usize) -> Vec<T> {
        let mut out = Vec::with_capacity(v.len());
        for r in 0..rings {
            out.extend((0..cols).map(|c| v[c * rings + r]));
        }
        out
    }
    let mut out = PointCloud::organized(rings, cols, permute(&cloud.xyz, rings, cols))?;
    out.intensity = cloud.intensity.as_deref().map(|v| permute(v, rings, cols));
    out.reflectivity = cloud
        .reflectivity
        .as_deref()
        .map(|v| permute(v, rings, cols));
    out.rgb = cloud.rgb.as_deref().map(|v| permute(v, rings, cols));
    out.frame_to_map = cloud.frame_to_map;
    out.sensor_origin = cloud.sensor_origin;
    out.stamp = cloud.stamp;
    out.validate()?;
    Ok(out)
}

/// The shared test data a test reads in place (`../shared/data`, beside the repository):
/// `None`, with a message saying so, where it is absent, and the test skips.
#[cfg(test)]
pub(crate) fn test_data(path: &str) -> Option<&Path> {
    let p = Path::new(path);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {path} is absent (shared test data, kept beside the repository)");
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dispatch_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("a.PLY");
        std::fs::write(
            &ply,
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\nend_header\n1 2 3\n",
        )
        .unwrap();
        assert_eq!(read_point_cloud(&ply).unwrap().xyz, vec![[1.0, 2.0, 3.0]]);
        let bin = dir.path().join("scan.bin");
        let pts: Vec<u8> = [4.0f32, 5.0, 6.0, 0.5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        std::fs::write(&bin, pts).unwrap();
        assert_eq!(read_point_cloud(&bin).unwrap().xyz, vec![[4.0, 5.0, 6.0]]);
        for name in ["cloud.pcd", "cloud"] {
            let e = read_point_cloud(&dir.path().join(name)).unwrap_err();
            assert!(e.to_string().contains(log::SUPPORTED), "{e}");
            assert!(e.to_string().contains(name), "{e}");
        }
    }

    #[test]
    fn organize_moves_every_channel_and_keeps_the_pose() {
        let mut c = PointCloud::unorganized((0..6).map(|i| [i as f32, 0.0, 0.0]).collect());
        c.intensity = Some((0..6).map(|i| i as f32).collect());
        c.rgb = Some((0..6).map(|i| [i as u8; 3]).collect());
        c.frame_to_map = crate::geom::pose_xyz_rpy(1.0, 2.0, 3.0, 0.0, 0.0, 0.5);
        let o = organize_column_major(&c, 2).unwrap();
        assert_eq!((o.rows, o.cols), (2, 3));
        // Ring 1, column 2 was point 2*2 + 1 = 5.
        assert_eq!(o.xyz[o.index(1, 2)], [5.0, 0.0, 0.0]);
        assert_eq!(o.intensity.as_ref().unwrap()[o.index(0, 1)], 2.0);
        assert_eq!(o.rgb.as_ref().unwrap()[o.index(1, 0)], [1; 3]);
        assert_eq!(o.frame_to_map, c.frame_to_map);
        assert!(organize_column_major(&c, 4).is_err());
        assert!(organize_column_major(&c, 0).is_err());
    }
}
