use super::*;
use crate::geom::{pose_xyz_rpy, PointCloud};
use proptest::prelude::*;

/// Deterministic test noise: splitmix64 and Box–Muller.
struct TestRng(u64);
impl TestRng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

fn grid(size: usize) -> RollingGrid {
    RollingGrid::new(
        GridConfig {
            size_cells: size,
            ..GridConfig::default()
        },
        0.0,
        0.0,
    )
    .unwrap()
}

/// `per_cell` points per 0.1 m cell over a `side` m square centred at the origin, heights
/// from `f` plus N(0, sigma).
fn terrain_cloud(
    f: &dyn Fn(f64, f64) -> f64,
    side: f64,
    per_cell: usize,
    sigma: f64,
    seed: u64,
) -> PointCloud {
    let mut rng = TestRng(seed);
    let cells = (side / 0.1).round() as usize;
    let mut pts = Vec::with_capacity(cells * cells * per_cell);
    for _ in 0..cells * cells * per_cell {
        let x = (rng.uniform() - 0.5) * side;
        let y = (rng.uniform() - 0.5) * side;
        pts.push([x as f32, y as f32, (f(x, y) + sigma * rng.normal()) as f32]);
    }
    PointCloud::unorganized(pts)
}

/// RMS of (cell elevation − f at the cell centre) over cells whose footprint `keep` accepts.
fn rms_error(
    g: &RollingGrid,
    f: &dyn Fn(f64, f64) -> f64,
    keep: &dyn Fn(f64, f64) -> bool,
) -> (f64, usize) {
    let mut se = 0.0;
    let mut n = 0;
    for (k, c) in g.observed() {
        let (x, y) = g.centre_of(k);
        if !keep(x, y) || c.hits < 20 {
            continue;
        }
        let z = g.config().z_ref + c.mean_mm().unwrap() * 1e-3;
        se += (z - f(x, y)).powi(2);
        n += 1;
    }
    ((se / n as f64).sqrt(), n)
}

#[test]
fn analytic_terrain_rms_within_one_centimetre() {
    let plane = |_x: f64, _y: f64| 1.25;
    let slope = |x: f64, y: f64| 0.3 * x - 0.1 * y + 2.0;
    let sinus =
        |x: f64, y: f64| 0.5 * (2.0 * std::f64::consts::PI * x / 8.0).sin() + 0.2 * (y / 3.0).cos();
    let step = |x: f64, _y: f64| if x < 0.0 { 0.0 } else { 0.5 };
    let all = |_x: f64, _y: f64| true;
    // Cells whose footprint does not straddle the step edge at x = 0.
    let off_edge = |x: f64, _y: f64| x.abs() > 0.06;
    type Case<'a> = (
        &'a str,
        &'a dyn Fn(f64, f64) -> f64,
        &'a dyn Fn(f64, f64) -> bool,
    );
    let cases: [Case; 4] = [
        ("plane", &plane, &all),
        ("slope", &slope, &all),
        ("sinusoid", &sinus, &all),
        ("step", &step, &off_edge),
    ];
    for (i, (name, f, keep)) in cases.into_iter().enumerate() {
        let mut g = grid(200);
        let cloud = terrain_cloud(f, 16.0, 25, 0.02, 7 + i as u64);
        let st = g.ingest(&cloud, &RangeNoise::constant(0.02)).unwrap();
        assert_eq!(st.fused + st.below, st.points, "{name}");
        let (rms, n) = rms_error(&g, f, keep);
        assert!(n > 20_000, "{name}: only {n} cells");
        assert!(rms <= 0.01, "{name}: rms {rms:.4} m over {n} cells");
    }
}

#[test]
fn step_edge_cells_take_the_upper_surface_not_the_average() {
    // Cells straddling a 0.5 m step hold two clusters; the split keeps the upper one when
    // it holds a quarter of the weight, never the meaningless average.
    let step = |x: f64, _y: f64| if x < 0.0 { 0.0 } else { 0.5 };
    let mut g = grid(200);
    g.ingest(
        &terrain_cloud(&step, 16.0, 25, 0.02, 3),
        &RangeNoise::constant(0.02),
    )
    .unwrap();
    for (k, c) in g.observed() {
        let (x, _) = g.centre_of(k);
        if x.abs() < 0.06 {
            let z = c.mean_mm().unwrap() * 1e-3;
            assert!(
                !(0.1..=0.4).contains(&z),
                "edge cell at x={x} averaged to {z}"
            );
        }
    }
}

