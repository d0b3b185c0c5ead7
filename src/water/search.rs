//! The body search: which cells a body can grow over, components grown from seeds, their
//! refinement by bottom returns, and ids that follow the previous snapshot's bodies
//! (sections 1 and 4 of the module documentation).

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};

use rayon::prelude::*;

use super::body::body_of;
use super::{WaterBody, WaterConfig};
use crate::error::Result;
use crate::grid::{CellKey, CellStats, Fusion, FusionLogs, TileMap};

/// The eight neighbours of a cell, as key offsets.
pub(crate) const N8: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];
pub(super) const N4: [(i64, i64); 4] = [(0, -1), (-1, 0), (1, 0), (0, 1)];

/// The key `k` moved by an offset.
pub(crate) fn add(k: CellKey, (dx, dy): (i64, i64)) -> CellKey {
    CellKey::new(k.x + dx, k.y + dy)
}

/// What the water stage reads of a cell.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Info {
    pub(super) p: f64,
    /// The probability without the bottom returns' term (`p` when there are none).
    pub(super) p_without_bottom: f64,
    /// Whether the bottom returns count as evidence of water (see
    /// [`WaterConfig::min_bottom_depth_m`]): until a body's surface shows they do not.
    pub(super) bottom_counts: bool,
    pub(super) elevation: Option<f64>,
    /// Standard deviation of the elevation estimate (m).
    pub(super) std: Option<f64>,
    pub(super) level: Option<f64>,
    pub(super) depth: Option<Bottom>,
}

/// A cell's bottom returns: their mean depth below a water surface at `z` is `a + gain·z`
/// (see [`crate::grid::Evidence::depth_at_m`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bottom {
    pub(super) a: f64,
    pub(super) gain: f64,
}

impl Bottom {
    fn of(ev: &crate::grid::Evidence, z_ref: f64) -> Option<Bottom> {
        let at_ref = ev.depth_at_m(0.0)?;
        let gain = ev.depth_at_m(1000.0)? - at_ref;
        Some(Bottom {
            a: at_ref - gain * z_ref,
            gain,
        })
    }

    /// The mean depth below a surface at `z` (m), never negative: a bottom above the
    /// surface is no water at all.
    pub(super) fn below(&self, z: f64) -> f64 {
        (self.a + self.gain * z).max(0.0)
    }
}

impl Info {
    /// Whether the cell's bottom returns are evidence of water.
    pub(super) fn has_bottom_evidence(&self) -> bool {
        self.depth.is_some() && self.bottom_counts
    }

    /// The water probability a body grows by: without the bottom returns once they no
    /// longer count. (`p` itself stays what the evidence says: the occluder test's dry
    /// ground reads it, so that one body's fit never depends on what another's took away.)
    pub(super) fn p_evidence(&self) -> f64 {
        if self.bottom_counts {
            self.p
        } else {
            self.p_without_bottom
        }
    }

    /// The cell with its bottom returns no longer evidence of water (their depth is still
    /// the cell's depth if other evidence keeps it in a body).
    pub(super) fn without_bottom_evidence(self) -> Info {
        Info {
            bottom_counts: false,
            ..self
        }
    }
}

/// The cells of `inner` with the bottom evidence of the cells in `void` taken away.
pub(crate) struct WithoutBottom<'a, C> {
    inner: &'a C,
    void: &'a BTreeSet<CellKey>,
}

impl<'a, C> WithoutBottom<'a, C> {
    /// `inner`'s cells, those in `void` without their bottom evidence.
    pub(crate) fn new(inner: &'a C, void: &'a BTreeSet<CellKey>) -> Self {
        WithoutBottom { inner, void }
    }
}

impl<C: CellInfos> CellInfos for WithoutBottom<'_, C> {
    fn get(&self, k: CellKey) -> Option<Info> {
        let i = self.inner.get(k)?;
        Some(if self.void.contains(&k) {
            i.without_bottom_evidence()
        } else {
            i
        })
    }

    fn column(&self, x: i64, ys: std::ops::Range<i64>, mut f: impl FnMut(CellKey, &Info)) {
        self.inner.column(x, ys, |k, i| {
            if self.void.contains(&k) {
                f(k, &i.without_bottom_evidence())
            } else {
                f(k, i)
            }
        })
    }
}

