//! Per-cell statistics: exact, mergeable, and small.
//!
//! Elevations are fixed-point millimetres relative to the grid's reference height, and
//! weights are quantized inverse variances, so every sum is an integer: combining cells is
//! exactly commutative and associative. Whatever order points arrive in, however they are
//! split across threads or logs, the same multiset of fused points gives bit-identical cells.

use serde::{Deserialize, Serialize};

use super::evidence::Evidence;
use super::Elev;

/// Reference standard deviation for weights: a point with σ = 1 cm has weight [`W_UNIT`].
pub(crate) const SIGMA_REF_M: f64 = 0.01;
/// Quantized weight of a point with σ = [`SIGMA_REF_M`].
pub(crate) const W_UNIT: f64 = 65536.0;
/// Largest quantized weight (σ ≈ 0.6 mm); smaller σ are clamped to it.
pub(crate) const W_MAX: u32 = 1 << 24;
/// Scale of a point's vertical weight `q = w·s²·V_SCALE` ([`vertical_weight`]).
pub(crate) const V_SCALE: f64 = 256.0;

/// What a point of weight `w` and range noise `sigma_m`, of which the share `s` (0..1)
/// reaches its height, adds to the variance of the weighted mean: `(w·s·σ)²`, in units of
/// `SIGMA_REF_M²·W_UNIT / V_SCALE`, quantized. That is `w·s²·V_SCALE` where `w` is the
/// point's own inverse variance, and more where `w` is clamped: a point noisier than
/// 2.56 m (weight 1) still carries all its noise. At least 1, so that no point's noise
/// vanishes (NaN gives 1), and at most `i32::MAX` (a point some 7 km off). Branch-free:
/// ingest runs it on lanes of points.
#[inline]
pub(crate) fn vertical_weight(w: u32, share: f64, sigma_m: f64) -> u32 {
    let a = f64::from(w) * share * sigma_m / SIGMA_REF_M;
    // `f64::max` takes 1 over a NaN.
    let q = (a * a * (V_SCALE / W_UNIT) + 0.5)
        .max(1.0)
        .min(i32::MAX as f64);
    q as u32
}

/// Quantized inverse-variance weight of a measurement with standard deviation `sigma_m`.
#[inline]
pub fn quantize_weight(sigma_m: f64) -> u32 {
    let r = SIGMA_REF_M / sigma_m;
    let w = W_UNIT * r * r;
    // NaN, or a σ so large its weight is below one unit.
    if w.is_nan() || w < 1.0 {
        return 1;
    }
    // Round half up; `as` saturates, and the clamp bounds it anyway.
    ((w + 0.5) as u64).min(W_MAX as u64) as u32
}

/// Elevation in whole millimetres (relative to the grid's reference height).
#[inline]
pub(crate) fn quantize_mm(dz_m: f64) -> Option<i32> {
    let mm = dz_m * 1000.0 + 0.5;
    // In range (NaN fails both comparisons); then floor without a libm call.
    if !(mm > -(i32::MAX as f64) && mm < i32::MAX as f64) {
        return None;
    }
    let t = mm as i64;
    Some((t - ((t as f64) > mm) as i64) as i32)
}

/// The statistics of one cell. `Default` is the empty cell ("never observed").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellStats {
    /// Points fused into the elevation estimate.
    pub hits: u32,
    /// Points that fell far below the cell's surface (beyond the gate): not averaged in,
    /// kept as evidence (reflections in water, negative obstacles).
    pub below: u32,
    /// Σ w (quantized weights).
    pub sw: u64,
    /// Σ q, the points' vertical weights (`vertical_weight`).
    pub swv: u64,
    /// Σ w·z (z in mm).
    pub swz: i128,
    /// Σ w·z² (z in mm).
    pub swzz: i128,
    /// Lowest fused elevation, mm (`i32::MAX` when empty).
    pub zmin: i32,
    /// Highest fused elevation, mm (`i32::MIN` when empty).
    pub zmax: i32,
    /// Water evidence from the cues (see [`Evidence`]).
    pub ev: Evidence,
}

