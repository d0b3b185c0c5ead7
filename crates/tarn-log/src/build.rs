//! Offline map building from a point cloud in the map frame.
//!
//! A cloud that fits in one window is fused in one batch. A larger one is cut into blocks
//! of whole windows (aligned to cell boundaries, so every cell belongs to one block); the
//! rolling grid moves from block to block and hands finished cells to the global
//! [`TileMap`]. Because a cell never spans two blocks and its sums are exact, the result is
//! the same as fusing everything into one unbounded grid.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::frames::{LogConfig, NamedTopics};
use crate::geom::PointCloud;
use crate::grid::{
    in_map_domain, key_of, CellKey, GridConfig, IngestStats, RangeNoise, RollingGrid, TileMap,
};
use crate::hazard::HazardMap;
use crate::mapper::{Mapper, MapperConfig, StageTimes};
use tarn::io::export;

/// Parameters of an offline build.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildConfig {
    /// Grid resolution, reference height and layers; `size_cells` is replaced by the window the build chooses.
    pub grid: GridConfig,
    /// Noise of the cloud's points (a map-frame cloud has no sensor origin: constant).
    pub noise: RangeNoise,
    /// Largest window side for a cloud build, cells (2048² cells ≈ 235 MB of layers);
    /// larger clouds are cut into blocks of this size.
    pub max_window_cells: usize,
    /// `map.mcap` and `map.tif`, when asked for.
    #[serde(skip)]
    pub extra: ExtraMaps,
}

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            grid: GridConfig::default(),
            noise: RangeNoise::constant(0.02),
            max_window_cells: 2048,
            extra: ExtraMaps::default(),
        }
    }
}

/// The outputs beside the contract's files, each written only when asked for, from the
/// finished `map.ply` (so that every output holds the same values) into the same staged
/// set: a build replaces all of its outputs at once or none.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExtraMaps {
    /// `map.mcap`: the map as a `grid_map_msgs/GridMap` and a `nav_msgs/OccupancyGrid`
    /// ([`crate::ros_export`]), with these headers.
    pub ros_map: Option<crate::ros_export::RosMapOptions>,
    /// `map.tif`: the layers as a GeoTIFF ([`tarn::io::geotiff`]).
    pub geotiff: Option<tarn::io::geotiff::GeoTiffOptions>,
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
                .then_some(tarn::io::geotiff::GeoTiffOptions { epsg: b.epsg }),
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
        let map = tarn::io::mapfile::read_map_ply(&dir.join("map.ply"))?;
        if let Some(o) = &self.ros_map {
            crate::ros_export::write_ros_map(&dir.join("map.mcap"), &map, o)?;
            written.push("map.mcap".to_string());
        }
        if let Some(o) = &self.geotiff {
            tarn::io::geotiff::write_geotiff(&dir.join("map.tif"), &map, o)?;
            written.push("map.tif".to_string());
        }
        Ok(written)
    }
}

/// What a cloud build produced.
#[derive(Debug, Clone)]
pub struct CloudBuild {
    /// The fused map, all of it.
    pub tiles: TileMap,
    /// What happened to the cloud's points.
    pub ingest: IngestStats,
    /// Windows the cloud was cut into.
    pub blocks: usize,
    /// Side of the window used, cells.
    pub window_cells: usize,
}

/// Key bounds of the finite points of a cloud within the map's domain
/// ([`MAX_MAP_COORD_M`](crate::grid::MAX_MAP_COORD_M)), and how many finite points lie beyond it.
fn key_bounds(cloud: &PointCloud, res: f64) -> (Option<(CellKey, CellKey)>, u64) {
    (0..cloud.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter(|&i| cloud.is_valid(i))
        .map(|i| {
            let p = cloud.point_in_map(i);
            if in_map_domain(p.x, p.y) {
                let k = key_of(res, p.x, p.y);
                (Some((k, k)), 0)
            } else {
                (None, 1)
            }
        })
        .reduce(
            || (None, 0),
            |(a, na), (b, nb)| {
                let k = match (a, b) {
                    (Some((a0, a1)), Some((b0, b1))) => Some((
                        CellKey::new(a0.x.min(b0.x), a0.y.min(b0.y)),
                        CellKey::new(a1.x.max(b1.x), a1.y.max(b1.y)),
                    )),
                    (a, b) => a.or(b),
                };
                (k, na + nb)
            },
        )
}

/// Smallest window side a block is split down to, cells.
const MIN_LEAF_CELLS: usize = 16;

/// A window of `s²` cells is fused as one piece only when it holds at least
/// `s² / LEAF_CELLS_PER_POINT` points; emptier ones are split in four (down to
/// [`MIN_LEAF_CELLS`]), so that the cost of moving and flushing windows stays proportional
/// to the points, however scattered they are.
const LEAF_CELLS_PER_POINT: usize = 64;

/// Fuses whole windows of a cloud, one at a time, into a tile map. A window whose cells
/// the points fill too sparsely is split into quadrants; windows of each side are reused.
struct LeafFuser<'a> {
    cloud: &'a PointCloud,
    res: f64,
    template: GridConfig,
    noise: RangeNoise,
    /// Grids by side (powers of two times [`MIN_LEAF_CELLS`], or the block side).
    grids: Vec<RollingGrid>,
    sub: PointCloud,
    scratch: Vec<u32>,
    stats: IngestStats,
}

