//! `tarn bench`: what each stage of the pipeline costs on a simulated (or given) log.
//!
//! Every stage is timed `reps` times and reported as its median: the machine is shared and
//! noisy, and a median ignores the runs a neighbour's build slowed down. The stages of one
//! frame run on a frame from the middle of the log, with a grid already holding the frames
//! before it (the steady state of a mapper). The full frame is the median
//! [`tarn::mapper::Mapper::update`] over the log (`frame_ms_method` says so), with the
//! colour camera's labels when the log has one: a full frame includes colour
//! classification and projection.
//!
//! A stage is one entry of `Stages`: adding one (water surfaces, labels) is one line.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use tarn::classify::color::RuleClassifier;
use tarn::classify::lut::ColorLut;
use tarn::classify::Label;
use tarn::cues::frame::{mirror_check_of, mirror_gray};
use tarn::cues::lidar::LidarBuffers;
use tarn::cues::{estimate_sensor_height, stereo_reflections_with, StereoCueConfig};
use tarn::error::{Error, Result};
use tarn::geom::PointCloud;
use tarn::grid::{CellKey, GridConfig, RangeNoise, RollingGrid, TileMap};
use tarn::hazard::HazardMap;
use tarn::project::{FrameLabelConfig, FrameLabels};
use tarn::sensor::Frame;
use tarn::sensor::Pixels;
use tarn_log::build::{build_log, LogBuildConfig};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_sim::sim::synthetic_lidar_cloud;

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Repetitions of every stage (medians are reported).
    pub reps: usize,
    /// A log to measure; `None` simulates `scene` into a temporary directory.
    pub log: Option<PathBuf>,
    /// The scene to simulate when no log is given.
    pub scene: PathBuf,
    /// The rig to simulate it with (`None`: the one the scene names).
    pub rig: Option<PathBuf>,
    /// Points of the synthetic lidar-like cloud that measures raw ingest throughput.
    pub ingest_points: usize,
    /// Bits per channel of the colour lookup table.
    pub lut_bits: u8,
    pub grid: GridConfig,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            reps: 7,
            log: None,
            scene: PathBuf::from(concat!(
                concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
                "/maps/default.toml"
            )),
            rig: None,
            ingest_points: 4_000_000,
            lut_bits: 6,
            grid: GridConfig::default(),
        }
    }
}

/// [`BenchReport::snapshot_cells_changed`] and `_or_beside` of a mapper publishing after
/// every one of `frames`; `None` with fewer than two published maps.
fn snapshot_churn(
    cfg: &tarn::mapper::MapperConfig,
    frames: &[Frame],
) -> Result<Option<(f64, f64)>> {
    use std::collections::{HashMap, HashSet};
    use tarn::grid::CellKey;
    let mut m = tarn::mapper::Mapper::new(cfg.clone())?;
    m.set_publish(true);
    let (mut changed, mut beside) = (Vec::new(), Vec::new());
    let mut previous: Option<std::sync::Arc<tarn::hazard::HazardMap>> = None;
    for f in frames {
        m.update(f)?;
        let map = m.hazard_map();
        if let Some(prev) = previous.filter(|_| !map.cells.is_empty()) {
            // Records compared by their bits (a NaN depth equals itself).
            let old: HashMap<CellKey, String> = prev
                .cells
                .iter()
                .map(|c| (c.key, format!("{c:?}")))
                .collect();
            let keys: HashSet<CellKey> = map.cells.iter().map(|c| c.key).collect();
            let moved: Vec<CellKey> = map
                .cells
                .iter()
                .filter(|c| old.get(&c.key) != Some(&format!("{c:?}")))
                .map(|c| c.key)
                .collect();
            let near: HashSet<CellKey> = moved
                .iter()
                .flat_map(|k| {
                    (-1..=1).flat_map(move |dy| {
                        (-1..=1).map(move |dx| CellKey::new(k.x + dx, k.y + dy))
                    })
                })
                .filter(|k| keys.contains(k))
                .collect();
            let n = map.cells.len() as f64;
            changed.push(moved.len() as f64 / n);
            beside.push(near.len() as f64 / n);
        }
        previous = Some(map);
    }
    Ok((!changed.is_empty()).then(|| (median(&mut changed), median(&mut beside))))
}

/// The result of [`run`]; `tarn bench --json` prints it.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub input: String,
    pub reps: usize,
    pub threads: usize,
    /// Raw ingest throughput on a synthetic lidar-like cloud of `ingest_points` points.
    pub ingest_points_per_s: f64,
    pub ingest_points: usize,
    /// The full frame, ms (see `frame_ms_method`).
    pub frame_ms: f64,
    pub frame_ms_method: String,
    /// The stages summed into `frame_ms`.
    pub frame_stages: Vec<String>,
    /// Where `frame_ms` goes: each stage of `Mapper::update` (recentre, lidar, stereo,
    /// labels, water), its median over the log's frames, median over the repetitions
    /// (the medians need not sum to `frame_ms`).
    pub frame_stages_ms: BTreeMap<String, f64>,
    /// Colour classification of a 640 × 480 image through the lookup table, one thread.
    pub classify_ms_640x480: f64,
    /// Log duration over the time `build::build_log` takes for the whole log (median).
    pub offline_x_realtime: f64,
    pub offline_build_s: f64,
    /// The same offline build with no water cue and no labels (`--cues none --labels
    /// none`), median seconds, and the ratio of the two (target ≤ 2).
    pub offline_bare_build_s: f64,
    pub offline_over_bare: f64,
    /// CPU seconds (user and system, every thread) over wall seconds of the offline build:
    /// the cores it kept busy (median over repetitions; `None` off unix).
    pub offline_cores_busy: Option<f64>,
    pub log_duration_s: f64,
    /// Peak resident memory of this process (VmHWM), bytes; `None` where /proc is absent.
    pub peak_memory_bytes: Option<u64>,
    /// Bytes of cell storage per cell of the rolling window (the grid's layers alone).
    pub bytes_per_cell: usize,
    /// Bytes per window cell of every allocation that grows with the window (the grid's
    /// layers and ingest accumulators, the water stage's and the label stage's buffers),
    /// counted from their capacities after the measured frames:
    /// [`tarn::mapper::Mapper::window_heap_bytes`] over the window's cells.
    pub bytes_per_cell_all: f64,
    /// The same by owner, bytes per window cell.
    pub bytes_per_cell_by_owner: BTreeMap<String, f64>,
    /// Minor page faults (getrusage `ru_minflt`) per `Mapper::update` (hazard map
    /// published), over the second half of the log's frames, held in memory, after the
    /// first half: the steady state. `None` off unix.
    pub page_faults_per_frame: Option<f64>,
    /// What an incremental water stage could skip: per published frame after the first,
    /// the share of the snapshot's cells whose record differs from the previous
    /// snapshot's (new cells included), and the share within one cell of such a cell (a
    /// record reads its 3 × 3 neighbourhood, so a stage that recomputes only what changed
    /// recomputes at least these). Medians over the log's frames.
    pub snapshot_cells_changed: Option<f64>,
    pub snapshot_cells_changed_or_beside: Option<f64>,
    /// Minor page faults per frame of the whole online build (`build_log` with the map
    /// published every frame, reading the log included), over all its frames.
    pub page_faults_per_frame_build: Option<f64>,
    /// Ingest of the measured frame's lidar scan as it comes (organized), points/s, on
    /// one thread, and the plain binning loop over the same points on one thread
    /// ([`plain_binning`]): the memory-bound reference. `ingest_vs_plain_scan` is their
    /// ratio.
    pub ingest_scan_points_per_s_1t: Option<f64>,
    pub plain_scan_points_per_s_1t: Option<f64>,
    pub ingest_vs_plain_scan: Option<f64>,
    /// The same for the dense synthetic batch of `ingest_points` points.
    pub ingest_dense_points_per_s_1t: f64,
    pub plain_dense_points_per_s_1t: f64,
    pub ingest_vs_plain_dense: f64,
    /// Shape of the measured frame's lidar scan (rows, columns).
    pub frame_lidar_shape: Option<(usize, usize)>,
    /// Median ms of every stage, per frame unless the name says otherwise.
    pub stages_ms: BTreeMap<String, f64>,
    /// Points in the measured frame's clouds.
    pub frame_lidar_points: usize,
    pub frame_stereo_points: usize,
}

