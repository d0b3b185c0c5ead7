//! Optics of lidar over water (paper section 3, re-derived): Snell and Fresnel at the surface,
//! water absorption against wavelength from a measured table, the return power from a water
//! bottom and from dry ground, and what follows from them: the greatest measurable depth at
//! each lookahead, the lookahead interval where a missing return is diagnostic of water, and
//! the correction of bottom returns for refraction and the speed of light in water.
//!
//! Conventions: angles in radians (reports in degrees say so), lengths in metres, z up. The
//! *lookahead* is the horizontal distance from the sensor to where the beam meets the water.
//!
//! Exports: the surface ([`snell`], [`fresnel`] and its [`Fresnel`], [`brewster_angle`]);
//! absorption ([`AbsorptionTable`], [`absorption_per_m`], [`ice_absorption_per_m`],
//! [`loss_distance_m`]); the lidar model ([`LidarWaterModel`], its [`LidarModelConfig`],
//! [`Attenuation`], [`Sensitivity`], [`SolidAngleForm`], [`PathGeometry`] and its
//! [`LidarModelReport`] of [`LidarModelRow`]s); bottom returns ([`correct_bottom_return`],
//! [`apparent_bottom_point`], [`bottom_depth_gain`]); thermal emission in the mid-wave
//! infrared ([`water_reflectance_mwir`], [`apparent_temperature`]).
//!
//! ```
//! use tarn::optics::{Attenuation, LidarModelConfig, LidarWaterModel};
//! let m = LidarWaterModel::new(LidarModelConfig::paper(Attenuation::PureWater {
//!     wavelength_nm: 625.0,
//! }))?;
//! // Clear water: over 1.5 m of depth measurable 4 m ahead of a 1 m high sensor.
//! assert!(m.max_depth(4.0)? > 1.5);
//! let (start, end) = m.diagnostic_interval(0.3)?.expect("dry ground returns");
//! assert!(start < end && (end - 11.0).abs() < 1e-9);
//! # Ok::<(), tarn::Error>(())
//! ```

mod absorption;
mod correction;
mod data;
mod fresnel;
mod lidar;
mod thermal;

pub use absorption::{absorption_per_m, ice_absorption_per_m, loss_distance_m, AbsorptionTable};
pub use correction::{apparent_bottom_point, bottom_depth_gain, correct_bottom_return};
pub use fresnel::{brewster_angle, fresnel, snell, Fresnel};
pub use lidar::{
    Attenuation, LidarModelConfig, LidarModelReport, LidarModelRow, LidarWaterModel, PathGeometry,
    Sensitivity, SolidAngleForm,
};
pub use thermal::{apparent_temperature, water_reflectance_mwir};
pub(crate) use thermal::{brightness_temperature, planck_rel, MWIR_UM};

#[cfg(test)]
mod tests;
