//! `tarn build` and the default run.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tarn::build::{
    build_file, build_log, check_output_dir, BuildConfig, BuildReport, LogBuildConfig,
    LogBuildReport,
};
use tarn::grid::{GridConfig, RangeNoise};
use tarn::io::frames::LogConfig;

#[derive(Args)]
pub struct BuildArgs {
    /// Input: a ROS 2 log (.mcap), or a cloud in the map frame (.ply ascii/binary, KITTI .bin).
    pub input: PathBuf,
    /// Output directory (created if needed; files are replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Cell size, metres.
    #[arg(long, default_value_t = 0.10)]
    pub resolution: f64,
    /// (cloud) Elevation noise of the input points, metres (one σ).
    #[arg(long, default_value_t = 0.02)]
    pub noise_sigma: f64,
    /// (cloud) Largest window side, cells; larger clouds are built in blocks.
    #[arg(long, default_value_t = 2048)]
    pub max_window_cells: usize,
    /// (log) Side of the rolling window around the vehicle, cells.
    #[arg(long, default_value_t = 400)]
    pub window_cells: usize,
    /// (log) Topic whose clouds make frames (default: lidar, or stereo if the log has no lidar).
    #[arg(long)]
    pub frame_topic: Option<String>,
    /// (log) Log configuration (JSON; fields of tarn::io::frames::LogConfig, all optional).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print the report as JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
}

impl BuildArgs {
    /// The arguments of `tarn build INPUT --out OUT` with every default.
    pub fn defaults(input: PathBuf, out: PathBuf) -> Self {
        BuildArgs {
            input,
            out,
            resolution: 0.10,
            noise_sigma: 0.02,
            max_window_cells: 2048,
            window_cells: 400,
            frame_topic: None,
            config: None,
            json: false,
        }
    }
}

/// Where the default scene lives: next to the binary's crate, or in the working directory.
pub fn default_scene() -> PathBuf {
    let here = PathBuf::from("maps/default.ply");
    if here.exists() {
        return here;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("maps/default.ply")
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
    let grid = GridConfig {
        resolution: a.resolution,
        ..GridConfig::default()
    };
    if !is_log(&a.input) {
        let r = run_cloud(a, grid)?;
        if a.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            print_summary(&r);
        }
        return Ok(());
    }
    let log = match &a.config {
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
        grid: GridConfig {
            size_cells: a.window_cells,
            ..grid
        },
        log,
        frame_topic: a.frame_topic.clone(),
    };
    let bar =
        progress_bar("{spinner} reading {bar:40} {binary_bytes}/{binary_total_bytes} ({eta})");
    let r = build_log(&a.input, &a.out, &cfg, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    let r = r.with_context(|| format!("building {}", a.input.display()))?;
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
    println!("  wrote map.ply terrain.ply map.png report.json");
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
    println!(
        "  cells observed {} at {} m ({} tiles)",
        r.cells_observed, r.resolution_m, r.tiles
    );
    if let Some((lo, hi)) = r.elevation_range_m {
        println!("  elevation {lo:.3}..{hi:.3} m");
    }
    for e in r.errors.iter().take(10) {
        println!("  skipped: {e}");
    }
    if r.errors.len() > 10 {
        println!(
            "  ... and {} more (report.json lists them all)",
            r.errors.len() - 10
        );
    }
    println!("  wrote map.ply terrain.ply map.png report.json");
}
