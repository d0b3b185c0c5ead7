use std::collections::VecDeque;

use super::beams::fit_line;
use super::below::{mirror_refuted, ScanLine};
use super::bright::bright_reference;
use super::walk::{
    below_gate, SlopeWindow, GATE_MIN, GATE_WINDOW, SLOPE_BASELINE_M, SLOPE_WINDOW_M,
};
use super::*;
use crate::cues::testutil::TestRng;
use crate::cues::{CueRun, PriorLevel, ReflectivityConfig, WaterPrior};
use crate::grid::{key_of, CellKey, Evidence, GridConfig, RangeNoise, RollingGrid};
use crate::optics::{apparent_bottom_point, Attenuation, LidarModelConfig, LidarWaterModel};

const RES: f64 = 0.1;

/// The paper's sensor (1 m high, dry ground lost at 11 m) at 905 nm in pure water.
fn optics(height: f64) -> LidarModelConfig {
    LidarModelConfig {
        height_m: height,
        ..LidarModelConfig::paper(Attenuation::PureWater {
            wavelength_nm: 905.0,
        })
    }
}

/// Flat ground at z = 0 with a pond (level 0, flat bottom at −depth) where `in_pond(x, y)`.
struct Scene<'a> {
    model: LidarWaterModel,
    depth: f64,
    in_pond: &'a dyn Fn(f64, f64) -> bool,
}

/// What the simulated beam did.
enum Shot {
    Missing { lookahead: f64, over_water: bool },
    Ground(Point3<f64>),
    Bottom { apparent: Point3<f64>, depth: f64 },
}

impl Scene<'_> {
    fn shoot(&self, o: Point3<f64>, u: Vector3<f64>) -> Option<Shot> {
        if u.z >= 0.0 {
            return None;
        }
        let t = o.z / -u.z;
        let hit = o + u * t;
        let d = (hit.x - o.x).hypot(hit.y - o.y);
        if (self.in_pond)(hit.x, hit.y) {
            if self.model.return_ratio(d, self.depth).unwrap() >= self.model.min_power_ratio() {
                let g = self.model.geometry(d, self.depth).unwrap();
                let dir = Vector3::new(hit.x - o.x, hit.y - o.y, 0.0) / d;
                let b = o + dir * g.bottom_distance - Vector3::z() * (o.z + self.depth);
                let apparent = apparent_bottom_point(o, b, 0.0, 1.33).unwrap();
                Some(Shot::Bottom {
                    apparent,
                    depth: self.depth,
                })
            } else {
                Some(Shot::Missing {
                    lookahead: d,
                    over_water: true,
                })
            }
        } else if self.model.dry_ratio(d).unwrap() >= self.model.min_power_ratio() {
            Some(Shot::Ground(hit))
        } else {
            Some(Shot::Missing {
                lookahead: d,
                over_water: false,
            })
        }
    }
}

/// A single-row vertical scanner in the x–z plane, `n` beams from 60° to 1° below the
/// horizon; range noise `sigma` along the beam.
fn vertical_scan(
    scene: &Scene,
    n: usize,
    sigma: f64,
    seed: u64,
) -> (PointCloud, Vec<[f32; 3]>, Vec<Shot>) {
    let o = Point3::new(0.0, 0.0, scene.model.config().height_m);
    let mut rng = TestRng(seed);
    let (mut xyz, mut dirs, mut shots) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..n {
        let dep = (60.0 - 59.0 * k as f64 / (n - 1) as f64).to_radians();
        let u = Vector3::new(dep.cos(), 0.0, -dep.sin());
        dirs.push([u.x as f32, u.y as f32, u.z as f32]);
        let shot = scene.shoot(o, u).unwrap();
        let p = match &shot {
            Shot::Missing { .. } => [f32::NAN; 3],
            Shot::Ground(p) | Shot::Bottom { apparent: p, .. } => {
                let v = p - o;
                let q = p + v / v.norm() * (sigma * rng.normal());
                [q.x as f32, q.y as f32, q.z as f32]
            }
        };
        xyz.push(p);
        shots.push(shot);
    }
    let mut c = PointCloud::organized(1, n, xyz).unwrap();
    c.sensor_origin = o;
    (c, dirs, shots)
}

fn shallow_pond_scene(model: &LidarWaterModel) -> (f64, f64) {
    // The pond starts before the diagnostic interval and ends inside it, so both bottom
    // returns and no-returns occur, with dry returning ground beyond.
    let (start, end) = model.diagnostic_interval(0.0).unwrap().unwrap();
    let bottom_seen = model.max_lookahead_for_depth(0.2).unwrap().unwrap();
    (0.5 * bottom_seen, 0.5 * (start + end))
}

