//! The water cues on the real RELLIS-3D Ouster OS1-64 frame 000104 (muddy two-track with
//! shallow puddles): missing returns must give no water evidence on its dry ground (its
//! ground rings have returns), and the reflectivity cue's separation of puddle from grass
//! and mud is measured (printed with `--nocapture`).

use std::path::Path;

use tarn::cues::{
    estimate_sensor_height, normalised_reflectivity, BeamModel, CueRun, LidarBuffers,
    LidarCueConfig, LidarCueModel, ReflectivityConfig,
};
use tarn::geom::PointCloud;
use tarn::grid::{key_of, CellKey, Cue};
use tarn::optics::{Attenuation, LidarModelConfig, Sensitivity, SolidAngleForm};

const DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/rellis3d-puddle-frame/"
);
const PUDDLE: u32 = 31;
const GRASS: u32 = 3;
const MUD: u32 = 33;
const CONCRETE: u32 = 23;
const RES: f64 = 0.1;

/// Whether the RELLIS-3D frame is beside the repository; a message says so when not.
fn available() -> bool {
    let ok = Path::new(DIR).join("000104.label").exists();
    if !ok {
        eprintln!("skipped: {DIR} is absent (shared test data, kept beside the repository)");
    }
    ok
}

/// The organized scan (64 rings × 2048) with reflectivity, and its labels in the same order.
fn load() -> (PointCloud, Vec<u32>) {
    let raw = tarn::io::read_ply(Path::new(&format!("{DIR}frame000104-1581624663_170.ply")))
        .expect("RELLIS-3D PLY");
    let cloud = tarn::io::organize_column_major(&raw, 64).unwrap();
    let bytes = std::fs::read(format!("{DIR}000104.label")).unwrap();
    let flat: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) & 0xFFFF)
        .collect();
    assert_eq!(flat.len(), cloud.len());
    let (rings, cols) = (cloud.rows, cloud.cols);
    let mut labels = vec![0; flat.len()];
    for r in 0..rings {
        for c in 0..cols {
            labels[r * cols + c] = flat[c * rings + r];
        }
    }
    (cloud, labels)
}

/// The Ouster OS1-64 (865 nm), taking its datasheet range on a 10 % target (40 m) as where
/// level dry ground of albedo 0.3 stops returning, in clear water.
fn ouster(height: f64) -> LidarModelConfig {
    LidarModelConfig {
        height_m: height,
        attenuation: Attenuation::PureWater {
            wavelength_nm: 865.0,
        },
        albedo: 0.3,
        aperture_diameter_m: 0.0254,
        n_water: 1.33,
        sensitivity: Sensitivity::DryLimit(40.0),
        solid_angle: SolidAngleForm::Exact,
    }
}

/// ROC AUC: the probability that a random `pos` value is below a random `neg` value
/// (ties count one half).
fn auc_lower(pos: &[f64], neg: &[f64]) -> f64 {
    let mut all: Vec<(f64, bool)> = pos
        .iter()
        .map(|&v| (v, true))
        .chain(neg.iter().map(|&v| (v, false)))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Rank sum with average ranks for ties.
    let mut rank_sum = 0.0;
    let mut i = 0;
    while i < all.len() {
        let mut j = i;
        while j + 1 < all.len() && all[j + 1].0 == all[i].0 {
            j += 1;
        }
        let avg = (i + j) as f64 / 2.0 + 1.0;
        rank_sum += avg * all[i..=j].iter().filter(|x| x.1).count() as f64;
        i = j + 1;
    }
    let (np, nn) = (pos.len() as f64, neg.len() as f64);
    // AUC that positives rank *lower* (darker).
    1.0 - (rank_sum - np * (np + 1.0) / 2.0) / (np * nn)
}

