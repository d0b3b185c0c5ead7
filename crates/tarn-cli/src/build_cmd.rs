//! `tarn build` and the default run.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tarn::grid::{GridConfig, RangeNoise};
use tarn::mapper::MapperConfig;
use tarn::project::{LabelSensor, LabelsConfig};
use tarn::rig::RigSpec;
use tarn_log::build::{
    build_file, build_log, check_output_dir, BuildConfig, BuildReport, ExtraMaps, LogBuildConfig,
    LogBuildReport, WaterSummary,
};
use tarn_log::frames::LogConfig;

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct BuildArgs {
    /// Input: a robot log (.mcap; rosbag2 directory or .db3; ROS 1 .bag), or a cloud in the
    /// map frame (.ply ascii/binary, KITTI .bin).
    pub input: PathBuf,
    /// Output directory (created if needed; files are replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Configuration (.toml, or JSON): the fields of tarn::mapper::MapperConfig. In a file a
    /// sensor whose section ([lidar], [stereo], [labels]) is absent is off; every option
    /// below can be set there, and an option given here overrides the file. Without it a
    /// log is built with every sensor it carries.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The rig's datasheet (maps/rigs/*.toml, or the rig.toml `tarn simulate` writes):
    /// lidar wavelength, sensitivity, aperture and range noise; stereo disparity noise,
    /// minimum disparity and baseline. Applied over the config.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Cell size, metres [default: 0.10, or the config's].
    #[arg(long)]
    pub resolution: Option<f64>,
    /// (cloud) Elevation noise of the input points, metres (one σ) [default: 0.02].
    #[arg(long)]
    pub noise_sigma: Option<f64>,
    /// (cloud) Largest window side, cells; larger clouds are built in blocks [default: 2048].
    #[arg(long)]
    pub max_window_cells: Option<usize>,
    /// (log) Side of the rolling window around the vehicle, cells [default: 400].
    #[arg(long)]
    pub window_cells: Option<usize>,
    /// (log) Topic whose clouds make frames (default: lidar, or stereo if the log has no lidar).
    #[arg(long)]
    pub frame_topic: Option<String>,
    /// (log) The lidar's PointCloud2 topic [default: /lidar/points, else the one
    /// PointCloud2 topic that is not the stereo cloud].
    #[arg(long)]
    pub lidar_topic: Option<String>,
    /// (log) The stereo PointCloud2 topic [default: /stereo/points, else the one
    /// PointCloud2 topic named *stereo*].
    #[arg(long)]
    pub stereo_topic: Option<String>,
    /// (log) The colour camera's Image topic (its CameraInfo: `camera_info` beside it)
    /// [default: /camera/image, else the one Image topic that is not SWIR or MWIR].
    #[arg(long)]
    pub camera_topic: Option<String>,
    /// (log) Which water cues run: all, none, or a list of lidar, reflectivity, stereo,
    /// mirror [default: the config's; all without a config].
    #[arg(long)]
    pub cues: Option<String>,
    /// (log) Log configuration (JSON; fields of tarn_log::frames::LogConfig, all optional;
    /// the config's [log] section does the same).
    #[arg(long)]
    pub log_config: Option<PathBuf>,
    /// (log) Image sensors whose labels go into the map's water evidence: none, or any of
    /// colour, swir, mwir [default: the config's; colour and swir without a config].
    #[arg(long, value_delimiter = ',')]
    pub labels: Vec<String>,
    /// (log) Colour model (JSON from `tarn train-colour`), compiled into a 6-bit lookup
    /// table; without it the paper's Table 1 rule.
    #[arg(long)]
    pub colour_model: Option<PathBuf>,
    /// (log) Local solar hour of the log (0..24), for the MWIR labels [default: each
    /// frame's, from its stamp (UTC) and the longitude]
    #[arg(long)]
    pub hour: Option<f64>,
    /// (log) Degrees east of Greenwich, for the local solar hour of the MWIR labels
    /// [default: the log's NavSatFix]
    #[arg(long)]
    pub longitude: Option<f64>,
    /// (log) Label every n-th pixel in x and y [default: 2].
    #[arg(long)]
    pub label_stride: Option<usize>,
    /// (log) Also label every row of pixels whose ground footprint is wider than a map
    /// cell, whatever the stride.
    #[arg(long)]
    pub label_wide_rows: bool,
    /// (log) Pixels whose hit is farther than this do not vote, metres [default: 40].
    #[arg(long)]
    pub label_max_range: Option<f64>,
    /// (log) Cells whose elevation σ exceeds this (metres) are holes to the label ray march
    /// (far stereo-only cells); `inf` keeps every cell [default: 0.1].
    #[arg(long)]
    pub label_surface_max_std: Option<f64>,
    /// (log) How a pixel finds its cell: `zbuffer` (the march started where the map drawn
    /// into the image says the ray meets it) or `march` (from the camera); the same votes
    /// [default: zbuffer].
    #[arg(long)]
    pub label_sampler: Option<String>,
    /// (log) Publish the window's hazard map after every frame, as the vehicle does, and
    /// time it (the `water` stage); without it the water stage runs once at the end. The
    /// map is the same.
    #[arg(long)]
    pub per_frame_maps: bool,
    /// (log) Every this many frames, the window's water bodies become a prior the lidar
    /// cue reads in the frames that follow: a return under a known water level is the
    /// bottom [default: 0, none; the config's `[lidar.cue] prior_every_frames`].
    #[arg(long, value_name = "FRAMES")]
    pub water_prior: Option<u32>,
    /// Print the report as JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// ROS and GIS outputs.
    #[command(flatten)]
    pub maps_out: crate::maps_out::MapsOutArgs,
}