/// `base` (its beams set to the scan's) run on a vertical scan of 600 beams, range noise
/// `sigma`, of flat ground with water `depth` deep where `in_pond`: the scan, the cue's
/// output and what each beam did.
fn run_over_pond(
    base: &LidarCueModel,
    depth: f64,
    in_pond: &dyn Fn(f64, f64) -> bool,
    sigma: f64,
    seed: u64,
) -> (PointCloud, LidarCues, Vec<Shot>) {
    let scene = Scene {
        model: base.optics().clone(),
        depth,
        in_pond,
    };
    let (cloud, dirs, shots) = vertical_scan(&scene, 600, sigma, seed);
    let cue = LidarCueModel {
        beams: BeamModel::Directions(dirs),
        ..base.clone()
    };
    let out = cue
        .run(&cloud, &scan_run(), &mut LidarBuffers::default())
        .unwrap();
    (cloud, out, shots)
}

/// The cue at its defaults, a 905 nm sensor 1 m over pure water, with no beam directions of
/// its own.
fn default_cue() -> LidarCueModel {
    LidarCueModel::new(
        optics(1.0),
        BeamModel::Directions(Vec::new()),
        LidarCueConfig::default(),
        None,
    )
    .unwrap()
}

#[test]
fn vertical_scanner_no_return_evidence_is_exactly_the_optics_interval() {
    let cue = default_cue();
    let (start, end) = cue.interval().unwrap();
    let (a, b) = shallow_pond_scene(cue.optics());
    let pond = move |x: f64, _y: f64| x >= a && x <= b;
    let (cloud, out, shots) = run_over_pond(&cue, 0.175, &pond, 0.0, 1);
    // Every missing beam over water inside the interval gives one no-return; nothing else.
    let expected: Vec<f64> = shots
        .iter()
        .filter_map(|s| match s {
            Shot::Missing { lookahead, .. } if *lookahead >= start && *lookahead <= end => {
                Some(*lookahead)
            }
            _ => None,
        })
        .collect();
    assert!(expected.len() > 20, "{} diagnostic beams", expected.len());
    eprintln!(
        "vertical scanner: interval [{start:.3}, {end:.3}] m, pond [{a:.3}, {b:.3}] m, {} missing \
         beams inside it, {} no-return events",
        expected.len(),
        out.stats.noret
    );
    assert_eq!(out.stats.noret as usize, expected.len());
    // The reported lookahead range is that of the diagnostic beams (to the millimetre).
    let lo = expected.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = expected.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let [rlo, rhi] = out.stats.noret_lookahead_mm.unwrap();
    assert!((rlo as f64 * 1e-3 - lo).abs() < 2e-3 && (rhi as f64 * 1e-3 - hi).abs() < 2e-3);
    assert!(rlo as f64 * 1e-3 >= start - 1e-3 && rhi as f64 * 1e-3 <= end + 1e-3);
    // The same scan published one beam per row (as the simulator and a SICK driver do),
    // with no beam model: the directions of the missing beams come from the line through
    // the returned ones, and the no-returns are the same.
    let column = PointCloud {
        rows: cloud.cols,
        cols: 1,
        ..cloud.clone()
    };
    let inferred = LidarCueModel {
        beams: BeamModel::default(),
        ..cue.clone()
    }
    .run(&column, &scan_run(), &mut LidarBuffers::default())
    .unwrap();
    assert_eq!(inferred.stats.no_direction, 0);
    assert_eq!(inferred.stats.noret, out.stats.noret);
    let water_missing = shots
        .iter()
        .filter(|s| {
            matches!(
                s,
                Shot::Missing {
                    over_water: true,
                    ..
                }
            )
        })
        .count();
    assert!(water_missing >= expected.len());
    for (k, e) in out.evidence.iter() {
        if e.noret > 0 {
            let (x, _) = crate::grid::centre_of(RES, *k);
            assert!(x >= start - RES && x <= end + RES, "noret at x = {x}");
            assert!(
                x >= a - RES && x <= b + RES,
                "noret outside the pond at x = {x}"
            );
        }
    }
    // Ground beyond the pond inside the interval returned: counted as diagnostic returns.
    assert!(out.stats.diag_ret > 0);
    for (k, e) in out.evidence.iter() {
        if e.diag_ret > 0 {
            let (x, _) = crate::grid::centre_of(RES, *k);
            assert!(
                x > b - RES && x >= start - RES && x <= end + RES,
                "diag_ret at {x}"
            );
        }
    }
}

