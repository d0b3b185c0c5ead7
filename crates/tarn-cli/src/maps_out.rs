//! The options of `tarn build` for its outputs beside the contract's: `map.mcap`
//! (`--ros-map`), `map.tif` (`--geotiff`) and `tiles.bin` (`--tiles`), over the config's
//! `[build]` `ros_map`, `geotiff`, `tiles`, `epsg` and `frame_id`. The library writes them with the contract's files
//! (`tarn_log::build::ExtraMaps`).

use clap::Args;
use tarn_log::build::BuildOptions;

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
    /// Also write tiles.bin: the map's cells before the water stage (elevation statistics
    /// and water evidence) as a tile set, the format tarn's Python package merges and
    /// finishes (docs/distributed.md).
    #[arg(long)]
    pub tiles: bool,
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
pub fn apply(a: &MapsOutArgs, b: &mut BuildOptions) {
    b.ros_map |= a.ros_map;
    b.geotiff |= a.geotiff;
    b.tiles |= a.tiles;
    if a.epsg.is_some() {
        b.epsg = a.epsg;
    }
    if a.frame_id.is_some() {
        b.frame_id = a.frame_id.clone();
    }
}
