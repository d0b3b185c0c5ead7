//! Looking a map's cells and water bodies up by key and by map position.

use super::{CellMap, HazardMap, MapCell};
use crate::grid::CellKey;
use crate::water::WaterBody;

impl HazardMap {
    /// The key of the cell under map position (x, y).
    pub(crate) fn key_at(&self, x: f64, y: f64) -> CellKey {
        crate::grid::key_of(self.resolution, x, y)
    }

    /// The observed cell under map position (x, y), if any: one query, a scan of the
    /// cells. A planner asking many positions takes [`HazardMap::index`] once.
    pub fn at(&self, x: f64, y: f64) -> Option<&MapCell> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let key = self.key_at(x, y);
        self.cells.iter().find(|c| c.key == key)
    }

    /// The cells and water bodies looked up by position, built once (linear in the cells)
    /// for a map that does not change while the index lives.
    pub fn index(&self) -> MapIndex<'_> {
        MapIndex {
            map: self,
            lookup: MapLookup::of(self),
        }
    }
}

/// A [`HazardMap`] looked up by position ([`HazardMap::index`]): what a planner asks of a
/// point it may drive over.
#[derive(Debug, Clone)]
pub struct MapIndex<'a> {
    map: &'a HazardMap,
    lookup: MapLookup,
}

impl<'a> MapIndex<'a> {
    /// The observed cell `key`, if any.
    pub fn cell(&self, key: CellKey) -> Option<&'a MapCell> {
        self.lookup.cell(self.map, key)
    }

    /// The observed cell under map position (x, y), if any (its class, hazard, water
    /// probability, elevation, σ and depth).
    pub fn at(&self, x: f64, y: f64) -> Option<&'a MapCell> {
        self.lookup.at(self.map, x, y)
    }

    /// The water body holding the cell under map position (x, y), if any.
    pub fn body_at(&self, x: f64, y: f64) -> Option<&'a WaterBody> {
        self.lookup.body_at(self.map, x, y)
    }
}

/// The tables of a [`MapIndex`] without the map they index, for an owner that keeps the
/// map beside them (a struct cannot hold a map and a borrow of it): each query takes the
/// map it was built from.
#[derive(Debug, Clone)]
pub struct MapLookup {
    /// Cell key → position in `map.cells`.
    cells: CellMap<u32>,
    /// Cell key → position in `map.bodies`.
    bodies: CellMap<u32>,
}

impl MapLookup {
    /// The tables of `map` (linear in its cells).
    pub fn of(map: &HazardMap) -> Self {
        let cells = map
            .cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.key, i as u32))
            .collect();
        let bodies = map
            .bodies
            .iter()
            .enumerate()
            .flat_map(|(b, body)| body.cells.iter().map(move |&k| (k, b as u32)))
            .collect();
        MapLookup { cells, bodies }
    }

    /// [`MapIndex::cell`] of `map`, the map these tables were built from.
    pub fn cell<'a>(&self, map: &'a HazardMap, key: CellKey) -> Option<&'a MapCell> {
        self.cells.get(&key).map(|&i| &map.cells[i as usize])
    }

    /// [`MapIndex::at`] of `map`, the map these tables were built from.
    pub fn at<'a>(&self, map: &'a HazardMap, x: f64, y: f64) -> Option<&'a MapCell> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        self.cell(map, map.key_at(x, y))
    }

    /// [`MapIndex::body_at`] of `map`, the map these tables were built from.
    pub fn body_at<'a>(&self, map: &'a HazardMap, x: f64, y: f64) -> Option<&'a WaterBody> {
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let k = map.key_at(x, y);
        self.bodies.get(&k).map(|&b| &map.bodies[b as usize])
    }
}