#[test]
fn bottom_returns_give_depth_within_five_centimetres() {
    let base = default_cue();
    let (a, b) = shallow_pond_scene(base.optics());
    let pond = move |x: f64, _y: f64| x >= a && x <= b;
    for depth in [0.15, 0.20] {
        let (cloud, out, shots) = run_over_pond(&base, depth, &pond, 0.01, 7);
        let n_bottom = shots
            .iter()
            .filter(|s| matches!(s, Shot::Bottom { .. }))
            .count();
        assert!(
            n_bottom > 20,
            "{n_bottom} bottom returns, pond {a}..{b}, bottom seen to {:?}",
            base.optics().max_lookahead_for_depth(depth)
        );
        assert!(
            out.stats.bottom as usize >= n_bottom * 9 / 10,
            "{:?}",
            out.stats
        );
        let (mut se, mut n) = (0.0, 0usize);
        for (k, e) in out.evidence.iter() {
            if e.depth_n > 0 {
                let (x, _) = crate::grid::centre_of(RES, *k);
                assert!(x >= a - RES && x <= b + RES);
                let err = e.depth_m().unwrap() - depth;
                se += err * err * e.depth_n as f64;
                n += e.depth_n as usize;
                // The level the bottom was measured against is the shore's.
                assert!(e.level_mm().unwrap().abs() < 20.0);
            }
        }
        let rms = (se / n as f64).sqrt();
        eprintln!("bottom returns over {depth} m of water: {n} samples, depth RMS {rms:.4} m");
        assert!(rms <= 0.05, "depth RMS {rms} m at {depth} m");
        // Without refraction correction the raw depths would be far off: the test can fail.
        let raw_rms = {
            let v: Vec<f64> = shots
                .iter()
                .filter_map(|s| match s {
                    Shot::Bottom { apparent, depth } => Some(-apparent.z - depth),
                    _ => None,
                })
                .collect();
            (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt()
        };
        assert!(raw_rms > 2.0 * rms, "raw {raw_rms} corrected {rms}");
        // Bottom returns are taken out of the elevation cloud.
        assert_eq!(
            out.corrected.valid_count() + out.stats.bottom as usize,
            cloud.valid_count()
        );
    }
}

#[test]
fn deep_below_level_return_is_specular_and_left_out_of_the_terrain() {
    let cue = LidarCueModel::new(
        optics(1.0),
        BeamModel::Infer {
            max_gap_fraction: 0.25,
        },
        LidarCueConfig::default(),
        None,
    )
    .unwrap();
    let o = Point3::new(0.0, 0.0, 1.0);
    // Ground at 2, 3, 4 m, then a return 2 m below the level seen at 8 m horizontal: the
    // mirror image of a point 2 m up a tree. No bottom is visible 2 m deep there.
    let mut pts: Vec<[f32; 3]> = [2.0f32, 3.0, 4.0].iter().map(|&x| [x, 0.0, 0.0]).collect();
    pts.push([8.0, 0.0, -2.0]);
    let mut cloud = PointCloud::organized(1, 4, pts).unwrap();
    cloud.sensor_origin = o;
    let out = cue
        .run(&cloud, &scan_run(), &mut LidarBuffers::default())
        .unwrap();
    assert_eq!(out.stats.specular, 1);
    assert_eq!(out.stats.bottom, 0);
    // Not fused as terrain: mirrored about the walked level it would stand where the tree
    // is only if the water lay at that level.
    assert!(out.corrected.xyz[3].iter().all(|v| v.is_nan()));
    assert_eq!(out.corrected.xyz[2], [4.0, 0.0, 0.0]);
    // The ray crosses the level at x = 8 · 1/3.
    let k = key_of(RES, 8.0 / 3.0, 0.0);
    assert_eq!(out.evidence.get(k).unwrap().reflect, 1);
    assert_eq!(out.evidence.total().reflect, 1);
}

/// A spinning lidar: `rings` elevations, `cols` azimuths, 1.8 m high, with the beams of
/// missing returns unknown to the cue (inferred from the scan).
fn spinning_scan(
    scene: &Scene,
    rings: usize,
    cols: usize,
) -> (PointCloud, Vec<Shot>, Vec<Vector3<f64>>) {
    let o = Point3::new(0.0, 0.0, scene.model.config().height_m);
    let (mut xyz, mut shots, mut dirs) = (Vec::new(), Vec::new(), Vec::new());
    for r in 0..rings {
        // Ring 0 the top beam, as on an Ouster: +5° down to −25°.
        let el = (5.0 - 30.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = -2.0 * std::f64::consts::PI * c as f64 / cols as f64;
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            dirs.push(u);
            match scene.shoot(o, u) {
                None => {
                    xyz.push([f32::NAN; 3]);
                    shots.push(Shot::Missing {
                        lookahead: f64::INFINITY,
                        over_water: false,
                    });
                }
                Some(s) => {
                    xyz.push(match &s {
                        Shot::Missing { .. } => [f32::NAN; 3],
                        Shot::Ground(p) | Shot::Bottom { apparent: p, .. } => {
                            [p.x as f32, p.y as f32, p.z as f32]
                        }
                    });
                    shots.push(s);
                }
            }
        }
    }
    let mut c = PointCloud::organized(rings, cols, xyz).unwrap();
    c.sensor_origin = o;
    (c, shots, dirs)
}

#[test]
fn spinning_lidar_with_inferred_beams_finds_the_pond_and_only_the_pond() {
    let cue = LidarCueModel::new(
        optics(1.8),
        BeamModel::default(),
        LidarCueConfig::default(),
        None,
    )
    .unwrap();
    let (start, end) = cue.interval().unwrap();
    let centre = 0.5 * (start + end);
    let radius = 0.35 * (end - start).max(2.0);
    let pond = move |x: f64, y: f64| (x - centre).hypot(y) <= radius;
    let scene = Scene {
        model: cue.optics().clone(),
        depth: 0.5,
        in_pond: &pond,
    };
    let (cloud, shots, _) = spinning_scan(&scene, 32, 1024);
    let out = cue
        .run(&cloud, &scan_run(), &mut LidarBuffers::default())
        .unwrap();
    let expected = shots
        .iter()
        .filter(|s| matches!(s, Shot::Missing { lookahead, over_water: true } if *lookahead >= start && *lookahead <= end))
        .count();
    assert!(expected > 50, "{expected}");
    // Inferred directions recover nearly all of them.
    assert!(
        out.stats.noret as usize >= expected * 9 / 10 && out.stats.noret as usize <= expected,
        "{} of {expected}",
        out.stats.noret
    );
    for (k, e) in out.evidence.iter() {
        if e.noret > 0 {
            let (x, y) = crate::grid::centre_of(RES, *k);
            assert!(
                (x - centre).hypot(y) <= radius + 2.0 * RES,
                "noret at ({x}, {y})"
            );
        }
    }
    // Fused into a grid, the pond's cells read as water and the dry cells do not.
    let mut g = RollingGrid::new(
        GridConfig {
            size_cells: 400,
            ..GridConfig::default()
        },
        0.0,
        0.0,
    )
    .unwrap();
    g.ingest(&out.corrected, &crate::grid::RangeNoise::LIDAR)
        .unwrap();
    assert_eq!(g.apply_evidence(&out.evidence.clone().into_batch()), 0);
    let f = crate::grid::Fusion::default();
    let (mut dry_water, mut dry) = (0, 0);
    for (k, c) in g.observed() {
        let (x, y) = g.centre_of(k);
        if !pond(x, y) && (x - centre).hypot(y) > radius + 2.0 * RES {
            dry += 1;
            if c.ev.water_probability(&f) > 0.5 {
                dry_water += 1;
            }
        }
    }
    assert!(dry > 1000);
    assert_eq!(dry_water, 0, "{dry_water} of {dry} dry cells called water");
}

/// A spinning lidar 1.8 m up with every cue, the reflectivity cue included.
fn reflectivity_cue() -> LidarCueModel {
    LidarCueModel::new(
        optics(1.8),
        BeamModel::default(),
        LidarCueConfig::default(),
        Some(ReflectivityConfig::default()),
    )
    .unwrap()
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let cue = reflectivity_cue();
    let (start, end) = cue.interval().unwrap();
    let c0 = 0.5 * (start + end);
    let pond = move |x: f64, y: f64| (x - c0).hypot(y) <= 2.0;
    let scene = Scene {
        model: cue.optics().clone(),
        depth: 0.3,
        in_pond: &pond,
    };
    let (mut cloud, _, _) = spinning_scan(&scene, 16, 512);
    let mut rng = TestRng(3);
    cloud.intensity = Some(
        (0..cloud.len())
            .map(|_| (10.0 + rng.uniform()) as f32)
            .collect(),
    );
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                cue.run(&cloud, &scan_run(), &mut LidarBuffers::default())
                    .unwrap()
            })
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.evidence.clone().into_batch(), b.evidence.into_batch());
    assert_eq!(a.stats, b.stats);
}