/// Median of a non-empty sample (the mean of the middle two for an even count).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Peak resident set of this process (VmHWM from /proc/self/status), bytes.
pub fn peak_memory_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// CPU seconds this process has used so far, user and system, every thread (getrusage);
/// `None` off unix.
pub fn cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes one `rusage` into the zeroed struct it is given.
        unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            if libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0 {
                let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
                return Some(t(u.ru_utime) + t(u.ru_stime));
            }
        }
        None
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Minor page faults of this process so far (getrusage `ru_minflt`); `None` off unix.
pub fn minor_faults() -> Option<u64> {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes one `rusage` into the zeroed struct it is given.
        unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            if libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0 {
                return Some(u.ru_minflt as u64);
            }
        }
        None
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// A dense window of per-cell sums for [`plain_binning`].
#[derive(Debug, Clone)]
pub struct PlainBins {
    n: usize,
    origin: CellKey,
    res: f64,
    count: Vec<u32>,
    sum_z: Vec<f32>,
}

impl PlainBins {
    /// A window of `n` × `n` cells of `res` metres with lower-left key `origin`.
    pub fn new(n: usize, res: f64, origin: CellKey) -> Self {
        PlainBins {
            n,
            origin,
            res,
            count: vec![0; n * n],
            sum_z: vec![0.0; n * n],
        }
    }

    /// Points added so far.
    #[cfg(test)]
    pub fn total(&self) -> u64 {
        self.count.iter().map(|&c| c as u64).sum()
    }
}

/// The reference ingest is measured against: every point of `cloud` moved into the map
/// frame by the cloud's pose and added (a count and Σ z) to its cell of a dense window in
/// one pass; no noise model, no gate, no buckets. What is left of the cost is reading the
/// points and one random access per point: the memory-bound floor of binning. Returns the
/// points that fell in the window.
pub fn plain_binning(cloud: &PointCloud, bins: &mut PlainBins) -> usize {
    let m = cloud.frame_to_map.to_homogeneous();
    let r = |i: usize, j: usize| m[(i, j)] as f32;
    let (inv, n) = (1.0 / bins.res, bins.n as i64);
    let (ox, oy) = (bins.origin.x, bins.origin.y);
    let mut added = 0;
    for p in &cloud.xyz {
        let x = r(0, 0) * p[0] + r(0, 1) * p[1] + r(0, 2) * p[2] + m[(0, 3)] as f32;
        let y = r(1, 0) * p[0] + r(1, 1) * p[1] + r(1, 2) * p[2] + m[(1, 3)] as f32;
        let z = r(2, 0) * p[0] + r(2, 1) * p[1] + r(2, 2) * p[2] + m[(2, 3)] as f32;
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            continue;
        }
        let kx = (x as f64 * inv).floor() as i64 - ox;
        let ky = (y as f64 * inv).floor() as i64 - oy;
        if (0..n).contains(&kx) && (0..n).contains(&ky) {
            let i = (ky * n + kx) as usize;
            bins.count[i] += 1;
            bins.sum_z[i] += z;
            added += 1;
        }
    }
    added
}

/// A stage: a name, whether it is part of one frame's work, and the work.
type Stage<'a> = (&'static str, bool, Box<dyn FnMut() -> Result<()> + 'a>);

/// The stages, timed round-robin `reps` times (so a burst of load hits them alike).
struct Stages<'a>(Vec<Stage<'a>>);

impl<'a> Stages<'a> {
    fn add(&mut self, name: &'static str, per_frame: bool, f: impl FnMut() -> Result<()> + 'a) {
        self.0.push((name, per_frame, Box::new(f)));
    }

