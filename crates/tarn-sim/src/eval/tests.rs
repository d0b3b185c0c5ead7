use super::*;
use crate::hazard::Hazard;
use crate::sim::TruthPose;
use proptest::prelude::*;

#[test]
fn distance_to_a_polyline() {
    let p = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
    assert_eq!(distance_to_path(&p, 5.0, 3.0), 3.0);
    assert_eq!(distance_to_path(&p, 13.0, 5.0), 3.0);
    assert_eq!(distance_to_path(&p, -4.0, 3.0), 5.0);
    assert_eq!(distance_to_path(&p[..1], 3.0, 4.0), 5.0);
}

#[test]
fn a_band_scores_only_its_cells_and_counts_sunk_ones() {
    let cell = |kx: i64, z: f64, class: Class| MapCell {
        key: CellKey::new(kx, 0),
        x: (kx as f64 + 0.5) * 1.0,
        y: 0.5,
        z,
        elevation_std: 0.0,
        water: 0.0,
        depth: 0.0,
        class,
        hazard: Hazard::Free,
        hits: 1,
        below: 0,
    };
    let truth = HazardMap::new(
        1.0,
        (0..40)
            .map(|k| cell(k, 0.0, if k == 12 { Class::Water } else { Class::Ground }))
            .collect(),
    );
    // Ground at 0; the map sinks cell 8 (a reflection fused as terrain) and calls 12 water.
    let mut map = truth.clone();
    map.cells[8].z = -0.5;
    map.cells[20].z = -0.1;
    let info = TruthInfo {
        scene: "t".into(),
        description: String::new(),
        seed: 0,
        resolution: 1.0,
        fording_depth_m: 0.3,
        origin: [0.0, 0.0],
        size: [40.0, 1.0],
        trajectory: vec![TruthPose {
            stamp: 0.0,
            x: 0.0,
            y: 0.5,
            z: 0.0,
            yaw: 0.0,
        }],
        water_bodies: Vec::new(),
        class_counts: [0; 6],
        topics: Vec::new(),
        colour_view: None,
        seen_water: None,
    };
    // Recall by what the camera saw: cell 12 seen as sky, 13 (water too) only as
    // terrain, 14 never; the map calls 12 and 14 water.
    let mut t2 = truth.clone();
    t2.cells[13].class = Class::Water;
    t2.cells[14].class = Class::Water;
    let mut m2 = t2.clone();
    m2.cells[13].class = Class::Ground;
    let info2 = TruthInfo {
        colour_view: Some(ColourView {
            sky: vec![[12, 0], [30, 0]],
            terrain: vec![[13, 0]],
        }),
        ..info.clone()
    };
    let v = evaluate(&m2, &t2, &info2).unwrap().colour_view.unwrap();
    assert_eq!((v.sky.water_cells, v.sky.water_detected), (1, 1));
    assert_eq!((v.terrain.water_cells, v.terrain.recall), (1, Some(0.0)));
    assert_eq!((v.unseen.water_cells, v.unseen.water_detected), (1, 1));
    assert!(evaluate(&m2, &t2, &info).unwrap().colour_view.is_none());
    let b = evaluate_band(&map, &truth, &info, 5.0, 25.0).unwrap();
    // Cells 5..=24 have centres at 5.5..24.5 m.
    assert_eq!(b.observed_cells, 20);
    assert_eq!((b.water_cells, b.water_detected), (1, 1));
    assert_eq!(b.sunk_cells, 1);
    assert_eq!(b.range, "5-25");
    assert!(evaluate_band(&map, &truth, &info, 5.0, 5.0).is_err());
}

/// A cell at key (kx, ky) of a grid of `res` m cells, z 0.
fn cell(res: f64, kx: i64, ky: i64, class: Class) -> MapCell {
    MapCell {
        key: CellKey::new(kx, ky),
        x: (kx as f64 + 0.5) * res,
        y: (ky as f64 + 0.5) * res,
        z: 0.0,
        elevation_std: 0.0,
        water: 0.0,
        depth: 0.0,
        class,
        hazard: Hazard::Free,
        hits: 1,
        below: 0,
    }
}