/// A scan run in the storage of earlier, different scans (larger, smaller, with and without
/// intensity) gives what it gives alone.
#[test]
fn buffers_reused_across_scans_give_each_scan_its_own_result() {
    let cue = reflectivity_cue();
    let (start, end) = cue.interval().unwrap();
    let c0 = 0.5 * (start + end);
    let pond = move |x: f64, y: f64| (x - c0).hypot(y - 0.5) <= 2.0;
    let scene = Scene {
        model: cue.optics().clone(),
        depth: 0.3,
        in_pond: &pond,
    };
    let mut rng = TestRng(5);
    let scans: Vec<PointCloud> = [
        (16, 512, true),
        (8, 256, false),
        (32, 1024, true),
        (16, 512, false),
    ]
    .into_iter()
    .map(|(rings, cols, lit)| {
        let (mut c, _, _) = spinning_scan(&scene, rings, cols);
        if lit {
            c.intensity = Some(
                (0..c.len())
                    .map(|_| (10.0 + rng.uniform()) as f32)
                    .collect(),
            );
        }
        c
    })
    .collect();
    let mut bufs = LidarBuffers::default();
    for (i, c) in scans.iter().enumerate() {
        let fresh = cue
            .run(c, &scan_run(), &mut LidarBuffers::default())
            .unwrap();
        let reused = cue.run(c, &scan_run(), &mut bufs).unwrap();
        assert!(
            fresh.evidence.iter().count() > 10,
            "scan {i}: {:?}",
            fresh.stats
        );
        assert_eq!(fresh.stats, reused.stats, "scan {i}");
        // Bit for bit (NaN slots included, which `==` calls unequal).
        let bits = |v: &dyn std::fmt::Debug| format!("{v:?}");
        assert!(
            bits(&fresh.corrected) == bits(&reused.corrected),
            "scan {i}"
        );
        assert!(bits(&fresh.surface) == bits(&reused.surface), "scan {i}");
        let (mut a, mut b) = (fresh.evidence, reused.evidence);
        let mut batch = vec![(CellKey::new(7, 7), Evidence::default())];
        b.drain_batch_into(&mut batch);
        assert_eq!(a.clone().into_batch(), batch, "scan {i}");
        assert!(b.iter().next().is_none());
        a.reset(RES, 0.0);
        assert!(a.iter().next().is_none());
        bufs.recycle(b, reused.corrected);
    }
}

