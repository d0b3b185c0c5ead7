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

/// A log from a thermal camera: its MWIR labels run by default, at the local solar hour of
/// each frame's stamp and the log's GNSS fix; without a fix (or a longitude, or `--hour`)
/// they are skipped with a warning and the map is still built.
#[test]
fn mwir_labels_take_their_hour_from_the_log_or_are_skipped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mwir = "[rig.mwir]\nposition = [0.0, 0.0, 1.5]\nrpy_deg = [0.0, 10.0, 0.0]\n\
                width = 32\nheight = 24\nhfov_deg = 50.0\n[sky]\ntime_of_day = 3.0\n";
    let p = |x: &std::path::Path| x.to_str().unwrap().to_string();
    for (name, gps) in [("fix", "[rig.gps]\n"), ("nofix", "")] {
        let scene = dir.path().join(format!("{name}.toml"));
        std::fs::write(&scene, format!("{SCENE}{mwir}{gps}")).unwrap();
        let sim = dir.path().join(format!("{name}-sim"));
        let r = tarn(&["simulate", &p(&scene), "--out", &p(&sim)]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let out = dir.path().join(format!("{name}-map"));
        let r = tarn(&["build", &p(&sim.join("log.mcap")), "--out", &p(&out)]);
        let (so, se) = (
            String::from_utf8_lossy(&r.stdout),
            String::from_utf8_lossy(&r.stderr),
        );
        assert_eq!(r.status.code(), Some(0), "{name}: {se}");
        let rep: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        let m = &rep["labels"]["mwir"];
        if gps.is_empty() {
            assert_eq!(m["frames"], 0, "{rep}");
            assert_eq!(m["frames_no_hour"], 3, "{rep}");
            assert!(se.contains("no local solar hour"), "{se}");
            // A longitude given: the same log's hour from its stamps.
            let r = tarn(&[
                "build",
                &p(&sim.join("log.mcap")),
                "--out",
                &p(&out),
                "--labels",
                "mwir",
                "--longitude=-120.5",
            ]);
            assert!(r.status.success());
            let rep: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                    .unwrap();
            assert_eq!(rep["labels"]["mwir"]["frames_hour_from_stamp"], 3, "{rep}");
        } else {
            assert_eq!(m["frames"], 3, "{rep}");
            assert_eq!(m["frames_hour_from_stamp"], 3, "{rep}");
            let [a, b] = [0, 1].map(|i| rep["labels"]["mwir_hours"][i].as_f64().unwrap());
            assert!((a - 3.0).abs() < 1e-3 && (b - 3.0).abs() < 1e-3, "{a} {b}");
            assert!(so.contains("mwir labels: 3 frames"), "{so}");
            assert!(!se.contains("no local solar hour"), "{se}");
        }
    }
}

/// A log with a lidar alone: `tarn info` and the build name the lidar and nothing the log
/// does not carry (no stereo cues, no camera labels, no stereo datasheet value assumed).
#[test]
fn a_lidar_only_log_is_reported_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let p = |x: &std::path::Path| x.to_str().unwrap().to_string();
    let sim = dir.path().join("sim");
    assert!(tarn(&["simulate", &p(&scene), "--out", &p(&sim)])
        .status
        .success());
    let log = p(&sim.join("log.mcap"));
    let info = String::from_utf8(tarn(&["info", &log]).stdout).unwrap();
    assert!(info.contains("sensors: lidar /lidar/points\n"), "{info}");
    let out = dir.path().join("map");
    let r = tarn(&["build", &log, "--out", &p(&out)]);
    assert!(r.status.success());
    let text = String::from_utf8(r.stdout).unwrap();
    assert!(
        !text.contains("stereo") && !text.contains("labels"),
        "{text}"
    );
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        rep["cues"],
        serde_json::json!(["lidar", "reflectivity"]),
        "{rep}"
    );
    assert!(rep["labels"].is_null(), "{rep}");
}
