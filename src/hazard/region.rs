//! The water stage of a merged map split by region, each region read with a halo of tiles
//! around it, joined into the map [`HazardMap::from_tiles`] gives for the whole, byte for
//! byte.
//!
//! ## What a cell's record reads
//!
//! A cell's record (class, hazard, z, depth, water, σ, hits) reads the cell itself, whether
//! its eight neighbours are water (the step and slope tests read the dry ones), and, for a
//! water cell, its body's surface and depth. A body is a connected component: unbounded.
//! What a body's fit reads around its cells: its 4-adjacent shore, the bank cell behind a
//! shore cell (2 cells out), the far shore (up to n cells out, n = ⌈shore_radius /
//! resolution⌉), and the occluder test's ground, blocks of n cells around the shore (up to
//! 2n cells from the body). So a body's [`WaterBody`] is a function of its cells and of the
//! observed cells within 2n of them; [`MARGIN`] adds two cells to that.
//!
//! ## A region's finish
//!
//! [`finish_region`] reads the tiles within `halo` tiles (Chebyshev) of the region's tiles
//! (the *known* tiles; so are the tiles outside the whole map's bounds, which hold no
//! cells) and runs the body search on them. Then:
//!
//! - a component none of whose cells lies within 2n + 2 cells of an unknown tile is whole,
//!   and its fit reads only known cells: it is the whole-map body, cell for cell and bit for
//!   bit (the search grows components from seeds in key order, so a component's first seed
//!   is its smallest seed key wherever the search runs);
//! - any other component, and every cell a body can grow over that is connected through
//!   such cells to a cell next to an unknown tile, is *open*: whether and how it is water
//!   is not decided by this region;
//! - a region tile is decided when none of its observed cells has an open cell in its 5 × 5
//!   window (what its record reads); its records are those of the whole map. The others are returned as
//!   undecided.
//!
//! Bodies go to the region holding their first seed, so each is returned once. Their ids
//! in the whole map count up from 1 in the order of their first seeds (a body whose surface
//! cannot be fitted takes an id and is dropped); [`join_regions`] gives them in that order.
//!
//! [`finish_by_regions`] is the driver: regions of `side × side` tiles, each finished with
//! the halo asked for; the undecided tiles of a region are finished again, as a region of
//! their own, with twice the halo, until none is left. A halo as wide as the map's bounds
//! knows every tile, so this ends; a body larger than the first halo is finished with a
//! halo that holds it and its ring of 2n + 2 cells.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use rayon::prelude::*;

use super::{cell_records, water_surface, Class, Hazard, HazardConfig, HazardMap, MapCell};
use crate::error::{Error, Result};
use crate::grid::{ByteReader, CellKey, CellStats, TileMap, TILE_CELLS};
use crate::water::{
    bodies_in_part, DepthStats, ShoreSample, SurfaceModel, SurfaceSource, WaterBody,
};

/// A tile key `(tx, ty)`: the tile of cells `tx·64 ..< tx·64 + 64` along x, likewise y.
pub type TileKey = (i64, i64);

/// Cells around a body, beyond the 2n its fit reads (module documentation), that must be
/// known for a region to decide it.
const MARGIN: i64 = 2;

/// What a region's finish decided (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct RegionMap {
    /// Cell edge length, metres.
    pub resolution: f64,
    /// The region's decided tiles that hold observed cells, in increasing key order.
    pub tiles: Vec<TileKey>,
    /// The records of the observed cells of `tiles`, in the whole map's order.
    pub cells: Vec<MapCell>,
    /// The bodies whose first seed lies in `tiles`, by first seed key: `None` for a body
    /// whose surface could not be fitted (it takes an id in the whole map, and no cells).
    /// Their `id` is 0 until [`join_regions`] numbers them.
    pub bodies: Vec<(CellKey, Option<WaterBody>)>,
    /// The region's tiles holding observed cells that it could not decide.
    pub undecided: Vec<TileKey>,
    /// Tiles of the map the finish read (the region's and its halo's).
    pub tiles_read: usize,
}

fn tile_of(k: CellKey) -> TileKey {
    (k.x.div_euclid(TILE_CELLS), k.y.div_euclid(TILE_CELLS))
}

/// Which tiles a region's finish knows: those within `halo` of a region tile, and those
/// outside the map's bounds.
struct Domain {
    region: BTreeSet<TileKey>,
    halo: i64,
    bounds: (TileKey, TileKey),
    /// Whether the tiles of a range `(x0, x1, y0, y1)` are all known.
    ranges: HashMap<(i64, i64, i64, i64), bool>,
}

impl Domain {
    fn in_bounds(&self, t: TileKey) -> bool {
        let (lo, hi) = self.bounds;
        (lo.0..=hi.0).contains(&t.0) && (lo.1..=hi.1).contains(&t.1)
    }

    /// Whether `t` lies within `halo` of a region tile.
    fn near_region(&self, t: TileKey) -> bool {
        let lo = (t.0.saturating_sub(self.halo), i64::MIN);
        let hi = (t.0.saturating_add(self.halo), i64::MAX);
        self.region
            .range(lo..=hi)
            .any(|r| r.1.abs_diff(t.1) <= self.halo as u64)
    }

