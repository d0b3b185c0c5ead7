//! `tarn build` and the default run.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tarn::build::{
    build_file, build_log, check_output_dir, BuildConfig, BuildReport, LogBuildConfig,
    LogBuildReport, WaterSummary,
};
use tarn::classify::color::RuleClassifier;
use tarn::classify::gmm::ColorModel;
use tarn::classify::lut::ColorLut;
use tarn::classify::thermal::{MwirConfig, SwirConfig};
use tarn::grid::{GridConfig, RangeNoise};
use tarn::io::frames::LogConfig;
use tarn::mapper::MapperConfig;
use tarn::project::{FrameLabelConfig, MwirLabelConfig};

#[derive(Args)]
pub struct BuildArgs {
    /// Input: a ROS 2 log (.mcap), or a cloud in the map frame (.ply ascii/binary, KITTI .bin).
    pub input: PathBuf,
    /// Output directory (created if needed; files are replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Cell size, metres [default: 0.10, or the mapper config's].
    #[arg(long)]
    pub resolution: Option<f64>,
    /// (cloud) Elevation noise of the input points, metres (one σ).
    #[arg(long, default_value_t = 0.02)]
    pub noise_sigma: f64,
    /// (cloud) Largest window side, cells; larger clouds are built in blocks.
    #[arg(long, default_value_t = 2048)]
    pub max_window_cells: usize,
    /// (log) Side of the rolling window around the vehicle, cells [default: 400, or the
    /// mapper config's].
    #[arg(long)]
    pub window_cells: Option<usize>,
    /// (log) Topic whose clouds make frames (default: lidar, or stereo if the log has no lidar).
    #[arg(long)]
    pub frame_topic: Option<String>,
    /// (log) Mapper configuration (.toml, or JSON): grid, fusion, vehicle, lidar and stereo
    /// sections, fields of tarn::mapper::MapperConfig, all optional. `tarn simulate` writes
    /// the one of its rig as DIR/mapper.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// (log) Which water cues run: all, none, or a list of lidar, reflectivity, stereo,
    /// mirror [default: the config's; all without a config].
    #[arg(long)]
    pub cues: Option<String>,
    /// (log) Log configuration (JSON; fields of tarn::io::frames::LogConfig, all optional).
    #[arg(long)]
    pub log_config: Option<PathBuf>,
    /// (log) Image sensors whose labels go into the map's water evidence: any of colour,
    /// swir, mwir (comma-separated). The map is then exported with water.
    #[arg(long, value_delimiter = ',')]
    pub labels: Vec<String>,
    /// (log) Colour model (JSON from `tarn train-color`), compiled into a 6-bit lookup
    /// table; without it the paper's Table 1 rule.
    #[arg(long)]
    pub colour_model: Option<PathBuf>,
    /// (log) Local solar hour of the log (0..24), for the MWIR labels.
    #[arg(long)]
    pub hour: Option<f64>,
    /// (log) Label every n-th pixel in x and y.
    #[arg(long, default_value_t = 2)]
    pub label_stride: usize,
    /// (log) Also label every row of pixels whose ground footprint is wider than a map
    /// cell, whatever the stride.
    #[arg(long)]
    pub label_wide_rows: bool,
    /// (log) Pixels whose hit is farther than this do not vote, metres.
    #[arg(long, default_value_t = 40.0)]
    pub label_max_range: f64,
    /// (log) Cells whose elevation σ exceeds this (metres) are holes to the label ray march
    /// (far stereo-only cells); `inf` keeps every cell.
    #[arg(long, default_value_t = 0.1)]
    pub label_surface_max_std: f64,
    /// (log) Publish the window's hazard map after every frame, as the vehicle does, and
    /// time it (the `water` stage); without it the water stage runs once at the end. The
    /// map is the same.
    #[arg(long)]
    pub per_frame_maps: bool,
    /// Print the report as JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
}

/// The label configuration of `--labels`, `--colour-model`, `--hour`.
fn label_config(a: &BuildArgs) -> anyhow::Result<Option<FrameLabelConfig>> {
    if a.labels.is_empty() {
        anyhow::ensure!(
            a.colour_model.is_none() && a.hour.is_none(),
            "--colour-model and --hour need --labels"
        );
        return Ok(None);
    }
    let mut cfg = FrameLabelConfig {
        ray_stride: a.label_stride,
        wide_rows: a.label_wide_rows,
        max_range: a.label_max_range,
        surface_max_std: a.label_surface_max_std,
        ..FrameLabelConfig::default()
    };
    for l in &a.labels {
        match l.trim() {
            "colour" | "color" => {
                cfg.colour = Some(match &a.colour_model {
                    Some(p) => ColorLut::compile(&ColorModel::load(p)?, 6)?,
                    None => ColorLut::compile(&RuleClassifier::default(), 8)?,
                })
            }
            "swir" => cfg.swir = Some(SwirConfig::default()),
            "mwir" => {
                let hour = a
                    .hour
                    .context("--labels mwir needs --hour (local solar hour of the log)")?;
                cfg.mwir = Some(MwirLabelConfig {
                    classifier: MwirConfig::default(),
                    hour,
                })
            }
            other => anyhow::bail!("--labels: unknown sensor {other:?} (colour, swir, mwir)"),
        }
    }
    anyhow::ensure!(
        cfg.colour.is_some() || a.colour_model.is_none(),
        "--colour-model needs --labels colour"
    );
    cfg.validate()?;
    Ok(Some(cfg))
}

