//! The online pipeline (DESIGN.md's data flow): one [`Mapper::update`] per [`Frame`].
//!
//! Each update runs these stages, timed separately in its [`FrameReport`]:
//!
//! 1. **recentre** — the rolling window follows the vehicle; cells that leave it go to the
//!    global [`TileMap`] (kept for [`Mapper::finish`]);
//! 2. **lidar** — the lidar cues ([`crate::cues::LidarCueModel`]: no-return, bottom and
//!    specular returns, reflectivity) and the ingest of the corrected scan; without lidar
//!    cues the raw scan is ingested;
//! 3. **stereo** — the stereo reflection cue ([`crate::cues::stereo_reflections`], with the
//!    mirror-image check when configured and the frame has a camera image) and the ingest of
//!    the corrected cloud; without the cue the raw cloud is ingested;
//! 4. **labels** — the colour, SWIR and MWIR images configured in `labels`, classified and
//!    projected onto the map as votes ([`crate::project::FrameLabels`]);
//! 5. **water** — the hazard map of the window, published as the new snapshot.
//!
//! With `[lidar.cue] prior_every_frames = N` the window's water bodies become, after every
//! N-th frame, the prior the lidar cue reads in the frames that follow
//! ([`crate::cues::prior::WaterPrior`], [`Mapper::water_prior`]): the map just published,
//! or, when the mapper does not publish (an offline build), the same map built for it. An
//! offline build with a prior is therefore the online run's map, at the cost of one water
//! stage every N frames.
//!
//! The cue work is [`crate::cues::FrameCues`]'s; the mapper only decides what runs. A sensor
//! the config leaves out (`lidar`/`stereo` absent) runs no code at all, not even ingest.
//!
//! ## Snapshots
//!
//! [`Mapper::hazard_map`] returns an `Arc<HazardMap>`: an immutable map of the window as it
//! was after the last update. Taking it is a reference-count increment. The mapper never
//! changes a published map; the water stage builds a new one and swaps the pointer
//! ([`MapSnapshots`], a mutex held only for that swap or for cloning the pointer). So a
//! planner thread holding a snapshot, or calling [`MapSnapshots::latest`] from another
//! thread, reads a consistent map while the mapper fuses the next frame.
//!
//! ## Determinism
//!
//! Cell statistics and evidence are exact integers (see [`crate::grid`]), the cues are
//! independent of thread count, so the map after any sequence of frames is bit-identical
//! for any number of rayon threads. `build_log` runs this same code, so an online run and an
//! offline build of a log give the same map.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::calib::{Calibration, CalibrationReport, Source, Sourced, StereoStated};
use crate::cues::prior::WaterPrior;
use crate::cues::{
    estimate_sensor_height, BeamModel, FrameCueConfig, FrameCues, FrameCuesReport, LidarCueConfig,
    LidarCueModel, ReflectivityConfig, StereoCueConfig,
};
use crate::error::{Error, Result};
use crate::grid::{Fusion, GridConfig, IngestStats, RangeNoise, RollingGrid, TileMap};
use crate::hazard::HazardMap;
use crate::optics::{Attenuation, LidarModelConfig, Sensitivity, SolidAngleForm};
use crate::sensor::Frame;
use crate::water::{HazardConfig, Vehicle, WaterConfig};

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
    /// with enough ground returns ([`estimate_sensor_height`]) and kept.
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
    /// [`Mapper`] runs it.
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
        camera: Option<&crate::geom::camera::CameraModel>,
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

/// Everything the [`Mapper`] needs. Loadable from TOML or JSON ([`MapperConfig::load`]);
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
    /// absent, [`Mapper::new`] compiles `labels`.
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
pub(crate) const CUE_NAMES: [&str; 4] = ["lidar", "reflectivity", "stereo", "mirror"];

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

/// Wall time of each stage of one update, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Moving the window with the vehicle and handing cells that leave it to the global map.
    pub recentre: f64,
    /// Lidar cues and the ingest of the (corrected) scan.
    pub lidar: f64,
    /// Stereo reflections and the ingest of the (corrected) cloud.
    pub stereo: f64,
    /// Image labels: classification, projection and votes (0 when none is configured).
    pub labels: f64,
    /// The window's hazard map, published as the snapshot.
    pub water: f64,
    /// The whole update.
    pub total: f64,
}

