//! The online pipeline (DESIGN.md's data flow): one [`Mapper::update`] per [`Frame`].
//!
//! Each update runs these stages, timed separately in its [`FrameReport`]:
//!
//! 1. **recentre** — the rolling window follows the vehicle; cells that leave it go to the
//!    global [`TileMap`] (kept for [`Mapper::finish`]);
//! 2. **lidar** — the lidar cues ([`crate::cues::LidarCueModel`]: no-return, bottom and
//!    specular returns, reflectivity) and the ingest of the corrected scan; without lidar
//!    cues the raw scan is ingested;
//! 3. **stereo** — the stereo reflection cue ([`crate::cues::stereo_reflections`], with the
//!    mirror-image check when configured and the frame has a camera image) and the ingest of
//!    the corrected cloud; without the cue the raw cloud is ingested;
//! 4. **labels** — the colour, SWIR and MWIR images configured in `labels`, classified and
//!    projected onto the map as votes ([`crate::project::FrameLabels`]);
//! 5. **water** — the hazard map of the window, published as the new snapshot.
//!
//! With `[lidar.cue] prior_every_frames = N` the window's water bodies become, after every
//! N-th frame, the prior the lidar cue reads in the frames that follow
//! ([`crate::cues::WaterPrior`], [`Mapper::water_prior`]): the map just published,
//! or, when the mapper does not publish (an offline build), the same map built for it. An
//! offline build with a prior is therefore the online run's map, at the cost of one water
//! stage every N frames.
//!
//! The cue work is [`crate::cues::FrameCues`]'s; the mapper only decides what runs. A sensor
//! the config leaves out (`lidar`/`stereo` absent) runs no code at all, not even ingest.
//!
//! ## Snapshots
//!
//! [`Mapper::hazard_map`] returns an `Arc<HazardMap>`: an immutable map of the window as it
//! was after the last update. Taking it is a reference-count increment. The mapper never
//! changes a published map; the water stage builds a new one and swaps the pointer
//! ([`MapSnapshots`], a mutex held only for that swap or for cloning the pointer). So a
//! planner thread holding a snapshot, or calling [`MapSnapshots::latest`] from another
//! thread, reads a consistent map while the mapper fuses the next frame.
//!
//! ## Determinism
//!
//! Cell statistics and evidence are exact integers (see [`crate::grid`]), the cues are
//! independent of thread count, so the map after any sequence of frames is bit-identical
//! for any number of rayon threads. `build_log` runs this same code, so an online run and an
//! offline build of a log give the same map.
//!
//! Exports: [`Mapper`], its [`MapperConfig`] ([`LidarConfig`], [`StereoConfig`], the cue
//! names [`CUE_NAMES`]), a frame's [`FrameReport`] with its [`StageTimes`], the published
//! [`MapSnapshots`], and [`window_centre`].

use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::calib::{Calibration, CalibrationReport, Source, Sourced};
use crate::cues::{estimate_sensor_height, FrameCues, WaterPrior};
use crate::error::{Error, Result};
use crate::grid::{GridConfig, RangeNoise, RollingGrid, TileMap};
use crate::hazard::{HazardConfig, HazardMap};
use crate::sensor::Frame;

mod config;
mod report;

pub use config::{LidarConfig, MapperConfig, StereoConfig, CUE_NAMES};
pub use report::{FrameReport, StageTimes};

/// A handle on the mapper's latest published hazard map, for other threads.
#[derive(Debug, Clone)]
pub struct MapSnapshots {
    latest: Arc<Mutex<Arc<HazardMap>>>,
}

impl MapSnapshots {
    /// The latest published map (a pointer copy under a briefly held lock).
    pub fn latest(&self) -> Arc<HazardMap> {
        match self.latest.lock() {
            Ok(g) => Arc::clone(&g),
            // A panic elsewhere while the pointer was swapped cannot leave it half-written:
            // the stored Arc is still a whole map.
            Err(p) => Arc::clone(&p.into_inner()),
        }
    }

    /// Publishes `map`; returns the map it replaces.
    fn publish(&self, map: Arc<HazardMap>) -> Arc<HazardMap> {
        match self.latest.lock() {
            Ok(mut g) => std::mem::replace(&mut *g, map),
            Err(p) => std::mem::replace(&mut *p.into_inner(), map),
        }
    }
}