impl BuildArgs {
    /// The arguments of `tarn build INPUT --out OUT` with every default.
    pub fn defaults(input: PathBuf, out: PathBuf) -> Self {
        BuildArgs {
            input,
            out,
            resolution: None,
            noise_sigma: 0.02,
            max_window_cells: 2048,
            window_cells: None,
            frame_topic: None,
            config: None,
            cues: None,
            log_config: None,
            labels: Vec::new(),
            colour_model: None,
            hour: None,
            label_stride: 2,
            label_wide_rows: false,
            label_max_range: 40.0,
            label_surface_max_std: 0.1,
            per_frame_maps: false,
            json: false,
        }
    }
}

fn progress_bar(template: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(ProgressStyle::with_template(template).expect("static template"));
    bar
}

fn is_log(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// Runs `tarn build`: prints the report, and fails after writing the map if the log was
/// damaged (the map holds everything before the damage).
pub fn run(a: &BuildArgs) -> anyhow::Result<()> {
    check_output_dir(&a.out)?;
    if !is_log(&a.input) {
        if a.config.is_some() || a.cues.is_some() || a.log_config.is_some() {
            anyhow::bail!(
                "--config, --cues and --log-config are for logs (.mcap); {} is a cloud",
                a.input.display()
            );
        }
        let grid = GridConfig {
            resolution: a.resolution.unwrap_or(0.10),
            ..GridConfig::default()
        };
        let r = run_cloud(a, grid)?;
        if a.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            print_summary(&r);
        }
        return Ok(());
    }
    let r = run_log(a)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print_log_summary(&r);
    }
    match &r.damage {
        Some(d) => anyhow::bail!("the map holds what came before the damage: {d}"),
        None => Ok(()),
    }
}

/// The mapper config of `tarn build LOG`: the file's (or the default), then the options.
pub fn mapper_config(a: &BuildArgs) -> anyhow::Result<MapperConfig> {
    let mut cfg = match &a.config {
        Some(p) => MapperConfig::load(p)?,
        None => MapperConfig::default(),
    };
    if let Some(r) = a.resolution {
        cfg.grid.resolution = r;
    }
    if let Some(n) = a.window_cells {
        cfg.grid.size_cells = n;
    }
    if let Some(c) = &a.cues {
        cfg.set_cues(c)?;
    }
    cfg.labels = label_config(a)?;
    cfg.validate()?;
    Ok(cfg)
}

/// Builds a log with a progress bar (frames and bytes); returns the report.
pub fn run_log(a: &BuildArgs) -> anyhow::Result<LogBuildReport> {
    let log = match &a.log_config {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| p.display().to_string())?;
            let c: LogConfig = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a log config", p.display()))?;
            c.validate()
                .with_context(|| format!("{}: bad log config", p.display()))?;
            c
        }
        None => LogConfig::default(),
    };
    let cfg = LogBuildConfig {
        mapper: mapper_config(a)?,
        log,
        frame_topic: a.frame_topic.clone(),
        per_frame_maps: a.per_frame_maps,
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

pub fn run_cloud(a: &BuildArgs, grid: GridConfig) -> anyhow::Result<BuildReport> {
    let cfg = BuildConfig {
        grid,
        noise: RangeNoise::constant(a.noise_sigma),
        max_window_cells: a.max_window_cells,
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
    println!("  wrote map.ply terrain.ply water.ply map.png report.json");
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
                "  {name} points {}: fused {}, below surface {}, missing {}, outside the window {}",
                p.points, p.fused, p.below, p.nonfinite, p.outside
            );
        }
    }
    if let Some(l) = &r.labels {
        for (name, s) in [("colour", &l.colour), ("swir", &l.swir), ("mwir", &l.mwir)] {
            if let Some(s) = s {
                println!(
                    "  {name} labels: {} frames ({} skipped), cell votes water {} / not {}",
                    s.frames, s.frames_skipped, s.cells_water, s.cells_dry
                );
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
        println!(
            "  lidar no-return {} (returned {}), bottom {}, specular {}, dark {}; stereo runs {} ({} reflected points)",
            c.lidar_noret, c.lidar_diag_ret, c.lidar_bottom, c.lidar_specular, c.lidar_dark,
            c.stereo_runs, c.stereo_reflected_points
        );
    }
    print_water(&r.water);
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
        h[0], h[1], h[2], h[3]
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
    println!(
        "  per frame (ms, median/p95/max): recentre {}, lidar {}, stereo {}, labels {}, water {}, total {}",
        cell("recentre"),
        cell("lidar"),
        cell("stereo"),
        cell("labels"),
        water,
        cell("total")
    );
}