/// A raster of `nx` × `ny` cells of `res` m from key (0, 0); `water` says which are.
pub(super) fn raster(res: f64, nx: i64, ny: i64, water: impl Fn(i64, i64) -> bool) -> HazardMap {
    let cells = (0..ny)
        .flat_map(|ky| (0..nx).map(move |kx| (kx, ky)))
        .map(|(kx, ky)| {
            let class = if water(kx, ky) {
                Class::Water
            } else {
                Class::Ground
            };
            cell(res, kx, ky, class)
        })
        .collect();
    HazardMap::new(res, cells)
}

/// Truth with a trajectory through `path` and the given seen water.
pub(super) fn info(res: f64, path: &[[f64; 2]], seen: Option<Vec<[i64; 2]>>) -> TruthInfo {
    TruthInfo {
        scene: "t".into(),
        description: String::new(),
        seed: 0,
        resolution: res,
        fording_depth_m: 0.3,
        origin: [0.0, 0.0],
        size: [1.0, 1.0],
        trajectory: path
            .iter()
            .map(|p| TruthPose {
                stamp: 0.0,
                x: p[0],
                y: p[1],
                z: 0.0,
                yaw: 0.0,
            })
            .collect(),
        water_bodies: Vec::new(),
        class_counts: [0; 6],
        topics: Vec::new(),
        colour_view: None,
        seen_water: seen,
    }
}

fn set_class(map: &mut HazardMap, kx: i64, ky: i64, class: Class) {
    let c = map.cells.iter_mut().find(|c| c.key == CellKey::new(kx, ky));
    c.unwrap().class = class;
}

#[test]
fn the_maps_sigma_and_water_probability_are_scored() {
    // 1 m cells along x, 10..20 m from the path: ten dry cells with errors 0.05·k and
    // σ 0.1, so errors 0, .05, .1 lie within 1σ (3), up to .2 within 2σ (5), up to .3
    // within 3σ (7); water cells 20..30 of p 0.95, dry ones of p 0.05 and 0.15.
    let truth = raster(1.0, 40, 1, |kx, _| (20..30).contains(&kx));
    let mut map = truth.clone();
    for c in map.cells.iter_mut() {
        let k = c.key.x;
        c.elevation_std = if k == 19 { f64::NAN } else { 0.1 };
        if (10..20).contains(&k) {
            c.z = 0.05 * (k - 10) as f64;
        }
        c.water = match k {
            20..=29 => 0.95,
            0..=4 => 0.15,
            _ => 0.05,
        };
    }
    let info = info(1.0, &[[0.0, 0.5]], None);
    let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
    // Cell 19 has no σ: nine scored, errors 0 … 0.40.
    assert_eq!(b.terrain_sigma_cells, 9);
    assert_eq!(b.terrain_within_sigma, [3, 5, 7]);
    assert_eq!(b.terrain_within_sigma_frac[0], Some(3.0 / 9.0));
    assert_eq!(b.terrain_confident_cells, 0);
    let all = evaluate(&map, &truth, &info).unwrap().all;
    let r = &all.water_reliability;
    assert_eq!(r.len(), 10);
    assert_eq!((r[0].cells, r[0].water_fraction), (25, Some(0.0)));
    assert_eq!((r[1].cells, r[1].water_fraction), (5, Some(0.0)));
    assert_eq!((r[9].cells, r[9].water_fraction), (10, Some(1.0)));
    assert!((r[9].mean_p.unwrap() - 0.95).abs() < 1e-6);
    assert_eq!((r[5].cells, r[5].mean_p), (0, None));
}

