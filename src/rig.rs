//! Rig files: a vehicle's sensors as their datasheets and mounts describe them
//! (`maps/rigs/*.toml`). `tarn build --rig` takes the values a log cannot carry from one
//! (the lidar's wavelength, sensitivity, aperture and range noise; the stereo pair's
//! disparity noise, minimum disparity and baseline; the colour camera's encoding); the
//! simulator renders a scene's logs with one.
//!
//! Exports: [`RigSpec`] and its parts ([`LidarSpec`] with its [`IntensityKind`],
//! [`StereoSpec`], [`CameraSpec`], [`GpsSpec`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{all_finite, non_negative, positive, unit, Error, Result};
use crate::grid::RangeNoise;
use crate::mapper::{LidarConfig, MapperConfig, StereoConfig};

/// The vehicle's sensors, as their datasheets and mounts describe them: nothing in a rig
/// belongs to a scene. A rig file (`maps/rigs/*.toml`) holds one; a scene names it
/// (`rig = "rigs/NAME.toml"`, relative to the scene file) or carries one inline.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct RigSpec {
    /// A name for reports (a rig file's stem when empty).
    #[serde(default)]
    pub name: String,
    /// A rig file a scene names but that is not read yet (a simulator scene's, which it resolves).
    #[serde(skip)]
    pub file: Option<String>,
    /// What the rig is, for people.
    #[serde(default)]
    pub description: String,
    /// The lidar (`/lidar/points`).
    pub lidar: Option<LidarSpec>,
    /// The stereo pair (`/stereo/points`, its left camera `/camera/image`).
    pub stereo: Option<StereoSpec>,
    /// A colour camera without a stereo partner (`/camera/image`).
    pub camera: Option<CameraSpec>,
    /// A short-wave infrared camera (`/swir/image`).
    pub swir: Option<CameraSpec>,
    /// A mid-wave infrared (thermal) camera (`/mwir/image`).
    pub mwir: Option<CameraSpec>,
    /// A GNSS receiver (`/gps/fix`).
    pub gps: Option<GpsSpec>,
}

/// A GNSS receiver: a `NavSatFix` at every pose, at the latitude given and at the longitude
/// where the scene's local solar time (`sky.time_of_day`) falls at the log's first stamp,
/// so that a reader finds the scene's hour from the stamps and the fix.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GpsSpec {
    /// Degrees north.
    #[serde(default = "d_latitude")]
    pub latitude_deg: f64,
}

fn d_latitude() -> f64 {
    34.2
}

/// What a lidar writes per return besides x, y, z.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum IntensityKind {
    /// Nothing.
    #[default]
    None,
    /// `intensity`: the raw return, proportional to the received power, which falls with
    /// range² and with the surface's backscatter at its incidence.
    Raw,
    /// `reflectivity`: range-corrected, not incidence-corrected, 0–255 (Ouster's
    /// convention: a Lambertian target of albedo ρ seen head-on reads 100·ρ).
    Reflectivity,
}

fn d_az() -> [f64; 2] {
    [-180.0, 180.0]
}
fn d_wavelength() -> f64 {
    905.0
}
fn d_aperture() -> f64 {
    0.0254
}
fn d_ref_albedo() -> f64 {
    0.3
}
fn d_max_range() -> f64 {
    120.0
}
fn d_range_noise() -> f64 {
    0.01
}

/// A lidar: `rings` beams between `elevation_deg` (low, high) fired at `columns` azimuths
/// over `azimuth_deg` (a spinning lidar), or one column (a 2-D vertical scanner).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LidarSpec {
    /// In base_link (m) and roll, pitch, yaw (degrees).
    pub position: [f64; 3],
    /// Roll, pitch, yaw of the mount, degrees.
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    /// Beams (rings), spread evenly over `elevation_deg`.
    pub rings: usize,
    /// Lowest and highest beam elevation, degrees.
    pub elevation_deg: [f64; 2],
    /// Azimuths fired per scan.
    pub columns: usize,
    /// Azimuth span of a scan, degrees [from, to].
    #[serde(default = "d_az")]
    pub azimuth_deg: [f64; 2],
    /// Laser wavelength, nm.
    #[serde(default = "d_wavelength")]
    pub wavelength_nm: f64,
    /// Receiver aperture diameter, m.
    #[serde(default = "d_aperture")]
    pub aperture_m: f64,
    /// Sensitivity: lookahead (m) at which level ground of `reference_albedo`, seen from
    /// this lidar's mounting height, stops returning.
    pub dry_limit_m: f64,
    /// The albedo `dry_limit_m` is stated for.
    #[serde(default = "d_ref_albedo")]
    pub reference_albedo: f64,
    /// Largest range measured, m.
    #[serde(default = "d_max_range")]
    pub max_range_m: f64,
    /// Standard deviation of the range noise (m).
    #[serde(default = "d_range_noise")]
    pub range_noise_m: f64,
    /// The per-return channel the lidar writes.
    #[serde(default)]
    pub intensity: IntensityKind,
}

