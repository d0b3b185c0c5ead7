//! The lidar's range noise and intensity law, measured from the log.
//!
//! **Range noise.** Along one ring of an organized scan, neighbouring returns from a
//! smooth surface lie at ranges that change smoothly with azimuth (on level ground from a
//! level sensor, not at all). The second difference `r[i−1] − 2·r[i] + r[i+1]` of three
//! such returns is then the noise alone, with variance 6·σ_r². Its median absolute
//! deviation, over many triples, is a σ that edges, mixed pixels and vegetation (a
//! minority) do not move; rough ground makes it larger, never smaller. Binned by range,
//! the σ's give `σ(r) = σ0 + per_m·r`.
//!
//! **Intensity law.** The reflectivity cue fits, per scan, how its channel falls with range
//! over the scan's ground ([`crate::cues::ChannelLaw`]): an exponent near −3 for a raw
//! intensity of Lambertian ground (cos θ / r², with cos θ = h/r on level ground), near −1
//! for a range-compensated reflectivity. The median exponent over the scans says which the
//! channel is, whatever its name, and the incidence exponent m that remains.

use serde::{Deserialize, Serialize};

use super::robust::{mad_sigma, median, Pool};
use crate::geom::PointCloud;
use crate::grid::RangeNoise;

/// Range bands of the noise fit (m): [1, 10), [10, 20), [20, 40].
const BANDS: [(f64, f64); 3] = [(1.0, 10.0), (10.0, 20.0), (20.0, 40.0)];
/// Triples kept per band (the newest), and offered per scan at most.
const POOL: usize = 30_000;
const PER_SCAN: usize = 20_000;
/// Triples a band needs before its σ counts.
pub(crate) const MIN_SAMPLES: usize = 300;

/// A measured lidar range noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LidarMeasurement {
    /// σ(r) = sigma0 + per_m·r.
    pub noise: RangeNoise,
    /// Triples it rests on.
    pub samples: usize,
}

/// Measures the lidar's range noise over the scans it is shown.
#[derive(Debug, Clone)]
pub(crate) struct LidarNoiseEstimator {
    /// Second differences and the middle return's range, per band.
    bands: Vec<Pool<[f32; 2]>>,
}

impl Default for LidarNoiseEstimator {
    fn default() -> Self {
        LidarNoiseEstimator {
            bands: BANDS.iter().map(|_| Pool::new(POOL)).collect(),
        }
    }
}

impl LidarNoiseEstimator {
    /// Adds one organized scan (rings × azimuth columns; a scan of one or two columns, a
    /// vertical scanner, is walked down its column).
    pub(crate) fn observe(&mut self, scan: &PointCloud) {
        // Walk the rings (rows); a scan of one or two columns, down its column.
        let along_rows = scan.cols >= 3;
        let (lines, len) = if along_rows {
            (scan.rows, scan.cols)
        } else {
            (scan.cols, scan.rows)
        };
        let at = |l: usize, k: usize| {
            if along_rows {
                scan.index(l, k)
            } else {
                scan.index(k, l)
            }
        };
        if len < 3 {
            return;
        }
        let o = scan.sensor_origin.coords;
        let range = |i: usize| -> Option<f64> {
            if !scan.is_valid(i) {
                return None;
            }
            let q = scan.xyz[i];
            let r = (nalgebra::Vector3::new(q[0] as f64, q[1] as f64, q[2] as f64) - o).norm();
            r.is_finite().then_some(r)
        };
        let stride = (lines * len).div_ceil(PER_SCAN).max(1);
        let mut n = 0usize;
        for l in 0..lines {
            for k in 1..len - 1 {
                n += 1;
                if n % stride != 0 {
                    continue;
                }
                let (Some(a), Some(b), Some(c)) =
                    (range(at(l, k - 1)), range(at(l, k)), range(at(l, k + 1)))
                else {
                    continue;
                };
                // Three returns from one smooth surface: not across an edge.
                if (c - a).abs() > 0.05 * b {
                    continue;
                }
                if let Some(band) = BANDS.iter().position(|&(lo, hi)| b >= lo && b < hi) {
                    self.bands[band].push([(a - 2.0 * b + c) as f32, b as f32]);
                }
            }
        }
    }