impl LeafFuser<'_> {
    fn key(&self, i: u32) -> CellKey {
        let p = self.cloud.point_in_map(i as usize);
        key_of(self.res, p.x, p.y)
    }

    /// Fuses the points `idx` (all inside the window of side `size` at `origin`).
    fn fuse(
        &mut self,
        idx: &mut [u32],
        origin: CellKey,
        size: usize,
        tiles: &mut TileMap,
    ) -> Result<()> {
        if size > MIN_LEAF_CELLS && size * size > LEAF_CELLS_PER_POINT * idx.len() {
            // Four quadrants (the first half rounded up), the points partitioned among
            // them with a counting sort.
            let h = size.div_ceil(2);
            let h64 = h as i64;
            let quadrant = |k: CellKey| {
                (((k.x - origin.x) >= h64) as usize) + 2 * (((k.y - origin.y) >= h64) as usize)
            };
            let mut counts = [0usize; 5];
            for &i in idx.iter() {
                counts[quadrant(self.key(i)) + 1] += 1;
            }
            for q in 0..4 {
                counts[q + 1] += counts[q];
            }
            let mut fill = counts;
            self.scratch.clear();
            self.scratch.resize(idx.len(), 0);
            for &i in idx.iter() {
                let q = quadrant(self.key(i));
                self.scratch[fill[q]] = i;
                fill[q] += 1;
            }
            idx.copy_from_slice(&self.scratch);
            for q in 0..4 {
                let part = &mut idx[counts[q]..counts[q + 1]];
                if part.is_empty() {
                    continue;
                }
                let o = CellKey::new(
                    origin.x + (q % 2) as i64 * h64,
                    origin.y + (q / 2) as i64 * h64,
                );
                self.fuse(part, o, h, tiles)?;
            }
            return Ok(());
        }
        let at = match self.grids.iter().position(|g| g.size() == size) {
            Some(at) => at,
            None => {
                let cfg = GridConfig {
                    size_cells: size,
                    ..self.template.clone()
                };
                self.grids.push(RollingGrid::new(cfg, 0.0, 0.0)?);
                self.grids.len() - 1
            }
        };
        self.sub.xyz.clear();
        self.sub
            .xyz
            .extend(idx.iter().map(|&i| self.cloud.xyz[i as usize]));
        self.sub.cols = self.sub.xyz.len();
        let grid = &mut self.grids[at];
        grid.move_origin(origin, tiles);
        let st = grid.ingest(&self.sub, &self.noise)?;
        grid.flush(tiles);
        self.stats.merge(&st);
        Ok(())
    }
}

/// Fuses a whole cloud into a global tile map. `progress(done, total)` is called with
/// point counts as blocks finish.
///
/// Time and memory follow the number of points, never the coordinates: points beyond
/// [`MAX_MAP_COORD_M`](crate::grid::MAX_MAP_COORD_M) are counted as outside; blocks are numbered densely only when
/// there are not many more of them than points, else only the occupied ones are; and a
/// block is fused in windows no larger than its points fill.
pub fn build_cloud(
    cloud: &PointCloud,
    cfg: &BuildConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CloudBuild> {
    cfg.grid.validate()?;
    cfg.noise.validate()?;
    cloud.validate()?;
    if cloud.len() >= u32::MAX as usize {
        return Err(Error::invalid(
            "cloud",
            format!(
                "{} points (at most {} per build)",
                cloud.len(),
                u32::MAX - 1
            ),
        ));
    }
    let res = cfg.grid.resolution;
    let total = cloud.len() as u64;
    let (bounds, beyond) = key_bounds(cloud, res);
    let Some((lo, hi)) = bounds else {
        // Nothing finite within the map: an empty map, every point counted.
        let tiles = TileMap::new(res, cfg.grid.z_ref)?;
        progress(total, total);
        return Ok(CloudBuild {
            tiles,
            ingest: IngestStats {
                points: total,
                nonfinite: total - beyond,
                outside: beyond,
                ..Default::default()
            },
            blocks: 0,
            window_cells: 0,
        });
    };
    // Keys lie within ±2³⁵ (the domain at the finest resolution): no overflow below.
    let extent = (hi.x - lo.x).max(hi.y - lo.y) as u64 + 1;
    let max_n = cfg.max_window_cells.clamp(MIN_LEAF_CELLS, 32768);
    let n = if extent <= max_n as u64 {
        (extent as usize)
            .next_power_of_two()
            .clamp(MIN_LEAF_CELLS, max_n)
    } else {
        max_n
    };
    let gcfg = GridConfig {
        size_cells: n,
        ..cfg.grid.clone()
    };
    let n64 = n as i64;
    let valid = cloud.valid_count() as u64;

    if extent <= n as u64 && n * n <= LEAF_CELLS_PER_POINT * valid as usize {
        // One window the points fill: fused in one batch.
        let mut grid = RollingGrid::new(gcfg, 0.0, 0.0)?;
        let mut tiles = TileMap::for_grid(&grid);
        grid.move_origin(lo, &mut tiles);
        let stats = grid.ingest(cloud, &cfg.noise)?;
        grid.flush(&mut tiles);
        progress(total, total);
        return Ok(CloudBuild {
            tiles,
            ingest: stats,
            blocks: 1,
            window_cells: n,
        });
    }

    // Blocks of whole windows, aligned at multiples of n cells from `lo`.
    let block_of = |i: usize| -> Option<(i64, i64)> {
        if !cloud.is_valid(i) {
            return None;
        }
        let p = cloud.point_in_map(i);
        if !in_map_domain(p.x, p.y) {
            return None;
        }
        let k = key_of(res, p.x, p.y);
        Some(((k.x - lo.x).div_euclid(n64), (k.y - lo.y).div_euclid(n64)))
    };
    let bw = (hi.x - lo.x).div_euclid(n64) + 1;
    let bh = (hi.y - lo.y).div_euclid(n64) + 1;
    let dense_limit = (valid as usize).max(1 << 16) as i64;
    // Block ids (u32::MAX: no block) and each id's block coordinates.
    let (ids, block_xy): (Vec<u32>, Vec<(i64, i64)>) = match bw.checked_mul(bh) {
        Some(nb) if nb <= dense_limit => {
            let ids = (0..cloud.len())
                .into_par_iter()
                .with_min_len(4096)
                .map(|i| block_of(i).map_or(u32::MAX, |(bx, by)| (by * bw + bx) as u32))
                .collect();
            (ids, (0..nb).map(|b| (b % bw, b / bw)).collect())
        }
        _ => {
            // Scattered: number only the occupied blocks, in row-major order.
            let mut occupied: Vec<(i64, i64)> = (0..cloud.len())
                .into_par_iter()
                .with_min_len(4096)
                .filter_map(|i| block_of(i).map(|(bx, by)| (by, bx)))
                .collect();
            occupied.par_sort_unstable();
            occupied.dedup();
            let number: std::collections::HashMap<(i64, i64), u32> = occupied
                .iter()
                .enumerate()
                .map(|(b, &(by, bx))| ((bx, by), b as u32))
                .collect();
            let ids = (0..cloud.len())
                .into_par_iter()
                .with_min_len(4096)
                .map(|i| block_of(i).map_or(u32::MAX, |b| number[&b]))
                .collect();
            (ids, occupied.into_iter().map(|(by, bx)| (bx, by)).collect())
        }
    };
    let nblocks = block_xy.len();
    // Counting sort of point indices by block.
    let mut start = vec![0usize; nblocks + 1];
    for &b in &ids {
        if b != u32::MAX {
            start[b as usize + 1] += 1;
        }
    }
    for b in 0..nblocks {
        start[b + 1] += start[b];
    }
    let mut order = vec![0u32; start[nblocks]];
    let mut fill = start.clone();
    for (i, &b) in ids.iter().enumerate() {
        if b != u32::MAX {
            order[fill[b as usize]] = i as u32;
            fill[b as usize] += 1;
        }
    }
    drop(ids);
    drop(fill);
    let mut stats = IngestStats::default();
    let skipped = total - order.len() as u64;
    stats.points += skipped;
    stats.nonfinite += skipped - beyond;
    stats.outside += beyond;
    let mut done = skipped;
    let mut blocks = 0;
    let mut sub = PointCloud::unorganized(Vec::new());
    sub.frame_to_map = cloud.frame_to_map;
    sub.sensor_origin = cloud.sensor_origin;
    sub.stamp = cloud.stamp;
    let mut tiles = TileMap::new(res, cfg.grid.z_ref)?;
    let mut fuser = LeafFuser {
        cloud,
        res,
        template: gcfg,
        noise: cfg.noise,
        grids: Vec::new(),
        sub,
        scratch: Vec::new(),
        stats: IngestStats::default(),
    };
    for (b, &(bx, by)) in block_xy.iter().enumerate() {
        let idx = &mut order[start[b]..start[b + 1]];
        if idx.is_empty() {
            continue;
        }
        crate::interrupt::check("fusing the cloud")?;
        blocks += 1;
        let len = idx.len() as u64;
        fuser.fuse(
            idx,
            CellKey::new(lo.x + bx * n64, lo.y + by * n64),
            n,
            &mut tiles,
        )?;
        done += len;
        progress(done, total);
    }
    stats.merge(&fuser.stats);
    Ok(CloudBuild {
        tiles,
        ingest: stats,
        blocks,
        window_cells: n,
    })
}

/// `report.json` of a build.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BuildReport {
    /// Version of tarn that wrote the report.
    pub tarn_version: String,
    /// The cloud read.
    pub input: PathBuf,
    /// The output directory.
    pub output: PathBuf,
    /// Cell side, metres.
    pub resolution_m: f64,
    /// Side of the window used, cells.
    pub window_cells: usize,
    /// Windows the cloud was cut into.
    pub blocks: usize,
    /// Observed cells of the map.
    pub cells_observed: usize,
    /// Tiles of the global map.
    pub tiles: usize,
    /// Bytes of rolling-grid storage per cell (all layers).
    pub bytes_per_cell_window: usize,
    /// Bytes held by the global map's cell storage.
    pub bytes_cells_global: usize,
    /// What happened to the cloud's points.
    pub points: IngestStats,
    /// Lowest and highest cell elevation, map z in metres; `None` for an empty map.
    pub elevation_range_m: Option<(f64, f64)>,
    /// Map-frame extent of the observed cells: [xmin, ymin, xmax, ymax] (cell edges).
    pub extent_m: Option<[f64; 4]>,
    /// The outputs written beside the contract's files (`map.mcap`, `map.tif`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub extra_outputs: Vec<String>,
    /// What the build noticed but could go on past.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Wall time of each step, seconds.
    pub timings_s: Timings,
}