#[test]
fn seen_water_the_map_lacks_counts_as_missed() {
    // 1 m cells along x, the path at the origin: cell k is k + 0.5 m away. Water 12..=15.
    let truth = raster(1.0, 40, 1, |kx, _| (12..=15).contains(&kx));
    let mut map = truth.clone();
    map.cells.retain(|c| c.key.x != 14);
    set_class(&mut map, 15, 0, Class::Ground);
    // Seen: the four water cells (14 twice), a dry cell and one outside the truth; the
    // last two are no water and do not count.
    let seen = vec![
        [12, 0],
        [13, 0],
        [14, 0],
        [15, 0],
        [14, 0],
        [30, 0],
        [99, 0],
    ];
    let info = info(1.0, &[[0.0, 0.5]], Some(seen));
    let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
    assert_eq!((b.seen_water_cells, b.seen_water_detected), (4, 2));
    assert_eq!(b.seen_recall, Some(0.5));
    // Recall over the observed water does not see the missing cell.
    assert_eq!((b.water_cells, b.water_detected), (3, 2));
    assert_eq!(b.water_recall, Some(2.0 / 3.0));
    assert_eq!(
        (b.called_water, b.called_true, b.precision),
        (2, 2, Some(1.0))
    );
    let r = evaluate(&map, &truth, &info).unwrap();
    assert_eq!(r.bins[2].range, "10-20");
    assert_eq!(r.bins[2].seen_recall, Some(0.5));
    assert_eq!(r.all.seen_water_cells, 4);
    assert_eq!(
        (r.bins[3].seen_water_cells, r.bins[3].seen_recall),
        (0, None)
    );
    assert_eq!((r.bins[3].called_water, r.bins[3].precision), (0, None));
    // Without the colour camera's view no seen cell is a sky reflection.
    assert_eq!((b.seen_sky_cells, b.seen_sky_recall), (0, None));

    // The camera saw 12 (called) and 14 (missing) reflecting the sky, 13 only terrain,
    // and the dry cell 30 the sky: of the seen water, two reflected the sky, one found.
    let mut info = info;
    info.colour_view = Some(ColourView {
        sky: vec![[12, 0], [14, 0], [30, 0]],
        terrain: vec![[13, 0]],
    });
    let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
    assert_eq!((b.seen_sky_cells, b.seen_sky_detected), (2, 1));
    assert_eq!(b.seen_sky_recall, Some(0.5));
    assert_eq!((b.seen_water_cells, b.seen_water_detected), (4, 2));
}

#[test]
fn water_called_at_the_shore_is_not_off_shore() {
    // 0.5 m cells, 60 × 3; water at (30..=33, 1). Within 0.5 m of it (the shore): the
    // dry cells beside it in x and y, not the diagonal ones (0.71 m).
    let truth = raster(0.5, 60, 3, |kx, ky| ky == 1 && (30..=33).contains(&kx));
    let mut map = truth.clone();
    set_class(&mut map, 29, 1, Class::Water); // shore, beside
    set_class(&mut map, 30, 0, Class::Water); // shore, below
    set_class(&mut map, 29, 0, Class::Water); // diagonal: off shore
    set_class(&mut map, 50, 1, Class::Water); // far: off shore
    map.cells.push(cell(0.5, 200, 1, Class::Water)); // outside the truth: not scored
    let r = evaluate(&map, &truth, &info(0.5, &[[0.0, 0.75]], None)).unwrap();
    let m = &r.all;
    assert_eq!(m.outside_truth, 1);
    assert_eq!((m.dry_cells, m.false_water), (176, 4));
    // 10 shore cells: 2 beside, 4 above and 4 below.
    assert_eq!((m.dry_offshore_cells, m.false_water_offshore), (166, 2));
    assert_eq!(m.false_rate_offshore, Some(2.0 / 166.0));
    // Precision: 4 true water of the 8 cells called water that have truth.
    assert_eq!((m.called_water, m.called_true), (8, 4));
    assert_eq!(m.precision, Some(0.5));
}