    /// Median ms per stage, and the names of the per-frame ones.
    fn time(mut self, reps: usize) -> Result<(BTreeMap<String, f64>, Vec<String>)> {
        let mut times = vec![Vec::with_capacity(reps); self.0.len()];
        for _ in 0..reps.max(1) {
            for (s, t) in self.0.iter_mut().zip(&mut times) {
                let t0 = Instant::now();
                (s.2)()?;
                t.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
        let per_frame = self
            .0
            .iter()
            .filter(|s| s.1)
            .map(|s| s.0.to_string())
            .collect();
        let medians = self
            .0
            .iter()
            .zip(&mut times)
            .map(|(s, t)| (s.0.to_string(), median(t)))
            .collect();
        Ok((medians, per_frame))
    }
}

/// An RGB buffer of 640 × 480 resampled (nearest) from a frame's camera image.
fn rgb_640x480(frame: &Frame) -> Option<Vec<u8>> {
    let img = &frame.image.as_ref()?.image;
    let Pixels::Rgb8(px) = &img.pixels else {
        return None;
    };
    let (w, h) = (640usize, 480usize);
    let mut out = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        let sy = y * img.height / h;
        for x in 0..w {
            let sx = x * img.width / w;
            out.extend_from_slice(&px[sy * img.width + sx]);
        }
    }
    Some(out)
}

/// Reads a log's frames (all of them: the simulated logs are small).
fn read_frames(log: &Path) -> Result<Vec<Frame>> {
    let mut s = FrameStream::open(log, &LogConfig::default())?;
    let mut frames = Vec::new();
    for f in s.by_ref() {
        frames.push(f?);
    }
    if frames.is_empty() {
        return Err(Error::invalid(
            format!("bench log {}", log.display()),
            "no frame could be built from it",
        ));
    }
    Ok(frames)
}

/// Measures every stage. See the module documentation.
pub fn run(opts: &BenchOptions) -> Result<BenchReport> {
    let tmp = tempfile::tempdir().map_err(|e| Error::io("temporary directory", e))?;
    // The pipeline as the vehicle would run it: the simulated rig's config, or the
    // defaults for a given log.
    let (log, mapper) = match &opts.log {
        Some(l) => (l.clone(), tarn::mapper::MapperConfig::default()),
        None => {
            let scene = tarn_sim::sim::Scene::load_with_rig(&opts.scene, opts.rig.as_deref())?;
            tarn_sim::sim::simulate(&scene, tmp.path(), tarn_sim::sim::SimOptions::default())?;
            (tmp.path().join("log.mcap"), scene.rig.mapper_config())
        }
    };
    let reps = opts.reps.max(1);
    let frames = read_frames(&log)?;
    let mid = frames.len() / 2;
    let frame = &frames[mid];
    // The colour camera's labels, as the main job and `tarn build --labels colour` run them
    // (the Table 1 rule through an 8-bit table), when the log has a colour camera.
    let colour_labels = match frame.image.as_ref() {
        Some(i) if i.camera.is_some() && matches!(i.image.pixels, Pixels::Rgb8(_)) => {
            Some(FrameLabelConfig {
                colour: Some(ColorLut::compile(&RuleClassifier::default(), 8)?),
                ..FrameLabelConfig::default()
            })
        }
        _ => None,
    };
    let log_cfg = LogBuildConfig {
        mapper: tarn::mapper::MapperConfig {
            label_models: colour_labels.clone(),
            ..mapper
        },
        ..LogBuildConfig::default()
    };

    // Each stage runs with what the mapper runs it with: its cue config (the lidar's noise,
    // the stereo cue with its mirror check, the surface points the colour check reads),
    // the lidar cue model (its buffers kept from run to run), and the stereo noise of the
    // frame's camera and baseline.
    let mcfg = &log_cfg.mapper;
    let fc = mcfg.frame_cue_config(colour_labels.as_ref());
    let lidar = frame.lidar.as_ref();
    let stereo = frame.stereo.as_ref();
    let camera = frame.image.as_ref().and_then(|i| i.camera.as_ref());
    // The noise the mapper would have measured by this frame (the frame alone).
    let mut calib = tarn::calib::Calibration::default();
    let lidar_noise = match (&mcfg.lidar, lidar) {
        (Some(l), Some(c)) => calib.lidar_noise(c, l.noise, &l.reflectivity_cue),
        _ => fc.lidar_noise,
    };
    let stereo_noise = match (&mcfg.stereo, stereo) {
        (Some(s), Some(c)) => {
            let stated = s.stated(camera, c.cols, frame.stereo_baseline_m);
            s.noise_of(calib.stereo_noise(c, lidar, stated).0.value)
        }
        _ => RangeNoise::STEREO,
    };
    let lidar_model = match (mcfg.lidar.as_ref().filter(|l| l.cues), lidar) {
        (Some(l), Some(c)) => Some(
            l.cue_model(
                l.height_m
                    .or_else(|| estimate_sensor_height(c))
                    .unwrap_or(1.8),
            )?,
        ),
        _ => None,
    };
    let gray = mirror_gray(frame, fc.stereo.is_some() && fc.mirror_check)?;
    let surface_points = fc.surface_points;

    // The grid as a mapper holds it at the middle frame.
    let res = opts.grid.resolution;
    let z_ref = opts.grid.z_ref;
    let centre = frame.base_to_map.translation.vector;
    let mut grid = RollingGrid::new(opts.grid.clone(), centre.x, centre.y)?;
    for f in &frames[..=mid] {
        if let Some(c) = &f.lidar {
            grid.ingest(c, &lidar_noise)?;
        }
        if let Some(c) = &f.stereo {
            grid.ingest(c, &stereo_noise)?;
        }
    }

    let lut = ColorLut::compile(&RuleClassifier::default(), opts.lut_bits)?;
    let rgb = rgb_640x480(frame);
    let mut labels = vec![Label::Other; 640 * 480];
    let mut tiles = TileMap::for_grid(&grid);
    tiles.absorb_window(&grid)?;
    let out_dir = tmp.path().join("export");
    std::fs::create_dir_all(&out_dir).map_err(|e| Error::io(&out_dir, e))?;

    let big = synthetic_lidar_cloud(opts.ingest_points, 0x9E37_79B9_7F4A_7C15);
    let mut big_grid = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
    big_grid.ingest(&big, &RangeNoise::LIDAR)?; // warm: scratch and surface

    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| Error::invalid("bench thread pool", e.to_string()))?;
    let (n, origin) = (grid.size(), grid.origin());
    let mut big_grid1 = big_grid.clone();
    let (big_n, big_origin) = (big_grid.size(), big_grid.origin());