fn d_bin() -> usize {
    2
}
fn d_disp_noise() -> f64 {
    0.2
}
fn d_img_noise() -> f64 {
    2.0
}
fn d_min_disp() -> f64 {
    1.0
}

/// The stereo pair: the left camera gives `/camera/image`, the pair gives `/stereo/points`
/// (`bin` × `bin` binned).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StereoSpec {
    /// Left camera body (x forward, y left, z up) in base_link; roll, pitch, yaw degrees.
    pub position: [f64; 3],
    /// Roll, pitch, yaw of the mount, degrees.
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    /// Image columns, pixels.
    pub width: usize,
    /// Image rows, pixels.
    pub height: usize,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Distance between the two cameras, m.
    pub baseline_m: f64,
    /// Standard deviation of the disparity (pixels of the binned disparity image, whose
    /// focal length is f / `bin`).
    #[serde(default = "d_disp_noise")]
    pub disparity_noise_px: f64,
    /// Matches whose (noisy) disparity falls below this are lost (binned pixels).
    #[serde(default = "d_min_disp")]
    pub min_disparity_px: f64,
    /// Binning of the disparity image (and the cloud) against the camera image.
    #[serde(default = "d_bin")]
    pub bin: usize,
    /// The left camera's lens distortion, plumb_bob [k1, k2, p1, p2, k3]: the image and its
    /// CameraInfo carry it; the cloud is computed on the rectified (pinhole) grid.
    #[serde(default)]
    pub distortion: Option<[f64; 5]>,
    /// How the colour image encodes radiance.
    #[serde(default = "d_linear")]
    pub encoding: crate::project::Encoding,
    /// Largest range measured, m.
    #[serde(default = "d_max_range")]
    pub max_range_m: f64,
    /// Standard deviation of the pixel noise (grey levels).
    #[serde(default = "d_img_noise")]
    pub image_noise: f64,
}

/// A single camera (SWIR or MWIR).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Mount position in base_link, m.
    pub position: [f64; 3],
    /// Roll, pitch, yaw of the mount, degrees.
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    /// Image columns, pixels.
    pub width: usize,
    /// Image rows, pixels.
    pub height: usize,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Standard deviation of the pixel noise (grey levels; centikelvin for MWIR).
    #[serde(default = "d_img_noise")]
    pub image_noise: f64,
    /// Lens distortion, plumb_bob [k1, k2, p1, p2, k3] (the CameraInfo carries it).
    #[serde(default)]
    pub distortion: Option<[f64; 5]>,
    /// How a colour image encodes radiance (SWIR and MWIR images are linear).
    #[serde(default = "d_linear")]
    pub encoding: crate::project::Encoding,
}

fn d_linear() -> crate::project::Encoding {
    crate::project::Encoding::Linear
}

impl RigSpec {
    /// The default [`MapperConfig`] with this rig's datasheet values ([`Self::apply_to`]).
    /// It takes the rig alone, so nothing of a scene (water clarity, levels, depths) can
    /// reach the mapper; what a log holds (focal lengths, binning, mounts, the lidar's
    /// height) the mapper reads from the log.
    pub fn mapper_config(&self) -> MapperConfig {
        let mut cfg = MapperConfig::default();
        self.apply_to(&mut cfg);
        cfg
    }

