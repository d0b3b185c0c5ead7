//! Files other programs read and write: point clouds in (PLY, KITTI `.bin`), maps out
//! (the export contract's `map.ply`, `terrain.ply`, `water.ply`, `map.png`; GeoTIFF;
//! the map read back). Robot logs are the `tarn-log` crate's.
//!
//! Exports: clouds in ([`read_point_cloud`] by extension; [`read_ply`],
//! [`read_ply_from_bytes`]; KITTI scans, [`read_kitti`], [`read_kitti_from_bytes`],
//! [`read_kitti_organized`], [`read_kitti_organized_from_bytes`]; [`organize_column_major`]);
//! maps out ([`write_map_files`] and [`write_map_files_marked`] into a [`Staging`] folder,
//! [`write_map_ply`], [`write_mesh_ply`], [`terrain_triangles`], [`needs_double`],
//! [`elevation_range`]; rasters, [`MapRaster`] of a [`Layer`], and [`write_geotiff`] with its
//! [`GeoTiffOptions`]; with the feature `render`, `render_map_png` within
//! `MAP_PNG_MAX_SIDE`); and `map.ply` read back ([`read_map_ply`], [`parse_map_ply`]).
//!
//! The PLY and KITTI readers share their names in their own modules (`read`,
//! `read_from_bytes`); the stage names them by format.

mod export;
mod geotiff;
mod kitti;
mod mapfile;
mod ply;
mod raster;
#[cfg(feature = "render")]
mod render;

pub use export::{
    elevation_range, needs_double, terrain_triangles, write_map_files, write_map_files_marked,
    write_map_ply, write_mesh_ply, Staging,
};
pub use geotiff::{write_geotiff, GeoTiffOptions};
pub use kitti::{
    read as read_kitti, read_from_bytes as read_kitti_from_bytes,
    read_organized as read_kitti_organized,
    read_organized_from_bytes as read_kitti_organized_from_bytes,
};
pub use mapfile::{parse_map_ply, read_map_ply};
pub use ply::{read as read_ply, read_from_bytes as read_ply_from_bytes};
pub use raster::{Layer, MapRaster};
#[cfg(feature = "render")]
pub use render::{render_map_png, MAP_PNG_MAX_SIDE};

use std::path::Path;

use crate::error::{Error, Result};
use crate::geom::PointCloud;

/// Reads a point cloud, choosing the reader by the file's extension (case-insensitive):
/// `.ply` → [`read_ply`], `.bin` → [`read_kitti`] (an unorganized KITTI scan).
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
            "not a point cloud tarn reads (.ply, .bin)".to_string(),
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
            assert!(e.to_string().contains("(.ply, .bin)"), "{e}");
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
