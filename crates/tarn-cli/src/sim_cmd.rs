//! `tarn simulate` and `tarn eval`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tarn_sim::sim::{simulate, LogCalibration, Scene, SimOptions};

fn parse_calibration(s: &str) -> Result<LogCalibration, String> {
    LogCalibration::ALL
        .iter()
        .find(|(n, _)| *n == s)
        .map(|(_, c)| *c)
        .ok_or_else(|| {
            let names: Vec<&str> = LogCalibration::ALL.iter().map(|(n, _)| *n).collect();
            format!("{s:?} is not one of {}", names.join(", "))
        })
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct SimulateArgs {
    /// Scene file (TOML, see maps/README.md).
    pub scene: PathBuf,
    /// Output directory: log.mcap, truth.ply, truth.json, scene.ply, rig.toml.
    #[arg(long)]
    pub out: PathBuf,
    /// Render with this rig (maps/rigs/*.toml) instead of the one the scene names.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Exact geometry: no range, disparity or pixel noise and no stereo dropout.
    #[arg(long)]
    pub no_noise: bool,
    /// How much of the rig's calibration the log carries: full, no-right-info (no right
    /// camera CameraInfo), zero-baseline (its P[0][3] = 0), raw-as-reflectivity (the
    /// lidar's raw intensity named `reflectivity`).
    #[arg(long, default_value = "full", value_parser = parse_calibration)]
    pub calibration: LogCalibration,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run_simulate(a: &SimulateArgs) -> anyhow::Result<()> {
    let scene = Scene::load_with_rig(&a.scene, a.rig.as_deref())?;
    let opts = SimOptions {
        noise: !a.no_noise,
        calibration: a.calibration,
    };
    let r = simulate(&scene, &a.out, opts)
        .with_context(|| format!("simulating {}", a.scene.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {} frames, {} lidar beams ({} returns), {} stereo rays ({} points), {} image pixels",
            r.scene, r.frames, r.lidar_beams, r.lidar_returns, r.stereo_rays, r.stereo_points, r.image_pixels
        );
        println!(
            "truth: {} cells, {} water; build {:.2} s, render {:.2} s, write {:.2} s -> {}",
            r.truth_cells,
            r.water_cells,
            r.build_s,
            r.render_s,
            r.write_s,
            a.out.display()
        );
    }
    Ok(())
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct EvalArgs {
    /// Map directory holding map.ply (the export contract).
    pub map_dir: PathBuf,
    /// Truth directory written by `tarn simulate` (truth.ply, truth.json).
    #[arg(long)]
    pub truth: PathBuf,
    /// Print one JSON object instead of a table; it also holds "matrix_bands", the bands
    /// 5-10, 10-20, 20-30 and 5-30 m of the evaluation matrix, and, when the map directory
    /// holds a tile set (`tarn build --tiles`), "cue_rates": each water cue's events on true
    /// water and on dry ground in those bands, beside "fusion_default", the default rule.
    #[arg(long)]
    pub json: bool,
    /// Also score this range band from the path, `LO,HI` metres (e.g. 5,25): a row
    /// (JSON: "band") after the bins.
    #[arg(long, value_parser = parse_band)]
    pub band: Option<(f64, f64)>,
}

fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("{s:?}: expected LO,HI in metres"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<f64>()
            .map_err(|e| format!("{v:?} in {s:?}: {e}"))
    };
    Ok((p(a)?, p(b)?))
}

pub fn run_eval(a: &EvalArgs) -> anyhow::Result<()> {
    let (map, truth, info) = tarn_sim::eval::read_dirs(&a.map_dir, &a.truth)?;
    let r = tarn_sim::eval::evaluate(&map, &truth, &info)?;
    let band = a
        .band
        .map(|(lo, hi)| tarn_sim::eval::evaluate_band(&map, &truth, &info, lo, hi))
        .transpose()?;
    if a.json {
        let mut v = serde_json::to_value(&r)?;
        if let Some(b) = &band {
            v["band"] = serde_json::to_value(b)?;
        }
        // The bands of the evaluation matrix (every scene by every rig), compared across runs;
        // with the simulated log beside the truth, the terrain where its lidar saw the ground.
        let log = a.truth.join("log.mcap");
        let lidar = log
            .is_file()
            .then(|| {
                // The window of a default build at the map's resolution.
                let grid = tarn::grid::GridConfig {
                    resolution: map.resolution,
                    ..Default::default()
                };
                tarn_sim::eval::lidar_cells(&log, &grid)
            })
            .transpose()?;
        v["matrix_bands"] = serde_json::to_value(tarn_sim::eval::evaluate_matrix_bands(
            &map,
            &truth,
            &info,
            lidar.as_ref(),
        )?)?;
        // With the build's tile set: how often each cue fired on water and on dry ground.
        if let Some(r) = tarn_sim::eval::rates::cue_rates_of_dir(&a.map_dir, &truth, &info)? {
            v["cue_rates"] = serde_json::to_value(r)?;
            // The likelihoods these counts are set beside.
            v["fusion_default"] = serde_json::to_value(tarn::grid::Fusion::default())?;
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "scene {} (map {} m, truth {} m cells)",
            r.scene, r.map_resolution, r.truth_resolution
        );
        print!("{}", r.markdown());
        println!(
            "obstacles (step > {} m or slope > {}° of the true terrain, or an object):",
            r.obstacle_limits.max_step_m, r.obstacle_limits.max_slope_deg
        );
        print!("{}", r.obstacle_markdown());
        if let Some(l) = r.colour_view_line() {
            println!("{l}");
        }
        if let Some(b) = &band {
            let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
            println!(
                "band {} m: {} observed, water recall {} ({} of {}), false-positive rate {} ({} of {}), sunk dry cells {}",
                b.range,
                b.observed_cells,
                f(b.water_recall),
                b.water_detected,
                b.water_cells,
                f(b.false_positive_rate),
                b.false_water,
                b.dry_cells,
                b.sunk_cells
            );
        }
    }
    Ok(())
}
