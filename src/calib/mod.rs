//! Sensor calibration measured from the log itself.
//!
//! A log rarely carries its whole calibration: drivers leave out the right camera's
//! `CameraInfo`, publish a zero baseline, name a raw intensity `reflectivity`, and nobody
//! knows their stereo pair's disparity noise. The cues' false-alarm rates depend on these
//! values, so the mapper measures them from the data it maps (the stereo pair's noise, the
//! lidar's range noise and intensity law), checks what it is told against the measurement
//! ([`resolve`]), and assumes nothing optimistic:
//!
//! - a measured value is used, and a stated one (the log's or the config's, a rig file's)
//!   that it contradicts by more than [`DISAGREEMENT`]× either way is reported with a
//!   warning;
//! - a stated value is used until a measurement exists;
//! - a value neither stated nor measured yet is taken at the noisy end of real sensors
//!   ([`NOISY_STEREO_PER_M2`], [`NOISY_LIDAR`]), and the stereo reflection cue, whose
//!   false alarms depend on it, places no evidence until it is known.
//!
//! [`Calibration`] holds the estimators of one mapper and writes the [`CalibrationReport`]
//! each frame: every value used, its [`Source`], and the measurement beside any stated one.
//! Each sensor is measured over its first [`Calibration::FRAMES`] frames and the value is
//! then held; an offline build measures them before it maps the first frame
//! ([`crate::mapper::Mapper::calibrate`]), so every frame of a log, and every piece a
//! distributed build cuts it into, is fused with the same noise.
//!
//! Exports: [`Calibration`] and its [`CalibrationReport`] ([`StereoCalibration`],
//! [`LidarCalibration`]); the stated values ([`StereoStated`], [`Sourced`], [`Source`]) and
//! [`resolve`] with its [`Resolved`]; the measurements ([`StereoMeasurement`] and its
//! [`StereoMethod`], [`LidarMeasurement`], [`IntensityLaw`]); the thresholds
//! [`DISAGREEMENT`], [`NOISY_STEREO_PER_M2`], [`NOISY_LIDAR`].

mod lidar;
pub(crate) mod robust;
mod stereo;

use serde::{Deserialize, Serialize};

use crate::geom::PointCloud;
use crate::grid::RangeNoise;
pub use lidar::{IntensityLaw, LidarMeasurement};
pub use stereo::{StereoMeasurement, StereoMethod};

/// A stated value and a measurement of it disagree when one exceeds the other by more than
/// this factor.
pub const DISAGREEMENT: f64 = 1.5;

/// The stereo noise coefficient (1/m, σ_z = a + c·z²) taken while it is neither stated nor
/// measured: a small binned pair (f ≈ 230 px, B = 6 cm, σ_d = 0.4 px) or a noisy matcher;
/// about twice the noisiest rig tarn is tested with.
pub const NOISY_STEREO_PER_M2: f64 = 0.03;

/// The lidar range noise taken while it is neither stated nor measured: 3 cm plus 1 mm per
/// metre, the noisy end of spinning lidars' datasheets.
pub const NOISY_LIDAR: RangeNoise = RangeNoise {
    sigma0: 0.03,
    per_m: 0.001,
    per_m2: 0.0,
};

/// Where a value the mapper used came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// The log: a `CameraInfo`, the scan's shape, its TF.
    Log,
    /// The mapper config (a rig file given to `tarn build --rig` goes there).
    Config,
    /// Measured from the log's own data.
    Measured,
    /// Nothing stated it and it could not be measured yet: the noisy end of real sensors.
    Default,
}

/// A value and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sourced {
    /// The value.
    pub value: f64,
    /// Where it came from.
    pub source: Source,
}

/// What [`resolve`] decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    /// The value to use, and where it came from.
    pub used: Sourced,
    /// Set when a stated value and the measurement disagree by more than [`DISAGREEMENT`]×.
    pub warning: Option<String>,
}

