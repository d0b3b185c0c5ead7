//! SWIR water by its reflection (paper section 4). At 1.55 µm water absorbs within a
//! millimetre (Segelstein 1981: k = 1.35·10⁻⁴, an absorption length of 0.9 mm), so level
//! water shows nothing of its body or bottom: its radiance is the Fresnel reflectance R(θ)
//! at its incidence θ times the radiance of what its mirror ray meets. The SWIR sky is dim
//! (Rayleigh scattering falls as λ⁻⁴), so water that mirrors the sky stays dark at any
//! incidence, grazing included (the paper's SWIR image: water "very dark … where it reflects
//! the sky; the angle of incidence at that point is at least 80 degrees"); what brightens
//! water is the reflection of bright things (clouds, trees, a bank), not the angle.
//!
//! [`classify_swir`] predicts each ground pixel's radiance were it water, from the image
//! itself: R between θ − [`RIPPLE_TILT`] and θ + [`RIPPLE_TILT`] (index
//! [`N_WATER_SWIR`]) times the radiance at the pixels that see what level water there
//! mirrors ([`GroundGeometry::mirror`]; a ripple of that tilt moves the mirror ray by twice
//! it, so the mirrors of the column's pixels within ± 2 tilts of incidence), plus a noise
//! margin of [`NOISE_SIGMAS`] × the camera's pixel noise. Then:
//!
//! * brighter than water could be even were it mirroring the brightest thing on its mirror
//!   ray's vertical plane (the image segment from the horizon to its mirror pixel: trees, a
//!   far bank, clouds, the sky down to the horizon; level ground farther out is not on the
//!   rising mirror ray) → [`Label::Other`];
//! * on a strip of its column of one radiance (within the noise margin and
//!   [`SAME_SURFACE`]) that holds rows where water's bounds lie wholly above that radiance
//!   and rows where they lie wholly below → [`Label::Other`]: a reflection's radiance rises
//!   steeply towards grazing (R · L), a Lambertian surface's (asphalt, soil, concrete) stays
//!   the same with range;
//! * brighter than a reflection of the measured sky, but not than that → [`Label::Unknown`]
//!   (it may be water mirroring bright terrain);
//! * darker than a reflection of the sky can be → [`Label::Unknown`] (a dark dry surface, or
//!   water mirroring something darker than the sky);
//! * within the sky reflection's bounds → [`Label::Water`] (or [`Label::SnowIce`] where a
//!   co-registered visible image is bright: snow is white in the visible, dark at 1.5 µm),
//!   unless the test cannot tell water from the terrain there:
//!   - the band's terrain (the `reference_percentile` of the ground pixels in a band of
//!     rows, [`band_percentiles`]) is no brighter than the bound: the mirror shows bright
//!     things, or the terrain is as dark as water would be → [`Label::Unknown`];
//!   - the same surface (same radiance within the noise margin and [`SAME_SURFACE`])
//!     reaches, along the pixel's column, rows where water could not have that radiance:
//!     a Lambertian surface keeps its radiance with range, a reflection does not (R·L
//!     rises steeply towards grazing), so a dark dry surface (asphalt, wet soil) that
//!     matches water in one range ring does not in the next → [`Label::Unknown`].
//!
//! No incidence gate: at grazing incidence the bounds rise with R and the terrain test
//! decides. Where the geometry is unknown (above the horizon, a failed ray), the mirror
//! pixel is outside the image (no measured radiance), or a mirror pixel is saturated (its
//! radiance unknown), the label is [`Label::Unknown`]; a saturated pixel is only known to be
//! at least that bright. At night (no SWIR light) the terrain is as dark as the noise
//! margin and nothing is decided.

use serde::{Deserialize, Serialize};

use super::horizon::GroundGeometry;
use super::thermal::{band_percentiles, check_sizes};
use super::{Label, LabelImage, MonoImage};
use crate::error::{Error, Result};