    fn known(&self, t: TileKey) -> bool {
        !self.in_bounds(t) || self.near_region(t)
    }

    /// Whether every cell within `m` cells (Chebyshev) of `k` lies in a known tile.
    fn deep(&mut self, k: CellKey, m: i64) -> bool {
        let t0 = tile_of(CellKey::new(k.x.saturating_sub(m), k.y.saturating_sub(m)));
        let t1 = tile_of(CellKey::new(k.x.saturating_add(m), k.y.saturating_add(m)));
        let key = (t0.0, t1.0, t0.1, t1.1);
        if let Some(&d) = self.ranges.get(&key) {
            return d;
        }
        let d = (t0.0..=t1.0).all(|x| (t0.1..=t1.1).all(|y| self.known((x, y))));
        self.ranges.insert(key, d);
        d
    }
}

/// The water stage of the region `region` (tile keys) of a merged map whose tile keys lie
/// within `bounds` (inclusive): the records and bodies [`HazardMap::from_tiles`] of the
/// whole map gives for the region's cells, for every tile it can decide, and the tiles it
/// cannot (module documentation). `tiles` must hold every tile of the map within `halo`
/// tiles of the region (it may hold more: only those are read); `halo` is at least 1. The
/// fusion rule is measured on `tiles`' false alarms ([`HazardConfig::measured_on`]); a cut
/// of a map holds none ([`TileMap::select`]), so give a region cut from a merged map the
/// whole build's ([`TileMap::add_false_alarms`]) for the map the whole build gives.
pub fn finish_region(
    tiles: &TileMap,
    region: &[TileKey],
    halo: i64,
    bounds: (TileKey, TileKey),
    cfg: &HazardConfig,
) -> Result<RegionMap> {
    let cfg = &cfg.measured_on(tiles);
    cfg.validate()?;
    if halo < 1 {
        return Err(Error::invalid(
            "region halo",
            format!("{halo} tiles; a region reads at least 1 tile around it"),
        ));
    }
    let (lo, hi) = bounds;
    if lo.0 > hi.0 || lo.1 > hi.1 {
        return Err(Error::invalid(
            "map bounds",
            format!("{lo:?}..={hi:?} is empty"),
        ));
    }
    let region: BTreeSet<TileKey> = region.iter().copied().collect();
    let mut dom = Domain {
        region: region.clone(),
        halo,
        bounds,
        ranges: HashMap::new(),
    };
    if let Some(t) = tiles.tile_keys().into_iter().find(|&t| !dom.in_bounds(t)) {
        return Err(Error::invalid(
            "map bounds",
            format!("tile {t:?} lies outside the bounds {lo:?}..={hi:?} given for the map"),
        ));
    }
    let sub = tiles.select(|t| dom.near_region(t));
    let res = sub.resolution();
    let observed: Vec<(CellKey, CellStats)> = sub.observed().collect();
    let in_region = |k: CellKey| region.contains(&tile_of(k));
    let region_tiles: BTreeSet<TileKey> = observed
        .iter()
        .map(|(k, _)| tile_of(*k))
        .filter(|t| region.contains(t))
        .collect();
    let mut out = RegionMap {
        resolution: res,
        tiles: Vec::new(),
        cells: Vec::new(),
        bodies: Vec::new(),
        undecided: Vec::new(),
        tiles_read: sub.tile_count(),
    };
    // A halo as wide as the map's bounds knows every tile: the whole map's search.
    let across = hi.0.saturating_sub(lo.0).max(hi.1.saturating_sub(lo.1));
    let whole = halo >= across && region.iter().any(|&t| dom.in_bounds(t));
    // A NaN water probability (a validated fusion rule gives none) seeds a body without
    // joining one, and whether it is read depends on cells up to two blocks away: only the
    // whole map decides it.
    let logs = cfg.fusion.logs();
    if !whole
        && observed
            .iter()
            .any(|(_, c)| c.ev.water_probability_in(&logs).is_nan())
    {
        out.undecided = region_tiles.into_iter().collect();
        return Ok(out);
    }

    let margin = 2 * cfg.water.shore_radius_cells(res) + MARGIN;
    let part = bodies_in_part(
        &sub,
        &observed,
        &cfg.fusion,
        &cfg.water,
        margin,
        |k, m| dom.deep(k, m),
        in_region,
    );
    let (bodies, open, void) = (part.bodies, part.open, part.void);
    let water = water_surface(bodies.iter().filter_map(|(_, b)| b.as_ref()), res);

    let undecided: BTreeSet<TileKey> = observed
        .iter()
        .map(|(k, _)| *k)
        .filter(|&k| in_region(k))
        // Its record reads the dry cells of its 5 × 5 window (the σ's gradient).
        .filter(|&k| {
            (-2..=2).any(|dy| (-2..=2).any(|dx| open.contains(&CellKey::new(k.x + dx, k.y + dy))))
        })
        .map(tile_of)
        .collect();
    let decided = |t: TileKey| region.contains(&t) && !undecided.contains(&t);
    out.cells = cell_records(&sub, &observed, cfg, &water, &void, |k| decided(tile_of(k)));
    out.bodies = bodies
        .into_iter()
        .filter(|(first, _)| decided(tile_of(*first)))
        .collect();
    out.tiles = region_tiles
        .iter()
        .copied()
        .filter(|t| !undecided.contains(t))
        .collect();
    out.undecided = undecided.into_iter().collect();
    Ok(out)
}

