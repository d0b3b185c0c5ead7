//! The scene format: TOML, every table with `deny_unknown_fields`, validated after parsing
//! so that a bad value is reported with its key (`water[1].level`) and the reason.
//! `maps/README.md` documents every key.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::hazard::Class;

fn d_zero() -> f64 {
    0.0
}
fn d_noise_scale() -> f64 {
    4.0
}
fn d_noon() -> f64 {
    12.0
}
/// The mapper's default cell size, so that each cell of a map at that size is scored
/// against the truth at its own centre.
fn d_truth_res() -> f64 {
    crate::grid::GridConfig::default().resolution
}

/// A whole scene.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Seeds terrain noise, rock shapes, ripples and sensor noise.
    #[serde(default)]
    pub seed: u64,
    /// Cell size of the ground-truth raster (m).
    #[serde(default = "d_truth_res")]
    pub truth_resolution: f64,
    /// Water shallower than this is a fordable hazard (class 1) in the truth (m).
    #[serde(default = "d_fording")]
    pub fording_depth: f64,
    pub terrain: TerrainSpec,
    #[serde(default)]
    pub water: Vec<WaterSpec>,
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
    #[serde(default)]
    pub patches: Vec<PatchSpec>,
    /// Extra or overriding materials (the built-in ones are in [`builtin_materials`]).
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    #[serde(default)]
    pub sky: SkySpec,
    pub trajectory: TrajectorySpec,
    /// The sensors: a rig file named relative to the scene file (`rig = "rigs/small.toml"`),
    /// or an inline table. [`Scene::load_with_rig`] renders the scene with another rig.
    #[serde(deserialize_with = "rig_or_file")]
    pub rig: RigSpec,
}

/// `rig = "FILE"` or `[rig]` with its tables: a file name is kept in [`RigSpec::file`] for
/// [`Scene::load`] to read.
fn rig_or_file<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<RigSpec, D::Error> {
    struct V;
    impl<'de> serde::de::Visitor<'de> for V {
        type Value = RigSpec;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a rig file name or a rig table")
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<RigSpec, E> {
            Ok(RigSpec {
                file: Some(v.to_string()),
                ..RigSpec::default()
            })
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(
            self,
            map: A,
        ) -> std::result::Result<RigSpec, A::Error> {
            RigSpec::deserialize(serde::de::value::MapAccessDeserializer::new(map))
        }
    }
    d.deserialize_any(V)
}

fn d_fording() -> f64 {
    0.3
}

/// The heightfield: a tilted plane plus value noise plus features.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TerrainSpec {
    /// Lower-left corner (x, y) of the terrain (m, map frame).
    pub origin: [f64; 2],
    /// Extent along x and y (m).
    pub size: [f64; 2],
    /// Heightfield vertex spacing (m).
    pub resolution: f64,
    #[serde(default = "d_zero")]
    pub elevation: f64,
    /// dz/dx, dz/dy of the base plane.
    #[serde(default)]
    pub slope: [f64; 2],
    /// Amplitude of the value noise (m).
    #[serde(default = "d_zero")]
    pub roughness: f64,
    /// Wavelength of the coarsest noise octave (m).
    #[serde(default = "d_noise_scale")]
    pub roughness_scale: f64,
    pub material: String,
    #[serde(default)]
    pub features: Vec<FeatureSpec>,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FeatureKind {
    Depression,
    Mound,
    Ditch,
    /// A raised band (`from`, `to`, `width`, `height`): a kerb beside pavement.
    Curb,
}

/// A depression or mound (elliptic, `centre`, `radius`, `depth`/`height`, flat for
/// `flat` × radius then a cosine rim) or a ditch (`from`, `to`, `width`, `depth`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FeatureSpec {
    pub kind: FeatureKind,
    pub centre: Option<[f64; 2]>,
    pub radius: Option<[f64; 2]>,
    pub depth: Option<f64>,
    pub height: Option<f64>,
    /// Fraction of the radius that is flat (bottom or top), 0..1.
    #[serde(default)]
    pub flat: f64,
    pub from: Option<[f64; 2]>,
    pub to: Option<[f64; 2]>,
    pub width: Option<f64>,
    /// Surface material inside the feature (default: the terrain's).
    pub material: Option<String>,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum WaterKind {
    /// A level surface at `level` over the terrain below it, within `radius` of `centre`.
    Level,
    /// A plane sloping from `from` (x, y, z) to `to` along a band `width` wide.
    Stream,
}

/// A water body.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WaterSpec {
    pub kind: WaterKind,
    pub level: Option<f64>,
    pub centre: Option<[f64; 2]>,
    pub radius: Option<f64>,
    pub from: Option<[f64; 3]>,
    pub to: Option<[f64; 3]>,
    pub width: Option<f64>,
    /// RMS slope of the surface ripples (rad); 0 is a still mirror.
    #[serde(default)]
    pub ripple: f64,
    /// Total attenuation of the water column at the lidar's wavelength (1/m): pure water's
    /// absorption there (the default, and the least any water has: 5.2 /m at 865 nm,
    /// 7.1 /m at 905 nm) plus what dissolved and suspended matter add.
    pub attenuation: Option<f64>,
    /// The water's own (body) colour, RGB 0..1.
    #[serde(default = "d_water_colour")]
    pub colour: [f64; 3],
    /// Mean surface temperature (K) and the half amplitude of its daily swing.
    #[serde(default = "d_water_temp")]
    pub temperature: f64,
    #[serde(default = "d_water_swing")]
    pub temperature_swing: f64,
}

