//! The cue model of one lidar sensor: its optics, the diagnostic interval of no-return
//! evidence, and the greatest depth its bottom returns can come from at each lookahead.

use super::{BeamModel, LidarCueConfig};
use crate::cues::ReflectivityConfig;
use crate::error::{Error, Result};
use crate::grid::RangeNoise;
use crate::optics::{LidarModelConfig, LidarWaterModel};

/// A lidar sensor's cue model: the optics for its height, wavelength and water clarity,
/// the diagnostic interval, a table of the greatest visible depth against lookahead, and
/// its beam model. Build it once per sensor (and again if its height changes).
#[derive(Debug, Clone)]
pub struct LidarCueModel {
    pub(super) optics: LidarWaterModel,
    pub(super) beams: BeamModel,
    pub(super) cfg: LidarCueConfig,
    pub(super) reflectivity: Option<ReflectivityConfig>,
    pub(super) interval: Option<(f64, f64)>,
    pub(super) table_step: f64,
    pub(super) depth_table: Vec<f64>,
    pub(super) noise: RangeNoise,
}

impl LidarCueModel {
    /// `optics.height_m` is the sensor's height above the ground (and a water level there).
    pub fn new(
        optics: LidarModelConfig,
        beams: BeamModel,
        cfg: LidarCueConfig,
        reflectivity: Option<ReflectivityConfig>,
    ) -> Result<Self> {
        cfg.validate()?;
        if let Some(r) = &reflectivity {
            r.validate()?;
        }
        match &beams {
            BeamModel::Infer { max_gap_fraction }
                if max_gap_fraction.is_nan() || *max_gap_fraction < 0.0 =>
            {
                return Err(Error::invalid(
                    "beam model max_gap_fraction",
                    format!("{max_gap_fraction} is not a number ≥ 0"),
                ))
            }
            BeamModel::Spinning {
                elevations_rad,
                azimuth0_rad,
                ..
            } if !(elevations_rad.iter().all(|v| v.is_finite()) && azimuth0_rad.is_finite()) => {
                return Err(Error::invalid("beam model", "non-finite beam angle"))
            }
            BeamModel::Directions(d) if !d.iter().flatten().all(|v| v.is_finite()) => {
                return Err(Error::invalid("beam model", "non-finite beam direction"))
            }
            _ => {}
        }
        let optics = LidarWaterModel::new(optics)?;
        let interval = optics.diagnostic_interval(cfg.min_depth_m)?;
        let end = optics
            .dry_limit()
            .unwrap_or(optics.config().height_m)
            .max(1.0)
            * 1.2;
        let table_step = (end / 400.0).max(0.02);
        let n = (end / table_step).ceil() as usize + 2;
        let depth_table = (0..n)
            .map(|i| optics.max_depth(i as f64 * table_step))
            .collect::<Result<Vec<_>>>()?;
        Ok(LidarCueModel {
            optics,
            beams,
            cfg,
            reflectivity,
            interval,
            table_step,
            depth_table,
            noise: RangeNoise::LIDAR,
        })
    }

    /// The range noise of the scans' returns (default [`RangeNoise::LIDAR`]): it sets the
    /// below-level gate's noise floor ([`LidarCueConfig::below_gate_m`]).
    pub fn with_range_noise(mut self, noise: RangeNoise) -> Self {
        self.set_range_noise(noise);
        self
    }

    /// Sets whether the strength channel is range-compensated, as measured from the log
    /// ([`ReflectivityConfig::range_compensated`]; `None`: by the channel's name).
    pub fn set_range_compensated(&mut self, compensated: Option<bool>) {
        if let Some(r) = self.reflectivity.as_mut() {
            r.range_compensated = compensated;
        }
    }

    /// Sets the range noise of the returns in place ([`LidarCueModel::with_range_noise`]).
    pub fn set_range_noise(&mut self, noise: RangeNoise) {
        self.noise = noise;
    }

    /// The water optics model the cue uses.
    pub fn optics(&self) -> &LidarWaterModel {
        &self.optics
    }

    /// The cue's settings.
    pub fn config(&self) -> &LidarCueConfig {
        &self.cfg
    }

    /// Lookaheads (m) where a missing return is diagnostic of water.
    pub fn interval(&self) -> Option<(f64, f64)> {
        self.interval
    }

    /// Greatest depth (m) whose bottom returns at `lookahead` (table, linear in between;
    /// 0 beyond the table).
    pub fn max_visible_depth(&self, lookahead: f64) -> f64 {
        if lookahead.is_nan() || lookahead < 0.0 {
            return 0.0;
        }
        let t = lookahead / self.table_step;
        // Checked before the cast: a lookahead of 1e20 m saturates `as usize`.
        if t.is_nan() || t >= self.depth_table.len().saturating_sub(1) as f64 {
            return 0.0;
        }
        let i = t as usize;
        let f = t - i as f64;
        self.depth_table[i] * (1.0 - f) + self.depth_table[i + 1] * f
    }

    #[inline]
    pub(super) fn in_interval(&self, d: f64) -> bool {
        matches!(self.interval, Some((a, b)) if d >= a && d <= b)
    }
}