#[test]
fn points_far_below_a_known_surface_are_counted_not_fused() {
    let mut g = grid(50);
    let flat = terrain_cloud(&|_, _| 0.0, 4.0, 20, 0.01, 1);
    g.ingest(&flat, &RangeNoise::constant(0.01)).unwrap();
    let before = g.cell_at(0.05, 0.05).unwrap();
    // A reflection 1.5 m below the surface, in a later batch.
    let refl = PointCloud::unorganized(vec![[0.05, 0.05, -1.5]; 7]);
    let st = g.ingest(&refl, &RangeNoise::constant(0.01)).unwrap();
    assert_eq!(st.below, 7);
    assert_eq!(st.fused, 0);
    let after = g.cell_at(0.05, 0.05).unwrap();
    assert_eq!(after.below, before.below + 7);
    assert_eq!(after.mean_mm(), before.mean_mm());
}

#[test]
fn a_surface_of_noisy_points_that_agree_does_not_gate_a_precise_one_below() {
    // Five far stereo points (σ 0.8 m) that happen to agree at 1.2 m, then the lidar's
    // ground (σ 2 cm) at 0: the difference is within three σ of the two heights together,
    // so the ground is fused, and, weighed by its precision, sets the elevation.
    let mut g = grid(50);
    let stereo = PointCloud::unorganized(vec![[0.05, 0.05, 1.2]; 5]);
    g.ingest(&stereo, &RangeNoise::constant(0.8)).unwrap();
    let lidar = PointCloud::unorganized(vec![[0.05, 0.05, 0.0]; 3]);
    let st = g.ingest(&lidar, &RangeNoise::constant(0.02)).unwrap();
    assert_eq!((st.fused, st.below), (3, 0));
    let z = g.cell_at(0.05, 0.05).unwrap().mean_mm().unwrap();
    assert!(z.abs() < 2.0, "{z} mm");
    // A precise surface still gates what lies far below it, precise or not.
    for sigma in [0.02, 0.3] {
        let below = PointCloud::unorganized(vec![[0.05, 0.05, -1.5]; 2]);
        let st = g.ingest(&below, &RangeNoise::constant(sigma)).unwrap();
        assert_eq!((st.fused, st.below), (0, 2), "σ {sigma}");
    }
}

#[test]
fn points_below_the_surface_in_the_same_batch_are_split_off() {
    let mut g = grid(50);
    let mut pts = vec![[0.05f32, 0.05, 0.30]; 30];
    pts.extend(vec![[0.05f32, 0.05, -2.0]; 5]);
    let st = g
        .ingest(&PointCloud::unorganized(pts), &RangeNoise::constant(0.02))
        .unwrap();
    assert_eq!((st.fused, st.below), (30, 5));
    let c = g.cell_at(0.05, 0.05).unwrap();
    assert_eq!(c.mean_mm(), Some(300.0));
    assert_eq!(c.below, 5);
}

#[test]
fn nonfinite_points_are_skipped_and_counted() {
    let mut g = grid(20);
    let cloud = PointCloud::unorganized(vec![
        [0.0, 0.0, 0.0],
        [f32::NAN, 0.0, 0.0],
        [0.0, f32::INFINITY, 0.0],
        [0.0, 0.0, f32::NEG_INFINITY],
        [f32::NAN; 3],
        [50.0, 0.0, 0.0],
    ]);
    let st = g.ingest(&cloud, &RangeNoise::LIDAR).unwrap();
    assert_eq!(
        st,
        IngestStats {
            points: 6,
            fused: 1,
            below: 0,
            nonfinite: 4,
            outside: 1
        }
    );
    assert_eq!(g.observed_count(), 1);
}

