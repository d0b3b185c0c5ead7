//! Cost of the image-label ray march ([`GridSurface::cast_through_holes`]) per frame: the
//! 160 × 120 rays of a 320 × 240 camera at stride 2, 1.6 m up and pitched 12° down, over a
//! 40 m window of rolling ground at 0.1 m observed densely to 10 m and on lidar rings (every
//! 4th cell row of range) beyond, with an unobserved 8 m pond 15 m ahead.
//!
//! `cargo bench --bench surface`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use tarn::grid::CellKey;
use tarn::project::GridSurface;

const N: usize = 400;
const RES: f64 = 0.1;

fn raster() -> Vec<f32> {
    let mut z = vec![f32::NAN; N * N];
    for (k, v) in z.iter_mut().enumerate() {
        let (x, y) = (
            ((k % N) as f64 + 0.5) * RES - 20.0,
            ((k / N) as f64 + 0.5) * RES - 20.0,
        );
        let r = x.hypot(y);
        let pond = (x - 15.0).hypot(y) < 4.0;
        let seen = r < 10.0 || (r / RES) as usize % 4 == 0;
        if seen && !pond {
            *v = (0.06 * (x / 2.0).sin() * (y / 3.0).cos() + 0.002 * x) as f32;
        }
    }
    z
}

fn rays() -> Vec<Vector3<f64>> {
    let (f, pitch) = (160.0 / 35f64.to_radians().tan(), 12f64.to_radians());
    let mut out = Vec::new();
    for v in (0..240).step_by(2) {
        for u in (0..320).step_by(2) {
            // Camera: x forward, y left, z up, before the pitch.
            let d = Vector3::new(f, 159.5 - u as f64, 119.5 - v as f64).normalize();
            let d = Vector3::new(
                d.x * pitch.cos() + d.z * pitch.sin(),
                d.y,
                d.z * pitch.cos() - d.x * pitch.sin(),
            );
            // Pixels above the horizon are sky: not cast.
            if d.z < 0.0 {
                out.push(d);
            }
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let z = raster();
    let origin = CellKey::new(-200, -200);
    let s = GridSurface::from_raster(N, RES, origin, z.clone()).unwrap();
    let rays = rays();
    let o = Point3::new(0.0, 0.0, 1.6);
    let mut g = c.benchmark_group("grid_surface_400x400");
    g.sample_size(20);
    g.bench_function("build", |b| {
        b.iter(|| GridSurface::from_raster(N, RES, origin, z.clone()).unwrap())
    });
    g.bench_function("cast_160x120_rays", |b| {
        b.iter(|| {
            rays.iter()
                .filter_map(|d| s.cast_through_holes(&o, d, 40.0))
                .count()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
