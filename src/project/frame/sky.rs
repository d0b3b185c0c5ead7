//! The sky in colour labels: the horizon rule, and the check of colour water against the
//! sky it would reflect ([`reflection_check`]).

use nalgebra::Vector3;

use super::Encoding;
use crate::classify::horizon::mirror_pixel;
use crate::classify::{Label, LabelImage};
use crate::geom::{CameraModel, Pose};

/// Sky-above-horizon rule with the cached rays: the same as
/// [`crate::classify::Horizon::apply`] with `sky_below_is_water` (sky colour below
/// the horizon is a reflection of the sky, i.e. water).
pub(super) fn apply_horizon(labels: &mut LabelImage, map_rays: &[Option<Vector3<f64>>]) {
    for (l, r) in labels.data.iter_mut().zip(map_rays) {
        let above = r.is_none_or(|r| r.z >= 0.0);
        if above {
            if *l != Label::Unknown {
                *l = Label::Sky;
            }
        } else if *l == Label::Sky {
            *l = Label::Water;
        }
    }
}

/// Relative index of water.
const N_WATER: f64 = 1.33;
/// Tilt (rad) a ripple may give the water's normal in the reflection check: the Fresnel
/// reflectance is taken at the incidence this much more grazing.
const RIPPLE_TILT: f64 = 0.03;
/// Water's own (body) radiance is at most this fraction of the sky's, channel by channel:
/// an assumption (the water-leaving reflectance of clear to turbid water is a few per
/// cent to some 15 %, against a sky that is at least as bright as the light it sheds).
const BODY_FRACTION: f64 = 0.2;
/// Linear radiance margin for pixel noise (about 3 σ of 2 grey levels at mid-grey).
const NOISE_MARGIN: f64 = 0.02;
/// Channel values at or above this are saturated: the sky's radiance there is unknown.
const SATURATED: u8 = 250;

/// The sky reflection check of colour water: level water at incidence θ shows the sky in
/// the mirror direction times its Fresnel reflectance R(θ), plus its own body colour
/// (at most a fifth of the sky's radiance in each channel), so channel by channel a water
/// pixel is no brighter than `(R + 0.2 (1 − R))·S + noise`, S the sky radiance in the
/// mirror direction and R taken a ripple's tilt more grazing than θ. S comes from the same
/// image: the pixel the mirror direction falls on where it is in view and labelled sky,
/// else the brightest sky pixel of the image. A water pixel brighter than that (sunlit
/// pavement, a pale slab) is not a sky reflection and becomes `Other`. A saturated sky
/// channel, whose radiance is unknown, bounds nothing, and an image without sky is not
/// checked: the check says nothing where it cannot tell. Read as sRGB, linear data looks
/// darker against its sky, so an encoding assumed wrongly that way vetoes less, never
/// more. Returns the pixels vetoed.
pub fn reflection_check(
    labels: &mut LabelImage,
    px: &[[u8; 3]],
    map_rays: &[Option<Vector3<f64>>],
    camera: &CameraModel,
    cam_to_map: &Pose,
    encoding: Encoding,
) -> u64 {
    let lin = encoding.table();
    let sky_of =
        |i: usize| -> [Option<f64>; 3] { px[i].map(|v| (v < SATURATED).then(|| lin[v as usize])) };
    // The brightest sky of the image, per channel (a channel with a saturated sky pixel
    // has no bound).
    let mut fallback: Option<[Option<f64>; 3]> = None;
    for (i, l) in labels.data.iter().enumerate() {
        if *l == Label::Sky {
            let s = sky_of(i);
            fallback = Some(match fallback {
                None => s,
                Some(f) => std::array::from_fn(|c| match (f[c], s[c]) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    _ => None,
                }),
            });
        }
    }
    let Some(fallback) = fallback else {
        return 0;
    };
    let to_cam = cam_to_map.rotation.inverse();
    let mut vetoed = 0;
    for i in 0..labels.data.len() {
        if labels.data[i] != Label::Water {
            continue;
        }
        let Some(d) = map_rays[i] else { continue };
        let cos_i = -d.z / d.norm();
        if cos_i.is_nan() || cos_i <= 0.0 {
            continue;
        }
        let theta = (cos_i.min(1.0).acos() + RIPPLE_TILT).min(89.9f64.to_radians());
        let r = crate::optics::fresnel(theta, N_WATER).map_or(1.0, |f| 0.5 * (f.r_s + f.r_p));
        let k = r + BODY_FRACTION * (1.0 - r);
        let sky = mirror_pixel(camera, &to_cam, &d)
            .filter(|&j| labels.data.get(j) == Some(&Label::Sky))
            .map_or(fallback, sky_of);
        let outside =
            (0..3).any(|c| sky[c].is_some_and(|s| lin[px[i][c] as usize] > k * s + NOISE_MARGIN));
        if outside {
            labels.data[i] = Label::Other;
            vetoed += 1;
        }
    }
    vetoed
}
