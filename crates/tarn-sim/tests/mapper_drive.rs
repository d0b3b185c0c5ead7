//! The mapper over a simulated drive: cues, threads, snapshots and offline builds agree.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use std::sync::Arc;

use tarn::calib::Source;
use tarn::grid::{RollingGrid, TileMap};
use tarn::hazard::HazardMap;
use tarn::mapper::*;
use tarn::sensor::Frame;
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_sim::sim::{simulate, Scene, SimOptions};

/// The default scene, cut down: 6 frames 2 m apart, a 256-column lidar, 160 × 120 stereo.
fn small_scene() -> Scene {
    let mut s = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../maps/default.toml"
    )))
    .unwrap();
    s.trajectory.frames = Some(6);
    s.trajectory.speed = 20.0;
    let l = s.rig.lidar.as_mut().unwrap();
    l.columns = 256;
    l.elevation_deg = [-25.0, 5.0];
    let st = s.rig.stereo.as_mut().unwrap();
    st.width = 160;
    st.height = 120;
    s.rig.swir = None;
    s.rig.mwir = None;
    s
}

struct Sim {
    _dir: tempfile::TempDir,
    log: std::path::PathBuf,
    frames: Vec<Frame>,
}

fn sim() -> &'static Sim {
    static SIM: OnceLock<Sim> = OnceLock::new();
    SIM.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        simulate(
            &small_scene(),
            dir.path(),
            SimOptions {
                noise: true,
                ..SimOptions::default()
            },
        )
        .unwrap();
        let log = dir.path().join("log.mcap");
        let frames: Vec<Frame> = FrameStream::open(&log, &LogConfig::default())
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        assert_eq!(frames.len(), 6);
        assert!(frames
            .iter()
            .all(|f| f.lidar.is_some() && f.stereo.is_some()));
        Sim {
            _dir: dir,
            log,
            frames,
        }
    })
}

fn run(cfg: &MapperConfig, frames: &[Frame]) -> (TileMap, Vec<FrameReport>) {
    let mut m = Mapper::new(cfg.clone()).unwrap();
    let reps = frames.iter().map(|f| m.update(f).unwrap()).collect();
    (m.finish(), reps)
}

#[test]
fn cues_put_water_evidence_at_the_pond() {
    let mut cfg = small_scene().rig.mapper_config();
    cfg.lidar.as_mut().unwrap().height_m = None; // estimated from the scan
    let (tiles, reps) = run(&cfg, &sim().frames);
    // The lidar is 1.8 m above base_link, which the simulator puts on the terrain.
    let h = reps[0].lidar_height_m.unwrap();
    assert!((h - 1.8).abs() < 0.1, "height {h}");
    // The lidar cue ran on every frame (diagnostic returns, specular returns off the pond).
    assert!(reps
        .iter()
        .all(|r| r.cues.lidar.is_some_and(|l| l.diag_ret > 0)));
    let hazard = tarn::hazard::HazardConfig {
        fusion: cfg.fusion,
        ..Default::default()
    };
    let map = HazardMap::from_tiles(&tiles, &hazard).unwrap();
    // Cells the evidence makes more likely water than not lie at the pond (centre (22, 6),
    // radius about 7 × 5 m).
    let wet: Vec<_> = map.cells.iter().filter(|c| c.water > 0.5).collect();
    let near = wet
        .iter()
        .filter(|c| ((c.x - 22.0) / 8.5).powi(2) + ((c.y - 6.0) / 6.5).powi(2) <= 1.0)
        .count();
    eprintln!(
        "{} cells with p > 0.5, {near} at the pond; {} called water",
        wet.len(),
        map.class_counts()[tarn::hazard::Class::Water as usize]
    );
    assert!(wet.len() > 20, "{} wet cells", wet.len());
    assert!(
        near as f64 >= 0.95 * wet.len() as f64,
        "{near} of {}",
        wet.len()
    );
}