/// Refractive index of liquid water at 1.55 µm (Segelstein 1981, 25 °C: n = 1.3109; Hale
/// and Querry 1973 give 1.317 at 1.6 µm). Lower than in the visible (1.33), so R is a little
/// lower.
pub const N_WATER_SWIR: f64 = 1.311;
/// Tilt (rad) a ripple may give the water's normal: R is taken between θ ∓ this, the mirror
/// radiance over the mirror rays of incidence θ ± twice this (as the colour reflection
/// check, `project::frame::sky`).
pub const RIPPLE_TILT: f64 = 0.03;
/// The noise margin in standard deviations of the pixel noise (one-sided 3 σ: about one
/// pixel in 700 of water falls outside its bound by noise alone).
pub const NOISE_SIGMAS: f32 = 3.0;
/// Grey levels at or above this are saturated: the radiance there is only a lower bound.
pub const SATURATED: f32 = 250.0;
/// The most grazing incidence the Fresnel reflectance is evaluated at (rad): 89.9°, where R
/// is within 0.3 % of 1.
pub const MAX_INCIDENCE: f64 = 89.9 * std::f64::consts::PI / 180.0;
/// Relative radiance change within which two pixels of a column may be one surface: the
/// texture of natural ground and pavement (a few to some 10 % at a pixel's scale), over the
/// noise margin.
pub const SAME_SURFACE: f32 = 0.1;

/// SWIR classifier parameters. See the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwirConfig {
    /// Standard deviation of the camera's pixel noise, grey levels (the rig's datasheet).
    pub noise_sd: f32,
    /// Percentile of the band that stands for dry terrain (bright side: it holds while water
    /// covers up to this fraction of a band).
    pub reference_percentile: f64,
    /// Half-height of the row band, rows.
    pub half_band_rows: usize,
    /// With a visible image: dark-in-SWIR pixels at least this bright in the visible are
    /// snow/ice rather than water.
    pub snow_min_visible: f32,
}

impl Default for SwirConfig {
    fn default() -> Self {
        SwirConfig {
            noise_sd: 2.0,
            reference_percentile: 0.75,
            half_band_rows: 8,
            snow_min_visible: 170.0,
        }
    }
}

/// Unpolarized Fresnel reflectance of water at 1.55 µm at incidence `theta` (rad), clamped
/// to [0, [`MAX_INCIDENCE`]].
pub fn water_reflectance_swir(theta: f64) -> f64 {
    let t = if theta.is_nan() {
        MAX_INCIDENCE
    } else {
        theta.clamp(0.0, MAX_INCIDENCE)
    };
    crate::optics::fresnel(t, N_WATER_SWIR).map_or(1.0, |f| 0.5 * (f.r_s + f.r_p))
}

/// What water at a pixel would look like: the bounds of a reflection of what its mirror
/// pixels show (`None` where its mirror is out of the image or saturated), and the most a
/// reflection of anything it may mirror could be.
#[derive(Debug, Clone, Copy, PartialEq)]
struct WaterBounds {
    sky: Option<(f32, f32)>,
    hi_any: f32,
}

/// The column's pixels around `i` (same column) whose incidence is within `span` of pixel
/// `i`'s, walking out from `i` while the incidence is finite.
fn column_window(geom: &GroundGeometry, i: usize, span: f32, mut f: impl FnMut(usize)) {
    let w = geom.width;
    let theta = geom.incidence[i];
    f(i);
    for step in [-(w as isize), w as isize] {
        let mut j = i as isize + step;
        while j >= 0 && (j as usize) < geom.incidence.len() {
            let t = geom.incidence[j as usize];
            if !(t - theta).abs().le(&span) {
                break;
            }
            f(j as usize);
            j += step;
        }
    }
}

/// Largest value above the horizon on the image segment from pixel `a` to its mirror pixel
/// `b`: what stands up on the mirror ray's vertical plane between the horizon and the
/// mirror direction (trees, a far bank, clouds, the sky), which water at `a` may mirror.
/// Level ground farther out is not on the mirror ray, which rises from the water.
fn segment_max(img: &MonoImage, geom: &GroundGeometry, a: usize, b: usize) -> f32 {
    let w = img.width;
    let (ax, ay) = ((a % w) as f64, (a / w) as f64);
    let (bx, by) = ((b % w) as f64, (b / w) as f64);
    let n = (bx - ax).abs().max((by - ay).abs()).max(1.0) as usize;
    (1..=n)
        .map(|k| {
            let t = k as f64 / n as f64;
            let (x, y) = ((ax + t * (bx - ax)).round(), (ay + t * (by - ay)).round());
            y as usize * w + x as usize
        })
        .filter(|&j| geom.incidence[j].is_nan())
        .map(|j| img.data[j])
        .fold(f32::NEG_INFINITY, f32::max)
}

