//! What the SWIR and MWIR classifiers share (paper sections 4 and 5): the check that an
//! image and its ground geometry have one size, and percentiles over a band of image rows
//! around a pixel's row (on level ground, a row is a range ring), restricted to pixels whose
//! ray meets the ground within the sensor's valid geometry. The SWIR rule takes its terrain
//! reference from the side of that distribution water does not reach, so it holds while
//! water covers up to three quarters of a band. The SWIR rule is in `swir`, the MWIR rule
//! in `mwir`.

use super::horizon::GroundGeometry;
use super::MonoImage;
use crate::error::{Error, Result};

const BINS: usize = 2048;

/// Per-row percentiles over a band of rows, from histograms of the included pixels.
pub(super) fn band_percentiles(
    img: &MonoImage,
    include: &[bool],
    half_band: usize,
    qs: &[f64],
) -> Vec<Option<Vec<f32>>> {
    let (w, h) = (img.width, img.height);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (v, &inc) in img.data.iter().zip(include) {
        if inc {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    if lo > hi {
        return vec![None; h];
    }
    let span = (hi - lo).max(1e-6);
    let bin = |v: f32| (((v - lo) / span) * (BINS - 1) as f32).round() as usize;
    let value = |b: usize| lo + span * b as f32 / (BINS - 1) as f32;
    let mut rows = vec![[0u32; BINS]; 0];
    rows.reserve(h);
    for y in 0..h {
        let mut hist = [0u32; BINS];
        for x in 0..w {
            let i = y * w + x;
            if include[i] {
                hist[bin(img.data[i])] += 1;
            }
        }
        rows.push(hist);
    }
    let mut acc = [0u64; BINS];
    let mut out = Vec::with_capacity(h);
    // Sliding window [y − half_band, y + half_band].
    for r in rows.iter().take(half_band.min(h)) {
        for (a, c) in acc.iter_mut().zip(r) {
            *a += *c as u64;
        }
    }
    for y in 0..h {
        if y + half_band < h {
            for (a, c) in acc.iter_mut().zip(&rows[y + half_band]) {
                *a += *c as u64;
            }
        }
        if y > half_band {
            for (a, c) in acc.iter_mut().zip(&rows[y - half_band - 1]) {
                *a -= *c as u64;
            }
        }
        let n: u64 = acc.iter().sum();
        if n == 0 {
            out.push(None);
            continue;
        }
        let mut res = Vec::with_capacity(qs.len());
        for &q in qs {
            let target = (q * (n - 1) as f64).round() as u64;
            let mut cum = 0u64;
            let mut b = BINS - 1;
            for (i, c) in acc.iter().enumerate() {
                cum += c;
                if cum > target {
                    b = i;
                    break;
                }
            }
            res.push(value(b));
        }
        out.push(Some(res));
    }
    out
}

pub(super) fn check_sizes(img: &MonoImage, g: &GroundGeometry, what: &str) -> Result<()> {
    let n = img.width * img.height;
    if img.width != g.width
        || img.height != g.height
        || img.data.len() != n
        || g.incidence.len() != n
        || g.range.len() != n
        || g.lookahead.len() != n
        || g.mirror.len() != n
    {
        return Err(Error::invalid(
            what,
            format!(
                "image is {} × {} ({} values), geometry is {} × {}",
                img.width,
                img.height,
                img.data.len(),
                g.width,
                g.height
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
pub(super) mod tests {
    /// Deterministic pseudo-noise in [−1, 1).
    pub(crate) fn noise(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}