#[test]
fn offline_build_is_the_online_map() {
    let s = sim();
    let cfg = MapperConfig::default();
    let mut m = Mapper::new(cfg.clone()).unwrap();
    // As an offline build does: the sensors' noise measured on the first frames, then held.
    for f in &s.frames {
        m.calibrate(f).unwrap();
        if m.calibration_settled() {
            break;
        }
    }
    m.hold_calibration();
    for f in &s.frames {
        m.update(f).unwrap();
    }
    let (tiles, online) = m.finish_map().unwrap();
    let out = tempfile::tempdir().unwrap();
    let r = tarn_log::build::build_log(
        &s.log,
        out.path(),
        &tarn_log::build::LogBuildConfig {
            mapper: cfg,
            ..Default::default()
        },
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(r.frames_fused, 6);
    assert_eq!(r.cells_observed, online.cells.len());
    assert_eq!(r.tiles, tiles.tile_count());
    let offline = tarn::io::read_map_ply(&out.path().join("map.ply")).unwrap();
    assert_eq!(offline.cells.len(), online.cells.len());
    for (a, b) in offline.cells.iter().zip(&online.cells) {
        assert_eq!(a.key, b.key);
        assert_eq!(a.z as f32, b.z as f32);
        assert_eq!(a.water, b.water);
        assert_eq!(a.class, b.class);
        assert_eq!(a.hazard, b.hazard);
        assert!(a.depth == b.depth || (a.depth.is_nan() && b.depth.is_nan()));
    }
    let counts = r.cue_counts;
    assert!(counts.lidar_diag_ret > 0 && counts.evidence_cells > 0);
    // Water probability, class and depth agree cell by cell: outside the water bodies a
    // cell is dry (depth 0) below one half, of unknown depth (NaN) from it up.
    for c in offline
        .cells
        .iter()
        .filter(|c| c.class != tarn::hazard::Class::Water)
    {
        assert_eq!(c.depth.is_nan(), c.water >= 0.5, "{c:?}");
        assert!(c.depth.is_nan() || c.depth == 0.0, "{c:?}");
    }
    assert_eq!(r.stage_latency_ms.len(), StageTimes::NAMES.len());
    // The offline build skips the per-frame water stage; the map above, with it on in the
    // online mapper, is the same.
    let water_ms = |r: &tarn_log::build::LogBuildReport| {
        r.stage_latency_ms
            .iter()
            .find(|l| l.stage == "water")
            .unwrap()
            .max_ms
    };
    assert!(!r.per_frame_maps);
    assert_eq!(water_ms(&r), 0.0);
    let r = tarn_log::build::build_log(
        &s.log,
        out.path(),
        &tarn_log::build::LogBuildConfig {
            mapper: MapperConfig::default(),
            build: tarn_log::build::BuildOptions {
                per_frame_maps: true,
                ..Default::default()
            },
            ..Default::default()
        },
        &mut |_, _| {},
    )
    .unwrap();
    assert!(r.per_frame_maps && water_ms(&r) > 0.0);
    assert_eq!(r.cells_observed, online.cells.len());
}

#[test]
fn without_cues_the_mapper_is_plain_ingest() {
    // The same sums as fusing every raw cloud into one grid by hand.
    let s = sim();
    let mut cfg = MapperConfig::default();
    cfg.set_cues("none").unwrap();
    let (tiles, reps) = run(&cfg, &s.frames);
    assert!(reps
        .iter()
        .all(|r| r.cues.lidar.is_none() && r.cues.stereo_runs == 0));
    let mut grid: Option<RollingGrid> = None;
    let mut global = TileMap::new(cfg.grid.resolution, cfg.grid.z_ref).unwrap();
    for (f, r) in s.frames.iter().zip(&reps) {
        let (cx, cy) = window_centre(&cfg.grid, &f.base_to_map);
        let g = match grid.as_mut() {
            Some(g) => {
                g.recenter(cx, cy, &mut global).unwrap();
                g
            }
            None => grid.insert(RollingGrid::new(cfg.grid.clone(), cx, cy).unwrap()),
        };
        // With the noise the mapper measured from the log by that frame.
        let lidar_noise = r.calibration.lidar.as_ref().unwrap().used_noise.unwrap();
        g.ingest(f.lidar.as_ref().unwrap(), &lidar_noise).unwrap();
        g.ingest(f.stereo.as_ref().unwrap(), &r.stereo_noise.unwrap().0)
            .unwrap();
    }
    grid.unwrap().flush(&mut global);
    assert!(tiles == global);
    assert!(tiles.observed().all(|(_, c)| c.ev.is_empty()));
}

#[test]
fn one_and_two_threads_give_the_same_map() {
    let frames = &sim().frames;
    let with = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| {
                let mut m = Mapper::new(MapperConfig::every_sensor()).unwrap();
                // The published hazard map of every frame, bit for bit (NaN depths too).
                let maps: Vec<String> = frames
                    .iter()
                    .map(|f| {
                        m.update(f).unwrap();
                        format!("{:?}", m.hazard_map())
                    })
                    .collect();
                (m.finish(), maps)
            })
    };
    let (a, b) = (with(1), with(2));
    assert!(a.0.observed_count() > 1000);
    assert!(a.0 == b.0);
    assert!(a.1 == b.1);
    // The maps hold water bodies, so the water stage's parallel passes were exercised.
    assert!(a.1.last().unwrap().contains("class: Water"));
}