impl BuildArgs {
    /// The arguments of `tarn build INPUT --out OUT` with every default.
    pub fn defaults(input: PathBuf, out: PathBuf) -> Self {
        BuildArgs {
            input,
            out,
            config: None,
            rig: None,
            resolution: None,
            noise_sigma: None,
            max_window_cells: None,
            window_cells: None,
            frame_topic: None,
            lidar_topic: None,
            stereo_topic: None,
            camera_topic: None,
            cues: None,
            log_config: None,
            labels: Vec::new(),
            colour_model: None,
            hour: None,
            longitude: None,
            label_stride: None,
            label_wide_rows: false,
            label_max_range: None,
            label_surface_max_std: None,
            label_sampler: None,
            per_frame_maps: false,
            water_prior: None,
            json: false,
            maps_out: Default::default(),
        }
    }
}

/// The label options over the config's `[labels]` (which they create when absent).
fn apply_label_args(a: &BuildArgs, cfg: &mut MapperConfig) -> anyhow::Result<()> {
    let given = !a.labels.is_empty()
        || a.colour_model.is_some()
        || a.hour.is_some()
        || a.longitude.is_some()
        || a.label_stride.is_some()
        || a.label_wide_rows
        || a.label_max_range.is_some()
        || a.label_surface_max_std.is_some()
        || a.label_sampler.is_some();
    if !given {
        return Ok(());
    }
    if a.labels.len() == 1 && a.labels[0].trim() == "none" {
        cfg.labels = None;
        return Ok(());
    }
    let l = cfg.labels.get_or_insert_with(|| LabelsConfig {
        sensors: Vec::new(),
        ..LabelsConfig::default()
    });
    if !a.labels.is_empty() {
        l.sensors = a
            .labels
            .iter()
            .map(|s| s.parse::<LabelSensor>())
            .collect::<Result<_, _>>()
            .context("--labels")?;
    }
    if let Some(p) = &a.colour_model {
        l.colour_model = Some(p.clone());
    }
    if let Some(h) = a.hour {
        l.hour = Some(h);
    }
    if let Some(lon) = a.longitude {
        l.longitude_deg = Some(lon);
    }
    if let Some(v) = a.label_stride {
        l.stride = v;
    }
    if a.label_wide_rows {
        l.wide_rows = true;
    }
    if let Some(v) = a.label_max_range {
        l.max_range_m = v;
    }
    if let Some(v) = a.label_surface_max_std {
        l.surface_max_std_m = v;
    }
    if let Some(v) = &a.label_sampler {
        l.sampler = v.parse().context("--label-sampler")?;
    }
    anyhow::ensure!(
        !l.sensors.is_empty(),
        "label options given, but no sensor to label with (--labels colour,swir,mwir)"
    );
    Ok(())
}