    // Each stage is one line here.
    // Two closures cannot both hold the grid mutably: each ingest works on its own copy.
    let (mut gl, mut gs) = (grid.clone(), grid.clone());
    let mut st = Stages(Vec::new());
    if let Some(c) = lidar {
        st.add("ingest_lidar", true, move || {
            gl.ingest(c, &lidar_noise).map(|_| ())
        });
    }
    if let Some(c) = stereo {
        st.add("ingest_stereo", true, move || {
            gs.ingest(c, &stereo_noise).map(|_| ())
        });
    }
    if let (Some(c), Some(m)) = (lidar, &lidar_model) {
        let mut bufs = LidarBuffers::default();
        st.add("cue_lidar", true, move || {
            let out = m.run_in(c, res, z_ref, surface_points, None, &mut bufs)?;
            bufs.recycle(out.evidence, out.corrected);
            Ok(())
        });
    }
    if let (Some(c), Some(cue)) = (stereo, fc.stereo) {
        let cfg = StereoCueConfig {
            noise: stereo_noise,
            ..cue
        };
        let check = mirror_check_of(frame, gray.as_ref());
        st.add("cue_stereo", true, move || {
            stereo_reflections_with(c, res, z_ref, check, &cfg, surface_points).map(|_| ())
        });
    }
    if let Some(rgb) = &rgb {
        st.add("classify_640x480", true, || {
            lut.classify_into(rgb, &mut labels)
        });
    }
    if let Some(cfg) = colour_labels {
        // Classification, ray casting and votes of the middle frame's colour image, on a
        // copy of the grid (the votes it adds do not change the cost of the next run).
        let mut fl = FrameLabels::new(cfg)?;
        let mut gl = grid.clone();
        st.add("labels_colour", true, move || {
            fl.apply(frame, &mut gl, None).map(|_| ())
        });
    }
    {
        // The water stage (bodies, surfaces, hazards of the window) of a mapper that has
        // fused the frames up to the middle one with the rig's cues and labels.
        let mut m = tarn::mapper::Mapper::new(log_cfg.mapper.clone())?;
        m.set_publish(false);
        for f in &frames[..=mid] {
            m.update(f)?;
        }
        st.add("water_window", true, move || m.publish_now().map(|_| ()));
    }
    st.add("export_map (whole map)", false, || {
        let map = HazardMap::from_elevation(&tiles);
        tarn::io::export::write_map_files(&out_dir, &map)
    });
    st.add("ingest_4M_synthetic", false, || {
        big_grid.ingest(&big, &RangeNoise::LIDAR).map(|_| ())
    });
    // Ingest against the plain binning loop on the same points, both on one thread: the
    // measured frame's scan as it comes, and the dense synthetic batch.
    let one = &one;
    if let Some(c) = lidar {
        let mut g1 = grid.clone();
        st.add("ingest_lidar_1t", false, move || {
            one.install(|| g1.ingest(c, &lidar_noise).map(|_| ()))
        });
        let mut bins = PlainBins::new(n, res, origin);
        st.add("plain_lidar_1t", false, move || {
            plain_binning(c, &mut bins);
            Ok(())
        });
    }
    {
        let big = &big;
        st.add("ingest_4M_synthetic_1t", false, move || {
            one.install(|| big_grid1.ingest(big, &RangeNoise::LIDAR).map(|_| ()))
        });
        let mut bins = PlainBins::new(big_n, res, big_origin);
        st.add("plain_4M_synthetic_1t", false, move || {
            plain_binning(big, &mut bins);
            Ok(())
        });
    }
    let (stages_ms, frame_stages) = st.time(reps)?;

    // Page faults and per-cell memory of the steady state: a mapper as the vehicle runs it
    // (the hazard map published every frame) over the frames in memory; the faults are
    // counted over the second half.
    let (faults, window_bytes, window_cells) = {
        let mut m = tarn::mapper::Mapper::new(log_cfg.mapper.clone())?;
        for f in &frames[..=mid] {
            m.update(f)?;
        }
        let f0 = minor_faults();
        for f in &frames[mid + 1..] {
            m.update(f)?;
        }
        let f1 = minor_faults();
        let measured = frames.len() - mid - 1;
        let faults = match (f0, f1) {
            (Some(a), Some(b)) if measured > 0 => Some((b - a) as f64 / measured as f64),
            _ => None,
        };
        let cells = m.grid().map_or(0, |g| g.size() * g.size());
        (faults, m.window_heap_bytes(), cells)
    };
    let churn = snapshot_churn(&log_cfg.mapper, &frames)?;

    // The whole log, offline (the water stage once, at the end), and as the vehicle runs
    // it (the hazard map published after every frame) for the full frame's time.
    let mut online_cfg = log_cfg.clone();
    online_cfg.build.per_frame_maps = true;
    // The same log with no water cue and no labels: the elevation map alone, the reference
    // of the offline ratio.
    let bare_cfg = {
        let mut c = log_cfg.clone();
        c.mapper.labels = None;
        c.mapper.label_models = None;
        c.mapper.set_cues("none")?;
        c
    };
    let mut builds = Vec::new();
    let mut bare_builds = Vec::new();
    let mut cores = Vec::new();
    let mut duration = 0.0;
    // Per stage of `Mapper::update` (and "total"), its median over the log's frames in each
    // repetition.
    let mut frame_parts: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut build_faults = Vec::new();
    for r in 0..reps.min(3) {
        let out = tmp.path().join(format!("build{r}"));
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let rep = build_log(&log, &out, &log_cfg, &mut |_, _| {})?;
        let wall = t0.elapsed().as_secs_f64();
        builds.push(wall);
        if let (Some(a), Some(b)) = (c0, cpu_seconds()) {
            cores.push((b - a) / wall);
        }
        duration = rep.log_duration_s;
        let t0 = Instant::now();
        build_log(&log, &out, &bare_cfg, &mut |_, _| {})?;
        bare_builds.push(t0.elapsed().as_secs_f64());
        let f0 = minor_faults();
        let rep = build_log(&log, &out, &online_cfg, &mut |_, _| {})?;
        if let (Some(a), Some(b)) = (f0, minor_faults()) {
            build_faults.push((b - a) as f64 / rep.frames_fused.max(1) as f64);
        }
        for s in &rep.stage_latency_ms {
            frame_parts
                .entry(s.stage.clone())
                .or_default()
                .push(s.median_ms);
        }
    }
    let build_s = median(&mut builds);
    let bare_build_s = median(&mut bare_builds);
    // The full frame is what `Mapper::update` takes (median over the log's frames, then
    // over the repetitions); the stage medians above say where that time goes.
    let mut frame_stages_ms: BTreeMap<String, f64> = frame_parts
        .iter_mut()
        .map(|(k, v)| (k.clone(), median(v)))
        .collect();
    let frame_ms = frame_stages_ms.remove("total").unwrap_or(f64::NAN);
    let classify = stages_ms
        .get("classify_640x480")
        .copied()
        .unwrap_or(f64::NAN);
    let ingest_ms = stages_ms["ingest_4M_synthetic"];
    let scan_points = lidar.map_or(0, |c| c.len()) as f64;
    let scan_rate = |k: &str| stages_ms.get(k).map(|ms| scan_points / (ms * 1e-3));
    let dense_rate = |k: &str| opts.ingest_points as f64 / (stages_ms[k] * 1e-3);
    Ok(BenchReport {
        input: log.display().to_string(),
        reps,
        threads: rayon::current_num_threads(),
        ingest_points_per_s: opts.ingest_points as f64 / (ingest_ms * 1e-3),
        ingest_points: opts.ingest_points,
        frame_ms,
        frame_ms_method: format!(
            "median Mapper::update time over the log's frames (build_log with the rig's mapper \
             config{}, the hazard map published every frame), median over repetitions",
            if log_cfg.mapper.label_models.is_some() {
                " and colour labels"
            } else {
                ""
            }
        ),
        frame_stages,
        frame_stages_ms,
        classify_ms_640x480: classify,
        snapshot_cells_changed: churn.map(|c| c.0),
        snapshot_cells_changed_or_beside: churn.map(|c| c.1),
        offline_x_realtime: duration / build_s,
        offline_build_s: build_s,
        offline_bare_build_s: bare_build_s,
        offline_over_bare: build_s / bare_build_s,
        offline_cores_busy: (!cores.is_empty()).then(|| median(&mut cores)),
        log_duration_s: duration,
        peak_memory_bytes: peak_memory_bytes(),
        bytes_per_cell: RollingGrid::bytes_per_cell(),
        bytes_per_cell_all: window_bytes.iter().map(|b| b.1).sum::<usize>() as f64
            / window_cells.max(1) as f64,
        bytes_per_cell_by_owner: window_bytes
            .iter()
            .map(|&(k, b)| (k.to_string(), b as f64 / window_cells.max(1) as f64))
            .collect(),
        page_faults_per_frame: faults,
        page_faults_per_frame_build: (!build_faults.is_empty()).then(|| median(&mut build_faults)),
        ingest_scan_points_per_s_1t: scan_rate("ingest_lidar_1t"),
        plain_scan_points_per_s_1t: scan_rate("plain_lidar_1t"),
        ingest_vs_plain_scan: scan_rate("ingest_lidar_1t")
            .zip(scan_rate("plain_lidar_1t"))
            .map(|(a, b)| a / b),
        ingest_dense_points_per_s_1t: dense_rate("ingest_4M_synthetic_1t"),
        plain_dense_points_per_s_1t: dense_rate("plain_4M_synthetic_1t"),
        ingest_vs_plain_dense: dense_rate("ingest_4M_synthetic_1t")
            / dense_rate("plain_4M_synthetic_1t"),
        frame_lidar_shape: lidar.map(|c| (c.rows, c.cols)),
        stages_ms,
        frame_lidar_points: lidar.map_or(0, |c| c.len()),
        frame_stereo_points: stereo.map_or(0, |c| c.len()),
    })
}

