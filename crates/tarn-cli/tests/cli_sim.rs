//! `tarn simulate` and `tarn eval` from the command line.

use std::process::Command;

fn tarn(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args(args)
        .output()
        .unwrap()
}

const SCENE: &str = r#"
name = "cli"
seed = 3
[terrain]
origin = [-5.0, -10.0]
size = [25.0, 20.0]
resolution = 0.5
material = "grass"
[[terrain.features]]
kind = "depression"
centre = [8.0, 0.0]
radius = [3.0, 3.0]
depth = 0.5
flat = 0.5
[[water]]
kind = "level"
level = -0.2
centre = [8.0, 0.0]
radius = 4.0
[trajectory]
waypoints = [[0.0, 0.0], [1.0, 0.0]]
speed = 1.0
rate_hz = 2.0
[rig.lidar]
position = [0.0, 0.0, 1.5]
rings = 8
elevation_deg = [-20.0, 0.0]
columns = 32
azimuth_deg = [-20.0, 20.0]
dry_limit_m = 15.0
"#;

#[test]
fn simulate_then_eval_truth_against_itself() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let out = dir.path().join("out");
    let r = tarn(&[
        "simulate",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let rep: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(rep["frames"], 3);
    assert!(rep["water_cells"].as_u64().unwrap() > 0);
    for f in ["log.mcap", "truth.ply", "truth.json", "scene.ply"] {
        assert!(out.join(f).exists(), "{f}");
    }
    let map = dir.path().join("map");
    std::fs::create_dir(&map).unwrap();
    std::fs::copy(out.join("truth.ply"), map.join("map.ply")).unwrap();
    let r = tarn(&[
        "eval",
        map.to_str().unwrap(),
        "--truth",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let e: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(e["all"]["water_recall"], 1.0);
    assert_eq!(e["all"]["false_positive_rate"], 0.0);
    let bands = e["matrix_bands"].as_array().unwrap();
    let names: Vec<_> = bands.iter().map(|b| b["range"].as_str().unwrap()).collect();
    assert_eq!(names, ["5-10", "10-20", "20-30", "5-30"]);
    // Part of the pond is 5-10 m from the path; the water the sensors saw is part of all the
    // water, and the truth finds all of it.
    let b = &bands[3];
    assert_eq!(b["seen_recall"], 1.0);
    let seen = b["seen_water_cells"].as_u64().unwrap();
    assert!(
        seen > 0 && seen <= b["water_cells"].as_u64().unwrap(),
        "{b}"
    );
    assert_eq!(b["precision"], 1.0);
    assert_eq!(b["false_rate_offshore"], 0.0);
    let r = tarn(&[
        "eval",
        map.to_str().unwrap(),
        "--truth",
        out.to_str().unwrap(),
    ]);
    let table = String::from_utf8(r.stdout).unwrap();
    assert!(
        table.contains("| 30+ |") && table.contains("| all |"),
        "{table}"
    );
}

#[test]
fn bad_scene_names_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("bad.toml");
    std::fs::write(&scene, SCENE.replace("radius = 4.0", "radius = -4.0")).unwrap();
    let r = tarn(&[
        "simulate",
        scene.to_str().unwrap(),
        "--out",
        dir.path().join("o").to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(
        e.contains("bad.toml") && e.contains("water[0].radius"),
        "{e}"
    );
    assert!(!dir.path().join("o").join("log.mcap").exists());
    let r = tarn(&[
        "eval",
        dir.path().to_str().unwrap(),
        "--truth",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("map.ply"));
}