    /// Puts the rig's datasheet values into `cfg`, keeping its cue choices and everything
    /// else: the lidar's wavelength, sensitivity (dry limit and its reference albedo),
    /// aperture and range noise; the stereo pair's disparity noise, minimum disparity and
    /// baseline; the colour camera's encoding. A sensor the rig lacks is turned off.
    pub fn apply_to(&self, cfg: &mut MapperConfig) {
        cfg.lidar = match (&self.lidar, cfg.lidar.take()) {
            (Some(l), Some(c)) => Some(LidarConfig {
                wavelength_nm: l.wavelength_nm,
                dry_limit_m: l.dry_limit_m,
                albedo: l.reference_albedo,
                aperture_diameter_m: l.aperture_m,
                // The datasheet's range and a margin for range noise: nothing real lies
                // beyond.
                max_range_m: l.max_range_m * 1.1,
                noise: Some(RangeNoise {
                    sigma0: l.range_noise_m.max(0.01),
                    ..RangeNoise::LIDAR
                }),
                ..c
            }),
            _ => None,
        };
        cfg.stereo = match (&self.stereo, cfg.stereo.take()) {
            (Some(s), Some(c)) => Some(StereoConfig {
                disparity_noise_px: Some(s.disparity_noise_px),
                min_disparity_px: s.min_disparity_px,
                baseline_m: Some(s.baseline_m),
                max_range_m: s.max_range_m * 1.1,
                ..c
            }),
            _ => None,
        };
        if let (Some(l), Some(e)) = (cfg.labels.as_mut(), self.colour_encoding()) {
            l.encoding = e;
        }
        if let (Some(l), Some(c)) = (cfg.labels.as_mut(), self.swir.as_ref()) {
            l.swir_noise_sd = c.image_noise as f32;
        }
    }

    /// The encoding of the colour camera (the stereo pair's left one, or the camera).
    pub fn colour_encoding(&self) -> Option<crate::project::Encoding> {
        self.stereo
            .as_ref()
            .map(|s| s.encoding)
            .or(self.camera.as_ref().map(|c| c.encoding))
    }

    /// Reads and validates a rig file; its name defaults to the file's stem.
    pub fn load(path: &Path) -> Result<RigSpec> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut rig: RigSpec = toml::from_str(&text).map_err(|e| {
            let loc = e
                .span()
                .map(|s| {
                    format!(
                        "line {}",
                        text[..s.start.min(text.len())].lines().count().max(1)
                    )
                })
                .unwrap_or_else(|| "rig".into());
            Error::format(path, loc, e.message().to_string())
        })?;
        if rig.name.is_empty() {
            rig.name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
        }
        rig.validate().map_err(|e| match e {
            Error::Invalid { what, message } => Error::format(path, what, message),
            e => e,
        })?;
        Ok(rig)
    }

    /// Checks every value; the error names the key (`rig.lidar.rings`).
    pub fn validate(&self) -> Result<()> {
        let r = self;
        if let Some(f) = &r.file {
            return Err(Error::invalid(
                "rig",
                format!(
                    "names the rig file {f:?}, which was not read: load the scene from its file"
                ),
            ));
        }
        if r.lidar.is_none()
            && r.stereo.is_none()
            && r.camera.is_none()
            && r.swir.is_none()
            && r.mwir.is_none()
        {
            return Err(Error::invalid(
                "rig",
                "configures no sensor (lidar, stereo, camera, swir, mwir)",
            ));
        }
        if let Some(l) = &r.lidar {
            validate_lidar(l)?;
        }
        if let Some(s) = &r.stereo {
            validate_stereo(s)?;
        }
        if r.stereo.is_some() && r.camera.is_some() {
            return Err(Error::invalid(
                "rig.camera",
                "the stereo pair's left camera is the colour camera: give one of stereo, camera",
            ));
        }
        if let Some(g) = &r.gps {
            if g.latitude_deg.is_nan() || g.latitude_deg.abs() > 90.0 {
                return Err(Error::invalid(
                    "rig.gps.latitude_deg",
                    format!("{} (must be within ±90°)", g.latitude_deg),
                ));
            }
        }
        for (name, c) in [("camera", &r.camera), ("swir", &r.swir), ("mwir", &r.mwir)] {
            if let Some(c) = c {
                let w = |k: &str| format!("rig.{name}.{k}");
                validate_camera(
                    &w,
                    &c.position,
                    &c.rpy_deg,
                    c.width,
                    c.height,
                    c.hfov_deg,
                    c.image_noise,
                    &c.distortion,
                )?;
            }
        }
        Ok(())
    }
}