    /// The range noise measured so far (`None` until a band has [`MIN_SAMPLES`]).
    pub fn estimate(&self) -> Option<LidarMeasurement> {
        // (mean range, σ, samples) of each band with enough triples.
        let pts: Vec<(f64, f64, f64)> = self
            .bands
            .iter()
            .filter(|p| p.len() >= MIN_SAMPLES)
            .filter_map(|p| {
                let s = mad_sigma(p.iter().map(|t| t[0] as f64))? / 6f64.sqrt();
                let r = p.iter().map(|t| t[1] as f64).sum::<f64>() / p.len() as f64;
                Some((r, s, p.len() as f64))
            })
            .collect();
        if pts.is_empty() {
            return None;
        }
        let samples = pts.iter().map(|p| p.2).sum::<f64>();
        let (mr, ms) = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), p| (a + p.0 * p.2, b + p.1 * p.2));
        let (mr, ms) = (mr / samples, ms / samples);
        // Weighted least squares of σ on r; a falling σ is a constant one.
        let (sxx, sxy) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
            (
                a + p.2 * (p.0 - mr).powi(2),
                b + p.2 * (p.0 - mr) * (p.1 - ms),
            )
        });
        let per_m = if pts.len() >= 2 && sxx > 0.0 {
            (sxy / sxx).max(0.0)
        } else {
            0.0
        };
        // A σ that the fit takes below 5 mm at zero range is held there, and the slope
        // refitted through it: no lidar is that precise near by.
        const FLOOR: f64 = 0.005;
        let (sigma0, per_m) = if ms - per_m * mr >= FLOOR {
            (ms - per_m * mr, per_m)
        } else {
            let (srr, srs) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
                (a + p.2 * p.0 * p.0, b + p.2 * p.0 * (p.1 - FLOOR))
            });
            (FLOOR, if srr > 0.0 { (srs / srr).max(0.0) } else { 0.0 })
        };
        let noise = RangeNoise {
            sigma0,
            per_m,
            per_m2: 0.0,
        };
        (noise.validate().is_ok()).then_some(LidarMeasurement {
            noise,
            samples: samples as usize,
        })
    }
}

/// What the lidar's strength channel is, from the falloff exponents its scans' ground
/// followed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntensityLaw {
    /// The channel read: `reflectivity` or `intensity`.
    pub channel: String,
    /// Median over the scans of the fitted exponent of the value against range.
    pub falloff_exponent: f64,
    /// Whether the channel behaves as range-compensated (exponent above −2: the ground's
    /// incidence alone), as opposed to a raw intensity that also falls as 1/r².
    pub range_compensated: bool,
    /// The incidence exponent m of the ground's backscatter (cosᵐθ; 1 for Lambertian)
    /// that remains once the channel's convention is taken out; `None` where that leaves a
    /// value outside 0–4, which no surface has: the mix of surfaces along the scan, not
    /// the incidence, then decides how the channel falls.
    pub incidence_exponent: Option<f64>,
    /// Scans the median is over.
    pub scans: usize,
}

/// How the strength channel `cfg` reads falls with range over one scan's ground: the
/// exponent of [`crate::cues::ChannelLaw`] fitted to the returns whose beams drop 3–45°
/// below the horizontal in the map (mostly the ground around the vehicle), and the
/// channel's name; `None` without such a fit.
pub(crate) fn scan_falloff(
    scan: &PointCloud,
    cfg: &crate::cues::ReflectivityConfig,
) -> Option<(f64, &'static str)> {
    let name = crate::cues::channel_name(scan, cfg)?;
    let o = scan.sensor_origin_in_map();
    let (lo, hi) = (3f64.to_radians().sin(), 45f64.to_radians().sin());
    let samples: Vec<(f64, f64)> = (0..scan.len())
        .filter(|&i| scan.is_valid(i))
        .filter_map(|i| {
            let v = scan.point_in_map(i) - o;
            let r = v.norm();
            let s = -v.z / r;
            if !(s >= lo && s <= hi && r >= cfg.min_range_m && r <= cfg.max_range_m) {
                return None;
            }
            crate::cues::channel_value(scan, i, cfg).map(|(x, _)| (x, r))
        })
        .collect();
    crate::cues::ChannelLaw::fit(&samples, cfg.min_samples).map(|l| (l.exponent, name))
}

/// Collects the scans' fitted falloff exponents.
#[derive(Debug, Clone)]
pub(crate) struct IntensityLawEstimator {
    exponents: Pool<f64>,
    channel: Option<&'static str>,
}

impl Default for IntensityLawEstimator {
    fn default() -> Self {
        IntensityLawEstimator {
            exponents: Pool::new(1000),
            channel: None,
        }
    }
}

impl IntensityLawEstimator {
    /// Adds one scan's fitted exponent and the channel it was read from.
    pub(crate) fn observe(&mut self, exponent: f64, channel: &'static str) {
        if exponent.is_finite() {
            self.exponents.push(exponent);
            self.channel = Some(channel);
        }
    }

    /// The law so far (`None` before a scan was fitted).
    pub fn estimate(&self) -> Option<IntensityLaw> {
        let mut e: Vec<f64> = self.exponents.iter().copied().collect();
        let falloff_exponent = median(&mut e)?;
        let range_compensated = falloff_exponent > -2.0;
        let m = if range_compensated {
            -falloff_exponent
        } else {
            -falloff_exponent - 2.0
        };
        let incidence_exponent = (0.0..=4.0).contains(&m).then_some(m);
        Some(IntensityLaw {
            channel: self.channel?.to_string(),
            falloff_exponent,
            range_compensated,
            incidence_exponent,
            scans: e.len(),
        })
    }
}