fn d_water_colour() -> [f64; 3] {
    [0.05, 0.12, 0.12]
}
fn d_water_temp() -> f64 {
    286.0
}
fn d_water_swing() -> f64 {
    1.0
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ObjectKind {
    /// Trunk and conical crown: `height`, `radius` (crown).
    Tree,
    /// A box `size` = [x, y, z] turned by `yaw_deg`.
    Building,
    /// A faceted ellipsoid with semi-axes `size`, half buried.
    Rock,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    pub kind: ObjectKind,
    pub position: [f64; 2],
    pub height: Option<f64>,
    pub radius: Option<f64>,
    pub size: Option<[f64; 3]>,
    #[serde(default)]
    pub yaw_deg: f64,
    pub material: Option<String>,
}

/// A disc of another surface material (snow, ice, wet soil, pale rock).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PatchSpec {
    pub centre: [f64; 2],
    pub radius: f64,
    pub material: String,
}

/// What a surface looks like to each sensor.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Visible albedo, RGB 0..1.
    pub rgb: [f64; 3],
    /// Reflectance around 1.5 µm, 0..1.
    pub swir: f64,
    /// Lambertian albedo at the lidar's wavelength, 0..1 (> 0).
    pub lidar: f64,
    /// Stereo matchability 0..1: the chance a pixel of it finds a match.
    pub texture: f64,
    /// Mean temperature (K) and the half amplitude of its daily swing (K).
    pub temperature: f64,
    pub temperature_swing: f64,
    /// Truth class: ground, vegetation, obstacle or snow_ice.
    pub class: MaterialClass,
    /// Lidar backscatter falls as cosᵐ of the incidence angle: 1 for a Lambertian surface
    /// (grass, soil), more for smooth ones (pavement), which stop returning at grazing
    /// incidence long before rough ground does.
    #[serde(default = "d_one")]
    pub backscatter_exponent: f64,
}

