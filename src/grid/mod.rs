//! The rolling elevation grid and the global tiled map.
//!
//! [`RollingGrid`] is a square window of cells that follows the vehicle. Its layers (one
//! elevation record a cell, the evidence as structure-of-arrays) are laid over a circular
//! buffer: a cell with global key `(kx, ky)` lives at
//! buffer position `(kx mod N, ky mod N)`, so moving the window only changes which keys
//! are in view and clears the rows and columns that wrap; nothing is copied. Users address
//! cells by world position or by [`CellKey`], never by buffer index.
//!
//! Cells that leave the window are handed to a [`CellSink`]; the offline builder's sink is
//! [`TileMap`], a sparse global map of fixed-size tiles. All statistics are exact integer
//! sums ([`CellStats`]), so grids and tile maps merge exactly.
//!
//! Exports: the window ([`RollingGrid`], its [`GridConfig`], [`IngestStats`] of an ingest,
//! [`RangeNoise`]; [`window_origin`]), cells ([`CellKey`], [`key_of`], [`centre_of`],
//! [`in_map_domain`] within [`MAX_MAP_COORD_M`], [`KeyHasher`] and [`BuildKeyHasher`],
//! [`CellStats`], [`quantize_weight`]), where cells go ([`CellSink`], [`DiscardSink`],
//! [`TileMap`] of [`TILE_CELLS`]-cell tiles, its file's [`TILESET_MAGIC`] and
//! [`TILESET_VERSION`]), and the water evidence ([`Evidence`], the [`Fusion`] rule over each
//! [`Cue`], [`CueLogOdds`], a cue's [`FalseAlarms`] measured from the log).

mod cell;
mod evidence;
mod false_alarms;
mod ingest;
mod layers;
mod tiles;

pub(crate) use cell::quantize_mm;
pub use cell::{quantize_weight, CellStats};
pub use evidence::{Cue, CueLogOdds, Evidence, Fusion};
pub(crate) use evidence::{FusionLogs, EVIDENCE_BYTES_PER_CELL, EVIDENCE_COUNTS};
pub use false_alarms::{FalseAlarms, LabelFalseAlarms};
pub use ingest::{IngestStats, RangeNoise};
pub(crate) use layers::{Elev, Layers};
pub(crate) use tiles::ByteReader;
pub use tiles::{TileMap, TILESET_MAGIC, TILESET_VERSION, TILE_CELLS};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Largest map-frame coordinate (|x| and |y|, metres) a cell may have: 100,000 km, beyond
/// any UTM, ECEF or local frame on Earth. Within it a cell key at the finest resolution
/// (5 mm) stays below 2³⁵, so every sum and difference of keys and window sizes is exact in
/// `i64`; points beyond it are outside every grid, and a window is never centred there.
pub const MAX_MAP_COORD_M: f64 = 1.0e8;

/// Whether `(x, y)` lies within [`MAX_MAP_COORD_M`] (false for NaN).
#[inline]
pub fn in_map_domain(x: f64, y: f64) -> bool {
    x.abs() <= MAX_MAP_COORD_M && y.abs() <= MAX_MAP_COORD_M
}

/// A multiply-rotate hasher for cell keys (two integers): SipHash's resistance to chosen
/// keys buys nothing for map cells and costs most of a lookup.
#[derive(Debug, Clone, Copy, Default)]
pub struct KeyHasher(u64);

impl std::hash::Hasher for KeyHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(*b as u64);
        }
    }
    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    #[inline]
    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }
    #[inline]
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 29)
    }
}

/// [`std::hash::BuildHasher`] of [`KeyHasher`].
pub type BuildKeyHasher = std::hash::BuildHasherDefault<KeyHasher>;

/// Global integer address of a cell: `floor(x / resolution)`, `floor(y / resolution)` in the
/// map frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct CellKey {
    /// Column: `floor(x / resolution)`, x in the map frame.
    pub x: i64,
    /// Row: `floor(y / resolution)`, y in the map frame.
    pub y: i64,
}

impl CellKey {
    /// The key of column `x`, row `y`.
    pub const fn new(x: i64, y: i64) -> Self {
        CellKey { x, y }
    }
}

