//! `tarn` with no arguments: simulate the default scene, build its map through the full
//! pipeline, score it against the truth, and print what it found and how fast.

use std::path::{Path, PathBuf};

use anyhow::Context;
use tarn_sim::sim::{simulate, Scene, SimOptions};

use crate::build_cmd::{self, BuildArgs};

/// Where the default scene lives: in the working directory, or next to the crate.
pub fn default_scene_toml() -> PathBuf {
    let here = PathBuf::from("maps/default.toml");
    if here.exists() {
        return here;
    }
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("maps/default.toml")
}

pub fn run(scene_path: &Path, out: &Path) -> anyhow::Result<()> {
    let sim_dir = out.join("sim");
    let scene = Scene::load(scene_path)?;
    println!(
        "tarn: simulating {} ({}) into {}",
        scene_path.display(),
        scene.description,
        sim_dir.display()
    );
    let s = simulate(
        &scene,
        &sim_dir,
        SimOptions {
            noise: true,
            ..SimOptions::default()
        },
    )
    .with_context(|| format!("simulating {}", scene_path.display()))?;
    println!(
        "  {} frames: {} lidar returns, {} stereo points; truth {} cells, {} water",
        s.frames, s.lidar_returns, s.stereo_points, s.truth_cells, s.water_cells
    );
    // What a user has: the log, and the rig's datasheet (nothing of the scene); every
    // sensor the log carries, with the default settings.
    let mut args = BuildArgs::defaults(sim_dir.join("log.mcap"), out.to_path_buf());
    args.rig = Some(sim_dir.join("rig.toml"));
    // The vehicle's view: the hazard map published after every frame, and its latency.
    args.per_frame_maps = true;
    println!(
        "tarn: building the map of {} into {}",
        args.input.display(),
        out.display()
    );
    let r = build_cmd::run_log(&args)?;
    println!(
        "  {} frames, {:.1} s of log in {:.2} s: {:.1}× real time; cues {}",
        r.frames_fused,
        r.log_duration_s,
        r.timings_s.total,
        r.x_realtime,
        r.cues.join(",")
    );
    println!(
        "  cells observed {} at {} m",
        r.cells_observed, r.resolution_m
    );
    build_cmd::print_water(&r.water);
    build_cmd::print_latency(&r);
    let e = tarn_sim::eval::evaluate_dirs(out, &sim_dir)?;
    println!("tarn: accuracy against the truth (by distance from the vehicle's path)");
    print!("{}", e.markdown());
    println!("tarn: obstacles against the truth");
    print!("{}", e.obstacle_markdown());
    if let Some(l) = e.colour_view_line() {
        println!("  {l}");
    }
    println!(
        "  wrote map.ply terrain.ply water.ply map.png report.json into {}",
        out.display()
    );
    build_cmd::damaged_input(&args.input, "the map holds", &r.damaged)
}
