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

use serde::Serialize;

use tarn::classify::{ColorLut, Label, RuleClassifier};
use tarn::cues::{
    estimate_sensor_height, mirror_check_of, mirror_gray, stereo_reflections, CueRun,
    FrameCueConfig, GrayImage, LidarBuffers, LidarCueModel, StereoCueConfig,
};
use tarn::error::{Error, Result};
use tarn::geom::PointCloud;
use tarn::grid::{GridConfig, RangeNoise, RollingGrid, TileMap};
use tarn::hazard::HazardMap;
use tarn::project::{FrameLabelConfig, FrameLabels};
use tarn::sensor::Frame;
use tarn::sensor::Pixels;
use tarn_log::build::{build_log, LogBuildConfig};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_sim::sim::synthetic_lidar_cloud;

mod cloud;
mod plain;
mod probe;
mod report;
mod sweep;
#[cfg(test)]
mod tests;

pub use cloud::cloud_build;
pub use plain::{plain_binning, PlainBins};
pub use probe::{cpu_seconds, median, minor_faults, peak_memory_bytes};
pub use sweep::{sweep, sweep_markdown, sweep_plot};

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
    let input = Input::load(opts, tmp.path())?;
    let reps = opts.reps.max(1);
    let frame = &input.frames[input.mid];
    let setup = FrameSetup::of(&input.log_cfg.mapper, frame, input.colour_labels.as_ref())?;
    let grid = window_grid(opts, &input.frames[..=input.mid], &setup)?;
    let (stages_ms, frame_stages) = time_stages(opts, &input, &setup, &grid, tmp.path(), reps)?;
    let steady = SteadyState::measure(&input)?;
    let churn = snapshot_churn(&input.log_cfg.mapper, &input.frames)?;
    let builds = Builds::time(&input, tmp.path(), reps)?;
    Ok(report(
        opts,
        &input,
        &setup,
        reps,
        (stages_ms, frame_stages),
        steady,
        churn,
        builds,
    ))
}

/// The log measured and the pipeline as the vehicle would run it on it.
struct Input {
    log: PathBuf,
    frames: Vec<Frame>,
    /// The middle frame: the one the stages of a frame are measured on.
    mid: usize,
    /// The colour camera's labels, when the log has a colour camera.
    colour_labels: Option<FrameLabelConfig>,
    log_cfg: LogBuildConfig,
}

impl Input {
    /// The given log with the default mapper config, or the scene simulated into `tmp`
    /// with its rig's config; its frames; the colour labels when its middle frame has a
    /// colour camera.
    fn load(opts: &BenchOptions, tmp: &Path) -> Result<Input> {
        // The pipeline as the vehicle would run it: the simulated rig's config, or the
        // defaults for a given log.
        let (log, mapper) = match &opts.log {
            Some(l) => (l.clone(), tarn::mapper::MapperConfig::default()),
            None => {
                let scene = tarn_sim::sim::Scene::load_with_rig(&opts.scene, opts.rig.as_deref())?;
                tarn_sim::sim::simulate(&scene, tmp, tarn_sim::sim::SimOptions::default())?;
                (tmp.join("log.mcap"), scene.rig.mapper_config())
            }
        };
        let frames = read_frames(&log)?;
        let mid = frames.len() / 2;
        let colour_labels = colour_labels_of(&frames[mid])?;
        let log_cfg = LogBuildConfig {
            mapper: tarn::mapper::MapperConfig {
                label_models: colour_labels.clone(),
                ..mapper
            },
            ..LogBuildConfig::default()
        };
        Ok(Input {
            log,
            frames,
            mid,
            colour_labels,
            log_cfg,
        })
    }
}

/// The colour camera's labels, as the main job and `tarn build --labels colour` run them
/// (the Table 1 rule through an 8-bit table), when `frame` has a colour camera.
fn colour_labels_of(frame: &Frame) -> Result<Option<FrameLabelConfig>> {
    Ok(match frame.image.as_ref() {
        Some(i) if i.camera.is_some() && matches!(i.image.pixels, Pixels::Rgb8(_)) => {
            Some(FrameLabelConfig {
                colour: Some(ColorLut::compile(&RuleClassifier::default(), 8)?),
                ..FrameLabelConfig::default()
            })
        }
        _ => None,
    })
}