/// The whole map from regions that decided every tile between them, each tile once (a
/// tile one region left undecided is decided by another, a re-finish): their records in
/// the map's order, their bodies numbered from 1 in the order of their first
/// seeds. Equal to [`HazardMap::from_tiles`] of the merged map when the regions came from
/// [`finish_region`] over it and cover its tiles.
pub fn join_regions(parts: Vec<RegionMap>) -> Result<HazardMap> {
    let Some(first) = parts.first() else {
        return Err(Error::invalid("regions", "no regions to join"));
    };
    let resolution = first.resolution;
    let mut owner: BTreeMap<TileKey, usize> = BTreeMap::new();
    for (i, p) in parts.iter().enumerate() {
        if p.resolution.to_bits() != resolution.to_bits() {
            return Err(Error::invalid(
                "regions",
                format!(
                    "resolutions differ: {} m and {} m",
                    resolution, p.resolution
                ),
            ));
        }
        for &t in &p.tiles {
            if owner.insert(t, i).is_some() {
                return Err(Error::invalid(
                    "regions",
                    format!("tile {t:?} finished by two regions"),
                ));
            }
        }
    }
    // A tile one region left undecided must be decided by another (a re-finish).
    if let Some(t) = parts
        .iter()
        .flat_map(|p| &p.undecided)
        .find(|t| !owner.contains_key(*t))
    {
        return Err(Error::invalid(
            "regions",
            format!("tile {t:?} undecided by every region: finish it with a larger halo first"),
        ));
    }
    let mut cells: Vec<(TileKey, MapCell)> = Vec::new();
    let mut bodies: Vec<(CellKey, Option<WaterBody>)> = Vec::new();
    for (i, p) in parts.into_iter().enumerate() {
        for c in p.cells {
            let t = tile_of(c.key);
            if owner.get(&t) != Some(&i) {
                return Err(Error::invalid(
                    "regions",
                    format!("cell {:?} outside the region's decided tiles", c.key),
                ));
            }
            cells.push((t, c));
        }
        for (k, b) in p.bodies {
            if owner.get(&tile_of(k)) != Some(&i) {
                return Err(Error::invalid(
                    "regions",
                    format!("body seeded at {k:?} outside the region's decided tiles"),
                ));
            }
            bodies.push((k, b));
        }
    }
    // Stable: a tile's cells keep their order.
    cells.sort_by_key(|(t, _)| *t);
    bodies.sort_by_key(|(k, _)| *k);
    if let Some(w) = bodies.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(Error::invalid(
            "regions",
            format!("two bodies seeded at {:?}", w[0].0),
        ));
    }
    let bodies = bodies
        .into_iter()
        .zip(1u32..)
        .filter_map(|((_, b), id)| b.map(|b| WaterBody { id, ..b }))
        .collect();
    Ok(HazardMap {
        resolution,
        cells: cells.into_iter().map(|(_, c)| c).collect(),
        bodies,
    })
}

/// What [`finish_by_regions`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SplitStats {
    /// Regions of the first round.
    pub regions: usize,
    /// Calls of [`finish_region`], the first round's and the re-finishes.
    pub finishes: usize,
    /// Tiles finished again with a larger halo (counted once per re-finish).
    pub refinished_tiles: usize,
    /// The largest halo used, tiles.
    pub largest_halo: i64,
    /// The most tiles one call read.
    pub most_tiles_read: usize,
}

/// The water stage of `tiles` by regions of `side × side` tiles, each finished with a halo
/// of `halo` tiles, the tiles a region cannot decide finished again with twice the halo
/// until all are decided (module documentation); joined, the map
/// [`HazardMap::from_tiles`] gives.
pub fn finish_by_regions(
    tiles: &TileMap,
    cfg: &HazardConfig,
    side: i64,
    halo: i64,
) -> Result<(HazardMap, SplitStats)> {
    if side < 1 {
        return Err(Error::invalid(
            "region side",
            format!("{side} tiles; a region is at least 1 tile"),
        ));
    }
    let keys = tiles.tile_keys();
    let Some(&first) = keys.first() else {
        cfg.validate()?;
        return Ok((HazardMap::from_tiles(tiles, cfg)?, SplitStats::default()));
    };
    let bounds = keys.iter().fold((first, first), |(lo, hi), &t| {
        (
            (lo.0.min(t.0), lo.1.min(t.1)),
            (hi.0.max(t.0), hi.1.max(t.1)),
        )
    });
    let extent = (bounds.1 .0 - bounds.0 .0).max(bounds.1 .1 - bounds.0 .1);
    let mut regions: BTreeMap<TileKey, Vec<TileKey>> = BTreeMap::new();
    for &t in &keys {
        regions
            .entry((t.0.div_euclid(side), t.1.div_euclid(side)))
            .or_default()
            .push(t);
    }
    let mut stats = SplitStats {
        regions: regions.len(),
        ..SplitStats::default()
    };
    let mut work: Vec<(Vec<TileKey>, i64)> = regions.into_values().map(|r| (r, halo)).collect();
    let mut parts = Vec::new();
    while !work.is_empty() {
        let done: Vec<(RegionMap, i64)> = work
            .par_iter()
            .map(|(r, h)| Ok((finish_region(tiles, r, *h, bounds, cfg)?, *h)))
            .collect::<Result<_>>()?;
        work = Vec::new();
        for (p, h) in done {
            stats.finishes += 1;
            stats.largest_halo = stats.largest_halo.max(h);
            stats.most_tiles_read = stats.most_tiles_read.max(p.tiles_read);
            if !p.undecided.is_empty() {
                if h >= extent {
                    return Err(Error::invalid(
                        "regions",
                        format!(
                            "{} tiles undecided with a halo of {h} tiles over a map {extent} \
                             tiles across",
                            p.undecided.len()
                        ),
                    ));
                }
                stats.refinished_tiles += p.undecided.len();
                work.push((p.undecided.clone(), (2 * h).min(extent)));
            }
            parts.push(p);
        }
    }
    Ok((join_regions(parts)?, stats))
}

