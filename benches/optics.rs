//! Speed of the lidar-over-water model: the per-beam return ratio (what a simulator or the
//! no-return cue calls per beam) and the derived answers that solve for a threshold.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use tarn::optics::{Attenuation, LidarModelConfig, LidarWaterModel};

fn bench(c: &mut Criterion) {
    let m = LidarWaterModel::new(LidarModelConfig::paper(Attenuation::PureWater {
        wavelength_nm: 905.0,
    }))
    .unwrap();
    let lookaheads: Vec<f64> = (0..1000).map(|i| i as f64 * 0.012).collect();
    c.bench_function("return_ratio x1000", |b| {
        b.iter(|| {
            let mut s = 0.0;
            for &d in &lookaheads {
                s += m.return_ratio(black_box(d), black_box(0.3)).unwrap();
            }
            s
        })
    });
    c.bench_function("max_depth", |b| {
        b.iter(|| m.max_depth(black_box(2.0)).unwrap())
    });
    c.bench_function("diagnostic_interval", |b| {
        b.iter(|| m.diagnostic_interval(black_box(0.3)).unwrap())
    });
    let rows: Vec<f64> = (0..=24).map(|i| i as f64 * 0.5).collect();
    c.bench_function("report 25 rows", |b| {
        b.iter(|| m.report(black_box(&rows), 0.3).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