impl BenchReport {
    /// A Markdown table of the stages and the headline numbers.
    pub fn markdown(&self) -> String {
        let mut s = String::from("| stage | median ms |\n| --- | ---: |\n");
        for (k, v) in &self.stages_ms {
            s.push_str(&format!("| {k} | {v:.3} |\n"));
        }
        s.push_str("\n| stage of `Mapper::update` | median ms |\n| --- | ---: |\n");
        for (k, v) in &self.frame_stages_ms {
            s.push_str(&format!("| {k} | {v:.3} |\n"));
        }
        s.push_str(&format!(
            "\nframe {:.2} ms ({}), ingest {:.1} M points/s, classify 640×480 {:.3} ms, \
             offline {:.1}× real time, peak memory {} MiB, {} bytes per cell, {} threads, {} reps\n",
            self.frame_ms,
            self.frame_ms_method,
            self.ingest_points_per_s / 1e6,
            self.classify_ms_640x480,
            self.offline_x_realtime,
            self.peak_memory_bytes.map_or("?".into(), |b| (b >> 20).to_string()),
            self.bytes_per_cell,
            self.threads,
            self.reps,
        ));
        let f = |v: Option<f64>, scale: f64, d: usize| {
            v.map_or("–".to_string(), |v| format!("{:.d$}", v / scale))
        };
        s.push_str(&format!(
            "one thread, M points/s: ingest of the frame's {} scan {} (plain binning {}, ratio {}); \
             dense batch {:.1} (plain {:.1}, ratio {:.2})\n\
             page faults per frame {} (steady state), {} (whole online build); \
             {:.1} bytes per window cell over all per-cell allocations\n\
             snapshot cells changed per frame {} %, or beside a changed one {} %\n",
            self.frame_lidar_shape
                .map_or("–".into(), |(r, c)| format!("{r}×{c}")),
            f(self.ingest_scan_points_per_s_1t, 1e6, 1),
            f(self.plain_scan_points_per_s_1t, 1e6, 1),
            f(self.ingest_vs_plain_scan, 1.0, 2),
            self.ingest_dense_points_per_s_1t / 1e6,
            self.plain_dense_points_per_s_1t / 1e6,
            self.ingest_vs_plain_dense,
            f(self.page_faults_per_frame, 1.0, 0),
            f(self.page_faults_per_frame_build, 1.0, 0),
            self.bytes_per_cell_all,
            f(self.snapshot_cells_changed, 0.01, 1),
            f(self.snapshot_cells_changed_or_beside, 0.01, 1),
        ));
        s.push_str(&self.targets_markdown());
        s
    }