/// The water bounds of pixel `i`, or `None` where its geometry is unknown. `brightest` is
/// the brightest pixel above the horizon (`None`: no sky in view), what water may mirror
/// where its mirror pixel is out of the image.
fn water_bounds(
    img: &MonoImage,
    geom: &GroundGeometry,
    i: usize,
    margin: f32,
    brightest: Option<f32>,
) -> Option<WaterBounds> {
    let theta = geom.incidence[i];
    if !theta.is_finite() {
        return None;
    }
    // A mirror pixel is above the horizon (near it, rounding may put one on the ground).
    let mirror = |j: usize| {
        let m = geom.mirror[j];
        (m != u32::MAX && geom.incidence.get(m as usize).is_some_and(|t| t.is_nan()))
            .then_some(m as usize)
    };
    let m0 = mirror(i);
    let r_hi = water_reflectance_swir(theta as f64 + RIPPLE_TILT) as f32;
    let r_lo = water_reflectance_swir(theta as f64 - RIPPLE_TILT) as f32;
    let unbounded = |l: f32| if l < SATURATED { l } else { f32::INFINITY };
    let Some(m0) = m0 else {
        // No mirror pixel: only "brighter than a reflection of anything in view" is known,
        // and only with sky in view (as the colour reflection check).
        return Some(WaterBounds {
            sky: None,
            hi_any: brightest.map_or(f32::INFINITY, |b| r_hi * unbounded(b) + margin),
        });
    };
    let (mut lmin, mut lmax) = (f32::INFINITY, f32::NEG_INFINITY);
    column_window(geom, i, 2.0 * RIPPLE_TILT as f32, |j| {
        // The window's mirrors that are in view (the pixel's own one is).
        if let Some(&l) = mirror(j).and_then(|m| img.data.get(m)) {
            lmin = lmin.min(l);
            lmax = lmax.max(l);
        }
    });
    // A saturated pixel on the mirror plane (the sun, a glint): no upper bound at all.
    let any = unbounded(segment_max(img, geom, i, m0).max(lmax));
    let sky = (lmin <= lmax && lmax < SATURATED && lmin.is_finite())
        .then_some((r_lo * lmin - margin, r_hi * lmax + margin));
    Some(WaterBounds {
        sky,
        hi_any: r_hi * any + margin,
    })
}

/// Labels a SWIR image: water (a reflection of the sky), snow/ice (the same, bright in a
/// co-registered visible image), other (brighter than water there could be), or unknown.
/// See the module documentation.
pub(crate) fn classify_swir(
    img: &MonoImage,
    geom: &GroundGeometry,
    visible: Option<&MonoImage>,
    cfg: &SwirConfig,
) -> Result<LabelImage> {
    check_sizes(img, geom, "SWIR image")?;
    if let Some(v) = visible {
        check_sizes(v, geom, "visible image for SWIR")?;
    }
    if !(cfg.noise_sd.is_finite()
        && cfg.noise_sd >= 0.0
        && cfg.snow_min_visible.is_finite()
        && (0.0..=1.0).contains(&cfg.reference_percentile))
    {
        return Err(Error::invalid("SWIR config", format!("{cfg:?}")));
    }
    let margin = NOISE_SIGMAS * cfg.noise_sd;
    let (w, n) = (img.width, img.data.len());
    let ground: Vec<bool> = img
        .data
        .iter()
        .zip(&geom.incidence)
        .map(|(v, inc)| v.is_finite() && inc.is_finite())
        .collect();
    let refs = band_percentiles(
        img,
        &ground,
        cfg.half_band_rows,
        &[cfg.reference_percentile],
    );
    // The brightest pixel above the horizon (rays that do not meet the ground).
    let brightest = img
        .data
        .iter()
        .zip(&geom.incidence)
        .filter(|(v, t)| t.is_nan() && v.is_finite())
        .map(|(v, _)| *v)
        .reduce(f32::max);
    let bounds: Vec<Option<WaterBounds>> = (0..n)
        .map(|i| {
            if ground[i] {
                water_bounds(img, geom, i, margin, brightest)
            } else {
                None
            }
        })
        .collect();
    let mut out = LabelImage::filled(img.width, img.height, Label::Unknown);
    for i in 0..n {
        let Some(b) = bounds[i] else { continue };
        let v = img.data[i];
        if v >= SATURATED {
            // At least this bright.
            if b.hi_any < SATURATED {
                out.data[i] = Label::Other;
            }
            continue;
        }
        if v > b.hi_any {
            out.data[i] = Label::Other;
            continue;
        }
        let Some((lo, hi)) = b.sky else { continue };
        if lambertian_strip(img, &bounds, i, w, margin) {
            out.data[i] = Label::Other;
            continue;
        }
        if v > hi || v < lo {
            continue;
        }
        let Some(r) = refs[i / w].as_ref().map(|r| r[0]) else {
            continue;
        };
        // The terrain must be brighter than water's bound by the noise margin (a NaN
        // reference decides nothing).
        let informative = matches!(
            (hi + margin).partial_cmp(&r),
            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
        );
        if !informative || same_surface_elsewhere(img, &bounds, i, w, margin) {
            continue;
        }
        out.data[i] = match visible {
            Some(vis) if vis.data[i] >= cfg.snow_min_visible => Label::SnowIce,
            _ => Label::Water,
        };
    }
    Ok(out)
}