/// Geometry and gating parameters of a grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GridConfig {
    /// Cell edge length, metres.
    pub resolution: f64,
    /// Cells per side of the rolling window.
    pub size_cells: usize,
    /// Reference height of the fixed-point elevations, metres (map frame). Elevations are
    /// stored in millimetres relative to it, so keep it within a few kilometres of the terrain.
    pub z_ref: f64,
    /// Mahalanobis gate: a point more than `gate_sigma` standard deviations (of the cell's
    /// spread and the point's own noise together) below the cell's surface is not fused but
    /// counted as below-surface.
    pub gate_sigma: f64,
    /// Smallest distance below the surface that can count as below-surface, metres; keeps
    /// rough but real ground from being split.
    pub gate_min_m: f64,
    /// Fused points a cell needs before its surface is trusted to gate new points.
    pub min_support: u32,
    /// How far ahead of the vehicle, along its heading, the online window's centre lies,
    /// as a fraction of the window's side (0..0.5): the lookahead the water cues use
    /// (their evidence reaches 30–45 m) stays in the window, at the cost of what lies
    /// behind, which the offline build keeps in its tiles.
    pub ahead: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            resolution: 0.10,
            size_cells: 400,
            z_ref: 0.0,
            gate_sigma: 3.0,
            gate_min_m: 0.15,
            min_support: 3,
            ahead: 0.25,
        }
    }
}

impl GridConfig {
    /// Rejects values no grid can be built with.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str, msg: String| Err(Error::invalid(format!("grid {what}"), msg));
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return bad(
                "resolution",
                format!("{} m (must be a positive number)", self.resolution),
            );
        }
        if self.resolution < 0.005 {
            return bad(
                "resolution",
                format!(
                    "{} m is below the 5 mm the fixed-point cells support",
                    self.resolution
                ),
            );
        }
        if !(2..=32768).contains(&self.size_cells) {
            return bad(
                "size",
                format!("{} cells per side (must be 2..=32768)", self.size_cells),
            );
        }
        if !self.z_ref.is_finite() {
            return bad("z_ref", format!("{}", self.z_ref));
        }
        if !(0.0..0.5).contains(&self.ahead) {
            return bad(
                "ahead",
                format!(
                    "{} (a fraction of the window's side, 0 ≤ ahead < 0.5)",
                    self.ahead
                ),
            );
        }
        if !(self.gate_sigma.is_finite() && self.gate_sigma > 0.0) {
            return bad("gate_sigma", format!("{}", self.gate_sigma));
        }
        if !(self.gate_min_m.is_finite() && self.gate_min_m >= 0.0) {
            return bad("gate_min_m", format!("{}", self.gate_min_m));
        }
        Ok(())
    }
}

/// Receives cells that leave the rolling window.
pub trait CellSink {
    /// Takes the statistics of the cell at `key` as it leaves the window.
    fn accept(&mut self, key: CellKey, cell: &CellStats);
}

/// A sink that forgets (an online mapper that only needs the window).
pub struct DiscardSink;

impl CellSink for DiscardSink {
    fn accept(&mut self, _key: CellKey, _cell: &CellStats) {}
}

/// A square window of cells on a circular buffer. See the module documentation.
#[derive(Debug, Clone)]
pub struct RollingGrid {
    cfg: GridConfig,
    n: usize,
    /// Key of the window's lower-left cell.
    origin: CellKey,
    pub(crate) layers: Layers,
    pub(crate) scratch: ingest::Scratch,
}

impl PartialEq for RollingGrid {
    fn eq(&self, o: &Self) -> bool {
        self.cfg == o.cfg && self.origin == o.origin && self.layers == o.layers
    }
}

impl RollingGrid {
    /// A grid whose window is centred on `(cx, cy)` (map frame, metres).
    pub fn new(cfg: GridConfig, cx: f64, cy: f64) -> Result<Self> {
        cfg.validate()?;
        check_centre(cx, cy)?;
        let n = cfg.size_cells;
        let mut g = RollingGrid {
            origin: CellKey::new(0, 0),
            n,
            layers: Layers::new(n * n),
            scratch: ingest::Scratch::default(),
            cfg,
        };
        g.origin = g.origin_for_centre(cx, cy);
        Ok(g)
    }

    /// The grid's configuration.
    pub fn config(&self) -> &GridConfig {
        &self.cfg
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.cfg.resolution
    }

    /// Cells per side.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Key of the lower-left cell of the window.
    pub fn origin(&self) -> CellKey {
        self.origin
    }

    /// Bytes of cell storage per cell (all layers).
    pub fn bytes_per_cell() -> usize {
        Layers::BYTES_PER_CELL
    }