    /// The ratios the speed targets are stated in, each beside its target, all from this
    /// run.
    pub fn targets_markdown(&self) -> String {
        let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
        let rows = [
            (
                "offline build / the same log with `--cues none --labels none`",
                format!(
                    "{} ({:.2} s / {:.2} s)",
                    f(Some(self.offline_over_bare), 2),
                    self.offline_build_s,
                    self.offline_bare_build_s
                ),
                "≤ 2.0",
            ),
            (
                "ingest of the frame's scan, one thread / plain binning",
                f(self.ingest_vs_plain_scan, 2),
                "≥ 0.5",
            ),
            (
                "cores kept busy by the offline build",
                format!("{} of {}", f(self.offline_cores_busy, 2), self.threads),
                "≥ 1.8 of 2",
            ),
            (
                "bytes per window cell, every per-cell allocation",
                format!("{:.0}", self.bytes_per_cell_all),
                "≤ 64",
            ),
        ];
        let mut s = String::from("\n| ratio (this run) | value | target |\n| --- | ---: | --- |\n");
        for (what, v, target) in rows {
            s.push_str(&format!("| {what} | {v} | {target} |\n"));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_samples() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }

    #[test]
    fn bench_on_the_default_scene_reports_every_required_field() {
        let opts = BenchOptions {
            reps: 1,
            ingest_points: 50_000,
            ..BenchOptions::default()
        };
        let r = run(&opts).unwrap();
        // The default scene has a colour camera: its labels are part of the full frame.
        assert!(
            r.frame_ms_method.contains("colour labels"),
            "{}",
            r.frame_ms_method
        );
        for s in [
            "ingest_lidar",
            "cue_lidar",
            "classify_640x480",
            "labels_colour",
            "water_window",
            "export_map (whole map)",
        ] {
            let v = r.stages_ms[s];
            assert!(v.is_finite() && v > 0.0, "{s}: {v}");
        }
        assert!(r.frame_stages.iter().all(|s| r.stages_ms.contains_key(s)));
        // The mapper's own stages, with the rig's cues and labels all running.
        for s in ["lidar", "stereo", "labels", "water"] {
            let v = r.frame_stages_ms[s];
            assert!(v.is_finite() && v > 0.0 && v < r.frame_ms, "{s}: {v}");
        }
        assert!(r.stages_ms["cue_stereo"] > 0.0);
        assert!(r.frame_ms.is_finite() && r.frame_ms > 0.0, "{}", r.frame_ms);
        assert!(r.ingest_points_per_s > 0.0 && r.offline_x_realtime > 0.0);
        assert!(r.offline_over_bare.is_finite() && r.offline_over_bare > 0.0);
        assert!((r.offline_over_bare - r.offline_build_s / r.offline_bare_build_s).abs() < 1e-12);
        // CPU time over wall time: some of a core at least, never more than the machine's
        // cores (and a little for the clocks' granularity).
        let cores = std::thread::available_parallelism().map_or(r.threads, |n| n.get());
        #[cfg(unix)]
        assert!(r
            .offline_cores_busy
            .is_some_and(|c| c > 0.0 && c <= cores as f64 + 0.25));
        assert!(r
            .markdown()
            .contains("cores kept busy by the offline build"));
        assert!(r.log_duration_s > 0.0);
        assert_eq!(r.bytes_per_cell, RollingGrid::bytes_per_cell());
        // Every per-cell allocation counts: at least the layers, and the owners add up.
        assert!(r.bytes_per_cell_all >= r.bytes_per_cell as f64);
        let owners: f64 = r.bytes_per_cell_by_owner.values().sum();
        assert!((owners - r.bytes_per_cell_all).abs() < 1e-6);
        assert!(r.ingest_vs_plain_scan.is_some_and(|v| v > 0.0));
        assert!(r.ingest_vs_plain_dense > 0.0);
        assert!(r.frame_lidar_shape.is_some_and(|(rows, _)| rows > 1));
        // A drive changes some of the window's records every frame, not all, and the
        // neighbours of the changed ones add to them.
        let (c, b) = (
            r.snapshot_cells_changed.unwrap(),
            r.snapshot_cells_changed_or_beside.unwrap(),
        );
        assert!(c > 0.0 && c < 1.0 && b >= c && b <= 1.0, "{c} {b}");
        #[cfg(unix)]
        assert!(r.page_faults_per_frame.is_some() && r.page_faults_per_frame_build.is_some());
        let json = serde_json::to_value(&r).unwrap();
        for k in [
            "ingest_points_per_s",
            "frame_ms",
            "frame_ms_method",
            "classify_ms_640x480",
            "offline_x_realtime",
            "offline_over_bare",
            "peak_memory_bytes",
            "bytes_per_cell",
            "stages_ms",
        ] {
            assert!(json.get(k).is_some_and(|v| !v.is_null()), "{k} missing");
        }
    }

    #[test]
    fn synthetic_cloud_builds_match_their_analytic_surface() {
        let c = synthetic_lidar_cloud(200_000, 3);
        let mut g = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
        g.ingest(&c, &RangeNoise::LIDAR).unwrap();
        // 2 cm uniform noise (σ 5.8 mm) averaged over a few points per cell, plus the
        // surface's variation across a 0.1 m cell: well under a centimetre.
        let rms = synthetic_rms(&g).unwrap();
        assert!(rms < 0.01, "{rms}");
        let b = cloud_build(100_000, 20.0).unwrap();
        assert_eq!(b.points, 100_000);
        assert!(b.cells_observed > 30_000 && b.cells_observed <= 40_401);
    }

    #[test]
    fn plain_binning_counts_the_points_in_the_window() {
        let c = PointCloud::unorganized(vec![
            [0.05, 0.05, 1.0],
            [0.06, 0.04, 3.0],
            [-0.05, 0.0, 2.0],
            [f32::NAN, 0.0, 0.0],
            [50.0, 0.0, 0.0],
        ]);
        let mut b = PlainBins::new(4, 0.1, CellKey::new(-2, -2));
        assert_eq!(plain_binning(&c, &mut b), 3);
        assert_eq!(b.total(), 3);
        // Cell (0, 0) is buffer index (0 + 2) * 4 + (0 + 2).
        assert_eq!((b.count[10], b.sum_z[10]), (2, 4.0));
        assert_eq!((b.count[9], b.sum_z[9]), (1, 2.0));
    }

    #[test]
    fn minor_faults_grow_with_fresh_pages() {
        let Some(before) = minor_faults() else { return };
        let v = vec![1u8; 64 << 20];
        assert!(v.iter().all(|&b| b == 1));
        let after = minor_faults().unwrap();
        // 64 MiB, above the allocator's largest mmap threshold: always fresh pages.
        assert!(after > before, "{before} -> {after}");
    }

    #[test]
    fn peak_memory_grows_with_a_touched_allocation() {
        let before = peak_memory_bytes().unwrap();
        let v = vec![1u8; 64 << 20];
        let after = peak_memory_bytes().unwrap();
        assert!(v.iter().all(|&b| b == 1));
        assert!(after >= before.max(64 << 20), "{before} -> {after}");
    }
}

/// One setting of one knob: what it cost and what error it gave.
#[derive(Debug, Clone, Serialize)]
pub struct SweepRow {
    pub knob: String,
    pub value: String,
    /// What was timed.
    pub timed: String,
    /// Median time, ms (`None`: not measured, see `note`).
    pub time_ms: Option<f64>,
    /// What the error is measured against.
    pub error_metric: String,
    pub error: Option<f64>,
    pub note: String,
}

fn row(
    knob: &str,
    value: impl ToString,
    timed: &str,
    time_ms: Option<f64>,
    metric: &str,
    error: Option<f64>,
) -> SweepRow {
    SweepRow {
        knob: knob.into(),
        value: value.to_string(),
        timed: timed.into(),
        time_ms,
        error_metric: metric.into(),
        error,
        note: String::new(),
    }
}

/// Median wall time (ms) of `reps` runs of `f`, and its last result.
fn timed<T>(reps: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut t = Vec::new();
    let mut last = None;
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        last = Some(f()?);
        t.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok((median(&mut t), last.expect("reps >= 1")))
}

/// The analytic surface of [`synthetic_lidar_cloud`] (map frame).
fn synthetic_surface(x: f64, y: f64) -> f64 {
    let r = x.hypot(y);
    0.05 * (r * 0.3).sin() - 1.8
}

/// RMS (m) of the grid's cell elevations against [`synthetic_surface`] at the cell centres,
/// over the observed cells 3–18 m out (inside the synthetic scan's ring).
fn synthetic_rms(g: &RollingGrid) -> Option<f64> {
    let (o, n) = (g.origin(), g.size() as i64);
    let (mut s2, mut cnt) = (0.0, 0usize);
    for ky in o.y..o.y + n {
        for kx in o.x..o.x + n {
            let k = tarn::grid::CellKey::new(kx, ky);
            let (cx, cy) = g.centre_of(k);
            let r = cx.hypot(cy);
            if !(3.0..=18.0).contains(&r) {
                continue;
            }
            if let Some(m) = g.cell(k).and_then(|c| c.mean_mm()) {
                let z = g.config().z_ref + m * 1e-3;
                s2 += (z - synthetic_surface(cx, cy)).powi(2);
                cnt += 1;
            }
        }
    }
    (cnt > 0).then(|| (s2 / cnt as f64).sqrt())
}

/// Sweeps the knobs that trade speed for error (see README "Speed against error").
pub fn sweep(opts: &BenchOptions) -> Result<Vec<SweepRow>> {
    let reps = opts.reps.max(1);
    let mut rows = Vec::new();
    let tmp = tempfile::tempdir().map_err(|e| Error::io("temporary directory", e))?;

    // Grid resolution on the simulated scene, scored by `tarn eval` against its truth.
    let sim_dir = tmp.path().join("sim");
    let scene = tarn_sim::sim::Scene::load_with_rig(&opts.scene, opts.rig.as_deref())?;
    tarn_sim::sim::simulate(&scene, &sim_dir, tarn_sim::sim::SimOptions::default())?;
    let log = sim_dir.join("log.mcap");
    for res in [0.05, 0.1, 0.2, 0.4] {
        let out = tmp.path().join(format!("res{res}"));
        let mut mapper = scene.rig.mapper_config();
        mapper.grid = GridConfig {
            resolution: res,
            size_cells: ((40.0 / res).round() as usize).max(2),
            ..opts.grid.clone()
        };
        let cfg = LogBuildConfig {
            mapper,
            ..LogBuildConfig::default()
        };
        let (ms, _) = timed(reps.min(3), || build_log(&log, &out, &cfg, &mut |_, _| {}))?;
        let e = tarn_sim::eval::evaluate_dirs(&out, &sim_dir)?;
        rows.push(row(
            "grid resolution (m)",
            res,
            "build_log, whole default scene",
            Some(ms),
            "terrain RMS vs simulator truth (m)",
            e.all.terrain_rms_m,
        ));
    }

    // Point subsampling on a synthetic lidar-like cloud against its analytic surface.
    let cloud = synthetic_lidar_cloud(opts.ingest_points, 7);
    for keep_every in [1usize, 2, 4, 8, 16] {
        let sub = PointCloud::unorganized(cloud.xyz.iter().step_by(keep_every).copied().collect());
        let mut g = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
        let (ms, _) = timed(reps, || {
            g = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
            g.ingest(&sub, &RangeNoise::LIDAR)
        })?;
        rows.push(row(
            "point subsampling (keep 1 in k)",
            keep_every,
            &format!("ingest of {} points into a fresh grid", sub.len()),
            Some(ms),
            "cell RMS vs analytic surface, 3–18 m (m)",
            synthetic_rms(&g),
        ));
    }

    // Lookup-table size against the exact Table-1 rule it tabulates.
    let rule = RuleClassifier::default();
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let rgb: Vec<u8> = (0..640 * 480 * 3)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 56) as u8
        })
        .collect();
    let exact: Vec<Label> = rgb
        .chunks_exact(3)
        .map(|p| rule.classify_pixel([p[0], p[1], p[2]]))
        .collect();
    let mut out = vec![Label::Other; 640 * 480];
    for bits in 3u8..=8 {
        let lut = ColorLut::compile(&rule, bits)?;
        let (ms, _) = timed(reps, || lut.classify_into(&rgb, &mut out))?;
        let wrong = out.iter().zip(&exact).filter(|(a, b)| a != b).count();
        rows.push(row(
            "lookup-table bits per channel",
            bits,
            "classify 640×480 uniform-random RGB, one thread",
            Some(ms),
            "pixels labelled unlike the exact rule (fraction)",
            Some(wrong as f64 / exact.len() as f64),
        ));
    }

    // Label projection: every `stride`-th pixel in x and y is classified and placed on the
    // map (the rest fill the quads between agreeing samples), and with `wide_rows` every row
    // whose ground footprint is wider than a cell too. Colour labels by the Table 1 rule on
    // the default scene with the main job's 80 m window; the error is the water the map
    // misses.
    let mut label_runs = Vec::new();
    for (stride, wide_rows) in [
        (1usize, false),
        (2, false),
        (4, false),
        (8, false),
        (2, true),
    ] {
        let out = tmp.path().join(format!("stride{stride}-{wide_rows}"));
        let mut mapper = scene.rig.mapper_config();
        mapper.grid.size_cells = 800;
        mapper.label_models = Some(tarn::project::FrameLabelConfig {
            colour: Some(ColorLut::compile(&RuleClassifier::default(), 8)?),
            ray_stride: stride,
            wide_rows,
            ..tarn::project::FrameLabelConfig::default()
        });
        let cfg = LogBuildConfig {
            mapper,
            ..LogBuildConfig::default()
        };
        let (_, rep) = timed(1, || build_log(&log, &out, &cfg, &mut |_, _| {}))?;
        let e = tarn_sim::eval::evaluate_dirs(&out, &sim_dir)?;
        let labels_ms = rep
            .stage_latency_ms
            .iter()
            .find(|l| l.stage == "labels")
            .map(|l| l.median_ms);
        label_runs.push((
            stride,
            wide_rows,
            labels_ms,
            e.all.water_recall.map(|r| 1.0 - r),
        ));
    }
    let label_row = |knob: &str, value: String, &(_, _, ms, missed): &(usize, bool, _, _)| {
        row(
            knob,
            value,
            "labels stage per frame (median), default scene",
            ms,
            "water cells missed (1 − recall, all ranges)",
            missed,
        )
    };
    for r in label_runs.iter().filter(|r| !r.1) {
        rows.push(label_row(
            "label ray-cast stride (pixels)",
            r.0.to_string(),
            r,
        ));
    }
    for r in label_runs.iter().filter(|r| r.0 == 2) {
        let value = if r.1 { "all" } else { "every 2nd" };
        rows.push(label_row(
            "label rows wider than a cell (stride 2)",
            value.into(),
            r,
        ));
    }

    // Water surface interpolation on the stream scene (a surface that is not level): the
    // same fused tile map, its water bodies given a level plane or the constrained Delaunay
    // surface with barycentric interpolation; error against the true water surface.
    let stream = tarn_sim::sim::Scene::load(&opts.scene.with_file_name("stream_slope.toml"))?;
    let stream_dir = tmp.path().join("stream");
    tarn_sim::sim::simulate(&stream, &stream_dir, tarn_sim::sim::SimOptions::default())?;
    let mut mapper = tarn::mapper::Mapper::new(stream.rig.mapper_config())?;
    for f in FrameStream::open(stream_dir.join("log.mcap"), &LogConfig::default())? {
        mapper.update(&f?)?;
    }
    let tiles = mapper.finish();
    // The Delaunay surface (barycentric) with its vertices as measured ("raw") and at the
    // median of their 1.5 m of shore (the default).
    let default_radius = tarn::water::WaterConfig::default().vertex_median_radius_m;
    for (i, (name, level_residual_m, vertex_median_radius_m)) in [
        ("level plane", 1e9, default_radius),
        ("Delaunay, raw", 0.0, 0.0),
        ("Delaunay, medians", 0.0, default_radius),
    ]
    .into_iter()
    .enumerate()
    {
        let mut hc = stream.rig.mapper_config().hazard_config();
        hc.water.level_residual_m = level_residual_m;
        hc.water.vertex_median_radius_m = vertex_median_radius_m;
        let (ms, map) = timed(reps, || HazardMap::from_tiles(&tiles, &hc))?;
        let out = tmp.path().join(format!("surface-{i}"));
        tarn::io::export::write_map_files(&out, &map)?;
        let e = tarn_sim::eval::evaluate_dirs(&out, &stream_dir)?;
        rows.push(row(
            "water surface interpolation",
            name,
            "water bodies and hazards of the stream scene's map",
            Some(ms),
            "water surface RMS vs simulator truth (m)",
            e.all.surface_rms_m,
        ));
    }
    let mut r = row(
        "water surface interpolation",
        "natural neighbour",
        "–",
        None,
        "–",
        None,
    );
    r.note = "not offered: spade interpolates natural neighbours only on unconstrained \
              triangulations, and the shore constraints are kept"
        .into();
    rows.push(r);
    let mut r = row("mixture components", "–", "–", None, "–", None);
    r.note =
        "measured on the real RELLIS-3D frame: cargo run --release --example rellis_eval".into();
    rows.push(r);
    Ok(rows)
}

