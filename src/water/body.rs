//! One body's fit: its shore, the far shore where its own is poorly seen, the surface
//! through them, and each cell's depth below it (sections 2 and 3 of the module
//! documentation).

use std::collections::{BTreeSet, HashMap, VecDeque};

use super::search::{add, CellInfos, Info, N4};
use super::{
    mesh, surface, DepthStats, ShoreSample, Surface, SurfaceSource, WaterBody, WaterConfig,
};
use crate::grid::{centre_of, CellKey};

/// The body of the component `cells` (sorted) with id `id`: shore, surface, depths; `None`
/// when no surface can be fitted. Reads the cells within 2n of the component, n =
/// ⌈shore_radius / resolution⌉ (the occluder test's ground, [`ground_near`]).
pub(crate) fn body_of(
    id: u32,
    cells: Vec<CellKey>,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Option<WaterBody> {
    let set: BTreeSet<CellKey> = cells.iter().copied().collect();
    let shore = shore_of(&set, info, res, cfg);
    let ground = ground_near(&set, &shore.keys, info, res, cfg);
    let kept = surface::reject_spilling(
        &shore.samples,
        &surface::reject_occluders(&shore.samples, &ground, cfg),
        cfg,
    );
    let samples = surface_samples(&cells, &set, &shore, &kept, info, res, cfg);
    let (fit, samples) = fit_surface(&cells, &set, shore.few_reliable, samples, info, res, cfg)?;
    let surface = fit.model.evaluator();
    let (cell_depth_m, depth) = depths(&cells, &surface, info, res);
    let cell_area = res * res;
    let mut body = WaterBody {
        id,
        area_m2: cells.len() as f64 * cell_area,
        cells,
        volume_m3: None,
        depth,
        shore_samples: shore.samples.len(),
        shore_samples_kept: kept.len(),
        surface_samples: samples.points.len(),
        surface_source: samples.source,
        surface: fit.model,
        level_residual_m: fit.level_residual_m,
        delaunay_residual_m: fit.delaunay_residual_m,
        cell_depth_m,
    };
    if body.depth.unknown_cells == 0 {
        let m = mesh::body_mesh(&body, res, &surface);
        body.volume_m3 = Some(m.volume());
    }
    Some(body)
}

/// A body's shore: its cells and their samples (the elevation less the bank's rise), in
/// the same order.
struct Shore {
    keys: Vec<CellKey>,
    samples: Vec<ShoreSample>,
    /// Fewer reliably measured shore cells than `min_shore_samples`: every shore cell is
    /// kept, and the level is weighted by the inverse of each cell's variance.
    few_reliable: bool,
}

/// The samples a surface is fitted to, their cells (in the same order), and where they
/// came from.
struct Samples {
    points: Vec<ShoreSample>,
    keys: Vec<CellKey>,
    source: SurfaceSource,
}

/// A surface sample at the centre of cell `k`.
fn sample(res: f64, k: CellKey, z: f64) -> ShoreSample {
    let (x, y) = centre_of(res, k);
    ShoreSample { x, y, z }
}

/// The shore of the body `set`: observed dry cells with an elevation, 4-adjacent to the
/// body, outside its small holes; only the reliably measured ones when there are enough.
fn shore_of(set: &BTreeSet<CellKey>, info: &impl CellInfos, res: f64, cfg: &WaterConfig) -> Shore {
    let hole_cells = (cfg.min_body_area_m2 / (res * res)).ceil() as usize;
    let mut shore_keys: BTreeSet<CellKey> = BTreeSet::new();
    for &k in set {
        for d in N4 {
            let n = add(k, d);
            if !set.contains(&n)
                && info
                    .get(n)
                    .is_some_and(|i| i.elevation.is_some() && i.depth.is_none())
            {
                shore_keys.insert(n);
            }
        }
    }
    shore_keys.retain(|&k| !in_small_hole(set, k, hole_cells));
    // Only reliably measured shore cells, when there are enough of them: a far cell seen by
    // a few stereo points has an elevation σ of decimetres to metres and would pull the
    // level with it.
    let reliable: Vec<CellKey> = shore_keys
        .iter()
        .copied()
        .filter(|&n| {
            info.get(n)
                .and_then(|i| i.std)
                .is_some_and(|s| s <= cfg.shore_max_std_m)
        })
        .collect();
    let few_reliable = reliable.len() < cfg.min_shore_samples.max(1);
    let keys: Vec<CellKey> = if few_reliable {
        shore_keys.into_iter().collect()
    } else {
        reliable
    };
    let samples = keys
        .iter()
        .map(|&k| {
            let z = info.get(k).and_then(|i| i.elevation).unwrap_or(f64::NAN);
            sample(res, k, z - bank_rise(set, k, z, info, res, cfg))
        })
        .collect();
    Shore {
        keys,
        samples,
        few_reliable,
    }
}

/// The samples the surface is fitted to, their cells and where they came from: the shore
/// samples `kept` by the occluder and spill tests when there are enough; else the far
/// shore; else the cues' water levels; else what is kept of the shore; else the body's own
/// elevations (section 2 of the module documentation).
fn surface_samples(
    cells: &[CellKey],
    set: &BTreeSet<CellKey>,
    shore: &Shore,
    kept: &[usize],
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Samples {
    let of_kept = || Samples {
        points: kept.iter().map(|&i| shore.samples[i]).collect(),
        keys: kept.iter().map(|&i| shore.keys[i]).collect(),
        source: SurfaceSource::Shore,
    };
    let of_cells = |z: &dyn Fn(&Info) -> Option<f64>, source| {
        let at: Vec<(CellKey, f64)> = cells
            .iter()
            .filter_map(|&k| info.get(k).and_then(|i| z(&i)).map(|z| (k, z)))
            .collect();
        Samples {
            points: at.iter().map(|&(k, z)| sample(res, k, z)).collect(),
            keys: at.iter().map(|&(k, _)| k).collect(),
            source,
        }
    };
    if kept.len() >= cfg.min_shore_samples.max(1) {
        return of_kept();
    }
    if let Some((points, keys)) = far_shore(set, info, res, cfg) {
        return Samples {
            points,
            keys,
            source: SurfaceSource::FarShore,
        };
    }
    let levels = of_cells(&|i| i.level, SurfaceSource::WaterLevels);
    if !levels.points.is_empty() {
        levels
    } else if !kept.is_empty() {
        of_kept()
    } else {
        of_cells(&|i| i.elevation, SurfaceSource::CellElevations)
    }
}

/// The surface through `samples`. When they are the shore and it has few reliably measured
/// cells (`few_reliable`), every shore cell counts, weighted by the inverse of its
/// elevation variance, so that the reliable few still decide the level; samples of σ of
/// metres make no surface, so the model is level. A shore that is neither level nor a
/// smooth surface (the fit fell back to its lowest samples), or a triangulated surface that
/// some body cells lie more than `shore_radius_m` outside of (beyond its samples' hull it
/// is carried on level, a guess), may be a stretch of a sloping stream seen in one place:
/// the far shore, where there is one, adds the rest of its length. Gives the fit and the
/// samples it went through.
fn fit_surface(
    cells: &[CellKey],
    set: &BTreeSet<CellKey>,
    few_reliable: bool,
    samples: Samples,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Option<(surface::Fit, Samples)> {
    let mut samples = samples;
    let shore = samples.source == SurfaceSource::Shore;
    let fit = if few_reliable && shore {
        let sigma: Vec<f64> = samples
            .keys
            .iter()
            .map(|&k| info.get(k).and_then(|i| i.std).unwrap_or(f64::INFINITY))
            .collect();
        surface::weighted_level(&samples.points, &sigma)?
    } else {
        surface::fit(
            &samples.points,
            &shore_constraints(&samples.keys),
            cfg,
            median_std(&samples.keys, info),
        )?
    };
    let extrapolated = || {
        let ev = fit.model.evaluator();
        cells.iter().any(|&k| {
            let (x, y) = centre_of(res, k);
            ev.outside_hull_m(x, y) > cfg.shore_radius_m
        })
    };
    let undecided = !few_reliable && shore && (!fit.decided || extrapolated());
    let Some((far, far_keys)) = undecided.then(|| far_shore(set, info, res, cfg)).flatten() else {
        return Some((fit, samples));
    };
    let own: BTreeSet<CellKey> = samples.keys.iter().copied().collect();
    for (s, k) in far.into_iter().zip(far_keys) {
        if !own.contains(&k) {
            samples.points.push(s);
            samples.keys.push(k);
        }
    }
    let noise = median_std(&samples.keys, info);
    let fit = surface::fit(
        &samples.points,
        &shore_constraints(&samples.keys),
        cfg,
        noise,
    )?;
    samples.source = SurfaceSource::ShoreAndFarShore;
    Some((fit, samples))
}

/// Each cell's bottom returns, moved from the levels the cue corrected them against onto
/// the body's `surface` (NaN where a cell has none), and the body's depth statistics.
fn depths(
    cells: &[CellKey],
    surface: &Surface,
    info: &impl CellInfos,
    res: f64,
) -> (Vec<f32>, DepthStats) {
    let cell_depth_m: Vec<f32> = cells
        .iter()
        .map(|&k| {
            info.get(k).and_then(|i| i.depth).map_or(f32::NAN, |d| {
                let (x, y) = centre_of(res, k);
                d.below(surface.at(x, y)) as f32
            })
        })
        .collect();
    let known: Vec<f64> = cell_depth_m
        .iter()
        .filter(|d| d.is_finite())
        .map(|&d| d as f64)
        .collect();
    let cell_area = res * res;
    let depth = DepthStats {
        known_cells: known.len(),
        unknown_cells: cells.len() - known.len(),
        known_area_m2: known.len() as f64 * cell_area,
        unknown_area_m2: (cells.len() - known.len()) as f64 * cell_area,
        mean_m: (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64),
        max_m: known.iter().copied().reduce(f64::max),
    };
    (cell_depth_m, depth)
}

/// The median elevation σ of the cells `keys` (0 when none has one).
fn median_std(keys: &[CellKey], info: &impl CellInfos) -> f64 {
    surface::median(
        keys.iter()
            .filter_map(|&k| info.get(k).and_then(|i| i.std))
            .collect(),
    )
    .unwrap_or(0.0)
}

/// Constraint edges of a surface fit: between every two 8-adjacent sample cells, each
/// pair once.
fn shore_constraints(keys: &[CellKey]) -> Vec<[usize; 2]> {
    let index: HashMap<CellKey, usize> = keys.iter().enumerate().map(|(i, &k)| (k, i)).collect();
    let mut constraints = Vec::new();
    for (i, &k) in keys.iter().enumerate() {
        for d in [(1, 0), (0, 1), (1, 1), (1, -1)] {
            if let Some(&j) = index.get(&add(k, d)) {
                constraints.push([i, j]);
            }
        }
    }
    constraints
}

/// The shore of a body seen across water no sensor measured (module documentation,
/// section 2): from each body cell, in each of the four directions, the first reliably
/// measured dry cell within `shore_radius_m` past at least one cell that is unobserved or
/// measured unreliably; kept when the occluder test keeps it, it stands no more than
/// `occluder_height_m` below the median of the others within `shore_radius_m`, and the
/// spill test keeps it. `None` when fewer than `min_shore_samples` are kept.
fn far_shore(
    set: &BTreeSet<CellKey>,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Option<(Vec<ShoreSample>, Vec<CellKey>)> {
    let firm = |i: &Info| {
        i.elevation.is_some()
            && i.depth.is_none()
            && i.std.is_some_and(|s| s <= cfg.shore_max_std_m)
    };
    let n = cfg.shore_radius_cells(res);
    let mut keys: BTreeSet<CellKey> = BTreeSet::new();
    for &k in set {
        for d in N4 {
            for j in 1..=n {
                let c = add(k, (d.0 * j, d.1 * j));
                if set.contains(&c) {
                    break;
                }
                if let Some(i) = info.get(c) {
                    if firm(&i) {
                        if j > 1 {
                            keys.insert(c);
                        }
                        break;
                    }
                }
            }
        }
    }
    let keys: Vec<CellKey> = keys.into_iter().collect();
    let shore: Vec<ShoreSample> = keys
        .iter()
        .map(|&k| {
            let (x, y) = centre_of(res, k);
            let z = info.get(k).and_then(|i| i.elevation).unwrap_or(f64::NAN);
            ShoreSample { x, y, z }
        })
        .collect();
    let ground = ground_near(set, &keys, info, res, cfg);
    let medians = surface::local_medians(&shore, cfg.shore_radius_m);
    let not_low: Vec<usize> = surface::reject_occluders(&shore, &ground, cfg)
        .into_iter()
        .filter(|&i| medians[i].z - shore[i].z <= cfg.occluder_height_m)
        .collect();
    let kept = surface::reject_spilling(&shore, &not_low, cfg);
    (kept.len() >= cfg.min_shore_samples.max(1)).then(|| {
        (
            kept.iter().map(|&i| shore[i]).collect(),
            kept.iter().map(|&i| keys[i]).collect(),
        )
    })
}

/// Whether the dry cell `k` lies in a hole of the body `set` of at most `max_cells` cells:
/// the cells not in the body that `k` reaches through 4-neighbours are at most that many.
/// Visits at most `max_cells + 1` cells.
pub(super) fn in_small_hole(set: &BTreeSet<CellKey>, k: CellKey, max_cells: usize) -> bool {
    let mut seen: BTreeSet<CellKey> = BTreeSet::from([k]);
    let mut queue = VecDeque::from([k]);
    while let Some(c) = queue.pop_front() {
        for d in N4 {
            let n = add(c, d);
            if !set.contains(&n) && seen.insert(n) {
                if seen.len() > max_cells {
                    return false;
                }
                queue.push_back(n);
            }
        }
    }
    seen.len() <= max_cells
}

/// How far the shore cell `k` (elevation `z`) stands above the water's edge beside it: half
/// a cell of the bank's rise away from the water, `g·res/2`, where `g` is the mean over the
/// directions in which `k` has water on one side and a reliably measured dry cell on the
/// other of `(z_behind − z)/res`, clamped to `0..=max_bank_slope`. 0 where no direction
/// has both. See the module documentation.
fn bank_rise(
    set: &BTreeSet<CellKey>,
    k: CellKey,
    z: f64,
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> f64 {
    if !z.is_finite() {
        return 0.0;
    }
    let (mut sum, mut n) = (0.0, 0u32);
    for d in N4 {
        let behind = add(k, (-d.0, -d.1));
        if !set.contains(&add(k, d)) || set.contains(&behind) {
            continue;
        }
        let Some(i) = info.get(behind) else { continue };
        if i.depth.is_some() || !i.std.is_some_and(|s| s <= cfg.shore_max_std_m) {
            continue;
        }
        if let Some(zb) = i.elevation {
            sum += ((zb - z) / res).clamp(0.0, cfg.max_bank_slope);
            n += 1;
        }
    }
    if n == 0 {
        return 0.0;
    }
    sum / n as f64 * res / 2.0
}

/// Dry, reliably measured cells (elevation σ ≤ `shore_max_std_m`, water probability below
/// `p_low`) within about `shore_radius_m` of the shore cells: the occluder test's reference
/// for the ground beside the shore. Visits only the blocks of cells around the shore.
fn ground_near(
    body: &BTreeSet<CellKey>,
    shore: &[CellKey],
    info: &impl CellInfos,
    res: f64,
    cfg: &WaterConfig,
) -> Vec<surface::ShoreSample> {
    let n = cfg.shore_radius_cells(res);
    let blocks: BTreeSet<(i64, i64)> = shore
        .iter()
        .flat_map(|k| {
            let (bx, by) = (k.x.div_euclid(n), k.y.div_euclid(n));
            (-1..=1).flat_map(move |dx| (-1..=1).map(move |dy| (bx + dx, by + dy)))
        })
        .collect();
    let shore: BTreeSet<CellKey> = shore.iter().copied().collect();
    let mut out = Vec::new();
    for (bx, by) in blocks {
        for x in bx * n..(bx + 1) * n {
            info.column(x, by * n..(by + 1) * n, |k, i| {
                let Some(z) = i.elevation else { return };
                let reliable = i.std.is_some_and(|s| s <= cfg.shore_max_std_m);
                if reliable && i.p < cfg.p_low && !body.contains(&k) && !shore.contains(&k) {
                    let (x, y) = centre_of(res, k);
                    out.push(surface::ShoreSample { x, y, z });
                }
            });
        }
    }
    out
}