    /// Bytes the grid holds on the heap: `(layers, ingest scratch)`, from the capacities
    /// of every allocation (the layers are per cell; the scratch is the binned and sorted
    /// points of the largest batch so far, and the accumulators of a bucket of cells per
    /// thread once a batch has had a dense bucket).
    pub(crate) fn heap_bytes(&self) -> (usize, usize) {
        (self.layers.heap_bytes(), self.scratch.heap_bytes())
    }

    /// The key of the cell containing the map point `(x, y)`.
    #[inline]
    pub fn key_of(&self, x: f64, y: f64) -> CellKey {
        key_of(self.cfg.resolution, x, y)
    }

    /// Centre of a cell in the map frame.
    pub fn centre_of(&self, k: CellKey) -> (f64, f64) {
        centre_of(self.cfg.resolution, k)
    }

    /// True when the key is inside the window.
    #[inline]
    pub fn contains(&self, k: CellKey) -> bool {
        let dx = k.x.wrapping_sub(self.origin.x);
        let dy = k.y.wrapping_sub(self.origin.y);
        (0..self.n as i64).contains(&dx) && (0..self.n as i64).contains(&dy)
    }

    /// Buffer index of an in-window key.
    #[inline]
    pub(crate) fn index(&self, k: CellKey) -> Option<usize> {
        self.contains(k).then(|| {
            let n = self.n as i64;
            (k.y.rem_euclid(n) * n + k.x.rem_euclid(n)) as usize
        })
    }

    /// The in-window key of buffer index `i` (the inverse of [`RollingGrid::index`]).
    #[inline]
    pub(crate) fn key_at(&self, i: usize) -> CellKey {
        let n = self.n as i64;
        let (bx, by) = ((i % self.n) as i64, (i / self.n) as i64);
        CellKey::new(
            self.origin.x + (bx - self.origin.x).rem_euclid(n),
            self.origin.y + (by - self.origin.y).rem_euclid(n),
        )
    }

    /// Statistics of a cell, if it is inside the window.
    pub fn cell(&self, k: CellKey) -> Option<CellStats> {
        self.index(k).map(|i| self.layers.get(i))
    }

    /// Statistics of the cell under the map point `(x, y)`.
    pub(crate) fn cell_at(&self, x: f64, y: f64) -> Option<CellStats> {
        self.cell(self.key_of(x, y))
    }

    /// Estimated terrain elevation (metres, map frame) under `(x, y)`.
    pub fn elevation_at(&self, x: f64, y: f64) -> Option<f64> {
        let c = self.cell_at(x, y)?;
        c.mean_mm().map(|m| self.cfg.z_ref + m * 1e-3)
    }