#[test]
fn empty_and_all_nan_clouds_change_nothing() {
    let mut g = grid(20);
    let empty = g.clone();
    assert_eq!(
        g.ingest(&PointCloud::unorganized(vec![]), &RangeNoise::LIDAR)
            .unwrap(),
        IngestStats::default()
    );
    let st = g
        .ingest(
            &PointCloud::unorganized(vec![[f32::NAN; 3]; 1000]),
            &RangeNoise::LIDAR,
        )
        .unwrap();
    assert_eq!(st.nonfinite, 1000);
    assert_eq!(g, empty);
}

#[test]
fn bad_configs_are_rejected_with_what_was_wrong() {
    for (res, size) in [(0.0, 10), (-0.1, 10), (f64::NAN, 10), (0.1, 0), (0.1, 1)] {
        let e = RollingGrid::new(
            GridConfig {
                resolution: res,
                size_cells: size,
                ..GridConfig::default()
            },
            0.0,
            0.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("resolution") || e.contains("size"), "{e}");
    }
    assert!(RollingGrid::new(GridConfig::default(), f64::NAN, 0.0).is_err());
    let mut g = grid(10);
    assert!(g.recenter(f64::INFINITY, 0.0, &mut DiscardSink).is_err());
    assert!(g
        .ingest(
            &PointCloud::unorganized(vec![[0.0; 3]]),
            &RangeNoise::constant(0.0)
        )
        .is_err());
}

#[test]
fn a_far_pose_keeps_centimetre_accuracy() {
    // UTM-like: 5,000 km east, 4,000 km north. Points are local f32, the pose carries the
    // offset in f64.
    let (ex, ny) = (5.0e6, 4.0e6);
    let mut g = RollingGrid::new(GridConfig::default(), ex, ny).unwrap();
    let mut cloud = terrain_cloud(&|x, _| 0.1 * x, 10.0, 20, 0.0, 5);
    cloud.frame_to_map = pose_xyz_rpy(ex, ny, 0.0, 0.0, 0.0, 0.0);
    g.ingest(&cloud, &RangeNoise::constant(0.02)).unwrap();
    let mut worst: f64 = 0.0;
    for (k, c) in g.observed() {
        let (x, _) = g.centre_of(k);
        let z = c.mean_mm().unwrap() * 1e-3;
        worst = worst.max((z - 0.1 * (x - ex)).abs());
    }
    assert!(worst < 0.01, "worst {worst}");
    assert!(g.observed_count() > 9000);
}

#[test]
fn one_and_two_threads_give_identical_grids() {
    let f = |x: f64, y: f64| 0.3 * (x * 0.7).sin() + 0.1 * y;
    let mut cloud = terrain_cloud(&f, 20.0, 8, 0.03, 11);
    // Reflections and holes so that the gate and the split both run.
    let mut rng = TestRng(99);
    for _ in 0..20_000 {
        let (x, y) = ((rng.uniform() - 0.5) * 20.0, (rng.uniform() - 0.5) * 20.0);
        cloud
            .xyz
            .push([x as f32, y as f32, (f(x, y) - 1.0 - rng.uniform()) as f32]);
    }
    cloud.cols = cloud.xyz.len();
    assert!(cloud.len() > 2 * 32 * 1024);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut g = grid(256);
            let a = g.ingest(&cloud, &RangeNoise::LIDAR).unwrap();
            let b = g.ingest(&cloud, &RangeNoise::LIDAR).unwrap();
            (g, a, b)
        })
    };
    let (g1, a1, b1) = run(1);
    let (g2, a2, b2) = run(2);
    assert_eq!((a1, b1), (a2, b2));
    assert!(a1.below > 0 && b1.below > 0);
    assert!(g1 == g2, "grids differ between 1 and 2 threads");
}

#[test]
fn moving_by_a_fraction_of_a_cell_a_million_times_does_not_drift() {
    // The window's position is a function of where it is asked to be, never an accumulation
    // of steps: after a million sub-cell moves around a closed path it is exactly where a
    // fresh grid would put it, and the data it holds is untouched.
    let mut g = grid(100);
    g.ingest(
        &PointCloud::unorganized(vec![[0.05, 0.05, 1.0]]),
        &RangeNoise::LIDAR,
    )
    .unwrap();
    let start = g.origin();
    let cell = g.cell_at(0.05, 0.05).unwrap();
    let mut sink = TileMap::for_grid(&g);
    let steps = 1_000_000u64;
    for i in 1..=steps {
        let t = 2.0 * std::f64::consts::PI * i as f64 / steps as f64;
        let (x, y) = (0.05 + 3.0 * t.sin(), 0.05 + 2.0 * (2.0 * t).sin());
        g.recenter(x, y, &mut sink).unwrap();
        if i % 99_991 == 0 {
            let fresh = RollingGrid::new(g.config().clone(), x, y).unwrap();
            assert_eq!(g.origin(), fresh.origin(), "step {i}");
        }
    }
    assert_eq!(g.origin(), start);
    assert_eq!(g.cell_at(0.05, 0.05), Some(cell));
    assert_eq!(sink.observed_count(), 0);
}