#[test]
fn bad_beam_models_are_errors_not_panics() {
    let cue = LidarCueModel::new(
        optics(1.0),
        BeamModel::Directions(vec![[1.0, 0.0, -1.0]; 3]),
        LidarCueConfig::default(),
        None,
    )
    .unwrap();
    let cloud = PointCloud::organized(1, 4, vec![[f32::NAN; 3]; 4]).unwrap();
    let e = cue
        .run(&cloud, &scan_run(), &mut LidarBuffers::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("3 directions"), "{e}");
    let bad = LidarCueConfig {
        below_gate_m: f64::NAN,
        ..LidarCueConfig::default()
    };
    assert!(LidarCueModel::new(optics(1.0), BeamModel::default(), bad, None).is_err());
    let spin = LidarCueModel::new(
        optics(1.0),
        BeamModel::Spinning {
            elevations_rad: vec![0.0; 5],
            azimuth0_rad: 0.0,
            clockwise: true,
        },
        LidarCueConfig::default(),
        None,
    )
    .unwrap();
    let e = spin.run(
        &PointCloud::organized(2, 2, vec![[f32::NAN; 3]; 4]).unwrap(),
        &scan_run(),
        &mut LidarBuffers::default(),
    );
    assert!(e.unwrap_err().to_string().contains("5 ring elevations"));
}

#[test]
fn sensor_height_is_estimated_from_the_ground_ring() {
    let pond = |_x: f64, _y: f64| false;
    let model = LidarWaterModel::new(optics(1.73)).unwrap();
    let scene = Scene {
        model,
        depth: 0.0,
        in_pond: &pond,
    };
    let (cloud, _, _) = spinning_scan(&scene, 32, 256);
    let h = estimate_sensor_height(&cloud).unwrap();
    assert!((h - 1.73).abs() < 1e-3, "{h}");
}

