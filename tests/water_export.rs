//! The water stage end to end on analytic scenes with known answers: evidence in a tile
//! map → `HazardMap::from_tiles` → every export. The files are left in
//! `target/water-check/<scene>/` for the Python check (`tests/python/test_water_mesh.py`), which
//! reads them with trimesh and Open3D and compares the mesh with `report.json`.

use std::path::PathBuf;

use tarn::grid::{CellKey, CellStats, Evidence, TileMap};
use tarn::hazard::HazardConfig;
use tarn::hazard::{Class, HazardMap};
use tarn::io;

const RES: f64 = 0.1;

fn dry(z: f64) -> CellStats {
    let mut c = CellStats::default();
    for _ in 0..4 {
        c.add((z * 1000.0).round() as i32, 65536);
    }
    c
}

fn wet(level: f64, depth: Option<f64>) -> CellStats {
    let mut ev = Evidence {
        noret: 6,
        ..Evidence::default()
    };
    ev.add_level((level * 1000.0).round() as i32);
    if let Some(d) = depth {
        ev.add_depth(d);
    }
    CellStats {
        ev,
        ..CellStats::default()
    }
}

/// Terrain at (x, y) and, where there is water, `Some((surface, depth))`.
type Cell = (f64, Option<(f64, Option<f64>)>);
type Scene = fn(f64, f64) -> Cell;

/// Two ponds on flat ground at z = 0 for x < 0 (one bowl-shaped and shallow with a 1 m
/// bush on its east shore, one 0.6 m deep around a dry island), a box, and for x ≥ 0 a
/// stream 1.6 m wide running down a 2 % slope in a ditch, without bottom returns.
fn mixed(x: f64, y: f64) -> Cell {
    if x < 0.0 {
        let r1 = (x + 6.0).hypot(y - 4.0);
        if r1 < 2.5 {
            return (
                -0.3,
                Some((0.0, Some(0.25 * (1.0 - (r1 / 2.5).powi(2)) + 0.02))),
            );
        }
        if (-3.6..-2.6).contains(&x) && (3.5..4.5).contains(&y) {
            return (1.0, None); // the bush
        }
        let r2 = (x + 6.0).hypot(y + 4.0);
        if (0.6..2.0).contains(&r2) {
            return (-0.6, Some((0.0, Some(0.6))));
        }
        if r2 < 0.6 {
            return (0.2 * (0.6 - r2), None); // the island, a low dome
        }
        if (-1.5..-0.9).contains(&x) && (8.0..8.6).contains(&y) {
            return (0.6, None); // a box: an obstacle
        }
        return (0.0, None);
    }
    let s = 0.02 * x;
    if y.abs() < 0.8 {
        return (s - 0.3, Some((s, None)));
    }
    (s + 0.1 * (y.abs() - 0.8).min(x), None)
}

fn tiles_of(f: Scene, half: i64) -> TileMap {
    let mut t = TileMap::new(RES, 0.0).unwrap();
    for ky in -half..half {
        for kx in -half..half {
            let k = CellKey::new(kx, ky);
            let (x, y) = t.centre_of(k);
            match f(x, y) {
                (_, Some((s, d))) => t.add(k, &wet(s, d)),
                (g, None) => t.add(k, &dry(g)),
            }
        }
    }
    t
}

#[test]
fn exports_of_a_scene_with_ponds_a_stream_and_a_box() {
    let t = tiles_of(mixed, 100);
    let map = HazardMap::from_tiles(&t, &HazardConfig::default()).unwrap();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/water-check/mixed");
    io::write_map_files(&dir, &map).unwrap();
    tarn::files::write_json(
        &dir.join("report.json"),
        &serde_json::json!({ "water_bodies": map.water_report() }),
    )
    .unwrap();
    for f in [
        "map.ply",
        "terrain.ply",
        "water.ply",
        "map.png",
        "report.json",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    let models: Vec<(&str, usize)> = map
        .bodies
        .iter()
        .map(|b| (b.surface.name(), b.cells.len()))
        .collect();
    eprintln!(
        "{}",
        serde_json::to_string_pretty(&map.water_report()).unwrap()
    );
    assert_eq!(map.bodies.len(), 3, "{models:?}");
    assert_eq!(
        map.bodies
            .iter()
            .filter(|b| b.surface.name() == "delaunay")
            .count(),
        1,
        "{models:?}"
    );
    assert_eq!(
        map.bodies.iter().filter(|b| b.volume_m3.is_some()).count(),
        2,
        "{models:?}"
    );
    assert!(map.class_counts()[Class::Obstacle as usize] > 0);
}
