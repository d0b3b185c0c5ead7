//! A cue's false-alarm rate measured from the log ([`FalseAlarms`], one per labelling camera
//! in [`LabelFalseAlarms`]), and the fusion rule that uses it in place of the stated one
//! ([`Fusion::measured`]).

use serde::{Deserialize, Serialize};

use super::Fusion;

/// One-sided 95 % point of the standard normal: the bound [`FalseAlarms::upper_bound`] takes.
const BOUND_Z: f64 = 1.645;

/// Samples of dry ground that a labelling cue saw, and how many of them it called water:
/// its false-alarm rate, measured from the log. The samples are what the log's lidar found
/// to be dry ground (returns water would not give) projected into the cue's image; a
/// sample counts as a false alarm when its pixel is labelled water after every check the
/// labels pass. Counts merge by
/// sums, like the cells' statistics, so the rate of many logs is the rate of their sums.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FalseAlarms {
    /// Dry-ground samples whose pixel was labelled (water or not).
    pub samples: u64,
    /// Of them, those labelled water.
    pub water: u64,
}

impl FalseAlarms {
    /// Adds another log's (or frame's) counts.
    pub fn merge(&mut self, o: &FalseAlarms) {
        self.samples = self.samples.saturating_add(o.samples);
        self.water = self.water.saturating_add(o.water);
    }

    /// The one-sided 95 % upper bound of the false-alarm rate (Wilson's score interval):
    /// the rate the samples cannot rule out, so that few samples never make a cue look
    /// better than they show. `None` without samples.
    pub fn upper_bound(&self) -> Option<f64> {
        if self.samples == 0 {
            return None;
        }
        let n = self.samples as f64;
        let p = (self.water.min(self.samples) as f64) / n;
        let z2 = BOUND_Z * BOUND_Z;
        let centre = p + z2 / (2.0 * n);
        let spread = BOUND_Z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
        Some(((centre + spread) / (1.0 + z2 / n)).min(1.0))
    }
}

/// The false alarms of each labelling camera that the log's lidar can check: colour and
/// SWIR. (MWIR's contrast is of temperature, which the lidar's dry ground does not bound.)
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LabelFalseAlarms {
    /// The colour labels'.
    pub colour: FalseAlarms,
    /// The SWIR labels'.
    #[serde(default)]
    pub swir: FalseAlarms,
}

impl LabelFalseAlarms {
    /// Adds another log's (or frame's) counts.
    pub fn merge(&mut self, o: &LabelFalseAlarms) {
        self.colour.merge(&o.colour);
        self.swir.merge(&o.swir);
    }
}