    /// Every in-window cell that holds data, in key order (row by row from the window's
    /// lower-left corner): deterministic.
    pub fn observed(&self) -> impl Iterator<Item = (CellKey, CellStats)> + '_ {
        let (n, o) = (self.n, self.origin);
        self.observed_indices().map(move |(j, i)| {
            let k = CellKey::new(o.x + (j % n) as i64, o.y + (j / n) as i64);
            (k, self.layers.get(i))
        })
    }

    /// The raster index (row-major from the window's lower-left cell) and the buffer index
    /// of every in-window cell that holds data, in the order of [`RollingGrid::observed`]:
    /// the buffer walked row by row, reading only the occupancy layer to skip the rest.
    pub(crate) fn observed_indices(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let n = self.n;
        (0..n).flat_map(move |dy| {
            self.observed_in_row(dy)
                .map(move |(dx, i)| (dy * n + dx, i))
        })
    }

    /// The column (from the window's left edge) and buffer index of every cell holding data
    /// in the window's row `dy` (from its lower edge), left to right.
    pub(crate) fn observed_in_row(&self, dy: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let n = self.n;
        let bx0 = self.origin.x.rem_euclid(n as i64) as usize;
        let by0 = self.origin.y.rem_euclid(n as i64) as usize;
        let row = (by0 + dy) % n * n;
        // The row's cells in the buffer: from bx0 to the end, then from 0 (it wraps).
        (row + bx0..row + n)
            .chain(row..row + bx0)
            .enumerate()
            .filter(move |&(_, i)| !self.layers.is_empty_at(i))
    }

    /// Every in-window cell that holds data, in the order of [`TileMap::observed`] (tile by
    /// tile, row by row within a tile): the window's cells listed as a tile map of them would
    /// list them, without building one.
    pub fn observed_by_tile(&self) -> impl Iterator<Item = (CellKey, CellStats)> + '_ {
        self.tile_rows().flat_map(move |(y, xs)| {
            xs.filter_map(move |x| {
                let k = CellKey::new(x, y);
                let i = self.index(k)?;
                (!self.layers.is_empty_at(i)).then(|| (k, self.layers.get(i)))
            })
        })
    }

    /// Runs `f` over every in-window cell, observed or not, with its key and buffer index,
    /// in the order of [`RollingGrid::observed_by_tile`]: tiles in parallel, each with its
    /// own accumulator, returned in tile order (the same whatever the thread count).
    pub(crate) fn map_by_tile<T: Default + Send>(
        &self,
        f: impl Fn(CellKey, usize, &mut T) + Sync,
    ) -> Vec<T> {
        let n = self.n as i64;
        let tiles: Vec<_> = self.tile_ranges().collect();
        tiles
            .into_par_iter()
            .map(|(xs, ys)| {
                let mut acc = T::default();
                for y in ys {
                    let row = (y.rem_euclid(n) * n) as usize;
                    let mut bx = xs.start.rem_euclid(n) as usize;
                    for x in xs.clone() {
                        f(CellKey::new(x, y), row + bx, &mut acc);
                        bx += 1;
                        if bx == self.n {
                            bx = 0;
                        }
                    }
                }
                acc
            })
            .collect()
    }

    /// The window's rows clipped to each tile, as `(y, x range)`, tile by tile as
    /// [`TileMap::observed`] lists cells.
    fn tile_rows(&self) -> impl Iterator<Item = (i64, std::ops::Range<i64>)> {
        self.tile_ranges()
            .flat_map(|(xs, ys)| ys.map(move |y| (y, xs.clone())))
    }

    /// The window clipped to each tile, as `(x range, y range)`, in the order of
    /// [`TileMap::observed`].
    pub(crate) fn tile_ranges(
        &self,
    ) -> impl Iterator<Item = (std::ops::Range<i64>, std::ops::Range<i64>)> {
        let t = tiles::TILE_CELLS;
        let n = self.n as i64;
        let (x0, y0) = (self.origin.x, self.origin.y);
        let (x1, y1) = (x0 + n, y0 + n);
        let ty = y0.div_euclid(t)..=(y1 - 1).div_euclid(t);
        (x0.div_euclid(t)..=(x1 - 1).div_euclid(t))
            .flat_map(move |tx| ty.clone().map(move |ty| (tx, ty)))
            .map(move |(tx, ty)| {
                (
                    (tx * t).max(x0)..(tx * t + t).min(x1),
                    (ty * t).max(y0)..(ty * t + t).min(y1),
                )
            })
    }

    /// Number of cells holding data.
    pub fn observed_count(&self) -> usize {
        (0..self.n * self.n)
            .filter(|&i| !self.layers.is_empty_at(i))
            .count()
    }

    fn origin_for_centre(&self, cx: f64, cy: f64) -> CellKey {
        window_origin(&self.cfg, cx, cy)
    }

    /// Moves the window so that it is centred on `(cx, cy)`. Cells that leave go to `sink`
    /// and their storage is cleared; every cell that stays keeps its data untouched.
    pub fn recenter(&mut self, cx: f64, cy: f64, sink: &mut dyn CellSink) -> Result<()> {
        check_centre(cx, cy)?;
        let o = self.origin_for_centre(cx, cy);
        self.move_origin(o, sink);
        Ok(())
    }

    /// Moves the window's lower-left corner to `new_origin`.
    pub fn move_origin(&mut self, new_origin: CellKey, sink: &mut dyn CellSink) {
        if new_origin == self.origin {
            return;
        }
        let n = self.n as i64;
        let old = self.origin;
        let (dx, dy) = (new_origin.x - old.x, new_origin.y - old.y);
        let leaving_x = |k: i64| k < new_origin.x || k >= new_origin.x + n;
        let leaving_y = |k: i64| k < new_origin.y || k >= new_origin.y + n;
        if dx.abs() >= n || dy.abs() >= n {
            // Nothing overlaps: every cell leaves.
            for ky in old.y..old.y + n {
                for kx in old.x..old.x + n {
                    self.evict(CellKey::new(kx, ky), sink);
                }
            }
        } else {
            // Columns that leave (whole height), then rows that leave (only the columns
            // that stay, so no cell is handed over twice).
            for kx in old.x..old.x + n {
                if leaving_x(kx) {
                    for ky in old.y..old.y + n {
                        self.evict(CellKey::new(kx, ky), sink);
                    }
                }
            }
            for ky in old.y..old.y + n {
                if leaving_y(ky) {
                    for kx in old.x..old.x + n {
                        if !leaving_x(kx) {
                            self.evict(CellKey::new(kx, ky), sink);
                        }
                    }
                }
            }
        }
        self.origin = new_origin;
    }

    fn evict(&mut self, k: CellKey, sink: &mut dyn CellSink) {
        let i = self.index(k).expect("evicted key is in the old window");
        if !self.layers.is_empty_at(i) {
            sink.accept(k, &self.layers.get(i));
            self.layers.set(i, &CellStats::default());
        }
    }

    /// Hands every cell with data to `sink` and clears the window (end of an offline build).
    pub fn flush(&mut self, sink: &mut dyn CellSink) {
        let n = self.n as i64;
        let o = self.origin;
        for ky in o.y..o.y + n {
            for kx in o.x..o.x + n {
                self.evict(CellKey::new(kx, ky), sink);
            }
        }
    }

    /// Adds another grid's cells into this one. Both must have the same configuration; cells
    /// of `other` outside this window are handed to `sink` (nothing is lost).
    pub fn merge(&mut self, other: &RollingGrid, sink: &mut dyn CellSink) -> Result<()> {
        if other.cfg.resolution != self.cfg.resolution || other.cfg.z_ref != self.cfg.z_ref {
            return Err(Error::invalid(
                "grid merge",
                format!(
                    "resolution/z_ref differ: {} m / {} m against {} m / {} m",
                    other.cfg.resolution, other.cfg.z_ref, self.cfg.resolution, self.cfg.z_ref
                ),
            ));
        }
        for (k, c) in other.observed() {
            match self.index(k) {
                Some(i) => self.layers.merge_at(i, &c),
                None => sink.accept(k, &c),
            }
        }
        Ok(())
    }
}