#[test]
fn rellis_missing_returns_say_nothing_on_dry_ground_and_reflectivity_separates_puddles() {
    if !available() {
        return;
    }
    let (cloud, labels) = load();
    let h = estimate_sensor_height(&cloud).expect("a ground ring");
    eprintln!("estimated sensor height {h:.3} m");
    assert!(h > 0.5 && h < 3.0, "{h}");
    let model = LidarCueModel::new(
        ouster(h),
        BeamModel::default(),
        LidarCueConfig::default(),
        Some(ReflectivityConfig::default()),
    )
    .unwrap();
    eprintln!("diagnostic interval {:?}", model.interval());
    let run = CueRun {
        surface_points: true,
        ..CueRun::new(RES, 0.0)
    };
    let out = model
        .run(&cloud, &run, &mut LidarBuffers::default())
        .unwrap();
    eprintln!("{:?}", out.stats);

    // Cells holding returns labelled as dry ground.
    let dry: std::collections::BTreeSet<CellKey> = (0..cloud.len())
        .filter(|&i| cloud.is_valid(i) && [GRASS, MUD, CONCRETE, 1].contains(&labels[i]))
        .map(|i| {
            let p = cloud.point_in_map(i);
            key_of(RES, p.x, p.y)
        })
        .collect();
    let noret_on_dry: u32 = out
        .evidence
        .iter()
        .filter(|(k, _)| dry.contains(k))
        .map(|(_, e)| e.noret as u32)
        .sum();
    eprintln!(
        "no-return evidence: {} beams in all, {} on {} dry cells",
        out.stats.noret,
        noret_on_dry,
        dry.len()
    );
    // A missing beam among returning neighbours is a dropout; the fusion weighs it against
    // the diagnostic returns of the same cell. What counts is the fused result: dry cells
    // called water because of missing returns must stay below the 0.3 % decoy budget.
    let f = tarn::grid::Fusion::default();
    let called: usize = out
        .evidence
        .iter()
        .filter(|(k, e)| dry.contains(k) && e.noret > 0 && e.water_probability(&f) > 0.5)
        .count();
    eprintln!(
        "dry cells called water through no-return: {called} of {} ({:.4} %)",
        dry.len(),
        100.0 * called as f64 / dry.len() as f64
    );
    assert!((called as f64) < 0.003 * dry.len() as f64);
    assert!((noret_on_dry as f64) < 0.003 * out.stats.noret.max(1) as f64 * 10.0);

    // Reflectivity separation, normalised for range and incidence on level ground.
    let o = cloud.sensor_origin_in_map();
    let cfg = ReflectivityConfig::default();
    let by = |label: u32, channel: tarn::cues::Channel| -> Vec<f64> {
        let c = ReflectivityConfig { channel, ..cfg };
        (0..cloud.len())
            .filter(|&i| cloud.is_valid(i) && labels[i] == label)
            .filter_map(|i| {
                let v = cloud.point_in_map(i) - o;
                let r = v.norm();
                normalised_reflectivity(&cloud, i, -v.z / r, r, &c)
            })
            .collect()
    };
    use tarn::cues::Channel;
    for ch in [Channel::Reflectivity, Channel::Intensity] {
        let (p, g, m) = (by(PUDDLE, ch), by(GRASS, ch), by(MUD, ch));
        let med = |v: &[f64]| {
            let mut s = v.to_vec();
            s.sort_by(|a, b| a.total_cmp(b));
            s[s.len() / 2]
        };
        let (ag, am) = (auc_lower(&p, &g), auc_lower(&p, &m));
        eprintln!(
            "{ch:?}: puddle n={} median {:.1}; grass n={} median {:.1}; mud n={} median {:.1}; \
             AUC puddle darker than grass {ag:.3}, than mud {am:.3}",
            p.len(),
            med(&p),
            g.len(),
            med(&g),
            m.len(),
            med(&m),
        );
        assert!(p.len() > 500 && g.len() > 5000);
        if ch == Channel::Reflectivity {
            // Puddles read darker than grass and mud (the cue's premise on this frame).
            assert!(ag > 0.55 && am > 0.55, "AUC {ag} {am}");
        }
    }
    // For comparison: the calibrated reflectivity without the incidence normalisation.
    let raw = |label: u32| -> Vec<f64> {
        (0..cloud.len())
            .filter(|&i| cloud.is_valid(i) && labels[i] == label)
            .filter_map(|i| {
                let r = (cloud.point_in_map(i) - o).norm();
                let c = ReflectivityConfig {
                    channel: Channel::Reflectivity,
                    ..cfg
                };
                normalised_reflectivity(&cloud, i, 1.0, r, &c)
            })
            .collect()
    };
    let (p, g, m) = (raw(PUDDLE), raw(GRASS), raw(MUD));
    eprintln!(
        "reflectivity without incidence normalisation: AUC puddle darker than grass {:.3}, than mud {:.3}",
        auc_lower(&p, &g),
        auc_lower(&p, &m)
    );
    // All cues fused: dry cells called water (the decoy budget is 0.3 %).
    let called_all = out
        .evidence
        .iter()
        .filter(|(k, e)| dry.contains(k) && e.water_probability(&f) > 0.5)
        .count();
    let why = |pick: &dyn Fn(&tarn::grid::CueLogOdds) -> f64| {
        out.evidence
            .iter()
            .filter(|(k, e)| {
                dry.contains(k) && e.water_probability(&f) > 0.5 && pick(&e.cue_log_odds(&f)) > 0.0
            })
            .count()
    };
    eprintln!(
        "dry cells called water with positive evidence from: no-return {}, reflection {}, \
         bottom {}, reflectivity {}",
        why(&|c| c[Cue::NoReturn]),
        why(&|c| c[Cue::Reflection]),
        why(&|c| c[Cue::Bottom]),
        why(&|c| c[Cue::Reflectivity])
    );
    let puddle_cells: std::collections::BTreeSet<CellKey> = (0..cloud.len())
        .filter(|&i| cloud.is_valid(i) && labels[i] == PUDDLE)
        .map(|i| {
            let p = cloud.point_in_map(i);
            key_of(RES, p.x, p.y)
        })
        .collect();
    let puddle_called = out
        .evidence
        .iter()
        .filter(|(k, e)| puddle_cells.contains(k) && e.water_probability(&f) > 0.5)
        .count();
    eprintln!(
        "all cues fused: dry cells called water {called_all} of {} ({:.2} %); puddle cells \
         called water {puddle_called} of {}",
        dry.len(),
        100.0 * called_all as f64 / dry.len() as f64,
        puddle_cells.len()
    );
    // The cue's own decision at the scan's threshold.
    let thr = out.reflectivity_threshold.expect("a threshold");
    // The decoy budget: under 0.3 % of the dry cells called water by all cues fused.
    assert!((called_all as f64) < 0.003 * dry.len() as f64);

    // The same evidence through the water stage, over the scan's own terrain (the points
    // the cues left in it): what the map calls water on dry ground and on the puddles.
    let mut tiles = tarn::grid::TileMap::new(RES, 0.0).unwrap();
    for i in (0..out.corrected.len()).filter(|&i| out.corrected.is_valid(i)) {
        let p = out.corrected.point_in_map(i);
        let mut c = tarn::grid::CellStats::default();
        c.add((p.z * 1000.0).round() as i32, 65536);
        tiles.add(key_of(RES, p.x, p.y), &c);
    }
    for (&k, e) in out.evidence.iter() {
        let c = tarn::grid::CellStats {
            ev: *e,
            ..Default::default()
        };
        tiles.add(k, &c);
    }
    let map = tarn::hazard::HazardMap::from_tiles(&tiles, &tarn::hazard::HazardConfig::default())
        .unwrap();
    let water: std::collections::BTreeSet<CellKey> = map
        .cells
        .iter()
        .filter(|c| c.class == tarn::hazard::Class::Water)
        .map(|c| c.key)
        .collect();
    let map_dry = dry.iter().filter(|k| water.contains(k)).count();
    let map_puddle = puddle_cells.iter().filter(|k| water.contains(k)).count();
    eprintln!(
        "through the water stage: dry cells called water {map_dry} of {} ({:.2} %), puddle \
         cells {map_puddle} of {}, {} bodies",
        dry.len(),
        100.0 * map_dry as f64 / dry.len() as f64,
        puddle_cells.len(),
        map.bodies.len()
    );
    assert!((map_dry as f64) < 0.003 * dry.len() as f64);
    let law = out.reflectivity_law.expect("a fitted law");
    eprintln!("the scan's fitted channel law: {law:?}");
    // Residuals from the fitted law, by label; and how well they separate puddles.
    let resid = |label: u32| -> Vec<f64> {
        let refl = cloud.reflectivity.as_ref().unwrap();
        (0..cloud.len())
            .filter(|&i| cloud.is_valid(i) && labels[i] == label)
            .filter_map(|i| {
                let v = cloud.point_in_map(i) - o;
                let (r, c) = (v.norm(), -v.z / v.norm());
                let x = refl[i] as f64;
                (x > 0.0
                    && r >= cfg.min_range_m
                    && r <= cfg.max_range_m
                    && c >= cfg.min_cos_incidence)
                    .then(|| law.residual(x, r))
            })
            .collect()
    };
    let (p, g, m) = (resid(PUDDLE), resid(GRASS), resid(MUD));
    let (ag, am) = (auc_lower(&p, &g), auc_lower(&p, &m));
    eprintln!(
        "reflectivity against the scan's fitted law: AUC puddle darker than grass {ag:.3}, than mud {am:.3}"
    );
    assert!(ag > 0.55 && am > 0.55, "AUC {ag} {am}");
    let dark_of = |label: u32| {
        let v = resid(label);
        (v.iter().filter(|&&x| x < thr).count(), v.len())
    };
    let (pd, pn) = dark_of(PUDDLE);
    let (gd, gn) = dark_of(GRASS);
    let (md, mn) = dark_of(MUD);
    let (cd, cn) = dark_of(CONCRETE);
    eprintln!(
        "dark below {thr:.1} (the scan's 15 % quantile): puddle {pd}/{pn}, grass {gd}/{gn}, \
         mud {md}/{mn}, concrete {cd}/{cn}; precision among puddle+grass+mud+concrete {:.3}",
        pd as f64 / (pd + gd + md + cd) as f64
    );
    assert!(pd as f64 / pn as f64 > gd as f64 / gn as f64);
}

