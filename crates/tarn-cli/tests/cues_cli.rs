//! `tarn cues`: the lidar cues of one scan through the binary.

use std::process::Command;

const PLY: &str = concat!(
    concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
    "/../shared/data/rellis3d-puddle-frame/frame000104-1581624663_170.ply"
);

fn tarn(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tarn"))
        .arg("cues")
        .args(args)
        .output()
        .expect("the tarn binary runs")
}

#[test]
fn rellis_scan_json_report() {
    if !std::path::Path::new(PLY).exists() {
        eprintln!("skipped: {PLY} is absent (shared test data, kept beside the repository)");
        return;
    }
    let out = tarn(&[PLY, "--rings", "64", "--dry-limit-m", "40", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["height_estimated"], true);
    let h = v["height_m"].as_f64().unwrap();
    assert!(h > 0.5 && h < 3.0);
    let iv = v["diagnostic_interval_m"].as_array().unwrap();
    assert!((iv[1].as_f64().unwrap() - 40.0).abs() < 1e-6);
    assert_eq!(v["stats"]["slots"], 131072);
    assert_eq!(v["stats"]["missing"], 53364);
}

#[test]
fn bad_input_is_a_clear_error() {
    let out = tarn(&[
        "/nonexistent/scan.bin",
        "--rings",
        "64",
        "--dry-limit-m",
        "40",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/scan.bin"), "{err}");
    let out = tarn(&[PLY, "--rings", "63", "--dry-limit-m", "40"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("63"));
}
