//! The vehicle's mapper configuration: the grid, each sensor and its cues, the water
//! stage and the vehicle; read from TOML, checked field by field.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::calib::{Source, Sourced, StereoStated};
use crate::cues::{
    BeamModel, FrameCueConfig, LidarCueConfig, LidarCueModel, ReflectivityConfig, StereoCueConfig,
};
use crate::error::{Error, Result};
use crate::grid::{Fusion, GridConfig, RangeNoise};
use crate::hazard::{HazardConfig, Vehicle};
use crate::optics::{Attenuation, LidarModelConfig, Sensitivity, SolidAngleForm};
use crate::water::WaterConfig;

/// The lidar: how its scans are fused and which of its cues run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarConfig {
    /// Run the geometric lidar cues (no-return inside the diagnostic interval, bottom and
    /// specular returns). Off: the raw scan is fused, nothing else.
    pub cues: bool,
    /// Run the reflectivity-drop cue (needs `cues`; uses the scan's intensity or
    /// reflectivity channel when it has one).
    pub reflectivity: bool,
    /// Wavelength (nm): pure-water absorption when `attenuation_per_m` is not given.
    pub wavelength_nm: f64,
    /// Water clarity: total attenuation (1/m). Absent: pure water at `wavelength_nm`.
    pub attenuation_per_m: Option<f64>,
    /// Lookahead (m) at which level dry ground of `albedo` stops returning (the
    /// sensitivity).
    pub dry_limit_m: f64,
    /// Height of the sensor above the ground (m). Absent: estimated from the first scan
    /// with enough ground returns ([`crate::cues::estimate_sensor_height`]) and kept.
    pub height_m: Option<f64>,
    /// Lambertian albedo of bottom and ground at the wavelength.
    pub albedo: f64,
    /// Diameter of the receiver aperture, metres.
    pub aperture_diameter_m: f64,
    /// Refractive index of the water relative to air.
    pub n_water: f64,
    /// Directions of missing beams are inferred from the scan across at most this fraction
    /// of a row.
    pub max_gap_fraction: f64,
    /// Range noise of the returns, as the datasheet states it. Absent: measured from the
    /// scans themselves ([`crate::calib`]), and until then the noisy end of real lidars
    /// ([`crate::calib::NOISY_LIDAR`]). A stated noise that the scans contradict is
    /// reported, and the measurement used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<RangeNoise>,
    /// Farthest plausible return, m: points beyond it are dropped (made missing returns)
    /// and counted in the frame's warnings.
    pub max_range_m: f64,
    /// Settings of the lidar water cues.
    pub cue: LidarCueConfig,
    /// Settings of the reflectivity cue (used when `reflectivity` is on).
    pub reflectivity_cue: ReflectivityConfig,
}

impl LidarConfig {
    /// The lidar cue model of this lidar mounted `height_m` above the ground, as the
    /// [`super::Mapper`] runs it.
    pub fn cue_model(&self, height_m: f64) -> Result<LidarCueModel> {
        LidarCueModel::new(
            MapperConfig::lidar_optics(self, height_m),
            BeamModel::Infer {
                max_gap_fraction: self.max_gap_fraction,
            },
            self.cue,
            self.reflectivity.then_some(self.reflectivity_cue),
        )
        .map(|m| m.with_range_noise(self.stated_noise()))
    }

    /// The stated range noise, or the noisy end of real lidars when none is stated.
    pub(crate) fn stated_noise(&self) -> RangeNoise {
        self.noise.unwrap_or(crate::calib::NOISY_LIDAR)
    }
}

impl Default for LidarConfig {
    /// A 905 nm spinning lidar whose returns from 30 % ground end at 40 m: the default
    /// scene's sensor (`maps/default.toml`).
    fn default() -> Self {
        LidarConfig {
            cues: true,
            reflectivity: true,
            wavelength_nm: 905.0,
            attenuation_per_m: None,
            dry_limit_m: 40.0,
            height_m: None,
            albedo: 0.3,
            aperture_diameter_m: 0.0254,
            n_water: 1.33,
            max_gap_fraction: 0.25,
            noise: None,
            max_range_m: 300.0,
            cue: LidarCueConfig::default(),
            reflectivity_cue: ReflectivityConfig::default(),
        }
    }
}