// The bytes of a region's finish, for moving it between processes.

/// First bytes of [`RegionMap::to_bytes`].
const REGION_MAGIC: &[u8; 8] = b"TARNREGN";
/// Version of the region format.
const REGION_VERSION: u32 = 1;

fn put_u32(o: &mut Vec<u8>, v: u32) {
    o.extend_from_slice(&v.to_le_bytes());
}
fn put_u64(o: &mut Vec<u8>, v: u64) {
    o.extend_from_slice(&v.to_le_bytes());
}
fn put_i64(o: &mut Vec<u8>, v: i64) {
    o.extend_from_slice(&v.to_le_bytes());
}
fn put_f64(o: &mut Vec<u8>, v: f64) {
    o.extend_from_slice(&v.to_le_bytes());
}
fn put_f32(o: &mut Vec<u8>, v: f32) {
    o.extend_from_slice(&v.to_le_bytes());
}
fn put_opt(o: &mut Vec<u8>, v: Option<f64>) {
    match v {
        None => o.push(0),
        Some(v) => {
            o.push(1);
            put_f64(o, v);
        }
    }
}
fn put_key(o: &mut Vec<u8>, k: CellKey) {
    put_i64(o, k.x);
    put_i64(o, k.y);
}

fn put_body(o: &mut Vec<u8>, b: &WaterBody) {
    put_u32(o, b.id);
    put_u64(o, b.cells.len() as u64);
    for (&k, &d) in b.cells.iter().zip(&b.cell_depth_m) {
        put_key(o, k);
        put_f32(o, d);
    }
    put_f64(o, b.area_m2);
    put_opt(o, b.volume_m3);
    let d = &b.depth;
    put_u64(o, d.known_cells as u64);
    put_u64(o, d.unknown_cells as u64);
    put_f64(o, d.known_area_m2);
    put_f64(o, d.unknown_area_m2);
    put_opt(o, d.mean_m);
    put_opt(o, d.max_m);
    put_u64(o, b.shore_samples as u64);
    put_u64(o, b.shore_samples_kept as u64);
    put_u64(o, b.surface_samples as u64);
    o.push(match b.surface_source {
        SurfaceSource::Shore => 0,
        SurfaceSource::FarShore => 1,
        SurfaceSource::WaterLevels => 2,
        SurfaceSource::CellElevations => 3,
        SurfaceSource::ShoreAndFarShore => 4,
    });
    match &b.surface {
        SurfaceModel::Level { z } => {
            o.push(0);
            put_f64(o, *z);
        }
        SurfaceModel::Delaunay {
            samples,
            constraints,
        } => {
            o.push(1);
            put_u64(o, samples.len() as u64);
            for s in samples {
                put_f64(o, s.x);
                put_f64(o, s.y);
                put_f64(o, s.z);
            }
            put_u64(o, constraints.len() as u64);
            for c in constraints {
                put_u64(o, c[0] as u64);
                put_u64(o, c[1] as u64);
            }
        }
    }
    put_f64(o, b.level_residual_m);
    put_opt(o, b.delaunay_residual_m);
}

fn corrupt(at: usize, msg: impl std::fmt::Display) -> Error {
    Error::invalid("region map", format!("at byte {at}: {msg}"))
}

