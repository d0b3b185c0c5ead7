//! How far dry ground returned along each azimuth of a scan ([`DryReach`]): the scan's
//! own limit on where a missing return says anything of water.

/// How far dry ground returned along each azimuth of one scan: the farthest lookahead of a
/// ground return per azimuth bin, from the sensor's position. A cell that no sensor saw
/// (a hole in the map) inside that reach is a hole where dry ground would have returned,
/// which water explains; a hole beyond it is explained by range alone (smooth or dark ground
/// at grazing incidence stops returning) and says nothing of water.
#[derive(Debug, Clone, PartialEq)]
pub struct DryReach {
    origin: [f64; 2],
    /// Farthest ground-return lookahead per azimuth bin (m): 0 where lines of the scan
    /// returned no ground, NaN where the scan has no line (a sensor that does not look
    /// there says nothing of it).
    bins: Vec<f32>,
}

impl DryReach {
    /// Azimuth bins over the full turn (0.5° each).
    pub const BINS: usize = 720;

    /// From each scan line's azimuth (rad, map frame) and the farthest lookahead its dry
    /// ground returned from (0 for none). Each bin holds the farthest of its lines; lines
    /// with a non-finite azimuth are ignored, a non-finite or negative reach counts as 0.
    pub fn new(origin: [f64; 2], lines: impl IntoIterator<Item = (f64, f64)>) -> Self {
        let mut bins = vec![f32::NAN; Self::BINS];
        for (az, far) in lines {
            if let Some(b) = Self::bin(az) {
                let far = if far.is_finite() && far > 0.0 {
                    far as f32
                } else {
                    0.0
                };
                // `f32::max` takes the other operand over a NaN.
                bins[b] = bins[b].max(far);
            }
        }
        DryReach { origin, bins }
    }

    fn bin(az: f64) -> Option<usize> {
        if !az.is_finite() {
            return None;
        }
        let t = az.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU;
        Some(((t * Self::BINS as f64) as usize).min(Self::BINS - 1))
    }

    /// The reach (m) towards map point (x, y): the farthest of its bin and the two beside
    /// it (a column between two scan lines is seen by both); 0 where lines there returned
    /// no ground, infinite where the scan has no line there (a vertical scanner looks one
    /// way only).
    pub fn reach_towards(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let Some(b) = Self::bin(dy.atan2(dx)) else {
            return 0.0;
        };
        let n = Self::BINS;
        let near = [(b + n - 1) % n, b, (b + 1) % n].map(|i| self.bins[i]);
        if near.iter().all(|v| v.is_nan()) {
            return f64::INFINITY;
        }
        near.into_iter().fold(0f32, f32::max) as f64
    }

    /// Whether map point (x, y) lies within the reach of dry ground along its azimuth,
    /// with `margin` metres of slack.
    pub fn covers(&self, x: f64, y: f64, margin: f64) -> bool {
        let d = crate::geom::hypot(x - self.origin[0], y - self.origin[1]);
        d <= self.reach_towards(x, y) + margin
    }
}

#[cfg(test)]
mod tests {
    use super::DryReach;
    use proptest::prelude::*;

    #[test]
    fn reach_is_per_azimuth_and_wraps_around() {
        let r = DryReach::new(
            [100.0, -50.0],
            [
                (0.0, 20.0),
                (std::f64::consts::FRAC_PI_2, 8.0),
                // Just below +π and just above −π: the same direction, two ends of the bins.
                (std::f64::consts::PI - 1e-4, 12.0),
                (f64::NAN, 99.0),
                (1.0, f64::INFINITY),
            ],
        );
        assert_eq!(r.reach_towards(115.0, -50.0), 20.0);
        assert_eq!(r.reach_towards(100.0, -40.0), 8.0);
        assert_eq!(r.reach_towards(90.0, -50.0 - 1e-6), 12.0);
        assert!(r.covers(119.0, -50.0, 0.0) && !r.covers(121.0, -50.0, 0.5));
        // No line towards −y: the scan says nothing there, and gates nothing.
        assert_eq!(r.reach_towards(100.0, -60.0), f64::INFINITY);
        assert!(r.covers(100.0, -1e6, 0.0));
        // A line that returned no ground: nothing covered along it.
        let none = DryReach::new([0.0, 0.0], [(0.0, 0.0), (0.1, f64::NAN)]);
        assert_eq!(none.reach_towards(5.0, 0.0), 0.0);
        assert!(!none.covers(5.0, 0.0, 0.2) && !none.covers(5.0, 0.5, 0.2));
    }

    proptest! {
        /// Whatever the lines, the reach towards any point is finite, non-negative, and at
        /// least that of a line pointing straight at it.
        #[test]
        fn reach_bounds(
            lines in prop::collection::vec((-10.0f64..10.0, -1e3f64..1e3), 0..50),
            x in -1e6f64..1e6, y in -1e6f64..1e6,
        ) {
            let r = DryReach::new([0.0, 0.0], lines.iter().copied());
            let got = r.reach_towards(x, y);
            prop_assert!(got >= 0.0 && (got.is_finite() || got == f64::INFINITY));
            let az = y.atan2(x);
            let direct = DryReach::new([0.0, 0.0], [(az, 5.0)]);
            prop_assert!(direct.reach_towards(x, y) == 5.0 || x == 0.0 && y == 0.0);
        }
    }
}
