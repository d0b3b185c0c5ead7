//! `tarn build LOG.mcap`: a vehicle drives a sloped plane with a spinning lidar; the map
//! built from its log matches the plane, and a truncated log gives the map of what came
//! before the damage plus a failing exit status.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use tarn::build::{build_log, LogBuildConfig};
use tarn::geom::{pose_xyz_rpy, PointCloud, Pose};
use tarn::grid::GridConfig;
use tarn::io::mcap_log::{LogWriter, WriteOptions};
use tarn::io::ply;
use tarn::io::ros::{Header, TfMessage, TransformStamped};
use tarn::mapper::MapperConfig;

const NS: u64 = 1_000_000_000;
const SLOPE: f64 = 0.05;

fn terrain(x: f64) -> f64 {
    SLOPE * x
}

fn base(t: f64) -> Pose {
    // Driving along +x at 2 m/s, following the slope, turning a little.
    pose_xyz_rpy(
        2.0 * t,
        0.3 * t,
        terrain(2.0 * t),
        0.0,
        -SLOPE.atan(),
        0.02 * t,
    )
}

fn lidar_ext() -> Pose {
    pose_xyz_rpy(0.2, 0.0, 1.8, 0.0, 0.0, 0.0)
}

fn hdr(ns: u64, f: &str) -> Header {
    Header::new(f, ns as i64)
}

/// A 16-ring scan of the plane z = SLOPE·x, seen from `sensor_to_map`, with ±1 cm noise.
fn scan(sensor_to_map: &Pose, k: u64) -> PointCloud {
    let (rings, cols) = (16, 360);
    let o = sensor_to_map * Point3::origin();
    let mut xyz = Vec::with_capacity(rings * cols);
    for r in 0..rings {
        let el = (-25.0 + 23.0 * r as f64 / (rings - 1) as f64).to_radians();
        for c in 0..cols {
            let az = (c as f64).to_radians();
            let ds = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let d = sensor_to_map * ds;
            let t = (SLOPE * o.x - o.z) / (d.z - SLOPE * d.x);
            let noise = (((r * 7919 + c * 104_729) as u64 + k * 31) % 201) as f64 / 10_000.0 - 0.01;
            xyz.push(if t > 0.5 && t < 30.0 {
                let p = ds * (t + noise);
                [p.x as f32, p.y as f32, p.z as f32]
            } else {
                [f32::NAN; 3]
            });
        }
    }
    PointCloud::organized(rings, cols, xyz).unwrap()
}

fn write_log(path: &Path, frames: u64) {
    let mut w = LogWriter::create(path, &WriteOptions::default()).unwrap();
    let ext = TransformStamped::new("base_link", "lidar", 0, lidar_ext());
    w.write_tf(
        "/tf_static",
        &TfMessage {
            transforms: vec![ext],
        },
        0,
    )
    .unwrap();
    for k in 0..=frames {
        let ns = k * NS / 10;
        let t = ns as f64 * 1e-9;
        let tf = TransformStamped::new("map", "base_link", ns as i64, base(t));
        w.write_tf(
            "/tf",
            &TfMessage {
                transforms: vec![tf],
            },
            ns,
        )
        .unwrap();
        if k > 0 && k < frames {
            let c = scan(&(base(t) * lidar_ext()), k);
            w.write_cloud("/lidar/points", &c, hdr(ns, "lidar"), ns)
                .unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn map_of_a_drive_matches_the_terrain() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("drive.mcap");
    write_log(&log, 100);
    let cfg = LogBuildConfig {
        mapper: MapperConfig {
            grid: GridConfig {
                size_cells: 200, // a 20 m window: the drive (20 m) makes it roll
                ..GridConfig::default()
            },
            ..MapperConfig::default()
        },
        ..Default::default()
    };
    let out = dir.path().join("map");
    let r = build_log(&log, &out, &cfg, &mut |_, _| {}).unwrap();
    assert_eq!(r.frames_fused, 99);
    assert!(r.damage.is_none() && r.errors.is_empty(), "{:?}", r.errors);
    assert!(r.lidar_points.fused > 100_000);
    assert!(r.x_realtime > 0.0);
    // Every cell against the plane; well-observed cells within a few centimetres.
    let cloud = ply::read(&out.join("map.ply")).unwrap();
    let mut se = 0.0;
    let mut n = 0;
    for i in 0..cloud.len() {
        let p = cloud.point_in_map(i);
        // The plane's height at the cell centre equals its mean over the cell.
        se += (p.z - terrain(p.x)).powi(2);
        n += 1;
    }
    let rms = (se / n as f64).sqrt();
    assert!(n > 20_000, "{n} cells");
    assert!(rms < 0.02, "rms {rms} over {n} cells");
}

#[test]
fn truncated_log_gives_the_map_before_the_damage_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("drive.mcap");
    write_log(&log, 60);
    let bytes = std::fs::read(&log).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let out = dir.path().join("map");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args([
            "build".as_ref(),
            cut.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("cut.mcap"), "{err}");
    assert!(err.contains("before the damage"), "{err}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let fused = report["frames_fused"].as_u64().unwrap();
    assert!(fused > 10 && fused < 59, "{fused}");
    assert!(out.join("map.ply").exists());
}
