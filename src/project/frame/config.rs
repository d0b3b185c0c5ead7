//! The label stage's settings: which image sensors label the map and how, as the mapper
//! runs them ([`FrameLabelConfig`]) and as a mapper config's `[labels]` section names them
//! ([`LabelsConfig`]).

use serde::{Deserialize, Serialize};

use crate::classify::{ColorLut, MwirConfig, SwirConfig};
use crate::error::{Error, Result};
use crate::sensor::Frame;

/// MWIR labelling: the classifier's parameters, and how the local solar hour of each
/// image is known.
#[derive(Debug, Clone, PartialEq)]
pub struct MwirLabelConfig {
    /// Parameters of the MWIR thermal contrast classifier.
    pub classifier: MwirConfig,
    /// Local solar hour (0..24) every image was taken at; `None`: from each frame's stamp
    /// (UTC) and the longitude (the equation of time, [`crate::classify::equation_of_time_min`]).
    pub hour: Option<f64>,
    /// Degrees east, for the solar hour; `None`: the log's GNSS fix ([`Frame::geo`]).
    pub longitude_deg: Option<f64>,
}

impl MwirLabelConfig {
    /// The local solar hour of `frame`: the given hour, or the frame's stamp at the
    /// configured longitude or the log's; `None` when neither is known.
    pub fn hour_of(&self, frame: &Frame) -> Option<f64> {
        self.hour.or_else(|| {
            let lon = self.longitude_deg.or(frame.geo.map(|g| g.1))?;
            crate::classify::solar::local_solar_hour(frame.stamp, lon)
        })
    }
}

/// Which image sensors label the map, and how.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameLabelConfig {
    /// Colour classifier as a lookup table (the Table 1 rule or a trained mixture model).
    pub colour: Option<ColorLut>,
    /// SWIR darkness classifier (`None`: no SWIR labels).
    pub swir: Option<SwirConfig>,
    /// MWIR labelling (`None`: no MWIR labels).
    pub mwir: Option<MwirLabelConfig>,
    /// Use every `ray_stride`-th pixel in x and y (1 = all).
    pub ray_stride: usize,
    /// Also use every row of pixels whose ground footprint is wider than a map cell
    /// (`sampled_rows`): there a skipped row skips whole cells, and the labels' edges
    /// (the water's, and a sky reflection's) move by that much. Off by default: with
    /// every cue the extra votes on the water's edge move the shores (README, "Image
    /// labels").
    pub wide_rows: bool,
    /// Pixels whose hit lies farther than this along the ray (metres) do not vote.
    pub max_range: f64,
    /// A stereo point places its pixel only up to this range (metres); farther pixels are
    /// ray-marched over the fused map. Stereo range noise grows with the square of the range
    /// (σ = z² σ_d / (f B): 2.9 m at 20 m for the simulated 320 px, 12 cm-baseline rig), so a
    /// single far point is a worse place for a vote than the map, which averages many.
    pub stereo_max_range: f64,
    /// Cells whose elevation σ bound exceeds this (metres) are holes to the ray march
    /// ([`GridSurface::from_grid_gated`]); infinity keeps every observed cell.
    ///
    /// [`GridSurface::from_grid_gated`]: crate::project::GridSurface::from_grid_gated
    pub surface_max_std: f64,
    /// How a pixel without a stereo point finds its cell.
    pub sampler: Sampler,
    /// Check colour water against the sky it would reflect ([`reflection_check`]), reading
    /// the image with this encoding; `None`: no check.
    ///
    /// [`reflection_check`]: super::reflection_check
    pub reflection_check: Option<Encoding>,
    /// Check colour water against where the lidar found the surface dry or wet
    /// (`ColourCheck`).
    pub colour_check: bool,
}

/// How the label stage finds where a pixel's ray meets the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Sampler {
    /// Each sampled pixel's ray marched over the map's elevations ([`GridSurface`]) from
    /// the camera; a water pixel crossing a hole is placed where it drops to the hole's
    /// lower rim.
    ///
    /// [`GridSurface`]: crate::project::GridSurface
    March,
    /// The same march, started where a z-buffer of the map (drawn into the image once
    /// per frame) says each ray first meets it: the same votes, a few steps per ray.
    #[default]
    #[serde(alias = "z_buffer")]
    Zbuffer,
}