/// The stereo camera: how its clouds are fused and which of its cues run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoConfig {
    /// Run the stereo reflection cue. Off: the raw cloud is fused.
    pub reflections: bool,
    /// Confirm reflections by mirror-image correlation of the camera image (when the frame
    /// has one with its camera model).
    pub mirror_check: bool,
    /// Disparity noise (one σ, pixels of the disparity image that made the cloud): a
    /// datasheet value. With the focal length (the left `CameraInfo`), the binning (image
    /// width over cloud width) and the baseline, it states the cloud's range noise
    /// ([`StereoConfig::stated`]). Absent (a log alone): the noise is measured from the log
    /// ([`crate::calib`]) and the reflection cue waits until it is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disparity_noise_px: Option<f64>,
    /// Smallest disparity the matcher reports (pixels of the disparity image).
    pub min_disparity_px: f64,
    /// The baseline (m), for logs without the right camera's `CameraInfo` (which, when
    /// present, is used instead).
    pub baseline_m: Option<f64>,
    /// Farthest plausible stereo point, m: points beyond it are dropped (made NaN) and
    /// counted in the frame's warnings.
    pub max_range_m: f64,
    /// Cue settings; of `cue.noise` only `sigma0` (the near-range term a of
    /// σ_z = a + c·z²) is read: c is stated or measured per frame.
    pub cue: StereoCueConfig,
}

impl Default for StereoConfig {
    fn default() -> Self {
        StereoConfig {
            reflections: true,
            mirror_check: true,
            disparity_noise_px: None,
            min_disparity_px: 1.0,
            baseline_m: None,
            max_range_m: 200.0,
            cue: StereoCueConfig::default(),
        }
    }
}

impl StereoConfig {
    /// What the frame and this config state of the stereo cloud's noise: the left camera's
    /// focal length, the binning k (image width over the cloud's `cloud_cols`), the
    /// baseline (the log's `baseline_m`, else the config's) and σ_d. Depth
    /// z = f_k·B/d with f_k = f/k, so a disparity error of σ_d is a depth error of
    /// z²·σ_d/(f_k·B): c = σ_d·k/(f·B) when every part is stated
    /// ([`crate::calib::StereoStated::per_m2`]).
    pub fn stated(
        &self,
        camera: Option<&crate::geom::CameraModel>,
        cloud_cols: usize,
        baseline_m: Option<f64>,
    ) -> StereoStated {
        let ok = |b: &f64| b.is_finite() && *b > 0.0;
        let sourced = |value, source| Sourced { value, source };
        let camera = camera.filter(|c| c.fx.is_finite() && c.fx > 0.0 && cloud_cols > 0);
        StereoStated {
            focal_px: camera.map(|c| c.fx),
            binning: camera.map(|c| (c.width / cloud_cols).max(1)),
            baseline_m: baseline_m
                .filter(ok)
                .map(|b| sourced(b, Source::Log))
                .or_else(|| {
                    self.baseline_m
                        .filter(ok)
                        .map(|b| sourced(b, Source::Config))
                }),
            disparity_noise_px: self.disparity_noise_px.map(|s| sourced(s, Source::Config)),
        }
    }

    /// The range noise of a cloud whose σ_z = a + c·z² has c = `per_m2` (a: `cue.noise`).
    pub fn noise_of(&self, per_m2: f64) -> RangeNoise {
        RangeNoise {
            sigma0: self.cue.noise.sigma0,
            per_m: 0.0,
            per_m2,
        }
    }
}

/// Everything the [`super::Mapper`] needs. Loadable from TOML or JSON ([`MapperConfig::load`]);
/// unknown keys are errors; [`MapperConfig::validate`] names the field that is wrong.
///
/// In a file, a sensor whose section is absent (`[lidar]`, `[stereo]`, `[labels]`) is off:
/// its data is not read at all. [`MapperConfig::default`] has the lidar and the stereo pair
/// and no image labels; [`MapperConfig::every_sensor`] adds colour and SWIR labels (what
/// `tarn build LOG` uses without a config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapperConfig {
    /// Cell size, window size and gating of the rolling grid.
    pub grid: GridConfig,
    /// The evidence fusion rule.
    pub fusion: Fusion,
    /// Fording depth, step and slope limits (hazards).
    pub vehicle: Vehicle,
    /// How evidence becomes water bodies with a surface and a depth.
    pub water: WaterConfig,
    /// The lidar; absent: lidar scans are not used at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lidar: Option<LidarConfig>,
    /// The stereo camera; absent: stereo clouds are not used at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stereo: Option<StereoConfig>,
    /// Image labels (colour, SWIR, MWIR) into the water evidence; absent: images are not
    /// used at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<crate::project::LabelsConfig>,
    /// The compiled form of `labels` (lookup tables), for code that builds its own; when
    /// absent, [`super::Mapper::new`] compiles `labels`.
    #[serde(skip)]
    pub label_models: Option<crate::project::FrameLabelConfig>,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            grid: GridConfig::default(),
            fusion: Fusion::default(),
            vehicle: Vehicle::default(),
            water: WaterConfig::default(),
            lidar: Some(LidarConfig::default()),
            stereo: Some(StereoConfig::default()),
            labels: None,
            label_models: None,
        }
    }
}

