//! `tarn cues`: the lidar water cues of one organized scan (.ply or KITTI .bin).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;
use tarn::cues::{
    estimate_sensor_height, BeamModel, CueRun, LidarBuffers, LidarCueConfig, LidarCueModel,
    LidarCueStats, ReflectivityConfig,
};
use tarn::optics::{Attenuation, LidarModelConfig, Sensitivity, SolidAngleForm};

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct CuesArgs {
    /// The scan, in the sensor frame: a column-major spinning-lidar scan (.ply or KITTI .bin).
    pub input: PathBuf,
    /// Rings of the scan (point = column × rings + ring).
    #[arg(long)]
    pub rings: usize,
    /// Sensor height above the ground (m); estimated from the scan's ground ring if absent.
    #[arg(long)]
    pub height_m: Option<f64>,
    /// Lidar wavelength (nm), for pure-water absorption.
    #[arg(long, default_value_t = 865.0)]
    pub wavelength_nm: f64,
    /// Lookahead (m) where level dry ground stops returning (sets the sensitivity).
    #[arg(long)]
    pub dry_limit_m: f64,
    /// Shallowest water whose missing returns are to be diagnostic (m).
    #[arg(long, default_value_t = 0.0)]
    pub min_depth_m: f64,
    /// Grid resolution of the evidence cells (m).
    #[arg(long, default_value_t = 0.1)]
    pub resolution: f64,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    height_m: f64,
    height_estimated: bool,
    diagnostic_interval_m: Option<[f64; 2]>,
    stats: LidarCueStats,
    reflectivity_threshold: Option<f64>,
    reflectivity_law: Option<tarn::cues::ChannelLaw>,
    evidence_cells: usize,
    cells_with_noret: usize,
    cells_with_depth: usize,
    cells_with_reflection: usize,
}

pub fn run(a: &CuesArgs) -> anyhow::Result<()> {
    let raw = tarn_log::log::read_cloud(&a.input)
        .with_context(|| format!("reading {}", a.input.display()))?;
    let cloud = tarn::io::organize_column_major(&raw, a.rings)?;
    let (height, estimated) = match a.height_m {
        Some(h) => (h, false),
        None => (
            estimate_sensor_height(&cloud).context(
                "cannot estimate the sensor height (fewer than 20 returns 10–45° below the \
                 horizon); give --height-m",
            )?,
            true,
        ),
    };
    let optics = LidarModelConfig {
        height_m: height,
        attenuation: Attenuation::PureWater {
            wavelength_nm: a.wavelength_nm,
        },
        albedo: 0.3,
        aperture_diameter_m: 0.0254,
        n_water: 1.33,
        sensitivity: Sensitivity::DryLimit(a.dry_limit_m),
        solid_angle: SolidAngleForm::Exact,
    };
    let cfg = LidarCueConfig {
        min_depth_m: a.min_depth_m,
        ..LidarCueConfig::default()
    };
    let model = LidarCueModel::new(
        optics,
        BeamModel::default(),
        cfg,
        Some(ReflectivityConfig::default()),
    )?;
    let run = CueRun {
        surface_points: true,
        ..CueRun::new(a.resolution, 0.0)
    };
    let out = model.run(&cloud, &run, &mut LidarBuffers::default())?;
    let count = |f: &dyn Fn(&tarn::grid::Evidence) -> bool| {
        out.evidence.iter().filter(|(_, e)| f(e)).count()
    };
    let rep = Report {
        height_m: height,
        height_estimated: estimated,
        diagnostic_interval_m: model.interval().map(|(s, e)| [s, e]),
        stats: out.stats,
        reflectivity_threshold: out.reflectivity_threshold,
        reflectivity_law: out.reflectivity_law,
        evidence_cells: out.evidence.len(),
        cells_with_noret: count(&|e| e.noret > 0),
        cells_with_depth: count(&|e| e.depth_n > 0),
        cells_with_reflection: count(&|e| e.reflect > 0),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rep)?);
    } else {
        println!(
            "sensor height      {:.3} m{}",
            rep.height_m,
            if estimated { " (estimated)" } else { "" }
        );
        match rep.diagnostic_interval_m {
            Some([s, e]) => println!("diagnostic interval {s:.2} – {e:.2} m"),
            None => println!("diagnostic interval none"),
        }
        let s = &rep.stats;
        println!(
            "slots {}  missing {}  (no direction {}, cast {}, inside the interval {})",
            s.slots, s.missing, s.no_direction, s.missing_cast, s.noret
        );
        println!(
            "returns inside the interval {}  bottom {}  specular {}  dark {}  lit {}",
            s.diag_ret, s.bottom, s.specular, s.dark, s.lit
        );
        println!(
            "evidence cells {}  (no-return {}, depth {}, reflection {})",
            rep.evidence_cells,
            rep.cells_with_noret,
            rep.cells_with_depth,
            rep.cells_with_reflection
        );
    }
    Ok(())
}