impl std::str::FromStr for Sampler {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim() {
            "march" => Ok(Sampler::March),
            "zbuffer" | "z_buffer" => Ok(Sampler::Zbuffer),
            o => Err(Error::invalid(
                "label sampler",
                format!("unknown sampler {o:?} (march, zbuffer)"),
            )),
        }
    }
}

/// How an 8-bit colour image encodes radiance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Encoding {
    /// sRGB (most cameras, and the safe assumption: read as sRGB, linear data looks
    /// darker against its sky and the reflection check vetoes less, never more).
    #[default]
    Srgb,
    /// Values proportional to radiance (the simulator's cameras).
    Linear,
}

impl Encoding {
    /// Linear radiance (0..1) of each 8-bit value.
    pub fn table(self) -> [f64; 256] {
        std::array::from_fn(|v| {
            let c = v as f64 / 255.0;
            match self {
                Encoding::Linear => c,
                Encoding::Srgb if c <= 0.04045 => c / 12.92,
                Encoding::Srgb => ((c + 0.055) / 1.055).powf(2.4),
            }
        })
    }
}

impl Default for FrameLabelConfig {
    fn default() -> Self {
        FrameLabelConfig {
            colour: None,
            swir: None,
            mwir: None,
            ray_stride: 2,
            wide_rows: false,
            max_range: 40.0,
            stereo_max_range: 10.0,
            surface_max_std: 0.1,
            sampler: Sampler::default(),
            reflection_check: Some(Encoding::Srgb),
            colour_check: true,
        }
    }
}

impl FrameLabelConfig {
    /// Checks the stride, ranges and surface limit, and that the MWIR classifier has a regime
    /// for `hour`; the error says what is out of range.
    pub fn validate(&self) -> Result<()> {
        if self.ray_stride == 0
            || !(self.max_range.is_finite() && self.max_range > 0.0)
            || self.stereo_max_range.is_nan()
            || self.surface_max_std.is_nan()
            || self.surface_max_std <= 0.0
        {
            return Err(Error::invalid(
                "label config",
                format!(
                    "ray_stride {} must be ≥ 1, max_range {} m finite and > 0, \
                     surface_max_std {} m > 0",
                    self.ray_stride, self.max_range, self.surface_max_std
                ),
            ));
        }
        if let Some(m) = &self.mwir {
            if let Some(h) = m.hour {
                m.classifier.regime(h)?;
            }
            if let Some(l) = m.longitude_deg.filter(|l| l.is_nan() || l.abs() > 180.0) {
                return Err(Error::invalid(
                    "label config",
                    format!("longitude {l}° (must be within ±180°)"),
                ));
            }
        }
        Ok(())
    }
}

/// An image sensor whose labels vote in the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelSensor {
    /// The colour camera (`color` is read too).
    #[serde(alias = "color")]
    Colour,
    /// The short-wave infrared camera.
    Swir,
    /// The mid-wave infrared camera.
    Mwir,
}

impl std::str::FromStr for LabelSensor {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim() {
            "colour" | "color" => Ok(LabelSensor::Colour),
            "swir" => Ok(LabelSensor::Swir),
            "mwir" => Ok(LabelSensor::Mwir),
            o => Err(Error::invalid(
                "labels",
                format!("unknown image sensor {o:?} (colour, swir, mwir)"),
            )),
        }
    }
}