fn progress_bar(template: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(ProgressStyle::with_template(template).expect("static template"));
    bar
}

/// The map was built, but from a damaged input: the process exits with status 3 (the
/// report names what was skipped).
#[derive(Debug)]
pub struct DamagedInput(pub String);

impl std::fmt::Display for DamagedInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DamagedInput {}

/// `Err(DamagedInput)` naming every damaged range of `input`, or `Ok` when there is none.
pub fn damaged_input(
    input: &Path,
    what: &str,
    damaged: &[tarn_log::mcap_log::DamagedRange],
) -> anyhow::Result<()> {
    if damaged.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = damaged.iter().map(|d| format!("  {d}")).collect();
    Err(DamagedInput(format!(
        "{}: damaged; {what} everything else ({} damaged range{}, listed in report.json):\n{}",
        input.display(),
        damaged.len(),
        if damaged.len() == 1 { "" } else { "s" },
        list.join("\n")
    ))
    .into())
}

/// Runs `tarn build`: prints the report; a map built from a damaged log is an
/// `Err(DamagedInput)` after the outputs were written (exit status 3).
pub fn run(a: &BuildArgs) -> anyhow::Result<()> {
    check_output_dir(&a.out)?;
    if !tarn_log::log::is_log(&a.input) {
        if a.cues.is_some() || a.log_config.is_some() || a.rig.is_some() {
            anyhow::bail!(
                "--cues, --rig and --log-config are for logs; {} is a cloud",
                a.input.display()
            );
        }
        let cfg = build_config(a)?;
        let r = run_cloud(a, &cfg)?;
        if a.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            print_summary(&r);
            print_extra(&r.extra_outputs);
        }
        return Ok(());
    }
    let r = run_log(a)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        for w in r.warnings.iter().filter(|w| w.contains("cannot run")) {
            eprintln!("warning: {w}");
        }
    } else {
        print_log_summary(&r);
        print_extra(&r.extra_outputs);
    }
    damaged_input(&a.input, "the map holds", &r.damaged)
}

fn print_extra(files: &[String]) {
    if !files.is_empty() {
        println!("  also wrote {}", files.join(" "));
    }
}

/// The config of `tarn build`: the file's (or every sensor), the rig's datasheet values,
/// then the options.
pub fn build_config(a: &BuildArgs) -> anyhow::Result<LogBuildConfig> {
    let mut build = match &a.config {
        Some(p) => LogBuildConfig::load(p)?,
        None => LogBuildConfig::of_mapper(MapperConfig::every_sensor()),
    };
    let cfg = &mut build.mapper;
    if let Some(p) = &a.rig {
        RigSpec::load(p)?.apply_to(cfg);
    }
    if let Some(r) = a.resolution {
        cfg.grid.resolution = r;
    }
    if let Some(n) = a.window_cells {
        cfg.grid.size_cells = n;
    }
    if let Some(c) = &a.cues {
        cfg.set_cues(c)?;
    }
    if let Some(v) = a.noise_sigma {
        build.build.noise_sigma_m = v;
    }
    if let Some(v) = a.max_window_cells {
        build.build.max_window_cells = v;
    }
    if a.per_frame_maps {
        build.build.per_frame_maps = true;
    }
    if let Some(n) = a.water_prior {
        match cfg.lidar.as_mut() {
            Some(l) => l.cue.prior_every_frames = n,
            None => eprintln!("warning: --water-prior: no lidar is configured to read it"),
        }
    }
    apply_label_args(a, cfg)?;
    if let Some(p) = &a.log_config {
        build.log = load_log_config(p)?;
    }
    if let Some(t) = &a.frame_topic {
        build.log.frame_topic = t.clone();
    }
    crate::maps_out::apply(&a.maps_out, &mut build.build);
    build.validate()?;
    Ok(build)
}

