//! `tarn build` and the default run.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tarn::build::{build_file, check_output_dir, BuildConfig, BuildReport};
use tarn::grid::{GridConfig, RangeNoise};

#[derive(Args)]
pub struct BuildArgs {
    /// Input cloud: .ply (ascii or binary) or KITTI .bin, in the map frame.
    pub input: PathBuf,
    /// Output directory (created if needed; files are replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Cell size, metres.
    #[arg(long, default_value_t = 0.10)]
    pub resolution: f64,
    /// Elevation noise of the input points, metres (one σ).
    #[arg(long, default_value_t = 0.02)]
    pub noise_sigma: f64,
    /// Largest window side, cells; larger clouds are built in blocks.
    #[arg(long, default_value_t = 2048)]
    pub max_window_cells: usize,
    /// Print the report as JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
}

/// Where the default scene lives: next to the binary's crate, or in the working directory.
pub fn default_scene() -> PathBuf {
    let here = PathBuf::from("maps/default.ply");
    if here.exists() {
        return here;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("maps/default.ply")
}

pub fn run_build(a: &BuildArgs) -> anyhow::Result<BuildReport> {
    check_output_dir(&a.out)?;
    let cfg = BuildConfig {
        grid: GridConfig {
            resolution: a.resolution,
            ..GridConfig::default()
        },
        noise: RangeNoise::constant(a.noise_sigma),
        max_window_cells: a.max_window_cells,
    };
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} fusing {bar:40} {human_pos}/{human_len} points ({eta})",
        )
        .expect("static template"),
    );
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
