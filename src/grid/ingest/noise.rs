//! The range noise model: how a range sensor's elevation noise grows with range.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Elevation noise of a range sensor against range `r` (metres from the sensor):
/// `σ(r) = sigma0 + per_m·r + per_m2·r²`. Lidar is close to constant (beam divergence adds a
/// little per metre); stereo grows with the square of range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeNoise {
    /// Noise at zero range, metres.
    pub sigma0: f64,
    /// Coefficient of `r` (metres of σ per metre of range).
    pub per_m: f64,
    /// Coefficient of `r²`, per metre.
    pub per_m2: f64,
}

impl RangeNoise {
    /// A spinning lidar: 2 cm, plus 1 mm per metre.
    pub const LIDAR: RangeNoise = RangeNoise {
        sigma0: 0.02,
        per_m: 0.001,
        per_m2: 0.0,
    };
    /// A stereo camera (f·B ≈ 150 px·m, 0.25 px disparity noise): σ_z ≈ r²·0.25/150.
    pub const STEREO: RangeNoise = RangeNoise {
        sigma0: 0.005,
        per_m: 0.0,
        per_m2: 0.0017,
    };

    /// A range-independent noise.
    pub const fn constant(sigma: f64) -> Self {
        RangeNoise {
            sigma0: sigma,
            per_m: 0.0,
            per_m2: 0.0,
        }
    }

    /// Elevation standard deviation at range `r` metres, metres.
    #[inline]
    pub fn sigma(&self, r: f64) -> f64 {
        self.sigma0 + r * (self.per_m + r * self.per_m2)
    }

    /// Checks that `sigma0` is positive and every term finite and non-negative.
    pub fn validate(&self) -> Result<()> {
        let ok = self.sigma0.is_finite()
            && self.sigma0 > 0.0
            && self.per_m.is_finite()
            && self.per_m >= 0.0
            && self.per_m2.is_finite()
            && self.per_m2 >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                "range noise",
                format!(
                    "sigma0 {} m, per_m {}, per_m2 {} (sigma0 must be > 0, all finite and >= 0)",
                    self.sigma0, self.per_m, self.per_m2
                ),
            ))
        }
    }
}

impl Default for RangeNoise {
    fn default() -> Self {
        RangeNoise::LIDAR
    }
}