/// Wall time of the steps of a build, seconds.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Timings {
    /// Reading the input (a log build: reading and decoding, fusion excluded).
    pub read: f64,
    /// Fusing points into the grid (a log build: the mapper's updates).
    pub fuse: f64,
    /// Making the hazard map and writing the output files.
    pub export: f64,
    /// The whole build.
    pub total: f64,
}

/// Reads a `.ply` or `.bin` cloud, builds its map and writes the contract files into `out`.
pub fn build_file(
    input: &Path,
    out: &Path,
    cfg: &BuildConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BuildReport> {
    let t0 = Instant::now();
    cfg.grid.validate()?;
    let cloud = crate::log::read_cloud(input)?;
    crate::interrupt::check("reading the cloud")?;
    if cloud.valid_count() == 0 {
        // Nothing to map: refuse rather than replace a previous map with an empty one.
        return Err(Error::format(
            input,
            "points",
            format!(
                "no finite point among the {} points (all NaN, infinite or missing returns)",
                cloud.len()
            ),
        ));
    }
    let t_read = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let built = build_cloud(&cloud, cfg, progress)?;
    drop(cloud);
    if built.tiles.observed_count() == 0 {
        let st = built.ingest;
        return Err(Error::format(
            input,
            "points",
            format!(
                "nothing built: none of the {} points lies within the map's domain \
                 (|x|, |y| ≤ {:e} m): {} beyond it, {} not finite",
                st.points,
                crate::grid::MAX_MAP_COORD_M,
                st.outside,
                st.nonfinite
            ),
        ));
    }
    let t_fuse = t1.elapsed().as_secs_f64();
    crate::interrupt::check("fusing the cloud")?;
    let t2 = Instant::now();
    let map = HazardMap::from_elevation(&built.tiles);
    let stage = export::Staging::new(out)?;
    export::write_map_files(stage.path(), &map)?;
    let extra_outputs = cfg.extra.write(stage.path(), &built.tiles)?;
    let t_export = t2.elapsed().as_secs_f64();
    let res = built.tiles.resolution();
    let report = BuildReport {
        tarn_version: env!("CARGO_PKG_VERSION").to_string(),
        input: input.to_path_buf(),
        output: out.to_path_buf(),
        resolution_m: res,
        window_cells: built.window_cells,
        blocks: built.blocks,
        cells_observed: map.cells.len(),
        tiles: built.tiles.tile_count(),
        bytes_per_cell_window: RollingGrid::bytes_per_cell(),
        bytes_cells_global: built.tiles.cell_bytes(),
        points: built.ingest,
        elevation_range_m: export::elevation_range(&map.cells),
        extent_m: map.key_bounds().map(|(lo, hi)| {
            [
                lo.x as f64 * res,
                lo.y as f64 * res,
                (hi.x + 1) as f64 * res,
                (hi.y + 1) as f64 * res,
            ]
        }),
        extra_outputs,
        warnings: swept_warnings(&stage),
        timings_s: Timings {
            read: t_read,
            fuse: t_fuse,
            export: t_export,
            total: t0.elapsed().as_secs_f64(),
        },
    };
    crate::files::write_json(&stage.path().join("report.json"), &report)?;
    crate::interrupt::check("writing the outputs")?;
    stage.commit()?;
    Ok(report)
}

/// One warning per staging folder of an earlier, killed build that `stage` removed.
fn swept_warnings(stage: &export::Staging) -> Vec<String> {
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

    #[test]
    fn a_warning_repeated_in_every_frame_is_one_line() {
        let mut w = FrameWarnings::default();
        for (i, t) in [100.0, 100.2, 100.4].iter().enumerate() {
            w.add(*t, &format!("{} stereo points beyond stereo.max_range_m = 132 m dropped (farthest 1.7{i}e2 m)", 150 + i));
        }
        w.add(
            100.4,
            "lidar cues cannot run: the scan is unorganized (5 points in one row)",
        );
        let lines: Vec<String> = w.lines().collect();
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert_eq!(
            lines[0],
            "3 frames from 100.000000 s to 100.400000 s, the first: 150 stereo points beyond \
             stereo.max_range_m = 132 m dropped (farthest 1.70e2 m)"
        );
        assert!(lines[1].starts_with("frame at 100.400000 s: lidar cues"));
    }

    /// Compiled label models given without a `[labels]` section (a library user's) label
    /// the log's cameras; only the sensors the log lacks are dropped.
    #[test]
    fn compiled_label_models_alone_keep_the_cameras_the_log_has() {
        use crate::mcap_log::LogSummary;
        use tarn::classify::{color::RuleClassifier, lut::ColorLut};
        let log = LogConfig::default();
        let summary = |topics: &[&str]| {
            LogSummary::of(
                topics
                    .iter()
                    .map(|t| (t.to_string(), ("schema".to_string(), 3)))
                    .collect(),
                Some(0),
                Some(1),
                Vec::new(),
            )
        };
        let cfg = MapperConfig {
            labels: None,
            label_models: Some(crate::project::FrameLabelConfig {
                colour: Some(ColorLut::compile(&RuleClassifier::default(), 5).unwrap()),
                ..Default::default()
            }),
            ..MapperConfig::default()
        };
        let with = sensors_of_log(&cfg, &log, &summary(&[&log.image_topic]));
        assert!(with.label_models.is_some_and(|m| m.colour.is_some()));
        let without = sensors_of_log(&cfg, &log, &summary(&[&log.lidar_topic]));
        assert!(without.label_models.is_none());
    }

    fn ramp(n: usize, side: f64) -> PointCloud {
        let mut pts = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let x = (i as f64 + 0.5) / n as f64 * side;
                let y = (j as f64 + 0.5) / n as f64 * side;
                pts.push([x as f32, y as f32, (0.1 * x) as f32]);
            }
        }
        PointCloud::unorganized(pts)
    }

    #[test]
    fn blocked_build_equals_single_window_build() {
        let cloud = ramp(600, 60.0);
        let one = build_cloud(&cloud, &BuildConfig::default(), &mut |_, _| {}).unwrap();
        assert_eq!(one.blocks, 1);
        // Windows of 100 cells: 6 × 6 blocks, the same cells with the same sums.
        let small = BuildConfig {
            max_window_cells: 100,
            ..BuildConfig::default()
        };
        let mut calls = 0;
        let a = build_cloud(&cloud, &small, &mut |_, _| calls += 1).unwrap();
        assert_eq!(a.blocks, 36);
        assert_eq!(calls, 36);
        assert!(a.tiles == one.tiles);
        assert_eq!(a.ingest, one.ingest);
        assert_eq!(a.ingest.fused, cloud.len() as u64);
    }

    #[test]
    fn absurd_coordinates_cost_nothing_and_are_counted() {
        // A small patch, then single points far away: finite but absurd, or beyond any map.
        let mut cloud = ramp(20, 2.0);
        let far = [1e6f32, -1e7, 9.9e7, 1e12, 1e20, -1e30, 3e38, f32::INFINITY];
        for &v in &far {
            cloud.xyz.push([v, 0.5, 0.0]);
            cloud.xyz.push([0.5, v, 0.0]);
            cloud.xyz.push([v, -v, 1.0]);
        }
        cloud.cols = cloud.xyz.len();
        let t = std::time::Instant::now();
        let b = build_cloud(&cloud, &BuildConfig::default(), &mut |_, _| {}).unwrap();
        assert!(t.elapsed().as_secs_f64() < 10.0, "{:?}", t.elapsed());
        let st = b.ingest;
        assert_eq!(st.points, cloud.len() as u64);
        // Within ±1e8 m: fused (3 values × 3 points); beyond: outside; inf: non-finite.
        assert_eq!(st.fused, 400 + 9, "{st:?}");
        assert_eq!(st.nonfinite, 3, "{st:?}");
        assert_eq!(st.outside, 12, "{st:?}");
        assert_eq!(b.tiles.observed_count(), 400 + 9);
        // Scattered cells keep their tiles sparse.
        assert!(
            b.tiles.cell_bytes() < 4 << 20,
            "{} bytes",
            b.tiles.cell_bytes()
        );
        // The picture of scattered cells stays bounded too.
        {
            let map = HazardMap::from_elevation(&b.tiles);
            let img = tarn::io::render::render_map_png(&map, &[]);
            assert!(img.width() <= 4096 && img.height() <= 4096 + 200);
        }
    }

    #[test]
    fn a_scattered_cloud_costs_per_point() {
        // 20,000 points, each in its own block, over ±5,000 km: the blocks are numbered
        // sparsely and each is fused in the smallest window.
        let mut state = 1u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1e7
        };
        let pts: Vec<[f32; 3]> = (0..20_000)
            .map(|_| [rnd() as f32, rnd() as f32, 0.0])
            .collect();
        let cloud = PointCloud::unorganized(pts);
        let t = std::time::Instant::now();
        let b = build_cloud(&cloud, &BuildConfig::default(), &mut |_, _| {}).unwrap();
        assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
        assert_eq!(b.ingest.fused, 20_000);
        assert_eq!(b.blocks, 20_000);
        assert!(
            b.tiles.cell_bytes() < 20_000 * 1024,
            "{}",
            b.tiles.cell_bytes()
        );
    }

    #[test]
    fn a_sparse_block_is_split_with_the_same_result() {
        // Two dense patches 150 m apart: one 2048² window, split into quadrants; the cells
        // are those of windows that fit each patch.
        let mut a = ramp(100, 10.0);
        let b = ramp(100, 10.0);
        a.xyz
            .extend(b.xyz.iter().map(|p| [p[0] + 150.0, p[1] + 120.0, p[2]]));
        a.cols = a.xyz.len();
        let split = build_cloud(&a, &BuildConfig::default(), &mut |_, _| {}).unwrap();
        let small = BuildConfig {
            max_window_cells: 100,
            ..BuildConfig::default()
        };
        let blocks = build_cloud(&a, &small, &mut |_, _| {}).unwrap();
        assert!(split.tiles == blocks.tiles);
        assert_eq!(split.ingest, blocks.ingest);
        assert_eq!(split.ingest.fused, 20_000);
    }

    #[test]
    fn all_nan_cloud_builds_an_empty_map() {
        let cloud = PointCloud::unorganized(vec![[f32::NAN; 3]; 10]);
        let b = build_cloud(&cloud, &BuildConfig::default(), &mut |_, _| {}).unwrap();
        assert_eq!(b.tiles.observed_count(), 0);
        assert_eq!(b.ingest.nonfinite, 10);
    }
}