#[test]
fn dry_ground_sloping_away_is_not_the_bottom_of_water() {
    // A spinning lidar 1.8 m above a plane falling 3 % along +x and rising along −x (the
    // stream scene's slope), every beam returning out to 40 m. Behind the vehicle downhill
    // the ground drops 1.2 m below the level under it: no bottom, specular or no-return
    // evidence may come of that.
    let (g, h) = (-0.03, 1.8);
    let o = Point3::new(0.0, 0.0, h);
    let (rings, cols) = (32, 512);
    let mut xyz = Vec::new();
    for r in 0..rings {
        let el = (5.0 - 30.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = 2.0 * std::f64::consts::PI * c as f64 / cols as f64;
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            // o + t u on z = g x: h + t u.z = g t u.x.
            let den = g * u.x - u.z;
            let t = if den > 0.0 { h / den } else { f64::INFINITY };
            let p = o + u * t;
            xyz.push(if t.is_finite() && p.x.hypot(p.y) <= 40.0 {
                [p.x as f32, p.y as f32, p.z as f32]
            } else {
                [f32::NAN; 3]
            });
        }
    }
    let mut cloud = PointCloud::organized(rings, cols, xyz).unwrap();
    cloud.sensor_origin = o;
    let run = |cfg: LidarCueConfig| {
        LidarCueModel::new(optics(h), BeamModel::default(), cfg, None)
            .unwrap()
            .run(&cloud, &scan_run(), &mut LidarBuffers::default())
            .unwrap()
            .stats
    };
    let s = run(LidarCueConfig::default());
    assert_eq!((s.bottom, s.specular, s.noret), (0, 0, 0), "{s:?}");
    // Holding the level flat (the cue before it followed the slope) reads the ground
    // behind as the bottom of water.
    let flat = run(LidarCueConfig {
        max_ground_slope: 0.0,
        ..LidarCueConfig::default()
    });
    assert!(
        flat.bottom + flat.specular + flat.unexplained > 1000,
        "{flat:?}"
    );
}

proptest::proptest! {
    /// The sliding window's running sums give the slope a fresh least-squares fit of the
    /// same returns gives, also with the level kilometres from zero, and span the same
    /// returns the walk kept before it had sums: the oldest dropped while more than two
    /// remain and it lies more than the window behind the newest.
    #[test]
    fn slope_window_is_a_fresh_fit_of_its_returns(
        level0 in proptest::prop_oneof![-5.0f64..5.0, 3000.0f64..5000.0],
        steps in proptest::collection::vec((0.0f64..1.5, -0.3f64..0.3), 1..80),
    ) {
        let mut w = SlopeWindow::new((0.0, level0));
        let mut kept: VecDeque<(f64, f64)> = VecDeque::from([(0.0, level0)]);
        let mut d = 0.0;
        for (dd, dz) in steps {
            d += dd;
            let p = (d, level0 + dz + 0.02 * d);
            w.push(p);
            kept.push_back(p);
            while kept.len() > 2 && kept.front().is_some_and(|f| d - f.0 > SLOPE_WINDOW_M) {
                kept.pop_front();
            }
            proptest::prop_assert_eq!(&w.pts, &kept);
            let want = if kept.front().is_some_and(|f| d - f.0 >= SLOPE_BASELINE_M) {
                fit_line(kept.iter().copied()).map(|(_, _, g)| g)
            } else {
                None
            };
            match (w.slope(), want) {
                (None, None) => {}
                (Some(a), Some(b)) => proptest::prop_assert!((a - b).abs() < 1e-9, "{} vs {}", a, b),
                (a, b) => proptest::prop_assert!(false, "{:?} vs {:?}", a, b),
            }
        }
    }
}

#[test]
fn bright_reference_drops_the_two_brightest() {
    let r = |v: &[f64]| bright_reference(&v.iter().copied().collect());
    assert_eq!(r(&[]), None);
    assert_eq!(r(&[f64::NAN]), None);
    assert_eq!(r(&[2.0]), Some(2.0));
    assert_eq!(r(&[2.0, 5.0]), Some(5.0));
    assert_eq!(r(&[1.0, 2.0, 3.0, 100.0, 200.0]), Some(3.0));
    assert_eq!(r(&[1.0, f64::NAN, 3.0, 2.0, 9.0, 9.0]), Some(3.0));
}

proptest::proptest! {
    /// A kerb's face, met head-on, comes out of the level-ground normalisation several
    /// times brighter than the ground: one or two such returns do not move the bound.
    #[test]
    fn two_outliers_do_not_raise_the_bright_reference(
        ground in proptest::collection::vec(0.1f64..10.0, 1..14),
        k in 1usize..3,
        spike in 11.0f64..1e6,
    ) {
        let mut line: std::collections::VecDeque<f64> = ground.iter().copied().collect();
        for _ in 0..k {
            line.push_back(spike);
        }
        let max = ground.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let r = bright_reference(&line).unwrap();
        if ground.len() + k >= 3 {
            proptest::prop_assert!(r <= max, "{r} > {max}");
        }
    }
}