/// Where the online window's centre goes for a vehicle at `base_to_map`: `ahead` of the
/// window's side in front of it, along its heading projected on the ground (the vehicle
/// itself when the heading is vertical).
pub fn window_centre(grid: &GridConfig, base_to_map: &crate::geom::Pose) -> (f64, f64) {
    let c = base_to_map.translation.vector;
    let h = base_to_map.rotation * nalgebra::Vector3::x();
    let n = h.x.hypot(h.y);
    if n.is_nan() || n <= 1e-6 {
        return (c.x, c.y);
    }
    let d = grid.ahead * grid.size_cells as f64 * grid.resolution / n;
    (c.x + d * h.x, c.y + d * h.y)
}

/// Refuses a pose that is not a finite rotation and translation within the map's domain
/// ([`crate::grid::MAX_MAP_COORD_M`]), naming the frame and the values.
fn check_pose(stamp: f64, what: &str, pose: &crate::geom::Pose) -> Result<()> {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion().coords;
    let norm = q.norm();
    let bad = if !(t.iter().all(|v| v.is_finite())) {
        Some("its translation is not finite")
    } else if !(t.iter().all(|v| v.abs() <= crate::grid::MAX_MAP_COORD_M)) {
        Some("its translation is beyond the map's ±1e8 m")
    } else if !(q.iter().all(|v| v.is_finite()) && (norm - 1.0).abs() < 1e-3) {
        Some("its rotation is not a unit quaternion")
    } else {
        None
    };
    match bad {
        None => Ok(()),
        Some(why) => Err(Error::invalid(
            format!("frame at {stamp:.6} s"),
            format!(
                "{what} pose refused: {why} (translation {:?}, quaternion xyzw {:?})",
                [t.x, t.y, t.z],
                [q.x, q.y, q.z, q.w]
            ),
        )),
    }
}