fn d_one() -> f64 {
    1.0
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MaterialClass {
    Ground,
    Vegetation,
    Obstacle,
    SnowIce,
}

impl MaterialClass {
    pub fn class(self) -> Class {
        match self {
            MaterialClass::Ground => Class::Ground,
            MaterialClass::Vegetation => Class::Vegetation,
            MaterialClass::Obstacle => Class::Obstacle,
            MaterialClass::SnowIce => Class::SnowIce,
        }
    }
}

/// The built-in materials (a scene's `[materials.NAME]` adds or overrides).
pub fn builtin_materials() -> BTreeMap<String, MaterialSpec> {
    use MaterialClass::*;
    let m = |rgb: [f64; 3], swir, lidar, texture, t, swing, class| MaterialSpec {
        rgb,
        swir,
        lidar,
        texture,
        temperature: t,
        temperature_swing: swing,
        class,
        backscatter_exponent: 1.0,
    };
    // Smooth pavement: specular enough that its backscatter falls as cos^m with m > 1.
    let smooth = |mut s: MaterialSpec, m: f64| {
        s.backscatter_exponent = m;
        s
    };
    [
        (
            "grass",
            m([0.18, 0.30, 0.10], 0.30, 0.35, 0.95, 286.0, 6.0, Ground),
        ),
        (
            "soil",
            m([0.30, 0.24, 0.17], 0.35, 0.30, 0.95, 287.0, 8.0, Ground),
        ),
        (
            "mud",
            m([0.20, 0.16, 0.12], 0.20, 0.20, 0.85, 287.0, 7.0, Ground),
        ),
        (
            "wet_soil",
            m([0.10, 0.08, 0.06], 0.12, 0.12, 0.80, 285.0, 5.0, Ground),
        ),
        (
            "gravel",
            m([0.38, 0.36, 0.33], 0.40, 0.35, 0.95, 288.0, 9.0, Ground),
        ),
        (
            "pale_rock",
            m([0.75, 0.74, 0.70], 0.60, 0.60, 0.60, 288.0, 9.0, Ground),
        ),
        (
            "rock",
            m([0.40, 0.38, 0.36], 0.40, 0.40, 0.90, 288.0, 8.0, Obstacle),
        ),
        (
            "snow",
            m([0.90, 0.92, 0.95], 0.15, 0.80, 0.40, 271.0, 2.0, SnowIce),
        ),
        (
            "ice",
            m([0.55, 0.62, 0.68], 0.05, 0.30, 0.30, 271.0, 1.0, SnowIce),
        ),
        (
            "bark",
            m([0.25, 0.18, 0.12], 0.35, 0.30, 0.95, 285.0, 5.0, Vegetation),
        ),
        (
            "foliage",
            m([0.10, 0.25, 0.08], 0.25, 0.40, 0.90, 284.0, 5.0, Vegetation),
        ),
        (
            "concrete",
            m([0.55, 0.53, 0.50], 0.45, 0.45, 0.90, 289.0, 7.0, Obstacle),
        ),
        (
            "pavement",
            smooth(
                m([0.50, 0.49, 0.46], 0.42, 0.40, 0.85, 290.0, 9.0, Ground),
                2.5,
            ),
        ),
        (
            "asphalt",
            smooth(
                m([0.16, 0.16, 0.16], 0.12, 0.15, 0.80, 292.0, 12.0, Ground),
                2.0,
            ),
        ),
        (
            "fresh_asphalt",
            smooth(
                m([0.05, 0.05, 0.055], 0.05, 0.07, 0.70, 294.0, 14.0, Ground),
                2.0,
            ),
        ),
        (
            "pale_slab",
            smooth(
                m([0.66, 0.72, 0.80], 0.45, 0.50, 0.35, 289.0, 8.0, Ground),
                3.0,
            ),
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum SkyKind {
    #[default]
    Clear,
    Overcast,
    PartlyCloudy,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SkySpec {
    #[serde(default)]
    pub kind: SkyKind,
    /// Local solar time, hours 0..24 (the sun is up from 6 to 18, due south at 12).
    #[serde(default = "d_noon")]
    pub time_of_day: f64,
}

impl Default for SkySpec {
    fn default() -> Self {
        SkySpec {
            kind: SkyKind::Clear,
            time_of_day: 12.0,
        }
    }
}

fn d_rate() -> f64 {
    10.0
}
fn d_start() -> f64 {
    100.0
}

/// The vehicle drives along `waypoints` (x, y) at `speed`, one frame every 1/`rate_hz` s.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrajectorySpec {
    pub waypoints: Vec<[f64; 2]>,
    pub speed: f64,
    #[serde(default = "d_rate")]
    pub rate_hz: f64,
    /// At most this many frames (default: until the last waypoint).
    pub frames: Option<usize>,
    /// Stamp of the first frame (s).
    #[serde(default = "d_start")]
    pub start_time: f64,
}

/// The vehicle's sensors, as their datasheets and mounts describe them: nothing in a rig
/// belongs to a scene. A rig file (`maps/rigs/*.toml`) holds one; a scene names it
/// (`rig = "rigs/NAME.toml"`, relative to the scene file) or carries one inline.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct RigSpec {
    /// A name for reports (a rig file's stem when empty).
    #[serde(default)]
    pub name: String,
    /// A rig file a scene names but that is not read yet (see [`Scene::load`]).
    #[serde(skip)]
    pub file: Option<String>,
    #[serde(default)]
    pub description: String,
    pub lidar: Option<LidarSpec>,
    pub stereo: Option<StereoSpec>,
    /// A colour camera without a stereo partner (`/camera/image`).
    pub camera: Option<CameraSpec>,
    pub swir: Option<CameraSpec>,
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
    /// range² and with the surface's backscatter at its incidence
    /// ([`crate::sim::Lidar::intensity_of`]).
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
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    pub rings: usize,
    pub elevation_deg: [f64; 2],
    pub columns: usize,
    #[serde(default = "d_az")]
    pub azimuth_deg: [f64; 2],
    #[serde(default = "d_wavelength")]
    pub wavelength_nm: f64,
    #[serde(default = "d_aperture")]
    pub aperture_m: f64,
    /// Sensitivity: lookahead (m) at which level ground of `reference_albedo`, seen from
    /// this lidar's mounting height, stops returning.
    pub dry_limit_m: f64,
    #[serde(default = "d_ref_albedo")]
    pub reference_albedo: f64,
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
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    pub width: usize,
    pub height: usize,
    pub hfov_deg: f64,
    pub baseline_m: f64,
    /// Standard deviation of the disparity (pixels of the binned disparity image, whose
    /// focal length is f / `bin`).
    #[serde(default = "d_disp_noise")]
    pub disparity_noise_px: f64,
    /// Matches whose (noisy) disparity falls below this are lost (binned pixels).
    #[serde(default = "d_min_disp")]
    pub min_disparity_px: f64,
    #[serde(default = "d_bin")]
    pub bin: usize,
    /// The left camera's lens distortion, plumb_bob [k1, k2, p1, p2, k3]: the image and its
    /// CameraInfo carry it; the cloud is computed on the rectified (pinhole) grid.
    #[serde(default)]
    pub distortion: Option<[f64; 5]>,
    /// How the colour image encodes radiance.
    #[serde(default = "d_linear")]
    pub encoding: crate::project::Encoding,
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
    pub position: [f64; 3],
    #[serde(default)]
    pub rpy_deg: [f64; 3],
    pub width: usize,
    pub height: usize,
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

fn bad(what: impl Into<String>, msg: impl Into<String>) -> Error {
    Error::invalid(what, msg)
}

fn finite(what: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(bad(what, format!("{v} is not finite")))
    }
}

fn positive(what: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(bad(what, format!("{v} must be a finite number > 0")))
    }
}

fn non_negative(what: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(bad(what, format!("{v} must be a finite number ≥ 0")))
    }
}

fn unit(what: &str, v: f64) -> Result<()> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(bad(what, format!("{v} must be in 0..1")))
    }
}