#[test]
fn a_map_published_on_demand_is_the_map_published_every_frame() {
    let frames = &sim().frames;
    let cfg = MapperConfig::every_sensor();
    let mut every = Mapper::new(cfg.clone()).unwrap();
    let mut asked = Mapper::new(cfg).unwrap();
    asked.set_publish(false);
    for (j, f) in frames.iter().enumerate() {
        every.update(f).unwrap();
        asked.update(f).unwrap();
        if j % 2 == 1 {
            let map = asked.publish_now().unwrap();
            // What was published is what a reader gets.
            assert!(Arc::ptr_eq(&map, &asked.hazard_map()));
        }
    }
    let map = asked.publish_now().unwrap();
    let last = every.hazard_map();
    assert!(!last.cells.is_empty());
    assert_eq!(format!("{:?}", map.cells), format!("{:?}", last.cells));
    assert_eq!(map.bodies.len(), last.bodies.len());
    assert!(!last.bodies.is_empty(), "the scene's pond is a body");
}

#[test]
fn a_water_prior_is_the_same_whether_the_mapper_publishes_or_not() {
    // The prior is the window's map every few frames: the one just published, or the same
    // map built for it when the mapper does not publish (an offline build). The result is
    // the same, byte for byte.
    let frames = &sim().frames;
    for every in [1, 2] {
        let mut cfg = MapperConfig::every_sensor();
        cfg.lidar.as_mut().unwrap().cue.prior_every_frames = every;
        let mut online = Mapper::new(cfg.clone()).unwrap();
        let mut offline = Mapper::new(cfg).unwrap();
        offline.set_publish(false);
        for (k, f) in frames.iter().enumerate() {
            let a = online.update(f).unwrap();
            let b = offline.update(f).unwrap();
            let stats = |r: &FrameReport| r.cues.lidar.unwrap();
            assert_eq!(stats(&a), stats(&b));
            let prior = |m: &Mapper| m.water_prior().map(|p| p.len());
            assert_eq!(prior(&online), prior(&offline));
            // Refreshed after every `every` frames.
            assert_eq!(prior(&online).is_some(), k + 1 >= every as usize);
        }
        // The pond is a body by the end of the drive.
        assert!(online.water_prior().unwrap().len() > 1000);
        assert!(online.finish() == offline.finish());
    }
}

#[test]
fn snapshots_are_readable_while_updating() {
    let frames = &sim().frames;
    let mut m = Mapper::new(MapperConfig::default()).unwrap();
    m.update(&frames[0]).unwrap();
    let first = m.hazard_map();
    let copy = (*first).clone();
    assert!(!first.cells.is_empty());
    let handle = m.snapshots();
    let done = AtomicBool::new(false);
    let seen = std::thread::scope(|s| {
        let reader = s.spawn(|| {
            let mut seen = Vec::new();
            loop {
                let finished = done.load(Ordering::Acquire);
                let snap = handle.latest();
                // Every published map is whole: sorted-unique keys, finite positions.
                assert!(snap
                    .cells
                    .iter()
                    .all(|c| c.x.is_finite() && c.y.is_finite()));
                if seen.last() != Some(&snap.cells.len()) {
                    seen.push(snap.cells.len());
                }
                if finished {
                    return seen;
                }
                std::thread::yield_now();
            }
        });
        for f in &frames[1..] {
            m.update(f).unwrap();
        }
        done.store(true, Ordering::Release);
        reader.join().unwrap()
    });
    // The reader saw the final map; the first snapshot never changed.
    assert_eq!(*seen.last().unwrap(), m.hazard_map().cells.len());
    // (Debug text: NaN elevation_std of evidence-only cells is not == itself.)
    assert_eq!(format!("{:?}", *first), format!("{copy:?}"));
    assert!(!Arc::ptr_eq(&first, &m.hazard_map()));
}

