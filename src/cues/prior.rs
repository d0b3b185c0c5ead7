//! The water a previous map found, read by the next frames' cues as a prior: the level of
//! its water bodies' surfaces, cell by cell, over the bodies and a reach around them.
//!
//! Data still flows one way within a frame: the prior is a map published before the frame
//! (the mapper's window map of an earlier frame), handed to the cues explicitly. The lidar
//! cue reads it where it needs the water level and its own walk cannot give one: a return
//! under a known water surface is the bed seen through the water, where the walk, which
//! follows the ground down a bank, would have taken the bed of a clear stream for ground.

use std::collections::{HashMap, VecDeque};

use crate::grid::{key_of, BuildKeyHasher, CellKey};

/// One cell of the prior: the water surface there and how well it is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PriorLevel {
    /// Water surface elevation, map z, metres.
    pub z: f64,
    /// Its standard deviation, metres: the body's shore samples' spread about its fitted
    /// surface.
    pub sigma: f64,
}

/// The water surface of an earlier map's bodies, over their cells and `reach_m` around
/// them (a cell beside a body takes the level of the nearest body cell).
#[derive(Debug, Clone, Default)]
pub struct WaterPrior {
    resolution: f64,
    levels: HashMap<CellKey, PriorLevel, BuildKeyHasher>,
}

impl WaterPrior {
    /// The prior of the given cells' levels (cells `resolution` metres wide), carried
    /// `reach_m` beyond them: breadth first from every given cell at once, each cell of the
    /// reach takes the level of a given cell nearest to it in 4-connected steps (the first
    /// reached, in the order given: deterministic). Non-finite levels are left out; a
    /// non-finite σ counts as 0.
    pub(crate) fn from_levels(
        resolution: f64,
        cells: impl IntoIterator<Item = (CellKey, PriorLevel)>,
        reach_m: f64,
    ) -> WaterPrior {
        let mut levels: HashMap<CellKey, PriorLevel, BuildKeyHasher> = HashMap::default();
        let mut front: VecDeque<(CellKey, u32)> = VecDeque::new();
        for (k, l) in cells {
            if l.z.is_finite() && !levels.contains_key(&k) {
                let sigma = if l.sigma.is_finite() { l.sigma } else { 0.0 };
                levels.insert(k, PriorLevel { z: l.z, sigma });
                front.push_back((k, 0));
            }
        }
        let steps = if resolution > 0.0 && reach_m.is_finite() && reach_m > 0.0 {
            (reach_m / resolution).floor().min(1e4) as u32
        } else {
            0
        };
        while let Some((k, n)) = front.pop_front() {
            if n >= steps {
                continue;
            }
            let level = levels[&k];
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let nk = CellKey::new(k.x.saturating_add(dx), k.y.saturating_add(dy));
                if let std::collections::hash_map::Entry::Vacant(e) = levels.entry(nk) {
                    e.insert(level);
                    front.push_back((nk, n + 1));
                }
            }
        }
        WaterPrior { resolution, levels }
    }

    /// The level under the map point `(x, y)`, if the prior has one there.
    pub(crate) fn level_at(&self, x: f64, y: f64) -> Option<PriorLevel> {
        if self.levels.is_empty() || !(x.is_finite() && y.is_finite()) {
            return None;
        }
        self.levels.get(&key_of(self.resolution, x, y)).copied()
    }

    /// Cells with a level.
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// Whether the prior has no level anywhere.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(z: f64) -> PriorLevel {
        PriorLevel { z, sigma: 0.01 }
    }

    #[test]
    fn the_reach_carries_the_nearest_level_whole_cells_far() {
        // Two cells at different levels, 0.1 m cells, a reach of 0.25 m: two steps.
        let p = WaterPrior::from_levels(
            0.1,
            [
                (CellKey::new(0, 0), level(1.0)),
                (CellKey::new(10, 0), level(2.0)),
            ],
            0.25,
        );
        let at = |x: i64, y: i64| p.level_at(x as f64 * 0.1 + 0.05, y as f64 * 0.1 + 0.05);
        assert_eq!(at(0, 0), Some(level(1.0)));
        assert_eq!(at(2, 0), Some(level(1.0)));
        assert_eq!(at(1, 1), Some(level(1.0)));
        assert_eq!(at(8, 0), Some(level(2.0)));
        assert_eq!(at(3, 0), None, "three steps away");
        assert_eq!(at(2, 1), None, "three 4-connected steps away");
        assert_eq!(p.len(), 2 * 13);
        assert_eq!(p.level_at(f64::NAN, 0.0), None);
    }

    #[test]
    fn bad_levels_and_reaches_give_nothing_beyond_the_cells() {
        let cells = [
            (CellKey::new(0, 0), level(f64::NAN)),
            (
                CellKey::new(5, 5),
                PriorLevel {
                    z: 0.5,
                    sigma: f64::INFINITY,
                },
            ),
            (CellKey::new(i64::MAX, i64::MIN), level(1e6)),
        ];
        for reach in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let p = WaterPrior::from_levels(0.1, cells, reach);
            assert_eq!(p.len(), 2, "reach {reach}");
            assert_eq!(p.level_at(0.05, 0.05), None);
            assert_eq!(p.level_at(0.55, 0.55).unwrap().sigma, 0.0);
        }
        // A reach at the edge of the key space saturates instead of wrapping.
        let p = WaterPrior::from_levels(0.1, cells, 0.1);
        assert_eq!(p.len(), 2 + 4 + 2);
        assert!(WaterPrior::default().is_empty());
    }
}