/// The cue names of [`MapperConfig::set_cues`].
pub const CUE_NAMES: [&str; 4] = ["lidar", "reflectivity", "stereo", "mirror"];

impl MapperConfig {
    /// The cues a mapper of this config runs on every frame, with `labels` its compiled
    /// image labels: the lidar's noise, the stereo reflection cue and its mirror check, and
    /// the surface points when the colour check reads them. The lidar cue model is left
    /// out (`None`): it needs the sensor's height ([`LidarConfig::cue_model`]).
    pub fn frame_cue_config(
        &self,
        labels: Option<&crate::project::FrameLabelConfig>,
    ) -> FrameCueConfig {
        FrameCueConfig {
            lidar: None,
            lidar_noise: self
                .lidar
                .as_ref()
                .map_or(crate::calib::NOISY_LIDAR, |l| l.stated_noise()),
            stereo: self
                .stereo
                .as_ref()
                .filter(|s| s.reflections)
                .map(|s| s.cue),
            mirror_check: self.stereo.as_ref().is_some_and(|s| s.mirror_check),
            surface_points: labels.is_some_and(|m| m.colour.is_some() && m.colour_check),
        }
    }

    /// Every sensor a log may carry: the lidar and the stereo pair with every cue, and
    /// colour, SWIR and MWIR labels (MWIR where each frame's local solar hour is known,
    /// from its stamp and the log's GNSS fix). A sensor the log lacks costs nothing.
    pub fn every_sensor() -> Self {
        MapperConfig {
            labels: Some(crate::project::LabelsConfig {
                sensors: vec![
                    crate::project::LabelSensor::Colour,
                    crate::project::LabelSensor::Swir,
                    crate::project::LabelSensor::Mwir,
                ],
                ..Default::default()
            }),
            ..Self::default()
        }
    }

    /// Reads a config from a `.toml` file, or JSON for any other extension. Errors name the
    /// file, and the key and line where parsing failed; then the config is validated.
    pub fn load(path: &Path) -> Result<Self> {
        let cfg: MapperConfig = crate::files::read_config(path)?;
        cfg.validate()
            .map_err(|e| Error::format(path, "mapper config", e.to_string()))?;
        Ok(cfg)
    }

    /// The part of the config the water stage needs.
    /// The significance of a bottom return's depth comes from the configured lidar's range
    /// noise where `water.min_bottom_depth_m` is not set.
    pub fn hazard_config(&self) -> HazardConfig {
        let mut water = self.water;
        if let (None, Some(l)) = (water.min_bottom_depth_m, &self.lidar) {
            water.min_bottom_depth_m = Some(2.0 * l.stated_noise().sigma0);
        }
        HazardConfig {
            fusion: self.fusion,
            water,
            vehicle: self.vehicle,
        }
    }