impl StageTimes {
    /// Stage names, in the order of [`StageTimes::values`].
    pub const NAMES: [&'static str; 6] =
        ["recentre", "lidar", "stereo", "labels", "water", "total"];

    /// The stage times, in the order of [`StageTimes::NAMES`].
    pub fn values(&self) -> [f64; 6] {
        [
            self.recentre,
            self.lidar,
            self.stereo,
            self.labels,
            self.water,
            self.total,
        ]
    }

    /// Adds another update's times, stage by stage.
    pub fn add(&mut self, o: &StageTimes) {
        self.recentre += o.recentre;
        self.lidar += o.lidar;
        self.stereo += o.stereo;
        self.labels += o.labels;
        self.water += o.water;
        self.total += o.total;
    }
}

/// What one frame contributed.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameReport {
    /// Stamp of the frame, seconds.
    pub stamp: f64,
    /// Frames fused so far, this one included.
    pub frame_index: u64,
    /// Raw ingest of a scan or cloud whose cue did not run.
    pub lidar_ingest: Option<IngestStats>,
    /// Raw ingest of a stereo cloud whose cue did not run.
    pub stereo_ingest: Option<IngestStats>,
    /// What the cues did (their ingest of corrected clouds included).
    pub cues: FrameCuesReport,
    /// The lidar height used by the cue model (given or estimated), once known.
    pub lidar_height_m: Option<f64>,
    /// The stereo cloud's range noise and where its c came from (a frame with a stereo
    /// cloud).
    pub stereo_noise: Option<(RangeNoise, Source)>,
    /// Every sensor value used so far, its source, and what the log measured
    /// ([`crate::calib`]).
    pub calibration: CalibrationReport,
    /// Cells of the published snapshot.
    pub snapshot_cells: usize,
    /// Snapshot cells called water.
    pub snapshot_water_cells: usize,
    /// What the image labels contributed (`None`: not configured).
    pub labels: Option<crate::project::FrameLabelsReport>,
    /// Wall time of each stage of the update.
    pub times_s: StageTimes,
    /// Lidar and stereo points beyond their sensor's `max_range_m`, dropped.
    pub beyond_max_range: [u64; 2],
    /// What the plausibility checks dropped from this frame, with the values.
    pub warnings: Vec<String>,
}

impl FrameReport {
    /// Points of the frame's lidar scan offered to the grid (raw or corrected).
    pub fn lidar_points(&self) -> Option<&IngestStats> {
        self.cues
            .lidar_ingest
            .as_ref()
            .or(self.lidar_ingest.as_ref())
    }

    /// Points of the frame's stereo cloud offered to the grid (raw or corrected).
    pub fn stereo_points(&self) -> Option<&IngestStats> {
        self.cues
            .stereo_ingest
            .as_ref()
            .or(self.stereo_ingest.as_ref())
    }
}

/// A handle on the mapper's latest published hazard map, for other threads.
#[derive(Debug, Clone)]
pub struct MapSnapshots {
    latest: Arc<Mutex<Arc<HazardMap>>>,
}

impl MapSnapshots {
    /// The latest published map (a pointer copy under a briefly held lock).
    pub fn latest(&self) -> Arc<HazardMap> {
        match self.latest.lock() {
            Ok(g) => Arc::clone(&g),
            // A panic elsewhere while the pointer was swapped cannot leave it half-written:
            // the stored Arc is still a whole map.
            Err(p) => Arc::clone(&p.into_inner()),
        }
    }

    /// Publishes `map`; returns the map it replaces.
    fn publish(&self, map: Arc<HazardMap>) -> Arc<HazardMap> {
        match self.latest.lock() {
            Ok(mut g) => std::mem::replace(&mut *g, map),
            Err(p) => std::mem::replace(&mut *p.into_inner(), map),
        }
    }
}

