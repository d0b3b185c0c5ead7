//! Fuses a synthetic lidar-like cloud a few times; for profilers (callgrind, perf).
//! `cargo run --release --example ingest_profile -- [points] [repeats]`
use tarn::geom::PointCloud;
use tarn::grid::{GridConfig, RangeNoise, RollingGrid};

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .and_then(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let reps: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(3);
    let mut pts = Vec::with_capacity(n);
    for i in 0..n {
        let az = (i as f32 / n as f32) * 64.0 * std::f32::consts::TAU;
        let r = 2.0 + 17.0 * ((i * 7919) % 1000) as f32 / 1000.0;
        pts.push([r * az.cos(), r * az.sin(), 0.05 * (r * 0.3).sin() - 1.8]);
    }
    let pc = PointCloud::unorganized(pts);
    let mut g = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
    let t = std::time::Instant::now();
    for _ in 0..reps {
        g.ingest(&pc, &RangeNoise::LIDAR).unwrap();
    }
    let dt = t.elapsed().as_secs_f64();
    println!("{:.1} M points/s", (n * reps) as f64 / dt / 1e6);
}