/// `report.json` of a build from a ROS 2 log.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LogBuildReport {
    /// Version of tarn that wrote the report.
    pub tarn_version: String,
    /// The log read.
    pub input: PathBuf,
    /// The output directory.
    pub output: PathBuf,
    /// Cell side, metres.
    pub resolution_m: f64,
    /// Side of the rolling window, cells.
    pub window_cells: usize,
    /// Topic whose messages made frames.
    pub frame_topic: String,
    /// Frames fused into the map.
    pub frames_fused: u64,
    /// Log duration, seconds.
    pub log_duration_s: f64,
    /// Log duration over build time (offline speed).
    pub x_realtime: f64,
    /// Whether the window's hazard map was published after every frame
    /// ([`LogBuildConfig::per_frame_maps`]); the `water` stage's latency is zero otherwise.
    #[serde(default)]
    pub per_frame_maps: bool,
    /// The cues that ran (`lidar`, `reflectivity`, `stereo`, `mirror`).
    pub cues: Vec<String>,
    /// The lidar height the cue model used (given, or estimated from the first scans).
    pub lidar_height_m: Option<f64>,
    /// The lidar cues' no-return diagnostic interval (lookahead, m).
    pub diagnostic_interval_m: Option<(f64, f64)>,
    /// Every sensor value the mapper used, its source (log, config or rig file, measured,
    /// default), the measurement beside any stated value, the cues that waited for a value
    /// and the stated values the log contradicts ([`crate::calib`]).
    #[serde(default)]
    pub calibration: crate::calib::CalibrationReport,
    /// What happened to the lidar points, summed over frames.
    pub lidar_points: IngestStats,
    /// What happened to the stereo points, summed over frames.
    pub stereo_points: IngestStats,
    /// What the cues found, summed over frames.
    pub cue_counts: CueCounts,
    /// What the frame stream read, built and skipped.
    pub frames: crate::frames::FrameStats,
    /// Messages or frames that could not be used, with where and why.
    pub errors: Vec<String>,
    /// What the build noticed but went on past: what the plausibility checks dropped from
    /// frames that were fused, one line per kind with the frames it happened in (the
    /// first [`MAX_WARNINGS`] kinds), then the build's own.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Lidar and stereo points beyond their sensor's `max_range_m`, dropped.
    #[serde(default)]
    pub points_beyond_max_range: BeyondRange,
    /// The damaged parts of the log, skipped: exact byte ranges, what was wrong, and the
    /// log times they held. Empty for an undamaged log; a map built from a damaged log
    /// holds everything else.
    #[serde(default)]
    pub damaged: Vec<crate::mcap_log::DamagedRange>,
    /// What the image labels contributed (`None`: not configured).
    #[serde(default)]
    pub labels: Option<crate::project::FrameLabelsReport>,
    /// Observed cells of the map.
    pub cells_observed: usize,
    /// Tiles of the global map.
    pub tiles: usize,
    /// Lowest and highest cell elevation, map z in metres; `None` for an empty map.
    pub elevation_range_m: Option<(f64, f64)>,
    /// What the map holds: water cells, area, depths, hazards.
    pub water: WaterSummary,
    /// The outputs written beside the contract's files (`map.mcap`, `map.tif`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub extra_outputs: Vec<String>,
    /// Wall time of each step, seconds.
    pub timings_s: Timings,
    /// Sum over frames of each stage of [`crate::mapper::Mapper::update`] (s).
    pub stage_totals_s: StageTimes,
    /// Per-frame latency of each stage (ms).
    pub stage_latency_ms: Vec<StageLatency>,
}

