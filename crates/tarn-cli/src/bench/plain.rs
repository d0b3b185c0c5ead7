//! The plain binning loop: the memory-bound reference ingest is measured against.

use tarn::geom::PointCloud;
use tarn::grid::CellKey;

/// A dense window of per-cell sums for [`plain_binning`].
#[derive(Debug, Clone)]
pub struct PlainBins {
    n: usize,
    origin: CellKey,
    res: f64,
    count: Vec<u32>,
    sum_z: Vec<f32>,
}

impl PlainBins {
    /// A window of `n` × `n` cells of `res` metres with lower-left key `origin`.
    pub fn new(n: usize, res: f64, origin: CellKey) -> Self {
        PlainBins {
            n,
            origin,
            res,
            count: vec![0; n * n],
            sum_z: vec![0.0; n * n],
        }
    }

    /// Points added so far.
    #[cfg(test)]
    pub fn total(&self) -> u64 {
        self.count.iter().map(|&c| c as u64).sum()
    }
}

/// The reference ingest is measured against: every point of `cloud` moved into the map
/// frame by the cloud's pose and added (a count and Σ z) to its cell of a dense window in
/// one pass; no noise model, no gate, no buckets. What is left of the cost is reading the
/// points and one random access per point: the memory-bound floor of binning. Returns the
/// points that fell in the window.
pub fn plain_binning(cloud: &PointCloud, bins: &mut PlainBins) -> usize {
    let m = cloud.frame_to_map.to_homogeneous();
    let r = |i: usize, j: usize| m[(i, j)] as f32;
    let (inv, n) = (1.0 / bins.res, bins.n as i64);
    let (ox, oy) = (bins.origin.x, bins.origin.y);
    let mut added = 0;
    for p in &cloud.xyz {
        let x = r(0, 0) * p[0] + r(0, 1) * p[1] + r(0, 2) * p[2] + m[(0, 3)] as f32;
        let y = r(1, 0) * p[0] + r(1, 1) * p[1] + r(1, 2) * p[2] + m[(1, 3)] as f32;
        let z = r(2, 0) * p[0] + r(2, 1) * p[1] + r(2, 2) * p[2] + m[(2, 3)] as f32;
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            continue;
        }
        let kx = (x as f64 * inv).floor() as i64 - ox;
        let ky = (y as f64 * inv).floor() as i64 - oy;
        if (0..n).contains(&kx) && (0..n).contains(&ky) {
            let i = (ky * n + kx) as usize;
            bins.count[i] += 1;
            bins.sum_z[i] += z;
            added += 1;
        }
    }
    added
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_binning_counts_the_points_in_the_window() {
        let c = PointCloud::unorganized(vec![
            [0.05, 0.05, 1.0],
            [0.06, 0.04, 3.0],
            [-0.05, 0.0, 2.0],
            [f32::NAN, 0.0, 0.0],
            [50.0, 0.0, 0.0],
        ]);
        let mut b = PlainBins::new(4, 0.1, CellKey::new(-2, -2));
        assert_eq!(plain_binning(&c, &mut b), 3);
        assert_eq!(b.total(), 3);
        // Cell (0, 0) is buffer index (0 + 2) * 4 + (0 + 2).
        assert_eq!((b.count[10], b.sum_z[10]), (2, 4.0));
        assert_eq!((b.count[9], b.sum_z[9]), (1, 2.0));
    }
}
