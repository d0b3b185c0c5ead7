//! `tarn simulate` and `tarn eval`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tarn::sim::{simulate, Scene, SimOptions};

#[derive(Args)]
pub struct SimulateArgs {
    /// Scene file (TOML, see maps/README.md).
    pub scene: PathBuf,
    /// Output directory: log.mcap, truth.ply, truth.json, scene.ply.
    #[arg(long)]
    pub out: PathBuf,
    /// Exact geometry: no range, disparity or pixel noise and no stereo dropout.
    #[arg(long)]
    pub no_noise: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run_simulate(a: &SimulateArgs) -> anyhow::Result<()> {
    let scene = Scene::load(&a.scene)?;
    let r = simulate(&scene, &a.out, SimOptions { noise: !a.no_noise })
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
pub struct EvalArgs {
    /// Map directory holding map.ply (the export contract).
    pub map_dir: PathBuf,
    /// Truth directory written by `tarn simulate` (truth.ply, truth.json).
    #[arg(long)]
    pub truth: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run_eval(a: &EvalArgs) -> anyhow::Result<()> {
    let r = tarn::eval::evaluate_dirs(&a.map_dir, &a.truth)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "scene {} (map {} m, truth {} m cells)",
            r.scene, r.map_resolution, r.truth_resolution
        );
        print!("{}", r.markdown());
    }
    Ok(())
}
