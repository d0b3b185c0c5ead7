//! `tarn lidar-model`: the lidar propagation model over water (paper section 3).

use std::path::PathBuf;

use crate::plot::plot_lidar_model;
use anyhow::Context;
use clap::{ArgGroup, Args, ValueEnum};
use tarn::optics::{Attenuation, LidarModelConfig, LidarWaterModel, Sensitivity, SolidAngleForm};

#[derive(Clone, Copy, ValueEnum)]
pub enum SolidAngleArg {
    /// Sagittal and tangential virtual distances (exact for a small aperture).
    Exact,
    /// The paper's single-distance form.
    Paper,
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
#[command(group(ArgGroup::new("attenuation").required(true).args(["wavelength_nm", "attenuation_per_m"])))]
#[command(group(ArgGroup::new("sensitivity").required(true).args(["min_power_ratio", "dry_limit_m"])))]
pub struct LidarModelArgs {
    /// Sensor height above the water surface (m).
    #[arg(long)]
    pub height_m: f64,
    /// Lidar wavelength (nm): attenuation is pure-water absorption (Segelstein 1981).
    #[arg(long)]
    pub wavelength_nm: Option<f64>,
    /// Total attenuation coefficient of the water (1/m), for natural or turbid water.
    #[arg(long)]
    pub attenuation_per_m: Option<f64>,
    /// Water depth (m) for the return ratio column and the diagnostic interval.
    #[arg(long, default_value_t = 0.0)]
    pub depth_m: f64,
    /// Lookaheads (m), comma separated; default every 0.5 m to past the dry-ground limit.
    #[arg(long, value_delimiter = ',')]
    pub lookahead_m: Vec<f64>,
    /// Lambertian albedo of the bottom and of dry ground.
    #[arg(long, default_value_t = 0.3)]
    pub albedo: f64,
    /// Receiver aperture diameter (m).
    #[arg(long, default_value_t = 0.0254)]
    pub aperture_diameter_m: f64,
    /// Refractive index of water.
    #[arg(long, default_value_t = 1.33)]
    pub n_water: f64,
    /// Smallest detectable ratio of received to emitted power.
    #[arg(long)]
    pub min_power_ratio: Option<f64>,
    /// Calibrate the minimum ratio as the dry-ground ratio at this lookahead (m).
    #[arg(long)]
    pub dry_limit_m: Option<f64>,
    /// Solid-angle form for the receiver seen from the bottom.
    #[arg(long, value_enum, default_value_t = SolidAngleArg::Exact)]
    pub solid_angle: SolidAngleArg,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Draw the paper's Figures 6b, 7, 8a and 8b for this sensor into a PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn lidar_model(a: LidarModelArgs) -> anyhow::Result<()> {
    let attenuation = match (a.wavelength_nm, a.attenuation_per_m) {
        (Some(w), _) => Attenuation::PureWater { wavelength_nm: w },
        (None, Some(c)) => Attenuation::PerMetre(c),
        (None, None) => anyhow::bail!("give --wavelength-nm or --attenuation-per-m"),
    };
    let sensitivity = match (a.min_power_ratio, a.dry_limit_m) {
        (Some(p), _) => Sensitivity::MinPowerRatio(p),
        (None, Some(l)) => Sensitivity::DryLimit(l),
        (None, None) => anyhow::bail!("give --min-power-ratio or --dry-limit-m"),
    };
    let model = LidarWaterModel::new(LidarModelConfig {
        height_m: a.height_m,
        attenuation,
        albedo: a.albedo,
        aperture_diameter_m: a.aperture_diameter_m,
        n_water: a.n_water,
        sensitivity,
        solid_angle: match a.solid_angle {
            SolidAngleArg::Exact => SolidAngleForm::Exact,
            SolidAngleArg::Paper => SolidAngleForm::Paper,
        },
    })?;
    let lookaheads = if a.lookahead_m.is_empty() {
        model.default_lookaheads()
    } else {
        a.lookahead_m.clone()
    };
    let report = model.report(&lookaheads, a.depth_m)?;
    if let Some(path) = &a.plot {
        plot_lidar_model(&model, a.depth_m, path)
            .with_context(|| format!("drawing {}", path.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "attenuation {:.4} /m, minimum power ratio {:.4e}, dry ground returns to {:.2} m",
        report.attenuation_per_m, report.min_power_ratio, report.dry_limit_m
    );
    println!(
        "zero-depth cutoff {:.2} m ({:.1}°); {} m of water returns to {:.2} m; diagnostic interval {}",
        report.zero_depth_cutoff_m,
        report.incidence_cutoff_deg,
        report.depth_m,
        report.max_lookahead_for_depth_m,
        match report.diagnostic_interval_m {
            Some([s, e]) => format!("{s:.2}–{e:.2} m"),
            None => "empty".to_string(),
        }
    );
    println!(
        "{:>9} {:>8} {:>7} {:>7} {:>12} {:>12} {:>9}",
        "ahead_m", "inc_deg", "T_s", "T_p", "return", "dry", "maxdep_m"
    );
    for r in &report.rows {
        println!(
            "{:>9.3} {:>8.2} {:>7.4} {:>7.4} {:>12.4e} {:>12.4e} {:>9.3}",
            r.lookahead_m,
            r.incidence_deg,
            r.transmittance_s,
            r.transmittance_p,
            r.return_ratio,
            r.dry_ratio,
            r.max_depth_m
        );
    }
    Ok(())
}
