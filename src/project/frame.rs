//! Image labels of one [`Frame`] into the grid's water evidence (same pattern as
//! [`crate::cues::frame::FrameCues`]).
//!
//! For each configured image sensor present in the frame: classify the image (colour through
//! a lookup table, pixels above the horizon — from the camera's pose — become sky; SWIR
//! darkness gated by incidence; MWIR thermal contrast by time of day within a lookahead),
//! find each pixel's map cell (through the stereo point of the pixel where the colour camera
//! has one, else by marching the pixel ray over the grid's elevations, [`GridSurface`]),
//! tally the frame's pixels per cell in a dense raster over the window, and add **one vote
//! per cell and frame** — the majority of its pixels, water or not — to the cell's
//! [`Evidence`] (`colour_water`/`colour_dry`, `swir_dark`/`swir_lit`,
//! `mwir_water`/`mwir_dry`), with the mean of the water pixels' levels as a water level
//! sample: a hit's height, or for water placed over a hole in the map, the tightest bound on
//! the level among its neighbours in the image (`tighten_hole_levels`). Sky and unknown
//! pixels do not vote; a tie is no vote.
//!
//! Only configured sensors run code; a configured sensor missing from the frame (or without
//! camera info or pose) is skipped and counted in the report.

use nalgebra::{Point3, Vector3, Vector4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::surface::GridSurface;
use super::zbuffer::ZBuffer;
use crate::classify::horizon::GroundGeometry;
use crate::classify::lut::ColorLut;
use crate::classify::thermal::{classify_mwir, classify_swir, MwirConfig, SwirConfig};
use crate::classify::{Label, LabelImage, MonoImage};
use crate::cues::{DryReach, ScanSurface, StereoSeen};
use crate::error::{Error, Result};
use crate::geom::camera::CameraModel;
use crate::geom::{ceil_i64, floor_i64, pose_is_finite, PointCloud, Pose};
use crate::grid::{CellKey, Evidence, RollingGrid};
use crate::sensor::{Frame, Pixels, SensorImage};

/// MWIR labelling: the classifier's parameters, and how the local solar hour of each
/// image is known.
#[derive(Debug, Clone, PartialEq)]
pub struct MwirLabelConfig {
    /// Parameters of the MWIR thermal contrast classifier.
    pub classifier: MwirConfig,
    /// Local solar hour (0..24) every image was taken at; `None`: from each frame's stamp
    /// (UTC) and the longitude ([`crate::classify::solar`]).
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
    pub surface_max_std: f64,
    /// How a pixel without a stereo point finds its cell.
    pub sampler: Sampler,
    /// Check colour water against the sky it would reflect ([`reflection_check`]), reading
    /// the image with this encoding; `None`: no check.
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
    /// ([`reflection_check`]).
    pub reflection_check: bool,
    /// How the colour camera encodes radiance (sRGB unless the camera says otherwise).
    pub encoding: Encoding,
    /// Stop counting a colour as water in a log where the lidar finds it on dry ground
    /// (`ColourCheck`).
    pub colour_check: bool,
}

impl Default for LabelsConfig {
    fn default() -> Self {
        let f = FrameLabelConfig::default();
        LabelsConfig {
            sensors: vec![LabelSensor::Colour],
            colour_model: None,
            hour: None,
            longitude_deg: None,
            stride: f.ray_stride,
            wide_rows: f.wide_rows,
            max_range_m: f.max_range,
            surface_max_std_m: f.surface_max_std,
            sampler: f.sampler,
            reflection_check: true,
            encoding: Encoding::default(),
            colour_check: true,
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
        use crate::classify::color::RuleClassifier;
        use crate::classify::gmm::ColorModel;
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
                LabelSensor::Swir => cfg.swir = Some(SwirConfig::default()),
                LabelSensor::Mwir => {
                    cfg.mwir = Some(MwirLabelConfig {
                        classifier: MwirConfig::default(),
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

/// What one sensor contributed in one frame (or, summed, over a log).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorLabelStats {
    /// Frames the sensor was used in.
    pub frames: u64,
    /// Configured but not usable in a frame (no image, camera info or pose).
    pub frames_skipped: u64,
    /// Pixels labelled water.
    pub pixels_water: u64,
    /// Pixels labelled other or snow/ice.
    pub pixels_not_water: u64,
    /// Pixels placed through a stereo point.
    pub via_point: u64,
    /// Pixels placed by a ray march through the map.
    pub via_ray: u64,
    /// Pixels not placed (the ray met nothing).
    pub no_hit: u64,
    /// Per-frame cell votes for water.
    pub cells_water: u64,
    /// Per-frame cell votes for dry.
    pub cells_dry: u64,
    /// Colour water pixels brighter than a reflection of the sky could be
    /// ([`reflection_check`]).
    pub reflection_vetoed: u64,
    /// Water pixels whose ray crossed a hole in the map beyond the lidar's dry reach
    /// ([`crate::cues::DryReach`]): a hole that range alone explains places no vote.
    pub beyond_reach: u64,
    /// Colour water pixels whose colour the log's lidar finds on dry ground
    /// (`ColourCheck`): no vote.
    pub colour_check_vetoed: u64,
    /// MWIR frames skipped for want of a local solar hour (no hour given, no longitude).
    #[serde(default)]
    pub frames_no_hour: u64,
    /// MWIR frames whose solar hour came from their stamp and the longitude.
    #[serde(default)]
    pub frames_hour_from_stamp: u64,
}

impl SensorLabelStats {
    /// Adds another frame's counts.
    pub fn merge(&mut self, o: &SensorLabelStats) {
        self.frames += o.frames;
        self.frames_skipped += o.frames_skipped;
        self.pixels_water += o.pixels_water;
        self.pixels_not_water += o.pixels_not_water;
        self.via_point += o.via_point;
        self.via_ray += o.via_ray;
        self.no_hit += o.no_hit;
        self.cells_water += o.cells_water;
        self.cells_dry += o.cells_dry;
        self.reflection_vetoed += o.reflection_vetoed;
        self.beyond_reach += o.beyond_reach;
        self.colour_check_vetoed += o.colour_check_vetoed;
        self.frames_no_hour += o.frames_no_hour;
        self.frames_hour_from_stamp += o.frames_hour_from_stamp;
    }
}

/// What one frame contributed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameLabelsReport {
    /// What the colour camera contributed (`None`: not configured).
    pub colour: Option<SensorLabelStats>,
    /// What the SWIR camera contributed (`None`: not configured).
    pub swir: Option<SensorLabelStats>,
    /// What the MWIR camera contributed (`None`: not configured).
    pub mwir: Option<SensorLabelStats>,
    /// The earliest and latest local solar hour the MWIR images were classified at.
    #[serde(default)]
    pub mwir_hours: Option<[f64; 2]>,
    /// Cell votes that fell outside the window (dropped).
    pub dropped: u64,
}

impl FrameLabelsReport {
    /// Adds another frame's counts, sensor by sensor.
    pub fn merge(&mut self, o: &FrameLabelsReport) {
        for (a, b) in [
            (&mut self.colour, &o.colour),
            (&mut self.swir, &o.swir),
            (&mut self.mwir, &o.mwir),
        ] {
            if let Some(b) = b {
                a.get_or_insert_with(Default::default).merge(b);
            }
        }
        if let Some([lo, hi]) = o.mwir_hours {
            let h = self.mwir_hours.get_or_insert([lo, hi]);
            *h = [h[0].min(lo), h[1].max(hi)];
        }
        self.dropped += o.dropped;
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cue {
    Colour,
    Swir,
    Mwir,
}

/// A camera's unit pixel rays (optical frame), computed once per camera model.
#[derive(Debug, Clone)]
struct RayCache {
    camera: CameraModel,
    rays: Vec<Option<Vector3<f64>>>,
    /// The rays rotated into the map frame by the current frame's pose (reused buffer).
    in_map: Vec<Option<Vector3<f64>>>,
}

impl RayCache {
    fn new(camera: &CameraModel) -> Self {
        RayCache {
            camera: camera.clone(),
            rays: camera.pixel_rays(),
            in_map: Vec::new(),
        }
    }

    /// `camera`'s pixel rays rotated into the map frame by `cam_to_map`, from the cache in
    /// `slot` (rebuilt when the camera changed).
    fn rays_in_map<'a>(
        slot: &'a mut Option<RayCache>,
        camera: &CameraModel,
        cam_to_map: &Pose,
    ) -> &'a [Option<Vector3<f64>>] {
        if slot.as_ref().is_none_or(|c| &c.camera != camera) {
            *slot = Some(RayCache::new(camera));
        }
        let cache = slot.as_mut().expect("just set");
        cache.in_map.clear();
        cache.in_map.extend(
            cache
                .rays
                .iter()
                .map(|r| r.map(|r| cam_to_map.rotation * r)),
        );
        &cache.in_map
    }
}

/// The per-frame label runner. Keeps each camera's pixel rays, the vote raster, the
/// elevation raster and the per-pixel buffers (labels, sampled pixels' hits, per-row votes)
/// between frames, so a frame pays neither undistortion nor allocation.
#[derive(Debug, Clone)]
pub struct FrameLabels {
    /// Which sensors label, and how.
    pub cfg: FrameLabelConfig,
    caches: [Option<RayCache>; 3],
    /// Per raster cell: water pixels, other pixels, Σ z of the water pixels' hits.
    tally: Vec<(u32, u32, f64)>,
    touched: Vec<u32>,
    /// The storage of the last frame's elevation raster.
    raster: Vec<f32>,
    /// What the log's range sensors said of the ground under each colour so far.
    colour_check: ColourCheck,
    /// Per-pixel storage of the last frame, reused.
    bufs: PixelBuffers,
    /// The z-buffer sampler's storage ([`Sampler::Zbuffer`]).
    zbuf: ZBuffer,
}

/// The label stage's per-pixel buffers, kept from frame to frame so that a frame allocates
/// nothing: their sizes follow the image, not the window.
#[derive(Debug, Clone, Default)]
struct PixelBuffers {
    /// The colour image's labels.
    labels: Vec<Label>,
    /// The sampled image rows and columns.
    rows: Vec<usize>,
    cols: Vec<usize>,
    /// Per sampled pixel, row-major: its hit.
    hits: Vec<Option<Hit>>,
    /// Per sampled row: pixels placed via a point, via a ray, not placed, beyond reach.
    counts: Vec<[u64; 4]>,
    /// Scratch of `tighten_hole_levels`.
    levels: Vec<f64>,
    /// Per sampled row: its cell votes (raster index, water, level).
    votes: Vec<Vec<(u32, bool, f32)>>,
}

/// Bits per channel of the colour bins the [`ColourCheck`] counts in.
const CHECK_BITS: u32 = 4;
/// One-sided 5 % point of the standard normal: the [`ColourCheck`]'s sign test.
const CHECK_Z: f64 = 1.645;

/// Whether pixel `(u, v)` and the eight around it (those inside the image) are all colour
/// water: only there does a sample tell which side of the water's edge it lies on. A lidar
/// point's projection is rounded to the nearest pixel, a stereo element's disparity is
/// matched over a window of pixels, and the label's edge is itself a pixel wide: a return
/// from the dry rim of a puddle lands on the puddle's edge pixels as often as on the rim's,
/// and a stereo match there may be the rim's texture.
fn inside_water(labels: &LabelImage, u: usize, v: usize) -> bool {
    let (w, h) = (labels.width, labels.height);
    (v.saturating_sub(1)..(v + 2).min(h)).all(|y| {
        (u.saturating_sub(1)..(u + 2).min(w)).all(|x| labels.data[y * w + x] == Label::Water)
    })
}

/// The colour classifier checked by the lidar, over a log. The paper's rule calls whatever
/// is bright and weakly saturated water, which pale concrete, a pale slab and snow are too:
/// the cue's false-alarm rate is then not the few per cent the fusion rule assumes but a
/// property of the scene. The lidar measures it. Each frame, the points where the scan
/// found dry ground (returns water would not give) and water (missing beams inside the
/// diagnostic interval, bottom and specular returns where their beams cross the water) are
/// projected into the colour image; a water pixel there, inside the water's edge
/// ([`inside_water`]), counts for its colour bin (4 bits a channel) as seen on dry ground
/// or on water. A colour the lidar finds on dry ground
/// more often than on water, by a one-sided sign test at 5 % (`dry − wet ≥ 1.645
/// √(dry + wet + 1)`, the normal form: four dry samples and none wet suffice), is not
/// evidence of water in this log: its pixels become `Unknown` and place no vote, near or
/// beyond the lidar's reach. The counts
/// go on whether a colour is vetoed or not, so a verdict follows the log. On a rig with
/// stereo the stereo elements registered to the image are samples too ([`StereoSeen`]): a
/// point at the local ground level within its own vertical noise is a dry one, a
/// reflection (the mirror image well below the level) one against. A missing
/// match counts for neither: still water mirroring the sky gives none, and neither do snow
/// and pale concrete without texture, the colours the check is for. Without either
/// sensor nothing is counted and nothing vetoed: the check says nothing where it cannot
/// tell.
#[derive(Debug, Clone, Default)]
struct ColourCheck {
    /// Per bin: lidar samples on dry ground and on water whose pixel is colour water.
    dry: Vec<u32>,
    wet: Vec<u32>,
}

impl ColourCheck {
    fn bin([r, g, b]: [u8; 3]) -> usize {
        let k = 8 - CHECK_BITS;
        ((r as usize >> k) << (2 * CHECK_BITS))
            | ((g as usize >> k) << CHECK_BITS)
            | (b as usize >> k)
    }

    /// One more dry (or wet) sample of `colour`.
    fn count(&mut self, colour: [u8; 3], dry: bool) {
        let b = Self::bin(colour);
        let n = if dry {
            &mut self.dry[b]
        } else {
            &mut self.wet[b]
        };
        *n = n.saturating_add(1);
    }

    fn vetoed(&self, bin: usize) -> bool {
        let (d, w) = (f64::from(self.dry[bin]), f64::from(self.wet[bin]));
        d - w >= CHECK_Z * (d + w + 1.0).sqrt()
    }

    /// Counts the frame's lidar `samples`, and the verdicts of the stereo `(cloud, k)`
    /// registered to the image at `1/k` of its resolution, that land on colour water, then
    /// takes the water label from pixels of vetoed colours. Returns the pixels vetoed.
    fn run(
        &mut self,
        labels: &mut LabelImage,
        px: &[[u8; 3]],
        camera: &CameraModel,
        cam_to_map: &Pose,
        samples: &ScanSurface,
        stereo: Option<(&PointCloud, usize)>,
    ) -> u64 {
        let bins = 1 << (3 * CHECK_BITS);
        self.dry.resize(bins, 0);
        self.wet.resize(bins, 0);
        let (w, h) = (labels.width, labels.height);
        if let Some((cloud, k)) = stereo.filter(|(c, _)| c.len() == samples.stereo.len()) {
            let half = (k - 1) / 2;
            for (e, seen) in samples.stereo.iter().enumerate() {
                let dry = match seen {
                    StereoSeen::Nothing => continue,
                    StereoSeen::Ground => true,
                    StereoSeen::NotGround => false,
                };
                let (u, v) = (k * (e % cloud.cols) + half, k * (e / cloud.cols) + half);
                if u >= w || v >= h || !inside_water(labels, u, v) {
                    continue;
                }
                self.count(px[v * w + u], dry);
            }
        }
        let to_cam = cam_to_map.inverse();
        for (points, dry) in [(&samples.dry, true), (&samples.wet, false)] {
            for p in points {
                let Some([u, v]) = camera.project(&(to_cam * p)) else {
                    continue;
                };
                let (u, v) = (u.round(), v.round());
                if !(u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64) {
                    continue;
                }
                let (u, v) = (u as usize, v as usize);
                if !inside_water(labels, u, v) {
                    continue;
                }
                self.count(px[v * w + u], dry);
            }
        }
        let mut vetoed = 0;
        for (l, &c) in labels.data.iter_mut().zip(px) {
            if *l == Label::Water && self.vetoed(Self::bin(c)) {
                *l = Label::Unknown;
                vetoed += 1;
            }
        }
        vetoed
    }
}

/// The whole factor `k` by which a `w × h` image upsamples the organized stereo `cloud`
/// registered to it (element (row, col) is pixel block (k·row.., k·col..)); `None` when it
/// is not one.
fn stereo_factor(cloud: &PointCloud, w: usize, h: usize) -> Option<usize> {
    if !(cloud.is_organized() && cloud.cols > 0 && w % cloud.cols == 0) {
        return None;
    }
    let k = w / cloud.cols;
    (k > 0 && cloud.rows * k == h).then_some(k)
}

/// Sky-above-horizon rule with the cached rays: the same as
/// [`crate::classify::horizon::Horizon::apply`] with `sky_below_is_water` (sky colour below
/// the horizon is a reflection of the sky, i.e. water).
fn apply_horizon(labels: &mut LabelImage, map_rays: &[Option<Vector3<f64>>]) {
    for (l, r) in labels.data.iter_mut().zip(map_rays) {
        let above = r.is_none_or(|r| r.z >= 0.0);
        if above {
            if *l != Label::Unknown {
                *l = Label::Sky;
            }
        } else if *l == Label::Sky {
            *l = Label::Water;
        }
    }
}

/// Relative index of water.
const N_WATER: f64 = 1.33;
/// Tilt (rad) a ripple may give the water's normal in the reflection check: the Fresnel
/// reflectance is taken at the incidence this much more grazing.
const RIPPLE_TILT: f64 = 0.03;
/// Water's own (body) radiance is at most this fraction of the sky's, channel by channel:
/// an assumption (the water-leaving reflectance of clear to turbid water is a few per
/// cent to some 15 %, against a sky that is at least as bright as the light it sheds).
const BODY_FRACTION: f64 = 0.2;
/// Linear radiance margin for pixel noise (about 3 σ of 2 grey levels at mid-grey).
const NOISE_MARGIN: f64 = 0.02;
/// Channel values at or above this are saturated: the sky's radiance there is unknown.
const SATURATED: u8 = 250;

/// The sky reflection check of colour water: level water at incidence θ shows the sky in
/// the mirror direction times its Fresnel reflectance R(θ), plus its own body colour
/// (at most a fifth of the sky's radiance in each channel), so channel by channel a water
/// pixel is no brighter than `(R + 0.2 (1 − R))·S + noise`, S the sky radiance in the
/// mirror direction and R taken a ripple's tilt more grazing than θ. S comes from the same
/// image: the pixel the mirror direction falls on where it is in view and labelled sky,
/// else the brightest sky pixel of the image. A water pixel brighter than that (sunlit
/// pavement, a pale slab) is not a sky reflection and becomes `Other`. A saturated sky
/// channel, whose radiance is unknown, bounds nothing, and an image without sky is not
/// checked: the check says nothing where it cannot tell. Read as sRGB, linear data looks
/// darker against its sky, so an encoding assumed wrongly that way vetoes less, never
/// more. Returns the pixels vetoed.
pub fn reflection_check(
    labels: &mut LabelImage,
    px: &[[u8; 3]],
    map_rays: &[Option<Vector3<f64>>],
    camera: &CameraModel,
    cam_to_map: &Pose,
    encoding: Encoding,
) -> u64 {
    let lin = encoding.table();
    let (w, h) = (labels.width, labels.height);
    let sky_of =
        |i: usize| -> [Option<f64>; 3] { px[i].map(|v| (v < SATURATED).then(|| lin[v as usize])) };
    // The brightest sky of the image, per channel (a channel with a saturated sky pixel
    // has no bound).
    let mut fallback: Option<[Option<f64>; 3]> = None;
    for (i, l) in labels.data.iter().enumerate() {
        if *l == Label::Sky {
            let s = sky_of(i);
            fallback = Some(match fallback {
                None => s,
                Some(f) => std::array::from_fn(|c| match (f[c], s[c]) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    _ => None,
                }),
            });
        }
    }
    let Some(fallback) = fallback else {
        return 0;
    };
    let to_cam = cam_to_map.rotation.inverse();
    let mut vetoed = 0;
    for i in 0..labels.data.len() {
        if labels.data[i] != Label::Water {
            continue;
        }
        let Some(d) = map_rays[i] else { continue };
        let cos_i = -d.z / d.norm();
        if cos_i.is_nan() || cos_i <= 0.0 {
            continue;
        }
        let theta = (cos_i.min(1.0).acos() + RIPPLE_TILT).min(89.9f64.to_radians());
        let r = crate::optics::fresnel(theta, N_WATER).map_or(1.0, |f| 0.5 * (f.r_s + f.r_p));
        let k = r + BODY_FRACTION * (1.0 - r);
        let mirror = to_cam * Vector3::new(d.x, d.y, -d.z);
        let sky = camera
            .project(&Point3::from(mirror))
            .and_then(|[u, v]| {
                let (u, v) = (u.round(), v.round());
                (u >= 0.0 && v >= 0.0 && (u as usize) < w && (v as usize) < h)
                    .then(|| v as usize * w + u as usize)
            })
            .filter(|&j| labels.data[j] == Label::Sky)
            .map_or(fallback, sky_of);
        let outside =
            (0..3).any(|c| sky[c].is_some_and(|s| lin[px[i][c] as usize] > k * s + NOISE_MARGIN));
        if outside {
            labels.data[i] = Label::Other;
            vetoed += 1;
        }
    }
    vetoed
}

fn mono_of(img: &SensorImage) -> MonoImage {
    let data = match &img.image.pixels {
        Pixels::Rgb8(p) => p
            .iter()
            .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / 3.0)
            .collect(),
        Pixels::Mono8(p) => p.iter().map(|&v| v as f32).collect(),
        Pixels::Mono16(p) => p.iter().map(|&v| v as f32).collect(),
    };
    MonoImage {
        width: img.image.width,
        height: img.image.height,
        data,
    }
}

/// One sampled pixel's hit on the map.
#[derive(Debug, Clone, Copy)]
struct Hit {
    p: Point3<f64>,
    /// Labelled water.
    wet: bool,
    /// The water level its vote gives: the hit's height, or for water placed over a hole,
    /// see [`tighten_hole_levels`].
    level: f64,
    /// For water placed where its ray drops to a hole's rim level: the ray's height at the
    /// end of the hole. The water under the pixel lies between that and the hit.
    floor: Option<f64>,
}

impl Hit {
    fn at(p: Point3<f64>, wet: bool) -> Self {
        Hit {
            p,
            wet,
            level: p.z,
            floor: None,
        }
    }
}

/// The image rows to label: every `stride`-th, and every row whose ground footprint on
/// either side is wider than `cell` metres, so that no skipped row spans more than a cell.
/// The footprint between two rows is how far apart their rays meet level ground `height`
/// metres below the camera, the widest of the first, middle and last columns (infinite
/// where only one of the two reaches the ground: the horizon). It grows with the square of
/// the range (r² / (h f) for focal length f): with the simulated 320 × 240 camera 1.6 m
/// up, a row spans a 0.1 m cell from about 6 m on, and 1 m at 20 m.
fn sampled_rows(
    map_rays: &[Option<Vector3<f64>>],
    w: usize,
    stride: usize,
    height: f64,
    cell: f64,
) -> Vec<usize> {
    let h = map_rays.len() / w.max(1);
    let stride = stride.max(1);
    let ground = |r: &Option<Vector3<f64>>| match r {
        Some(r) if r.z < 0.0 && height > 0.0 => Some(height / -r.z * r.xy().norm()),
        _ => None,
    };
    let wide = |y: usize| {
        y + 1 < h
            && [0, w / 2, w.saturating_sub(1)].iter().any(|&x| {
                match (
                    ground(&map_rays[y * w + x]),
                    ground(&map_rays[(y + 1) * w + x]),
                ) {
                    (Some(a), Some(b)) => (a - b).abs() > cell,
                    (None, None) => false,
                    _ => true,
                }
            })
    };
    (0..h)
        .filter(|&y| y % stride == 0 || wide(y) || (y > 0 && wide(y - 1)))
        .collect()
}

/// Image neighbourhood (sampled pixels either side) over which water placed over holes
/// shares the tightest bound on its level.
const HOLE_LEVEL_WINDOW: usize = 8;

/// A water pixel whose ray crosses a hole (unobserved cells) is placed where the ray drops
/// to the lower of the hole's two rims: water lies at or below both, so that height is an
/// upper bound of the level, and the ray's height where the hole ends is a lower one. Where
/// the near rim is a bank top, the bound is decimetres above the water: on the simulated
/// stream, the level samples of the water seen along the channel stood 15 to 28 cm above
/// it. Every ray across the same water bounds the same level, so each such pixel's level is
/// the lowest upper bound among the hole-placed water pixels within [`HOLE_LEVEL_WINDOW`]
/// sampled pixels of it in the image (what is near in the image is one water surface; a
/// stream's level varies along it), but never below its own lower bound.
///
/// The pixel's vote then moves along its ray to where the ray meets the tightened level.
/// Where it was placed, at its own upper bound, is only the nearest place the water can be:
/// up to 3.7 m short of a pond 0.35 m below its banks, on the near bank, where its votes
/// made a band of water on dry ground and its shore cells lifted the pond's level to the
/// bank top. A hole with no far rim in reach (as on the simulated pond in the first
/// frames) has no lower bound but the ray's end, and its pixels move as far as their
/// window's lowest upper bound.
fn tighten_hole_levels(
    hits: &mut [Option<Hit>],
    nc: usize,
    origin: Point3<f64>,
    scratch: &mut Vec<f64>,
) {
    if nc == 0 {
        return;
    }
    let nr = hits.len() / nc;
    // Per sampled pixel its upper bound (∞: none), then the window minimum over columns.
    scratch.clear();
    scratch.extend(hits.iter().map(|h| match h {
        Some(h @ Hit { floor: Some(_), .. }) => h.p.z,
        _ => f64::INFINITY,
    }));
    if scratch.iter().all(|b| b.is_infinite()) {
        return;
    }
    let k = HOLE_LEVEL_WINDOW;
    let n = scratch.len();
    scratch.extend_from_within(..);
    let (upper, across) = scratch.split_at_mut(n);
    for (r, row) in across.chunks_mut(nc).enumerate() {
        let up = &upper[r * nc..(r + 1) * nc];
        for (c, a) in row.iter_mut().enumerate() {
            *a = up[c.saturating_sub(k)..(c + k + 1).min(nc)]
                .iter()
                .fold(f64::INFINITY, |a, &b| a.min(b));
        }
    }
    for (i, h) in hits.iter_mut().enumerate() {
        let Some(Hit {
            floor: Some(floor),
            level,
            p,
            ..
        }) = h
        else {
            continue;
        };
        let (r, c) = (i / nc, i % nc);
        let low = (r.saturating_sub(k)..(r + k + 1).min(nr))
            .map(|rr| across[rr * nc + c])
            .fold(f64::INFINITY, f64::min);
        *level = low.max(*floor).min(*level);
        if *level < p.z && p.z < origin.z {
            *p = origin + (*p - origin) * ((origin.z - *level) / (origin.z - p.z));
        }
    }
}

/// Calls `f(raster index, level)` once for every cell of `surface` that the quad of pixel
/// hits `q` = [a, b, c, d] overlaps (a = pixel (x, y), b = (x + s, y), c = (x, y + s),
/// d = (x + s, y + s); each (x, y, z, level)): the quad stands for the ground between the
/// four hits, and every cell it covers, even in part, gets the pixel's vote once. The quad
/// is split into the triangles a-b-d and a-d-c; a cell overlaps a triangle when no axis
/// separates them (x, y and the three edge normals). The level is interpolated linearly
/// over the triangle at the cell's centre. A cell that overlaps both triangles counts once.
fn quad_cells(surface: &GridSurface, q: [Vector4<f64>; 4], mut f: impl FnMut(usize, f64)) {
    if !q.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return;
    }
    let [a, b, c, d] = q;
    let res = surface.resolution();
    let (o, n) = (surface.origin(), surface.size() as i64);
    // The quad is split into the triangles a-b-d and a-d-c. Everything of a triangle that
    // does not depend on the cell is taken once (the same arithmetic, in the same order,
    // as a cell-by-cell barycentric test: the results are bit for bit those).
    let tris = [
        Tri::new([a, b, d], res, o, n),
        Tri::new([a, d, c], res, o, n),
    ];
    for (k, t) in tris.iter().enumerate() {
        let Some(t) = t else { continue };
        let [i0, i1, j0, j1] = t.range;
        for j in j0..=j1 {
            let y = (j as f64 + 0.5) * res;
            for i in i0..=i1 {
                let x = (i as f64 + 0.5) * res;
                let Some(l) = t.bary(x, y) else { continue };
                // A cell that overlaps both triangles counts once, with the first.
                if k == 1 && tris[0].as_ref().is_some_and(|t0| t0.overlaps(i, j, x, y)) {
                    continue;
                }
                let level = l[0] * t.p[0].w + l[1] * t.p[1].w + l[2] * t.p[2].w;
                f(((j - o.y) * n + (i - o.x)) as usize, level);
            }
        }
    }
}

/// One triangle of [`quad_cells`]: what the test of a cell against it needs, taken once.
struct Tri {
    p: [Vector4<f64>; 3],
    /// p1 − p0 and p2 − p0 (x, y).
    u: [f64; 2],
    v: [f64; 2],
    det: f64,
    /// Per vertex i: −half·(|e.x| + |e.y|) for the edge e opposite it: how far outside
    /// that edge (times |det|·|e|⁻¹) a cell centre may lie while the cell still reaches it.
    reach: [f64; 3],
    /// Cells (global keys) whose centres lie within half a cell of the bounding box,
    /// clipped to the window: i0, i1, j0, j1.
    range: [i64; 4],
}

impl Tri {
    /// `None` for a triangle without area (no cell overlaps it).
    fn new(p: [Vector4<f64>; 3], res: f64, o: CellKey, n: i64) -> Option<Self> {
        let [p0, p1, p2] = p;
        let (u, v) = ([p1.x - p0.x, p1.y - p0.y], [p2.x - p0.x, p2.y - p0.y]);
        let det = u[0] * v[1] - v[0] * u[1];
        if det.abs() <= f64::EPSILON * res * res {
            return None;
        }
        let half = 0.5 * res;
        let reach = std::array::from_fn(|i| {
            let e = p[(i + 1) % 3] - p[(i + 2) % 3];
            -half * (e.x.abs() + e.y.abs())
        });
        let lo = |v: fn(&Vector4<f64>) -> f64| p.iter().map(v).fold(f64::INFINITY, f64::min);
        let hi = |v: fn(&Vector4<f64>) -> f64| p.iter().map(v).fold(f64::NEG_INFINITY, f64::max);
        let first = |m: f64, origin: i64| ceil_i64((m - half) / res - 0.5).max(origin);
        let last = |m: f64, origin: i64| floor_i64((m + half) / res - 0.5).min(origin + n - 1);
        let range = [
            first(lo(|p| p.x), o.x),
            last(hi(|p| p.x), o.x),
            first(lo(|p| p.y), o.y),
            last(hi(|p| p.y), o.y),
        ];
        Some(Tri {
            p,
            u,
            v,
            det,
            reach,
            range,
        })
    }

    /// Barycentric coordinates of the centre (x, y), if the cell overlaps the triangle:
    /// `l[i]·|det| / |e|` is the distance of the centre inside the edge e opposite vertex
    /// i, and the cell reaches `(|e.x| + |e.y|)·half / |e|` beyond its centre along that
    /// edge's normal.
    #[inline]
    fn bary(&self, x: f64, y: f64) -> Option<[f64; 3]> {
        let (p0, [ux, uy], [vx, vy], det) = (&self.p[0], self.u, self.v, self.det);
        let l1 = ((x - p0.x) * vy - vx * (y - p0.y)) / det;
        let l2 = (ux * (y - p0.y) - (x - p0.x) * uy) / det;
        let l = [1.0 - l1 - l2, l1, l2];
        let ad = det.abs();
        (0..3).all(|i| l[i] * ad >= self.reach[i]).then_some(l)
    }

    /// Whether cell (i, j), centre (x, y), is in the range and overlaps the triangle.
    #[inline]
    fn overlaps(&self, i: i64, j: i64, x: f64, y: f64) -> bool {
        let [i0, i1, j0, j1] = self.range;
        (i0..=i1).contains(&i) && (j0..=j1).contains(&j) && self.bary(x, y).is_some()
    }
}

impl FrameLabels {
    /// A runner of the labels `cfg` names. Fails when `cfg` does not validate.
    pub fn new(cfg: FrameLabelConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(FrameLabels {
            cfg,
            caches: [None, None, None],
            tally: Vec::new(),
            touched: Vec::new(),
            raster: Vec::new(),
            colour_check: ColourCheck::default(),
            bufs: PixelBuffers::default(),
            zbuf: ZBuffer::default(),
        })
    }

    /// Bytes allocated per window cell between frames (capacities): the vote tally, the
    /// cells it touched and the elevation raster.
    pub fn heap_bytes(&self) -> usize {
        self.tally.capacity() * std::mem::size_of::<(u32, u32, f64)>()
            + self.touched.capacity() * std::mem::size_of::<u32>()
            + self.raster.capacity() * std::mem::size_of::<f32>()
            + self.zbuf.heap_bytes()
    }

    /// Classifies the frame's configured images, projects the labels and adds one vote per
    /// cell and sensor to `grid`'s evidence.
    pub fn apply(
        &mut self,
        frame: &Frame,
        grid: &mut RollingGrid,
        samples: Option<&ScanSurface>,
    ) -> Result<FrameLabelsReport> {
        let mut rep = FrameLabelsReport::default();
        let any = self.cfg.colour.is_some() || self.cfg.swir.is_some() || self.cfg.mwir.is_some();
        if !any {
            return Ok(rep);
        }
        let raster = std::mem::take(&mut self.raster);
        let surface = GridSurface::from_grid_gated_in(grid, self.cfg.surface_max_std, raster);
        let nn = surface.size() * surface.size();
        if self.tally.len() != nn {
            self.tally = vec![(0, 0, 0.0); nn];
        }
        let base = frame.base_to_map.translation.vector;
        let ground_z = match surface.elevation(base.x, base.y) {
            z if z.is_finite() => z as f64,
            _ => base.z,
        };
        for cue in [Cue::Colour, Cue::Swir, Cue::Mwir] {
            let (configured, img) = match cue {
                Cue::Colour => (self.cfg.colour.is_some(), &frame.image),
                Cue::Swir => (self.cfg.swir.is_some(), &frame.swir),
                Cue::Mwir => (self.cfg.mwir.is_some(), &frame.mwir),
            };
            if !configured {
                continue;
            }
            let mut st = SensorLabelStats::default();
            let usable = img.as_ref().and_then(|i| {
                let cam = i.camera.as_ref()?;
                let pose = i.frame_to_map.filter(pose_is_finite)?;
                (cam.width == i.image.width && cam.height == i.image.height)
                    .then_some((i, cam, pose))
            });
            let hour = match (cue, &self.cfg.mwir) {
                (Cue::Mwir, Some(m)) => m.hour_of(frame),
                _ => None,
            };
            match usable {
                None => st.frames_skipped += 1,
                Some(_) if cue == Cue::Mwir && hour.is_none() => st.frames_no_hour += 1,
                Some((img, cam, pose)) => {
                    if let Some(h) = hour {
                        let r = rep.mwir_hours.get_or_insert([h, h]);
                        *r = [r[0].min(h), r[1].max(h)];
                        st.frames_hour_from_stamp +=
                            u64::from(self.cfg.mwir.as_ref().is_some_and(|m| m.hour.is_none()));
                    }
                    st.frames = 1;
                    let stereo = if cue == Cue::Colour {
                        frame.stereo.as_ref()
                    } else {
                        None
                    };
                    rep.dropped += self.run(
                        cue, img, cam, &pose, stereo, hour, ground_z, &surface, samples, grid,
                        &mut st,
                    )?;
                }
            }
            match cue {
                Cue::Colour => rep.colour = Some(st),
                Cue::Swir => rep.swir = Some(st),
                Cue::Mwir => rep.mwir = Some(st),
            }
        }
        self.raster = surface.into_raster();
        Ok(rep)
    }

    /// One sensor's image in the frame: classified ([`Self::classify`]), its sampled pixels
    /// placed on the map ([`Placer`]), each pixel's votes spread over the cells its quad
    /// covers ([`quad_votes`]), tallied per cell, and one vote per cell added to `grid`
    /// ([`add_cell_votes`]). Returns the votes that fell outside the window.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        cue: Cue,
        img: &SensorImage,
        camera: &CameraModel,
        cam_to_map: &Pose,
        stereo: Option<&PointCloud>,
        hour: Option<f64>,
        ground_z: f64,
        surface: &GridSurface,
        samples: Option<&ScanSurface>,
        grid: &mut RollingGrid,
        st: &mut SensorLabelStats,
    ) -> Result<u64> {
        let FrameLabels {
            cfg,
            caches,
            tally,
            touched,
            colour_check,
            bufs,
            zbuf,
            ..
        } = self;
        let map_rays = RayCache::rays_in_map(&mut caches[cue as usize], camera, cam_to_map);
        let view = SensorView {
            cue,
            img,
            camera,
            cam_to_map,
            map_rays,
            stereo,
            hour,
            ground_z,
            samples,
        };
        let labels = Self::classify(cfg, &view, &mut bufs.labels, colour_check, st)?;
        let (w, h) = (camera.width, camera.height);
        let origin = Point3::from(cam_to_map.translation.vector);
        let max_range = cfg.max_range;
        let mut buf = std::mem::take(bufs);
        buf.cols.clear();
        buf.cols.extend((0..w).step_by(cfg.ray_stride));
        if cfg.wide_rows {
            buf.rows = sampled_rows(
                map_rays,
                w,
                cfg.ray_stride,
                cam_to_map.translation.z - ground_z,
                surface.resolution(),
            );
        } else {
            buf.rows.clear();
            buf.rows.extend((0..h).step_by(cfg.ray_stride));
        }
        let (nr, nc) = (buf.rows.len(), buf.cols.len());
        let zbuf = if cfg.sampler == Sampler::Zbuffer {
            zbuf.draw(
                surface, camera, cam_to_map, map_rays, &buf.rows, &buf.cols, max_range,
            );
            Some(&*zbuf)
        } else {
            None
        };
        let placer = Placer {
            labels: &labels,
            width: w,
            stereo: stereo.and_then(|c| Some((c, stereo_factor(c, w, h)?))),
            stereo_range: cfg.stereo_max_range.min(max_range),
            origin,
            zbuf,
            map_rays,
            surface,
            max_range,
            reach: samples.and_then(|l| l.reach.as_ref()),
        };
        placer.place_all(&buf.rows, &buf.cols, &mut buf.hits, &mut buf.counts);
        tighten_hole_levels(&mut buf.hits, nc, origin, &mut buf.levels);
        quad_votes(surface, &buf.hits, nr, nc, &mut buf.votes);
        for n in &buf.counts[..nr] {
            st.via_point += n[0];
            st.via_ray += n[1];
            st.no_hit += n[2];
            st.beyond_reach += n[3];
        }
        for l in &labels.data {
            match l {
                Label::Water => st.pixels_water += 1,
                Label::Other | Label::SnowIce => st.pixels_not_water += 1,
                _ => {}
            }
        }
        tally_votes(tally, touched, &buf.votes[..nr]);
        let dropped = add_cell_votes(tally, touched, cue, surface, grid, st);
        if cue == Cue::Colour {
            buf.labels = labels.data;
        }
        self.bufs = buf;
        Ok(dropped)
    }

    /// The labels of the view's image: colour through the lookup table
    /// ([`Self::classify_colour`]), SWIR darkness and MWIR thermal contrast over the ground
    /// geometry of the camera's rays.
    fn classify(
        cfg: &FrameLabelConfig,
        view: &SensorView<'_>,
        buf: &mut Vec<Label>,
        colour_check: &mut ColourCheck,
        st: &mut SensorLabelStats,
    ) -> Result<LabelImage> {
        let SensorView {
            img,
            camera,
            cam_to_map,
            map_rays,
            ground_z,
            ..
        } = *view;
        Ok(match view.cue {
            Cue::Colour => Self::classify_colour(cfg, view, buf, colour_check, st)?,
            Cue::Swir => {
                let g = GroundGeometry::of_rays(camera, map_rays, cam_to_map, ground_z);
                classify_swir(&mono_of(img), &g, None, cfg.swir.as_ref().expect("cfg"))?
            }
            Cue::Mwir => {
                let m = cfg.mwir.as_ref().expect("configured");
                let g = GroundGeometry::of_rays(camera, map_rays, cam_to_map, ground_z);
                let hour = view.hour.expect("an MWIR frame without an hour is skipped");
                classify_mwir(&mono_of(img), &g, hour, &m.classifier)?
            }
        })
    }

    /// The colour image's labels, into the storage `buf` (taken): each pixel through the
    /// lookup table, the horizon rule ([`apply_horizon`]), then the checks that veto colour
    /// water: against the sky it would reflect ([`reflection_check`]) and against what the
    /// log's lidar and stereo found under its colour ([`ColourCheck`]).
    fn classify_colour(
        cfg: &FrameLabelConfig,
        view: &SensorView<'_>,
        buf: &mut Vec<Label>,
        colour_check: &mut ColourCheck,
        st: &mut SensorLabelStats,
    ) -> Result<LabelImage> {
        let SensorView {
            img,
            camera,
            cam_to_map,
            map_rays,
            ..
        } = *view;
        let (w, h) = (camera.width, camera.height);
        let lut = cfg.colour.as_ref().expect("configured");
        let Pixels::Rgb8(px) = &img.image.pixels else {
            return Err(Error::invalid(
                "colour image",
                format!("{}: not a colour image", img.image.frame_id),
            ));
        };
        if px.len() != w * h {
            return Err(Error::invalid(
                "colour image",
                format!("{} pixels for {w} × {h}", px.len()),
            ));
        }
        let mut data = std::mem::take(buf);
        data.resize(w * h, Label::Other);
        // Rows in parallel; every label is written.
        data.par_chunks_mut(w.max(1))
            .zip(px.par_chunks(w.max(1)))
            .try_for_each(|(l, p)| lut.classify_into(p.as_flattened(), l))?;
        let mut l = LabelImage {
            width: w,
            height: h,
            data,
        };
        apply_horizon(&mut l, map_rays);
        if let Some(enc) = cfg.reflection_check {
            st.reflection_vetoed += reflection_check(&mut l, px, map_rays, camera, cam_to_map, enc);
        }
        if let Some(samples) = view.samples.filter(|_| cfg.colour_check) {
            let stereo = view.stereo.and_then(|c| Some((c, stereo_factor(c, w, h)?)));
            st.colour_check_vetoed +=
                colour_check.run(&mut l, px, camera, cam_to_map, samples, stereo);
        }
        Ok(l)
    }
}

/// One sensor's image in one frame, and what its labels are placed with.
struct SensorView<'a> {
    cue: Cue,
    img: &'a SensorImage,
    camera: &'a CameraModel,
    cam_to_map: &'a Pose,
    /// The camera's unit pixel rays in the map frame, row-major.
    map_rays: &'a [Option<Vector3<f64>>],
    /// The stereo cloud registered to the image (colour only).
    stereo: Option<&'a PointCloud>,
    /// The local solar hour (MWIR only).
    hour: Option<f64>,
    /// The ground's height under the vehicle.
    ground_z: f64,
    /// Where the frame's lidar found the surface dry or wet.
    samples: Option<&'a ScanSurface>,
}