/// What the mapper runs the middle frame's stages with: its cue config (the lidar's noise,
/// the stereo cue with its mirror check, the surface points the colour check reads), the
/// lidar cue model, and the stereo noise of the frame's camera and baseline.
struct FrameSetup<'f> {
    frame: &'f Frame,
    lidar: Option<&'f PointCloud>,
    stereo: Option<&'f PointCloud>,
    fc: FrameCueConfig,
    lidar_noise: RangeNoise,
    stereo_noise: RangeNoise,
    lidar_model: Option<LidarCueModel>,
    gray: Option<GrayImage>,
}

impl<'f> FrameSetup<'f> {
    fn of(
        mcfg: &tarn::mapper::MapperConfig,
        frame: &'f Frame,
        colour_labels: Option<&FrameLabelConfig>,
    ) -> Result<FrameSetup<'f>> {
        let fc = mcfg.frame_cue_config(colour_labels);
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
        Ok(FrameSetup {
            frame,
            lidar,
            stereo,
            fc,
            lidar_noise,
            stereo_noise,
            lidar_model,
            gray,
        })
    }
}

/// The grid as a mapper holds it at the middle frame: `frames` (up to and including it)
/// ingested with the frame's noise.
fn window_grid(opts: &BenchOptions, frames: &[Frame], setup: &FrameSetup) -> Result<RollingGrid> {
    let centre = setup.frame.base_to_map.translation.vector;
    let mut grid = RollingGrid::new(opts.grid.clone(), centre.x, centre.y)?;
    for f in frames {
        if let Some(c) = &f.lidar {
            grid.ingest(c, &setup.lidar_noise)?;
        }
        if let Some(c) = &f.stereo {
            grid.ingest(c, &setup.stereo_noise)?;
        }
    }
    Ok(grid)
}

/// Times the stages (see [`Stages`]): median ms per stage, and the names of the per-frame
/// ones.
fn time_stages(
    opts: &BenchOptions,
    input: &Input,
    setup: &FrameSetup,
    grid: &RollingGrid,
    tmp: &Path,
    reps: usize,
) -> Result<(BTreeMap<String, f64>, Vec<String>)> {
    let lut = ColorLut::compile(&RuleClassifier::default(), opts.lut_bits)?;
    let rgb = rgb_640x480(setup.frame);
    let mut labels = vec![Label::Other; 640 * 480];
    let mut tiles = TileMap::for_grid(grid);
    tiles.absorb_window(grid)?;
    let out_dir = tmp.join("export");
    std::fs::create_dir_all(&out_dir).map_err(|e| Error::io(&out_dir, e))?;

    let big = synthetic_lidar_cloud(opts.ingest_points, 0x9E37_79B9_7F4A_7C15);
    let mut big_grid = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
    big_grid.ingest(&big, &RangeNoise::LIDAR)?; // warm: scratch and surface

    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| Error::invalid("bench thread pool", e.to_string()))?;

    let mut st = Stages(Vec::new());
    add_frame_stages(&mut st, opts, setup, grid)?;
    if let Some(rgb) = &rgb {
        st.add("classify_640x480", true, || {
            lut.classify_into(rgb, &mut labels)
        });
    }
    add_label_and_water_stages(&mut st, input, grid)?;
    st.add("export_map (whole map)", false, || {
        let map = HazardMap::from_elevation(&tiles);
        tarn::io::write_map_files(&out_dir, &map)
    });
    let big_grid1 = big_grid.clone();
    st.add("ingest_4M_synthetic", false, || {
        big_grid.ingest(&big, &RangeNoise::LIDAR).map(|_| ())
    });
    add_one_thread_stages(&mut st, opts, setup, grid, &one, &big, big_grid1);
    st.time(reps)
}

/// Ingest and cues of the middle frame's clouds. Two closures cannot both hold the grid
/// mutably: each ingest works on its own copy.
fn add_frame_stages<'a>(
    st: &mut Stages<'a>,
    opts: &BenchOptions,
    setup: &'a FrameSetup,
    grid: &RollingGrid,
) -> Result<()> {
    let (res, z_ref) = (opts.grid.resolution, opts.grid.z_ref);
    let run = CueRun {
        surface_points: setup.fc.surface_points,
        ..CueRun::new(res, z_ref)
    };
    let (lidar_noise, stereo_noise) = (setup.lidar_noise, setup.stereo_noise);
    let (mut gl, mut gs) = (grid.clone(), grid.clone());
    if let Some(c) = setup.lidar {
        st.add("ingest_lidar", true, move || {
            gl.ingest(c, &lidar_noise).map(|_| ())
        });
    }
    if let Some(c) = setup.stereo {
        st.add("ingest_stereo", true, move || {
            gs.ingest(c, &stereo_noise).map(|_| ())
        });
    }
    if let (Some(c), Some(m)) = (setup.lidar, &setup.lidar_model) {
        let mut bufs = LidarBuffers::default();
        st.add("cue_lidar", true, move || {
            let out = m.run(c, &run, &mut bufs)?;
            bufs.recycle(out.evidence, out.corrected);
            Ok(())
        });
    }
    if let (Some(c), Some(cue)) = (setup.stereo, setup.fc.stereo) {
        let cfg = StereoCueConfig {
            noise: stereo_noise,
            ..cue
        };
        let check = mirror_check_of(setup.frame, setup.gray.as_ref());
        st.add("cue_stereo", true, move || {
            stereo_reflections(c, &run, check, &cfg).map(|_| ())
        });
    }
    Ok(())
}