impl Default for CellStats {
    fn default() -> Self {
        CellStats {
            hits: 0,
            below: 0,
            sw: 0,
            swv: 0,
            swz: 0,
            swzz: 0,
            zmin: i32::MAX,
            zmax: i32::MIN,
            ev: Evidence::default(),
        }
    }
}

impl CellStats {
    /// True when nothing at all was recorded in the cell: no point and no water evidence
    /// ("never observed"). A cell holding only no-return evidence is observed.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.hits == 0 && self.below == 0 && self.ev.is_empty()
    }

    /// Fuses one quantized measurement whose noise is all vertical.
    #[inline]
    pub fn add(&mut self, z_mm: i32, w: u32) {
        self.add_sample(
            z_mm,
            w,
            (u64::from(w) * V_SCALE as u64).min(i32::MAX as u64) as u32,
        );
    }

    /// Fuses one quantized measurement of weight `w` and vertical weight `q`.
    #[inline]
    pub(crate) fn add_sample(&mut self, z_mm: i32, w: u32, q: u32) {
        let mut e = Elev::of(self);
        e.add(z_mm, w, q);
        e.write_to(self);
    }

    /// The commutative, associative combine.
    #[inline]
    pub fn merge(&mut self, o: &CellStats) {
        let mut e = Elev::of(self);
        e.merge(&Elev::of(o));
        e.write_to(self);
        self.ev.merge(&o.ev);
    }

    /// Weighted mean elevation in mm relative to the reference, if any point was fused.
    #[inline]
    pub fn mean_mm(&self) -> Option<f64> {
        (self.sw > 0).then(|| self.swz as f64 / self.sw as f64)
    }

    /// Weighted spread (variance of the fused points about their mean), mm².
    #[inline]
    pub(crate) fn spread_var_mm2(&self) -> Option<f64> {
        let m = self.mean_mm()?;
        Some((self.swzz as f64 / self.sw as f64 - m * m).max(0.0))
    }

    /// Standard deviation of the elevation estimate, metres: the standard error of the
    /// weighted mean from the vertical part of each point's noise (a range sensor errs
    /// along its ray, so a grazing return's height is far better known than its range),
    /// or the empirical standard error when the points disagree more than that. What the
    /// map publishes as `elevation_std`.
    pub fn elevation_std_m(&self) -> Option<f64> {
        self.with_spread(self.vertical_var_m2())
    }

    /// The variance of the weighted mean from the vertical part of each point's noise (m²).
    fn vertical_var_m2(&self) -> f64 {
        let sw = self.sw as f64;
        (SIGMA_REF_M * SIGMA_REF_M) * W_UNIT * (self.swv as f64 / V_SCALE) / (sw * sw)
    }

    /// How much more the points spread about their mean than the vertical part of their
    /// noise explains (m², the points taken as equally weighted): the terrain's own
    /// variation within the cell (roughness, and a slope across it), by which one place in
    /// the cell, its centre, differs from the mean of all of it.
    pub(crate) fn excess_spread_var_m2(&self) -> Option<f64> {
        let per_point = self.vertical_var_m2() * self.hits as f64;
        Some((self.spread_var_mm2()? * 1e-6 - per_point).max(0.0))
    }

    /// [`Self::elevation_std_m`] as if every point's range error were vertical (and no
    /// point noisier than the weights' floor, σ 2.56 m): a bound that holds on any slope
    /// (on a bank facing the sensor the range error moves the height at a fixed place
    /// fully), which the map's own quality gates use (the ray march's holes, the water's
    /// shore cells, the step test).
    pub fn range_bound_std_m(&self) -> Option<f64> {
        self.with_spread((SIGMA_REF_M * SIGMA_REF_M) * W_UNIT / self.sw as f64)
    }

    /// `model_var` (m²), or the empirical variance of the mean where that is larger.
    fn with_spread(&self, model_var: f64) -> Option<f64> {
        let emp_var = self.spread_var_mm2()? * 1e-6 / self.hits as f64;
        Some(model_var.max(emp_var).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Points 2 cm either side of their mean with millimetre noise spread by 2 cm more
    /// than their noise explains; points that spread only as their noise does, not at all.
    #[test]
    fn excess_spread_is_the_spread_beyond_the_points_noise() {
        let (sigma, share) = (0.01, 0.1);
        let w = quantize_weight(sigma);
        let mut c = CellStats::default();
        for z in [-20, 20, -20, 20] {
            c.add_sample(z, w, vertical_weight(w, share, sigma));
        }
        let e = c.excess_spread_var_m2().unwrap();
        let want = 4e-4 - (sigma * share).powi(2);
        assert!((e - want).abs() < 2e-6, "{e} {want}");
        let mut quiet = CellStats::default();
        for z in [-1, 1, -1, 1] {
            quiet.add_sample(z, w, vertical_weight(w, 1.0, sigma));
        }
        assert_eq!(quiet.excess_spread_var_m2(), Some(0.0));
        assert_eq!(CellStats::default().excess_spread_var_m2(), None);
    }

    #[test]
    fn published_std_is_the_vertical_part_even_past_the_weight_floor() {
        for (sigma, share) in [(0.02, 0.1), (0.02, 1.0), (5.0, 0.1), (40.0, 0.3)] {
            let mut c = CellStats::default();
            let w = quantize_weight(sigma);
            for z in [-10, 0, 10, 0] {
                c.add_sample(z, w, vertical_weight(w, share, sigma));
            }
            // Four points: the vertical σ over 2, whatever the weight's floor (σ 2.56 m).
            let want = sigma * share / 2.0;
            let got = c.elevation_std_m().unwrap();
            assert!(
                (got / want - 1.0).abs() < 0.02 || got * 1000.0 < 8.0,
                "{sigma} {share}: {got}"
            );
            // The bound reads the weights, which stop at σ 2.56 m.
            if sigma < 2.56 {
                let bound = c.range_bound_std_m().unwrap();
                assert!(bound >= got, "{bound} < {got}");
            }
        }
    }

    #[test]
    fn weights_follow_inverse_variance() {
        assert_eq!(quantize_weight(0.01), 65536);
        assert_eq!(quantize_weight(0.02), 16384);
        assert_eq!(quantize_weight(1e-9), W_MAX);
        assert_eq!(quantize_weight(1e9), 1);
        assert_eq!(quantize_weight(f64::NAN), 1);
    }

    #[test]
    fn quantize_rejects_non_finite() {
        assert_eq!(quantize_mm(f64::NAN), None);
        assert_eq!(quantize_mm(f64::INFINITY), None);
        assert_eq!(quantize_mm(1e12), None);
        assert_eq!(quantize_mm(-0.0014), Some(-1));
    }

    #[test]
    fn mean_and_std_of_known_points() {
        let mut c = CellStats::default();
        for z in [990, 1000, 1010] {
            c.add(z, quantize_weight(0.01));
        }
        assert_eq!(c.mean_mm(), Some(1000.0));
        // model σ/√3 = 5.77 mm; empirical spread 8.16 mm /√3 = 4.7 mm -> the model wins.
        let s = c.elevation_std_m().unwrap();
        assert!((s - 0.01 / 3f64.sqrt()).abs() < 1e-9, "{s}");
    }

    proptest! {
        #[test]
        fn merge_is_commutative_and_associative(
            a in prop::collection::vec((-100_000i32..100_000, 1u32..W_MAX), 0..20),
            b in prop::collection::vec((-100_000i32..100_000, 1u32..W_MAX), 0..20),
            c in prop::collection::vec((-100_000i32..100_000, 1u32..W_MAX), 0..20),
        ) {
            let cell = |v: &[(i32, u32)]| {
                let mut s = CellStats::default();
                for &(z, w) in v { s.add(z, w); }
                s
            };
            let (ca, cb, cc) = (cell(&a), cell(&b), cell(&c));
            let mut ab_c = ca; ab_c.merge(&cb); ab_c.merge(&cc);
            let mut bc = cb; bc.merge(&cc);
            let mut a_bc = ca; a_bc.merge(&bc);
            let mut cba = cc; cba.merge(&cb); cba.merge(&ca);
            prop_assert_eq!(ab_c, a_bc);
            prop_assert_eq!(ab_c, cba);
            let all: Vec<_> = a.iter().chain(&b).chain(&c).copied().collect();
            prop_assert_eq!(ab_c, cell(&all));
        }
    }
}