#[test]
fn the_shore_is_a_disc_of_half_a_metre() {
    // 0.25 m cells: the margin is two cells along an axis, one diagonally.
    let truth = raster(0.25, 20, 20, |kx, ky| (kx, ky) == (10, 10));
    let s = Shore::new(&truth);
    let near = |dx: i64, dy: i64| s.near(CellKey::new(10 + dx, 10 + dy));
    assert!(near(2, 0) && near(0, -2) && near(1, 1) && near(-1, 1));
    assert!(!near(2, 1) && !near(3, 0) && !near(2, 2) && !near(-1, -2));
    // Outside the raster nothing is near.
    assert!(!s.near(CellKey::new(-1, -1)) && !s.near(CellKey::new(i64::MIN, 0)));
    // A sparse truth (two far cells) gives the same answers.
    let mut sparse = truth.clone();
    sparse.cells.retain(|c| c.key.x == 10 || c.key.y == 10);
    sparse.cells.push(cell(0.25, 1000, 1000, Class::Ground));
    let s2 = Shore::new(&sparse);
    assert!(matches!(s2, Shore::Sparse(_)));
    assert!(s2.near(CellKey::new(12, 10)) && !s2.near(CellKey::new(13, 10)));
}

/// Truth of 0.5 m cells, 80 × 2, water at x 10–13 m (keys 20..=25); a map of 1 m cells
/// calling water at x 10–12 m (keys 10 and 11, not 12); the path the line x = 0.5 m.
fn two_resolutions(seen: bool) -> (HazardMap, HazardMap, TruthInfo) {
    let truth = raster(0.5, 80, 2, |kx, _| (20..=25).contains(&kx));
    let map = raster(1.0, 40, 1, |kx, _| kx == 10 || kx == 11);
    let seen = seen.then(|| {
        (20..=25)
            .flat_map(|kx| (0..2).map(move |ky| [kx, ky]))
            .collect()
    });
    let path = [[0.5, -100.0], [0.5, 100.0]];
    (map, truth, info(0.5, &path, seen))
}

#[test]
fn truth_cells_are_banded_by_their_own_centres() {
    let (map, truth, info) = two_resolutions(true);
    // Truth key 20 (centre 10.25 m, 9.75 m from the path) is in 5-10 though its map
    // cell (key 10, centre 10.5 m, 10 m away) is in 10-20; the map calls it water.
    let b = evaluate_band(&map, &truth, &info, 5.0, 10.0).unwrap();
    assert_eq!((b.seen_water_cells, b.seen_water_detected), (2, 2));
    assert_eq!((b.water_cells, b.water_recall), (0, None));
    // Keys 21..=25 are 10.25–12.25 m away; 24 and 25 are in map cell 12, not water.
    let b = evaluate_band(&map, &truth, &info, 10.0, 20.0).unwrap();
    assert_eq!((b.seen_water_cells, b.seen_water_detected), (10, 6));
    assert_eq!(b.seen_recall, Some(0.6));
    // Map cells 10, 11, 12 meet truth keys 21, 23, 25 (their centres' cells).
    assert_eq!((b.water_cells, b.water_detected), (3, 2));
    let r = evaluate(&map, &truth, &info).unwrap();
    assert_eq!(
        (r.bins[1].range.as_str(), r.bins[1].seen_water_cells),
        ("5-10", 2)
    );
    assert_eq!(r.bins[2].seen_water_detected, 6);
    assert_eq!((r.all.seen_water_cells, r.all.seen_water_detected), (12, 8));
}

#[test]
fn without_seen_water_seen_recall_is_the_observed_recall() {
    let (map, truth, info) = two_resolutions(false);
    let r = evaluate(&map, &truth, &info).unwrap();
    let mut bins = r.bins.clone();
    bins.push(r.all.clone());
    bins.extend(evaluate_matrix_bands(&map, &truth, &info, None).unwrap());
    for b in &bins {
        assert_eq!(b.seen_water_cells, b.water_cells, "{}", b.range);
        assert_eq!(b.seen_water_detected, b.water_detected, "{}", b.range);
        assert_eq!(b.seen_recall, b.water_recall, "{}", b.range);
    }
    assert_eq!(r.all.seen_recall, Some(2.0 / 3.0));
}