/// The value to use for `what` (named in the warning): the measurement when there is one
/// (a stated value it contradicts by more than [`DISAGREEMENT`]× either way is warned
/// about), else the stated value, else `noisy` as a [`Source::Default`]. Non-finite or
/// non-positive inputs count as absent.
pub fn resolve(what: &str, stated: Option<Sourced>, measured: Option<f64>, noisy: f64) -> Resolved {
    let stated = stated.filter(|s| s.value.is_finite() && s.value >= 0.0);
    let measured = measured.filter(|m| m.is_finite() && *m > 0.0);
    match (stated, measured) {
        (Some(s), Some(m)) => {
            let ratio = if s.value > 0.0 {
                (m / s.value).max(s.value / m)
            } else {
                f64::INFINITY
            };
            let warning = (ratio > DISAGREEMENT).then(|| {
                format!(
                    "{what}: stated {:.4e} ({}) but measured {m:.4e} from the log, {ratio:.2}× \
                     apart; the measurement is used",
                    s.value,
                    source_name(s.source)
                )
            });
            Resolved {
                used: Sourced {
                    value: m,
                    source: Source::Measured,
                },
                warning,
            }
        }
        (None, Some(m)) => Resolved {
            used: Sourced {
                value: m,
                source: Source::Measured,
            },
            warning: None,
        },
        (Some(s), None) => Resolved {
            used: s,
            warning: None,
        },
        (None, None) => Resolved {
            used: Sourced {
                value: noisy,
                source: Source::Default,
            },
            warning: None,
        },
    }
}

fn source_name(s: Source) -> &'static str {
    match s {
        Source::Log => "the log",
        Source::Config => "the config or rig file",
        Source::Measured => "measured",
        Source::Default => "assumed",
    }
}

/// What the stereo pair's calibration came to.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StereoCalibration {
    /// What the log and the config state (its fields stand in this one's JSON object).
    #[serde(flatten)]
    pub stated: StereoStated,
    /// c of σ_z = a + c·z² (1/m) from what is stated (σ_d·k/(f·B)), when all of it is.
    pub stated_per_m2: Option<f64>,
    /// c measured from the log.
    pub measured: Option<StereoMeasurement>,
    /// c measured against the lidar and from plane fits, each when it has enough samples.
    pub measured_by_lidar_per_m2: Option<f64>,
    /// See `measured_by_lidar_per_m2`.
    pub measured_by_planes_per_m2: Option<f64>,
    /// σ_d the measurement implies with the stated focal length, binning and baseline.
    pub implied_disparity_noise_px: Option<f64>,
    /// The c used (last frame), and its source.
    pub used_per_m2: Option<Sourced>,
    /// Frames the measurement rests on.
    pub measured_frames: u64,
    /// Frames whose stereo reflection cue waited for the noise to be known.
    pub frames_waited: u64,
}

/// What the lidar's calibration came to.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LidarCalibration {
    /// Range noise at zero range (m) stated by the config or rig file.
    pub stated_sigma0_m: Option<f64>,
    /// Range noise measured from the scans (`σ(r) = sigma0 + per_m·r`).
    pub measured: Option<LidarMeasurement>,
    /// Scans the measurement rests on.
    pub measured_frames: u64,
    /// The range noise used (last frame): σ0 and its source.
    pub used_sigma0_m: Option<Sourced>,
    /// The range noise used, whole.
    pub used_noise: Option<RangeNoise>,
    /// The sensor's height above the ground (m): the config's, or measured from the scans.
    pub height_m: Option<Sourced>,
    /// What the strength channel is, from how it falls with range over the ground.
    pub intensity_law: Option<IntensityLaw>,
}

/// Every sensor value the mapper used, where it came from, and what was measured.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// The stereo pair (absent without stereo clouds).
    pub stereo: Option<StereoCalibration>,
    /// The lidar (absent without lidar scans).
    pub lidar: Option<LidarCalibration>,
    /// Datasheet values the log cannot carry and nothing stated (they hold the config's
    /// defaults): what the mapper assumed.
    pub assumed: Vec<String>,
    /// Cues that waited, and why.
    pub waited: Vec<String>,
    /// Stated values the measurements contradict, and channels that are not what their
    /// names say.
    pub warnings: Vec<String>,
}

/// The stereo values a frame and the config state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StereoStated {
    /// Focal length of the left camera (px, its `CameraInfo`).
    pub focal_px: Option<f64>,
    /// Image width over cloud width (the log's image and cloud).
    pub binning: Option<usize>,
    /// The baseline: the right camera's `CameraInfo`, else the config.
    pub baseline_m: Option<Sourced>,
    /// The disparity noise σ_d (px of the disparity image) the config or rig file states.
    pub disparity_noise_px: Option<Sourced>,
}

impl StereoStated {
    /// c = σ_d·k/(f·B) when every part is stated.
    pub fn per_m2(&self) -> Option<f64> {
        let (f, k, b, s) = (
            self.focal_px?,
            self.binning?,
            self.baseline_m?.value,
            self.disparity_noise_px?.value,
        );
        let c = s * k as f64 / (f * b);
        (f > 0.0 && b > 0.0 && c.is_finite() && c >= 0.0).then_some(c)
    }
}