impl ByteReader<'_> {
    fn opt(&mut self, what: &str) -> Result<Option<f64>> {
        let at = self.pos;
        match self.u8(what)? {
            0 => Ok(None),
            1 => Ok(Some(self.f64(what)?)),
            t => Err(corrupt(at, format!("{what}: option tag {t}"))),
        }
    }
    fn key(&mut self, what: &str) -> Result<CellKey> {
        Ok(CellKey::new(self.i64(what)?, self.i64(what)?))
    }
    fn usize(&mut self, what: &str) -> Result<usize> {
        let at = self.pos;
        let v = self.u64(what)?;
        usize::try_from(v).map_err(|_| corrupt(at, format!("{what} {v} too large")))
    }
    /// A count of items of at least `each` bytes, checked against the bytes left.
    fn count(&mut self, what: &str, each: usize) -> Result<usize> {
        let at = self.pos;
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.pos) / each.max(1);
        if n > left as u64 {
            return Err(corrupt(
                at,
                format!(
                    "{n} {what} cannot fit in the {} bytes left",
                    self.bytes.len() - self.pos
                ),
            ));
        }
        Ok(n as usize)
    }

    fn body(&mut self) -> Result<WaterBody> {
        let id = self.u32("body id")?;
        let n = self.count("body cells", 20)?;
        let mut cells = Vec::with_capacity(n);
        let mut cell_depth_m = Vec::with_capacity(n);
        for _ in 0..n {
            let at = self.pos;
            let k = self.key("body cell")?;
            if cells.last().is_some_and(|&l: &CellKey| l >= k) {
                return Err(corrupt(at, format!("body cell {k:?} out of order")));
            }
            cells.push(k);
            cell_depth_m.push(self.f32("cell depth")?);
        }
        let area_m2 = self.f64("area")?;
        let volume_m3 = self.opt("volume")?;
        let depth = DepthStats {
            known_cells: self.usize("known cells")?,
            unknown_cells: self.usize("unknown cells")?,
            known_area_m2: self.f64("known area")?,
            unknown_area_m2: self.f64("unknown area")?,
            mean_m: self.opt("mean depth")?,
            max_m: self.opt("max depth")?,
        };
        let shore_samples = self.usize("shore samples")?;
        let shore_samples_kept = self.usize("shore samples kept")?;
        let surface_samples = self.usize("surface samples")?;
        let at = self.pos;
        let surface_source = match self.u8("surface source")? {
            0 => SurfaceSource::Shore,
            1 => SurfaceSource::FarShore,
            2 => SurfaceSource::WaterLevels,
            3 => SurfaceSource::CellElevations,
            4 => SurfaceSource::ShoreAndFarShore,
            t => return Err(corrupt(at, format!("surface source {t}"))),
        };
        let at = self.pos;
        let surface = match self.u8("surface model")? {
            0 => SurfaceModel::Level {
                z: self.f64("level")?,
            },
            1 => {
                let n = self.count("surface samples", 24)?;
                let mut samples = Vec::with_capacity(n);
                for _ in 0..n {
                    samples.push(ShoreSample {
                        x: self.f64("sample x")?,
                        y: self.f64("sample y")?,
                        z: self.f64("sample z")?,
                    });
                }
                let m = self.count("constraints", 16)?;
                let mut constraints = Vec::with_capacity(m);
                for _ in 0..m {
                    let at = self.pos;
                    let c = [self.usize("constraint")?, self.usize("constraint")?];
                    if c.iter().any(|&i| i >= n) {
                        return Err(corrupt(
                            at,
                            format!("constraint {c:?} beyond the {n} samples"),
                        ));
                    }
                    constraints.push(c);
                }
                SurfaceModel::Delaunay {
                    samples,
                    constraints,
                }
            }
            t => return Err(corrupt(at, format!("surface model {t}"))),
        };
        Ok(WaterBody {
            id,
            cells,
            area_m2,
            volume_m3,
            depth,
            shore_samples,
            shore_samples_kept,
            surface_samples,
            surface_source,
            surface,
            level_residual_m: self.f64("level residual")?,
            delaunay_residual_m: self.opt("Delaunay residual")?,
            cell_depth_m,
        })
    }
}

/// Bytes of one map record.
const CELL_BYTES: usize = 16 + 32 + 8 + 2 + 8;

