//! Tests of ingest: the three ways a bucket is fused agree, and the lane classifier bins
//! every point as the scalar one does.

#[cfg(target_arch = "x86_64")]
use super::bin::bin_chunk_avx2;
use super::bin::{bin_chunk_baseline, Classified};
use super::*;
use crate::geom::pose_xyz_rpy;
use crate::grid::GridConfig;
use proptest::prelude::*;

/// A sample as (idx, z_mm, weight and share, σ bits).
type Bits = (u32, i32, u32, u32);

/// Everything a binning produced, comparable (σ by its bits).
fn outcome(p: &Binned) -> (IngestStats, Vec<Vec<Bits>>) {
    let b = p
        .buckets
        .iter()
        .map(|v| {
            v.iter()
                .map(|s| (s.idx, s.z_mm, s.wv, s.sigma_mm.to_bits()))
                .collect()
        })
        .collect();
    (p.stats, b)
}

/// Coordinates that stress the fast path: cell edges (exact multiples of the
/// resolution), values a hair off them, non-finite and huge values.
fn coord() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -25.0f32..25.0,
        2 => (-250i32..250).prop_map(|k| k as f32 * 0.1),
        1 => (-250i32..250, -3i32..=3).prop_map(|(k, u)| f32::from_bits(
            ((k as f32 * 0.1).to_bits() as i32 + u) as u32
        )),
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => prop_oneof![Just(1e30f32), Just(-3e9), Just(2.1e9), Just(1e-40)],
    ]
}

/// Pass 2 of `cloud` into `g` with every bucket fused by one path: 0 sorts by
/// comparison, 1 by counting, 2 through dense accumulators.
fn fuse_by(g: &mut RollingGrid, cloud: &PointCloud, path: u8) -> (u64, u64) {
    let ctx = g.ctx(cloud, &RangeNoise::LIDAR);
    let nb = (g.n * g.n).div_ceil(BUCKET_CELLS);
    let mut p = Binned::default();
    bin_chunk(&ctx, 0..cloud.len(), nb, &mut p);
    let binned = [p];
    let (k, min_mm) = (g.cfg.gate_sigma, g.cfg.gate_min_m * 1000.0);
    let support = g.cfg.min_support.max(1);
    let mut acc = Dense {
        cells: vec![Acc::default(); BUCKET_CELLS],
        swv: vec![0; BUCKET_CELLS],
    };
    let mut sum = (0, 0);
    for (bi, mut lay) in split_buckets(&mut g.layers).into_iter().enumerate() {
        let mut out = vec![Sample::ZERO; binned[0].buckets[bi].len()];
        let (f, b) = match path {
            2 => fuse_dense(&binned, bi, &mut lay, &mut acc, k, min_mm, support),
            _ => fuse_bucket(
                &binned,
                bi,
                &mut lay,
                &mut out,
                path == 1,
                k,
                min_mm,
                support,
            ),
        };
        assert!(acc
            .cells
            .iter()
            .all(|a| a.is_untouched() && a.group == u32::MAX));
        assert!(acc.swv.iter().all(|&v| v == 0));
        sum = (sum.0 + f, sum.1 + b);
    }
    sum
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// The three ways pass 2 fuses a bucket (sorted by comparison, sorted by counting,
    /// dense accumulators) give the same grid and the same counts, batch after batch:
    /// the prior gate (second batch) and the first batch's split both run.
    #[test]
    fn every_fuse_path_gives_the_same_grid(
        pts in prop::collection::vec(
            (-1.0f32..1.0, -1.0f32..1.0, -0.05f32..0.05, 0u8..8), 1..3000),
        cut in 0usize..3000,
    ) {
        let xyz: Vec<[f32; 3]> = pts
            .iter()
            .map(|&(x, y, dz, kind)| {
                [x, y, 0.2 * (x * 0.5).sin() + dz - if kind == 0 { 0.9 } else { 0.0 }]
            })
            .collect();
        let cut = cut % xyz.len();
        let batches = [
            PointCloud::unorganized(xyz[..cut].to_vec()),
            PointCloud::unorganized(xyz[cut..].to_vec()),
        ];
        let cfg = GridConfig { size_cells: 100, ..GridConfig::default() };
        let run = |path: u8| {
            let mut g = RollingGrid::new(cfg.clone(), 0.0, 0.0).unwrap();
            let counts: Vec<_> = batches.iter().map(|b| fuse_by(&mut g, b, path)).collect();
            (g, counts)
        };
        let (g0, c0) = run(0);
        // Cells of 0.1 m: a few points a cell, so that the prior gates the second
        // batch (whose reflections are counted below) once the first is large.
        if cut >= 2000 && xyz.len() - cut >= 200 {
            prop_assert!(c0[1].1 > 0, "no point of the second batch was gated");
        }
        for path in [1, 2] {
            let (g, c) = run(path);
            prop_assert_eq!(&c, &c0, "path {}", path);
            prop_assert!(g == g0, "grids differ on path {}", path);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    /// The lane classifier (baseline and, where the CPU has it, AVX2) bins every point
    /// exactly as the scalar classifier does.
    #[test]
    fn lane_classifier_is_the_scalar_one(
        pts in prop::collection::vec((coord(), coord(), coord()), 0..400),
        pose in (-1e4f64..1e4, -1e4f64..1e4, -50f64..50.0, -0.2f64..0.2, 0f64..6.3),
        centre in prop_oneof![Just((0.0, 0.0)), (-1e6f64..1e6, -1e6f64..1e6)],
        z_ref in -100f64..100.0,
        noise in prop_oneof![
            Just(RangeNoise::LIDAR),
            Just(RangeNoise::STEREO),
            (1e-4f64..1.0).prop_map(RangeNoise::constant),
        ],
        size in prop_oneof![Just(16usize), Just(400), Just(700)],
        moved in any::<bool>(),
    ) {
        let cfg = GridConfig { size_cells: size, z_ref, ..GridConfig::default() };
        let g = RollingGrid::new(cfg, centre.0, centre.1).unwrap();
        let mut cloud = PointCloud::unorganized(
            pts.iter().map(|&(x, y, z)| [x, y, z]).collect(),
        );
        if moved {
            cloud.frame_to_map = pose_xyz_rpy(
                pose.0 + centre.0, pose.1 + centre.1, pose.2, pose.3, 0.0, pose.4,
            );
            cloud.sensor_origin = nalgebra::Point3::new(0.5, -0.25, 1.5);
        }
        let ctx = g.ctx(&cloud, &noise);
        let nb = (size * size).div_ceil(BUCKET_CELLS);
        let mut want = Binned::default();
        want.buckets.resize_with(nb, Vec::new);
        want.stats.points = cloud.len() as u64;
        for i in 0..cloud.len() {
            match ctx.classify(i) {
                Classified::Sample(s) => {
                    want.buckets[(s.idx >> BUCKET_SHIFT) as usize].push(s)
                }
                Classified::NonFinite => want.stats.nonfinite += 1,
                Classified::Outside => want.stats.outside += 1,
            }
        }
        let mut got = Binned::default();
        bin_chunk_baseline(&ctx, 0..cloud.len(), nb, &mut got);
        prop_assert_eq!(outcome(&got), outcome(&want));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut got = Binned::default();
            // SAFETY: checked just above.
            unsafe { bin_chunk_avx2(&ctx, 0..cloud.len(), nb, &mut got) };
            prop_assert_eq!(outcome(&got), outcome(&want));
        }
    }
}
