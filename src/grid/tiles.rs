//! The sparse global map: fixed-size tiles of cells, created only where something was
//! observed.

use std::collections::BTreeMap;

use super::{centre_of, CellKey, CellSink, CellStats, GridConfig, LabelFalseAlarms, RollingGrid};
use crate::error::{Error, Result};

#[path = "tiles_codec.rs"]
mod codec;

pub(crate) use codec::ByteReader;
pub use codec::{TILESET_MAGIC, TILESET_VERSION};

/// Cells per tile side.
pub const TILE_CELLS: i64 = 64;

/// Observed cells a tile holds as a sorted list before it switches to a dense array: a
/// map of scattered points costs about 100 bytes per observed cell, not a whole tile's
/// 393 kB per point.
const SPARSE_MAX: usize = 256;

/// A tile: `TILE_CELLS²` cells, row-major; few observed cells are kept as a list sorted by
/// their index in the tile.
#[derive(Debug, Clone)]
enum Tile {
    Sparse(Vec<(u16, CellStats)>),
    Dense {
        cells: Vec<CellStats>,
        observed: u32,
    },
}

impl Tile {
    fn new() -> Self {
        Tile::Sparse(Vec::new())
    }

    fn observed(&self) -> usize {
        match self {
            Tile::Sparse(v) => v.len(),
            Tile::Dense { observed, .. } => *observed as usize,
        }
    }

    fn get(&self, i: usize) -> Option<&CellStats> {
        match self {
            Tile::Sparse(v) => v
                .binary_search_by_key(&(i as u16), |e| e.0)
                .ok()
                .map(|j| &v[j].1),
            Tile::Dense { cells, .. } => Some(&cells[i]),
        }
    }

    fn merge(&mut self, i: usize, c: &CellStats) {
        match self {
            Tile::Sparse(v) => match v.binary_search_by_key(&(i as u16), |e| e.0) {
                Ok(j) => v[j].1.merge(c),
                Err(j) => {
                    if v.len() < SPARSE_MAX {
                        v.insert(j, (i as u16, *c));
                    } else {
                        let mut cells =
                            vec![CellStats::default(); (TILE_CELLS * TILE_CELLS) as usize];
                        for (k, s) in v.drain(..) {
                            cells[k as usize] = s;
                        }
                        cells[i] = *c;
                        *self = Tile::Dense {
                            cells,
                            observed: SPARSE_MAX as u32 + 1,
                        };
                    }
                }
            },
            Tile::Dense { cells, observed } => {
                if cells[i].is_empty() {
                    *observed += 1;
                }
                cells[i].merge(c);
            }
        }
    }

    /// Observed cells by index in the tile, in index order.
    fn cells(&self) -> Box<dyn Iterator<Item = (usize, &CellStats)> + '_> {
        match self {
            Tile::Sparse(v) => Box::new(v.iter().map(|(i, c)| (*i as usize, c))),
            Tile::Dense { cells, .. } => {
                Box::new(cells.iter().enumerate().filter(|(_, c)| !c.is_empty()))
            }
        }
    }

    fn bytes(&self) -> usize {
        match self {
            Tile::Sparse(v) => v.capacity() * std::mem::size_of::<(u16, CellStats)>(),
            Tile::Dense { cells, .. } => cells.len() * std::mem::size_of::<CellStats>(),
        }
    }
}

impl PartialEq for Tile {
    /// The same observed cells, whichever storage holds them.
    fn eq(&self, o: &Self) -> bool {
        self.observed() == o.observed() && self.cells().eq(o.cells())
    }
}

/// A sparse global map of cells at one resolution and reference height. Keys are
/// unbounded; memory grows with the observed area only.
///
/// Beside the cells it holds the colour and SWIR labels' false alarms measured on the logs
/// its cells came from ([`LabelFalseAlarms`]): the water stage reads the rate of the map's own
/// logs. They merge with the cells (sums); a part of a map cut by tile
/// ([`TileMap::select`], [`TileMap::partition`]) holds cells only.
#[derive(Debug, Clone, PartialEq)]
pub struct TileMap {
    resolution: f64,
    z_ref: f64,
    tiles: BTreeMap<(i64, i64), Tile>,
    false_alarms: LabelFalseAlarms,
}