#[test]
fn a_lidar_only_config_runs_no_stereo_code() {
    let s = sim();
    let cfg = MapperConfig {
        stereo: None,
        ..MapperConfig::default()
    };
    let (tiles, reps) = run(&cfg, &s.frames);
    for r in &reps {
        assert!(r.stereo_ingest.is_none() && r.cues.stereo_ingest.is_none());
        assert_eq!(r.cues.stereo_runs, 0);
        assert!(r.cues.lidar.is_some());
    }
    // The same map as frames that carry no stereo at all.
    let stripped: Vec<Frame> = s
        .frames
        .iter()
        .map(|f| Frame {
            stereo: None,
            image: None,
            ..f.clone()
        })
        .collect();
    let (t2, _) = run(&MapperConfig::default(), &stripped);
    assert!(tiles == t2);
    assert_eq!(cfg.cue_names(), ["lidar", "reflectivity"]);
}

/// The stereo range noise is stated by the disparity noise, the focal length and binning
/// of the log's camera and the baseline of its right CameraInfo: σ_z = z²·σ_d·k/(f·B);
/// the mapper measures it from the log and uses the measurement, within 30 % of the rig's
/// true coefficient from the first frame.
#[test]
fn stereo_noise_is_stated_by_the_camera_and_measured_from_the_log() {
    let s = sim();
    let f = &s.frames[2];
    let cam = f.image.as_ref().unwrap().camera.as_ref().unwrap();
    let cloud = f.stereo.as_ref().unwrap();
    let b = f.stereo_baseline_m.unwrap();
    let spec = small_scene().rig.stereo.unwrap();
    assert!((b - spec.baseline_m).abs() < 1e-12);
    let k = (cam.width / cloud.cols) as f64;
    assert_eq!(k, spec.bin as f64);
    let cfg = StereoConfig {
        disparity_noise_px: Some(0.4),
        ..StereoConfig::default()
    };
    let stated = cfg.stated(Some(cam), cloud.cols, Some(b));
    assert_eq!(stated.baseline_m.unwrap().source, tarn::calib::Source::Log);
    assert!((stated.per_m2().unwrap() - 0.4 * k / (cam.fx * b)).abs() < 1e-15);
    // The config's baseline serves a log without the right camera; without σ_d, a camera
    // or a baseline, nothing is stated.
    let with_b = StereoConfig {
        baseline_m: Some(b),
        ..cfg
    };
    let s2 = with_b.stated(Some(cam), cloud.cols, None);
    assert_eq!(s2.baseline_m.unwrap().source, tarn::calib::Source::Config);
    assert_eq!(s2.per_m2(), stated.per_m2());
    assert_eq!(cfg.stated(Some(cam), cloud.cols, None).per_m2(), None);
    assert_eq!(cfg.stated(None, cloud.cols, Some(b)).per_m2(), None);
    let unstated = StereoConfig::default().stated(Some(cam), cloud.cols, Some(b));
    assert_eq!(unstated.per_m2(), None);
    // This cut-down rig (160 × 120, binned) reports nothing nearer than its matcher's
    // limit lets the noise be measured: with nothing stated, the reflection cue waits and
    // says why, and the cloud is fused with the noisy-end coefficient.
    let mut m = Mapper::new(MapperConfig::default()).unwrap();
    for f in &s.frames {
        let r = m.update(f).unwrap();
        let (noise, source) = r.stereo_noise.unwrap();
        assert_eq!(source, Source::Default);
        assert_eq!(noise.per_m2, tarn::calib::NOISY_STEREO_PER_M2);
        assert_eq!(r.cues.stereo_runs, 0);
    }
    let cal = m.calibration();
    assert_eq!(cal.stereo.as_ref().unwrap().frames_waited, 6);
    assert!(
        cal.waited[0].contains("no disparity noise"),
        "{:?}",
        cal.waited
    );
    // With σ_d stated, the stated coefficient is used from the first frame.
    let mut cfg = MapperConfig::default();
    cfg.stereo.as_mut().unwrap().disparity_noise_px = Some(spec.disparity_noise_px);
    let mut m = Mapper::new(cfg).unwrap();
    let r = m.update(&s.frames[0]).unwrap();
    let (noise, source) = r.stereo_noise.unwrap();
    assert_eq!(source, Source::Config);
    let true_c = spec.disparity_noise_px * k / (cam.fx * b);
    assert!((noise.per_m2 / true_c - 1.0).abs() < 1e-9);
}

