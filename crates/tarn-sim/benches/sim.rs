//! Simulator speed: rays per second against the default scene's mesh (terrain + objects +
//! water), and the time to simulate the default scene (noise on, files written; the other
//! scenes' times come from `tarn simulate`, which reports them).
//! `cargo bench --bench sim`; the thread count is rayon's default (the machine's cores).

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use tarn_sim::sim::{cast_fan, simulate, Scene, SimOptions, World};

fn scene(name: &str) -> Scene {
    let p = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .join("maps")
        .join(format!("{name}.toml"));
    Scene::load(&p).expect("shipped scene")
}

fn rays(c: &mut Criterion) {
    let w = World::build(&scene("default")).unwrap();
    let n = 200_000;
    let mut g = c.benchmark_group("sim_rays");
    g.throughput(Throughput::Elements(n as u64));
    g.sample_size(10);
    g.bench_function("default_scene_cast", |b| b.iter(|| cast_fan(&w, n)));
    g.finish();
}

fn default_scene(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_scene");
    g.sample_size(10);
    let dir = tempfile::tempdir().unwrap();
    let s = scene("default");
    g.bench_function("default", |b| {
        b.iter(|| simulate(&s, dir.path(), SimOptions::default()).unwrap())
    });
    g.finish();
}

criterion_group!(benches, rays, default_scene);
criterion_main!(benches);