#[test]
fn bottom_returns_of_shallow_water_are_found_and_dry_ground_gives_none() {
    // Bottom returns of water 6 to 10 cm deep lie a few centimetres below its surface:
    // inside the below-level gate's ceiling, outside three standard deviations of a scan
    // line whose ground returns fall 5 mm from one to the next.
    let base = default_cue().with_range_noise(RangeNoise::constant(0.005));
    let (a, b) = shallow_pond_scene(base.optics());
    for (depth, in_pond) in [(0.06, true), (0.10, true), (0.10, false)] {
        let pond = move |x: f64, _y: f64| in_pond && x >= a && x <= b;
        let (_, out, shots) = run_over_pond(&base, depth, &pond, 0.005, 11);
        let apparent: Vec<f64> = shots
            .iter()
            .filter_map(|s| match s {
                Shot::Bottom { apparent, .. } => Some(-apparent.z),
                _ => None,
            })
            .collect();
        if !in_pond {
            assert!(apparent.is_empty());
            assert!(out.stats.bottom <= 2, "dry ground: {:?}", out.stats);
            continue;
        }
        // Most lie within the gate's ceiling, which alone would take them for ground.
        let shallow = apparent
            .iter()
            .filter(|&&v| v < base.config().below_gate_m)
            .count();
        assert!(
            shallow > 20 && 2 * shallow > apparent.len(),
            "{shallow} of {} bottom returns within the ceiling",
            apparent.len()
        );
        assert!(
            out.stats.bottom as usize >= apparent.len() * 8 / 10,
            "{depth} m: {} bottom returns found of {}: {:?}",
            out.stats.bottom,
            apparent.len(),
            out.stats
        );
    }
}

proptest::proptest! {
    #[test]
    fn below_gate_lies_between_the_noise_floor_and_the_ceiling(
        drops in proptest::collection::vec(0.0f64..0.5, 0..40),
        sigma_v in 0.0f64..0.05,
        ceiling in 0.01f64..0.3,
    ) {
        let mut d = VecDeque::new();
        for v in drops {
            if d.len() == GATE_WINDOW {
                d.pop_front();
            }
            d.push_back(v);
        }
        let g = below_gate(&d, sigma_v, ceiling);
        proptest::prop_assert!(g <= ceiling);
        if d.len() < GATE_MIN {
            proptest::prop_assert_eq!(g, ceiling);
        } else {
            let floor = (3.0 * std::f64::consts::SQRT_2 * sigma_v).min(ceiling);
            proptest::prop_assert!(g >= floor - 1e-12);
        }
        proptest::prop_assert!(below_gate(&d, f64::NAN, ceiling) <= ceiling);
    }
}

#[test]
fn returns_under_a_prior_water_level_are_bottom_returns_and_dry_ground_beside_it_is_not() {
    // The flat bed of clear water 5 cm deep, seen by a vertical scanner: level with the
    // ground before it, the walk takes it for ground. With the water the previous map found
    // over a stretch where the optics see 0.2 m deep, the returns there are bottom returns
    // at that level, with depth; a prior level within the line's gate of the ground says
    // nothing.
    let base = default_cue().with_range_noise(RangeNoise::constant(0.005));
    let dry = |_: f64, _: f64| false;
    let (cloud, plain, _) = run_over_pond(&base, 0.0, &dry, 0.005, 5);
    assert_eq!(plain.stats.bottom, 0, "{:?}", plain.stats);
    let b = 0.5 * base.optics().max_lookahead_for_depth(0.2).unwrap().unwrap();
    let patch = (0.5 * b / RES).ceil() as i64..(b / RES).floor() as i64;
    let in_patch = |x: f64| patch.contains(&((x / RES).floor() as i64));
    let prior_at = |z: f64, sigma: f64| {
        WaterPrior::from_levels(
            RES,
            patch
                .clone()
                .map(|x| (CellKey::new(x, 0), PriorLevel { z, sigma })),
            0.0,
        )
    };
    let cue = LidarCueModel {
        beams: BeamModel::Directions(
            (0..cloud.len())
                .map(|k| {
                    let p = cloud.point_in_map(k) - cloud.sensor_origin;
                    let u = p / p.norm();
                    [u.x as f32, u.y as f32, u.z as f32]
                })
                .collect(),
        ),
        ..base.clone()
    };
    let run = |prior: &WaterPrior| {
        cue.run(
            &cloud,
            &CueRun {
                prior: Some(prior),
                ..CueRun::new(RES, 0.0)
            },
            &mut LidarBuffers::default(),
        )
        .unwrap()
    };
    let wet = run(&prior_at(0.05, 0.005));
    let seen = (0..cloud.len())
        .filter(|&k| cloud.is_valid(k) && in_patch(cloud.point_in_map(k).x))
        .count() as u64;
    assert!(seen > 20);
    assert_eq!(wet.stats.bottom_under_prior, wet.stats.bottom);
    assert_eq!(wet.stats.bottom, seen, "{:?}", wet.stats);
    // The returns are out of the terrain. The beam's time in water reads as n times its
    // path, so the bed appears deeper than it lies (by the index at normal incidence, less
    // towards grazing): corrected, 5 cm of apparent depth is 3.8 to 5 cm of water.
    for k in 0..cloud.len() {
        let x = cloud.point_in_map(k).x;
        assert_eq!(wet.corrected.is_valid(k), cloud.is_valid(k) && !in_patch(x));
    }
    let depths: Vec<f64> = wet
        .evidence
        .into_batch()
        .iter()
        .filter_map(|(_, e)| e.depth_m())
        .collect();
    assert!(!depths.is_empty());
    assert!(
        depths.iter().all(|&d| d > 0.05 / 1.34 && d < 0.05),
        "{depths:?}"
    );
    // A level 1 cm over the ground, known exactly: within the line's gate but for the
    // noise's tail. Known to 1 cm, a level 2 cm over it is within three of its σ; known
    // exactly, it is not.
    let few = |z, sigma| run(&prior_at(z, sigma)).stats.bottom <= seen / 20;
    assert!(few(0.01, 0.0));
    assert!(few(0.02, 0.01));
    assert!(!few(0.02, 0.0));
}