/// Whether pixel `i` (radiance v) lies on a strip of its column of one radiance (every pixel
/// within the noise margin and [`SAME_SURFACE`] of v) that holds both a row where water's
/// bounds lie wholly above v and one where they lie wholly below: a reflection's radiance
/// would have to change along it, a Lambertian surface's (asphalt, soil, concrete) does not.
fn lambertian_strip(
    img: &MonoImage,
    bounds: &[Option<WaterBounds>],
    i: usize,
    w: usize,
    margin: f32,
) -> bool {
    let v = img.data[i];
    let tol = margin + SAME_SURFACE * v;
    let (mut above, mut below) = (false, false);
    for step in [-(w as isize), w as isize] {
        for (j, lo, hi) in sky_bounds_along(bounds, i, step) {
            if (img.data[j] - v).abs() > tol {
                break;
            }
            above |= lo > v;
            below |= hi < v;
            if above && below {
                return true;
            }
        }
    }
    false
}

/// From pixel `i` along its column by `step` (± the width), each pixel with its water
/// bounds of a sky reflection, while they last: `(index, lo, hi)`, pixel `i` first.
fn sky_bounds_along(
    bounds: &[Option<WaterBounds>],
    i: usize,
    step: isize,
) -> impl Iterator<Item = (usize, f32, f32)> + '_ {
    std::iter::successors(Some(i as isize), move |j| Some(j + step))
        .map_while(|j| usize::try_from(j).ok().filter(|&j| j < bounds.len()))
        .map_while(|j| bounds[j].and_then(|b| b.sky).map(|(lo, hi)| (j, lo, hi)))
}

/// Whether the surface at pixel `i` (radiance v) reaches, along its column, a row where water
/// could not have radiance v: the first row farther out whose water bounds lie wholly above
/// v, and the first nearer whose bounds lie wholly below, each checked for a pixel of the
/// same radiance (within the noise margin and [`SAME_SURFACE`]).
fn same_surface_elsewhere(
    img: &MonoImage,
    bounds: &[Option<WaterBounds>],
    i: usize,
    w: usize,
    margin: f32,
) -> bool {
    let v = img.data[i];
    let tol = margin + SAME_SURFACE * v;
    // Farther out (up the image) water is brighter; nearer (down), darker: the first row
    // each way whose bounds lie wholly beyond v decides.
    let up = sky_bounds_along(bounds, i, -(w as isize))
        .skip(1)
        .find(|&(_, lo, _)| lo > v + tol);
    let down = sky_bounds_along(bounds, i, w as isize)
        .skip(1)
        .find(|&(_, _, hi)| hi < v - tol);
    [up, down]
        .into_iter()
        .flatten()
        .any(|(j, _, _)| (img.data[j] - v).abs() <= tol)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests;