#[inline]
fn split(k: CellKey) -> ((i64, i64), usize) {
    let (tx, ty) = (k.x.div_euclid(TILE_CELLS), k.y.div_euclid(TILE_CELLS));
    let (cx, cy) = (k.x.rem_euclid(TILE_CELLS), k.y.rem_euclid(TILE_CELLS));
    ((tx, ty), (cy * TILE_CELLS + cx) as usize)
}

impl TileMap {
    /// An empty map of cells `resolution` metres wide, elevations relative to `z_ref` (map z,
    /// metres). Fails when the resolution or reference height is out of range.
    pub fn new(resolution: f64, z_ref: f64) -> Result<Self> {
        GridConfig {
            resolution,
            z_ref,
            ..GridConfig::default()
        }
        .validate()?;
        Ok(TileMap {
            resolution,
            z_ref,
            tiles: BTreeMap::new(),
            false_alarms: LabelFalseAlarms::default(),
        })
    }

    /// Its cells and false alarms, leaving this map empty with the same resolution and
    /// reference height.
    pub fn take(&mut self) -> TileMap {
        TileMap {
            resolution: self.resolution,
            z_ref: self.z_ref,
            tiles: std::mem::take(&mut self.tiles),
            false_alarms: std::mem::take(&mut self.false_alarms),
        }
    }

    /// An empty map matching a grid's resolution and reference height.
    pub fn for_grid(grid: &RollingGrid) -> Self {
        TileMap {
            resolution: grid.resolution(),
            z_ref: grid.config().z_ref,
            tiles: BTreeMap::new(),
            false_alarms: LabelFalseAlarms::default(),
        }
    }

    /// The colour and SWIR labels' false alarms on the dry ground of the logs this map's
    /// cells came from.
    pub fn false_alarms(&self) -> LabelFalseAlarms {
        self.false_alarms
    }

    /// Adds false alarms measured on the logs this map's cells come from.
    pub fn add_false_alarms(&mut self, a: &LabelFalseAlarms) {
        self.false_alarms.merge(a);
    }

    /// Cell edge length, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Reference height of the stored elevations, map z, metres.
    pub fn z_ref(&self) -> f64 {
        self.z_ref
    }

    /// Adds a cell's statistics at `k`.
    pub fn add(&mut self, k: CellKey, c: &CellStats) {
        if c.is_empty() {
            return;
        }
        let (tk, i) = split(k);
        self.tiles.entry(tk).or_insert_with(Tile::new).merge(i, c);
    }

    /// The statistics of the cell at `k`; `None` when it was never observed.
    pub fn get(&self, k: CellKey) -> Option<CellStats> {
        let (tk, i) = split(k);
        self.tiles
            .get(&tk)
            .and_then(|t| t.get(i).copied())
            .filter(|c| !c.is_empty())
    }

    /// Merges another map (same resolution and reference height) into this one.
    pub fn merge(&mut self, other: &TileMap) -> Result<()> {
        if other.resolution != self.resolution || other.z_ref != self.z_ref {
            return Err(Error::invalid(
                "tile map merge",
                format!(
                    "resolution/z_ref differ: {} m / {} m against {} m / {} m",
                    other.resolution, other.z_ref, self.resolution, self.z_ref
                ),
            ));
        }
        for (k, c) in other.observed() {
            self.add(k, &c);
        }
        self.false_alarms.merge(&other.false_alarms);
        Ok(())
    }

    /// Copies every observed cell of a grid's window in (the grid is not changed).
    pub fn absorb_window(&mut self, grid: &RollingGrid) -> Result<()> {
        if grid.resolution() != self.resolution || grid.config().z_ref != self.z_ref {
            return Err(Error::invalid(
                "tile map",
                "grid resolution or z_ref differs from the map's",
            ));
        }
        for (k, c) in grid.observed() {
            self.add(k, &c);
        }
        Ok(())
    }