/// Warnings kept in a log build's report.
pub const MAX_WARNINGS: usize = 100;

/// Points dropped as beyond their sensor's maximum range.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BeyondRange {
    /// Lidar points dropped.
    pub lidar: u64,
    /// Stereo points dropped.
    pub stereo: u64,
}

/// Cue events summed over a build.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CueCounts {
    /// Missing lidar beams meeting the ground inside the diagnostic interval.
    pub lidar_noret: u64,
    /// Nearest and farthest lookahead of the no-return beams' ground hits (mm).
    pub lidar_noret_lookahead_mm: Option<[u64; 2]>,
    /// Lidar ground returns inside the diagnostic interval.
    pub lidar_diag_ret: u64,
    /// Lidar returns from under the water surface (bottom returns, their depth kept as evidence).
    pub lidar_bottom: u64,
    /// Lidar returns mirrored by the water surface: reflection evidence, left out of the terrain.
    pub lidar_specular: u64,
    /// Lidar returns below the walked level that the scan saw nothing above: ground below
    /// the level (a depression's far bank), kept in the terrain.
    #[serde(default)]
    pub lidar_below_ground: u64,
    /// Lidar ground returns darker than the scan's dark threshold (reflectivity cue).
    pub lidar_dark: u64,
    /// Stereo reflection runs confirmed.
    pub stereo_runs: u64,
    /// Stereo points found to be reflections.
    pub stereo_reflected_points: u64,
    /// Evidence cells merged into the window.
    pub evidence_cells: u64,
    /// Evidence cells dropped outside the window.
    pub evidence_dropped: u64,
}

