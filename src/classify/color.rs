//! The paper's colour features and its Table 1 statistics as a rule baseline.
//!
//! Brightness I = (R+G+B)/3 and saturation S = 1 − min(R,G,B)/I (0 for a black pixel).
//! Table 1 of the paper (Fort Indiantown Gap, manually segmented) gives per-class mean and
//! standard deviation of I and S:
//!
//! | class | I mean | I std | S mean | S std |
//! | --- | --- | --- | --- | --- |
//! | sky | 253.4 | 4.0 | 0.0067 | 0.014 |
//! | water | 176.0 | 37.6 | 0.21 | 0.091 |
//! | rest of image | 106.2 | 27.0 | 0.29 | 0.10 |
//!
//! [`RuleClassifier`] treats each row as an axis-aligned Gaussian in (I, S) and picks the most
//! likely class (equal priors). Clipped sky (255, 255, 255) has I = 255, S = 0: it is sky by
//! colour. Below the horizon such a pixel is a reflection of the sky, i.e. water; that
//! decision belongs to [`super::horizon::Horizon::apply`], which knows where the horizon is.

use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Label, LabelImage};

/// Brightness I = (R+G+B)/3, 0..255.
#[inline]
pub fn brightness([r, g, b]: [u8; 3]) -> f32 {
    (r as f32 + g as f32 + b as f32) / 3.0
}

/// Saturation S = 1 − min(R,G,B)/I, 0..1; 0 for black.
#[inline]
pub fn saturation(rgb: [u8; 3]) -> f32 {
    let i = brightness(rgb);
    if i <= 0.0 {
        return 0.0;
    }
    let m = rgb[0].min(rgb[1]).min(rgb[2]) as f32;
    1.0 - m / i
}

/// Mean and standard deviation of brightness and saturation for one class.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClassStats {
    /// Mean brightness ([`brightness`]), 0..255.
    pub brightness_mean: f32,
    /// Standard deviation of brightness.
    pub brightness_std: f32,
    /// Mean saturation ([`saturation`]), 0..1.
    pub saturation_mean: f32,
    /// Standard deviation of saturation.
    pub saturation_std: f32,
}

impl ClassStats {
    /// Log-likelihood (up to a shared constant) of an (I, S) pair.
    fn log_lik(&self, i: f32, s: f32) -> f32 {
        let di = (i - self.brightness_mean) / self.brightness_std;
        let ds = (s - self.saturation_mean) / self.saturation_std;
        -0.5 * (di * di + ds * ds) - (self.brightness_std * self.saturation_std).ln()
    }
}

/// Rule baseline from the paper's Table 1: maximum likelihood over sky, water and the rest
/// with axis-aligned Gaussians in (brightness, saturation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RuleClassifier {
    /// Sky pixels.
    pub sky: ClassStats,
    /// Water pixels.
    pub water: ClassStats,
    /// Everything else.
    pub rest: ClassStats,
}

impl Default for RuleClassifier {
    /// The values printed in the paper's Table 1.
    fn default() -> Self {
        RuleClassifier {
            sky: ClassStats {
                brightness_mean: 253.4,
                brightness_std: 4.0,
                saturation_mean: 0.0067,
                saturation_std: 0.014,
            },
            water: ClassStats {
                brightness_mean: 176.0,
                brightness_std: 37.6,
                saturation_mean: 0.21,
                saturation_std: 0.091,
            },
            rest: ClassStats {
                brightness_mean: 106.2,
                brightness_std: 27.0,
                saturation_mean: 0.29,
                saturation_std: 0.10,
            },
        }
    }
}

impl RuleClassifier {
    /// Label of one pixel.
    pub fn classify_pixel(&self, rgb: [u8; 3]) -> Label {
        let (i, s) = (brightness(rgb), saturation(rgb));
        let ls = self.sky.log_lik(i, s);
        let lw = self.water.log_lik(i, s);
        let lr = self.rest.log_lik(i, s);
        if lw >= ls && lw >= lr {
            Label::Water
        } else if ls >= lr {
            Label::Sky
        } else {
            Label::Other
        }
    }

    /// Labels of a whole image (rows in parallel; the result does not depend on threads).
    pub fn classify(&self, img: &RgbImage) -> LabelImage {
        let w = img.width() as usize;
        let raw = img.as_raw();
        let mut data = vec![Label::Other; raw.len() / 3];
        data.par_chunks_mut(w.max(1))
            .zip(raw.par_chunks(3 * w.max(1)))
            .for_each(|(out, row)| {
                for (o, p) in out.iter_mut().zip(row.chunks_exact(3)) {
                    *o = self.classify_pixel([p[0], p[1], p[2]]);
                }
            });
        LabelImage {
            width: w,
            height: img.height() as usize,
            data,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn features_known_values() {
        assert_eq!(brightness([30, 60, 90]), 60.0);
        assert!((saturation([30, 60, 90]) - 0.5).abs() < 1e-6);
        assert_eq!(saturation([0, 0, 0]), 0.0);
        assert_eq!(saturation([255, 255, 255]), 0.0);
        assert_eq!(saturation([200, 0, 0]), 1.0);
    }

    #[test]
    fn table1_means_classify_as_their_class() {
        let r = RuleClassifier::default();
        // Grey-ish pixels with the class means of Table 1.
        let px = |i: f32, s: f32| {
            // min = I(1 − S); put the remainder on one channel pair evenly.
            let m = i * (1.0 - s);
            let rest = (3.0 * i - m) / 2.0;
            [rest.round() as u8, rest.round() as u8, m.round() as u8]
        };
        assert_eq!(r.classify_pixel(px(253.4, 0.0067)), Label::Sky);
        assert_eq!(r.classify_pixel(px(176.0, 0.21)), Label::Water);
        assert_eq!(r.classify_pixel(px(106.2, 0.29)), Label::Other);
        // Clipped sky.
        assert_eq!(r.classify_pixel([255, 255, 255]), Label::Sky);
        // Dark vegetation.
        assert_eq!(r.classify_pixel([40, 70, 30]), Label::Other);
    }

    proptest! {
        #[test]
        fn image_matches_pixels(px in proptest::collection::vec(any::<u8>(), 3 * 12)) {
            let img = RgbImage::from_raw(4, 3, px.clone()).unwrap();
            let r = RuleClassifier::default();
            let l = r.classify(&img);
            for (i, p) in px.chunks(3).enumerate() {
                prop_assert_eq!(l.data[i], r.classify_pixel([p[0], p[1], p[2]]));
            }
        }

        #[test]
        fn saturation_in_unit_interval(p in any::<[u8; 3]>()) {
            let s = saturation(p);
            prop_assert!((0.0..=1.0).contains(&s));
        }
    }
}