/// The `[labels]` section of a mapper config: which image sensors label the map, and how
/// ([`LabelsConfig::compile`] makes the [`FrameLabelConfig`] the mapper runs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LabelsConfig {
    /// Sensors whose labels vote (a sensor the log lacks is skipped, and counted).
    pub sensors: Vec<LabelSensor>,
    /// A colour model (JSON from `tarn train-colour`), compiled into a 6-bit lookup table;
    /// without it the paper's Table 1 rule (its exact table over brightness and saturation).
    pub colour_model: Option<std::path::PathBuf>,
    /// Local solar hour of the log (0..24) for the MWIR labels; without it, each frame's
    /// from its stamp and the longitude.
    pub hour: Option<f64>,
    /// Degrees east of Greenwich, for the local solar hour; without it, the log's GNSS
    /// fix (`sensor_msgs/NavSatFix`).
    pub longitude_deg: Option<f64>,
    /// Kelvin per count of the MWIR image (0.01: mono16 centikelvin, as radiometric
    /// cameras write); a camera of raw counts states its calibration here.
    pub mwir_kelvin_per_count: f64,
    /// Kelvin at count 0 of the MWIR image.
    pub mwir_kelvin_offset: f64,
    /// Label every n-th pixel in x and y.
    pub stride: usize,
    /// Also label every row of pixels whose ground footprint is wider than a map cell.
    pub wide_rows: bool,
    /// Pixels whose hit is farther than this do not vote (m).
    pub max_range_m: f64,
    /// Cells whose elevation σ bound (`CellStats::range_bound_std_m`) exceeds this are
    /// holes to the ray march (m).
    pub surface_max_std_m: f64,
    /// How a pixel finds its cell: `zbuffer` (the default) or `march`; the same votes.
    pub sampler: Sampler,
    /// Veto colour water that is brighter than a reflection of the sky it faces could be
    /// ([`reflection_check`](super::reflection_check)).
    pub reflection_check: bool,
    /// How the colour camera encodes radiance (sRGB unless the camera says otherwise).
    pub encoding: Encoding,
    /// Stop counting a colour as water in a log where the lidar finds it on dry ground
    /// (`ColourCheck`).
    pub colour_check: bool,
    /// Standard deviation of the SWIR camera's pixel noise, grey levels (the rig's
    /// datasheet): the SWIR rule's noise margin ([`SwirConfig::noise_sd`]).
    pub swir_noise_sd: f32,
}

impl Default for LabelsConfig {
    fn default() -> Self {
        let f = FrameLabelConfig::default();
        LabelsConfig {
            sensors: vec![LabelSensor::Colour],
            colour_model: None,
            hour: None,
            longitude_deg: None,
            mwir_kelvin_per_count: MwirConfig::default().kelvin_per_count,
            mwir_kelvin_offset: MwirConfig::default().kelvin_offset,
            stride: f.ray_stride,
            wide_rows: f.wide_rows,
            max_range_m: f.max_range,
            surface_max_std_m: f.surface_max_std,
            sampler: f.sampler,
            reflection_check: true,
            encoding: Encoding::default(),
            colour_check: true,
            swir_noise_sd: SwirConfig::default().noise_sd,
        }
    }
}

impl LabelsConfig {
    /// The classifiers and settings the mapper runs: the colour model read and compiled
    /// (or the Table 1 rule), SWIR and MWIR with their defaults.
    pub fn compile(&self) -> Result<FrameLabelConfig> {
        self.compile_at(6, 8)
    }

    /// Every check of [`Self::compile`] (the colour model read, the sensors' settings) with
    /// one-bit lookup tables, which take no time to build.
    pub fn check(&self) -> Result<()> {
        self.compile_at(1, 1).map(|_| ())
    }

    /// [`Self::compile`] with the lookup tables' bits per channel for a colour model and
    /// for the rule.
    fn compile_at(&self, model_bits: u8, rule_bits: u8) -> Result<FrameLabelConfig> {
        use crate::classify::{ColorModel, RuleClassifier};
        let mut cfg = FrameLabelConfig {
            ray_stride: self.stride,
            wide_rows: self.wide_rows,
            max_range: self.max_range_m,
            surface_max_std: self.surface_max_std_m,
            sampler: self.sampler,
            reflection_check: self.reflection_check.then_some(self.encoding),
            colour_check: self.colour_check,
            ..FrameLabelConfig::default()
        };
        for s in &self.sensors {
            match s {
                LabelSensor::Colour => {
                    cfg.colour = Some(match &self.colour_model {
                        Some(p) => ColorLut::compile(&ColorModel::load(p)?, model_bits)?,
                        None => ColorLut::compile(&RuleClassifier::default(), rule_bits)?,
                    })
                }
                LabelSensor::Swir => {
                    cfg.swir = Some(SwirConfig {
                        noise_sd: self.swir_noise_sd,
                        ..SwirConfig::default()
                    })
                }
                LabelSensor::Mwir => {
                    cfg.mwir = Some(MwirLabelConfig {
                        classifier: MwirConfig {
                            kelvin_per_count: self.mwir_kelvin_per_count,
                            kelvin_offset: self.mwir_kelvin_offset,
                            ..MwirConfig::default()
                        },
                        hour: self.hour,
                        longitude_deg: self.longitude_deg,
                    })
                }
            }
        }
        if self.colour_model.is_some() && cfg.colour.is_none() {
            return Err(Error::invalid(
                "labels",
                "a colour model needs the colour sensor in labels.sensors (--labels colour)",
            ));
        }
        cfg.validate()?;
        Ok(cfg)
    }
}