/// A log configuration file (`--log-config`: JSON, the fields of `LogConfig`, all optional),
/// checked.
pub fn load_log_config(p: &Path) -> anyhow::Result<LogConfig> {
    let text = std::fs::read_to_string(p).with_context(|| p.display().to_string())?;
    let cfg: LogConfig = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a log config", p.display()))?;
    cfg.validate()
        .with_context(|| format!("{}: bad log config", p.display()))?;
    Ok(cfg)
}

/// Builds a log with a progress bar (frames and bytes); returns the report.
pub fn run_log(a: &BuildArgs) -> anyhow::Result<LogBuildReport> {
    // The frame topic is chosen from the log unless it was named.
    let mut cfg = build_config(a)?;
    cfg.topics = tarn_log::frames::NamedTopics {
        lidar: a.lidar_topic.clone(),
        stereo: a.stereo_topic.clone(),
        camera: a.camera_topic.clone(),
        frame: None,
    };
    let bar =
        progress_bar("{spinner} mapping {bar:40} {binary_bytes}/{binary_total_bytes} ({eta})");
    let r = build_log(&a.input, &a.out, &cfg, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    r.with_context(|| format!("building {}", a.input.display()))
}

pub fn run_cloud(a: &BuildArgs, build: &LogBuildConfig) -> anyhow::Result<BuildReport> {
    let mapper = &build.mapper;
    let cfg = BuildConfig {
        grid: GridConfig {
            resolution: mapper.grid.resolution,
            ..GridConfig::default()
        },
        noise: RangeNoise::constant(build.build.noise_sigma_m),
        max_window_cells: build.build.max_window_cells,
        // A cloud is in the map frame; it has no log time.
        extra: ExtraMaps::of(&build.build, &build.log.map_frame, 0),
    };
    let bar = progress_bar("{spinner} fusing {bar:40} {human_pos}/{human_len} points ({eta})");
    let report = build_file(&a.input, &a.out, &cfg, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    report.with_context(|| format!("building {}", a.input.display()))
}

pub fn print_summary(r: &BuildReport) {
    let p = &r.points;
    println!(
        "tarn {}: {} -> {}",
        r.tarn_version,
        r.input.display(),
        r.output.display()
    );
    println!(
        "  points {}: fused {}, below surface {}, non-finite {}, outside {}",
        p.points, p.fused, p.below, p.nonfinite, p.outside
    );
    println!(
        "  cells observed {} at {} m ({} tiles, {} window blocks of {} cells)",
        r.cells_observed, r.resolution_m, r.tiles, r.blocks, r.window_cells
    );
    if let (Some((lo, hi)), Some(e)) = (r.elevation_range_m, r.extent_m) {
        println!(
            "  extent x {:.2}..{:.2} m, y {:.2}..{:.2} m, elevation {:.3}..{:.3} m",
            e[0], e[2], e[1], e[3], lo, hi
        );
    }
    let t = &r.timings_s;
    println!(
        "  time read {:.3} s, fuse {:.3} s ({:.1} M points/s), export {:.3} s, total {:.3} s",
        t.read,
        t.fuse,
        p.points as f64 / t.fuse.max(1e-9) / 1e6,
        t.export,
        t.total
    );
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
    println!("  wrote map.ply terrain.ply water.ply map.png report.json");
}

/// The frames refused for a pose jump, as the stream named them.
fn jumps_of(r: &LogBuildReport) -> impl Iterator<Item = &String> {
    r.frames
        .skip_reasons
        .iter()
        .filter(|s| s.contains("max_speed_mps"))
}

fn print_log_summary(r: &LogBuildReport) {
    println!(
        "tarn {}: {} -> {}",
        r.tarn_version,
        r.input.display(),
        r.output.display()
    );
    println!(
        "  {} frames fused from {} ({:.1} s of log, {:.1}× real time); {} skipped without a transform",
        r.frames_fused, r.frame_topic, r.log_duration_s, r.x_realtime, r.frames.frames_skipped_no_tf
    );
    for (name, p) in [("lidar", &r.lidar_points), ("stereo", &r.stereo_points)] {
        if p.points > 0 {
            println!(
                "  {name} points {}: fused {}, below surface {}, non-finite (missing returns) {}, outside the window {}",
                p.points, p.fused, p.below, p.nonfinite, p.outside
            );
        }
    }
    if let Some(l) = &r.labels {
        for (name, s) in [("colour", &l.colour), ("swir", &l.swir), ("mwir", &l.mwir)] {
            match s {
                // Configured, and the log has no such camera: nothing to say.
                Some(s) if s.frames == 0 && s.frames_no_hour == 0 => {}
                Some(s) => {
                    let hours = match l.mwir_hours.filter(|_| name == "mwir") {
                        Some([a, b]) if s.frames_hour_from_stamp > 0 => format!(
                            ", local solar hour {a:.2}–{b:.2} (from the stamps and longitude)"
                        ),
                        Some([a, _]) => format!(", local solar hour {a:.2} (given)"),
                        None => String::new(),
                    };
                    println!(
                        "  {name} labels: {} frames ({} skipped), cell votes water {} / not {}{hours}",
                        s.frames,
                        s.frames_skipped + s.frames_no_hour,
                        s.cells_water,
                        s.cells_dry
                    );
                    let fa = s.false_alarms;
                    let rate = match name {
                        "colour" => Some(("p_colour_false", r.fusion.p_colour_false)),
                        "swir" => Some(("p_swir_false", r.fusion.p_swir_false)),
                        _ => None,
                    };
                    if let Some((field, p)) = rate.filter(|_| fa.samples > 0) {
                        println!(
                            "    false alarms: {} of {} dry-ground samples of the lidar labelled water; fusion {field} {p:.2e} (the rate's 95 % bound)",
                            fa.water, fa.samples
                        );
                    }
                }
                None => {}
            }
        }
    }
    println!(
        "  cells observed {} at {} m ({} tiles)",
        r.cells_observed, r.resolution_m, r.tiles
    );
    if let Some((lo, hi)) = r.elevation_range_m {
        println!("  elevation {lo:.3}..{hi:.3} m");
    }
    if !r.cues.is_empty() {
        println!(
            "  cues {}{}{}",
            r.cues.join(","),
            r.lidar_height_m.map_or(String::new(), |h| format!(
                "; lidar {h:.2} m above the ground"
            )),
            r.diagnostic_interval_m
                .map_or(String::new(), |(a, b)| format!(
                    ", no-return diagnostic {a:.1}–{b:.1} m"
                ))
        );
        let c = &r.cue_counts;
        let ran = |n: &str| r.cues.iter().any(|x| x == n);
        let mut parts = Vec::new();
        if ran("lidar") {
            parts.push(format!(
                "lidar no-return {} (returned {}), bottom {}, specular {}, below-level ground {}, dark {}",
                c.lidar_noret, c.lidar_diag_ret, c.lidar_bottom, c.lidar_specular,
                c.lidar_below_ground, c.lidar_dark
            ));
        }
        if ran("stereo") {
            parts.push(format!(
                "stereo runs {} ({} reflected points)",
                c.stereo_runs, c.stereo_reflected_points
            ));
        }
        println!("  {}", parts.join("; "));
    }
    print_water(&r.water);
    crate::log_cmd::print_calibration(&r.calibration);
    for w in &r.calibration.warnings {
        eprintln!("warning: calibration: {w}");
    }
    print_latency(r);
    for e in r.errors.iter().take(10) {
        println!("  skipped: {e}");
    }
    if r.errors.len() > 10 {
        println!(
            "  ... and {} more (report.json lists them all)",
            r.errors.len() - 10
        );
    }
    // What the plausibility checks refused or dropped, on stderr.
    let jumps = jumps_of(r);
    let shown = jumps.chain(&r.warnings).count();
    for w in jumps_of(r).chain(&r.warnings).take(10) {
        eprintln!("warning: {w}");
    }
    if shown > 10 {
        eprintln!(
            "warning: {} more (report.json lists them; {} frames refused for a pose jump)",
            shown - 10,
            r.frames.frames_refused_pose_jump
        );
    }
    println!("  wrote map.ply terrain.ply water.ply map.png report.json");
}

pub fn print_water(w: &WaterSummary) {
    let depth = match (w.depth_mean_m, w.depth_max_m) {
        (Some(m), Some(x)) => format!(
            "; depth measured in {} cells: mean {m:.2} m, max {x:.2} m; unknown in {}",
            w.depth_cells,
            w.water_cells - w.depth_cells
        ),
        _ if w.water_cells > 0 => "; depth unknown (no bottom returns)".to_string(),
        _ => String::new(),
    };
    println!(
        "  water {} cells ({:.1} m²){depth}",
        w.water_cells, w.water_area_m2
    );
    let h = &w.hazard_cells;
    println!(
        "  hazards: free {}, shallow water {}, deep or unknown-depth water {}, obstacle {}",
        h.free, h.shallow_water, h.deep_water, h.obstacle
    );
    for b in w.bodies.as_array().into_iter().flatten() {
        let num = |k: &str| b[k].as_f64();
        let surface = match (b["surface_model"].as_str(), num("surface_z")) {
            (Some(m), Some(z)) => format!("{m} at z {z:.3} m"),
            (Some(m), None) => m.to_string(),
            _ => "?".into(),
        };
        let volume = num("volume_m3").map_or("volume unknown".into(), |v| format!("{v:.2} m³"));
        println!(
            "  body {}: {:.1} m², {volume}, surface {surface} (residual level {} / Delaunay {})",
            b["id"],
            num("area_m2").unwrap_or(f64::NAN),
            num("level_residual_m").map_or("–".into(), |r| format!("{r:.3} m")),
            num("delaunay_residual_m").map_or("–".into(), |r| format!("{r:.3} m")),
        );
    }
}

pub fn print_latency(r: &LogBuildReport) {
    let cell = |name: &str| {
        r.stage_latency_ms
            .iter()
            .find(|s| s.stage == name)
            .map_or("–".to_string(), |s| {
                format!("{:.1}/{:.1}/{:.1}", s.median_ms, s.p95_ms, s.max_ms)
            })
    };
    let water = if r.per_frame_maps {
        cell("water")
    } else {
        "– (once, at the end)".to_string()
    };
    // The stages of the sensors the log has.
    let mut stages = vec![format!("recentre {}", cell("recentre"))];
    if r.lidar_points.points > 0 {
        stages.push(format!("lidar {}", cell("lidar")));
    }
    if r.stereo_points.points > 0 {
        stages.push(format!("stereo {}", cell("stereo")));
    }
    if r.labels.is_some() {
        stages.push(format!("labels {}", cell("labels")));
    }
    println!(
        "  per frame (ms, median/p95/max): {}, water {water}, total {}",
        stages.join(", "),
        cell("total")
    );
}
