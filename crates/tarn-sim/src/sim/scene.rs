//! The scene format: TOML, every table with `deny_unknown_fields`, validated after parsing
//! so that a bad value is reported with its key (`water[1].level`) and the reason.
//! `maps/README.md` documents every key.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{all_finite, finite, non_negative, positive, unit, Error, Result};
use crate::hazard::Class;
pub use crate::rig::{CameraSpec, GpsSpec, IntensityKind, LidarSpec, RigSpec, StereoSpec};

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

fn bad(what: impl Into<String>, msg: impl Into<String>) -> Error {
    Error::invalid(what, msg)
}

fn need<T: Copy>(what: String, v: Option<T>, kind: &str) -> Result<T> {
    v.ok_or_else(|| bad(what, format!("missing: a {kind} needs it")))
}

/// Every material by name: the built-in ones and the scene's.
type Materials = BTreeMap<String, MaterialSpec>;

/// `name` is one of `mats`; the error (under `what`) lists the known ones.
fn known(mats: &Materials, what: String, name: &str) -> Result<()> {
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
}

/// Terrain feature `i`: its material, rim, and the dimensions of its kind.
fn validate_feature(i: usize, f: &FeatureSpec, mats: &Materials) -> Result<()> {
    let w = |k: &str| format!("terrain.features[{i}].{k}");
    let kind = format!("{:?}", f.kind).to_lowercase();
    if let Some(m) = &f.material {
        known(mats, w("material"), m)?;
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
    Ok(())
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
        self.validate_materials()?;
        self.validate_terrain(&mats)?;
        self.validate_water()?;
        self.validate_objects(&mats)?;
        self.validate_patches(&mats)?;
        self.validate_sky()?;
        self.validate_trajectory()?;
        self.rig.validate()
    }

    /// The scene's own materials: colours, reflectances and temperatures in range.
    fn validate_materials(&self) -> Result<()> {
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
        Ok(())
    }

    /// The terrain's extent, resolution, surface and features; `mats` are the materials a
    /// name may refer to.
    fn validate_terrain(&self, mats: &Materials) -> Result<()> {
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
        known(mats, "terrain.material".into(), &t.material)?;
        for (i, f) in t.features.iter().enumerate() {
            validate_feature(i, f, mats)?;
        }
        Ok(())
    }

    /// Every water body: its region by kind, ripple, attenuation, colour and temperature.
    fn validate_water(&self) -> Result<()> {
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
        Ok(())
    }

    /// Every object: its position, material and the dimensions of its kind.
    fn validate_objects(&self, mats: &Materials) -> Result<()> {
        for (i, o) in self.objects.iter().enumerate() {
            let w = |k: &str| format!("objects[{i}].{k}");
            let kind = format!("{:?}", o.kind).to_lowercase();
            all_finite(&w("position"), &o.position)?;
            finite(&w("yaw_deg"), o.yaw_deg)?;
            if let Some(m) = &o.material {
                known(mats, w("material"), m)?;
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
        Ok(())
    }

    /// Every material patch: its disc and material.
    fn validate_patches(&self, mats: &Materials) -> Result<()> {
        for (i, p) in self.patches.iter().enumerate() {
            let w = |k: &str| format!("patches[{i}].{k}");
            all_finite(&w("centre"), &p.centre)?;
            positive(&w("radius"), p.radius)?;
            known(mats, w("material"), &p.material)?;
        }
        Ok(())
    }

    /// The sky: a time of day within the day.
    fn validate_sky(&self) -> Result<()> {
        let s = &self.sky;
        if !(0.0..24.0).contains(&s.time_of_day) {
            return Err(bad(
                "sky.time_of_day",
                format!("{} must be in 0..24 (hours)", s.time_of_day),
            ));
        }
        Ok(())
    }

    /// The trajectory: at least two waypoints, all over the terrain, and its timing.
    fn validate_trajectory(&self) -> Result<()> {
        let t = &self.terrain;
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
        Ok(())
    }
}