/// How a sampled pixel finds its hit on the map: through its stereo point where it has
/// one within range, else by the march over the map, started where the z-buffer says its
/// ray first meets the map.
struct Placer<'a> {
    labels: &'a LabelImage,
    /// Image width, pixels.
    width: usize,
    /// The stereo cloud and the factor by which the image upsamples it.
    stereo: Option<(&'a PointCloud, usize)>,
    /// A stereo point places its pixel only up to this range (metres).
    stereo_range: f64,
    /// The camera's position in the map.
    origin: Point3<f64>,
    zbuf: Option<&'a ZBuffer>,
    map_rays: &'a [Option<Vector3<f64>>],
    surface: &'a GridSurface,
    max_range: f64,
    /// The lidar's dry reach: a hole beyond it is explained by range alone.
    reach: Option<&'a DryReach>,
}

impl Placer<'_> {
    /// Per sampled pixel (`rows` × `cols`, row-major into `hits`): its hit, whether it is
    /// water (`None`: no vote), and the water level it gives (see `tighten_hole_levels`);
    /// per sampled row into `counts`: pixels placed via a point, via a ray, not placed,
    /// beyond reach. Rows in parallel, into the buffers of the last frame.
    fn place_all(
        &self,
        rows: &[usize],
        cols: &[usize],
        hits: &mut Vec<Option<Hit>>,
        counts: &mut Vec<[u64; 4]>,
    ) {
        let (nr, nc) = (rows.len(), cols.len());
        hits.resize(nr * nc, None);
        // Zeroed here, not per row: a row without sampled columns (an image 0 pixels wide)
        // is never visited.
        counts.clear();
        counts.resize(nr, [0; 4]);
        hits.par_chunks_mut(nc.max(1))
            .zip(counts[..nr].par_iter_mut())
            .zip(rows.par_iter())
            .enumerate()
            .for_each(|(r, ((out, n), &y))| {
                for (ci, (slot, &x)) in out.iter_mut().zip(cols).enumerate() {
                    *slot = self.place(r * nc + ci, x, y, n);
                }
            });
    }

    /// The hit of pixel (x, y), sample `k` of the z-buffer, counted in `n` (via point, via
    /// ray, no hit, beyond reach); `None`: no vote.
    fn place(&self, k: usize, x: usize, y: usize, n: &mut [u64; 4]) -> Option<Hit> {
        let (origin, surface) = (self.origin, self.surface);
        let i = y * self.width + x;
        let water = match self.labels.data[i] {
            Label::Water => true,
            Label::Other | Label::SnowIce => false,
            Label::Sky | Label::Unknown => return None,
        };
        if let Some((c, f)) = self.stereo {
            let e = (y / f) * c.cols + x / f;
            if c.is_valid(e) {
                let p = c.point_in_map(e);
                if (p - origin).norm() <= self.stereo_range {
                    n[0] += 1;
                    return Some(Hit::at(p, water));
                }
            }
        }
        // With the z-buffer, the march starts where the ray first meets the drawn map; a
        // ray that meets nothing drawn meets no ground, and only water (placed in a hole at
        // its near rim's level) is marched.
        let mut after = 0.0;
        if let Some(zb) = self.zbuf {
            match zb.first(k) {
                Some(t) => after = t,
                None if water => {}
                None => {
                    n[2] += 1;
                    return None;
                }
            }
        }
        let cast = self.map_rays[i].and_then(|d| {
            surface
                .cast_through_holes_after(&origin, &d, self.max_range, after)
                .map(|h| (d, h))
        });
        // A hole beyond the dry reach is explained by range alone.
        if let (Some((_, (p, _, Some(_)))), Some(r)) = (cast, self.reach) {
            if !r.covers(p.x, p.y, 2.0 * surface.resolution()) {
                n[3] += 1;
                return None;
            }
        }
        match cast {
            // Only water is placed where the ray crosses a hole's rim level: whatever else
            // a pixel there shows (a bank the map has not seen, terrain reflected in the
            // water) is not at that level, and its vote would land on the water.
            Some((d, (p, _, hole))) if water || hole.is_none() => {
                n[1] += 1;
                let floor = hole.map(|t| origin.z + d.z * t);
                Some(Hit {
                    floor,
                    ..Hit::at(p, water)
                })
            }
            _ => {
                n[2] += 1;
                None
            }
        }
    }
}

