//! A 10 km drive through the rolling grid (the small version of `examples/long_drive.rs`,
//! which also samples the process's memory): the window's storage is fixed, the global tile
//! map holds only tiles with observed cells, and it grows by about the same amount every
//! kilometre (linearly with the ground observed, never with time or frame count).

use nalgebra::Point3;
use tarn::geom::{pose_xyz_rpy, PointCloud};
use tarn::grid::{GridConfig, RangeNoise, RollingGrid, TileMap, TILE_CELLS};

fn terrain(x: f64, y: f64) -> f64 {
    1.5 * (x / 37.0).sin() + 0.8 * (y / 23.0).cos()
}

fn path(s: f64) -> (f64, f64) {
    (s, 60.0 * (s / 300.0).sin())
}

/// Points on the terrain in rings of 3..12 m around the vehicle, in the vehicle's frame.
fn scan(s: f64) -> PointCloud {
    let (x, y) = path(s);
    let pose = pose_xyz_rpy(x, y, terrain(x, y) + 1.8, 0.0, 0.0, 0.0);
    let inv = pose.inverse();
    let mut xyz = Vec::new();
    for r in 0..6 {
        let rad = 3.0 + 1.8 * r as f64;
        for c in 0..90 {
            let a = (c as f64 * 4.0).to_radians();
            let (px, py) = (x + rad * a.cos(), y + rad * a.sin());
            let q = inv * Point3::new(px, py, terrain(px, py));
            xyz.push([q.x as f32, q.y as f32, q.z as f32]);
        }
    }
    let mut c = PointCloud::unorganized(xyz);
    c.frame_to_map = pose;
    c
}

#[test]
fn ten_km_drive_keeps_the_window_flat_and_the_tile_map_observed() {
    let cfg = GridConfig {
        resolution: 0.25,
        size_cells: 160,
        ..GridConfig::default()
    };
    let (x0, y0) = path(0.0);
    let mut grid = RollingGrid::new(cfg, x0, y0).unwrap();
    let mut tiles = TileMap::for_grid(&grid);
    let mut per_km = Vec::new();
    let mut last = 0usize;
    for f in 0..=5000u32 {
        let s = 2.0 * f as f64;
        let (x, y) = path(s);
        grid.recenter(x, y, &mut tiles).unwrap();
        let st = grid.ingest(&scan(s), &RangeNoise::LIDAR).unwrap();
        assert_eq!(st.outside, 0, "frame {f}");
        if f > 0 && f % 500 == 0 {
            let mut used = std::collections::BTreeSet::new();
            for (k, _) in tiles.observed() {
                used.insert((k.x.div_euclid(TILE_CELLS), k.y.div_euclid(TILE_CELLS)));
            }
            assert_eq!(
                used.len(),
                tiles.tile_count(),
                "a tile without observed cells"
            );
            assert_eq!(grid.size(), 160);
            let bytes = tiles.cell_bytes();
            per_km.push(bytes - last);
            last = bytes;
        }
    }
    assert_eq!(per_km.len(), 10);
    // Kilometre 1 starts from nothing; after it each kilometre adds about the same.
    let rest = &per_km[1..];
    let (lo, hi) = (rest.iter().min().unwrap(), rest.iter().max().unwrap());
    assert!(*lo > 0, "{per_km:?}");
    assert!(
        (*hi as f64) < 1.6 * *lo as f64,
        "tile growth per km {per_km:?}"
    );
}
