//! The water stage of a merged map of simulated logs split by region with a halo, joined,
//! against the whole map's: byte for byte.

use tarn::grid::TileMap;
use tarn::hazard::{join_regions, HazardMap, RegionMap};
use tarn::mapper::MapperConfig;
use tarn_log::build::{
    build_tiles, finish_tile_region, finish_tiles, finish_tiles_by_regions, LogBuildConfig,
};
use tarn_sim::sim::{simulate, Scene, SimOptions};

/// A drive of the default scene (small rig) along `waypoints`, 8 frames at 2 Hz: the two
/// drives of `python/tests/test_tarn.py`, one along each shore of the pond, each seeing
/// part of it.
fn drive(dir: &std::path::Path, waypoints: &[[f64; 2]]) -> std::path::PathBuf {
    let mut s = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../maps/default.toml"
    )))
    .unwrap();
    s.trajectory.waypoints = waypoints.to_vec();
    s.trajectory.speed = 3.0;
    s.trajectory.rate_hz = 2.0;
    s.trajectory.frames = Some(8);
    simulate(
        &s,
        dir,
        SimOptions {
            noise: true,
            ..SimOptions::default()
        },
    )
    .unwrap();
    dir.join("log.mcap")
}

fn ply(m: &HazardMap) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("map.ply");
    tarn::io::write_map_ply(&p, m).unwrap();
    std::fs::read(p).unwrap()
}

/// Every record and body alike, bit for bit (NaN depths included).
fn same(a: &HazardMap, b: &HazardMap) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

#[test]
fn a_pond_cut_by_regions_finishes_to_the_whole_map() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("south"), dir.path().join("north"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    let logs = [
        drive(&a, &[[4.0, -1.0], [34.0, -1.0]]),
        drive(&b, &[[36.0, 13.0], [6.0, 13.0]]),
    ];
    let mapper = MapperConfig::every_sensor();
    let cfg = LogBuildConfig::of_mapper(mapper.clone());
    let mut tiles = TileMap::new(mapper.grid.resolution, mapper.grid.z_ref).unwrap();
    for l in &logs {
        tiles
            .merge(&build_tiles(l, &cfg, None).unwrap().tiles)
            .unwrap();
    }
    let whole = finish_tiles(&tiles, &mapper).unwrap();
    let pond = whole
        .bodies
        .iter()
        .max_by(|a, b| a.area_m2.total_cmp(&b.area_m2))
        .expect("the pond is found");
    let pond_tiles: std::collections::BTreeSet<(i64, i64)> = pond
        .cells
        .iter()
        .map(|k| (k.x.div_euclid(64), k.y.div_euclid(64)))
        .collect();
    eprintln!(
        "{} cells in {} tiles, {} bodies; the pond: {} m² over {} tiles",
        whole.cells.len(),
        tiles.tile_count(),
        whole.bodies.len(),
        pond.area_m2,
        pond_tiles.len()
    );
    assert!(pond.area_m2 > 10.0, "{}", pond.area_m2);
    let want = ply(&whole);
    let mut refinished = false;
    for (side, halo) in [(1, 1), (2, 1), (1, 3), (3, 2)] {
        let (m, stats) = finish_tiles_by_regions(&tiles, &mapper, side, halo).unwrap();
        eprintln!("regions of {side} tiles, halo {halo}: {stats:?}");
        assert!(ply(&m) == want, "side {side}, halo {halo}");
        assert!(same(&m, &whole), "side {side}, halo {halo}");
        // The pond crosses region borders whatever the side.
        let regions: std::collections::BTreeSet<_> = pond_tiles
            .iter()
            .map(|t| (t.0.div_euclid(side), t.1.div_euclid(side)))
            .collect();
        assert!(regions.len() > 1);
        refinished |= stats.refinished_tiles > 0;
        assert!(stats.most_tiles_read <= tiles.tile_count());
    }
    // With one tile of halo (6.4 m) the pond (about 14 m across) is undecided at first.
    assert!(refinished);

    // Regions finished from their own tiles only (as a worker holds them), with the whole
    // build's colour false alarms (a cut holds none), through their bytes, joined: the
    // same map.
    let keys = tiles.tile_keys();
    let lo = keys
        .iter()
        .fold(keys[0], |a, t| (a.0.min(t.0), a.1.min(t.1)));
    let hi = keys
        .iter()
        .fold(keys[0], |a, t| (a.0.max(t.0), a.1.max(t.1)));
    let mut parts = Vec::new();
    let mut pending: Vec<(Vec<(i64, i64)>, i64)> =
        keys.chunks(5).map(|c| (c.to_vec(), 2)).collect();
    while let Some((region, halo)) = pending.pop() {
        let near = |t: (i64, i64)| {
            region
                .iter()
                .any(|r| r.0.abs_diff(t.0) <= halo as u64 && r.1.abs_diff(t.1) <= halo as u64)
        };
        let mut own = tiles.select(near);
        own.add_false_alarms(&tiles.false_alarms());
        let r = finish_tile_region(&own, &region, halo, (lo, hi), &mapper).unwrap();
        let r = RegionMap::from_bytes(&r.to_bytes()).unwrap();
        if !r.undecided.is_empty() {
            pending.push((r.undecided.clone(), 2 * halo));
        }
        parts.push(r);
    }
    let joined = join_regions(parts).unwrap();
    assert!(ply(&joined) == want);
    assert!(same(&joined, &whole));
}