/// Largest side (metres) of a pixel's quad that votes over the cells it covers: larger
/// ones straddle an occlusion edge.
const QUAD_MAX_M: f64 = 3.0;

/// The cell votes (raster index, water, level) of each sampled row of `hits` (`nr` × `nc`)
/// into `votes`, rows in parallel. Each sampled pixel stands for the quad spanned by its
/// hit and those of its right, lower and diagonal neighbours: when all four agree and the
/// quad is no larger than [`QUAD_MAX_M`], every cell the quad overlaps gets the vote once
/// (a pixel row covers a metre of ground at 20 m, far more than a cell; [`quad_cells`]);
/// otherwise only the pixel's own cell.
fn quad_votes(
    surface: &GridSurface,
    hits: &[Option<Hit>],
    nr: usize,
    nc: usize,
    votes: &mut Vec<Vec<(u32, bool, f32)>>,
) {
    if votes.len() < nr {
        votes.resize_with(nr, Vec::new);
    }
    votes[..nr].par_iter_mut().enumerate().for_each(|(r, out)| {
        out.clear();
        let row = &hits[r * nc..(r + 1) * nc];
        let next = hits.get((r + 1) * nc..(r + 2) * nc);
        for c in 0..nc {
            row_vote(surface, row, next, c, out);
        }
    });
}

