//! Local solar time from a UTC stamp and a longitude, for the thermal rule's regime (water
//! warmer than the land at night, cooler by day), which follows the sun, not the clock.
//!
//! Local apparent solar time is UTC plus the longitude's share of the day (15° an hour) plus
//! the equation of time, the difference between the apparent and the mean sun (−14 to
//! +16 minutes over the year, from the Earth's eccentric orbit and its tilt). The equation
//! of time is NOAA's Fourier fit (Spencer, 1971) over the fractional year, good to about a
//! minute, far finer than the hours the regimes span.

/// Seconds in a day.
const DAY_S: f64 = 86_400.0;

/// Civil (proleptic Gregorian) year and day of the year (0-based) of `days` since
/// 1970-01-01 (H. Hinnant's `civil_from_days`).
fn year_and_day(days: i64) -> (i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy_march = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy_march + 2) / 153;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    // Day of the year from March 1st's count: January and February come first.
    let jan_feb = 31 + if leap { 29 } else { 28 };
    let doy = if month <= 2 {
        doy_march - 306
    } else {
        doy_march + jan_feb
    };
    (year, doy)
}

/// The equation of time (minutes, apparent minus mean solar time) at `unix_s` seconds since
/// the epoch (UTC).
pub fn equation_of_time_min(unix_s: f64) -> f64 {
    let days = (unix_s / DAY_S).floor();
    let (year, doy) = year_and_day(days as i64);
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    let hour = (unix_s - days * DAY_S) / 3600.0;
    let g = std::f64::consts::TAU / if leap { 366.0 } else { 365.0 }
        * (doy as f64 + (hour - 12.0) / 24.0);
    229.18
        * (0.000075 + 0.001868 * g.cos()
            - 0.032077 * g.sin()
            - 0.014615 * (2.0 * g).cos()
            - 0.040849 * (2.0 * g).sin())
}

/// Local apparent solar time (hours, 0 ≤ h < 24) at `unix_s` seconds since the epoch (UTC)
/// and `longitude_deg` degrees east. `None` when either is not finite, the longitude lies
/// outside ±180°, or the stamp outside ±10,000 years of the epoch.
pub(crate) fn local_solar_hour(unix_s: f64, longitude_deg: f64) -> Option<f64> {
    if !(unix_s.is_finite()
        && unix_s.abs() < 3.2e11
        && longitude_deg.is_finite()
        && longitude_deg.abs() <= 180.0)
    {
        return None;
    }
    let utc_h = unix_s.rem_euclid(DAY_S) / 3600.0;
    let h = (utc_h + longitude_deg / 15.0 + equation_of_time_min(unix_s) / 60.0).rem_euclid(24.0);
    // `rem_euclid` can round up to exactly 24 for a tiny negative value.
    Some(if h >= 24.0 { 0.0 } else { h })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Seconds since the epoch of a UTC date and hour (days counted by hand for the test).
    fn utc(year: i64, month: u32, day: u32, hour: f64) -> f64 {
        let leap = |y: i64| (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
        let mut days = 0i64;
        for y in 1970..year {
            days += if leap(y) { 366 } else { 365 };
        }
        let months = [
            31,
            if leap(year) { 29 } else { 28 },
            31,
            30,
            31,
            30,
            31,
            31,
            30,
            31,
            30,
            31,
        ];
        days += months[..month as usize - 1].iter().sum::<i64>() + i64::from(day) - 1;
        days as f64 * DAY_S + hour * 3600.0
    }

    #[test]
    fn day_of_year_matches_the_calendar() {
        for (y, m, d, want) in [
            (1970, 1, 1, 0),
            (2024, 2, 29, 59),
            (2024, 3, 1, 60),
            (2023, 3, 1, 59),
            (2024, 12, 31, 365),
            (2000, 12, 31, 365),
            (1900 + 200, 12, 31, 364),
        ] {
            let days = (utc(y, m, d, 0.0) / DAY_S) as i64;
            assert_eq!(year_and_day(days), (y, want), "{y}-{m}-{d}");
        }
        // Before the epoch too.
        assert_eq!(year_and_day(-1), (1969, 364));
    }

    /// The equation of time's extremes and zeros as almanacs give them (to a minute).
    #[test]
    fn equation_of_time_matches_the_almanac() {
        for (m, d, want) in [
            (2, 11, -14.2),
            (4, 15, 0.0),
            (5, 14, 3.7),
            (6, 13, 0.0),
            (7, 26, -6.5),
            (9, 1, 0.0),
            (11, 3, 16.4),
            (12, 25, 0.0),
        ] {
            let e = equation_of_time_min(utc(2024, m, d, 12.0));
            assert!(
                (e - want).abs() < 1.0,
                "{m}-{d}: {e:.2} min, almanac {want}"
            );
        }
    }

    #[test]
    fn solar_hour_follows_longitude_and_the_equation_of_time() {
        // Greenwich at noon UTC on 11 February: the sun culminates 14 minutes later.
        let h = local_solar_hour(utc(2024, 2, 11, 12.0), 0.0).unwrap();
        assert!((h - (12.0 - 14.2 / 60.0)).abs() < 1.0 / 60.0, "{h}");
        // Pasadena (118.17° W) at 20:00 UTC on 21 June: about 12:05 local solar time.
        let h = local_solar_hour(utc(2024, 6, 21, 20.0), -118.17).unwrap();
        assert!(
            (h - (20.0 - 118.17 / 15.0 - 1.8 / 60.0)).abs() < 1.0 / 60.0,
            "{h}"
        );
        // Wraps across midnight either way.
        let h = local_solar_hour(utc(2024, 3, 20, 23.0), 30.0).unwrap();
        assert!((h - (1.0 - 7.5 / 60.0)).abs() < 1.0 / 60.0, "{h}");
        let h = local_solar_hour(utc(2024, 3, 20, 1.0), -30.0).unwrap();
        assert!((h - (23.0 - 7.5 / 60.0)).abs() < 1.0 / 60.0, "{h}");
    }

    #[test]
    fn absurd_inputs_have_no_solar_hour() {
        for (t, lon) in [
            (f64::NAN, 0.0),
            (0.0, f64::NAN),
            (f64::INFINITY, 0.0),
            (0.0, 181.0),
            (1e15, 0.0),
            (-1e15, 0.0),
        ] {
            assert_eq!(local_solar_hour(t, lon), None, "{t} {lon}");
        }
    }

    proptest! {
        /// Within 0..24 for any stamp of ±3000 years and any longitude, and 15° east is an
        /// hour later (the equation of time moves by under a second in the 0 s between).
        #[test]
        fn solar_hour_is_a_time_of_day(t in -9.0e10f64..9.0e10, lon in -165.0f64..165.0) {
            let h = local_solar_hour(t, lon).unwrap();
            prop_assert!((0.0..24.0).contains(&h), "{}", h);
            let east = local_solar_hour(t, lon + 15.0).unwrap();
            let d = (east - h).rem_euclid(24.0);
            prop_assert!((d - 1.0).abs() < 1e-9, "{} {} {}", h, east, d);
        }
    }
}