/// On the default rig's real-sized stereo pair (640 × 480, binned 2 × 2) the mapper
/// measures the noise coefficient from the log alone, within 30 % of the rig's true one
/// from the first frame, against the lidar and from the cloud's own planes.
#[test]
fn a_real_sized_stereo_pairs_noise_is_measured_from_the_first_frame() {
    let mut scene = Scene::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../maps/default.toml"
    )))
    .unwrap();
    scene.trajectory.frames = Some(2);
    scene.rig.swir = None;
    scene.rig.mwir = None;
    let spec = scene.rig.stereo.clone().unwrap();
    let dir = tempfile::tempdir().unwrap();
    simulate(&scene, dir.path(), SimOptions::default()).unwrap();
    let frames: Vec<Frame> = FrameStream::open(dir.path().join("log.mcap"), &LogConfig::default())
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    let cam = frames[0].image.as_ref().unwrap().camera.clone().unwrap();
    let k = (cam.width / frames[0].stereo.as_ref().unwrap().cols) as f64;
    let true_c = spec.disparity_noise_px * k / (cam.fx * spec.baseline_m);
    let mut m = Mapper::new(MapperConfig::default()).unwrap();
    let r = m.update(&frames[0]).unwrap();
    let (noise, source) = r.stereo_noise.unwrap();
    assert_eq!(source, Source::Measured);
    assert!(
        (noise.per_m2 / true_c - 1.0).abs() < 0.3,
        "{} for {true_c}",
        noise.per_m2
    );
    let st = r.calibration.stereo.unwrap();
    assert_eq!(st.frames_waited, 0);
    for c in [st.measured_by_lidar_per_m2, st.measured_by_planes_per_m2] {
        let c = c.expect("both methods measure");
        assert!((c / true_c - 1.0).abs() < 0.3, "{c} for {true_c}");
    }
    // The lidar's range noise too.
    let l = r.calibration.lidar.unwrap();
    let sigma = l.measured.unwrap().noise.sigma(10.0);
    let true_sigma = scene.rig.lidar.unwrap().range_noise_m;
    assert!(
        (sigma / true_sigma - 1.0).abs() < 0.3,
        "{sigma} for {true_sigma}"
    );
}

#[test]
fn snapshots_are_the_generic_maps_of_the_window() {
    // The water stage reads the window's layers directly; every frame, its snapshot is the
    // map the generic path makes of the window's cells (in tile order, with the previous
    // snapshot's bodies), bit for bit. Bodies come and go (the sim's pond).
    let same = |a: &HazardMap, b: &HazardMap| format!("{a:?}") == format!("{b:?}");
    let mut m = Mapper::new(MapperConfig::default()).unwrap();
    let cfg = m.config().hazard_config();
    let mut bodies = 0;
    let mut held: Option<(Arc<HazardMap>, HazardMap)> = None;
    for (i, f) in sim().frames.iter().enumerate() {
        let previous = m.hazard_map();
        m.update(f).unwrap();
        let g = m.grid().unwrap();
        let tiles = TileMap::for_grid(g);
        let cells = g.observed_by_tile().collect();
        let want = HazardMap::from_cells_after(&tiles, cells, &cfg, &previous.bodies).unwrap();
        let got = m.hazard_map();
        assert!(same(&got, &want), "frame {i}");
        bodies += got.bodies.len();
        // A snapshot someone holds is never reused for a later map.
        if i == 2 {
            held = Some((Arc::clone(&got), (*got).clone()));
        }
    }
    let (held, copy) = held.unwrap();
    assert!(same(&held, &copy));
    eprintln!("{bodies} bodies over the frames");
}
