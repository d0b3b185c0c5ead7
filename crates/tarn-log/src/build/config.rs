//! The settings of a log build and the config file that holds them.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::frames::{LogConfig, NamedTopics};
use crate::mapper::MapperConfig;

/// The `[build]` section: options of an offline build (`tarn build`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildOptions {
    /// Publish the window's hazard map after every frame, as on the vehicle, and time it;
    /// off, the water stage runs once at the end (the map is the same).
    pub per_frame_maps: bool,
    /// (cloud inputs) Elevation noise of the points (m, one σ).
    pub noise_sigma_m: f64,
    /// (cloud inputs) Largest window side (cells); larger clouds are built in blocks.
    pub max_window_cells: usize,
    /// Also write `map.mcap`: the map as a GridMap and an OccupancyGrid
    /// ([`crate::ros_export`]).
    pub ros_map: bool,
    /// Also write `map.tif`: the map's layers as a GeoTIFF ([`tarn::io::write_geotiff`]).
    pub geotiff: bool,
    /// Also write `tiles.bin`: the map's cells before the water stage, as a tile set
    /// ([`crate::grid::TileMap::to_bytes`]).
    pub tiles: bool,
    /// EPSG code of the projected CRS the map frame is in, written into `map.tif`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epsg: Option<u16>,
    /// The frame the map's coordinates are in, named in `map.mcap`'s headers; `None`: the
    /// log config's `map_frame`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame_id: Option<String>,
}

impl BuildOptions {
    /// Rejects values no build can run with; the error names the field.
    pub fn validate(&self) -> Result<()> {
        if !(self.noise_sigma_m.is_finite() && self.noise_sigma_m > 0.0) {
            return Err(Error::invalid(
                "build.noise_sigma_m",
                format!("{} is not a finite number > 0", self.noise_sigma_m),
            ));
        }
        if self.max_window_cells < 16 {
            return Err(Error::invalid(
                "build.max_window_cells",
                format!("{} must be ≥ 16", self.max_window_cells),
            ));
        }
        Ok(())
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            per_frame_maps: false,
            noise_sigma_m: 0.02,
            max_window_cells: 2048,
            ros_map: false,
            geotiff: false,
            tiles: false,
            epsg: None,
            frame_id: None,
        }
    }
}

/// Settings of a log build: the vehicle's mapper config, and what only an offline build
/// reads: the log's topics and frames, and the outputs besides the map. One config file
/// holds all three ([`LogBuildConfig::load`]): the mapper's sections, `[log]` and `[build]`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogBuildConfig {
    /// The pipeline: grid, fusion, vehicle, sensors and cues.
    pub mapper: MapperConfig,
    /// Log reading settings: topic and frame names, matching tolerances, speed limit. Its
    /// `frame_topic`, when not the default, names the topic frames are built on; by
    /// default the lidar topic, or the stereo topic when the log has no lidar messages.
    pub log: LogConfig,
    /// What the build does besides mapping.
    pub build: BuildOptions,
    /// Sensor topics chosen by name ([`LogConfig::with_topics_of`] finds the others by
    /// type).
    pub topics: NamedTopics,
}

/// A config file's sections, as written: the mapper's, then `[log]` and `[build]`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ConfigFile {
    grid: crate::grid::GridConfig,
    fusion: crate::grid::Fusion,
    vehicle: crate::hazard::Vehicle,
    water: crate::water::WaterConfig,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    lidar: Option<crate::mapper::LidarConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    stereo: Option<crate::mapper::StereoConfig>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    labels: Option<crate::project::LabelsConfig>,
    log: LogConfig,
    build: BuildOptions,
}

impl Default for ConfigFile {
    fn default() -> Self {
        ConfigFile::of(&LogBuildConfig::default())
    }
}

impl ConfigFile {
    fn of(c: &LogBuildConfig) -> Self {
        let m = c.mapper.clone();
        ConfigFile {
            grid: m.grid,
            fusion: m.fusion,
            vehicle: m.vehicle,
            water: m.water,
            lidar: m.lidar,
            stereo: m.stereo,
            labels: m.labels,
            log: c.log.clone(),
            build: c.build.clone(),
        }
    }
}

impl LogBuildConfig {
    /// The log build of a mapper config with the default log settings and outputs.
    pub fn of_mapper(mapper: MapperConfig) -> Self {
        LogBuildConfig {
            mapper,
            ..Default::default()
        }
    }

    /// Reads a config file: TOML for a `.toml` file, JSON for any other extension. A
    /// section left out takes its defaults, but for a sensor's (`[lidar]`, `[stereo]`,
    /// `[labels]`), whose absence turns the sensor off. Errors name the file, and the key
    /// and line where parsing failed; then the config is validated.
    pub fn load(path: &Path) -> Result<Self> {
        let f: ConfigFile = crate::files::read_config(path)?;
        let cfg = LogBuildConfig {
            mapper: MapperConfig {
                grid: f.grid,
                fusion: f.fusion,
                vehicle: f.vehicle,
                water: f.water,
                lidar: f.lidar,
                stereo: f.stereo,
                labels: f.labels,
                label_models: None,
            },
            log: f.log,
            build: f.build,
            topics: NamedTopics::default(),
        };
        cfg.validate()
            .map_err(|e| Error::format(path, "config", e.to_string()))?;
        Ok(cfg)
    }

    /// The config as TOML text (what [`LogBuildConfig::load`] reads back).
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(&ConfigFile::of(self)).map_err(|e| Error::invalid("config", e.to_string()))
    }

    /// Rejects values no build can run with; the error names the field.
    pub fn validate(&self) -> Result<()> {
        self.mapper.validate()?;
        self.log
            .validate()
            .map_err(|e| Error::invalid("config log", e.to_string()))?;
        self.build
            .validate()
            .map_err(|e| Error::invalid("config", e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One file holds the mapper's sections, `[log]` and `[build]`; every section
    /// round-trips, an absent sensor section stays off, and a bad value is named.
    #[test]
    fn a_config_file_holds_the_mapper_the_log_and_the_outputs() {
        let dir = tempfile::tempdir().unwrap();
        let load = |name: &str, text: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            LogBuildConfig::load(&p)
        };
        let mut every = LogBuildConfig::of_mapper(MapperConfig::every_sensor());
        every.build.per_frame_maps = true;
        every.build.epsg = Some(32633);
        every.log.frame_topic = every.log.stereo_topic.clone();
        every.mapper.labels.as_mut().unwrap().stride = 3;
        assert_eq!(load("v.toml", &every.to_toml().unwrap()).unwrap(), every);
        let json = serde_json::to_string(&ConfigFile::of(&every)).unwrap();
        assert_eq!(load("v.json", &json).unwrap(), every);
        let bare = load("e.toml", "[build]\ntiles = true\n").unwrap();
        assert!(bare.build.tiles && bare.mapper.lidar.is_none());
        assert_eq!(bare.log, LogConfig::default());
        let err = load("b.toml", "[build]\nmax_window_cells = 3\n").unwrap_err();
        assert!(err.to_string().contains("build.max_window_cells"), "{err}");
        let err = load("u.toml", "[built]\n").unwrap_err();
        assert!(err.to_string().contains("line 1"), "{err}");
    }
}
