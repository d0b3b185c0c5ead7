//! The bound on how bright a ground return water could give: the brightest recent
//! ground of the scan line, the bed allowed brighter than its bank, and the optics' loss
//! through the shallowest water. A ground return brighter than that is dry.

use std::collections::VecDeque;

use super::LidarCueModel;

impl LidarCueModel {
    /// The optics' loss through the shallowest water at lookahead `d`:
    /// [`LidarWaterModel::return_ratio`] at zero depth over
    /// [`LidarWaterModel::dry_ratio`] (Fresnel transmission in and out, and the steeper
    /// refracted beam on the bottom). NaN where the optics give none.
    pub(super) fn shallowest_loss(&self, d: f64) -> f64 {
        match (self.optics.return_ratio(d, 0.0), self.optics.dry_ratio(d)) {
            (Ok(w), Ok(g)) if g > 0.0 => w / g,
            _ => f64::NAN,
        }
    }
}

/// Ground returns along a scan line whose brightest bounds what the bottom of water there
/// could return ([`bright_reference`]).
pub(super) const BRIGHT_WINDOW: usize = 16;

/// How much brighter than the ground before it the bed of water may be, at the lidar's
/// wavelength: natural surfaces span about 0.1 (wet dark soil) to 0.6 (pale sand, dry
/// concrete) in albedo, and a bed three times its bank (sand or gravel under soil and
/// grass) is allowed before a return at the level is called brighter than water allows.
pub(super) const BED_BRIGHTER: f64 = 3.0;

/// The brightest of a line's recent ground returns after its two brightest: a return
/// normalised as level ground that is not (a kerb's vertical face, met head-on and divided
/// by the grazing incidence of the ground around it, comes out several times brighter
/// than the ground) is one or two beams of a line, and must not raise the bound the
/// ground after it is judged by. With fewer than three returns, the brightest.
pub(super) fn bright_reference(bright: &VecDeque<f64>) -> Option<f64> {
    let mut top = [f64::NEG_INFINITY; 3];
    for &v in bright.iter().filter(|v| !v.is_nan()) {
        if v > top[0] {
            top = [v, top[0], top[1]];
        } else if v > top[1] {
            top = [top[0], v, top[1]];
        } else if v > top[2] {
            top[2] = v;
        }
    }
    match top {
        [a, _, _] if a == f64::NEG_INFINITY => None,
        [a, _, c] if c == f64::NEG_INFINITY => Some(a),
        [_, _, c] => Some(c),
    }
}
