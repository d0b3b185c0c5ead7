//! Robust statistics of the estimators: the median, the median absolute deviation (MAD)
//! as a Gaussian σ, and a bounded first-in-first-out pool of samples.

use std::collections::VecDeque;

/// MAD × this is the σ of a Gaussian (1 / Φ⁻¹(3/4)).
pub(crate) const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// The median of `v` (reordered in place); `None` when empty.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// The σ of a Gaussian whose median absolute deviation `v` has: `MAD_TO_SIGMA · median
/// |v − median v|`, which a minority of outliers does not move. `None` when empty.
pub(crate) fn mad_sigma(v: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    let m = median(&mut v)?;
    for x in v.iter_mut() {
        *x = (*x - m).abs();
    }
    median(&mut v).map(|d| MAD_TO_SIGMA * d)
}

/// The newest `cap` samples: a log is measured over its first seconds and keeps being
/// measured as it goes, in memory bounded whatever its length.
#[derive(Debug, Clone)]
pub(crate) struct Pool<T> {
    cap: usize,
    items: VecDeque<T>,
    /// Samples ever offered.
    pub seen: u64,
}

impl<T> Pool<T> {
    /// An empty pool of at most `cap` samples.
    pub fn new(cap: usize) -> Self {
        Pool {
            cap: cap.max(1),
            items: VecDeque::new(),
            seen: 0,
        }
    }

    /// Adds a sample, dropping the oldest when full.
    pub fn push(&mut self, t: T) {
        if self.items.len() == self.cap {
            self.items.pop_front();
        }
        self.items.push_back(t);
        self.seen += 1;
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// The samples held, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        self.items.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mad_sigma_of_a_gaussian_ignores_a_few_outliers() {
        // A Gaussian sample of σ 3 (Box–Muller over a 64-bit mixing hash) and 2 % outliers.
        let unit = |i: u64| {
            let mut z = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let g: Vec<f64> = (0..20_000u64)
            .map(|i| {
                let (u1, u2) = (unit(2 * i + 1).max(1e-300), unit(2 * i + 2));
                (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos() * 3.0
            })
            .chain((0..400).map(|i| 1e3 + i as f64))
            .collect();
        let s = mad_sigma(g.iter().copied()).unwrap();
        assert!((s - 3.0).abs() < 0.3, "{s}");
        assert_eq!(mad_sigma(std::iter::empty()), None);
        assert_eq!(mad_sigma([f64::NAN, f64::INFINITY].into_iter()), None);
        assert_eq!(mad_sigma([2.0].into_iter()), Some(0.0));
    }

    #[test]
    fn pool_keeps_the_newest() {
        let mut p = Pool::new(3);
        for i in 0..5 {
            p.push(i);
        }
        assert_eq!(p.iter().copied().collect::<Vec<_>>(), vec![2, 3, 4]);
        assert_eq!(p.seen, 5);
        assert_eq!(p.len(), 3);
    }
}