/// Where the online window's centre goes for a vehicle at `base_to_map`: `ahead` of the
/// window's side in front of it, along its heading projected on the ground (the vehicle
/// itself when the heading is vertical).
pub fn window_centre(grid: &GridConfig, base_to_map: &crate::geom::Pose) -> (f64, f64) {
    let c = base_to_map.translation.vector;
    let h = base_to_map.rotation * nalgebra::Vector3::x();
    let n = h.x.hypot(h.y);
    if n.is_nan() || n <= 1e-6 {
        return (c.x, c.y);
    }
    let d = grid.ahead * grid.size_cells as f64 * grid.resolution / n;
    (c.x + d * h.x, c.y + d * h.y)
}

/// Refuses a pose that is not a finite rotation and translation within the map's domain
/// ([`crate::grid::MAX_MAP_COORD_M`]), naming the frame and the values.
fn check_pose(stamp: f64, what: &str, pose: &crate::geom::Pose) -> Result<()> {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion().coords;
    let norm = q.norm();
    let bad = if !(t.iter().all(|v| v.is_finite())) {
        Some("its translation is not finite")
    } else if !(t.iter().all(|v| v.abs() <= crate::grid::MAX_MAP_COORD_M)) {
        Some("its translation is beyond the map's ±1e8 m")
    } else if !(q.iter().all(|v| v.is_finite()) && (norm - 1.0).abs() < 1e-3) {
        Some("its rotation is not a unit quaternion")
    } else {
        None
    };
    match bad {
        None => Ok(()),
        Some(why) => Err(Error::invalid(
            format!("frame at {stamp:.6} s"),
            format!(
                "{what} pose refused: {why} (translation {:?}, quaternion xyzw {:?})",
                [t.x, t.y, t.z],
                [q.x, q.y, q.z, q.w]
            ),
        )),
    }
}

