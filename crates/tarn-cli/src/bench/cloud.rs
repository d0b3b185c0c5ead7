//! `tarn bench --cloud`: building a large synthetic cloud into a map.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use tarn::error::Result;
use tarn::geom::PointCloud;

/// What building a large synthetic cloud into a map cost.
#[derive(Debug, Clone, Serialize)]
pub struct CloudBenchRow {
    pub points: usize,
    pub side_m: f64,
    /// Making the cloud in memory (stands in for reading a file).
    pub generate_s: f64,
    pub build_s: f64,
    pub points_per_s: f64,
    pub blocks: usize,
    pub cells_observed: usize,
}

/// Builds an `n`-point synthetic cloud over a `side_m` square (gentle analytic relief) with
/// `build::build_cloud`.
pub fn cloud_build(n: usize, side_m: f64) -> Result<CloudBenchRow> {
    let t0 = Instant::now();
    let pts: Vec<[f32; 3]> = (0..n)
        .into_par_iter()
        .map(|i| {
            // A low-discrepancy (R2) sequence: spread evenly, reproducible, no RNG state.
            let a = (i as f64 * 0.754_877_666_246_692_7).fract();
            let b = (i as f64 * 0.569_840_290_998_053_3).fract();
            let (x, y) = ((a - 0.5) * side_m, (b - 0.5) * side_m);
            [
                x as f32,
                y as f32,
                (0.3 * (0.2 * x).sin() * (0.15 * y).cos()) as f32,
            ]
        })
        .collect();
    let cloud = PointCloud::unorganized(pts);
    let generate_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let b = tarn_log::build::build_cloud(
        &cloud,
        &tarn_log::build::BuildConfig::default(),
        &mut |_, _| {},
    )?;
    let build_s = t1.elapsed().as_secs_f64();
    Ok(CloudBenchRow {
        points: n,
        side_m,
        generate_s,
        build_s,
        points_per_s: n as f64 / build_s,
        blocks: b.blocks,
        cells_observed: b.tiles.observed_count(),
    })
}
