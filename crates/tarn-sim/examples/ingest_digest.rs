//! Prints a digest of the cells and ingest statistics that a fixed set of ingests produces
//! (lidar and stereo noise, layered clouds that take the split path, gated batches, a moved
//! and rotated pose, missing returns, points outside the window, a blocked cloud build).
//! Two builds of the ingest code make the same map exactly when they print the same lines.
//! `cargo run --release --example ingest_digest`
use std::hash::{Hash, Hasher};

use tarn::geom::{pose_xyz_rpy, PointCloud};
use tarn::grid::{CellKey, CellStats, GridConfig, RangeNoise, RollingGrid};
use tarn_log::build::{build_cloud, BuildConfig};

struct Rng(u64);
impl Rng {
    fn u(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn digest<'a>(cells: impl Iterator<Item = (CellKey, CellStats)> + 'a) -> (usize, u64) {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let mut n = 0;
    for (k, c) in cells {
        n += 1;
        (
            k.x, k.y, c.hits, c.below, c.sw, c.swz, c.swzz, c.zmin, c.zmax,
        )
            .hash(&mut h);
    }
    (n, h.finish())
}

/// Ground with a step, a layer 0.5 m below part of it (reflections), some NaN and far points.
fn cloud(n: usize, seed: u64, spread: f32) -> PointCloud {
    let mut r = Rng(seed);
    let pts = (0..n)
        .map(|i| {
            if i % 97 == 0 {
                return [f32::NAN, 0.0, 0.0];
            }
            if i % 89 == 0 {
                return [500.0, 3.0, 0.0];
            }
            let x = (r.u() - 0.5) * spread;
            let y = (r.u() - 0.5) * spread;
            let mut z = 0.05 * (0.3 * x).sin() + 0.02 * (r.u() - 0.5) - 1.8;
            if x > 3.0 {
                z += 0.4;
            }
            if y < -2.0 && i % 3 == 0 {
                z -= 0.5;
            }
            [x, y, z]
        })
        .collect();
    PointCloud::unorganized(pts)
}

fn main() {
    for (name, noise) in [("lidar", RangeNoise::LIDAR), ("stereo", RangeNoise::STEREO)] {
        let mut g = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
        let mut lines = Vec::new();
        for (b, &(n, spread)) in [(300_000, 30.0), (50_000, 45.0), (200_000, 30.0), (7, 10.0)]
            .iter()
            .enumerate()
        {
            let mut c = cloud(n, 11 + b as u64, spread);
            if b == 2 {
                c.frame_to_map = pose_xyz_rpy(1.25, -0.75, 0.1, 0.02, -0.01, 0.3);
                c.sensor_origin = nalgebra::Point3::new(0.3, 0.1, 1.5);
            }
            let st = g.ingest(&c, &noise).unwrap();
            lines.push(format!("{st:?}"));
        }
        let (cells, h) = digest(g.observed());
        println!("{name}: {cells} cells, digest {h:016x}");
        for l in lines {
            println!("  {l}");
        }
    }
    let t = tarn_sim::sim::synthetic_lidar_cloud(1_000_000, 5);
    let mut g = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
    let s1 = g.ingest(&t, &RangeNoise::LIDAR).unwrap();
    let s2 = g.ingest(&t, &RangeNoise::LIDAR).unwrap();
    let (cells, h) = digest(g.observed());
    println!("synthetic: {cells} cells, digest {h:016x}\n  {s1:?}\n  {s2:?}");

    let cfg = BuildConfig {
        max_window_cells: 256,
        ..BuildConfig::default()
    };
    let b = build_cloud(&cloud(400_000, 99, 60.0), &cfg, &mut |_, _| {}).unwrap();
    let (cells, h) = digest(b.tiles.observed());
    println!(
        "build_cloud: {} blocks, {cells} cells, digest {h:016x}\n  {:?}",
        b.blocks, b.ingest
    );
}