impl Fusion {
    /// The rule with each labelling camera's false-alarm rate measured from the log in
    /// place of the stated one (`p_colour_false`, `p_swir_false`), where its switch
    /// ([`Fusion::colour_false_from_log`], [`Fusion::swir_false_from_log`]) is on and there
    /// are samples: the rate's 95 % upper bound ([`FalseAlarms::upper_bound`]). A rate as
    /// high as the cue's detection rate makes its votes no evidence either way (both ratios
    /// 1), never evidence against what they say.
    pub fn measured(&self, a: &LabelFalseAlarms) -> Fusion {
        let mut f = *self;
        let rate = |alarms: &FalseAlarms, on: bool, detect: f64| {
            let p = alarms.upper_bound().filter(|_| on)?;
            Some(p.clamp(f64::MIN_POSITIVE, detect))
        };
        if let Some(p) = rate(&a.colour, self.colour_false_from_log, self.p_colour_detect) {
            f.p_colour_false = p;
        }
        if let Some(p) = rate(&a.swir, self.swir_false_from_log, self.p_swir_detect) {
            f.p_swir_false = p;
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn no_samples_keep_the_stated_rate() {
        let f = Fusion::default();
        assert_eq!(FalseAlarms::default().upper_bound(), None);
        assert_eq!(f.measured(&LabelFalseAlarms::default()), f);
    }

    #[test]
    fn the_bound_is_wilsons() {
        // 0 of 100: z² / (n + z²).
        let b = FalseAlarms {
            samples: 100,
            water: 0,
        };
        let z2 = BOUND_Z * BOUND_Z;
        assert!((b.upper_bound().unwrap() - z2 / (100.0 + z2)).abs() < 1e-12);
        // 10 of 100: the upper end of the 90 % two-sided Wilson interval, 0.0612–0.1604.
        let b = FalseAlarms {
            samples: 100,
            water: 10,
        };
        assert!((b.upper_bound().unwrap() - 0.1604).abs() < 1e-4, "{b:?}");
    }

    #[test]
    fn a_rate_as_high_as_detection_makes_votes_no_evidence() {
        let high = FalseAlarms {
            samples: 1000,
            water: 900,
        };
        let f = Fusion::default().measured(&LabelFalseAlarms {
            colour: high,
            swir: high,
        });
        assert_eq!(f.p_colour_false, f.p_colour_detect);
        assert_eq!(f.p_swir_false, f.p_swir_detect);
        let l = f.logs();
        let mut e = crate::grid::Evidence::default();
        e.add_image_vote(crate::grid::Cue::Colour, true);
        e.add_image_vote(crate::grid::Cue::Colour, false);
        assert_eq!(e.cue_log_odds(&f)[crate::grid::Cue::Colour], 0.0);
        assert!(f.validate().is_ok(), "{l:?}");
    }

    #[test]
    fn off_keeps_the_stated_rate() {
        let f = Fusion {
            colour_false_from_log: false,
            swir_false_from_log: false,
            ..Fusion::default()
        };
        let few = FalseAlarms {
            samples: 1_000_000,
            water: 3,
        };
        let many = LabelFalseAlarms {
            colour: few,
            swir: few,
        };
        assert_eq!(f.measured(&many), f);
        let m = Fusion::default().measured(&many);
        assert!(m.p_colour_false < 1e-4 && m.p_swir_false < 1e-4, "{m:?}");
        // Each camera's rate from its own samples only.
        let colour_only = Fusion::default().measured(&LabelFalseAlarms {
            colour: few,
            ..Default::default()
        });
        assert_eq!(colour_only.p_swir_false, Fusion::default().p_swir_false);
    }

    proptest! {
        #[test]
        fn the_bound_lies_above_the_rate_and_falls_with_samples(
            n in 1u64..10_000_000,
            frac in 0.0f64..=1.0,
        ) {
            let k = (n as f64 * frac) as u64;
            let a = FalseAlarms { samples: n, water: k };
            let b = a.upper_bound().unwrap();
            prop_assert!(b >= k as f64 / n as f64 - 1e-12 && b <= 1.0, "{a:?} {b}");
            // Ten times the samples at the same rate: a bound no higher.
            let more = FalseAlarms { samples: n * 10, water: k * 10 };
            prop_assert!(more.upper_bound().unwrap() <= b + 1e-12);
            let f = Fusion::default().measured(&LabelFalseAlarms { colour: a, swir: a });
            prop_assert!(f.validate().is_ok());
            prop_assert!(f.p_colour_false <= f.p_colour_detect);
            prop_assert!(f.p_swir_false <= f.p_swir_detect);
        }

        #[test]
        fn merging_is_summing(a in 0u64..1 << 40, b in 0u64..1 << 40, c in 0u64..1 << 40, d in 0u64..1 << 40) {
            let (x, y) = (FalseAlarms { samples: a.max(b), water: a.min(b) }, FalseAlarms { samples: c.max(d), water: c.min(d) });
            let (mut xy, mut yx) = (x, y);
            xy.merge(&y);
            yx.merge(&x);
            prop_assert_eq!(xy, yx);
            prop_assert_eq!(xy.samples, x.samples + y.samples);
        }
    }
}