    /// Observed cells in a fixed order (tile by tile, row by row): deterministic.
    pub fn observed(&self) -> impl Iterator<Item = (CellKey, CellStats)> + '_ {
        self.tiles.iter().flat_map(|(&(tx, ty), t)| {
            t.cells().map(move |(i, c)| {
                let i = i as i64;
                let k = CellKey::new(
                    tx * TILE_CELLS + i % TILE_CELLS,
                    ty * TILE_CELLS + i / TILE_CELLS,
                );
                (k, *c)
            })
        })
    }

    /// Number of observed cells.
    pub fn observed_count(&self) -> usize {
        self.tiles.values().map(Tile::observed).sum()
    }

    /// Number of tiles holding cells.
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Bytes held by cell storage.
    pub fn cell_bytes(&self) -> usize {
        self.tiles.values().map(Tile::bytes).sum()
    }

    /// Elevation of a cell in metres (map frame).
    pub fn elevation(&self, c: &CellStats) -> Option<f64> {
        c.mean_mm().map(|m| self.z_ref + m * 1e-3)
    }

    /// Centre of a cell in the map frame.
    pub fn centre_of(&self, k: CellKey) -> (f64, f64) {
        centre_of(self.resolution, k)
    }

    /// Inclusive key bounds of the observed cells, if any.
    pub fn key_bounds(&self) -> Option<(CellKey, CellKey)> {
        let mut it = self.observed().map(|(k, _)| k);
        let first = it.next()?;
        let (mut lo, mut hi) = (first, first);
        for k in it {
            lo = CellKey::new(lo.x.min(k.x), lo.y.min(k.y));
            hi = CellKey::new(hi.x.max(k.x), hi.y.max(k.y));
        }
        Some((lo, hi))
    }
}

impl CellSink for TileMap {
    fn accept(&mut self, key: CellKey, cell: &CellStats) {
        self.add(key, cell);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(hits: u32) -> CellStats {
        CellStats {
            hits,
            ..CellStats::default()
        }
    }

    #[test]
    fn sparse_and_dense_tiles_hold_the_same_cells() {
        // 600 cells of one tile in two orders (the tile turns dense after 256), plus
        // repeated cells: the same map, listed in the same order, whatever the order.
        let keys: Vec<CellKey> = (0..600)
            .map(|i| CellKey::new((i * 37) % 64, 128 + (i / 8) % 64))
            .collect();
        let (mut a, mut b) = (
            TileMap::new(0.1, 0.0).unwrap(),
            TileMap::new(0.1, 0.0).unwrap(),
        );
        for (i, k) in keys.iter().enumerate() {
            a.add(*k, &cell(1 + i as u32 % 3));
        }
        for (i, k) in keys.iter().enumerate().rev() {
            b.add(*k, &cell(1 + i as u32 % 3));
        }
        assert!(a == b);
        assert_eq!(
            a.observed().collect::<Vec<_>>(),
            b.observed().collect::<Vec<_>>()
        );
        assert_eq!(a.tile_count(), 1);
        let distinct: std::collections::BTreeSet<_> = keys.iter().collect();
        assert_eq!(a.observed_count(), distinct.len());
        // The listing is in index order within the tile, as a dense tile lists it.
        let listed: Vec<_> = a.observed().map(|(k, _)| (k.y, k.x)).collect();
        let mut sorted = listed.clone();
        sorted.sort();
        assert_eq!(listed, sorted);
        for k in &keys {
            assert!(a.get(*k).is_some());
        }
        assert!(a.get(CellKey::new(63, 0)).is_none());
        // A few scattered cells cost about a hundred bytes each, not a whole tile.
        let mut c = TileMap::new(0.1, 0.0).unwrap();
        for i in 0..100 {
            c.add(CellKey::new(i * 1000, -i * 1000), &cell(1));
        }
        assert_eq!(c.tile_count(), 100);
        assert!(c.cell_bytes() < 100 * 1024, "{}", c.cell_bytes());
    }
}
