//! Absorption coefficient of pure water (and ice) against wavelength, from measured tables.
//!
//! Water: Segelstein 1981 (25 °C); ice: Warren & Brandt 2008 (−7 °C); both from the CC0
//! refractiveindex.info database (see `data/tables.rs` for the exact source). The tables are
//! embedded between 190 and 2100 nm. Between rows the coefficient is interpolated linearly in
//! wavelength and *logarithmically* in α: absorption bands are exponential in shape, and a
//! linear interpolation of α overestimates it between rows on a rising flank.
//!
//! Natural water also scatters and carries dissolved and suspended matter; its total
//! attenuation `c = a + b` is larger than these pure-water numbers. For it give `c`
//! directly (see [`super::Attenuation::PerMetre`]).

use super::data::tables::{SEGELSTEIN_1981_WATER, WARREN_BRANDT_2008_ICE};
use crate::error::{Error, Result};

/// Which measured table to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AbsorptionTable {
    /// Liquid water, Segelstein 1981.
    Water,
    /// Ice, Warren & Brandt 2008.
    Ice,
}

impl AbsorptionTable {
    fn rows(self) -> &'static [(f64, f64, f64)] {
        match self {
            AbsorptionTable::Water => SEGELSTEIN_1981_WATER,
            AbsorptionTable::Ice => WARREN_BRANDT_2008_ICE,
        }
    }

    /// The wavelength range (nm) the embedded table covers.
    pub fn range_nm(self) -> (f64, f64) {
        let r = self.rows();
        (r[0].0, r[r.len() - 1].0)
    }

    /// The embedded (wavelength nm, absorption 1/m) rows, in increasing wavelength.
    pub fn samples(self) -> impl Iterator<Item = (f64, f64)> {
        self.rows().iter().map(|&(w, _, a)| (w, a))
    }

    fn name(self) -> &'static str {
        match self {
            AbsorptionTable::Water => "pure-water absorption (Segelstein 1981)",
            AbsorptionTable::Ice => "ice absorption (Warren & Brandt 2008)",
        }
    }

    /// Absorption coefficient (1/m) at `wavelength_nm`, interpolated in the table.
    pub fn absorption_per_m(self, wavelength_nm: f64) -> Result<f64> {
        let rows = self.rows();
        let (lo, hi) = self.range_nm();
        if !(wavelength_nm.is_finite() && wavelength_nm >= lo && wavelength_nm <= hi) {
            return Err(Error::invalid(
                "wavelength",
                format!(
                    "{wavelength_nm} nm is outside the {} table ({lo:.1}–{hi:.1} nm)",
                    self.name()
                ),
            ));
        }
        // First row with wavelength >= the query.
        let j = rows.partition_point(|r| r.0 < wavelength_nm);
        if rows[j].0 == wavelength_nm || j == 0 {
            return Ok(rows[j].2);
        }
        let (w0, _, a0) = rows[j - 1];
        let (w1, _, a1) = rows[j];
        let f = (wavelength_nm - w0) / (w1 - w0);
        Ok((a0.ln() * (1.0 - f) + a1.ln() * f).exp())
    }
}

/// Absorption coefficient of pure liquid water (1/m) at `wavelength_nm` (190–2100 nm).
pub fn absorption_per_m(wavelength_nm: f64) -> Result<f64> {
    AbsorptionTable::Water.absorption_per_m(wavelength_nm)
}

/// Absorption coefficient of ice (1/m) at `wavelength_nm` (190–2100 nm).
pub fn ice_absorption_per_m(wavelength_nm: f64) -> Result<f64> {
    AbsorptionTable::Ice.absorption_per_m(wavelength_nm)
}

