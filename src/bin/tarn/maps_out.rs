//! The ROS and GIS outputs of `tarn build`: `map.mcap` (`--ros-map`) and `map.tif`
//! (`--geotiff`), written from the finished `map.ply` after the contract's files.

use std::path::Path;

use anyhow::Context;
use clap::Args;
use tarn::io::geotiff::{write_geotiff, GeoTiffOptions};
use tarn::io::mapfile::read_map_ply;
use tarn::io::ros_export::{write_ros_map, RosMapOptions};

#[derive(Args, Debug, Clone, Default)]
pub struct MapsOutArgs {
    /// Also write map.mcap: the map as a grid_map_msgs/GridMap (every layer) on
    /// /tarn/grid_map and a nav_msgs/OccupancyGrid of the hazards on /tarn/occupancy.
    #[arg(long)]
    pub ros_map: bool,
    /// Also write map.tif: a float32 GeoTIFF, one band per layer (elevation, elevation_std,
    /// water_probability, class, hazard, depth), NaN as nodata.
    #[arg(long)]
    pub geotiff: bool,
    /// Frame the map's coordinates are in, named in map.mcap's headers [default: the log
    /// config's map_frame, "map"].
    #[arg(long)]
    pub frame_id: Option<String>,
    /// EPSG code of the projected CRS the map frame is in (e.g. 32633 for UTM 33N), written
    /// into map.tif; without it map.tif has a geotransform but no CRS.
    #[arg(long)]
    pub epsg: Option<u16>,
}

impl MapsOutArgs {
    /// Whether any of these outputs was asked for.
    pub fn any(&self) -> bool {
        self.ros_map || self.geotiff
    }
}

/// Writes the outputs asked for into `out`, from `out/map.ply`. `frame` names the map's
/// frame unless `--frame-id` does; `stamp_ns` is the map's log time. Returns the names
/// of the files written.
pub fn write(
    a: &MapsOutArgs,
    out: &Path,
    frame: &str,
    stamp_ns: u64,
) -> anyhow::Result<Vec<&'static str>> {
    let mut written = Vec::new();
    if !a.any() {
        return Ok(written);
    }
    let ply = out.join("map.ply");
    let map = read_map_ply(&ply).with_context(|| format!("reading back {}", ply.display()))?;
    if a.ros_map {
        let opts = RosMapOptions {
            frame_id: a.frame_id.clone().unwrap_or_else(|| frame.to_string()),
            stamp_ns,
        };
        write_ros_map(&out.join("map.mcap"), &map, &opts)?;
        written.push("map.mcap");
    }
    if a.geotiff {
        write_geotiff(&out.join("map.tif"), &map, &GeoTiffOptions { epsg: a.epsg })?;
        written.push("map.tif");
    }
    Ok(written)
}