/// The votes of sampled pixel `c` of `row` (the next row below: `next`) into `out`.
fn row_vote(
    surface: &GridSurface,
    row: &[Option<Hit>],
    next: Option<&[Option<Hit>]>,
    c: usize,
    out: &mut Vec<(u32, bool, f32)>,
) {
    let Some(h00) = row[c] else { return };
    let wet = h00.wet;
    let quad = next.and_then(|nx| {
        let q = [*row.get(c + 1)?.as_ref()?, nx[c]?, (*nx.get(c + 1)?)?];
        q.iter()
            .all(|h| h.wet == wet)
            .then_some([h00, q[0], q[1], q[2]])
    });
    // |a − b| ≤ QUAD_MAX_M as |a − b|² ≤ QUAD_MAX_M², the same verdict: the root is
    // correctly rounded and QUAD_MAX_M² exact.
    let quad = quad.filter(|q| {
        [(0, 1), (0, 2), (1, 3), (2, 3)]
            .iter()
            .all(|&(a, b)| (q[a].p - q[b].p).norm_squared() <= QUAD_MAX_M * QUAD_MAX_M)
    });
    match quad {
        None => {
            if let Some(j) = surface.index_of(h00.p.x, h00.p.y) {
                out.push((j as u32, wet, h00.level as f32));
            }
        }
        Some(q) => {
            let before = out.len();
            quad_cells(
                surface,
                q.map(|h| Vector4::new(h.p.x, h.p.y, h.p.z, h.level)),
                |j, level| out.push((j as u32, wet, level as f32)),
            );
            if out.len() == before {
                // A degenerate quad (no area, or a corner not finite): the pixel's own
                // cell.
                if let Some(j) = surface.index_of(h00.p.x, h00.p.y) {
                    out.push((j as u32, wet, h00.level as f32));
                }
            }
        }
    }
}