/// Makes every finite point of `cloud` farther than `max` from its sensor a missing
/// return; `None` when there is none, else the gated cloud, how many and the farthest.
fn gate_range(
    cloud: &crate::geom::PointCloud,
    max: f64,
) -> Option<(crate::geom::PointCloud, u64, f64)> {
    let o = cloud.sensor_origin;
    let range = |p: &[f32; 3]| {
        let d = [p[0] as f64 - o.x, p[1] as f64 - o.y, p[2] as f64 - o.z];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    let beyond = |p: &[f32; 3]| p.iter().all(|v| v.is_finite()) && range(p) > max;
    if !cloud.xyz.iter().any(beyond) {
        return None;
    }
    let mut c = cloud.clone();
    let (mut n, mut far) = (0u64, 0.0f64);
    for p in c.xyz.iter_mut() {
        if beyond(p) {
            n += 1;
            far = far.max(range(p));
            *p = [f32::NAN; 3];
        }
    }
    Some((c, n, far))
}

/// The vehicle's and the clouds' poses are rotations within the map.
fn check_frame_poses(frame: &Frame) -> Result<()> {
    check_pose(frame.stamp, "vehicle (base_link → map)", &frame.base_to_map)?;
    for (what, c) in [("lidar", &frame.lidar), ("stereo", &frame.stereo)] {
        if let Some(c) = c {
            check_pose(frame.stamp, &format!("{what} cloud"), &c.frame_to_map)?;
        }
    }
    Ok(())
}

/// The noise a frame is fused with ([`Mapper::observe_noise`]).
#[derive(Default)]
struct FrameNoise {
    lidar: Option<RangeNoise>,
    stereo: Option<(Sourced, bool)>,
}

/// The online mapper. See the module documentation.
pub struct Mapper {
    cfg: MapperConfig,
    cues: FrameCues,
    labels: Option<crate::project::FrameLabels>,
    /// The lidar height the cue model was built for.
    lidar_height: Option<f64>,
    grid: Option<RollingGrid>,
    global: TileMap,
    snapshots: MapSnapshots,
    /// Whether `update` publishes the window's hazard map (stage 5).
    publish: bool,
    /// Buffers of the water stage, kept between frames.
    scratch: crate::hazard::WindowScratch,
    frames: u64,
    /// Whether the warning that the lidar cues cannot run on an unorganized scan was given.
    warned_unorganized: bool,
    /// The sensors' noise, measured from the frames and checked against what is stated.
    calib: Calibration,
}

impl Mapper {
    /// The frame with the points beyond each sensor's `max_range_m` made missing returns,
    /// and images whose pose is not plausible left without a pose; `None` when nothing
    /// changes. What was dropped goes into the report.
    fn gate_frame(&self, frame: &Frame, rep: &mut FrameReport) -> Option<Frame> {
        let mut out: Option<Frame> = None;
        let ranges = [
            self.cfg.lidar.as_ref().map(|l| l.max_range_m),
            self.cfg.stereo.as_ref().map(|s| s.max_range_m),
        ];
        for (k, (what, max)) in ["lidar", "stereo"].into_iter().zip(ranges).enumerate() {
            let cloud = if k == 0 { &frame.lidar } else { &frame.stereo };
            let (Some(cloud), Some(max)) = (cloud, max) else {
                continue;
            };
            if let Some((gated, n, far)) = gate_range(cloud, max) {
                rep.beyond_max_range[k] += n;
                rep.warnings.push(format!(
                    "{n} {what} points beyond {what}.max_range_m = {max} m dropped (farthest {far:.4e} m)"
                ));
                let f = out.get_or_insert_with(|| frame.clone());
                if k == 0 {
                    f.lidar = Some(gated);
                } else {
                    f.stereo = Some(gated);
                }
            }
        }
        let names = ["colour", "swir", "mwir"];
        for (k, img) in [&frame.image, &frame.swir, &frame.mwir]
            .into_iter()
            .enumerate()
        {
            let Some(pose) = img.as_ref().and_then(|i| i.frame_to_map.as_ref()) else {
                continue;
            };
            if let Err(e) = check_pose(frame.stamp, &format!("{} image", names[k]), pose) {
                rep.warnings
                    .push(format!("{e}; the image is used without a pose"));
                let f = out.get_or_insert_with(|| frame.clone());
                let slot = [&mut f.image, &mut f.swir, &mut f.mwir][k]
                    .as_mut()
                    .expect("the image is there");
                slot.frame_to_map = None;
            }
        }
        out
    }

    /// Measures the sensors' noise on `frame` (gated) until the calibration holds its
    /// values: the lidar's range noise, and the stereo cloud's c with whether it is known.
    fn observe_noise(&mut self, frame: &Frame) -> FrameNoise {
        self.calib.count_frame();
        let mut out = FrameNoise::default();
        if let (Some(l), Some(cloud)) = (&self.cfg.lidar, &frame.lidar) {
            // An unorganized scan has no scan lines to measure the noise along.
            if !(cloud.rows == 1 && cloud.cols > 1) {
                out.lidar = Some(self.calib.lidar_noise(cloud, l.noise, &l.reflectivity_cue));
            }
        }
        if let (Some(s), Some(cloud)) = (&self.cfg.stereo, &frame.stereo) {
            let camera = frame.image.as_ref().and_then(|i| i.camera.as_ref());
            let stated = s.stated(camera, cloud.cols, frame.stereo_baseline_m);
            let lidar = self.cfg.lidar.as_ref().and(frame.lidar.as_ref());
            out.stereo = Some(self.calib.stereo_noise(cloud, lidar, stated));
        }
        out
    }

    /// Measures the sensors' noise on `frame` without mapping it, as [`Mapper::update`]
    /// would: an offline build shows the log's first frames to the mapper this way until
    /// [`Mapper::calibration_settled`], so that every frame is fused with the noise held
    /// from then on, whichever piece of the log a mapper builds. On a vehicle, calling it
    /// on the first frames before mapping them does the same.
    pub fn calibrate(&mut self, frame: &Frame) -> Result<()> {
        check_frame_poses(frame)?;
        let mut rep = FrameReport::default();
        let gated = self.gate_frame(frame, &mut rep);
        self.observe_noise(gated.as_ref().unwrap_or(frame));
        Ok(())
    }

    /// Holds the calibration's values as they are ([`crate::calib::Calibration::hold`]).
    pub fn hold_calibration(&mut self) {
        self.calib.hold();
    }

    /// Whether the calibration holds its values ([`crate::calib::Calibration::is_settled`]).
    pub fn calibration_settled(&self) -> bool {
        self.calib.is_settled()
    }

    /// A mapper for `cfg` (validated). With a given lidar height the cue model is built
    /// here; with `height_m` absent, on the first scan that allows the estimate.
    pub fn new(cfg: MapperConfig) -> Result<Mapper> {
        cfg.validate()?;
        let models = match (&cfg.label_models, &cfg.labels) {
            (Some(m), _) => Some(m.clone()),
            (None, Some(l)) => Some(l.compile()?),
            (None, None) => None,
        };
        let mut fc = cfg.frame_cue_config(models.as_ref());
        let mut lidar_height = None;
        if let Some(l) = cfg.lidar.as_ref().filter(|l| l.cues) {
            if let Some(h) = l.height_m {
                fc.lidar = Some(l.cue_model(h)?);
                lidar_height = Some(h);
            }
        }
        let mut calib = Calibration::default();
        calib.set_assumed(cfg.assumed_datasheet_values());
        let global = TileMap::new(cfg.grid.resolution, cfg.grid.z_ref)?;
        let empty = Arc::new(HazardMap::new(cfg.grid.resolution, Vec::new()));
        let labels = models.map(crate::project::FrameLabels::new).transpose()?;
        Ok(Mapper {
            cfg,
            cues: FrameCues::new(fc),
            labels,
            lidar_height,
            grid: None,
            global,
            snapshots: MapSnapshots {
                latest: Arc::new(Mutex::new(empty)),
            },
            publish: true,
            scratch: Default::default(),
            frames: 0,
            warned_unorganized: false,
            calib,
        })
    }

    /// The mapper's configuration.
    pub fn config(&self) -> &MapperConfig {
        &self.cfg
    }

    /// Whether [`Mapper::update`] ends by publishing the window's hazard map (on by
    /// default: a vehicle reads it every frame). Off, the water stage is skipped and
    /// [`Mapper::hazard_map`] keeps the last map published: an offline build needs only
    /// the map of everything at the end ([`Mapper::finish_map`]), which does not depend on
    /// the snapshots, and saves the stage that costs most of a frame.
    pub fn set_publish(&mut self, on: bool) {
        self.publish = on;
    }

    /// Frames fused so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The lidar height the cue model uses, once known.
    pub fn lidar_height(&self) -> Option<f64> {
        self.lidar_height
    }

    /// Every sensor value used so far, where it came from, and what the log measured
    /// ([`crate::calib`]); it converges as frames come.
    pub fn calibration(&self) -> &CalibrationReport {
        self.calib.report()
    }

    /// The lidar cues' diagnostic interval (m of lookahead), once the cue model exists.
    pub fn diagnostic_interval(&self) -> Option<(f64, f64)> {
        self.cues.cfg.lidar.as_ref().and_then(|m| m.interval())
    }

    /// Bytes of every allocation that grows with the window's cells, by owner (from their
    /// capacities): the grid's layers and ingest accumulators, the water stage's buffers and
    /// the label stage's raster and tally. Divided by the window's cells: bytes per cell.
    pub fn window_heap_bytes(&self) -> Vec<(&'static str, usize)> {
        let (layers, ingest) = self.grid.as_ref().map_or((0, 0), |g| g.heap_bytes());
        vec![
            ("grid_layers", layers),
            ("ingest_scratch", ingest),
            ("water_scratch", self.scratch.heap_bytes()),
            ("labels", self.labels.as_ref().map_or(0, |l| l.heap_bytes())),
        ]
    }

    /// The water the lidar cue reads as a prior in the next frame ([`WaterPrior`]): `None`
    /// before the first refresh or without one ([`LidarCueConfig::prior_every_frames`]).
    pub fn water_prior(&self) -> Option<&WaterPrior> {
        self.cues.prior.as_ref()
    }

    /// The rolling window (after the first frame).
    pub fn grid(&self) -> Option<&RollingGrid> {
        self.grid.as_ref()
    }

    /// Fuses one frame. On error (a bad cloud in the frame) the frame's remaining stages
    /// are skipped; what was fused before the error stays.
    pub fn update(&mut self, frame: &Frame) -> Result<FrameReport> {
        let t0 = Instant::now();
        let mut rep = FrameReport {
            stamp: frame.stamp,
            ..FrameReport::default()
        };
        let mut times = StageTimes::default();

        // 0. plausibility: poses that are rotations within the map, points within range.
        check_frame_poses(frame)?;
        let gated = self.gate_frame(frame, &mut rep);
        let frame = gated.as_ref().unwrap_or(frame);
        let noise = self.observe_noise(frame);

        // 1. recentre
        let t = Instant::now();
        let (cx, cy) = window_centre(&self.cfg.grid, &frame.base_to_map);
        let grid = match self.grid.as_mut() {
            Some(g) => {
                g.recenter(cx, cy, &mut self.global)?;
                g
            }
            None => self
                .grid
                .insert(RollingGrid::new(self.cfg.grid.clone(), cx, cy)?),
        };
        times.recentre = t.elapsed().as_secs_f64();

        // 2. lidar
        let t = Instant::now();
        let mut surface = None;
        if let (Some(l), Some(cloud)) = (&self.cfg.lidar, &frame.lidar) {
            // An unorganized scan (one row of many points: a driver's flat cloud without a
            // `ring` field to organize it by) has no scan lines for the cues to walk, nor
            // for the noise to be measured along.
            let unorganized = cloud.rows == 1 && cloud.cols > 1;
            let noise = noise.lidar.unwrap_or_else(|| l.stated_noise());
            self.cues.cfg.lidar_noise = noise;
            if l.cues && self.cues.cfg.lidar.is_none() {
                if let Some(h) = estimate_sensor_height(cloud) {
                    // Centimetres: the estimate is a median of noisy returns.
                    let h = (h * 100.0).round() / 100.0;
                    if h > 0.0 {
                        self.cues.cfg.lidar = Some(l.cue_model(h)?);
                        self.lidar_height = Some(h);
                    }
                }
            }
            if let Some(m) = self.cues.cfg.lidar.as_mut() {
                m.set_range_noise(noise);
                if let Some(c) = self.calib.range_compensated() {
                    m.set_range_compensated(Some(c));
                }
            }
            if self.cues.cfg.lidar.is_some() && !unorganized {
                surface = self.cues.apply_lidar(frame, grid, &mut rep.cues)?;
            } else {
                if unorganized && l.cues && !self.warned_unorganized {
                    self.warned_unorganized = true;
                    rep.warnings.push(format!(
                        "lidar cues (no-return, bottom, specular) cannot run: the scan is \
                         unorganized ({} points in one row) and has no `ring` field to \
                         organize it into rings and azimuth columns; its points are fused \
                         without them",
                        cloud.cols
                    ));
                }
                rep.lidar_ingest = Some(grid.ingest(cloud, &noise)?);
            }
            let source = if l.height_m.is_some() {
                Source::Config
            } else {
                Source::Measured
            };
            self.calib
                .set_lidar_height(self.lidar_height.map(|value| Sourced { value, source }));
        }
        rep.lidar_height_m = self.lidar_height;
        times.lidar = t.elapsed().as_secs_f64();

        // 3. stereo: its noise measured (against this frame's lidar scan when there is
        // one), then the reflection cue, which waits while the noise is unknown.
        let t = Instant::now();
        if let (Some(s), Some(cloud), Some((c, known))) =
            (&self.cfg.stereo, &frame.stereo, noise.stereo)
        {
            let noise = s.noise_of(c.value);
            rep.stereo_noise = Some((noise, c.source));
            if let Some(c) = self.cues.cfg.stereo.as_mut() {
                c.noise = noise;
            }
            if s.reflections && known {
                // What stereo says of the surface joins what the lidar says.
                if let Some(st) = self.cues.apply_stereo(frame, grid, &mut rep.cues)? {
                    surface = Some(match surface {
                        Some(mut s) => {
                            s.stereo = st.stereo;
                            s
                        }
                        None => st,
                    });
                }
            } else {
                rep.stereo_ingest = Some(grid.ingest(cloud, &noise)?);
            }
        }
        rep.calibration = self.calib.report().clone();
        times.stereo = t.elapsed().as_secs_f64();

        // 4. labels: colour, SWIR and MWIR classification projected onto the map as votes.
        let t = Instant::now();
        if let Some(fl) = self.labels.as_mut() {
            rep.labels = Some(fl.apply(frame, grid, surface.as_ref())?);
        }
        times.labels = t.elapsed().as_secs_f64();

        // 5. water: the window's hazard map, published.
        if self.publish {
            let t = Instant::now();
            let map = self.publish_now()?;
            rep.snapshot_cells = map.cells.len();
            rep.snapshot_water_cells = map.class_counts()[crate::hazard::Class::Water as usize];
            times.water = t.elapsed().as_secs_f64();
        }

        self.frames += 1;
        // 6. the prior of the frames that follow: the window's water bodies, every
        // `prior_every_frames` frames (the map just published, or the same map built now).
        let cue = self.cfg.lidar.as_ref().map(|l| l.cue);
        if let Some(cue) = cue.filter(|c| c.prior_every_frames > 0) {
            if self.frames % u64::from(cue.prior_every_frames) == 0 {
                let t = Instant::now();
                let map = if self.publish {
                    self.snapshots.latest()
                } else {
                    Arc::new(self.window_map()?)
                };
                self.cues.prior = Some(map.water_prior(cue.prior_reach_m));
                times.water += t.elapsed().as_secs_f64();
            }
        }
        rep.frame_index = self.frames;
        times.total = t0.elapsed().as_secs_f64();
        rep.times_s = times;
        Ok(rep)
    }

    /// Builds the window's hazard map now and publishes it (the water stage of
    /// [`Mapper::update`]): for a mapper that does not publish every frame
    /// ([`Mapper::set_publish`]) but wants a map every few frames.
    pub fn publish_now(&mut self) -> Result<Arc<HazardMap>> {
        let map = Arc::new(self.window_map()?);
        // The map this one replaces is storage for the next, once no other thread holds
        // it (a published map is never changed).
        if let Ok(old) = Arc::try_unwrap(self.snapshots.publish(map.clone())) {
            self.scratch.recycle(old);
        }
        Ok(map)
    }

    /// The hazard map of the current window, its cells in the order a tile map holds them
    /// (a snapshot lists its cells as the map of the same cells built offline does). Water
    /// bodies keep the ids of the previous snapshot's bodies they grew from.
    fn window_map(&mut self) -> Result<HazardMap> {
        let previous = self.snapshots.latest();
        let cfg = self.cfg.hazard_config();
        match &self.grid {
            Some(g) => HazardMap::from_window_after(g, &cfg, &previous.bodies, &mut self.scratch),
            None => {
                let geometry = TileMap::new(self.cfg.grid.resolution, self.cfg.grid.z_ref)?;
                HazardMap::from_cells_after(&geometry, Vec::new(), &cfg, &previous.bodies)
            }
        }
    }

    /// The hazard map of a tile map under this mapper's fusion, water and vehicle settings.
    pub fn hazard_map_of(&self, tiles: &TileMap) -> Result<HazardMap> {
        HazardMap::from_tiles(tiles, &self.cfg.hazard_config())
    }

    /// The hazard map of the window after the last update: an immutable snapshot, cheap to
    /// take (a pointer copy), never changed by later updates.
    pub fn hazard_map(&self) -> Arc<HazardMap> {
        self.snapshots.latest()
    }

    /// A handle another thread can read the latest snapshot through while this mapper
    /// keeps updating.
    pub fn snapshots(&self) -> MapSnapshots {
        self.snapshots.clone()
    }

    /// Hands over the cells that have left the window so far, and forgets them: the mapper
    /// only ever adds to them (a cell that comes back into the window starts empty there
    /// and is added again when it leaves), so they are final, and what a mapper holds
    /// stays bounded by the window and the area driven since the last take. The merge of
    /// every take and [`Mapper::finish`] is, byte for byte, what `finish` alone would
    /// have given: a long drive can hand its map on in pieces while the vehicle drives,
    /// and a long log be built in exact time chunks, one after another.
    pub fn take_left_tiles(&mut self) -> TileMap {
        self.global.take()
    }

    /// Everything the mapper saw: the cells that left the window and the window itself.
    pub fn finish(mut self) -> TileMap {
        if let Some(g) = self.grid.as_mut() {
            g.flush(&mut self.global);
        }
        self.global
    }

    /// [`Mapper::finish`] and the hazard map of all of it.
    pub fn finish_map(self) -> Result<(TileMap, HazardMap)> {
        let cfg = self.cfg.hazard_config();
        let tiles = self.finish();
        let map = HazardMap::from_tiles(&tiles, &cfg)?;
        Ok((tiles, map))
    }
}

#[cfg(test)]
mod tests;