/// The sweep as a Markdown table.
pub fn sweep_markdown(rows: &[SweepRow]) -> String {
    let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
    let mut s = String::from(
        "| knob | value | time (ms) | timed | error | error metric |\n| --- | ---: | ---: | --- | ---: | --- |\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            r.knob,
            r.value,
            f(r.time_ms, 3),
            if r.note.is_empty() { &r.timed } else { &r.note },
            f(r.error, 5),
            r.error_metric
        ));
    }
    s
}

/// Error against time, one panel per measured knob (log-scaled time).
pub fn sweep_plot(rows: &[SweepRow], path: &Path) -> Result<()> {
    use plotters::prelude::*;
    static FONT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let font_ok = *FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if !font_ok {
        return Err(Error::invalid(
            "sweep plot",
            "the embedded DejaVu Sans font did not load",
        ));
    }
    let knobs: Vec<&str> = {
        let mut k: Vec<&str> = rows
            .iter()
            .filter(|r| r.time_ms.is_some() && r.error.is_some())
            .map(|r| r.knob.as_str())
            .collect();
        k.dedup();
        k
    };
    let err = |e: Box<dyn std::error::Error>| Error::invalid("sweep plot", e.to_string());
    // Three significant digits, no trailing zeros.
    let short = |v: f64| {
        let d = (2 - v.abs().max(1e-9).log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.d$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    // Room for each knob's caption.
    let (w, h) = (320 * knobs.len().max(1) as u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(Box::new(e)))?;
        let panels = root.split_evenly((1, knobs.len().max(1)));
        for (knob, area) in knobs.iter().zip(panels.iter()) {
            let pts: Vec<(f64, f64, String)> = rows
                .iter()
                .filter(|r| r.knob == *knob)
                .filter_map(|r| Some((r.time_ms?, r.error?, r.value.clone())))
                .collect();
            let (t0, t1) = pts
                .iter()
                .fold((f64::INFINITY, 0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let e1 = pts.iter().fold(0f64, |a, p| a.max(p.1));
            let metric = rows
                .iter()
                .find(|r| r.knob == *knob)
                .map(|r| r.error_metric.clone());
            let mut chart = ChartBuilder::on(area)
                .caption(*knob, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d((t0 * 0.7..t1 * 2.5).log_scale(), 0.0..e1 * 1.15 + 1e-9)
                .map_err(|e| err(Box::new(e)))?;
            // A few labels on the log axis (its default key points crowd a decade with
            // labels that overlap); each point says its own time.
            chart
                .configure_mesh()
                .x_labels(6)
                .x_label_formatter(&|v| short(*v))
                .x_desc("time (ms, log)")
                .y_desc(metric.unwrap_or_default())
                .label_style(("sans-serif", 12))
                .draw()
                .map_err(|e| err(Box::new(e)))?;
            chart
                .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), &BLUE))
                .map_err(|e| err(Box::new(e)))?;
            chart
                .draw_series(pts.iter().map(|p| {
                    EmptyElement::at((p.0, p.1))
                        + Circle::new((0, 0), 4, BLUE.filled())
                        + Text::new(
                            format!("{} ({} ms)", p.2, short(p.0)),
                            (6, -14),
                            ("sans-serif", 13),
                        )
                }))
                .map_err(|e| err(Box::new(e)))?;
        }
        root.present().map_err(|e| err(Box::new(e)))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| Error::invalid("sweep plot", "buffer size"))?;
    img.save(path)
        .map_err(|e| Error::invalid(format!("sweep plot {}", path.display()), e.to_string()))
}

/// What building a large synthetic cloud into a map cost.
#[derive(Debug, Clone, Serialize)]
pub struct CloudBenchRow {
    pub points: usize,
    pub side_m: f64,
    /// Making the cloud in memory (stands in for reading a file).
    pub generate_s: f64,
    pub build_s: f64,
    pub points_per_s: f64,
    pub blocks: usize,
    pub cells_observed: usize,
}

/// Builds an `n`-point synthetic cloud over a `side_m` square (gentle analytic relief) with
/// `build::build_cloud`.
pub fn cloud_build(n: usize, side_m: f64) -> Result<CloudBenchRow> {
    let t0 = Instant::now();
    let pts: Vec<[f32; 3]> = (0..n)
        .into_par_iter()
        .map(|i| {
            // A low-discrepancy (R2) sequence: spread evenly, reproducible, no RNG state.
            let a = (i as f64 * 0.754_877_666_246_692_7).fract();
            let b = (i as f64 * 0.569_840_290_998_053_3).fract();
            let (x, y) = ((a - 0.5) * side_m, (b - 0.5) * side_m);
            [
                x as f32,
                y as f32,
                (0.3 * (0.2 * x).sin() * (0.15 * y).cos()) as f32,
            ]
        })
        .collect();
    let cloud = PointCloud::unorganized(pts);
    let generate_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let b = tarn_log::build::build_cloud(
        &cloud,
        &tarn_log::build::BuildConfig::default(),
        &mut |_, _| {},
    )?;
    let build_s = t1.elapsed().as_secs_f64();
    Ok(CloudBenchRow {
        points: n,
        side_m,
        generate_s,
        build_s,
        points_per_s: n as f64 / build_s,
        blocks: b.blocks,
        cells_observed: b.tiles.observed_count(),
    })
}