/// Adds the rows' `votes` to the per-cell `tally` (water pixels, other pixels, Σ level of
/// the water pixels), noting in `touched` each cell as it gets its first vote.
fn tally_votes(
    tally: &mut [(u32, u32, f64)],
    touched: &mut Vec<u32>,
    votes: &[Vec<(u32, bool, f32)>],
) {
    for out in votes {
        for &(j, water, z) in out {
            let t = &mut tally[j as usize];
            if t.0 == 0 && t.1 == 0 {
                touched.push(j);
            }
            if water {
                t.0 += 1;
                t.2 += z as f64;
            } else {
                t.1 += 1;
            }
        }
    }
}

/// One vote per `touched` cell of the `tally` (emptied), for the cue's water or dry
/// evidence: the majority of its pixels, a tie no vote, water with the mean of its levels
/// as a level sample. Returns the votes that fell outside `grid`'s window.
fn add_cell_votes(
    tally: &mut [(u32, u32, f64)],
    touched: &mut Vec<u32>,
    cue: Cue,
    surface: &GridSurface,
    grid: &mut RollingGrid,
    st: &mut SensorLabelStats,
) -> u64 {
    // Cells in raster order: deterministic whatever the thread count.
    touched.sort_unstable();
    let (nw, o) = (surface.size(), surface.origin());
    let z_ref = grid.config().z_ref;
    let mut dropped = 0;
    for &j in touched.iter() {
        let (wn, dn, zs) = std::mem::take(&mut tally[j as usize]);
        let mut e = Evidence::default();
        let vote = match wn.cmp(&dn) {
            std::cmp::Ordering::Greater => Some(true),
            std::cmp::Ordering::Less => Some(false),
            std::cmp::Ordering::Equal => None,
        };
        let Some(water) = vote else { continue };
        let (fw, fd) = match cue {
            Cue::Colour => (&mut e.colour_water, &mut e.colour_dry),
            Cue::Swir => (&mut e.swir_dark, &mut e.swir_lit),
            Cue::Mwir => (&mut e.mwir_water, &mut e.mwir_dry),
        };
        if water {
            *fw = 1;
            st.cells_water += 1;
            let level = zs / wn as f64;
            e.add_level(((level - z_ref) * 1000.0).round() as i32);
        } else {
            *fd = 1;
            st.cells_dry += 1;
        }
        let key = CellKey::new(
            o.x + (j as usize % nw) as i64,
            o.y + (j as usize / nw) as i64,
        );
        if !grid.add_evidence(key, &e) {
            dropped += 1;
        }
    }
    touched.clear();
    dropped
}

#[cfg(test)]
mod tests;