/// Path length (m) after which a fraction `lost` (0..1) of the power has been absorbed:
/// `−ln(1 − lost)/α`.
pub fn loss_distance_m(attenuation_per_m: f64, lost: f64) -> Result<f64> {
    if !(attenuation_per_m.is_finite() && attenuation_per_m > 0.0) {
        return Err(Error::invalid(
            "attenuation coefficient",
            format!("{attenuation_per_m} 1/m is not finite and positive"),
        ));
    }
    if !(lost > 0.0 && lost < 1.0) {
        return Err(Error::invalid(
            "lost fraction",
            format!("{lost} is not in (0, 1)"),
        ));
    }
    Ok(-(1.0 - lost).ln() / attenuation_per_m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn tables_are_sorted_positive_and_consistent_with_k() {
        for t in [AbsorptionTable::Water, AbsorptionTable::Ice] {
            let rows = t.rows();
            assert!(rows.len() > 100);
            for w in rows.windows(2) {
                assert!(w[0].0 < w[1].0, "{t:?} not increasing at {}", w[0].0);
            }
            for &(nm, k, a) in rows {
                assert!(a > 0.0 && k > 0.0);
                // alpha = 4 pi k / lambda, to the 6 significant digits of the derived table.
                let a_k = 4.0 * std::f64::consts::PI * k / (nm * 1e-9);
                assert!(
                    (a / a_k - 1.0).abs() < 1e-4,
                    "{t:?} at {nm} nm: {a} vs {a_k}"
                );
            }
            let (lo, hi) = t.range_nm();
            assert!(lo <= 200.0 && hi >= 2000.0, "{t:?} covers {lo}..{hi}");
        }
    }

    #[test]
    fn table_rows_are_returned_exactly() {
        for &(nm, _, a) in SEGELSTEIN_1981_WATER {
            assert_eq!(absorption_per_m(nm).unwrap(), a);
        }
    }

    #[test]
    fn agrees_with_other_measurements_at_lidar_wavelengths() {
        // The cross-check table in the shared data README (other sources: WOPP v3,
        // Kou 1993, Kedenburg 2012) within 15 % where they agree with each other.
        for (nm, reference) in [(650.0, 0.340), (850.0, 4.38), (905.0, 7.09), (1064.0, 15.1)] {
            let a = absorption_per_m(nm).unwrap();
            assert!(
                (a / reference - 1.0).abs() < 0.15,
                "{nm} nm: {a} vs {reference}"
            );
        }
        // 1550 nm: four sources span 1083..1210 /m.
        let a = absorption_per_m(1550.0).unwrap();
        assert!((1000.0..1250.0).contains(&a), "{a}");
    }

    #[test]
    fn paper_99_percent_loss_distances() {
        // Paper, section 3: 99 % lost after 144, 16, 0.68 and 0.004 m at 525, 625, 900 and
        // 1550 nm. Segelstein gives the same order everywhere; see docs/optics.md for numbers.
        let d = |nm: f64| loss_distance_m(absorption_per_m(nm).unwrap(), 0.99).unwrap();
        assert!((d(625.0) / 16.0 - 1.0).abs() < 0.15, "625: {}", d(625.0));
        assert!((d(900.0) / 0.68 - 1.0).abs() < 0.15, "900: {}", d(900.0));
        assert!(
            (d(1550.0) / 0.004 - 1.0).abs() < 0.15,
            "1550: {}",
            d(1550.0)
        );
        // 525 nm: the blue-green minimum is where measurements disagree most (Segelstein's
        // value is 1.23× the paper's implied 0.032 /m).
        assert!((d(525.0) / 144.0 - 1.0).abs() < 0.5, "525: {}", d(525.0));
    }

    #[test]
    fn out_of_range_is_an_error() {
        assert!(absorption_per_m(100.0).is_err());
        assert!(absorption_per_m(3000.0).is_err());
        assert!(absorption_per_m(f64::NAN).is_err());
        assert!(ice_absorption_per_m(-5.0).is_err());
        assert!(loss_distance_m(0.0, 0.99).is_err());
        assert!(loss_distance_m(1.0, 1.0).is_err());
    }

    #[test]
    fn ice_is_dark_in_swir() {
        // The SWIR snow/ice cue: ice absorbs strongly around 1.5 µm and hardly in the visible.
        assert!(ice_absorption_per_m(1550.0).unwrap() > 1000.0);
        assert!(ice_absorption_per_m(550.0).unwrap() < 0.2);
    }

    proptest! {
        #[test]
        fn interpolation_stays_between_neighbours(nm in 190.2f64..2098.9) {
            let rows = SEGELSTEIN_1981_WATER;
            let a = absorption_per_m(nm).unwrap();
            let j = rows.partition_point(|r| r.0 < nm);
            let (lo, hi) = if j == 0 { (rows[0].2, rows[0].2) } else {
                (rows[j - 1].2.min(rows[j].2), rows[j - 1].2.max(rows[j].2))
            };
            prop_assert!(a.is_finite() && a >= lo * (1.0 - 1e-12) && a <= hi * (1.0 + 1e-12));
        }
    }
}