/// The estimators of one mapper and what they came to.
#[derive(Debug, Clone, Default)]
pub struct Calibration {
    stereo: stereo::StereoNoiseEstimator,
    lidar: lidar::LidarNoiseEstimator,
    law: lidar::IntensityLawEstimator,
    /// Frames each estimator was shown, and frames offered in all.
    stereo_frames: u64,
    lidar_frames: u64,
    frames: u64,
    stereo_estimate: Option<StereoMeasurement>,
    lidar_estimate: Option<LidarMeasurement>,
    /// Every value held as it is now ([`Calibration::hold`]).
    held: bool,
    report: CalibrationReport,
}

impl Calibration {
    /// A sensor's noise is measured over its first this many frames, and then held: the
    /// noise of a sensor does not change along a log, and a value held fixed keeps the map
    /// of a log independent of how it is cut into pieces ([`Calibration::is_settled`]).
    /// A sensor whose noise could not be measured yet keeps being measured.
    pub const FRAMES: u64 = 20;

    /// Whether every sensor seen has its measurement held, after at least
    /// [`Calibration::FRAMES`] frames: an offline build measures the log's first frames
    /// until then before it maps any ([`crate::mapper::Mapper::calibrate`]).
    pub fn is_settled(&self) -> bool {
        let held = |seen: u64, measured: bool| seen == 0 || (seen >= Self::FRAMES && measured);
        self.frames >= Self::FRAMES
            && held(self.lidar_frames, self.lidar_estimate.is_some())
            && held(self.stereo_frames, self.stereo_estimate.is_some())
    }

    /// Holds every value as it is now, measured or not: an offline build does so after
    /// measuring the log's first frames, so that no piece of the log is fused with values
    /// another piece did not have.
    pub fn hold(&mut self) {
        self.held = true;
    }

    /// Counts one frame offered (whatever sensors it has).
    pub(crate) fn count_frame(&mut self) {
        self.frames += 1;
    }

    /// Measures one lidar scan (until its measurement is held): its range noise, and how
    /// the channel `strength` reads falls with range ([`Calibration::range_compensated`]).
    /// Returns the range noise to use: the measured, else `stated`, else [`NOISY_LIDAR`].
    pub fn lidar_noise(
        &mut self,
        scan: &PointCloud,
        stated: Option<RangeNoise>,
        strength: &crate::cues::ReflectivityConfig,
    ) -> RangeNoise {
        let held =
            self.held || (self.lidar_frames >= Self::FRAMES && self.lidar_estimate.is_some());
        if !held {
            self.lidar.observe(scan);
            self.lidar_frames += 1;
            self.lidar_estimate = self.lidar.estimate();
            if let Some((e, channel)) = lidar::scan_falloff(scan, strength) {
                self.intensity_falloff(e, channel);
            }
        }
        let r = resolve(
            "lidar range noise σ0 (m)",
            stated.map(|n| Sourced {
                value: n.sigma0,
                source: Source::Config,
            }),
            self.lidar_estimate.map(|m| m.noise.sigma0),
            NOISY_LIDAR.sigma0,
        );
        let noise = match (r.used.source, self.lidar_estimate, stated) {
            (Source::Measured, Some(m), _) => m.noise,
            (_, _, Some(s)) => s,
            _ => NOISY_LIDAR,
        };
        let l = self.report.lidar.get_or_insert_with(Default::default);
        l.stated_sigma0_m = stated.map(|n| n.sigma0);
        l.measured = self.lidar_estimate;
        l.measured_frames = self.lidar_frames;
        l.used_sigma0_m = Some(r.used);
        l.used_noise = Some(noise);
        set_warning(&mut self.report.warnings, "lidar range noise", r.warning);
        noise
    }

    /// Records the lidar's height and where it came from.
    pub(crate) fn set_lidar_height(&mut self, height: Option<Sourced>) {
        if let Some(l) = self.report.lidar.as_mut() {
            l.height_m = height;
        }
    }

    /// Whether the lidar's strength channel is range-compensated, as measured (`None`
    /// before a scan's ground could be fitted).
    pub fn range_compensated(&self) -> Option<bool> {
        let law = self.report.lidar.as_ref()?.intensity_law.as_ref()?;
        Some(law.range_compensated)
    }

    /// Adds one scan's fitted intensity falloff, read from `channel`.
    fn intensity_falloff(&mut self, exponent: f64, channel: &'static str) {
        self.law.observe(exponent, channel);
        let law = self.law.estimate();
        let warning = law.as_ref().and_then(|l| {
            let named_compensated = l.channel == "reflectivity";
            (named_compensated != l.range_compensated).then(|| {
                format!(
                    "lidar channel `{}` falls as r^{:.2} over the ground: it behaves as {}, \
                     and is read as such",
                    l.channel,
                    l.falloff_exponent,
                    if l.range_compensated {
                        "a range-compensated reflectivity"
                    } else {
                        "a raw intensity, not range-compensated"
                    }
                )
            })
        });
        set_warning(&mut self.report.warnings, "lidar channel", warning);
        self.report
            .lidar
            .get_or_insert_with(Default::default)
            .intensity_law = law;
    }