impl CueCounts {
    fn add(&mut self, r: &crate::cues::FrameCuesReport) {
        if let Some(l) = &r.lidar {
            self.lidar_noret += l.noret;
            if let Some([lo, hi]) = l.noret_lookahead_mm {
                let [a, b] = self.lidar_noret_lookahead_mm.unwrap_or([lo, hi]);
                self.lidar_noret_lookahead_mm = Some([a.min(lo), b.max(hi)]);
            }
            self.lidar_diag_ret += l.diag_ret;
            self.lidar_bottom += l.bottom;
            self.lidar_specular += l.specular;
            self.lidar_below_ground += l.below_ground;
            self.lidar_dark += l.dark;
        }
        self.stereo_runs += r.stereo_runs as u64;
        self.stereo_reflected_points += r.stereo_reflected_points as u64;
        self.evidence_cells += r.evidence_cells as u64;
        self.evidence_dropped += r.evidence_dropped as u64;
    }
}

/// Cells per hazard code of `map.ply` (0 to 3).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct HazardCells {
    /// Free to drive (0).
    pub free: usize,
    /// Shallow water within fording depth (1).
    pub shallow_water: usize,
    /// Deep or unknown-depth water (2).
    pub deep_water: usize,
    /// A geometric obstacle (3).
    pub obstacle: usize,
}

/// The water in a hazard map.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WaterSummary {
    /// Cells classified water.
    pub water_cells: usize,
    /// Area of the water cells, square metres.
    pub water_area_m2: f64,
    /// Water cells with a measured depth, and their depths.
    pub depth_cells: usize,
    /// Mean depth of those cells, metres; `None` when no depth was measured.
    pub depth_mean_m: Option<f64>,
    /// Greatest depth of those cells, metres; `None` when no depth was measured.
    pub depth_max_m: Option<f64>,
    /// Cells per hazard code.
    pub hazard_cells: HazardCells,
    /// Cells with any water evidence (probability above the prior).
    pub cells_with_evidence: usize,
    /// The water bodies ([`crate::water::WaterBody::report`]): area, volume, depth, the
    /// surface model and the residuals that chose it.
    #[serde(default)]
    pub bodies: serde_json::Value,
}

impl WaterSummary {
    /// Summarises `map`; `fusion` gives the prior above which a cell counts as having evidence.
    pub fn of(map: &HazardMap, fusion: &crate::grid::Fusion) -> Self {
        use crate::hazard::Class;
        let mut s = WaterSummary {
            bodies: map.water_report(),
            ..Default::default()
        };
        let mut depths = Vec::new();
        for c in &map.cells {
            let h = &mut s.hazard_cells;
            *match c.hazard {
                crate::hazard::Hazard::Free => &mut h.free,
                crate::hazard::Hazard::ShallowWater => &mut h.shallow_water,
                crate::hazard::Hazard::DeepWater => &mut h.deep_water,
                crate::hazard::Hazard::Obstacle => &mut h.obstacle,
            } += 1;
            if c.water as f64 > fusion.prior + 1e-6 {
                s.cells_with_evidence += 1;
            }
            if c.class == Class::Water {
                s.water_cells += 1;
                if c.depth.is_finite() {
                    depths.push(c.depth as f64);
                }
            }
        }
        s.water_area_m2 = s.water_cells as f64 * map.resolution * map.resolution;
        s.depth_cells = depths.len();
        if !depths.is_empty() {
            s.depth_mean_m = Some(depths.iter().sum::<f64>() / depths.len() as f64);
            s.depth_max_m = depths.iter().copied().reduce(f64::max);
        }
        s
    }
}

/// Median, 95th percentile and maximum of one stage's per-frame time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageLatency {
    /// Stage name, one of [`StageTimes::NAMES`].
    pub stage: String,
    /// Median per-frame time, milliseconds.
    pub median_ms: f64,
    /// 95th percentile (nearest rank), milliseconds.
    pub p95_ms: f64,
    /// Largest per-frame time, milliseconds.
    pub max_ms: f64,
}

/// Latency statistics per stage of a sequence of per-frame stage times (nearest-rank
/// percentiles).
pub fn stage_latency(times: &[StageTimes]) -> Vec<StageLatency> {
    StageTimes::NAMES
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let mut v: Vec<f64> = times.iter().map(|t| t.values()[k] * 1e3).collect();
            v.sort_by(f64::total_cmp);
            let rank = |q: f64| {
                if v.is_empty() {
                    0.0
                } else {
                    v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
                }
            };
            StageLatency {
                stage: name.to_string(),
                median_ms: rank(0.5),
                p95_ms: rank(0.95),
                max_ms: v.last().copied().unwrap_or(0.0),
            }
        })
        .collect()
}

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
    /// Also write `map.tif`: the map's layers as a GeoTIFF ([`tarn::io::geotiff`]).
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
    vehicle: crate::water::Vehicle,
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

