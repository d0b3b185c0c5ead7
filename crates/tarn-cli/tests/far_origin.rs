//! Poses and clouds 5,000 km from the map origin (UTM-like): centimetre accuracy is kept
//! through the PLY reader, ingest, export (`map.ply` and `terrain.ply` store
//! `double` x y z in the map frame) and the readers that load them back.

use std::path::Path;

use tarn::io;

const E: f64 = 5_000_000.0;
const N: f64 = 4_000_000.0;

fn terrain(x: f64, y: f64) -> f64 {
    310.0 + 0.05 * (x - E) + 0.3 * ((y - N) * 0.4).sin()
}

fn write_double_cloud(path: &Path) {
    let mut body = Vec::new();
    let mut n = 0;
    for i in 0..200 {
        for j in 0..200 {
            let (x, y) = (E + 0.013 + i as f64 * 0.05, N + 0.007 + j as f64 * 0.05);
            for v in [x, y, terrain(x, y)] {
                body.extend_from_slice(&v.to_le_bytes());
            }
            n += 1;
        }
    }
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\n\
         property double y\nproperty double z\nend_header\n"
    )
    .into_bytes();
    bytes.extend_from_slice(&body);
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn a_map_5000_km_out_keeps_centimetres_through_build_and_export() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("utm.ply");
    write_double_cloud(&input);
    let out = dir.path().join("map");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args([
            "build",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // The contract reader: cell centres on the 0.1 m lattice, elevations on the terrain.
    let map = io::read_map_ply(&out.join("map.ply")).unwrap();
    assert!(map.cells.len() > 9000, "{} cells", map.cells.len());
    let r = map.resolution;
    let mut worst_xy: f64 = 0.0;
    let mut worst_z: f64 = 0.0;
    for c in &map.cells {
        assert!(
            (c.x - E).abs() < 20.0 && (c.y - N).abs() < 20.0,
            "{} {}",
            c.x,
            c.y
        );
        worst_xy = worst_xy
            .max((c.x - (c.key.x as f64 + 0.5) * r).abs())
            .max((c.y - (c.key.y as f64 + 0.5) * r).abs());
        worst_z = worst_z.max((c.z - terrain(c.x, c.y)).abs());
    }
    assert!(worst_xy < 0.001, "cell centres off by {worst_xy} m");
    assert!(worst_z < 0.02, "elevations off by {worst_z} m");
    let mut keys: Vec<_> = map.cells.iter().map(|c| (c.key.x, c.key.y)).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(
        keys.len(),
        map.cells.len(),
        "cells collapsed onto the same key"
    );

    // Map-frame coordinates, in double, that any PLY reader takes as they are.
    for name in ["map.ply", "terrain.ply"] {
        let bytes = std::fs::read(out.join(name)).unwrap();
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(1024)]).into_owned();
        assert!(head.contains("property double x\n"), "{name}: {head}");
        assert!(!head.contains("comment origin"), "{name}: {head}");
    }
    // The point-cloud reader sees the same points in the map frame.
    for name in ["map.ply", "terrain.ply"] {
        let cloud = io::read_ply(&out.join(name)).unwrap();
        assert_eq!(cloud.len(), map.cells.len(), "{name}");
        for i in (0..cloud.len()).step_by(97) {
            let p = cloud.point_in_map(i);
            let c = &map.cells[i];
            assert!(
                (p.x - c.x).abs() < 1e-3 && (p.y - c.y).abs() < 1e-3 && (p.z - c.z).abs() < 1e-3,
                "{name} vertex {i}: {p:?} vs {} {} {}",
                c.x,
                c.y,
                c.z
            );
        }
    }
}

#[test]
fn a_map_near_the_origin_keeps_float_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("near.ply");
    std::fs::write(
        &input,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nend_header\n1 1 0\n1.2 1 0\n1 1.2 0\n",
    )
    .unwrap();
    let out = dir.path().join("map");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args([
            "build",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(out.join("map.ply")).unwrap();
    let text = String::from_utf8_lossy(&bytes[..300]);
    assert!(!text.contains("comment origin"), "{text}");
    assert!(text.contains("property float x\n"), "{text}");
}

#[test]
fn a_bad_origin_line_is_refused_with_its_line() {
    for bad in ["1 2", "1 2 nan", "a b c", "1 2 inf"] {
        let text = format!(
            "ply\nformat ascii 1.0\ncomment origin {bad}\nelement vertex 1\nproperty float x\n\
             property float y\nproperty float z\nend_header\n1 1 0\n"
        );
        let e = io::read_ply_from_bytes(text.as_bytes(), "o.ply")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("o.ply") && e.contains("line 3") && e.contains("origin"),
            "{e}"
        );
    }
}
