//! A log's cells before the water stage, and the water stage over them: the two halves of
//! a map-reduce over many logs.

use std::path::Path;

use crate::error::{Error, Result};
use crate::grid::TileMap;
use crate::hazard::HazardMap;
use crate::mapper::{Mapper, MapperConfig};

use super::*;

/// The cells of one log (or of the frames of one time range of it), before the water
/// stage: what [`build_tiles`] gives.
#[derive(Debug, Clone)]
pub struct TileBuild {
    /// Every cell the frames observed, with its elevation statistics and water evidence.
    pub tiles: TileMap,
    /// Frames fused into `tiles`.
    pub frames_fused: u64,
    /// Frames read from the log but outside the time range, not fused.
    pub frames_outside: u64,
    /// Frames that could not be read or fused, with why.
    pub errors: Vec<String>,
    /// The damaged parts of the log, skipped.
    pub damaged: Vec<crate::mcap_log::DamagedRange>,
    /// The lidar height the cue model used.
    pub lidar_height_m: Option<f64>,
}

/// The cells of a log as [`build_log`] fuses them, without the water stage and without
/// writing anything: [`finish_tiles`] of the result is the map `build_log` writes, cell for
/// cell. Tile maps of many logs merge exactly ([`TileMap::merge`]: integer sums, in any
/// order), so the map of many logs is a map-reduce: `build_tiles` per log, merge, finish.
///
/// `range_s = Some((t0, t1))` fuses only the frames stamped in `t0 <= t < t1` (log time,
/// seconds), with a mapper that starts empty at the first of them. That is **not** the
/// same as the part of a whole-log build those frames contributed: the cues of a frame
/// read the window the earlier frames left (the local ground, the below-surface gate, the
/// lidar height estimated from the first scans), so the merged time chunks of a log can
/// differ from its one-pass build where the first frames of a chunk looked
/// (`docs/distributed.md` has numbers). Chunk by log when the result must be exact.
///
/// A log none of whose frames (in the range) could be fused gives an empty tile map, not
/// an error; a file that is not a log is an error.
pub fn build_tiles(
    input: &Path,
    cfg: &LogBuildConfig,
    range_s: Option<(f64, f64)>,
) -> Result<TileBuild> {
    use crate::frames::FrameStream;
    if let Some((t0, t1)) = range_s {
        if t0.is_nan() || t1.is_nan() || t0 > t1 {
            return Err(Error::invalid(
                "time range",
                format!("{t0} s .. {t1} s is not a range"),
            ));
        }
    }
    let summary = crate::log::summarize_quick(input)?;
    let log_cfg = frame_log_config(cfg, &summary, input)?;
    let mut mapper = Mapper::new(sensors_of_log(&cfg.mapper, &log_cfg, &summary))?;
    mapper.set_publish(false);
    calibrate_on_log(&mut mapper, input, &log_cfg)?;
    let mut stream = FrameStream::open(input, &log_cfg)?;
    let (mut frames_fused, mut frames_outside) = (0u64, 0u64);
    let mut errors = Vec::new();
    for item in stream.by_ref() {
        crate::interrupt::check("reading the log")?;
        let frame = match item {
            Ok(f) => f,
            Err(e) => {
                errors.push(e.to_string());
                continue;
            }
        };
        if let Some((t0, t1)) = range_s {
            if !(frame.stamp >= t0 && frame.stamp < t1) {
                frames_outside += 1;
                continue;
            }
        }
        match mapper.update(&frame) {
            Ok(_) => frames_fused += 1,
            Err(e) => errors.push(format!("frame at {:.6} s: {e}", frame.stamp)),
        }
    }
    if let Some(e) = stream.fatal_error() {
        return Err(Error::format(
            input,
            format!("topic {}", log_cfg.frame_topic),
            format!("no map built: {e}"),
        ));
    }
    let damaged = stream.damaged().to_vec();
    let lidar_height_m = mapper.lidar_height();
    Ok(TileBuild {
        tiles: mapper.finish(),
        frames_fused,
        frames_outside,
        errors,
        damaged,
        lidar_height_m,
    })
}

/// The water stage over a (merged) tile map: water bodies, classes, hazards and depth
/// under `cfg`'s fusion, water and vehicle settings, as [`build_log`] runs it at the end of
/// a log. It runs on the whole map at once, so a water body that crosses tile borders, or
/// the areas of several logs, is found whole. [`finish_tiles_by_regions`] gives the same
/// map region by region.
pub fn finish_tiles(tiles: &TileMap, cfg: &MapperConfig) -> Result<HazardMap> {
    check_tiles(tiles, cfg)?;
    HazardMap::from_tiles(tiles, &cfg.hazard_config())
}

/// Refuses a tile map whose resolution or reference height is not the config's.
fn check_tiles(tiles: &TileMap, cfg: &MapperConfig) -> Result<()> {
    let expect = (cfg.grid.resolution, cfg.grid.z_ref);
    if (tiles.resolution(), tiles.z_ref()) != expect {
        return Err(Error::invalid(
            "tile map",
            format!(
                "resolution/z_ref {} m / {} m, the config says {} m / {} m",
                tiles.resolution(),
                tiles.z_ref(),
                expect.0,
                expect.1
            ),
        ));
    }
    Ok(())
}

/// [`finish_tiles`] region by region: regions of `side × side` tiles, each finished with a
/// halo of `halo` tiles, the tiles a region cannot decide finished again with larger halos
/// ([`crate::hazard::finish_by_regions`]). The same map, byte for byte.
pub fn finish_tiles_by_regions(
    tiles: &TileMap,
    cfg: &MapperConfig,
    side: i64,
    halo: i64,
) -> Result<(HazardMap, crate::hazard::SplitStats)> {
    check_tiles(tiles, cfg)?;
    crate::hazard::finish_by_regions(tiles, &cfg.hazard_config(), side, halo)
}

/// The water stage of one region of a merged map whose tile keys lie within `bounds`,
/// read with a halo of `halo` tiles ([`crate::hazard::finish_region`]).
pub fn finish_tile_region(
    tiles: &TileMap,
    region: &[crate::hazard::TileKey],
    halo: i64,
    bounds: (crate::hazard::TileKey, crate::hazard::TileKey),
    cfg: &MapperConfig,
) -> Result<crate::hazard::RegionMap> {
    check_tiles(tiles, cfg)?;
    crate::hazard::finish_region(tiles, region, halo, bounds, &cfg.hazard_config())
}
