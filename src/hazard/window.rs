//! The hazard map of the mapper's rolling window, read straight from the window's layers.
//!
//! [`HazardMap::from_cells_after`] of the window's cells gives the same map (the
//! equivalence is tested, frame by frame, bit for bit); this path skips what makes that one
//! slow on a dense window of ~10⁵ observed cells: gathering each cell's full statistics,
//! computing every water probability twice, the hashed and ordered maps of the body search
//! (the window answers lookups by key itself), and fresh allocations every frame (the
//! buffers live in a [`WindowScratch`] between frames). Per-cell rules are the generic
//! path's: [`Seen`], [`dry_terrain`], [`CellRule`], [`crate::water::bodies_from`].

use super::*;
use rayon::prelude::*;

use crate::grid::{FusionLogs, RollingGrid};
use crate::water::{bodies_from, seeds_body, CellInfos, Info};

/// Buffers of [`HazardMap::from_window_after`], kept between frames; what they hold is
/// only meaningful within one call.
#[derive(Debug, Default)]
pub(crate) struct WindowScratch {
    /// Observed cells of the window in tile order: buffer index and water probability
    /// (the rest of a cell's record is read from the layers when it is written).
    seen: Vec<(u32, f32)>,
    /// Observed cells of each tile (in the order of [`RollingGrid::map_by_tile`]).
    per_tile: Vec<usize>,
    /// Cells that seed a body.
    seeds: Vec<CellKey>,
    /// Storage for the next map's cells (an earlier map's, once nothing else held it).
    cells: Vec<MapCell>,
}

impl WindowScratch {
    /// Bytes allocated (capacities): observed cells, their count per tile, seeds, map
    /// cells.
    pub(crate) fn heap_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        b(&self.seen) + b(&self.per_tile) + b(&self.seeds) + b(&self.cells)
    }

    /// Keeps the storage of a map nobody reads any more for the next map.
    pub(crate) fn recycle(&mut self, map: HazardMap) {
        if map.cells.capacity() > self.cells.capacity() {
            self.cells = map.cells;
        }
    }
}

/// What the water stage reads from one tile of the window: its observed cells (buffer
/// index and water probability) and the cells that seed a body.
#[derive(Default)]
struct TileCells {
    seen: Vec<(u32, f32)>,
    seeds: Vec<CellKey>,
}

/// The observed cells of a window, looked up in its layers.
struct WindowInfos<'a> {
    grid: &'a RollingGrid,
    fusion: &'a FusionLogs,
}

impl CellInfos for WindowInfos<'_> {
    fn get(&self, k: CellKey) -> Option<Info> {
        let i = self.grid.index(k)?;
        let l = &self.grid.layers;
        if l.is_empty_at(i) {
            return None;
        }
        let c = l.get(i);
        let p = c.ev.water_probability_in(self.fusion);
        Some(Info::of(&c, p, self.fusion, self.grid.config().z_ref))
    }

    fn column(&self, x: i64, ys: std::ops::Range<i64>, mut f: impl FnMut(CellKey, &Info)) {
        for y in ys {
            let k = CellKey::new(x, y);
            if let Some(i) = self.get(k) {
                f(k, &i);
            }
        }
    }
}

/// How far the step, slope and σ rules read around a cell (its 5 × 5 window).
const REACH: i64 = 2;

/// The dry terrain ([`dry_terrain`]) of the window's cells within [`REACH`] of the tile
/// `xs` × `ys`, water cells and cells outside the window not dry: all that the rules of
/// the tile's cells read.
fn tile_dry(
    grid: &RollingGrid,
    water: &CellMap<(f64, f32)>,
    (xs, ys): (&std::ops::Range<i64>, &std::ops::Range<i64>),
) -> DryCells {
    let (z_ref, l) = (grid.config().z_ref, &grid.layers);
    let lo = CellKey::new(xs.start - REACH, ys.start - REACH);
    let (width, height) = (xs.end - xs.start + 2 * REACH, ys.end - ys.start + 2 * REACH);
    let mut cells: Vec<Dry> = vec![NOT_DRY; (width * height) as usize];
    for dy in 0..height {
        for dx in 0..width {
            let k = CellKey::new(lo.x + dx, lo.y + dy);
            let Some(i) = grid.index(k) else { continue };
            if l.is_empty_at(i) {
                continue;
            }
            if let Some(t) = dry_terrain(&l.elevation_stats(i), z_ref) {
                cells[(dy * width + dx) as usize] = t;
            }
        }
    }
    let hi = CellKey::new(lo.x + width, lo.y + height);
    for &k in water.keys() {
        if k.x >= lo.x && k.y >= lo.y && k.x < hi.x && k.y < hi.y {
            cells[((k.y - lo.y) * width + (k.x - lo.x)) as usize] = NOT_DRY;
        }
    }
    DryCells::Dense {
        lo,
        width,
        height,
        cells,
    }
}