    /// Measures one stereo cloud (against `lidar`, the frame's scan, when there is one) and
    /// returns the noise coefficient c to use and whether it is known (stated or
    /// measured): when it is not, the stereo reflection cue must wait.
    pub fn stereo_noise(
        &mut self,
        cloud: &PointCloud,
        lidar: Option<&PointCloud>,
        stated: StereoStated,
    ) -> (Sourced, bool) {
        let held =
            self.held || (self.stereo_frames >= Self::FRAMES && self.stereo_estimate.is_some());
        if !held {
            self.stereo.observe(cloud, lidar);
            self.stereo_frames += 1;
            // Each method once; the lidar's is preferred ([`stereo::StereoNoiseEstimator::estimate`]).
            let (by_lidar, by_planes) = (self.stereo.by_lidar(), self.stereo.by_planes());
            self.stereo_estimate = by_lidar.or(by_planes);
            let s = self.report.stereo.get_or_insert_with(Default::default);
            s.measured_by_lidar_per_m2 = by_lidar.map(|m| m.per_m2);
            s.measured_by_planes_per_m2 = by_planes.map(|m| m.per_m2);
        }
        let stated_c = stated.per_m2();
        let r = resolve(
            "stereo noise coefficient c of σ_z = a + c·z² (1/m)",
            stated_c.map(|c| Sourced {
                value: c,
                // The least certain of its parts: σ_d is rarely in a log.
                source: stated
                    .disparity_noise_px
                    .map_or(Source::Config, |s| s.source),
            }),
            self.stereo_estimate.map(|m| m.per_m2),
            NOISY_STEREO_PER_M2,
        );
        let known = r.used.source != Source::Default;
        let s = self.report.stereo.get_or_insert_with(Default::default);
        s.stated = stated;
        s.stated_per_m2 = stated_c;
        s.measured = self.stereo_estimate;
        s.measured_frames = self.stereo_frames;
        s.implied_disparity_noise_px = match (self.stereo_estimate, stated) {
            (
                Some(m),
                StereoStated {
                    focal_px: Some(f),
                    binning: Some(k),
                    baseline_m: Some(b),
                    ..
                },
            ) => Some(m.per_m2 * f * b.value / k as f64),
            _ => None,
        };
        s.used_per_m2 = Some(r.used);
        if !known {
            s.frames_waited += 1;
            let why = format!(
                "stereo reflections: waited {} frame(s) for the stereo noise ({}; not yet \
                 measurable from the log); the cloud was fused with the noisy-end c = {} /m",
                s.frames_waited,
                missing_parts(&stated),
                NOISY_STEREO_PER_M2
            );
            self.report
                .waited
                .retain(|w| !w.starts_with("stereo reflections:"));
            self.report.waited.push(why);
        }
        set_warning(&mut self.report.warnings, "stereo noise", r.warning);
        (r.used, known)
    }

    /// Records the datasheet values that were assumed ([`CalibrationReport::assumed`]).
    pub(crate) fn set_assumed(&mut self, assumed: Vec<String>) {
        self.report.assumed = assumed;
    }

    /// What the calibration came to so far.
    pub fn report(&self) -> &CalibrationReport {
        &self.report
    }
}

/// What of σ_d·k/(f·B) the log and the config leave out.
fn missing_parts(s: &StereoStated) -> String {
    let mut v = Vec::new();
    if s.focal_px.is_none() {
        v.push("no left CameraInfo (focal length)");
    }
    if s.baseline_m.is_none() {
        v.push("no baseline (the right CameraInfo is absent or has P[0][3] = 0, and no stereo.baseline_m)");
    }
    if s.disparity_noise_px.is_none() {
        v.push("no disparity noise σ_d (stereo.disparity_noise_px, or a rig file)");
    }
    if v.is_empty() {
        "all parts stated".into()
    } else {
        v.join("; ")
    }
}

/// Keeps one warning per `key`: the latest.
fn set_warning(list: &mut Vec<String>, key: &str, w: Option<String>) {
    list.retain(|x| !x.starts_with(key));
    if let Some(w) = w {
        list.push(format!("{key}: {w}"));
    }
}

#[cfg(test)]
mod tests;