fn all_finite(what: &str, v: &[f64]) -> Result<()> {
    v.iter().try_for_each(|x| finite(what, *x))
}

fn need<T: Copy>(what: String, v: Option<T>, kind: &str) -> Result<T> {
    v.ok_or_else(|| bad(what, format!("missing: a {kind} needs it")))
}

impl Scene {
    /// Parses and validates a scene; errors name the key.
    pub fn from_toml_str(text: &str) -> Result<Scene> {
        let scene: Scene = toml::from_str(text)
            .map_err(|e| Error::invalid("scene", e.to_string().trim_end().to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// Reads, parses and validates a scene file; errors name the file, and the key. A rig
    /// named by file is read relative to the scene file.
    pub fn load(path: &Path) -> Result<Scene> {
        Self::load_with_rig(path, None)
    }

    /// [`Scene::load`], with the sensors of the rig file `rig` instead of the scene's own.
    pub fn load_with_rig(path: &Path, rig: Option<&Path>) -> Result<Scene> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut scene: Scene = toml::from_str(&text).map_err(|e| {
            let loc = e
                .span()
                .map(|s| {
                    let line = text[..s.start.min(text.len())].lines().count().max(1);
                    format!("line {line}")
                })
                .unwrap_or_else(|| "scene".into());
            Error::format(path, loc, e.message().to_string())
        })?;
        let named = scene.rig.file.take();
        match (rig, named) {
            (Some(r), _) => scene.rig = RigSpec::load(r)?,
            (None, Some(f)) => {
                let dir = path.parent().unwrap_or(Path::new("."));
                scene.rig = RigSpec::load(&dir.join(f))?;
            }
            (None, None) => {}
        }
        scene.validate().map_err(|e| match e {
            Error::Invalid { what, message } => Error::format(path, what, message),
            e => e,
        })?;
        Ok(scene)
    }

    /// All materials: built-in plus the scene's.
    pub fn all_materials(&self) -> BTreeMap<String, MaterialSpec> {
        let mut m = builtin_materials();
        m.extend(self.materials.clone());
        m
    }

    /// Checks every value; the error names the key (`water[0].radius`).
    pub fn validate(&self) -> Result<()> {
        if self.name.trim().is_empty() {
            return Err(bad("name", "must not be empty"));
        }
        positive("truth_resolution", self.truth_resolution)?;
        non_negative("fording_depth", self.fording_depth)?;
        let mats = self.all_materials();
        for (k, m) in &self.materials {
            let w = |f: &str| format!("materials.{k}.{f}");
            for (i, c) in m.rgb.iter().enumerate() {
                unit(&w(&format!("rgb[{i}]")), *c)?;
            }
            unit(&w("swir"), m.swir)?;
            unit(&w("lidar"), m.lidar)?;
            if m.lidar <= 0.0 {
                return Err(bad(w("lidar"), "must be > 0"));
            }
            unit(&w("texture"), m.texture)?;
            if !(m.backscatter_exponent.is_finite()
                && (0.5..=50.0).contains(&m.backscatter_exponent))
            {
                return Err(bad(
                    w("backscatter_exponent"),
                    format!("{} must be in 0.5..=50", m.backscatter_exponent),
                ));
            }
            positive(&w("temperature"), m.temperature)?;
            non_negative(&w("temperature_swing"), m.temperature_swing)?;
        }
        let known = |what: String, name: &str| -> Result<()> {
            if mats.contains_key(name) {
                Ok(())
            } else {
                Err(bad(
                    what,
                    format!(
                        "unknown material {name:?} (known: {})",
                        mats.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                ))
            }
        };

        let t = &self.terrain;
        all_finite("terrain.origin", &t.origin)?;
        positive("terrain.size[0]", t.size[0])?;
        positive("terrain.size[1]", t.size[1])?;
        positive("terrain.resolution", t.resolution)?;
        let verts = (t.size[0] / t.resolution + 1.0) * (t.size[1] / t.resolution + 1.0);
        if verts > 4.0e6 {
            return Err(bad(
                "terrain.resolution",
                format!(
                    "{} gives {verts:.0} heightfield vertices (at most 4 million)",
                    t.resolution
                ),
            ));
        }
        finite("terrain.elevation", t.elevation)?;
        all_finite("terrain.slope", &t.slope)?;
        non_negative("terrain.roughness", t.roughness)?;
        positive("terrain.roughness_scale", t.roughness_scale)?;
        known("terrain.material".into(), &t.material)?;
        for (i, f) in t.features.iter().enumerate() {
            let w = |k: &str| format!("terrain.features[{i}].{k}");
            let kind = format!("{:?}", f.kind).to_lowercase();
            if let Some(m) = &f.material {
                known(w("material"), m)?;
            }
            unit(&w("flat"), f.flat)?;
            if f.flat >= 1.0 {
                return Err(bad(w("flat"), "must be < 1"));
            }
            match f.kind {
                FeatureKind::Depression | FeatureKind::Mound => {
                    all_finite(&w("centre"), &need(w("centre"), f.centre, &kind)?)?;
                    let r = need(w("radius"), f.radius, &kind)?;
                    positive(&w("radius[0]"), r[0])?;
                    positive(&w("radius[1]"), r[1])?;
                    if f.kind == FeatureKind::Depression {
                        positive(&w("depth"), need(w("depth"), f.depth, &kind)?)?;
                    } else {
                        positive(&w("height"), need(w("height"), f.height, &kind)?)?;
                    }
                }
                FeatureKind::Ditch | FeatureKind::Curb => {
                    let a = need(w("from"), f.from, &kind)?;
                    let b = need(w("to"), f.to, &kind)?;
                    all_finite(&w("from"), &a)?;
                    all_finite(&w("to"), &b)?;
                    if a == b {
                        return Err(bad(w("to"), "must differ from `from`"));
                    }
                    positive(&w("width"), need(w("width"), f.width, &kind)?)?;
                    if f.kind == FeatureKind::Ditch {
                        positive(&w("depth"), need(w("depth"), f.depth, &kind)?)?;
                    } else {
                        positive(&w("height"), need(w("height"), f.height, &kind)?)?;
                    }
                }
            }
        }
        for (i, b) in self.water.iter().enumerate() {
            let w = |k: &str| format!("water[{i}].{k}");
            let kind = format!("{:?} water body", b.kind).to_lowercase();
            match b.kind {
                WaterKind::Level => {
                    finite(&w("level"), need(w("level"), b.level, &kind)?)?;
                    all_finite(&w("centre"), &need(w("centre"), b.centre, &kind)?)?;
                    positive(&w("radius"), need(w("radius"), b.radius, &kind)?)?;
                }
                WaterKind::Stream => {
                    let a = need(w("from"), b.from, &kind)?;
                    let c = need(w("to"), b.to, &kind)?;
                    all_finite(&w("from"), &a)?;
                    all_finite(&w("to"), &c)?;
                    if a[0] == c[0] && a[1] == c[1] {
                        return Err(bad(w("to"), "must differ from `from` in x or y"));
                    }
                    positive(&w("width"), need(w("width"), b.width, &kind)?)?;
                }
            }
            non_negative(&w("ripple"), b.ripple)?;
            if b.ripple > 0.5 {
                return Err(bad(
                    w("ripple"),
                    format!("{} rad RMS slope is not a ripple (≤ 0.5)", b.ripple),
                ));
            }
            if let Some(a) = b.attenuation {
                non_negative(&w("attenuation"), a)?;
            }
            for (j, c) in b.colour.iter().enumerate() {
                unit(&w(&format!("colour[{j}]")), *c)?;
            }
            positive(&w("temperature"), b.temperature)?;
            non_negative(&w("temperature_swing"), b.temperature_swing)?;
        }
        for (i, o) in self.objects.iter().enumerate() {
            let w = |k: &str| format!("objects[{i}].{k}");
            let kind = format!("{:?}", o.kind).to_lowercase();
            all_finite(&w("position"), &o.position)?;
            finite(&w("yaw_deg"), o.yaw_deg)?;
            if let Some(m) = &o.material {
                known(w("material"), m)?;
            }
            match o.kind {
                ObjectKind::Tree => {
                    positive(&w("height"), need(w("height"), o.height, &kind)?)?;
                    positive(&w("radius"), need(w("radius"), o.radius, &kind)?)?;
                }
                ObjectKind::Building | ObjectKind::Rock => {
                    let s = need(w("size"), o.size, &kind)?;
                    for (j, v) in s.iter().enumerate() {
                        positive(&w(&format!("size[{j}]")), *v)?;
                    }
                }
            }
        }
        for (i, p) in self.patches.iter().enumerate() {
            let w = |k: &str| format!("patches[{i}].{k}");
            all_finite(&w("centre"), &p.centre)?;
            positive(&w("radius"), p.radius)?;
            known(w("material"), &p.material)?;
        }
        let s = &self.sky;
        if !(0.0..24.0).contains(&s.time_of_day) {
            return Err(bad(
                "sky.time_of_day",
                format!("{} must be in 0..24 (hours)", s.time_of_day),
            ));
        }
        let tr = &self.trajectory;
        if tr.waypoints.len() < 2 {
            return Err(bad(
                "trajectory.waypoints",
                format!("{} given, at least 2 needed", tr.waypoints.len()),
            ));
        }
        for (i, p) in tr.waypoints.iter().enumerate() {
            all_finite(&format!("trajectory.waypoints[{i}]"), p)?;
            let inside = p[0] >= t.origin[0]
                && p[0] <= t.origin[0] + t.size[0]
                && p[1] >= t.origin[1]
                && p[1] <= t.origin[1] + t.size[1];
            if !inside {
                return Err(bad(
                    format!("trajectory.waypoints[{i}]"),
                    format!("{p:?} is outside the terrain"),
                ));
            }
        }
        positive("trajectory.speed", tr.speed)?;
        positive("trajectory.rate_hz", tr.rate_hz)?;
        non_negative("trajectory.start_time", tr.start_time)?;
        if tr.frames == Some(0) {
            return Err(bad("trajectory.frames", "must be ≥ 1"));
        }
        self.rig.validate()
    }
}

impl RigSpec {
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
            return Err(bad(
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
            return Err(bad(
                "rig",
                "configures no sensor (lidar, stereo, camera, swir, mwir)",
            ));
        }
        if let Some(l) = &r.lidar {
            let w = |k: &str| format!("rig.lidar.{k}");
            all_finite(&w("position"), &l.position)?;
            all_finite(&w("rpy_deg"), &l.rpy_deg)?;
            if l.rings == 0 || l.rings > 512 {
                return Err(bad(w("rings"), format!("{} must be in 1..=512", l.rings)));
            }
            if l.columns == 0 || l.columns > 8192 {
                return Err(bad(
                    w("columns"),
                    format!("{} must be in 1..=8192", l.columns),
                ));
            }
            let [lo, hi] = l.elevation_deg;
            if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -90.0 && hi <= 90.0) {
                return Err(bad(
                    w("elevation_deg"),
                    format!("{:?} must be [low, high] within ±90", l.elevation_deg),
                ));
            }
            let [a0, a1] = l.azimuth_deg;
            if !(a0.is_finite() && a1.is_finite() && a0 <= a1 && a1 - a0 <= 360.0) {
                return Err(bad(
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
                return Err(bad(w("position"), "z must be above the ground (> 0)"));
            }
        }
        let cam = |w: &dyn Fn(&str) -> String,
                   pos: &[f64; 3],
                   rpy: &[f64; 3],
                   width: usize,
                   height: usize,
                   hfov: f64,
                   noise: f64,
                   distortion: &Option<[f64; 5]>|
         -> Result<()> {
            if let Some(d) = distortion {
                all_finite(&w("distortion"), d)?;
                if d.iter().any(|k| k.abs() > 1.0) {
                    return Err(bad(
                        w("distortion"),
                        format!("{d:?}: plumb_bob coefficients beyond ±1 are not a lens"),
                    ));
                }
            }
            all_finite(&w("position"), pos)?;
            all_finite(&w("rpy_deg"), rpy)?;
            if width == 0 || height == 0 || width > 4096 || height > 4096 {
                return Err(bad(
                    w("width"),
                    format!("{width} × {height} must be within 1..=4096"),
                ));
            }
            if !(hfov > 1.0 && hfov < 170.0) {
                return Err(bad(w("hfov_deg"), format!("{hfov} must be in (1, 170)")));
            }
            non_negative(&w("image_noise"), noise)
        };
        if let Some(s) = &r.stereo {
            let w = |k: &str| format!("rig.stereo.{k}");
            cam(
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
                return Err(bad(
                    w("bin"),
                    format!(
                        "{} must be ≥ 1 and divide {} × {}",
                        s.bin, s.width, s.height
                    ),
                ));
            }
            positive(&w("max_range_m"), s.max_range_m)?;
        }
        if r.stereo.is_some() && r.camera.is_some() {
            return Err(bad(
                "rig.camera",
                "the stereo pair's left camera is the colour camera: give one of stereo, camera",
            ));
        }
        if let Some(g) = &r.gps {
            if g.latitude_deg.is_nan() || g.latitude_deg.abs() > 90.0 {
                return Err(bad(
                    "rig.gps.latitude_deg",
                    format!("{} (must be within ±90°)", g.latitude_deg),
                ));
            }
        }
        for (name, c) in [("camera", &r.camera), ("swir", &r.swir), ("mwir", &r.mwir)] {
            if let Some(c) = c {
                let w = |k: &str| format!("rig.{name}.{k}");
                cam(
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
