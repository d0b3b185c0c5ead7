//! What the water and hazard stage is configured with: the fusion rule, the water
//! bodies' search and fit, and the vehicle the hazards are judged for.

use serde::{Deserialize, Serialize};

use crate::error::{check, Error, Result};
use crate::grid::{Fusion, LabelFalseAlarms, TileMap};
use crate::water::WaterConfig;

/// What the vehicle can drive through.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Vehicle {
    /// Deepest water the vehicle may ford (m).
    pub fording_depth_m: f64,
    /// Highest step between neighbouring cells it can climb (m).
    pub max_step_m: f64,
    /// Steepest slope it can drive (degrees).
    pub max_slope_deg: f64,
}

impl Default for Vehicle {
    fn default() -> Self {
        Vehicle {
            fording_depth_m: 0.3,
            max_step_m: 0.25,
            max_slope_deg: 25.0,
        }
    }
}

impl Vehicle {
    /// Checks that the depth and step are finite and non-negative (the step positive) and the
    /// slope strictly between 0 and 90 degrees; the error names the bad field.
    pub fn validate(&self) -> Result<()> {
        check::non_negative("vehicle.fording_depth_m", self.fording_depth_m)?;
        check::positive("vehicle.max_step_m", self.max_step_m)?;
        let slope = self.max_slope_deg;
        if slope > 0.0 && slope < 90.0 {
            Ok(())
        } else {
            Err(Error::invalid(
                "vehicle.max_slope_deg",
                format!("{slope} must lie strictly between 0 and 90"),
            ))
        }
    }
}

/// Everything the water and hazard stage needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct HazardConfig {
    /// The evidence fusion rule.
    pub fusion: Fusion,
    /// Water body segmentation and surface fitting.
    pub water: WaterConfig,
    /// What the vehicle can drive through.
    pub vehicle: Vehicle,
}

impl HazardConfig {
    /// Checks every part; the error names the bad field.
    pub fn validate(&self) -> Result<()> {
        self.fusion.validate()?;
        self.water.validate()?;
        self.vehicle.validate()
    }

    /// The config with the fusion rule measured on the logs of `tiles`
    /// ([`Fusion::measured`] of [`TileMap::false_alarms`]).
    pub fn measured_on(&self, tiles: &TileMap) -> HazardConfig {
        self.measured(&tiles.false_alarms())
    }

    /// The config with the fusion rule measured on the colour and SWIR labels' false
    /// alarms `alarms` ([`Fusion::measured`]).
    pub fn measured(&self, alarms: &LabelFalseAlarms) -> HazardConfig {
        HazardConfig {
            fusion: self.fusion.measured(alarms),
            ..*self
        }
    }

    /// Reads a JSON config; unknown fields are errors naming the file.
    pub fn from_json_file(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let cfg: HazardConfig = serde_json::from_str(&text).map_err(|e| {
            Error::format(
                path,
                format!("line {} column {}", e.line(), e.column()),
                e.to_string(),
            )
        })?;
        cfg.validate()?;
        Ok(cfg)
    }
}
