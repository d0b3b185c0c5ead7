//! Counter-based randomness: every random number is a hash of the seed and the indices of
//! what it belongs to (frame, ray, purpose), so results do not depend on the thread count
//! or the order of evaluation.

/// SplitMix64 finalizer.
#[inline]
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of a seed and a list of indices.
#[inline]
pub fn hash(seed: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(mix(seed), |h, &p| mix(h ^ mix(p)))
}

/// Uniform in [0, 1) from a hash.
#[inline]
pub fn unit_f64(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A standard normal deviate from a hash (Box–Muller).
#[inline]
pub fn normal(h: u64) -> f64 {
    let u1 = unit_f64(h).max(1e-300);
    let u2 = unit_f64(mix(h ^ 0xA5A5_A5A5));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_and_normal_moments() {
        let n = 200_000u64;
        let (mut s, mut s2, mut u) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let h = hash(42, &[i]);
            let z = normal(h);
            s += z;
            s2 += z * z;
            u += unit_f64(h);
        }
        let nf = n as f64;
        assert!((s / nf).abs() < 0.01, "mean {}", s / nf);
        assert!((s2 / nf - 1.0).abs() < 0.02, "variance {}", s2 / nf);
        assert!((u / nf - 0.5).abs() < 0.005);
        assert_ne!(hash(1, &[2, 3]), hash(1, &[3, 2]));
    }
}