fn arb_points(n: std::ops::Range<usize>) -> impl Strategy<Value = Vec<[f32; 3]>> {
    // Points of a gentle surface: height spread far below the gate, so no point is gated and
    // the fused sums are exactly those of the concatenation.
    prop::collection::vec(
        (-6.0f32..6.0, -6.0f32..6.0, -0.05f32..0.05).prop_map(|(x, y, dz)| [x, y, 0.02 * x + dz]),
        n,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn moves_and_back_keep_overlapping_cells(
        pts in arb_points(0..400),
        moves in prop::collection::vec((-30i64..30, -30i64..30), 1..12),
    ) {
        let mut g = grid(64);
        g.ingest(&PointCloud::unorganized(pts), &RangeNoise::LIDAR).unwrap();
        let start = g.origin();
        let before: Vec<_> = g.observed().collect();
        let mut sink = TileMap::for_grid(&g);
        // Cells inside every window visited stay exactly; all others went to the sink.
        let (mut lo, mut hi) = ((start.x, start.y), (start.x + 63, start.y + 63));
        for &(dx, dy) in &moves {
            let o = CellKey::new(g.origin().x + dx, g.origin().y + dy);
            g.move_origin(o, &mut sink);
            lo = (lo.0.max(o.x), lo.1.max(o.y));
            hi = (hi.0.min(o.x + 63), hi.1.min(o.y + 63));
        }
        g.move_origin(start, &mut sink);
        for (k, c) in &before {
            let stayed = (lo.0..=hi.0).contains(&k.x) && (lo.1..=hi.1).contains(&k.y);
            if stayed {
                prop_assert_eq!(g.cell(*k), Some(*c));
                prop_assert_eq!(sink.get(*k), None);
            } else {
                prop_assert_eq!(g.cell(*k), Some(CellStats::default()));
                prop_assert_eq!(sink.get(*k), Some(*c));
            }
        }
    }

    /// The occupancy layer the water stage reads says exactly which cells hold something,
    /// through ingest, evidence of every kind (empty evidence included) and moves; the
    /// row scan built on it finds every cell that holds data, in key order, at its index.
    #[test]
    fn occupancy_follows_every_writer(
        pts in arb_points(0..300),
        evidence in prop::collection::vec((-40i64..40, -40i64..40, 0u8..4), 0..40),
        moves in prop::collection::vec((-40i64..40, -40i64..40), 0..4),
    ) {
        let mut g = grid(64);
        let mut sink = DiscardSink;
        g.ingest(&PointCloud::unorganized(pts), &RangeNoise::LIDAR).unwrap();
        for (i, &(x, y, kind)) in evidence.iter().enumerate() {
            let mut e = Evidence::default();
            match kind {
                0 => {}
                1 => e.add_level(-120),
                2 => e.noret = 1,
                _ => e.add_bottom_return(0.2, 30, 1.5),
            }
            let o = g.origin();
            g.add_evidence(CellKey::new(o.x + 32 + x, o.y + 32 + y), &e);
            if let Some(&(dx, dy)) = moves.get(i) {
                g.move_origin(CellKey::new(o.x + dx, o.y + dy), &mut sink);
            }
        }
        for i in 0..64 * 64 {
            prop_assert_eq!(g.layers.is_empty_at(i), g.layers.get(i).is_empty(), "cell {}", i);
        }
        // The row scan lists the cells that hold data in key order, at their indices.
        let o = g.origin();
        let scanned: Vec<_> = g
            .observed_indices()
            .map(|(j, i)| (CellKey::new(o.x + (j % 64) as i64, o.y + (j / 64) as i64), i))
            .collect();
        let listed: Vec<_> = (0..64 * 64)
            .map(|j| CellKey::new(o.x + (j % 64) as i64, o.y + (j / 64) as i64))
            .filter_map(|k| g.index(k).filter(|&i| !g.layers.get(i).is_empty()).map(|i| (k, i)))
            .collect();
        prop_assert_eq!(scanned, listed);
    }

    #[test]
    fn a_cell_is_never_visible_at_two_positions(
        moves in prop::collection::vec((-100i64..100, -100i64..100), 1..8),
        probe in (-20.0f64..20.0, -20.0f64..20.0),
    ) {
        let mut g = grid(32);
        for &(dx, dy) in &moves {
            let o = CellKey::new(g.origin().x + dx, g.origin().y + dy);
            g.move_origin(o, &mut DiscardSink);
            // Every buffer slot belongs to exactly one in-window key.
            let mut seen = vec![false; 32 * 32];
            for ky in o.y..o.y + 32 {
                for kx in o.x..o.x + 32 {
                    let i = g.index(CellKey::new(kx, ky)).unwrap();
                    prop_assert!(!seen[i]);
                    seen[i] = true;
                }
            }
            prop_assert!(!g.contains(CellKey::new(o.x - 1, o.y)));
            prop_assert!(!g.contains(CellKey::new(o.x, o.y + 32)));
        }
        // A point lands at its own key and nowhere else.
        let (cx, cy) = g.centre_of(CellKey::new(g.origin().x + 5, g.origin().y + 7));
        let (px, py) = (cx + probe.0 * 0.0, cy + probe.1 * 0.0);
        g.ingest(&PointCloud::unorganized(vec![[px as f32, py as f32, 0.5]]), &RangeNoise::LIDAR).unwrap();
        let hits: Vec<_> = g.observed().map(|(k, _)| k).collect();
        prop_assert_eq!(hits, vec![g.key_of(px, py)]);
    }

    #[test]
    fn a_move_beyond_the_window_clears_everything(
        pts in arb_points(1..300),
        far in 64i64..10_000,
        diag in any::<bool>(),
    ) {
        let mut g = grid(64);
        g.ingest(&PointCloud::unorganized(pts), &RangeNoise::LIDAR).unwrap();
        let before: Vec<_> = g.observed().collect();
        let mut sink = TileMap::for_grid(&g);
        let o = g.origin();
        g.move_origin(CellKey::new(o.x + far, o.y + if diag { -far } else { 0 }), &mut sink);
        prop_assert_eq!(g.observed_count(), 0);
        prop_assert_eq!(sink.observed().collect::<Vec<_>>(), {
            let mut b = before.clone();
            b.sort_by_key(|(k, _)| ((k.x.div_euclid(64), k.y.div_euclid(64)), k.y, k.x));
            b
        });
    }

    #[test]
    fn merging_two_maps_equals_ingesting_the_concatenation(
        a in arb_points(0..300),
        b in arb_points(0..300),
    ) {
        let ingest = |pts: Vec<[f32; 3]>| {
            let mut g = grid(128);
            g.ingest(&PointCloud::unorganized(pts), &RangeNoise::LIDAR).unwrap();
            g
        };
        let ga = ingest(a.clone());
        let gb = ingest(b.clone());
        let gab = ingest(a.iter().chain(&b).copied().collect());
        let mut merged = ga.clone();
        merged.merge(&gb, &mut DiscardSink).unwrap();
        prop_assert!(merged == gab);
        // The same through the global tile maps, in either order.
        let mut ta = TileMap::for_grid(&ga);
        ta.absorb_window(&ga).unwrap();
        // The window lists its cells in the tile map's order (the mapper's snapshots rely
        // on it); also for a window that is not aligned with the tiles.
        prop_assert_eq!(ga.observed_by_tile().collect::<Vec<_>>(), ta.observed().collect::<Vec<_>>());
        let mut shifted = RollingGrid::new(GridConfig { size_cells: 100, ..GridConfig::default() }, 3.37, -2.11).unwrap();
        shifted.ingest(&PointCloud::unorganized(a.clone()), &RangeNoise::LIDAR).unwrap();
        let mut ts = TileMap::for_grid(&shifted);
        ts.absorb_window(&shifted).unwrap();
        prop_assert_eq!(shifted.observed_by_tile().collect::<Vec<_>>(), ts.observed().collect::<Vec<_>>());
        let mut tb = TileMap::for_grid(&gb);
        tb.absorb_window(&gb).unwrap();
        let mut tab = TileMap::for_grid(&gab);
        tab.absorb_window(&gab).unwrap();
        let mut t1 = ta.clone();
        t1.merge(&tb).unwrap();
        tb.merge(&ta).unwrap();
        prop_assert!(t1 == tab);
        prop_assert!(tb == tab);
    }
}

/// Points on a rough surface with a share of them far below it (reflections), so that
/// both the prior gate and the first-batch split run.
fn arb_layered(n: std::ops::Range<usize>) -> impl Strategy<Value = Vec<[f32; 3]>> {
    prop::collection::vec((-6.0f32..6.0, -6.0f32..6.0, -0.05f32..0.05, 0u8..10), n).prop_map(|v| {
        v.into_iter()
            .map(|(x, y, dz, kind)| {
                let z = 0.2 * (x * 0.5).sin() + dz - if kind == 0 { 0.9 } else { 0.0 };
                [x, y, z]
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn chunking_and_point_order_do_not_change_the_grid(
        first in arb_layered(1..2000),
        second in arb_layered(1..2000),
        chunks in 2usize..9,
        rot in 0usize..2000,
    ) {
        let run = |a: &[[f32; 3]], b: &[[f32; 3]], chunks: usize| {
            let mut g = grid(128);
            let sa = g
                .ingest_chunked(&PointCloud::unorganized(a.to_vec()), &RangeNoise::LIDAR, chunks)
                .unwrap();
            let sb = g
                .ingest_chunked(&PointCloud::unorganized(b.to_vec()), &RangeNoise::LIDAR, chunks)
                .unwrap();
            (g, sa, sb)
        };
        let (g1, a1, b1) = run(&first, &second, 1);
        // Another chunking, and each batch rotated and reversed.
        let mut fa = first.clone();
        fa.rotate_left(rot % first.len());
        fa.reverse();
        let mut sb = second.clone();
        sb.rotate_left(rot % second.len());
        let (g2, a2, b2) = run(&fa, &sb, chunks);
        prop_assert_eq!((a1, b1), (a2, b2));
        prop_assert!(g1 == g2, "grids differ with {} chunks", chunks);
    }

    #[test]
    fn cell_coord_is_floor_of_the_quotient(
        k in -2_000_000_000i64..2_000_000_000,
        ulps in -3i64..4,
        res in prop::sample::select(vec![0.005, 0.05, 0.1, 0.2, 0.25, 0.3, 1.0 / 3.0, 0.7, 2.0]),
        frac in 0.0f64..1.0,
    ) {
        // Exactly on (a few ulps around) a cell boundary, and anywhere inside a cell.
        let edge = k as f64 * res;
        let v = edge * (1.0 + ulps as f64 * f64::EPSILON);
        let inside = (k as f64 + frac) * res;
        for v in [v, inside, -v, -inside] {
            prop_assert_eq!(
                crate::geom::cell_coord(v, 1.0 / res, res),
                (v / res).floor() as i64,
                "v {} res {}", v, res
            );
        }
    }

    #[test]
    fn fast_weight_is_quantize_weight(e in -12.0f64..6.0, m in 1.0f64..10.0) {
        let sigma = m * 10f64.powf(e);
        prop_assert_eq!(super::ingest::weight_of(sigma), quantize_weight(sigma));
        for s in [0.0, -sigma, f64::NAN, f64::INFINITY, 6.25e-4 * 0.999_999, 6.25e-4] {
            prop_assert_eq!(super::ingest::weight_of(s), quantize_weight(s));
        }
    }
}

/// A range sensor errs along its ray: the published σ of level ground seen at grazing
/// incidence is the vertical part of the range noise, and is what the cells' errors show
/// (about 68 % within 1σ, 99.7 % within 3σ); the range bound keeps every error vertical.
#[test]
fn elevation_std_follows_the_vertical_part_of_range_noise() {
    let (sigma, height, per_cell) = (0.03, 2.0, 4);
    let mut rng = TestRng(7);
    let mut pts = Vec::new();
    // Cells along y = 0.05, 5–25 m out, each hit by `per_cell` rays.
    let cells: Vec<f64> = (50..250).map(|i| i as f64 * 0.1 + 0.05).collect();
    for &x in &cells {
        for _ in 0..per_cell {
            let (tx, ty) = (
                x + (rng.uniform() - 0.5) * 0.08,
                0.05 + (rng.uniform() - 0.5) * 0.08,
            );
            let d = nalgebra::Vector3::new(tx, ty, -height);
            let r = d.norm();
            let p = d * ((r + sigma * rng.normal()) / r);
            pts.push([p.x as f32, p.y as f32, (height + p.z) as f32]);
        }
    }
    let mut cloud = PointCloud::unorganized(pts);
    cloud.sensor_origin = nalgebra::Point3::new(0.0, 0.0, height);
    let mut g = grid(600);
    g.ingest(&cloud, &RangeNoise::constant(sigma)).unwrap();
    let (mut within1, mut within3, mut ratio) = (0, 0, 0.0);
    for &x in &cells {
        let c = g.cell_at(x, 0.05).unwrap();
        let (z, s, bound) = (
            c.mean_mm().unwrap() * 1e-3,
            c.elevation_std_m().unwrap(),
            c.range_bound_std_m().unwrap(),
        );
        // The vertical share at x is height / range: at most 0.37 here.
        ratio += s / bound / (height / x.hypot(height));
        assert!(bound >= sigma / f64::from(c.hits).sqrt() - 1e-4, "{bound}");
        within1 += (z.abs() <= s) as usize;
        within3 += (z.abs() <= 3.0 * s) as usize;
    }
    let n = cells.len() as f64;
    let (f1, f3) = (within1 as f64 / n, within3 as f64 / n);
    // The published σ is the bound times the share (more where the points' spread says so).
    assert!(
        (0.9..1.4).contains(&(ratio / n)),
        "σ / bound / share {}",
        ratio / n
    );
    assert!((0.58..0.78).contains(&f1), "{f1} within 1σ");
    assert!(f3 >= 0.98, "{f3} within 3σ");
}

#[test]
fn key_at_is_the_inverse_of_index_wherever_the_window_moved() {
    let mut g = grid(7);
    for o in [(0, 0), (3, -5), (-11, 9), (100, 2)] {
        g.move_origin(CellKey::new(o.0, o.1), &mut DiscardSink);
        let o = g.origin();
        for y in o.y..o.y + 7 {
            for x in o.x..o.x + 7 {
                let k = CellKey::new(x, y);
                assert_eq!(g.key_at(g.index(k).unwrap()), k);
            }
        }
    }
}

proptest! {
    /// The layers give back the evidence last set in each cell, whichever slots its level
    /// and depth evidence went to and whether an infrared camera voted, and layers holding
    /// the same cells are equal whatever order the cells were written in.
    #[test]
    fn layers_keep_every_cells_evidence(
        writes in prop::collection::vec(
            (0usize..40, 0u16..3, 0u32..3, 0u32..2, any::<i64>(), 0u16..2), 0..120),
    ) {
        let mut l = Layers::new(40);
        let mut truth = vec![Evidence::default(); 40];
        for &(i, noret, level_n, depth_n, sum, swir) in &writes {
            let e = Evidence {
                noret,
                colour_dry: noret,
                level_n,
                level_sum_mm: if level_n > 0 { sum } else { 0 },
                depth_n,
                depth_sum_mm: depth_n * 7,
                depth_gain_level_sum: sum.wrapping_mul(depth_n as i64),
                swir_dark: swir,
                mwir_dry: swir,
                ..Evidence::default()
            };
            l.set_ev(i, &e);
            truth[i] = e;
            for (j, t) in truth.iter().enumerate() {
                prop_assert_eq!(l.get_ev(j), *t);
            }
        }
        // The same cells written in the other order.
        let mut r = Layers::new(40);
        for (i, t) in truth.iter().enumerate().rev() {
            r.set_ev(i, t);
        }
        prop_assert!(l == r);
    }
}
