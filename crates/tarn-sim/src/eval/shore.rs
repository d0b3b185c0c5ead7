//! The water's edge: the truth cells near enough to true water that calling them wet is no
//! real false alarm.

use super::{KeySet, SHORE_MARGIN_M};
use crate::grid::CellKey;
use crate::hazard::{Class, HazardMap};

/// The truth cells within [`SHORE_MARGIN_M`] of the centre of a true water cell: the water
/// mask dilated by a disc. A dense array over the truth raster's bounding box, or a hash
/// set when the truth is sparse (a box over four times its cells).
pub(super) enum Shore {
    Dense {
        lo: CellKey,
        width: i64,
        height: i64,
        /// One flag per cell of the box, row by row.
        near: Vec<bool>,
    },
    Sparse(KeySet),
}

impl Shore {
    pub(super) fn new(truth: &HazardMap) -> Self {
        let res = truth.resolution;
        let water: KeySet = truth
            .cells
            .iter()
            .filter(|c| c.class == Class::Water)
            .map(|c| c.key)
            .collect();
        // Offsets whose centres are within the margin (a hair of slack for rounding).
        let r = (SHORE_MARGIN_M / res).ceil() as i64;
        let disc: Vec<(i64, i64)> = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| (dx as f64).hypot(dy as f64) * res <= SHORE_MARGIN_M + 1e-9)
            .collect();
        let mut s = match truth.cells.first() {
            None => Shore::Sparse(KeySet::default()),
            Some(first) => {
                let (lo, hi) = truth
                    .cells
                    .iter()
                    .fold((first.key, first.key), |(lo, hi), c| {
                        (
                            CellKey::new(lo.x.min(c.key.x), lo.y.min(c.key.y)),
                            CellKey::new(hi.x.max(c.key.x), hi.y.max(c.key.y)),
                        )
                    });
                let (width, height) = (hi.x - lo.x + 1, hi.y - lo.y + 1);
                if width.saturating_mul(height) <= 4 * truth.cells.len() as i64 {
                    Shore::Dense {
                        lo,
                        width,
                        height,
                        near: vec![false; (width * height) as usize],
                    }
                } else {
                    Shore::Sparse(KeySet::default())
                }
            }
        };
        // The water cell nearest a dry cell has a neighbour (the step towards the dry
        // cell) that is not water, else that neighbour would be nearer: only water cells
        // on a boundary need stamping.
        let boundary = |k: &&CellKey| {
            [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|(dx, dy)| !water.contains(&CellKey::new(k.x + dx, k.y + dy)))
        };
        for k in water.iter().filter(boundary) {
            for (dx, dy) in &disc {
                s.mark(CellKey::new(k.x + dx, k.y + dy));
            }
        }
        s
    }

    /// The index of `k` in a dense box of `width` × `height` from `lo`, if it is inside.
    fn slot(lo: CellKey, width: i64, height: i64, k: CellKey) -> Option<usize> {
        let (x, y) = (k.x.checked_sub(lo.x)?, k.y.checked_sub(lo.y)?);
        ((0..width).contains(&x) && (0..height).contains(&y)).then(|| (y * width + x) as usize)
    }

    fn mark(&mut self, k: CellKey) {
        match self {
            Shore::Dense {
                lo,
                width,
                height,
                near,
            } => {
                if let Some(i) = Shore::slot(*lo, *width, *height, k) {
                    near[i] = true;
                }
            }
            Shore::Sparse(set) => {
                set.insert(k);
            }
        }
    }

    /// Whether the centre of truth cell `k` is within [`SHORE_MARGIN_M`] of a water cell's.
    pub(super) fn near(&self, k: CellKey) -> bool {
        match self {
            Shore::Dense {
                lo,
                width,
                height,
                near,
            } => Shore::slot(*lo, *width, *height, k).is_some_and(|i| near[i]),
            Shore::Sparse(set) => set.contains(&k),
        }
    }
}