impl RegionMap {
    /// The region's finish as bytes (magic `TARNREGN`, version, then every field,
    /// little-endian, floats by their bits, and a CRC-32 of all before it): a map read back
    /// with [`RegionMap::from_bytes`] is equal to this one, bit for bit.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut o = Vec::with_capacity(64 + self.cells.len() * CELL_BYTES);
        o.extend_from_slice(REGION_MAGIC);
        put_u32(&mut o, REGION_VERSION);
        put_f64(&mut o, self.resolution);
        put_u64(&mut o, self.tiles_read as u64);
        for list in [&self.tiles, &self.undecided] {
            put_u64(&mut o, list.len() as u64);
            for &(x, y) in list {
                put_i64(&mut o, x);
                put_i64(&mut o, y);
            }
        }
        put_u64(&mut o, self.cells.len() as u64);
        for c in &self.cells {
            put_key(&mut o, c.key);
            for v in [c.x, c.y, c.z, c.elevation_std] {
                put_f64(&mut o, v);
            }
            put_f32(&mut o, c.water);
            put_f32(&mut o, c.depth);
            o.push(c.class as u8);
            o.push(c.hazard as u8);
            put_u32(&mut o, c.hits);
            put_u32(&mut o, c.below);
        }
        put_u64(&mut o, self.bodies.len() as u64);
        for (k, b) in &self.bodies {
            put_key(&mut o, *k);
            match b {
                None => o.push(0),
                Some(b) => {
                    o.push(1);
                    put_body(&mut o, b);
                }
            }
        }
        let crc = crc32fast::hash(&o);
        put_u32(&mut o, crc);
        o
    }

    /// Reads bytes written by [`RegionMap::to_bytes`]; anything else is an error naming
    /// the byte where it went wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<RegionMap> {
        if bytes.len() < 8 + 4 + 4 || &bytes[..8] != REGION_MAGIC {
            return Err(corrupt(0, "not a region map (magic is not TARNREGN)"));
        }
        let (body, crc) = bytes.split_at(bytes.len() - 4);
        let mut r = ByteReader {
            bytes: body,
            pos: 8,
            format: "region map",
        };
        let version = r.u32("version")?;
        if version != REGION_VERSION {
            return Err(corrupt(
                8,
                format!("version {version}; this tarn reads version {REGION_VERSION}"),
            ));
        }
        let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
        let got = crc32fast::hash(body);
        if want != got {
            return Err(corrupt(
                body.len(),
                format!("CRC {want:#010x} recorded, {got:#010x} computed: the bytes are damaged"),
            ));
        }
        let resolution = r.f64("resolution")?;
        let tiles_read = r.usize("tiles read")?;
        let mut lists = [Vec::new(), Vec::new()];
        for list in &mut lists {
            let n = r.count("tiles", 16)?;
            for _ in 0..n {
                let at = r.pos;
                let t = (r.i64("tile x")?, r.i64("tile y")?);
                if list.last().is_some_and(|&l| l >= t) {
                    return Err(corrupt(at, format!("tile {t:?} out of order")));
                }
                list.push(t);
            }
        }
        let [tiles, undecided] = lists;
        let n = r.count("cells", CELL_BYTES)?;
        let mut cells = Vec::with_capacity(n);
        for _ in 0..n {
            let key = r.key("cell key")?;
            let (x, y, z, elevation_std) = (
                r.f64("cell x")?,
                r.f64("cell y")?,
                r.f64("cell z")?,
                r.f64("cell σ")?,
            );
            let (water, depth) = (r.f32("water")?, r.f32("depth")?);
            let at = r.pos;
            let class = *Class::ALL
                .get(r.u8("class")? as usize)
                .ok_or_else(|| corrupt(at, "class code beyond 5"))?;
            let at = r.pos;
            let hazard = match r.u8("hazard")? {
                0 => Hazard::Free,
                1 => Hazard::ShallowWater,
                2 => Hazard::DeepWater,
                3 => Hazard::Obstacle,
                h => return Err(corrupt(at, format!("hazard code {h}"))),
            };
            cells.push(MapCell {
                key,
                x,
                y,
                z,
                elevation_std,
                water,
                depth,
                class,
                hazard,
                hits: r.u32("hits")?,
                below: r.u32("below")?,
            });
        }
        let n = r.count("bodies", 17)?;
        let mut bodies = Vec::with_capacity(n);
        for _ in 0..n {
            let k = r.key("first seed")?;
            let at = r.pos;
            let b = match r.u8("body tag")? {
                0 => None,
                1 => Some(r.body()?),
                t => return Err(corrupt(at, format!("body tag {t}"))),
            };
            bodies.push((k, b));
        }
        if r.pos != body.len() {
            return Err(corrupt(
                r.pos,
                format!("{} bytes after the last body", body.len() - r.pos),
            ));
        }
        Ok(RegionMap {
            resolution,
            tiles,
            cells,
            bodies,
            undecided,
            tiles_read,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Evidence;
    use proptest::prelude::*;

    /// A map of level ground with elevation noise and ponds of water evidence: each pond
    /// a disc `(cx, cy, r)` in cells, its cells seen through no-return evidence (p ≈ 0.84,
    /// a seed), a fringe ring of weaker evidence (joins only), bottom returns in some cells.
    fn map(ponds: &[(i64, i64, i64)], seed: u64, extent: (i64, i64)) -> TileMap {
        map_with(ponds, &[], seed, extent)
    }

    /// [`map`] with channels of weak evidence (one reflection: a body grows over them, none
    /// starts in them), rectangles `(x0, y0, x1, y1)` of cells seen only that way.
    fn map_with(
        ponds: &[(i64, i64, i64)],
        channels: &[(i64, i64, i64, i64)],
        seed: u64,
        extent: (i64, i64),
    ) -> TileMap {
        let mut t = TileMap::new(0.1, 0.0).unwrap();
        let mut h = seed;
        let mut next = || {
            h ^= h << 13;
            h ^= h >> 7;
            h ^= h << 17;
            h
        };
        for x in 0..extent.0 {
            for y in 0..extent.1 {
                let k = CellKey::new(x, y);
                let r = next();
                if r % 23 == 0 {
                    continue; // unobserved
                }
                let d2 = |&(cx, cy, rad): &(i64, i64, i64)| {
                    let d = (x - cx).pow(2) + (y - cy).pow(2);
                    (d, rad * rad)
                };
                let inside = ponds.iter().map(d2).any(|(d, r2)| d <= r2);
                let fringe = ponds
                    .iter()
                    .map(d2)
                    .any(|(d, r2)| d > r2 && d <= r2 + 4 * r2.max(1).isqrt() + 4);
                let mut c = CellStats::default();
                let channel = channels
                    .iter()
                    .any(|&(x0, y0, x1, y1)| (x0..=x1).contains(&x) && (y0..=y1).contains(&y));
                if channel && !inside {
                    c.ev.reflect = 1;
                    c.ev.add_level(((r >> 8) % 30) as i32);
                } else if inside {
                    let mut ev = Evidence {
                        noret: 20,
                        ..Evidence::default()
                    };
                    ev.add_level(((r >> 8) % 30) as i32);
                    if r % 3 == 0 {
                        ev.add_depth(0.1 + ((r >> 16) % 40) as f64 * 0.01);
                    }
                    c.ev = ev;
                } else {
                    if fringe && r % 2 == 0 {
                        c.ev.reflect = 1;
                    }
                    // Ground 5–15 cm above the water in ±15 cm waves, noisy, some cells
                    // unreliable, one in four a bush 30–60 cm high: which shore samples
                    // the occluder test keeps depends on the ground around them.
                    let bush = if (r >> 40) % 4 == 0 {
                        300 + ((r >> 44) % 300) as i32
                    } else {
                        0
                    };
                    let wave = (150.0 * (x as f64 * 0.37).sin() * (y as f64 * 0.29).cos()) as i32;
                    let z = 50 + ((r >> 20) % 100) as i32 + wave + bush;
                    let pts = 1 + (r >> 32) % 6;
                    for i in 0..pts {
                        c.add(z + (i as i32 * 7) % 23, 65536);
                    }
                }
                t.add(k, &c);
            }
        }
        t
    }

    /// `t` with bottom returns in the ground cells of the rectangles `beds`: four each, at
    /// a depth of 0–8 cm below the level they were corrected against (no gain), so that
    /// the refinement takes some out of the evidence and leaves others.
    fn with_beds(t: &TileMap, beds: &[(i64, i64, i64, i64)]) -> TileMap {
        let mut out = TileMap::new(t.resolution(), t.z_ref()).unwrap();
        for (k, mut c) in t.observed() {
            let bed = beds
                .iter()
                .any(|&(x0, y0, x1, y1)| (x0..=x1).contains(&k.x) && (y0..=y1).contains(&k.y));
            if bed && c.hits > 0 {
                let d = (k.x * 7 + k.y * 13).rem_euclid(9) as f64 * 0.01;
                for _ in 0..4 {
                    c.ev.add_depth(d);
                }
            }
            out.add(k, &c);
        }
        out
    }

    fn ply(m: &HazardMap) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        crate::io::write_map_ply(&p, m).unwrap();
        std::fs::read(p).unwrap()
    }

    fn same(a: &HazardMap, b: &HazardMap) {
        assert_eq!(a.cells.len(), b.cells.len());
        for (x, y) in a.cells.iter().zip(&b.cells) {
            assert_eq!(format!("{x:?}"), format!("{y:?}"));
        }
        assert_eq!(format!("{:?}", a.bodies), format!("{:?}", b.bodies));
        assert!(ply(a) == ply(b));
    }

    #[test]
    fn a_pond_across_regions_is_the_whole_maps() {
        // Three ponds: one across the corner of four tiles, one large (beyond a 1-tile
        // halo), one small inside a tile; and a tiny one below the smallest body.
        // A channel of weak evidence runs from the small pond across the map: the tiles
        // along it are water only through the pond, which most regions do not hold.
        let ponds = [(64, 64, 9), (150, 120, 60), (30, 205, 5), (170, 20, 1)];
        // Beds of bottom returns beside the channel and across the large pond's tiles.
        let t = with_beds(
            &map_with(&ponds, &[(30, 204, 255, 206)], 7, (256, 224)),
            &[(20, 190, 250, 200), (60, 40, 140, 70)],
        );
        let cfg = HazardConfig::default();
        let whole = HazardMap::from_tiles(&t, &cfg).unwrap();
        assert!(whole.bodies.len() >= 3, "{}", whole.bodies.len());
        // The beds' shallow returns were taken out of the evidence: with only those at or
        // above the surface taken out, the bodies differ.
        let mut counted = cfg;
        counted.water.min_bottom_depth_m = Some(0.0);
        let all_count = HazardMap::from_tiles(&t, &counted).unwrap();
        assert_ne!(
            format!("{:?}", all_count.bodies),
            format!("{:?}", whole.bodies)
        );
        assert!(whole
            .bodies
            .iter()
            .any(|b| b.cells.iter().any(|k| k.x == 255)));
        let mut refinished = false;
        for (side, halo) in [(1, 1), (2, 1), (1, 2), (3, 3), (4, 8)] {
            let (m, s) = finish_by_regions(&t, &cfg, side, halo).unwrap();
            same(&m, &whole);
            refinished |= s.refinished_tiles > 0;
            if (side, halo) == (4, 8) {
                // A halo wider than the map decides everything in one round.
                assert_eq!(s.refinished_tiles, 0);
            }
        }
        // The large pond does not fit a 1-tile halo: some tiles were finished again.
        assert!(refinished);
    }

    #[test]
    fn a_body_whose_ring_crosses_the_halo_is_not_decided_there() {
        // With regions of one tile and one tile of halo, the region of tile (1, 1) reads
        // cells 0..192 a side. The pond (x 102..178, its fringe to about 180) lies inside
        // that, but the ground its shore fit reads reaches past cell 191: the region must
        // leave it to a larger halo.
        let t = map(&[(140, 96, 38)], 5, (256, 256));
        let cfg = HazardConfig::default();
        let whole = HazardMap::from_tiles(&t, &cfg).unwrap();
        assert_eq!(whole.bodies.len(), 1);
        let (m, s) = finish_by_regions(&t, &cfg, 1, 1).unwrap();
        same(&m, &whole);
        assert!(s.refinished_tiles > 0);
        let r = finish_region(&t, &[(1, 1)], 1, ((0, 0), (3, 3)), &cfg).unwrap();
        assert_eq!(r.undecided, vec![(1, 1)]);
    }

    #[test]
    fn an_undecided_body_is_reported_not_guessed() {
        let t = map(&[(100, 100, 70)], 3, (200, 200));
        let cfg = HazardConfig::default();
        let bounds = ((0, 0), (3, 3));
        let r = finish_region(&t, &[(1, 1)], 1, bounds, &cfg).unwrap();
        assert_eq!(r.undecided, vec![(1, 1)]);
        assert!(r.cells.is_empty() && r.bodies.is_empty());
        // A halo over the whole map decides it; the body goes back once, with the region
        // holding its first seed.
        let r = finish_region(&t, &[(1, 1)], 3, bounds, &cfg).unwrap();
        assert!(r.undecided.is_empty());
        assert!(r.cells.iter().any(|c| c.class == Class::Water));
        let mut returned = 0;
        for tx in 0..4 {
            for ty in 0..4 {
                let r = finish_region(&t, &[(tx, ty)], 3, bounds, &cfg).unwrap();
                assert!(r.undecided.is_empty());
                returned += r.bodies.len();
            }
        }
        assert_eq!(returned, 1);
        // Joining a region that left tiles undecided is refused.
        let r = finish_region(&t, &[(1, 1)], 1, bounds, &cfg).unwrap();
        assert!(join_regions(vec![r]).is_err());
        // Bad arguments are errors.
        assert!(finish_region(&t, &[(1, 1)], 0, bounds, &cfg).is_err());
        assert!(finish_region(&t, &[(1, 1)], 1, ((0, 0), (1, 1)), &cfg).is_err());
        assert!(finish_by_regions(&t, &cfg, 0, 1).is_err());
    }

    #[test]
    fn region_bytes_read_back_and_damage_is_an_error() {
        let t = map(&[(64, 64, 12), (20, 100, 6)], 11, (128, 128));
        let cfg = HazardConfig::default();
        let r = finish_region(
            &t,
            &[(0, 0), (1, 0), (0, 1), (1, 1)],
            1,
            ((0, 0), (1, 1)),
            &cfg,
        )
        .unwrap();
        assert!(!r.bodies.is_empty() && r.undecided.is_empty());
        let b = r.to_bytes();
        let back = RegionMap::from_bytes(&b).unwrap();
        assert_eq!(format!("{back:?}"), format!("{r:?}"));
        assert_eq!(back.to_bytes(), b);
        for i in (0..b.len()).step_by(97) {
            let mut d = b.clone();
            d[i] ^= 0x20;
            assert!(RegionMap::from_bytes(&d).is_err());
            assert!(RegionMap::from_bytes(&b[..i]).is_err());
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(12))]
        #[test]
        fn any_split_and_halo_is_the_whole_map(
            ponds in prop::collection::vec((0i64..200, 0i64..200, 0i64..40), 1..4),
            channels in prop::collection::vec((0i64..200, 0i64..200, 0i64..200, 0i64..4), 0..2),
            seed in 1u64..u64::MAX,
            side in 1i64..4,
            halo in 1i64..4,
            shift in (-2i64..2, -2i64..2),
        ) {
            // Channels along x or y, 1 to 4 cells wide.
            let channels: Vec<_> = channels
                .iter()
                .map(|&(a, b, c, w)| if a % 2 == 0 { (a.min(c), b, a.max(c), b + w) } else { (b, a.min(c), b + w, a.max(c)) })
                .collect();
            // Beds of bottom returns, some shallow enough to be taken out of the evidence,
            // across the region borders the channels cross.
            let beds: Vec<_> = channels.iter().map(|&(x0, y0, x1, y1)| (x0, y0 + 6, x1, y1 + 9)).collect();
            let t = with_beds(&map_with(&ponds, &channels, seed, (200, 200)), &beds);
            // Maps off the origin too: negative tile keys.
            let mut moved = TileMap::new(0.1, 0.0).unwrap();
            for (k, c) in t.observed() {
                moved.add(CellKey::new(k.x + shift.0 * 64 + 5, k.y + shift.1 * 64 - 3), &c);
            }
            let cfg = HazardConfig::default();
            let whole = HazardMap::from_tiles(&moved, &cfg).unwrap();
            let (m, _) = finish_by_regions(&moved, &cfg, side, halo).unwrap();
            same(&m, &whole);
        }
    }
}