impl Info {
    /// The cell's water probability, as its evidence gives it.
    pub(crate) fn p(&self) -> f64 {
        self.p
    }

    /// Whether a body grows over the cell: water probability (without the bottom returns
    /// once they no longer count) at least `p_low`, or bottom returns that count.
    pub(crate) fn joins(&self, cfg: &WaterConfig) -> bool {
        self.p_evidence() >= cfg.p_low || self.has_bottom_evidence()
    }

    /// The info of an observed cell `c` whose water probability under `logs` is `p`, in a
    /// map of reference height `z_ref`.
    pub(crate) fn of(c: &CellStats, p: f64, logs: &FusionLogs, z_ref: f64) -> Info {
        let p_without_bottom = if c.ev.depth_n > 0 {
            c.ev.water_probability_without_bottom_in(logs)
        } else {
            p
        };
        Info {
            p,
            p_without_bottom,
            bottom_counts: true,
            elevation: c.mean_mm().map(|m| z_ref + m * 1e-3),
            std: c.range_bound_std_m().filter(|s| s.is_finite()),
            level: c.ev.level_mm().map(|mm| z_ref + mm * 1e-3),
            depth: Bottom::of(&c.ev, z_ref),
        }
    }
}

/// Whether a cell of water probability `p` seeds a body (a NaN probability does, as it
/// always has: it is not below `p_high`).
pub(crate) fn seeds_body(p: f64, cfg: &WaterConfig) -> bool {
    p >= cfg.p_high || p.is_nan()
}

/// The cells the body search reads: the [`Info`] of observed cells by key. A tile map's
/// cells are an ordered map of them; the mapper's window reads them from its layers.
pub(crate) trait CellInfos {
    /// The info of the cell `k`, if it was observed.
    fn get(&self, k: CellKey) -> Option<Info>;

    /// Calls `f` for every observed cell of column `x` with a row in `ys`, by increasing
    /// row.
    fn column(&self, x: i64, ys: std::ops::Range<i64>, f: impl FnMut(CellKey, &Info));
}

impl CellInfos for BTreeMap<CellKey, Info> {
    fn get(&self, k: CellKey) -> Option<Info> {
        BTreeMap::get(self, &k).copied()
    }

    fn column(&self, x: i64, ys: std::ops::Range<i64>, mut f: impl FnMut(CellKey, &Info)) {
        for (&k, i) in self.range(CellKey::new(x, ys.start)..CellKey::new(x, ys.end)) {
            f(k, i);
        }
    }
}

/// Connected components with hysteresis over `p`, grown from `seeds` (every cell that
/// seeds a body, in increasing key order): deterministic. Each with the seed it grew from,
/// its smallest.
pub(crate) fn components_seeded(
    cells: &impl CellInfos,
    seeds: impl IntoIterator<Item = CellKey>,
    cfg: &WaterConfig,
) -> Vec<(CellKey, Vec<CellKey>)> {
    let mut seen: BTreeSet<CellKey> = BTreeSet::new();
    let mut out = Vec::new();
    for k in seeds {
        if seen.contains(&k) {
            continue;
        }
        let mut body = vec![k];
        seen.insert(k);
        let mut q = VecDeque::from([k]);
        while let Some(c) = q.pop_front() {
            for d in N8 {
                let n = add(c, d);
                if !seen.contains(&n) && cells.get(n).is_some_and(|i| i.joins(cfg)) {
                    seen.insert(n);
                    body.push(n);
                    q.push_back(n);
                }
            }
        }
        body.sort_unstable();
        out.push((k, body));
    }
    out
}

