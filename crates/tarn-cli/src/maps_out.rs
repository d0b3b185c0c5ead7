//! The ROS and GIS outputs of `tarn build`: `map.mcap` (`--ros-map`) and `map.tif`
//! (`--geotiff`), or the config's `[build]` `ros_map`, `geotiff` and `epsg`, written from
//! the finished `map.ply` after the contract's files.

use std::path::Path;

use anyhow::Context;
use clap::Args;
use tarn::io::geotiff::{write_geotiff, GeoTiffOptions};
use tarn::io::mapfile::read_map_ply;
use tarn::io::ros_export::{write_ros_map, RosMapOptions};
use tarn::mapper::MapperConfig;

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

/// The options over the config's `[build]` section.
pub fn apply(a: &MapsOutArgs, cfg: &mut MapperConfig) {
    cfg.build.ros_map |= a.ros_map;
    cfg.build.geotiff |= a.geotiff;
    if a.epsg.is_some() {
        cfg.build.epsg = a.epsg;
    }
}

/// Writes the outputs the config asks for (`[build]` `ros_map`, `geotiff`, `epsg`, with
/// the options applied) into `out`, from `out/map.ply`. The map's frame is `--frame-id`,
/// else the log config's `map_frame`; `stamp_ns` is the map's log time. Returns the names
/// of the files written.
pub fn write(
    a: &MapsOutArgs,
    cfg: &MapperConfig,
    out: &Path,
    stamp_ns: u64,
) -> anyhow::Result<Vec<&'static str>> {
    let b = &cfg.build;
    let mut written = Vec::new();
    if !(b.ros_map || b.geotiff) {
        return Ok(written);
    }
    let ply = out.join("map.ply");
    let map = read_map_ply(&ply).with_context(|| format!("reading back {}", ply.display()))?;
    if b.ros_map {
        let opts = RosMapOptions {
            frame_id: a
                .frame_id
                .clone()
                .unwrap_or_else(|| cfg.log.map_frame.clone()),
            stamp_ns,
        };
        write_ros_map(&out.join("map.mcap"), &map, &opts)?;
        written.push("map.mcap");
    }
    if b.geotiff {
        write_geotiff(&out.join("map.tif"), &map, &GeoTiffOptions { epsg: b.epsg })?;
        written.push("map.tif");
    }
    Ok(written)
}
