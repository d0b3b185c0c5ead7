//! A long drive through the rolling grid: a vehicle follows a winding path over rolling
//! terrain for `--km` kilometres (default 10) at 1 m per frame; every frame a synthetic
//! spinning-lidar scan of the terrain is fused into a rolling window, cells leaving the
//! window go to the global tile map. Every kilometre it prints the process's resident
//! memory (VmRSS from /proc/self/status), the window's cell bytes, and the tile map's
//! tiles, bytes and observed cells, and checks that every tile holds observed cells.
//!
//! `cargo run --release --example long_drive -- [--km 10] [--resolution 0.25]`

use nalgebra::{Point3, Vector3};
use tarn::geom::{pose_xyz_rpy, PointCloud, Pose};
use tarn::grid::{GridConfig, RangeNoise, RollingGrid, TileMap, TILE_CELLS};

fn terrain(x: f64, y: f64) -> f64 {
    1.5 * (x / 37.0).sin() + 0.8 * (y / 23.0).cos() + 0.002 * x
}

fn path(s: f64) -> (f64, f64, f64) {
    let (x, y) = (s, 60.0 * (s / 300.0).sin());
    let yaw = (0.2 * (s / 300.0).cos()).atan();
    (x, y, yaw)
}

/// An 8 × 180 scan from 1.8 m above the terrain at arc length `s`: rays hit the terrain
/// (found by bisection along the ray), returns beyond 12 m are missing.
fn scan(s: f64) -> PointCloud {
    let (x, y, yaw) = path(s);
    let pose: Pose = pose_xyz_rpy(x, y, terrain(x, y) + 1.8, 0.0, 0.0, yaw);
    let o = pose * Point3::origin();
    let (rings, cols) = (8, 180);
    let mut xyz = Vec::with_capacity(rings * cols);
    for r in 0..rings {
        let el = (-30.0 + 25.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = (c as f64 * 2.0).to_radians();
            let ds = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let d = pose.rotation * ds;
            let above = |t: f64| {
                let p = o + d * t;
                p.z - terrain(p.x, p.y)
            };
            let (mut lo, mut hi) = (0.0, 12.0);
            xyz.push(if above(hi) > 0.0 {
                [f32::NAN; 3]
            } else {
                for _ in 0..20 {
                    let m = 0.5 * (lo + hi);
                    if above(m) > 0.0 {
                        lo = m
                    } else {
                        hi = m
                    }
                }
                let q = ds * hi;
                [q.x as f32, q.y as f32, q.z as f32]
            });
        }
    }
    let mut cloud = PointCloud::organized(rings, cols, xyz).unwrap();
    cloud.frame_to_map = pose;
    cloud
}

fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str, d: f64| -> anyhow::Result<f64> {
        match args.iter().position(|a| a == name) {
            Some(i) => Ok(args
                .get(i + 1)
                .ok_or_else(|| anyhow::anyhow!("{name} needs a value"))?
                .parse()?),
            None => Ok(d),
        }
    };
    let km = arg("--km", 10.0)?;
    let resolution = arg("--resolution", 0.25)?;
    let cfg = GridConfig {
        resolution,
        size_cells: (40.0 / resolution).round() as usize,
        ..GridConfig::default()
    };
    let (x0, y0, _) = path(0.0);
    let mut grid = RollingGrid::new(cfg.clone(), x0, y0)?;
    let mut tiles = TileMap::for_grid(&grid);
    let window_bytes = cfg.size_cells * cfg.size_cells * RollingGrid::bytes_per_cell();
    println!(
        "| km | VmRSS kB | window bytes | tiles | tile bytes | observed cells (tiles + window) |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    let frames = (km * 1000.0).round() as u64;
    for f in 0..=frames {
        let s = f as f64;
        let (x, y, _) = path(s);
        grid.recenter(x, y, &mut tiles)?;
        grid.ingest(&scan(s), &RangeNoise::LIDAR)?;
        if f % 1000 == 0 {
            // Every tile holds observed cells: the map grows only with what was observed.
            let mut used = std::collections::BTreeSet::new();
            for (k, _) in tiles.observed() {
                used.insert((k.x.div_euclid(TILE_CELLS), k.y.div_euclid(TILE_CELLS)));
            }
            anyhow::ensure!(
                used.len() == tiles.tile_count(),
                "tiles without observations"
            );
            println!(
                "| {} | {} | {} | {} | {} | {} |",
                f / 1000,
                rss_kb(),
                window_bytes,
                tiles.tile_count(),
                tiles.cell_bytes(),
                tiles.observed_count() + grid.observed_count()
            );
        }
    }
    Ok(())
}