/// Finds the water bodies of a tile map. `previous` are the bodies of the last snapshot
/// (empty for the first): ids follow the rule in the module documentation.
pub fn find_bodies(
    tiles: &TileMap,
    fusion: &Fusion,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> Result<Vec<WaterBody>> {
    fusion.validate()?;
    cfg.validate()?;
    let observed: Vec<(CellKey, CellStats)> = tiles.observed().collect();
    Ok(find_bodies_and_void(tiles, &observed, fusion, cfg, previous).0)
}

/// [`find_bodies`] given the tile map's observed cells, collected once by a caller that
/// reads them again (a scan of the tiles reads every cell slot, observed or not), and the
/// cells whose bottom returns the search found to be no evidence of water (see
/// [`bodies_from`]). The caller has validated `fusion` and `cfg`.
pub(crate) fn find_bodies_and_void(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    fusion: &Fusion,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> (Vec<WaterBody>, BTreeSet<CellKey>) {
    let info = infos(tiles, observed, fusion, cfg);
    let seeds = info
        .iter()
        .filter(|(_, i)| seeds_body(i.p, cfg))
        .map(|(&k, _)| k);
    bodies_from(&info, seeds, tiles.resolution(), cfg, previous)
}

/// The bodies a part of a map decides: the body search run on the part's observed cells,
/// as [`find_bodies_and_void`] runs it on the whole map (`hazard::region` drives
/// it region by region).
pub(crate) struct PartBodies {
    /// The bodies of the components the part knows whole (with `margin` cells around
    /// them) and that hold a wanted cell or lie within two cells of one, each with its
    /// first seed: `None` for a body whose surface could not be fitted.
    pub bodies: Vec<(CellKey, Option<WaterBody>)>,
    /// Cells whose water the part cannot decide: every cell a body can grow over that
    /// connects to a cell next to unknown ground, and the components not known whole.
    pub open: HashSet<CellKey>,
    /// The cells whose bottom returns the refinement took out of the evidence.
    pub void: BTreeSet<CellKey>,
}

/// The body search on a part of a map (`tiles`, its `observed` cells). `known(k, m)` says
/// whether every cell within `m` cells (Chebyshev) of `k` is known to the part; `wanted(k)`
/// whether a cell's record is asked for. A component is decided when every cell of it is
/// known `margin` cells deep; bodies too small for `min_body_area_m2` are none.
pub(crate) fn bodies_in_part(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    fusion: &Fusion,
    w: &WaterConfig,
    margin: i64,
    mut known: impl FnMut(CellKey, i64) -> bool,
    wanted: impl Fn(CellKey) -> bool,
) -> PartBodies {
    let res = tiles.resolution();
    let info = infos(tiles, observed, fusion, w);
    let seeds = info
        .iter()
        .filter(|(_, i)| seeds_body(i.p(), w))
        .map(|(&k, _)| k);
    let comps = components_seeded(&info, seeds, w);

    // Cells a body can grow over that connect to a cell next to an unknown tile.
    let mut open: HashSet<CellKey> = HashSet::new();
    let mut queue: VecDeque<CellKey> = VecDeque::new();
    for (&k, i) in &info {
        if i.joins(w) && !known(k, 1) && open.insert(k) {
            queue.push_back(k);
        }
    }
    while let Some(c) = queue.pop_front() {
        for d in N8 {
            let n = add(c, d);
            if !open.contains(&n) && info.get(&n).is_some_and(|i| i.joins(w)) {
                open.insert(n);
                queue.push_back(n);
            }
        }
    }
    // Components: decided when whole and their ring known.
    // Within two cells: a record reads its 5 × 5 window.
    let near_wanted = |k: CellKey| (-2..=2).any(|dy| (-2..=2).any(|dx| wanted(add(k, (dx, dy)))));
    let cell_area = res * res;
    let mut kept: Vec<(CellKey, Vec<CellKey>)> = Vec::new();
    // The bottom returns a whole component's refinement took out of the evidence (as the
    // whole map's search does, component by component).
    let mut void = BTreeSet::new();
    for (seed, comp) in comps {
        if !comp.iter().all(|&k| known(k, margin)) {
            open.extend(comp);
            continue;
        }
        if !comp.iter().any(|&k| near_wanted(k)) {
            continue;
        }
        // Each component the refinement leaves starts at its smallest seed key, as the
        // whole map's search starts it; too small a body is no body.
        for (first, comp) in refine_component(&info, seed, comp, res, w, &mut void) {
            if comp.len() as f64 * cell_area >= w.min_body_area_m2 {
                kept.push((first, comp));
            }
        }
    }
    let info = WithoutBottom::new(&info, &void);
    let bodies = kept
        .into_par_iter()
        .map(|(first, comp)| (first, body_of(0, comp, &info, res, w)))
        .collect();
    PartBodies { bodies, open, void }
}

/// The [`Info`] of the `observed` cells of `tiles` that the body search reads (see
/// [`find_bodies_and_void`]): the cells within blocks of 2n + 2 cells next to the block of a
/// cell a body can grow over.
pub(crate) fn infos(
    tiles: &TileMap,
    observed: &[(CellKey, CellStats)],
    fusion: &Fusion,
    cfg: &WaterConfig,
) -> BTreeMap<CellKey, Info> {
    let res = tiles.resolution();
    // Only the neighbourhood of possible water matters: the cells a body can grow over
    // (p ≥ p_low, or with bottom returns), their shore and the ground the occluder test
    // reads around it, all within 2n + 1 cells of a body cell for n = ⌈shore_radius /
    // resolution⌉. So only cells in
    // blocks of 2n + 2 cells next to such a cell's block are looked at (most of a map is
    // dry and far from water: every frame, this skips an ordered map of all of it).
    let b = 2 * cfg.shore_radius_cells(res) + 2;
    let block = |k: CellKey| (k.x.div_euclid(b), k.y.div_euclid(b));
    let logs = fusion.logs();
    let p: Vec<f64> = observed
        .iter()
        .map(|(_, c)| c.ev.water_probability_in(&logs))
        .collect();
    let mut near: HashSet<(i64, i64)> = HashSet::new();
    for ((k, c), &p) in observed.iter().zip(&p) {
        if p >= cfg.p_low || c.ev.depth_n > 0 {
            let (bx, by) = block(*k);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    near.insert((bx + dx, by + dy));
                }
            }
        }
    }
    observed
        .iter()
        .zip(p)
        .filter(|((k, _), _)| near.contains(&block(*k)))
        .map(|(&(k, c), p)| (k, Info::of(&c, p, &logs, tiles.z_ref())))
        .collect()
}

