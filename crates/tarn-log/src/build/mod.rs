//! Offline builds: a point cloud in the map frame ([`build_file`], [`build_cloud`]) or a
//! robot log through the online [`Mapper`](tarn::mapper::Mapper) ([`build_log`]: one code
//! path for online and offline), their reports (`report.json`), the config file of a build
//! ([`LogBuildConfig`]), and a log's cells before the water stage with the water stage
//! over them ([`build_tiles`], [`finish_tiles`]), for builds of many logs.

use std::path::Path;

use crate::error::{Error, Result};
use crate::grid::TileMap;
use tarn::io;

mod cloud;
mod config;
mod log;
mod report;
mod tiles;

pub use cloud::*;
pub use config::*;
pub use log::*;
pub use report::*;
pub use tiles::*;

/// The outputs beside the contract's files, each written only when asked for, from the
/// finished `map.ply` (so that every output holds the same values) into the same staged
/// set: a build replaces all of its outputs at once or none.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExtraMaps {
    /// `map.mcap`: the map as a `grid_map_msgs/GridMap` and a `nav_msgs/OccupancyGrid`
    /// ([`crate::ros_export`]), with these headers.
    pub ros_map: Option<crate::ros_export::RosMapOptions>,
    /// `map.tif`: the layers as a GeoTIFF ([`tarn::io::write_geotiff`]).
    pub geotiff: Option<tarn::io::GeoTiffOptions>,
    /// `tiles.bin`: the map's cells before the water stage (elevation statistics and
    /// water evidence) as a tile set ([`TileMap::to_bytes`]), which merges exactly with
    /// other builds' and can be finished again under another fusion rule.
    pub tiles: bool,
}

impl ExtraMaps {
    /// What the `[build]` section asks for: the map's frame is `frame_id`, else `map_frame`;
    /// `stamp_ns` is the map's log time.
    pub fn of(b: &BuildOptions, map_frame: &str, stamp_ns: u64) -> Self {
        ExtraMaps {
            ros_map: b.ros_map.then(|| crate::ros_export::RosMapOptions {
                frame_id: b.frame_id.clone().unwrap_or_else(|| map_frame.to_string()),
                stamp_ns,
            }),
            geotiff: b
                .geotiff
                .then_some(tarn::io::GeoTiffOptions { epsg: b.epsg }),
            tiles: b.tiles,
        }
    }

    /// Writes the asked-for files into `dir`, the map's from `dir/map.ply` and the tile
    /// set from `tiles`; their names.
    fn write(&self, dir: &Path, tiles: &TileMap) -> Result<Vec<String>> {
        let mut written = Vec::new();
        if self.tiles {
            let p = dir.join("tiles.bin");
            std::fs::write(&p, tiles.to_bytes()).map_err(|e| Error::io(&p, e))?;
            written.push("tiles.bin".to_string());
        }
        if self.ros_map.is_none() && self.geotiff.is_none() {
            return Ok(written);
        }
        let map = tarn::io::read_map_ply(&dir.join("map.ply"))?;
        if let Some(o) = &self.ros_map {
            crate::ros_export::write_ros_map(&dir.join("map.mcap"), &map, o)?;
            written.push("map.mcap".to_string());
        }
        if let Some(o) = &self.geotiff {
            tarn::io::write_geotiff(&dir.join("map.tif"), &map, o)?;
            written.push("map.tif".to_string());
        }
        Ok(written)
    }
}

/// One warning per staging folder of an earlier, killed build that `stage` removed.
fn swept_warnings(stage: &io::Staging) -> Vec<String> {
    stage
        .swept()
        .iter()
        .map(|p| {
            format!(
                "removed {}: the staging folder of an earlier build of this output that was \
                 killed before it finished",
                p.display()
            )
        })
        .collect()
}

/// Rejects an output directory that is an existing file.
pub fn check_output_dir(out: &Path) -> Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(Error::invalid(
            "output directory",
            format!("{} exists and is not a directory", out.display()),
        ));
    }
    Ok(())
}