/// Makes every finite point of `cloud` farther than `max` from its sensor a missing
/// return; `None` when there is none, else the gated cloud, how many and the farthest.
fn gate_range(
    cloud: &crate::geom::PointCloud,
    max: f64,
) -> Option<(crate::geom::PointCloud, u64, f64)> {
    let o = cloud.sensor_origin;
    let range = |p: &[f32; 3]| {
        let d = [p[0] as f64 - o.x, p[1] as f64 - o.y, p[2] as f64 - o.z];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    let beyond = |p: &[f32; 3]| p.iter().all(|v| v.is_finite()) && range(p) > max;
    if !cloud.xyz.iter().any(beyond) {
        return None;
    }
    let mut c = cloud.clone();
    let (mut n, mut far) = (0u64, 0.0f64);
    for p in c.xyz.iter_mut() {
        if beyond(p) {
            n += 1;
            far = far.max(range(p));
            *p = [f32::NAN; 3];
        }
    }
    Some((c, n, far))
}

/// The vehicle's and the clouds' poses are rotations within the map.
fn check_frame_poses(frame: &Frame) -> Result<()> {
    check_pose(frame.stamp, "vehicle (base_link → map)", &frame.base_to_map)?;
    for (what, c) in [("lidar", &frame.lidar), ("stereo", &frame.stereo)] {
        if let Some(c) = c {
            check_pose(frame.stamp, &format!("{what} cloud"), &c.frame_to_map)?;
        }
    }
    Ok(())
}

/// The noise a frame is fused with ([`Mapper::observe_noise`]).
#[derive(Default)]
struct FrameNoise {
    lidar: Option<RangeNoise>,
    stereo: Option<(Sourced, bool)>,
}

/// The online mapper. See the module documentation.
pub struct Mapper {
    cfg: MapperConfig,
    cues: FrameCues,
    labels: Option<crate::project::FrameLabels>,
    /// The lidar height the cue model was built for.
    lidar_height: Option<f64>,
    grid: Option<RollingGrid>,
    global: TileMap,
    snapshots: MapSnapshots,
    /// Whether `update` publishes the window's hazard map (stage 5).
    publish: bool,
    /// Buffers of the water stage, kept between frames.
    scratch: crate::hazard::WindowScratch,
    frames: u64,
    /// Whether the warning that the lidar cues cannot run on an unorganized scan was given.
    warned_unorganized: bool,
    /// The sensors' noise, measured from the frames and checked against what is stated.
    calib: Calibration,
}

impl Mapper {
    /// The frame with the points beyond each sensor's `max_range_m` made missing returns,
    /// and images whose pose is not plausible left without a pose; `None` when nothing
    /// changes. What was dropped goes into the report.
    fn gate_frame(&self, frame: &Frame, rep: &mut FrameReport) -> Option<Frame> {
        let mut out: Option<Frame> = None;
        let ranges = [
            self.cfg.lidar.as_ref().map(|l| l.max_range_m),
            self.cfg.stereo.as_ref().map(|s| s.max_range_m),
        ];
        for (k, (what, max)) in ["lidar", "stereo"].into_iter().zip(ranges).enumerate() {
            let cloud = if k == 0 { &frame.lidar } else { &frame.stereo };
            let (Some(cloud), Some(max)) = (cloud, max) else {
                continue;
            };
            if let Some((gated, n, far)) = gate_range(cloud, max) {
                rep.beyond_max_range[k] += n;
                rep.warnings.push(format!(
                    "{n} {what} points beyond {what}.max_range_m = {max} m dropped (farthest {far:.4e} m)"
                ));
                let f = out.get_or_insert_with(|| frame.clone());
                if k == 0 {
                    f.lidar = Some(gated);
                } else {
                    f.stereo = Some(gated);
                }
            }
        }
        let names = ["colour", "swir", "mwir"];
        for (k, img) in [&frame.image, &frame.swir, &frame.mwir]
            .into_iter()
            .enumerate()
        {
            let Some(pose) = img.as_ref().and_then(|i| i.frame_to_map.as_ref()) else {
                continue;
            };
            if let Err(e) = check_pose(frame.stamp, &format!("{} image", names[k]), pose) {
                rep.warnings
                    .push(format!("{e}; the image is used without a pose"));
                let f = out.get_or_insert_with(|| frame.clone());
                let slot = [&mut f.image, &mut f.swir, &mut f.mwir][k]
                    .as_mut()
                    .expect("the image is there");
                slot.frame_to_map = None;
            }
        }
        out
    }

    /// Measures the sensors' noise on `frame` (gated) until the calibration holds its
    /// values: the lidar's range noise, and the stereo cloud's c with whether it is known.
    fn observe_noise(&mut self, frame: &Frame) -> FrameNoise {
        self.calib.count_frame();
        let mut out = FrameNoise::default();
        if let (Some(l), Some(cloud)) = (&self.cfg.lidar, &frame.lidar) {
            // An unorganized scan has no scan lines to measure the noise along.
            if !(cloud.rows == 1 && cloud.cols > 1) {
                out.lidar = Some(self.calib.lidar_noise(cloud, l.noise, &l.reflectivity_cue));
            }
        }
        if let (Some(s), Some(cloud)) = (&self.cfg.stereo, &frame.stereo) {
            let camera = frame.image.as_ref().and_then(|i| i.camera.as_ref());
            let stated = s.stated(camera, cloud.cols, frame.stereo_baseline_m);
            let lidar = self.cfg.lidar.as_ref().and(frame.lidar.as_ref());
            out.stereo = Some(self.calib.stereo_noise(cloud, lidar, stated));
        }
        out
    }

    /// Measures the sensors' noise on `frame` without mapping it, as [`Mapper::update`]
    /// would: an offline build shows the log's first frames to the mapper this way until
    /// [`Mapper::calibration_settled`], so that every frame is fused with the noise held
    /// from then on, whichever piece of the log a mapper builds. On a vehicle, calling it
    /// on the first frames before mapping them does the same.
    pub fn calibrate(&mut self, frame: &Frame) -> Result<()> {
        check_frame_poses(frame)?;
        let mut rep = FrameReport::default();
        let gated = self.gate_frame(frame, &mut rep);
        self.observe_noise(gated.as_ref().unwrap_or(frame));
        Ok(())
    }

    /// Holds the calibration's values as they are ([`crate::calib::Calibration::hold`]).
    pub fn hold_calibration(&mut self) {
        self.calib.hold();
    }

    /// Whether the calibration holds its values ([`crate::calib::Calibration::is_settled`]).
    pub fn calibration_settled(&self) -> bool {
        self.calib.is_settled()
    }

    /// A mapper for `cfg` (validated). With a given lidar height the cue model is built
    /// here; with `height_m` absent, on the first scan that allows the estimate.
    pub fn new(cfg: MapperConfig) -> Result<Mapper> {
        cfg.validate()?;
        let models = match (&cfg.label_models, &cfg.labels) {
            (Some(m), _) => Some(m.clone()),
            (None, Some(l)) => Some(l.compile()?),
            (None, None) => None,
        };
        let mut fc = cfg.frame_cue_config(models.as_ref());
        let mut lidar_height = None;
        if let Some(l) = cfg.lidar.as_ref().filter(|l| l.cues) {
            if let Some(h) = l.height_m {
                fc.lidar = Some(l.cue_model(h)?);
                lidar_height = Some(h);
            }
        }
        let mut calib = Calibration::default();
        calib.set_assumed(cfg.assumed_datasheet_values());
        let global = TileMap::new(cfg.grid.resolution, cfg.grid.z_ref)?;
        let empty = Arc::new(HazardMap::new(cfg.grid.resolution, Vec::new()));
        let labels = models.map(crate::project::FrameLabels::new).transpose()?;
        Ok(Mapper {
            cfg,
            cues: FrameCues::new(fc),
            labels,
            lidar_height,
            grid: None,
            global,
            snapshots: MapSnapshots {
                latest: Arc::new(Mutex::new(empty)),
            },
            publish: true,
            scratch: Default::default(),
            frames: 0,
            warned_unorganized: false,
            calib,
        })
    }

    /// The mapper's configuration.
    pub fn config(&self) -> &MapperConfig {
        &self.cfg
    }

    /// Whether [`Mapper::update`] ends by publishing the window's hazard map (on by
    /// default: a vehicle reads it every frame). Off, the water stage is skipped and
    /// [`Mapper::hazard_map`] keeps the last map published: an offline build needs only
    /// the map of everything at the end ([`Mapper::finish_map`]), which does not depend on
    /// the snapshots, and saves the stage that costs most of a frame.
    pub fn set_publish(&mut self, on: bool) {
        self.publish = on;
    }

    /// Frames fused so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The lidar height the cue model uses, once known.
    pub fn lidar_height(&self) -> Option<f64> {
        self.lidar_height
    }

    /// Every sensor value used so far, where it came from, and what the log measured
    /// ([`crate::calib`]); it converges as frames come.
    pub fn calibration(&self) -> &CalibrationReport {
        self.calib.report()
    }

    /// The lidar cues' diagnostic interval (m of lookahead), once the cue model exists.
    pub fn diagnostic_interval(&self) -> Option<(f64, f64)> {
        self.cues.cfg.lidar.as_ref().and_then(|m| m.interval())
    }

    /// Bytes of every allocation that grows with the window's cells, by owner (from their
    /// capacities): the grid's layers and ingest accumulators, the water stage's buffers and
    /// the label stage's raster and tally. Divided by the window's cells: bytes per cell.
    pub fn window_heap_bytes(&self) -> Vec<(&'static str, usize)> {
        let (layers, ingest) = self.grid.as_ref().map_or((0, 0), |g| g.heap_bytes());
        vec![
            ("grid_layers", layers),
            ("ingest_scratch", ingest),
            ("water_scratch", self.scratch.heap_bytes()),
            ("labels", self.labels.as_ref().map_or(0, |l| l.heap_bytes())),
        ]
    }

    /// The water the lidar cue reads as a prior in the next frame ([`WaterPrior`]): `None`
    /// before the first refresh or without one ([`crate::cues::LidarCueConfig::prior_every_frames`]).
    pub fn water_prior(&self) -> Option<&WaterPrior> {
        self.cues.prior.as_ref()
    }

    /// The rolling window (after the first frame).
    pub fn grid(&self) -> Option<&RollingGrid> {
        self.grid.as_ref()
    }

    /// Fuses one frame. On error (a bad cloud in the frame) the frame's remaining stages
    /// are skipped; what was fused before the error stays.
    pub fn update(&mut self, frame: &Frame) -> Result<FrameReport> {
        let t0 = Instant::now();
        let mut rep = FrameReport {
            stamp: frame.stamp,
            ..FrameReport::default()
        };
        let mut times = StageTimes::default();

        // 0. plausibility: poses that are rotations within the map, points within range.
        check_frame_poses(frame)?;
        let gated = self.gate_frame(frame, &mut rep);
        let frame = gated.as_ref().unwrap_or(frame);
        let noise = self.observe_noise(frame);

        // 1. recentre
        let t = Instant::now();
        let (cx, cy) = window_centre(&self.cfg.grid, &frame.base_to_map);
        let grid = match self.grid.as_mut() {
            Some(g) => {
                g.recenter(cx, cy, &mut self.global)?;
                g
            }
            None => self
                .grid
                .insert(RollingGrid::new(self.cfg.grid.clone(), cx, cy)?),
        };
        times.recentre = t.elapsed().as_secs_f64();

        // 2. lidar
        let t = Instant::now();
        let mut surface = None;
        if let (Some(l), Some(cloud)) = (&self.cfg.lidar, &frame.lidar) {
            // An unorganized scan (one row of many points: a driver's flat cloud without a
            // `ring` field to organize it by) has no scan lines for the cues to walk, nor
            // for the noise to be measured along.
            let unorganized = cloud.rows == 1 && cloud.cols > 1;
            let noise = noise.lidar.unwrap_or_else(|| l.stated_noise());
            self.cues.cfg.lidar_noise = noise;
            if l.cues && self.cues.cfg.lidar.is_none() {
                if let Some(h) = estimate_sensor_height(cloud) {
                    // Centimetres: the estimate is a median of noisy returns.
                    let h = (h * 100.0).round() / 100.0;
                    if h > 0.0 {
                        self.cues.cfg.lidar = Some(l.cue_model(h)?);
                        self.lidar_height = Some(h);
                    }
                }
            }
            if let Some(m) = self.cues.cfg.lidar.as_mut() {
                m.set_range_noise(noise);
                if let Some(c) = self.calib.range_compensated() {
                    m.set_range_compensated(Some(c));
                }
            }
            if self.cues.cfg.lidar.is_some() && !unorganized {
                surface = self.cues.apply_lidar(frame, grid, &mut rep.cues)?;
            } else {
                if unorganized && l.cues && !self.warned_unorganized {
                    self.warned_unorganized = true;
                    rep.warnings.push(format!(
                        "lidar cues (no-return, bottom, specular) cannot run: the scan is \
                         unorganized ({} points in one row) and has no `ring` field to \
                         organize it into rings and azimuth columns; its points are fused \
                         without them",
                        cloud.cols
                    ));
                }
                rep.lidar_ingest = Some(grid.ingest(cloud, &noise)?);
            }
            let source = if l.height_m.is_some() {
                Source::Config
            } else {
                Source::Measured
            };
            self.calib
                .set_lidar_height(self.lidar_height.map(|value| Sourced { value, source }));
        }
        rep.lidar_height_m = self.lidar_height;
        times.lidar = t.elapsed().as_secs_f64();

        // 3. stereo: its noise measured (against this frame's lidar scan when there is
        // one), then the reflection cue, which waits while the noise is unknown.
        let t = Instant::now();
        if let (Some(s), Some(cloud), Some((c, known))) =
            (&self.cfg.stereo, &frame.stereo, noise.stereo)
        {
            let noise = s.noise_of(c.value);
            rep.stereo_noise = Some((noise, c.source));
            if let Some(c) = self.cues.cfg.stereo.as_mut() {
                c.noise = noise;
            }
            if s.reflections && known {
                // What stereo says of the surface joins what the lidar says.
                if let Some(st) = self.cues.apply_stereo(frame, grid, &mut rep.cues)? {
                    surface = Some(match surface {
                        Some(mut s) => {
                            s.stereo = st.stereo;
                            s
                        }
                        None => st,
                    });
                }
            } else {
                rep.stereo_ingest = Some(grid.ingest(cloud, &noise)?);
            }
        }
        rep.calibration = self.calib.report().clone();
        times.stereo = t.elapsed().as_secs_f64();

        // 4. labels: colour, SWIR and MWIR classification projected onto the map as votes.
        let t = Instant::now();
        if let Some(fl) = self.labels.as_mut() {
            let labels = fl.apply(frame, grid, surface.as_ref())?;
            self.global.add_false_alarms(&labels.false_alarms());
            rep.labels = Some(labels);
        }
        times.labels = t.elapsed().as_secs_f64();

        // 5. water: the window's hazard map, published.
        if self.publish {
            let t = Instant::now();
            let map = self.publish_now()?;
            rep.snapshot_cells = map.cells.len();
            rep.snapshot_water_cells = map.class_counts()[crate::hazard::Class::Water as usize];
            times.water = t.elapsed().as_secs_f64();
        }

        self.frames += 1;
        // 6. the prior of the frames that follow: the window's water bodies, every
        // `prior_every_frames` frames (the map just published, or the same map built now).
        let cue = self.cfg.lidar.as_ref().map(|l| l.cue);
        if let Some(cue) = cue.filter(|c| c.prior_every_frames > 0) {
            if self.frames % u64::from(cue.prior_every_frames) == 0 {
                let t = Instant::now();
                let map = if self.publish {
                    self.snapshots.latest()
                } else {
                    Arc::new(self.window_map()?)
                };
                self.cues.prior = Some(map.water_prior(cue.prior_reach_m));
                times.water += t.elapsed().as_secs_f64();
            }
        }
        rep.frame_index = self.frames;
        times.total = t0.elapsed().as_secs_f64();
        rep.times_s = times;
        Ok(rep)
    }

    /// Builds the window's hazard map now and publishes it (the water stage of
    /// [`Mapper::update`]): for a mapper that does not publish every frame
    /// ([`Mapper::set_publish`]) but wants a map every few frames.
    pub fn publish_now(&mut self) -> Result<Arc<HazardMap>> {
        let map = Arc::new(self.window_map()?);
        // The map this one replaces is storage for the next, once no other thread holds
        // it (a published map is never changed).
        if let Ok(old) = Arc::try_unwrap(self.snapshots.publish(map.clone())) {
            self.scratch.recycle(old);
        }
        Ok(map)
    }

    /// The hazard map of the current window, its cells in the order a tile map holds them
    /// (a snapshot lists its cells as the map of the same cells built offline does). Water
    /// bodies keep the ids of the previous snapshot's bodies they grew from.
    fn window_map(&mut self) -> Result<HazardMap> {
        let previous = self.snapshots.latest();
        let cfg = self.hazard_config();
        match &self.grid {
            Some(g) => HazardMap::from_window_after(g, &cfg, &previous.bodies, &mut self.scratch),
            None => {
                let geometry = TileMap::new(self.cfg.grid.resolution, self.cfg.grid.z_ref)?;
                HazardMap::from_cells_after(&geometry, Vec::new(), &cfg, &previous.bodies)
            }
        }
    }

    /// The hazard map of a tile map under this mapper's fusion, water and vehicle settings,
    /// the fusion measured on the tile map's own logs ([`HazardMap::from_tiles`]).
    pub fn hazard_map_of(&self, tiles: &TileMap) -> Result<HazardMap> {
        HazardMap::from_tiles(tiles, &self.cfg.hazard_config())
    }

    /// The water stage's settings: the config's ([`MapperConfig::hazard_config`]), its
    /// fusion rule measured on the frames so far ([`crate::grid::Fusion::measured`] of the
    /// colour and SWIR labels' false alarms on the dry ground the lidar sampled): what
    /// its window's maps assume.
    pub fn hazard_config(&self) -> HazardConfig {
        let alarms = self
            .labels
            .as_ref()
            .map(|l| l.false_alarms())
            .unwrap_or_default();
        self.cfg.hazard_config().measured(&alarms)
    }

    /// The hazard map of the window after the last update: an immutable snapshot, cheap to
    /// take (a pointer copy), never changed by later updates.
    pub fn hazard_map(&self) -> Arc<HazardMap> {
        self.snapshots.latest()
    }

    /// A handle another thread can read the latest snapshot through while this mapper
    /// keeps updating.
    pub fn snapshots(&self) -> MapSnapshots {
        self.snapshots.clone()
    }

    /// Hands over the cells that have left the window so far, and forgets them: the mapper
    /// only ever adds to them (a cell that comes back into the window starts empty there
    /// and is added again when it leaves), so they are final, and what a mapper holds
    /// stays bounded by the window and the area driven since the last take. The merge of
    /// every take and [`Mapper::finish`] is, byte for byte, what `finish` alone would
    /// have given: a long drive can hand its map on in pieces while the vehicle drives,
    /// and a long log be built in exact time chunks, one after another.
    pub fn take_left_tiles(&mut self) -> TileMap {
        self.global.take()
    }

    /// Everything the mapper saw: the cells that left the window and the window itself.
    pub fn finish(mut self) -> TileMap {
        if let Some(g) = self.grid.as_mut() {
            g.flush(&mut self.global);
        }
        self.global
    }

    /// [`Mapper::finish`] and the hazard map of all of it.
    pub fn finish_map(self) -> Result<(TileMap, HazardMap)> {
        let cfg = self.cfg.hazard_config();
        let tiles = self.finish();
        let map = HazardMap::from_tiles(&tiles, &cfg)?;
        Ok((tiles, map))
    }
}

#[cfg(test)]
mod tests;
