//! `tarn bench`: per-stage medians on the default scene (or a given log), the speed/error
//! sweeps, and large-cloud builds.

use std::path::PathBuf;

use std::io::Write;

use crate::bench::{cloud_build, run, sweep, sweep_markdown, sweep_plot, BenchOptions};
use anyhow::Context;
use clap::Args;

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct BenchArgs {
    /// Measure this log instead of simulating the scene.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Scene to simulate when no log is given.
    #[arg(long, default_value = "maps/default.toml")]
    pub scene: PathBuf,
    /// Rig to simulate the scene with (maps/rigs/*.toml; e.g. full_frame.toml for the full
    /// sensor sizes) instead of the one it names.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Repetitions of every stage (medians are reported).
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Sweep the knobs that trade speed for error; writes sweep.md, sweep.json and
    /// sweep.png into --out.
    #[arg(long)]
    pub sweep: bool,
    /// Output directory of --sweep.
    #[arg(long, default_value = "out/bench")]
    pub out: PathBuf,
    /// Build synthetic clouds of these many points (comma-separated, e.g. 1e6,1e8) with
    /// `build_cloud` over --cloud-side-m squares and report times.
    #[arg(long, value_delimiter = ',')]
    pub cloud_points: Vec<f64>,
    /// Side of the synthetic cloud's square, metres (comma-separated for several).
    #[arg(long, value_delimiter = ',', default_values_t = [200.0])]
    pub cloud_side_m: Vec<f64>,
}

pub fn run_bench(a: &BenchArgs) -> anyhow::Result<()> {
    let opts = BenchOptions {
        reps: a.reps,
        log: a.log.clone(),
        scene: a.scene.clone(),
        rig: a.rig.clone(),
        ..BenchOptions::default()
    };
    if !a.cloud_points.is_empty() {
        let mut rows = Vec::new();
        for &side in &a.cloud_side_m {
            for &n in &a.cloud_points {
                let r = cloud_build(n as usize, side)?;
                if !a.json {
                    println!(
                        "{} points over {} m: generate {:.2} s, build {:.2} s ({:.1} M points/s), {} blocks, {} cells",
                        r.points, r.side_m, r.generate_s, r.build_s, r.points_per_s / 1e6, r.blocks, r.cells_observed
                    );
                }
                rows.push(r);
            }
        }
        if a.json {
            println!("{}", serde_json::to_string_pretty(&rows)?);
        }
        return Ok(());
    }
    if a.sweep {
        let rows = sweep(&opts)?;
        std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
        let md = sweep_markdown(&rows);
        tarn::files::write_atomic(&a.out.join("sweep.md"), |w| w.write_all(md.as_bytes()))?;
        tarn::files::write_json(&a.out.join("sweep.json"), &rows)?;
        sweep_plot(&rows, &a.out.join("sweep.png"))?;
        print!("{md}");
        return Ok(());
    }
    let r = run(&opts)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", r.markdown());
    }
    Ok(())
}
