//! Point ingest throughput of the rolling grid: 1 M and 10 M points, 1 and 2 threads.
//!
//! `cargo bench --bench ingest`. The cloud is a lidar-like ground patch in front of the
//! sensor (range-weighted noise), fused into the default 40 m × 40 m window at 0.10 m.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use tarn::geom::PointCloud;
use tarn::grid::{GridConfig, RangeNoise, RollingGrid};

fn cloud(n: usize) -> PointCloud {
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f32 / (1u64 << 53) as f32
    };
    // Points ordered as a spinning lidar emits them: azimuth sweeps, rings outward.
    let mut pts = Vec::with_capacity(n);
    for i in 0..n {
        let az = (i as f32 / n as f32) * 64.0 * std::f32::consts::TAU;
        let r = 2.0 + 17.0 * u();
        pts.push([
            r * az.cos(),
            r * az.sin(),
            0.05 * (r * 0.3).sin() + 0.02 * (u() - 0.5) - 1.8,
        ]);
    }
    let mut c = PointCloud::unorganized(pts);
    c.sensor_origin = nalgebra::Point3::new(0.0, 0.0, 0.0);
    c
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("ingest");
    g.sample_size(10);
    for &n in &[1_000_000usize, 10_000_000] {
        let pc = cloud(n);
        for &threads in &[1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut grid = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
            // Warm the scratch and give cells a surface (the steady state of a mapper).
            pool.install(|| grid.ingest(&pc, &RangeNoise::LIDAR).unwrap());
            g.throughput(Throughput::Elements(n as u64));
            g.bench_with_input(
                BenchmarkId::new(format!("{threads}-thread"), format!("{}M", n / 1_000_000)),
                &pc,
                |b, pc| b.iter(|| pool.install(|| grid.ingest(pc, &RangeNoise::LIDAR).unwrap())),
            );
        }
    }
    g.finish();
    eprintln!(
        "bytes per cell in the window: {} (layers), tile map: {}",
        RollingGrid::bytes_per_cell(),
        std::mem::size_of::<tarn::grid::CellStats>()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