/// The water bodies of `cells` at resolution `res`, grown from `seeds` (every observed
/// cell that [seeds a body](seeds_body), in increasing key order), with ids after the
/// `previous` bodies. Reads only cells within 2n + 1 of a cell a body can grow over, n =
/// ⌈shore_radius / resolution⌉ (see [`find_bodies_and_void`]). Also the cells whose bottom
/// returns turned out to be no evidence of water (they lie no deeper than
/// `min_bottom_depth_m` under the surface their body found): the map publishes their
/// water probability without them.
pub(crate) fn bodies_from(
    cells: &impl CellInfos,
    seeds: impl IntoIterator<Item = CellKey>,
    res: f64,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> (Vec<WaterBody>, BTreeSet<CellKey>) {
    // Bottom returns that do not lie below the surface found by more than the lidar's
    // noise are what dry ground at the water's level gives: they are no evidence (module
    // documentation, section 1). Taking them away only shrinks or splits a component, and
    // a body's fit does not read what others took away, so each component is refined on
    // its own.
    let mut void = BTreeSet::new();
    let mut comps: Vec<(CellKey, Vec<CellKey>)> = components_seeded(cells, seeds, cfg)
        .into_iter()
        .flat_map(|(seed, comp)| refine_component(cells, seed, comp, res, cfg, &mut void))
        .collect();
    comps.sort_unstable_by_key(|&(seed, _)| seed);
    let cells = WithoutBottom {
        inner: cells,
        void: &void,
    };
    let comps: Vec<Vec<CellKey>> = comps.into_iter().map(|(_, c)| c).collect();
    let bodies = bodies_once(&cells, comps, res, cfg, previous);
    (bodies, void)
}

/// Most passes of [`refine_component`].
const MAX_BOTTOM_PASSES: usize = 8;

/// The components a first-pass component `comp` (grown from `seed`) leaves once the bottom
/// returns that lie no more than `min_bottom_depth_m` below its bodies' surfaces are taken
/// out of the evidence (added to `void`), found again until every bottom return left in a
/// body lies deeper, at most [`MAX_BOTTOM_PASSES`] times. Each with the seed it grew from.
pub(crate) fn refine_component(
    cells: &impl CellInfos,
    seed: CellKey,
    comp: Vec<CellKey>,
    res: f64,
    cfg: &WaterConfig,
    void: &mut BTreeSet<CellKey>,
) -> Vec<(CellKey, Vec<CellKey>)> {
    if !comp
        .iter()
        .any(|&k| cells.get(k).is_some_and(|i| i.depth.is_some()))
    {
        return vec![(seed, comp)];
    }
    let min_depth = cfg.min_bottom_depth();
    let cell_area = res * res;
    let all = comp.clone();
    let mut comps = vec![(seed, comp)];
    for _ in 0..MAX_BOTTOM_PASSES {
        let shallow: Vec<CellKey> = {
            let cells = WithoutBottom {
                inner: cells,
                void: &*void,
            };
            comps
                .iter()
                .filter(|(_, c)| c.len() as f64 * cell_area >= cfg.min_body_area_m2)
                .filter_map(|(_, c)| body_of(0, c.clone(), &cells, res, cfg))
                .flat_map(|b| {
                    b.cells
                        .into_iter()
                        .zip(b.cell_depth_m)
                        .filter(|(_, d)| d.is_finite() && f64::from(*d) <= min_depth)
                        .map(|(k, _)| k)
                })
                .collect()
        };
        let before = void.len();
        void.extend(shallow);
        if void.len() == before {
            break;
        }
        let cells = WithoutBottom {
            inner: cells,
            void: &*void,
        };
        let seeds = all.iter().copied().filter(|&k| {
            cells
                .get(k)
                .is_some_and(|i| seeds_body(i.p_evidence(), cfg))
        });
        comps = components_seeded(&cells, seeds, cfg);
    }
    comps
}

/// The bodies of components `comps` (in increasing order of their seeds): ids, and each
/// body's shore, surface and depth.
fn bodies_once(
    cells: &impl CellInfos,
    comps: Vec<Vec<CellKey>>,
    res: f64,
    cfg: &WaterConfig,
    previous: &[WaterBody],
) -> Vec<WaterBody> {
    let cell_area = res * res;
    let comps: Vec<Vec<CellKey>> = comps
        .into_iter()
        .filter(|b| b.len() as f64 * cell_area >= cfg.min_body_area_m2)
        .collect();
    let ids = assign_ids(&comps, previous);
    let mut bodies = Vec::with_capacity(comps.len());
    for (body, id) in comps.into_iter().zip(ids) {
        if let Some(b) = body_of(id, body, cells, res, cfg) {
            bodies.push(b);
        }
    }
    bodies
}

/// Ids for new components given the previous bodies (module documentation, "Ids").
pub(super) fn assign_ids(comps: &[Vec<CellKey>], previous: &[WaterBody]) -> Vec<u32> {
    let owner: HashMap<CellKey, usize> = previous
        .iter()
        .enumerate()
        .flat_map(|(i, b)| b.cells.iter().map(move |&k| (k, i)))
        .collect();
    let mut next = previous.iter().map(|b| b.id).max().unwrap_or(0) + 1;
    // (component, ancestor, overlap) of every component that overlaps a previous body.
    let mut claims: Vec<(usize, usize, usize)> = Vec::new();
    for (ci, cells) in comps.iter().enumerate() {
        let mut overlap: BTreeMap<usize, usize> = BTreeMap::new();
        for k in cells {
            if let Some(&i) = owner.get(k) {
                *overlap.entry(i).or_default() += 1;
            }
        }
        // The largest ancestor; ties to the smaller id.
        if let Some((&a, &n)) = overlap.iter().max_by(|(a, _), (b, _)| {
            previous[**a]
                .cells
                .len()
                .cmp(&previous[**b].cells.len())
                .then(previous[**b].id.cmp(&previous[**a].id))
        }) {
            claims.push((ci, a, n));
        }
    }
    let mut ids: Vec<Option<u32>> = vec![None; comps.len()];
    // Per ancestor, the claim with the largest overlap wins (ties: first component).
    let mut best: BTreeMap<usize, (usize, usize)> = BTreeMap::new();
    for &(ci, a, n) in &claims {
        let e = best.entry(a).or_insert((ci, n));
        if n > e.1 {
            *e = (ci, n);
        }
    }
    for (a, (ci, _)) in best {
        ids[ci] = Some(previous[a].id);
    }
    ids.into_iter()
        .map(|id| {
            id.unwrap_or_else(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}