/// Builds the map of a robot log (any storage [`crate::log::open`] reads) through the online [`Mapper`] (one code path for online
/// and offline): each frame is fused at its pose into a rolling window centred on the
/// vehicle, with the configured cues; cells that leave it go to the global tile map. At the
/// end the hazard map of everything is exported. `progress(bytes_read, bytes_total)`.
///
/// A damaged or truncated log gives the map of everything that could be read: damaged
/// chunks and records are skipped and listed in [`LogBuildReport::damaged`]. A file that
/// is not a log, or cannot be read, is an error.
pub fn build_log(
    input: &Path,
    out: &Path,
    cfg: &LogBuildConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<LogBuildReport> {
    use crate::frames::FrameStream;

    let t0 = Instant::now();
    let summary = crate::log::summarize_quick(input)?;
    let log_cfg = frame_log_config(cfg, &summary, input)?;
    let mut mapper = Mapper::new(sensors_of_log(&cfg.mapper, &log_cfg, &summary))?;
    mapper.set_publish(cfg.build.per_frame_maps);
    calibrate_on_log(&mut mapper, input, &log_cfg)?;
    let mut stream = FrameStream::open(input, &log_cfg)?;
    let (mut lidar, mut stereo) = (IngestStats::default(), IngestStats::default());
    let mut counts = CueCounts::default();
    let mut errors = Vec::new();
    let mut warnings = Vec::new();
    let mut frame_warnings = FrameWarnings::default();
    let mut beyond = BeyondRange::default();
    let mut frames_fused = 0u64;
    let mut t_fuse = 0.0;
    let mut stage_totals = StageTimes::default();
    let mut per_frame = Vec::new();
    let mut label_totals: Option<crate::project::FrameLabelsReport> = None;
    let mut vehicle_path: Vec<[f64; 2]> = Vec::new();
    let path_step = cfg.mapper.grid.resolution;
    // Frames are read and decoded on a second thread while this one fuses the previous
    // frame: the order, and so the map, is the log's. A bounded queue keeps at most two
    // decoded frames waiting.
    let (tx, rx) = std::sync::mpsc::sync_channel(2);
    // What the reader leaves: its counts, the damaged parts of the log, and the error that
    // ended reading early if one did.
    type ReadEnd = (
        crate::frames::FrameStats,
        Vec<crate::mcap_log::DamagedRange>,
        Option<String>,
    );
    let (stream_stats, damaged, fatal) = std::thread::scope(|scope| -> Result<ReadEnd> {
        // Owned here, so that an early return drops it and the reader's next send fails.
        let rx = rx;
        let reader = scope.spawn(move || {
            while let Some(item) = stream.next() {
                // The fusing side stopped (an interrupt): stop reading.
                if tx.send((item, stream.progress())).is_err() {
                    break;
                }
            }
            (
                stream.stats().clone(),
                stream.damaged().to_vec(),
                stream.fatal_error().map(str::to_string),
            )
        });
        for (item, (done, total)) in rx.iter() {
            crate::interrupt::check("reading the log")?;
            progress(done, total);
            let frame = match item {
                Ok(f) => f,
                Err(e) => {
                    errors.push(e.to_string());
                    continue;
                }
            };
            let t = Instant::now();
            match mapper.update(&frame) {
                Ok(r) => {
                    // The vehicle's path for map.png: a point per cell travelled.
                    let at = frame.base_to_map.translation.vector;
                    if vehicle_path
                        .last()
                        .is_none_or(|p: &[f64; 2]| (p[0] - at.x).hypot(p[1] - at.y) >= path_step)
                    {
                        vehicle_path.push([at.x, at.y]);
                    }
                    beyond.lidar += r.beyond_max_range[0];
                    beyond.stereo += r.beyond_max_range[1];
                    for w in &r.warnings {
                        frame_warnings.add(frame.stamp, w);
                    }
                    if let Some(s) = r.lidar_points() {
                        lidar.merge(s);
                    }
                    if let Some(s) = r.stereo_points() {
                        stereo.merge(s);
                    }
                    counts.add(&r.cues);
                    if let Some(l) = &r.labels {
                        crate::project::FrameLabelsReport::merge(
                            label_totals.get_or_insert_with(Default::default),
                            l,
                        );
                    }
                    stage_totals.add(&r.times_s);
                    per_frame.push(r.times_s);
                    frames_fused += 1;
                }
                Err(e) => errors.push(format!("frame at {:.6} s: {e}", frame.stamp)),
            }
            t_fuse += t.elapsed().as_secs_f64();
        }
        reader.join().map_err(|_| {
            Error::format(
                input,
                "frames",
                "the thread reading the log stopped unexpectedly",
            )
        })
    })?;
    if let Some(e) = fatal {
        // Not a log, or unreadable: nothing is written.
        return Err(Error::format(
            input,
            format!("topic {}", log_cfg.frame_topic),
            format!("no map built: {e}"),
        ));
    }
    if frames_fused == 0 {
        // Nothing to map: refuse rather than replace a previous map with an empty one.
        let why = damaged
            .first()
            .map(|d| format!("{}: {d}", input.display()))
            .or_else(|| errors.first().cloned())
            .unwrap_or_else(|| {
                format!(
                    "{} messages, {} frames skipped without a transform to {}",
                    summary.messages, stream_stats.frames_skipped_no_tf, log_cfg.map_frame
                )
            });
        return Err(Error::format(
            input,
            format!("topic {}", log_cfg.frame_topic),
            format!("no frame could be built: {why}"),
        ));
    }
    let cues = mapper.config().cue_names();
    let lidar_height_m = mapper.lidar_height();
    let diagnostic_interval_m = mapper.diagnostic_interval();
    let calibration = mapper.calibration().clone();
    let fusion = mapper.config().fusion;
    let (gcfg, res) = (
        mapper.config().grid.clone(),
        mapper.config().grid.resolution,
    );
    let t_read_fuse = t0.elapsed().as_secs_f64();
    let t2 = Instant::now();
    warnings.extend(frame_warnings.lines());
    if let Some(m) = label_totals.and_then(|l| l.mwir) {
        if m.frames_no_hour > 0 {
            warnings.push(format!(
                "mwir labels skipped in {} frames: no local solar hour (give --hour, or a \
                 longitude: labels.longitude_deg, --longitude, or a NavSatFix in the log)",
                m.frames_no_hour
            ));
        }
    }
    let (tiles, map) = mapper.finish_map()?;
    if map.cells.is_empty() {
        let pts = |p: &IngestStats| {
            format!(
                "{} points, {} fused, {} non-finite, {} outside the window",
                p.points, p.fused, p.nonfinite, p.outside
            )
        };
        return Err(Error::format(
            input,
            format!("topic {}", log_cfg.frame_topic),
            format!(
                "nothing built: {frames_fused} frames read, and no cell observed (lidar: {}; \
                 stereo: {})",
                pts(&lidar),
                pts(&stereo)
            ),
        ));
    }
    let stage = export::Staging::new(out)?;
    warnings.extend(swept_warnings(&stage));
    export::write_map_files_marked(
        stage.path(),
        &map,
        &damage_marks(input, &damaged),
        &vehicle_path,
    )?;
    let extra_outputs = ExtraMaps::of(&cfg.build, &log_cfg.map_frame, summary.end_ns.unwrap_or(0))
        .write(stage.path(), &tiles)?;
    let t_export = t2.elapsed().as_secs_f64();
    let total = t0.elapsed().as_secs_f64();
    let report = LogBuildReport {
        tarn_version: env!("CARGO_PKG_VERSION").to_string(),
        input: input.to_path_buf(),
        output: out.to_path_buf(),
        resolution_m: res,
        window_cells: gcfg.size_cells,
        frame_topic: log_cfg.frame_topic.clone(),
        frames_fused,
        log_duration_s: summary.duration_s,
        x_realtime: summary.duration_s / total.max(1e-9),
        per_frame_maps: cfg.build.per_frame_maps,
        cues,
        lidar_height_m,
        diagnostic_interval_m,
        calibration,
        lidar_points: lidar,
        stereo_points: stereo,
        cue_counts: counts,
        frames: stream_stats,
        errors,
        warnings,
        points_beyond_max_range: beyond,
        damaged,
        labels: label_totals,
        cells_observed: map.cells.len(),
        tiles: tiles.tile_count(),
        elevation_range_m: export::elevation_range(&map.cells),
        water: WaterSummary::of(&map, &fusion),
        extra_outputs,
        timings_s: Timings {
            read: t_read_fuse - t_fuse,
            fuse: t_fuse,
            export: t_export,
            total,
        },
        stage_totals_s: stage_totals,
        stage_latency_ms: stage_latency(&per_frame),
    };
    crate::files::write_json(&stage.path().join("report.json"), &report)?;
    crate::interrupt::check("writing the outputs")?;
    stage.commit()?;
    Ok(report)
}

/// Per-frame warnings gathered by kind (the text with its numbers left out), so that a
/// warning repeated in every frame is one line: the first frame's text, with how many
/// frames and which span of time.
#[derive(Default)]
struct FrameWarnings {
    /// Kind → (first text, first and last stamp, frames), in order of first appearance.
    kinds: Vec<(String, String, f64, f64, u64)>,
}

impl FrameWarnings {
    fn kind(w: &str) -> String {
        let mut k = String::with_capacity(w.len());
        let mut in_number = false;
        for c in w.chars() {
            let numeric = c.is_ascii_digit() || (in_number && ".e+-".contains(c));
            if numeric && !in_number {
                k.push('#');
            } else if !numeric {
                k.push(c);
            }
            in_number = numeric;
        }
        k
    }

    fn add(&mut self, stamp: f64, w: &str) {
        let kind = Self::kind(w);
        let full = self.kinds.len() >= MAX_WARNINGS;
        match self.kinds.iter_mut().find(|e| e.0 == kind) {
            Some(e) => {
                e.3 = stamp;
                e.4 += 1;
            }
            None if !full => self.kinds.push((kind, w.to_string(), stamp, stamp, 1)),
            None => {}
        }
    }

    fn lines(&self) -> impl Iterator<Item = String> + '_ {
        self.kinds.iter().map(|(_, w, t0, t1, n)| match n {
            1 => format!("frame at {t0:.6} s: {w}"),
            _ => format!("{n} frames from {t0:.6} s to {t1:.6} s, the first: {w}"),
        })
    }
}