impl RollingGrid {
    /// Merges water evidence into the cell `k`; `false` (and nothing recorded) when `k` is
    /// outside the window.
    pub(crate) fn add_evidence(&mut self, k: CellKey, e: &Evidence) -> bool {
        match self.index(k) {
            Some(i) => {
                self.layers.merge_ev_at(i, e);
                true
            }
            None => false,
        }
    }

    /// Merges a batch of per-cell evidence; returns how many entries fell outside the
    /// window (dropped). The result does not depend on the batch's order.
    pub fn apply_evidence(&mut self, batch: &[(CellKey, Evidence)]) -> usize {
        batch
            .iter()
            .filter(|(k, e)| !self.add_evidence(*k, e))
            .count()
    }

    /// Water evidence of an in-window cell.
    pub fn evidence(&self, k: CellKey) -> Option<Evidence> {
        self.index(k).map(|i| self.layers.get_ev(i))
    }

    /// Water level and elevation helper: the grid's reference height plus `mm`.
    pub fn z_of_mm(&self, mm: f64) -> f64 {
        self.cfg.z_ref + mm * 1e-3
    }
}

/// A window centre must be finite and within [`MAX_MAP_COORD_M`].
fn check_centre(cx: f64, cy: f64) -> Result<()> {
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(Error::invalid(
            "grid centre",
            format!("({cx}, {cy}) is not finite"),
        ));
    }
    if !in_map_domain(cx, cy) {
        return Err(Error::invalid(
            "grid centre",
            format!("({cx}, {cy}) m is beyond the map's ±{MAX_MAP_COORD_M:e} m"),
        ));
    }
    Ok(())
}

/// The lower-left cell of a rolling window of `cfg` centred on `(cx, cy)` (map frame): its
/// cells are the `cfg.size_cells` columns and rows from there.
pub fn window_origin(cfg: &GridConfig, cx: f64, cy: f64) -> CellKey {
    let c = key_of(cfg.resolution, cx, cy);
    let h = (cfg.size_cells / 2) as i64;
    CellKey::new(c.x - h, c.y - h)
}

/// The key of the cell containing `(x, y)` at `resolution`.
#[inline]
pub fn key_of(resolution: f64, x: f64, y: f64) -> CellKey {
    // f64::floor, not geom::floor_i64: inlined into the AVX2 ingest it vectorises to
    // vroundpd, and floor_i64 there cost 15 % of ingest.
    CellKey::new(
        (x / resolution).floor() as i64,
        (y / resolution).floor() as i64,
    )
}

/// Centre of cell `k` at `resolution`.
#[inline]
pub fn centre_of(resolution: f64, k: CellKey) -> (f64, f64) {
    (
        (k.x as f64 + 0.5) * resolution,
        (k.y as f64 + 0.5) * resolution,
    )
}

#[cfg(test)]
mod tests;