#[test]
fn matrix_bands_are_the_three_bands_and_their_union() {
    let (map, truth, info) = two_resolutions(true);
    let m = evaluate_matrix_bands(&map, &truth, &info, None).unwrap();
    let names: Vec<_> = m.iter().map(|b| b.range.as_str()).collect();
    assert_eq!(names, ["5-10", "10-20", "20-30", "5-30"]);
    for (b, &(lo, hi)) in m.iter().zip(&MATRIX_BANDS) {
        assert_eq!(*b, evaluate_band(&map, &truth, &info, lo, hi).unwrap());
    }
    let sum = |f: fn(&BinMetrics) -> usize| m[..3].iter().map(f).sum::<usize>();
    let u = &m[3];
    assert_eq!(u.observed_cells, sum(|b| b.observed_cells));
    assert_eq!(u.seen_water_cells, sum(|b| b.seen_water_cells));
    assert_eq!(u.seen_water_detected, sum(|b| b.seen_water_detected));
    assert_eq!(u.dry_offshore_cells, sum(|b| b.dry_offshore_cells));
    assert_eq!(u.called_water, sum(|b| b.called_water));
    assert_eq!((u.seen_water_cells, u.seen_water_detected), (12, 8));
}

/// A random case: truth of 0.5 m cells (12 × 6) with random water, a map at 0.25, 0.5
/// or 1 m over and around it (random cells, classes and z in quarter metres, so that
/// sums of squares are exact in any order), random seen water, a random path; and the
/// map's cells in a shuffled order.
fn case() -> impl Strategy<Value = (HazardMap, TruthInfo, HazardMap, HazardMap)> {
    (
        prop::collection::vec(any::<bool>(), 72),
        prop::option::of(prop::collection::vec((-1i64..14, -1i64..8), 0..30)),
        prop_oneof![Just(0.25), Just(0.5), Just(1.0)],
        prop::collection::vec(prop::option::of((any::<bool>(), -8i8..8)), 32 * 20),
        prop::collection::vec((-40i8..60, -40i8..40), 1..4),
    )
        .prop_flat_map(|(water, seen, mres, cells, path)| {
            let truth = raster(0.5, 12, 6, |kx, ky| water[(ky * 12 + kx) as usize]);
            let seen = seen.map(|v| v.into_iter().map(|(x, y)| [x, y]).collect());
            let path: Vec<[f64; 2]> = path
                .iter()
                .map(|&(x, y)| [x as f64 / 4.0, y as f64 / 4.0])
                .collect();
            let info = info(0.5, &path, seen);
            // Keys over -1 .. 7 m × -1 .. 4 m at the map's resolution.
            let (w, h) = ((8.0 / mres) as i64, (5.0 / mres) as i64);
            let cells: Vec<MapCell> = (0..w * h)
                .filter_map(|i| {
                    let (called, z) = cells[i as usize]?;
                    let class = if called { Class::Water } else { Class::Ground };
                    let mut c = cell(
                        mres,
                        i % w - (1.0 / mres) as i64,
                        i / w - (1.0 / mres) as i64,
                        class,
                    );
                    c.z = z as f64 / 4.0;
                    Some(c)
                })
                .collect();
            let map = HazardMap::new(mres, cells.clone());
            let shuffled = Just(cells)
                .prop_shuffle()
                .prop_map(move |c| HazardMap::new(mres, c));
            (Just(truth), Just(info), Just(map), shuffled)
        })
}