/// The colour labels of the middle frame, and the water stage of the window.
fn add_label_and_water_stages<'a>(
    st: &mut Stages<'a>,
    input: &'a Input,
    grid: &RollingGrid,
) -> Result<()> {
    let frame = &input.frames[input.mid];
    if let Some(cfg) = input.colour_labels.clone() {
        // Classification, ray casting and votes of the middle frame's colour image, on a
        // copy of the grid (the votes it adds do not change the cost of the next run).
        let mut fl = FrameLabels::new(cfg)?;
        let mut gl = grid.clone();
        st.add("labels_colour", true, move || {
            fl.apply(frame, &mut gl, None).map(|_| ())
        });
    }
    // The water stage (bodies, surfaces, hazards of the window) of a mapper that has
    // fused the frames up to the middle one with the rig's cues and labels.
    let mut m = tarn::mapper::Mapper::new(input.log_cfg.mapper.clone())?;
    m.set_publish(false);
    for f in &input.frames[..=input.mid] {
        m.update(f)?;
    }
    st.add("water_window", true, move || m.publish_now().map(|_| ()));
    Ok(())
}

/// Ingest against the plain binning loop on the same points, both on one thread: the
/// measured frame's scan as it comes, and the dense synthetic batch.
fn add_one_thread_stages<'a>(
    st: &mut Stages<'a>,
    opts: &BenchOptions,
    setup: &'a FrameSetup,
    grid: &RollingGrid,
    one: &'a rayon::ThreadPool,
    big: &'a PointCloud,
    mut big_grid1: RollingGrid,
) {
    let res = opts.grid.resolution;
    let lidar_noise = setup.lidar_noise;
    if let Some(c) = setup.lidar {
        let mut g1 = grid.clone();
        st.add("ingest_lidar_1t", false, move || {
            one.install(|| g1.ingest(c, &lidar_noise).map(|_| ()))
        });
        let mut bins = PlainBins::new(grid.size(), res, grid.origin());
        st.add("plain_lidar_1t", false, move || {
            plain_binning(c, &mut bins);
            Ok(())
        });
    }
    let (big_n, big_origin) = (big_grid1.size(), big_grid1.origin());
    st.add("ingest_4M_synthetic_1t", false, move || {
        one.install(|| big_grid1.ingest(big, &RangeNoise::LIDAR).map(|_| ()))
    });
    let mut bins = PlainBins::new(big_n, res, big_origin);
    st.add("plain_4M_synthetic_1t", false, move || {
        plain_binning(big, &mut bins);
        Ok(())
    });
}