/// Missing returns on the real scan, by what lies there: each cell with no-return evidence
/// takes the label of the nearest return within 2 m (smooth concrete stops returning long
/// before grass does, so the cells past its last return are concrete or beyond). With the
/// scan's own dry limit along each scan line, no cell called water through missing returns
/// has concrete nearest; with the optics' interval alone (the configured sensitivity) they
/// are the concrete past where it stops returning.
#[test]
fn rellis_missing_returns_past_where_concrete_stops_returning_say_nothing() {
    if !available() {
        return;
    }
    let (cloud, labels) = load();
    let h = estimate_sensor_height(&cloud).unwrap();
    let o = cloud.sensor_origin_in_map();
    // Returns by 1 m bins, for the nearest-label search.
    type Bins = std::collections::HashMap<(i64, i64), Vec<(f64, f64, u32)>>;
    let mut bins: Bins = Default::default();
    for i in (0..cloud.len()).filter(|&i| cloud.is_valid(i)) {
        let p = cloud.point_in_map(i);
        bins.entry((p.x.floor() as i64, p.y.floor() as i64))
            .or_default()
            .push((p.x, p.y, labels[i]));
    }
    let nearest = |x: f64, y: f64| -> Option<u32> {
        let (bx, by) = (x.floor() as i64, y.floor() as i64);
        let mut best: Option<(f64, u32)> = None;
        for dx in -2..=2 {
            for dy in -2..=2 {
                for &(px, py, l) in bins.get(&(bx + dx, by + dy)).into_iter().flatten() {
                    let d = (px - x).hypot(py - y);
                    if d <= 2.0 && best.is_none_or(|b| d < b.0) {
                        best = Some((d, l));
                    }
                }
            }
        }
        best.map(|b| b.1)
    };
    let f = tarn::grid::Fusion::default();
    let mut on_concrete = Vec::new();
    for scan_dry_limit in [false, true] {
        let model = LidarCueModel::new(
            ouster(h),
            BeamModel::default(),
            LidarCueConfig {
                scan_dry_limit,
                ..LidarCueConfig::default()
            },
            None,
        )
        .unwrap();
        let run = CueRun {
            surface_points: true,
            ..CueRun::new(RES, 0.0)
        };
        let out = model
            .run(&cloud, &run, &mut LidarBuffers::default())
            .unwrap();
        let mut by_label: std::collections::BTreeMap<u32, usize> = Default::default();
        let mut lookahead = Vec::new();
        for (k, e) in out.evidence.iter() {
            if e.noret > 0 && e.water_probability(&f) > 0.5 {
                let (x, y) = ((k.x as f64 + 0.5) * RES, (k.y as f64 + 0.5) * RES);
                let l = nearest(x, y).unwrap_or(0);
                *by_label.entry(l).or_default() += 1;
                if l == CONCRETE {
                    lookahead.push((x - o.x).hypot(y - o.y));
                }
            }
        }
        lookahead.sort_by(f64::total_cmp);
        eprintln!(
            "scan dry limit {scan_dry_limit}: {} missing beams as evidence, {} past the scan's dry limit; \
             cells called water through them by nearest label {by_label:?}; on concrete at \
             {:.1}–{:.1} m",
            out.stats.noret,
            out.stats.noret_beyond_dry,
            lookahead.first().unwrap_or(&0.0),
            lookahead.last().unwrap_or(&0.0)
        );
        on_concrete.push(by_label.get(&CONCRETE).copied().unwrap_or(0));
    }
    assert!(on_concrete[0] > 0, "{on_concrete:?}");
    assert_eq!(on_concrete[1], 0, "{on_concrete:?}");
}