impl HazardMap {
    /// [`HazardMap::from_cells_after`] of the window's observed cells in tile order (as
    /// [`RollingGrid::observed_by_tile`] lists them), with the grid's resolution and
    /// reference height: the same map, bit for bit.
    ///
    /// No buffer spans the window: the dry terrain the step, slope and σ rules read is
    /// gathered tile by tile (with the two cells around it the rules reach), and an
    /// observed cell is kept as its buffer index and water probability until its record
    /// is written.
    pub(crate) fn from_window_after(
        grid: &RollingGrid,
        cfg: &HazardConfig,
        previous: &[WaterBody],
        scratch: &mut WindowScratch,
    ) -> Result<Self> {
        cfg.validate()?;
        let (res, z_ref) = (grid.resolution(), grid.config().z_ref);
        let l = &grid.layers;
        let WindowScratch {
            seen,
            per_tile,
            seeds,
            cells,
        } = scratch;
        seen.clear();
        seeds.clear();
        per_tile.clear();
        let logs = cfg.fusion.logs();
        // Per tile, in parallel: the observed cells and the seeds.
        let tiles = grid.map_by_tile(|key, i, acc: &mut TileCells| {
            if l.is_empty_at(i) {
                return;
            }
            let p = l.get_ev(i).water_probability_in(&logs);
            if seeds_body(p, &cfg.water) {
                acc.seeds.push(key);
            }
            acc.seen.push((i as u32, p as f32));
        });
        for t in tiles {
            seen.extend_from_slice(&t.seen);
            seeds.extend_from_slice(&t.seeds);
            per_tile.push(t.seen.len());
        }
        seeds.sort_unstable();
        let infos = WindowInfos {
            grid,
            fusion: &logs,
        };
        let (bodies, void) = bodies_from(&infos, seeds.iter().copied(), res, &cfg.water, previous);
        let water = water_surface(&bodies, res);
        // Each tile's observed cells: a slice of `seen`.
        let mut tiles = Vec::with_capacity(per_tile.len());
        let mut rest: &[(u32, f32)] = seen;
        for (range, &k) in grid.tile_ranges().zip(per_tile.iter()) {
            let (now, next) = rest.split_at(k);
            tiles.push((range, now));
            rest = next;
        }
        let mut out = std::mem::take(cells);
        out.clear();
        out.reserve(seen.len());
        // Tiles in parallel; a parallel extend keeps their order.
        out.par_extend(tiles.into_par_iter().flat_map_iter(|((xs, ys), now)| {
            let dry = tile_dry(grid, &water, (&xs, &ys));
            let rule = CellRule::new(cfg, res, z_ref, &water, &dry);
            let records: Vec<MapCell> = now
                .iter()
                .filter_map(|&(i, p)| {
                    let i = i as usize;
                    let key = grid.key_at(i);
                    let ev = || l.get_ev(i);
                    let s = Seen::of(key, &l.elevation_stats(i), p);
                    // A cell whose bottom returns the water stage voided: see
                    // `voided_water`.
                    let s = if void.contains(&key) {
                        let w = voided_water(key, &ev(), &logs, &void, &water);
                        Seen {
                            water: w.unwrap_or(s.water),
                            ..s
                        }
                    } else {
                        s
                    };
                    rule.record(s, || ev().level_mm())
                })
                .collect();
            records
        }));
        Ok(HazardMap {
            resolution: res,
            cells: out,
            bodies,
        })
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::grid::{DiscardSink, Evidence, GridConfig};
    use crate::hazard::Vehicle;

    /// Bit-for-bit equality of two maps (NaN depths included; `==` says NaN ≠ NaN).
    fn same_map(a: &HazardMap, b: &HazardMap) -> bool {
        format!("{a:?}") == format!("{b:?}")
    }

    /// The generic path's map of the window: the reference.
    fn generic(g: &RollingGrid, cfg: &HazardConfig, previous: &[WaterBody]) -> HazardMap {
        let t = TileMap::new(g.resolution(), g.config().z_ref).unwrap();
        HazardMap::from_cells_after(&t, g.observed_by_tile().collect(), cfg, previous).unwrap()
    }

    /// A pseudo-random number in 0..1 for cell `k` and salt `s`.
    fn hash01(seed: u64, k: CellKey, s: u64) -> f64 {
        let mut z = seed
            ^ (k.x as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (k.y as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ s.wrapping_mul(0x1656_67b1_9e37_79f9);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)) as f64 / u64::MAX as f64
    }

    /// Fills the window with a random scene: ground on a slope with steps and noisy far
    /// cells, unobserved holes, ponds of strong and weak water evidence (some with depths),
    /// evidence-only cells and stray weak evidence.
    fn fill(g: &mut RollingGrid, seed: u64, ponds: &[(f64, f64, f64, bool)], empty: f64) {
        let (n, o) = (g.size() as i64, g.origin());
        for dy in 0..n {
            for dx in 0..n {
                let k = CellKey::new(o.x + dx, o.y + dy);
                let r = |s| hash01(seed, k, s);
                if r(0) < empty {
                    continue;
                }
                let (x, y) = g.centre_of(k);
                let mut c = CellStats::default();
                let wet = ponds
                    .iter()
                    .find(|&&(px, py, pr, _)| (x - px).hypot(y - py) < pr);
                let ground = 0.2 * x + 0.05 * y + if (k.x / 7) % 3 == 0 { 0.4 } else { 0.0 };
                if wet.is_none() || r(1) < 0.1 {
                    let w = if r(2) < 0.2 { 3 } else { 65536 };
                    for j in 0..1 + (r(3) * 4.0) as u64 {
                        let z = ground + (hash01(seed, k, 10 + j) - 0.5) * 0.1;
                        c.add((z * 1000.0).round() as i32, w);
                    }
                }
                let mut ev = Evidence::default();
                if let Some(&(_, _, _, deep)) = wet {
                    ev.noret = if r(4) < 0.7 { 6 } else { 1 };
                    if r(5) < 0.8 {
                        ev.add_level(((ground - 0.3) * 1000.0) as i32);
                    }
                    if deep && r(6) < 0.5 {
                        ev.add_depth(0.1 + r(7));
                    }
                } else if r(8) < 0.03 {
                    ev.reflect = 1 + (r(9) * 3.0) as u16;
                    ev.add_level(((ground - 0.1) * 1000.0) as i32);
                } else if r(8) < 0.05 {
                    ev.add_depth(0.2);
                }
                c.ev = ev;
                if let Some(i) = g.index(k) {
                    g.layers.set(i, &c);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// The window path gives the generic path's map of the window's cells, bit for bit,
        /// for windows at any offset from the tiles and from the buffer's origin, with and
        /// without bodies of a previous map.
        #[test]
        fn window_path_is_the_generic_path(
            size in 2usize..150,
            centre in (-30.0f64..30.0, -30.0f64..30.0),
            moved in (-40i64..40, -40i64..40),
            seed in any::<u64>(),
            ponds in prop::collection::vec(
                (-15.0f64..15.0, -15.0f64..15.0, 0.2f64..4.0, any::<bool>()), 0..4),
            empty in 0.0f64..0.6,
        ) {
            let cfg = HazardConfig::default();
            let grid_cfg = GridConfig { size_cells: size, ..GridConfig::default() };
            let mut g = RollingGrid::new(grid_cfg, centre.0, centre.1).unwrap();
            let ponds: Vec<_> = ponds
                .into_iter()
                .map(|(x, y, r, d)| (x + centre.0, y + centre.1, r, d))
                .collect();
            fill(&mut g, seed, &ponds, empty);
            let mut scratch = WindowScratch::default();
            let first = HazardMap::from_window_after(&g, &cfg, &[], &mut scratch).unwrap();
            prop_assert!(same_map(&first, &generic(&g, &cfg, &[])));
            // The window moves (its cells wrap around the buffer), more is seen, and the
            // bodies of the first map give the ids.
            let o = g.origin();
            g.move_origin(CellKey::new(o.x + moved.0, o.y + moved.1), &mut DiscardSink);
            fill(&mut g, seed ^ 1, &ponds, empty + 0.3);
            scratch.recycle(first.clone());
            let second = HazardMap::from_window_after(&g, &cfg, &first.bodies, &mut scratch).unwrap();
            prop_assert!(same_map(&second, &generic(&g, &cfg, &first.bodies)));
        }
    }

    #[test]
    fn random_windows_have_bodies_and_hazards() {
        // The scenes of the property above exercise what they should: bodies (with and
        // without depths), obstacles, evidence-only cells.
        let mut g = RollingGrid::new(
            GridConfig {
                size_cells: 140,
                ..GridConfig::default()
            },
            3.0,
            -2.0,
        )
        .unwrap();
        fill(
            &mut g,
            7,
            &[(3.0, -2.0, 3.0, true), (-2.0, 1.0, 1.5, false)],
            0.2,
        );
        let cfg = HazardConfig::default();
        let m = HazardMap::from_window_after(&g, &cfg, &[], &mut WindowScratch::default()).unwrap();
        assert!(same_map(&m, &generic(&g, &cfg, &[])));
        assert!(m.bodies.len() >= 2, "{} bodies", m.bodies.len());
        let n = m.class_counts();
        for c in [Class::Ground, Class::Water, Class::Obstacle] {
            assert!(n[c as usize] > 0, "{n:?}");
        }
        assert!(m
            .cells
            .iter()
            .any(|c| c.hazard == Hazard::Obstacle && c.class == Class::Ground));
        assert!(m.cells.iter().any(|c| c.hazard == Hazard::DeepWater));
        // A bad config is the generic path's error.
        let bad = HazardConfig {
            vehicle: Vehicle {
                max_step_m: -1.0,
                ..Vehicle::default()
            },
            ..cfg
        };
        assert!(
            HazardMap::from_window_after(&g, &bad, &[], &mut WindowScratch::default()).is_err()
        );
    }
}