/// Page faults and per-cell memory of the steady state: a mapper as the vehicle runs it
/// (the hazard map published every frame) over the frames in memory; the faults are
/// counted over the second half.
struct SteadyState {
    faults: Option<f64>,
    window_bytes: Vec<(&'static str, usize)>,
    window_cells: usize,
}

impl SteadyState {
    fn measure(input: &Input) -> Result<SteadyState> {
        let (frames, mid) = (&input.frames, input.mid);
        let mut m = tarn::mapper::Mapper::new(input.log_cfg.mapper.clone())?;
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
        Ok(SteadyState {
            faults,
            window_bytes: m.window_heap_bytes(),
            window_cells: cells,
        })
    }
}

/// The whole log built offline (the water stage once, at the end), bare (no water cue, no
/// labels), and as the vehicle runs it (the hazard map published after every frame) for
/// the full frame's time; up to three repetitions of each.
struct Builds {
    builds: Vec<f64>,
    bare_builds: Vec<f64>,
    cores: Vec<f64>,
    duration: f64,
    /// Per stage of `Mapper::update` (and "total"), its median over the log's frames in
    /// each repetition.
    frame_parts: BTreeMap<String, Vec<f64>>,
    build_faults: Vec<f64>,
}

impl Builds {
    fn time(input: &Input, tmp: &Path, reps: usize) -> Result<Builds> {
        let (log, log_cfg) = (&input.log, &input.log_cfg);
        let mut online_cfg = log_cfg.clone();
        online_cfg.build.per_frame_maps = true;
        // The same log with no water cue and no labels: the elevation map alone, the
        // reference of the offline ratio.
        let bare_cfg = {
            let mut c = log_cfg.clone();
            c.mapper.labels = None;
            c.mapper.label_models = None;
            c.mapper.set_cues("none")?;
            c
        };
        let mut b = Builds {
            builds: Vec::new(),
            bare_builds: Vec::new(),
            cores: Vec::new(),
            duration: 0.0,
            frame_parts: BTreeMap::new(),
            build_faults: Vec::new(),
        };
        for r in 0..reps.min(3) {
            let out = tmp.join(format!("build{r}"));
            let (t0, c0) = (Instant::now(), cpu_seconds());
            let rep = build_log(log, &out, log_cfg, &mut |_, _| {})?;
            let wall = t0.elapsed().as_secs_f64();
            b.builds.push(wall);
            if let (Some(a), Some(c1)) = (c0, cpu_seconds()) {
                b.cores.push((c1 - a) / wall);
            }
            b.duration = rep.log_duration_s;
            let t0 = Instant::now();
            build_log(log, &out, &bare_cfg, &mut |_, _| {})?;
            b.bare_builds.push(t0.elapsed().as_secs_f64());
            let f0 = minor_faults();
            let rep = build_log(log, &out, &online_cfg, &mut |_, _| {})?;
            if let (Some(a), Some(f1)) = (f0, minor_faults()) {
                b.build_faults
                    .push((f1 - a) as f64 / rep.frames_fused.max(1) as f64);
            }
            for s in &rep.stage_latency_ms {
                b.frame_parts
                    .entry(s.stage.clone())
                    .or_default()
                    .push(s.median_ms);
            }
        }
        Ok(b)
    }
}

/// The report of the measurements.
#[allow(clippy::too_many_arguments)]
fn report(
    opts: &BenchOptions,
    input: &Input,
    setup: &FrameSetup,
    reps: usize,
    (stages_ms, frame_stages): (BTreeMap<String, f64>, Vec<String>),
    steady: SteadyState,
    churn: Option<(f64, f64)>,
    mut b: Builds,
) -> BenchReport {
    let (lidar, stereo) = (setup.lidar, setup.stereo);
    let (window_bytes, window_cells) = (&steady.window_bytes, steady.window_cells);
    let build_s = median(&mut b.builds);
    let bare_build_s = median(&mut b.bare_builds);
    // The full frame is what `Mapper::update` takes (median over the log's frames, then
    // over the repetitions); the stage medians above say where that time goes.
    let mut frame_stages_ms: BTreeMap<String, f64> = b
        .frame_parts
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
    BenchReport {
        input: input.log.display().to_string(),
        reps,
        threads: rayon::current_num_threads(),
        ingest_points_per_s: opts.ingest_points as f64 / (ingest_ms * 1e-3),
        ingest_points: opts.ingest_points,
        frame_ms,
        frame_ms_method: format!(
            "median Mapper::update time over the log's frames (build_log with the rig's mapper \
             config{}, the hazard map published every frame), median over repetitions",
            if input.log_cfg.mapper.label_models.is_some() {
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
        offline_x_realtime: b.duration / build_s,
        offline_build_s: build_s,
        offline_bare_build_s: bare_build_s,
        offline_over_bare: build_s / bare_build_s,
        offline_cores_busy: (!b.cores.is_empty()).then(|| median(&mut b.cores)),
        log_duration_s: b.duration,
        peak_memory_bytes: peak_memory_bytes(),
        bytes_per_cell: RollingGrid::bytes_per_cell(),
        bytes_per_cell_all: window_bytes.iter().map(|b| b.1).sum::<usize>() as f64
            / window_cells.max(1) as f64,
        bytes_per_cell_by_owner: window_bytes
            .iter()
            .map(|&(k, b)| (k.to_string(), b as f64 / window_cells.max(1) as f64))
            .collect(),
        page_faults_per_frame: steady.faults,
        page_faults_per_frame_build: (!b.build_faults.is_empty())
            .then(|| median(&mut b.build_faults)),
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
    }
}