/// Frames of a log's start an offline build reads to measure the sensors' noise, at most.
pub const CALIBRATION_MAX_FRAMES: usize = 200;

/// Shows the first frames of the log to `mapper` ([`Mapper::calibrate`]) until its
/// calibration is settled, at most [`CALIBRATION_MAX_FRAMES`], and holds what it measured:
/// every build of the log, whole or in time chunks, then fuses every frame with the same
/// noise. Frames that cannot be read are left to the build, which reports them.
pub fn calibrate_on_log(mapper: &mut Mapper, input: &Path, log_cfg: &LogConfig) -> Result<()> {
    let stream = crate::frames::FrameStream::open(input, log_cfg)?;
    for frame in stream.take(CALIBRATION_MAX_FRAMES).flatten() {
        crate::interrupt::check("measuring the sensors' noise")?;
        // A frame the mapper refuses (an implausible pose) is refused again, and reported,
        // when the build reaches it.
        let _ = mapper.calibrate(&frame);
        if mapper.calibration_settled() {
            break;
        }
    }
    mapper.hold_calibration();
    Ok(())
}

/// `cfg` with the sensors the log has no messages of left out (its lidar, stereo cloud,
/// colour, SWIR and MWIR images, on the topics `log` chose): a sensor the log lacks adds
/// nothing to the map, and the report then names only what the log has and what the
/// mapper assumed of it.
pub fn sensors_of_log(
    cfg: &MapperConfig,
    log: &LogConfig,
    summary: &crate::mcap_log::LogSummary,
) -> MapperConfig {
    use crate::project::LabelSensor;
    let has = |t: &str| summary.has_messages(t);
    let mut c = cfg.clone();
    if !has(&log.lidar_topic) {
        c.lidar = None;
    }
    if !has(&log.stereo_topic) {
        c.stereo = None;
    }
    if let Some(l) = &mut c.labels {
        l.sensors.retain(|s| match s {
            LabelSensor::Colour => has(&log.image_topic),
            LabelSensor::Swir => has(&log.swir_topic),
            LabelSensor::Mwir => has(&log.mwir_topic),
        });
        if l.sensors.is_empty() {
            c.labels = None;
            c.label_models = None;
        }
    }
    // Compiled models stand for `labels` or are given alone (a library user's, the bench's).
    if let Some(m) = &mut c.label_models {
        if !has(&log.image_topic) {
            m.colour = None;
        }
        if !has(&log.swir_topic) {
            m.swir = None;
        }
        if !has(&log.mwir_topic) {
            m.mwir = None;
        }
        if m.colour.is_none() && m.swir.is_none() && m.mwir.is_none() {
            c.label_models = None;
        }
    }
    c
}

/// The log settings of a build: [`LogBuildConfig::log`] with its sensor topics chosen
/// ([`LogConfig::with_topics_of`]: named ones, else by message type).
pub fn frame_log_config(
    cfg: &LogBuildConfig,
    summary: &crate::mcap_log::LogSummary,
    input: &Path,
) -> Result<LogConfig> {
    let mut named = cfg.topics.clone();
    if named.frame.is_none() && cfg.log.frame_topic != LogConfig::default().frame_topic {
        named.frame = Some(cfg.log.frame_topic.clone());
    }
    cfg.log.with_topics_of(summary, &named, input)
}

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

/// The comment lines that mark `map.ply` of a map built from a damaged log: the input, how
/// many ranges were skipped, and the first few of them (`report.json` lists them all).
fn damage_marks(input: &Path, damaged: &[crate::mcap_log::DamagedRange]) -> Vec<String> {
    const SHOWN: usize = 16;
    if damaged.is_empty() {
        return Vec::new();
    }
    let mut v = vec![format!(
        "damaged input: {} had {} damaged range(s), skipped; report.json lists them",
        input.file_name().unwrap_or_default().to_string_lossy(),
        damaged.len()
    )];
    v.extend(
        damaged
            .iter()
            .take(SHOWN)
            .map(|d| format!("damaged bytes {}..{}", d.start_byte, d.end_byte)),
    );
    v
}