proptest! {
    #[test]
    fn new_rates_are_rates_and_ignore_the_map_order((truth, info, map, shuffled) in case()) {
        let r = evaluate(&map, &truth, &info).unwrap();
        let m = evaluate_matrix_bands(&map, &truth, &info, None).unwrap();
        for b in r.bins.iter().chain([&r.all]).chain(&m) {
            for v in [b.seen_recall, b.false_rate_offshore, b.precision].into_iter().flatten() {
                prop_assert!((0.0..=1.0).contains(&v), "{b:?}");
            }
            prop_assert!(b.seen_water_detected <= b.seen_water_cells);
            prop_assert!(b.false_water_offshore <= b.dry_offshore_cells);
            prop_assert!(b.dry_offshore_cells <= b.dry_cells);
            prop_assert!(b.called_true <= b.called_water);
        }
        // Off shore by brute force: every water centre farther than the margin.
        let water: Vec<&MapCell> = truth.cells.iter().filter(|c| c.class == Class::Water).collect();
        let offshore = map.cells.iter().filter(|c| {
            let k = CellKey::new((c.x / 0.5).floor() as i64, (c.y / 0.5).floor() as i64);
            truth.cells.iter().find(|t| t.key == k).is_some_and(|t| {
                t.class != Class::Water
                    && water.iter().all(|w| (w.x - t.x).hypot(w.y - t.y) > SHORE_MARGIN_M)
            })
        });
        prop_assert_eq!(r.all.dry_offshore_cells, offshore.count());
        prop_assert_eq!(&evaluate(&shuffled, &truth, &info).unwrap(), &r);
        prop_assert_eq!(&evaluate_matrix_bands(&shuffled, &truth, &info, None).unwrap(), &m);
    }
}

#[test]
fn obstacles_are_scored_against_the_true_terrain_and_objects() {
    // 0.25 m cells, 40 × 5: ground at 0 up to key 19, a 0.5 m step up from key 20 on
    // (beyond the 0.25 m limit); key 35 is an object (truth hazard obstacle); key 30
    // is water. The mapper's rule makes 20 (the upper side) a step: the true obstacles
    // are keys 20 and 35.
    let mut truth = raster(0.25, 40, 5, |kx, _| kx == 30);
    for c in &mut truth.cells {
        if c.key.x >= 20 {
            c.z = 0.5;
        }
        if c.key.x == 35 {
            c.class = Class::Obstacle;
            c.hazard = Hazard::Obstacle;
        }
    }
    let true_keys = [20, 35];
    // The map calls the step's upper side (20) and a flat cell (5) obstacles.
    let mut map = truth.clone();
    for c in &mut map.cells {
        c.class = Class::Ground;
        c.hazard = if c.key.x == 20 || c.key.x == 5 {
            Hazard::Obstacle
        } else {
            Hazard::Free
        };
    }
    let r = evaluate(&map, &truth, &info(0.25, &[[0.0, 0.625]], None)).unwrap();
    let a = &r.all;
    assert_eq!(a.obstacle_cells, true_keys.len() * 5);
    assert_eq!((a.obstacle_detected, a.obstacle_recall), (5, Some(0.5)));
    assert_eq!((a.called_obstacle, a.false_obstacle), (10, 5));
    assert_eq!(a.obstacle_precision, Some(0.5));
    // By range: key 5 (1.375 m) in 0-5, keys 20, 35 (5.125, 8.875 m) in 5-10.
    assert_eq!((r.bins[0].obstacle_cells, r.bins[0].false_obstacle), (0, 5));
    assert_eq!(
        (r.bins[1].obstacle_cells, r.bins[1].obstacle_detected),
        (10, 5)
    );
    assert_eq!(r.bins[1].obstacle_precision, Some(1.0));
    // A noisy flat map of a flat truth has no true obstacle and scores none.
    let flat = raster(0.25, 40, 5, |_, _| false);
    let r = evaluate(&flat, &flat, &info(0.25, &[[0.0, 0.625]], None)).unwrap();
    assert_eq!((r.all.obstacle_cells, r.all.called_obstacle), (0, 0));
    assert_eq!(
        (r.all.obstacle_recall, r.all.obstacle_precision),
        (None, None)
    );
    assert_eq!(r.obstacle_limits, ObstacleLimits::default());
}

#[test]
fn bin_names() {
    let n: Vec<_> = (0..5).map(bin_name).collect();
    assert_eq!(n, ["0-5", "5-10", "10-20", "20-30", "30+"]);
}
