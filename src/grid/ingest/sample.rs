//! A point reduced to what the grid needs ([`Sample`]): its cell, its height, its weight
//! and the share of its range noise that reaches its height.

use super::bin::floor_small;
use crate::grid::cell::vertical_weight;

/// A point reduced to what the grid needs.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sample {
    pub(super) idx: u32,
    pub(super) z_mm: i32,
    /// The weight (low [`W_BITS`] bits) and the code of the share of the point's noise
    /// that reaches its height (the rest, [`share_code`]): one word, so that a sample
    /// stays 16 bytes.
    pub(super) wv: u32,
    pub(super) sigma_mm: f32,
}

/// Bits of [`Sample::wv`] that hold the weight (up to
/// [`W_MAX`](crate::grid::cell::W_MAX) = 2²⁴).
pub(super) const W_BITS: u32 = 25;

/// The vertical share `s` (0.05..1) as a 7-bit code: `round(127·√s)`, which keeps the
/// share to 4 % and its square to 7 % at the 0.05 floor, less above it.
#[inline]
pub(super) fn share_code(share: f64) -> u32 {
    floor_small(127.0 * share.sqrt() + 0.5).1 as u32
}

impl Sample {
    #[inline]
    pub(super) fn w(&self) -> u32 {
        self.wv & ((1 << W_BITS) - 1)
    }

    /// The vertical weight ([`vertical_weight`]) from the weight, the share's code and
    /// the range noise.
    #[inline]
    pub(super) fn q(&self) -> u32 {
        let c = f64::from(self.wv >> W_BITS) / 127.0;
        vertical_weight(self.w(), c * c, f64::from(self.sigma_mm) * 1e-3)
    }

    /// Filler of the sort buffer (every slot is written before it is read).
    pub(super) const ZERO: Sample = Sample {
        idx: 0,
        z_mm: 0,
        wv: 0,
        sigma_mm: 0.0,
    };
}

/// Smallest share of a point's range noise that reaches its height: the sine of the
/// most grazing ray (about 3°) whose vertical error is still taken from its range error.
/// Below it, the beam's footprint and the ground's roughness across it, not the range
/// noise, decide the height, and they do not shrink with the angle.
const MIN_VERTICAL_SHARE: f64 = 0.05;

/// The share of a point's range noise that reaches its height: a range sensor errs along
/// its ray, so a point `dz` metres above or below the sensor at `range` is `|dz|/range`
/// of its range error off in height (at least [`MIN_VERTICAL_SHARE`]). A grazing lidar
/// return at 20 m is a few millimetres off in height although its range is centimetres
/// off; a point straight below the sensor carries all of it.
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` would keep a NaN
pub(super) fn vertical_share(dz: f64, range: f64) -> f64 {
    // `f64::max` takes the floor over a NaN (a point at the sensor).
    (dz.abs() / range).max(MIN_VERTICAL_SHARE).min(1.0)
}
