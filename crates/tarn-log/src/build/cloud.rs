//! A point cloud in the map frame, built into a map: in one batch when it fits one window,
//! else cut into blocks of whole windows (aligned to cell boundaries, so every cell belongs
//! to one block); the rolling grid moves from block to block and hands finished cells to
//! the global [`TileMap`]. Because a cell never spans two blocks and its sums are exact,
//! the result is the same as fusing everything into one unbounded grid.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geom::PointCloud;
use crate::grid::{
    in_map_domain, key_of, CellKey, GridConfig, IngestStats, RangeNoise, RollingGrid, TileMap,
};
use crate::hazard::HazardMap;
use tarn::io;

use super::*;

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
    check_cloud(cloud, cfg)?;
    let res = cfg.grid.resolution;
    let total = cloud.len() as u64;
    let (bounds, beyond) = key_bounds(cloud, res);
    let Some((lo, hi)) = bounds else {
        return empty_build(cfg, total, beyond, progress);
    };
    // Keys lie within ±2³⁵ (the domain at the finest resolution): no overflow below.
    let extent = (hi.x - lo.x).max(hi.y - lo.y) as u64 + 1;
    let n = window_side(extent, cfg.max_window_cells);
    let gcfg = GridConfig {
        size_cells: n,
        ..cfg.grid.clone()
    };
    let n64 = n as i64;
    let valid = cloud.valid_count() as u64;

    if extent <= n as u64 && n * n <= LEAF_CELLS_PER_POINT * valid as usize {
        return fuse_one_window(cloud, gcfg, lo, &cfg.noise, total, progress);
    }

    let Blocks {
        xy: block_xy,
        start,
        mut order,
    } = Blocks::of(cloud, res, lo, hi, n, valid);
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

/// Checks the build's grid and noise, the cloud, and that its points can be indexed by
/// `u32` (one value, `u32::MAX`, is kept for "no block").
fn check_cloud(cloud: &PointCloud, cfg: &BuildConfig) -> Result<()> {
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
    Ok(())
}

/// Nothing finite within the map: an empty map, every point counted (`beyond` of the
/// `total` as outside the map's domain, the rest as non-finite).
fn empty_build(
    cfg: &BuildConfig,
    total: u64,
    beyond: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CloudBuild> {
    let tiles = TileMap::new(cfg.grid.resolution, cfg.grid.z_ref)?;
    progress(total, total);
    Ok(CloudBuild {
        tiles,
        ingest: IngestStats {
            points: total,
            nonfinite: total - beyond,
            outside: beyond,
            ..Default::default()
        },
        blocks: 0,
        window_cells: 0,
    })
}

/// The window side for a cloud whose keys span `extent` cells: the power of two that
/// holds it when it fits in `max_window_cells` (clamped to `[MIN_LEAF_CELLS, 32768]`),
/// else that largest side.
fn window_side(extent: u64, max_window_cells: usize) -> usize {
    let max_n = max_window_cells.clamp(MIN_LEAF_CELLS, 32768);
    if extent <= max_n as u64 {
        (extent as usize)
            .next_power_of_two()
            .clamp(MIN_LEAF_CELLS, max_n)
    } else {
        max_n
    }
}

/// One window the points fill: the whole cloud fused in one batch into a grid of `gcfg`
/// placed at `lo`.
fn fuse_one_window(
    cloud: &PointCloud,
    gcfg: GridConfig,
    lo: CellKey,
    noise: &RangeNoise,
    total: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CloudBuild> {
    let n = gcfg.size_cells;
    let mut grid = RollingGrid::new(gcfg, 0.0, 0.0)?;
    let mut tiles = TileMap::for_grid(&grid);
    grid.move_origin(lo, &mut tiles);
    let stats = grid.ingest(cloud, noise)?;
    grid.flush(&mut tiles);
    progress(total, total);
    Ok(CloudBuild {
        tiles,
        ingest: stats,
        blocks: 1,
        window_cells: n,
    })
}

/// A cloud's points sorted into blocks of whole windows, aligned at multiples of the
/// window side from the lowest key.
struct Blocks {
    /// Each block's coordinates, in windows from the lowest key.
    xy: Vec<(i64, i64)>,
    /// Block `b`'s points are `order[start[b]..start[b + 1]]`.
    start: Vec<usize>,
    /// Point indices, grouped by block.
    order: Vec<u32>,
}

impl Blocks {
    /// The blocks of side `n` cells of the points whose keys lie in `lo..=hi`; `valid`
    /// is the cloud's count of valid points.
    fn of(cloud: &PointCloud, res: f64, lo: CellKey, hi: CellKey, n: usize, valid: u64) -> Self {
        let (ids, xy) = Self::number(cloud, res, lo, hi, n, valid);
        let (start, order) = Self::sort(ids, xy.len());
        Blocks { xy, start, order }
    }

    /// Each point's block id (`u32::MAX`: no block) and each id's block coordinates:
    /// every block of the bounds numbered densely, in row-major order, when there are not
    /// many more of them than points; else only the occupied ones.
    fn number(
        cloud: &PointCloud,
        res: f64,
        lo: CellKey,
        hi: CellKey,
        n: usize,
        valid: u64,
    ) -> (Vec<u32>, Vec<(i64, i64)>) {
        let n64 = n as i64;
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
        match bw.checked_mul(bh) {
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
        }
    }

    /// Counting sort of point indices by block id: `(start, order)` of [`Blocks`].
    fn sort(ids: Vec<u32>, nblocks: usize) -> (Vec<usize>, Vec<u32>) {
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
        (start, order)
    }
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
    let stage = io::Staging::new(out)?;
    io::write_map_files(stage.path(), &map)?;
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
        elevation_range_m: io::elevation_range(&map.cells),
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

#[cfg(test)]
mod tests {
    use super::*;

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
            let img = tarn::io::render_map_png(&map, &[]);
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