/// One scan line from a sensor 2 m up towards +x, every `step_deg` from −12° to +6°,
/// against a terrain profile `ground(x)` (the first x where the beam is at or below it,
/// marched in 1 cm steps to 40 m; no hit: no return): the cloud, directions and slots.
fn profile_line(
    ground: &dyn Fn(f64) -> f64,
    step_deg: f64,
) -> (PointCloud, Vec<Option<Vector3<f64>>>, Vec<u32>) {
    let o = Point3::new(0.0, 0.0, 2.0);
    let (mut pts, mut dirs) = (Vec::new(), Vec::new());
    let n = (18.0 / step_deg).round() as usize;
    for k in 0..=n {
        let a = (-12.0 + k as f64 * step_deg).to_radians();
        let u = Vector3::new(a.cos(), 0.0, a.sin());
        let hit = (1..4000)
            .map(|i| o + u * (i as f64 * 0.01 / a.cos()))
            .find(|q| q.z <= ground(q.x));
        pts.push(hit.map_or([f32::NAN; 3], |q| [q.x as f32, q.y as f32, q.z as f32]));
        dirs.push(Some(u));
    }
    let line = (0..pts.len() as u32).collect();
    (PointCloud::unorganized(pts), dirs, line)
}

/// A return 0.7 m under the walked level (z = 0) at 15 m. Where it is the foot of a
/// depression's far bank, rising at 45° behind it, the line's higher beams pass through
/// the space above it and meet the bank farther on: ground. Where a wall 1 m high stands
/// at 15 m, the object a mirror in water at the level would show there, the beams that
/// cross above the return stop at the wall: a mirror, as when the beams cross only high.
#[test]
fn a_below_level_return_is_ground_only_where_the_line_sees_nothing_above_it() {
    let o = Point3::new(0.0, 0.0, 2.0);
    let p = Point3::new(15.0, 0.0, -0.7);
    let refuted = |(cloud, dirs, slots): (PointCloud, Vec<Option<Vector3<f64>>>, Vec<u32>)| {
        let line = ScanLine {
            cloud: &cloud,
            dirs: &dirs,
            slots: &slots,
            o,
        };
        mirror_refuted(&line, p, 0.0, 0.01, 0.3)
    };
    let bank = |x: f64| if x < 15.0 { -5.0 } else { (x - 15.7).min(0.0) };
    assert!(refuted(profile_line(&bank, 0.25)));
    let wall = |x: f64| if (15.0..15.1).contains(&x) { 1.0 } else { -5.0 };
    assert!(!refuted(profile_line(&wall, 0.25)));
    // Beams 3° apart cross the space above the return only high (about 0.8 m apart at
    // 15 m): nothing is known of the lowest 0.3 m, where a low object would stand.
    let sparse = profile_line(&bank, 3.0);
    let lowest = sparse
        .1
        .iter()
        .flatten()
        .map(|u| o.z + u.z * 15.0 / u.x)
        .filter(|&z| z > p.z + 0.1)
        .fold(f64::INFINITY, f64::min);
    assert!(lowest > p.z + 0.3, "{lowest}");
    assert!(!refuted(sparse));
}

/// The options of a scan's run in these tests: the test grid, with the surface points.
fn scan_run() -> CueRun<'static> {
    CueRun {
        surface_points: true,
        ..CueRun::new(RES, 0.0)
    }
}