    /// The config as TOML text (what [`MapperConfig::load`] reads back).
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| Error::invalid("mapper config", e.to_string()))
    }

    /// Rejects values no mapper can run with; the error names the field
    /// (`lidar.dry_limit_m`, `fusion.prior`, ...).
    pub fn validate(&self) -> Result<()> {
        let named = |section: &str, r: Result<()>| {
            r.map_err(|e| match e {
                Error::Invalid { what, message } if section.is_empty() => {
                    Error::invalid(format!("mapper config {what}"), message)
                }
                Error::Invalid { what, message } => {
                    Error::invalid(format!("mapper config {section}: {what}"), message)
                }
                e => e,
            })
        };
        named("grid", self.grid.validate())?;
        named("fusion", self.fusion.validate())?;
        named("", self.water.validate())?;
        named("", self.vehicle.validate())?;
        if let Some(l) = &self.lidar {
            let pos = |name: &str, v: f64| {
                if v.is_finite() && v > 0.0 {
                    Ok(())
                } else {
                    Err(Error::invalid(
                        format!("mapper config lidar.{name}"),
                        format!("{v} is not a finite number > 0"),
                    ))
                }
            };
            pos("wavelength_nm", l.wavelength_nm)?;
            if l.max_range_m.is_nan() || l.max_range_m <= 0.0 {
                return Err(Error::invalid(
                    "mapper config lidar.max_range_m",
                    format!("{} is not a number > 0", l.max_range_m),
                ));
            }
            pos("dry_limit_m", l.dry_limit_m)?;
            pos("aperture_diameter_m", l.aperture_diameter_m)?;
            if let Some(c) = l.attenuation_per_m {
                pos("attenuation_per_m", c)?;
            }
            if let Some(h) = l.height_m {
                pos("height_m", h)?;
            }
            if !(l.albedo > 0.0 && l.albedo <= 1.0) {
                return Err(Error::invalid(
                    "mapper config lidar.albedo",
                    format!("{} is not in (0, 1]", l.albedo),
                ));
            }
            if !(l.n_water.is_finite() && l.n_water >= 1.0) {
                return Err(Error::invalid(
                    "mapper config lidar.n_water",
                    format!("{} is not a refractive index ≥ 1", l.n_water),
                ));
            }
            if !(l.max_gap_fraction.is_finite() && l.max_gap_fraction >= 0.0) {
                return Err(Error::invalid(
                    "mapper config lidar.max_gap_fraction",
                    format!("{} is not a number ≥ 0", l.max_gap_fraction),
                ));
            }
            if l.reflectivity && !l.cues {
                return Err(Error::invalid(
                    "mapper config lidar.reflectivity",
                    "the reflectivity cue runs inside the lidar cues: set lidar.cues too",
                ));
            }
            if let Some(n) = &l.noise {
                named("lidar.noise", n.validate())?;
            }
            named("lidar.cue", l.cue.validate())?;
            // The prior holds the window's bodies and their reach: bounded by the window.
            let side = self.grid.resolution * self.grid.size_cells as f64;
            if l.cue.prior_reach_m > side {
                return Err(Error::invalid(
                    "mapper config lidar.cue.prior_reach_m",
                    format!(
                        "{} m is more than the window's side ({side} m: grid.size_cells × \
                         grid.resolution)",
                        l.cue.prior_reach_m
                    ),
                ));
            }
            named("lidar.reflectivity_cue", l.reflectivity_cue.validate())?;
        }
        if let Some(s) = &self.stereo {
            if s.mirror_check && !s.reflections {
                return Err(Error::invalid(
                    "mapper config stereo.mirror_check",
                    "the mirror check confirms stereo reflections: set stereo.reflections too",
                ));
            }
            if let Some(d) = s.disparity_noise_px {
                if !(d.is_finite() && d >= 0.0) {
                    return Err(Error::invalid(
                        "mapper config stereo.disparity_noise_px",
                        format!("{d} is not a number ≥ 0"),
                    ));
                }
            }
            if !(s.min_disparity_px.is_finite() && s.min_disparity_px > 0.0) {
                return Err(Error::invalid(
                    "mapper config stereo.min_disparity_px",
                    format!("{} is not a number > 0", s.min_disparity_px),
                ));
            }
            if let Some(b) = s.baseline_m {
                if !(b.is_finite() && b > 0.0) {
                    return Err(Error::invalid(
                        "mapper config stereo.baseline_m",
                        format!("{b} is not a finite number > 0"),
                    ));
                }
            }
            if s.max_range_m.is_nan() || s.max_range_m <= 0.0 {
                return Err(Error::invalid(
                    "mapper config stereo.max_range_m",
                    format!("{} is not a number > 0", s.max_range_m),
                ));
            }
            named("stereo.cue", s.cue.validate())?;
        }
        if let Some(l) = &self.labels {
            l.check()
                .map_err(|e| Error::invalid("mapper config labels", e.to_string()))?;
        }
        Ok(())
    }

    /// The cues this config runs, by name ([`CUE_NAMES`], in that order).
    pub fn cue_names(&self) -> Vec<String> {
        let lidar = self.lidar.as_ref().filter(|l| l.cues);
        let stereo = self.stereo.as_ref().filter(|s| s.reflections);
        let on = [
            lidar.is_some(),
            lidar.is_some_and(|l| l.reflectivity),
            stereo.is_some(),
            stereo.is_some_and(|s| s.mirror_check),
        ];
        CUE_NAMES
            .iter()
            .zip(on)
            .filter(|(_, on)| *on)
            .map(|(n, _)| n.to_string())
            .collect()
    }

    /// Turns the cues on or off by name: `"all"`, `"none"`, or a comma-separated list of
    /// [`CUE_NAMES`] (`lidar` — no-return, bottom and specular; `reflectivity`; `stereo` —
    /// reflections; `mirror` — their mirror-image check). Listed cues run, the others not.
    /// A cue of a sensor the config leaves out is an error.
    pub fn set_cues(&mut self, spec: &str) -> Result<()> {
        let spec = spec.trim();
        let names: Vec<&str> = match spec {
            "all" => {
                let mut v = Vec::new();
                if self.lidar.is_some() {
                    v.extend(["lidar", "reflectivity"]);
                }
                if self.stereo.is_some() {
                    v.extend(["stereo", "mirror"]);
                }
                v
            }
            "none" | "" => Vec::new(),
            s => s.split(',').map(str::trim).collect(),
        };
        for n in &names {
            if !CUE_NAMES.contains(n) {
                return Err(Error::invalid(
                    "cue list",
                    format!(
                        "unknown cue {n:?} in {spec:?} (cues: all, none, or {})",
                        CUE_NAMES.join(",")
                    ),
                ));
            }
        }
        let on = |n: &str| names.contains(&n);
        let need = |n: &str, sensor: &str| {
            Error::invalid(
                "cue list",
                format!("cue {n:?} needs the {sensor}, which the config leaves out"),
            )
        };
        match &mut self.lidar {
            Some(l) => {
                l.cues = on("lidar") || on("reflectivity");
                l.reflectivity = on("reflectivity");
            }
            None if on("lidar") || on("reflectivity") => return Err(need("lidar", "lidar")),
            None => {}
        }
        match &mut self.stereo {
            Some(s) => {
                s.reflections = on("stereo") || on("mirror");
                s.mirror_check = on("mirror");
            }
            None if on("stereo") || on("mirror") => return Err(need("stereo", "stereo camera")),
            None => {}
        }
        Ok(())
    }

    /// The datasheet values of the configured sensors that hold their defaults: what a
    /// mapper of this config assumes of sensors the log cannot describe (a rig file states
    /// them).
    pub(crate) fn assumed_datasheet_values(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Some(l) = &self.lidar {
            let d = LidarConfig::default();
            for (name, value, default) in [
                ("lidar.wavelength_nm", l.wavelength_nm, d.wavelength_nm),
                ("lidar.dry_limit_m", l.dry_limit_m, d.dry_limit_m),
                ("lidar.albedo", l.albedo, d.albedo),
                (
                    "lidar.aperture_diameter_m",
                    l.aperture_diameter_m,
                    d.aperture_diameter_m,
                ),
            ] {
                if value == default {
                    v.push(format!("{name} = {value} (the default)"));
                }
            }
        }
        if let Some(s) = &self.stereo {
            if s.min_disparity_px == StereoConfig::default().min_disparity_px {
                v.push(format!(
                    "stereo.min_disparity_px = {} (the default)",
                    s.min_disparity_px
                ));
            }
        }
        v
    }

    /// The optics of the configured lidar at sensor height `height_m`.
    fn lidar_optics(l: &LidarConfig, height_m: f64) -> LidarModelConfig {
        LidarModelConfig {
            height_m,
            attenuation: match l.attenuation_per_m {
                Some(c) => Attenuation::PerMetre(c),
                None => Attenuation::PureWater {
                    wavelength_nm: l.wavelength_nm,
                },
            },
            albedo: l.albedo,
            aperture_diameter_m: l.aperture_diameter_m,
            n_water: l.n_water,
            sensitivity: Sensitivity::DryLimit(l.dry_limit_m),
            solid_angle: SolidAngleForm::Exact,
        }
    }
}
