//! The dry terrain the step, slope and σ rules read: each dry cell's elevation, σ and
//! weight ([`dry_terrain`]), looked up by key in a dense array or a hash map ([`DryCells`]).

use super::terrain::{Neighbourhood, Window};
use super::CellMap;
use crate::grid::{CellKey, CellStats};

/// A dry cell's elevation (m), its range-bound σ (m) and the weight of its elevation in its
/// neighbours' gradient (m⁻², [`dry_terrain`]).
pub(super) type Dry = (f64, f64, f64);

/// What [`DryCells`] holds where a cell is not dry.
pub(super) const NOT_DRY: Dry = (f64::NAN, 0.0, 0.0);

/// The dry cells ([`Dry`]), looked up by key: a dense array over the cells' bounding box
/// when that is at most four times the cells (a window), else a hash map (a sparse global
/// map). The step and slope test asks nine cells per cell, the σ twenty-five.
pub(super) enum DryCells {
    Dense {
        lo: CellKey,
        width: i64,
        height: i64,
        /// NaN elevation: not a dry cell.
        cells: Vec<Dry>,
    },
    Sparse(CellMap<Dry>),
}

impl DryCells {
    pub(super) fn new(dry: Vec<(CellKey, Dry)>) -> Self {
        let Some(&(first, _)) = dry.first() else {
            return DryCells::Sparse(CellMap::default());
        };
        let (lo, hi) = dry.iter().fold((first, first), |(lo, hi), (k, _)| {
            (
                CellKey::new(lo.x.min(k.x), lo.y.min(k.y)),
                CellKey::new(hi.x.max(k.x), hi.y.max(k.y)),
            )
        });
        let (width, height) = (hi.x - lo.x + 1, hi.y - lo.y + 1);
        if width.saturating_mul(height) > 4 * dry.len() as i64 {
            return DryCells::Sparse(dry.into_iter().collect());
        }
        let mut cells = vec![NOT_DRY; (width * height) as usize];
        for (k, v) in dry {
            cells[((k.y - lo.y) * width + (k.x - lo.x)) as usize] = v;
        }
        DryCells::Dense {
            lo,
            width,
            height,
            cells,
        }
    }

    pub(super) fn get(&self, k: CellKey) -> Option<Dry> {
        match self {
            DryCells::Dense {
                lo,
                width,
                height,
                cells,
            } => {
                let (x, y) = (k.x - lo.x, k.y - lo.y);
                if x < 0 || y < 0 || x >= *width || y >= *height {
                    return None;
                }
                let v = cells[(y * width + x) as usize];
                (!v.0.is_nan()).then_some(v)
            }
            DryCells::Sparse(m) => m.get(&k).copied(),
        }
    }

    /// The dry 3 × 3 neighbourhood of `k`: elevation and range-bound σ.
    #[inline]
    pub(super) fn neighbourhood(&self, k: CellKey) -> Neighbourhood {
        let mut nb = [(f64::NAN, 0.0); 9];
        self.square(k, 1, |d| (d.0, d.1), &mut nb);
        nb
    }

    /// The dry 5 × 5 window around `k` (row by row from its lower-left cell): elevation and
    /// weight, NaN elevation where the cell is not dry.
    #[inline]
    pub(super) fn window(&self, k: CellKey) -> Window {
        let mut win = [(f64::NAN, 0.0); 25];
        self.square(k, 2, |d| (d.0, d.2), &mut win);
        win
    }

    /// `pick` of the cells within `r` of `k` into `out` (row by row from the lower-left,
    /// `(2r + 1)²` of them; [`NOT_DRY`] where a cell is not dry): slices of the dense array
    /// where the square lies inside it.
    #[inline]
    fn square(&self, k: CellKey, r: i64, pick: impl Fn(Dry) -> (f64, f64), out: &mut [(f64, f64)]) {
        let side = (2 * r + 1) as usize;
        if let DryCells::Dense {
            lo,
            width,
            height,
            cells,
        } = self
        {
            let (x, y) = (k.x - lo.x, k.y - lo.y);
            if x >= r && y >= r && x < width - r && y < height - r {
                for (i, row) in out.chunks_mut(side).enumerate() {
                    let at = ((y - r + i as i64) * width + x - r) as usize;
                    for (o, &d) in row.iter_mut().zip(&cells[at..at + side]) {
                        *o = pick(d);
                    }
                }
                return;
            }
        }
        for (j, o) in out.iter_mut().enumerate() {
            let (dx, dy) = ((j % side) as i64 - r, (j / side) as i64 - r);
            *o = pick(
                self.get(CellKey::new(k.x + dx, k.y + dy))
                    .unwrap_or(NOT_DRY),
            );
        }
    }
}

/// Elevation (m) of a cell with fused points, its range-bound σ for the step and slope
/// tests (0 when unknown), and the weight its elevation has in its neighbours' gradient:
/// the inverse of its vertical variance and the millimetre's
/// ([`window_gradient`](super::terrain::window_gradient)).
pub(super) fn dry_terrain(c: &CellStats, z_ref: f64) -> Option<Dry> {
    let finite = |s: Option<f64>| s.filter(|s| s.is_finite()).unwrap_or(0.0);
    Some((
        c.mean_mm().map(|m| z_ref + m * 1e-3)?,
        finite(c.range_bound_std_m()),
        weight(finite(c.elevation_std_m())),
    ))
}

/// The weight of an elevation of σ `s` (m) in a gradient: the inverse of its variance and
/// the millimetre's it is stored to.
pub(super) fn weight(s: f64) -> f64 {
    1.0 / (s * s + 1e-6 / 12.0)
}