/// The lidar's mount, scan pattern and optics.
fn validate_lidar(l: &LidarSpec) -> Result<()> {
    let w = |k: &str| format!("rig.lidar.{k}");
    all_finite(&w("position"), &l.position)?;
    all_finite(&w("rpy_deg"), &l.rpy_deg)?;
    if l.rings == 0 || l.rings > 512 {
        return Err(Error::invalid(
            w("rings"),
            format!("{} must be in 1..=512", l.rings),
        ));
    }
    if l.columns == 0 || l.columns > 8192 {
        return Err(Error::invalid(
            w("columns"),
            format!("{} must be in 1..=8192", l.columns),
        ));
    }
    let [lo, hi] = l.elevation_deg;
    if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -90.0 && hi <= 90.0) {
        return Err(Error::invalid(
            w("elevation_deg"),
            format!("{:?} must be [low, high] within ±90", l.elevation_deg),
        ));
    }
    let [a0, a1] = l.azimuth_deg;
    if !(a0.is_finite() && a1.is_finite() && a0 <= a1 && a1 - a0 <= 360.0) {
        return Err(Error::invalid(
            w("azimuth_deg"),
            format!("{:?} must be [from, to] spanning ≤ 360", l.azimuth_deg),
        ));
    }
    positive(&w("wavelength_nm"), l.wavelength_nm)?;
    positive(&w("aperture_m"), l.aperture_m)?;
    positive(&w("dry_limit_m"), l.dry_limit_m)?;
    unit(&w("reference_albedo"), l.reference_albedo)?;
    positive(&w("reference_albedo"), l.reference_albedo)?;
    positive(&w("max_range_m"), l.max_range_m)?;
    non_negative(&w("range_noise_m"), l.range_noise_m)?;
    if l.position[2] <= 0.0 {
        return Err(Error::invalid(
            w("position"),
            "z must be above the ground (> 0)",
        ));
    }
    Ok(())
}

/// The stereo pair: its left camera, baseline, disparities and binning.
fn validate_stereo(s: &StereoSpec) -> Result<()> {
    let w = |k: &str| format!("rig.stereo.{k}");
    validate_camera(
        &w,
        &s.position,
        &s.rpy_deg,
        s.width,
        s.height,
        s.hfov_deg,
        s.image_noise,
        &s.distortion,
    )?;
    positive(&w("baseline_m"), s.baseline_m)?;
    non_negative(&w("disparity_noise_px"), s.disparity_noise_px)?;
    positive(&w("min_disparity_px"), s.min_disparity_px)?;
    if s.bin == 0 || s.width % s.bin != 0 || s.height % s.bin != 0 {
        return Err(Error::invalid(
            w("bin"),
            format!(
                "{} must be ≥ 1 and divide {} × {}",
                s.bin, s.width, s.height
            ),
        ));
    }
    positive(&w("max_range_m"), s.max_range_m)?;
    Ok(())
}

/// A camera's mount, lens, image size, field of view and noise; `w` names a key of it.
#[allow(clippy::too_many_arguments)]
fn validate_camera(
    w: &dyn Fn(&str) -> String,
    pos: &[f64; 3],
    rpy: &[f64; 3],
    width: usize,
    height: usize,
    hfov: f64,
    noise: f64,
    distortion: &Option<[f64; 5]>,
) -> Result<()> {
    if let Some(d) = distortion {
        all_finite(&w("distortion"), d)?;
        if d.iter().any(|k| k.abs() > 1.0) {
            return Err(Error::invalid(
                w("distortion"),
                format!("{d:?}: plumb_bob coefficients beyond ±1 are not a lens"),
            ));
        }
    }
    all_finite(&w("position"), pos)?;
    all_finite(&w("rpy_deg"), rpy)?;
    if width == 0 || height == 0 || width > 4096 || height > 4096 {
        return Err(Error::invalid(
            w("width"),
            format!("{width} × {height} must be within 1..=4096"),
        ));
    }
    if !(hfov > 1.0 && hfov < 170.0) {
        return Err(Error::invalid(
            w("hfov_deg"),
            format!("{hfov} must be in (1, 170)"),
        ));
    }
    non_negative(&w("image_noise"), noise)
}
