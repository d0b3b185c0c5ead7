//! `tarn lidar-model --json`: the contract keys and the paper's numbers, through the binary.

use std::process::Command;

use serde_json::Value;

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tarn"))
        .arg("lidar-model")
        .args(args)
        .output()
        .expect("the tarn binary runs")
}

fn json(args: &[&str]) -> Value {
    let out = run(args);
    assert!(
        out.status.success(),
        "tarn lidar-model {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON object")
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

#[test]
fn contract_keys_and_paper_numbers() {
    let v = json(&[
        "--height-m",
        "1",
        "--wavelength-nm",
        "900",
        "--depth-m",
        "0.3",
        "--lookahead-m",
        "0,1,2,5,8",
        "--dry-limit-m",
        "11",
        "--json",
    ]);
    for key in [
        "attenuation_per_m",
        "min_power_ratio",
        "dry_limit_m",
        "zero_depth_cutoff_m",
        "max_lookahead_for_depth_m",
        "diagnostic_interval_m",
        "rows",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    // Segelstein at 900 nm.
    assert!((num(&v, "attenuation_per_m") - 6.82).abs() < 0.05);
    assert!((num(&v, "dry_limit_m") - 11.0).abs() < 1e-6);
    let cut = num(&v, "zero_depth_cutoff_m");
    assert!((cut - 6.5).abs() < 0.3, "{cut}");
    assert!(num(&v, "max_lookahead_for_depth_m") < 2.0);
    let interval = v["diagnostic_interval_m"].as_array().unwrap();
    assert_eq!(interval.len(), 2);
    assert_eq!(
        interval[0].as_f64(),
        Some(num(&v, "max_lookahead_for_depth_m"))
    );
    assert!((interval[1].as_f64().unwrap() - 11.0).abs() < 1e-6);

    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 5);
    let p = num(&v, "min_power_ratio");
    let mut last_return = f64::INFINITY;
    for (row, want_d) in rows.iter().zip([0.0, 1.0, 2.0, 5.0, 8.0]) {
        for key in [
            "lookahead_m",
            "incidence_deg",
            "transmittance_s",
            "transmittance_p",
            "return_ratio",
            "dry_ratio",
            "max_depth_m",
        ] {
            assert!(row[key].as_f64().is_some(), "row lacks {key}: {row}");
        }
        assert_eq!(num(row, "lookahead_m"), want_d);
        assert!((num(row, "incidence_deg") - want_d.atan().to_degrees()).abs() < 1e-9);
        let r = num(row, "return_ratio");
        assert!(r < last_return && r < num(row, "dry_ratio"));
        last_return = r;
        // Past the zero-depth cutoff nothing returns.
        if want_d > cut {
            assert_eq!(num(row, "max_depth_m"), 0.0);
        } else {
            assert!(num(row, "max_depth_m") > 0.0);
        }
        // 30 cm returns exactly where max_depth ≥ 0.3.
        assert_eq!(r >= p, num(row, "max_depth_m") >= 0.3);
    }
    // Normal incidence: T = 1 − ((n−1)/(n+1))².
    let t0 = 1.0 - (0.33f64 / 2.33).powi(2);
    assert!((num(&rows[0], "transmittance_s") - t0).abs() < 1e-12);
    assert!((num(&rows[0], "transmittance_p") - t0).abs() < 1e-12);
}

#[test]
fn attenuation_and_min_power_can_be_given_directly() {
    let dry = json(&[
        "--height-m",
        "1",
        "--attenuation-per-m",
        "2.2",
        "--dry-limit-m",
        "11",
        "--depth-m",
        "0.5",
        "--json",
    ]);
    let p = num(&dry, "min_power_ratio");
    let direct = json(&[
        "--height-m",
        "1",
        "--attenuation-per-m",
        "2.2",
        "--min-power-ratio",
        &format!("{p:e}"),
        "--depth-m",
        "0.5",
        "--json",
    ]);
    assert_eq!(num(&direct, "attenuation_per_m"), 2.2);
    assert!((num(&direct, "dry_limit_m") - 11.0).abs() < 1e-6);
    // Murky water: half a metre measurable out to about 2 m.
    let d = num(&direct, "max_lookahead_for_depth_m");
    assert!((1.5..3.0).contains(&d), "{d}");
    // Default lookaheads run every 0.5 m past the dry limit.
    let rows = direct["rows"].as_array().unwrap();
    assert!(rows.len() > 22 && num(&rows[1], "lookahead_m") == 0.5);
}

#[test]
fn paper_solid_angle_is_never_more_pessimistic() {
    let args = [
        "--height-m",
        "1",
        "--wavelength-nm",
        "625",
        "--dry-limit-m",
        "11",
        "--lookahead-m",
        "1,2,4,6",
        "--json",
    ];
    let exact = json(&args);
    let mut paper_args = args.to_vec();
    paper_args.extend(["--solid-angle", "paper"]);
    let paper = json(&paper_args);
    let pairs = exact["rows"]
        .as_array()
        .unwrap()
        .iter()
        .zip(paper["rows"].as_array().unwrap());
    for (a, b) in pairs {
        assert!(num(b, "max_depth_m") >= num(a, "max_depth_m"));
    }
    assert!(num(&exact["rows"][2], "max_depth_m") > 1.5); // clear water at 4 m
}

#[test]
fn too_strong_absorption_returns_nothing() {
    let v = json(&[
        "--height-m",
        "1",
        "--wavelength-nm",
        "1550",
        "--depth-m",
        "0.01",
        "--dry-limit-m",
        "11",
        "--lookahead-m",
        "0,1",
        "--json",
    ]);
    assert_eq!(num(&v, "max_lookahead_for_depth_m"), 0.0);
    for row in v["rows"].as_array().unwrap() {
        assert!(num(row, "return_ratio") < num(&v, "min_power_ratio"));
    }
}

#[test]
fn bad_arguments_fail_with_a_message() {
    let base = [
        "--height-m",
        "1",
        "--wavelength-nm",
        "900",
        "--dry-limit-m",
        "11",
    ];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        base.iter().chain(extra).copied().collect()
    };
    for args in [
        vec!["--height-m", "1", "--dry-limit-m", "11"], // no attenuation
        vec!["--height-m", "1", "--wavelength-nm", "900"], // no sensitivity
        vec![
            "--height-m",
            "-1",
            "--wavelength-nm",
            "900",
            "--dry-limit-m",
            "11",
        ],
        vec![
            "--height-m",
            "1",
            "--wavelength-nm",
            "5000",
            "--dry-limit-m",
            "11",
        ],
        with(&["--albedo", "2"]),
        with(&["--lookahead-m", "1,-2"]),
        with(&["--depth-m", "nan"]),
        with(&["--attenuation-per-m", "1"]),  // both attenuations
        with(&["--min-power-ratio", "1e-8"]), // both sensitivities
    ] {
        let out = run(&args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.trim().is_empty(), "{args:?} gave no message");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn plot_writes_a_png() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.png");
    let out = run(&[
        "--height-m",
        "1",
        "--wavelength-nm",
        "905",
        "--dry-limit-m",
        "11",
        "--plot",
        path.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&path).unwrap();
    assert_eq!((img.width(), img.height()), (1600, 1200));
    // Something was drawn: not a blank page.
    let rgb = img.to_rgb8();
    let dark = rgb.pixels().filter(|p| p.0.iter().all(|&c| c < 80)).count();
    assert!(dark > 10_000, "{dark} dark pixels");
    // Nothing else left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}
