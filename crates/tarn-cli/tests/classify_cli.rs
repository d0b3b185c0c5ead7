//! `tarn train-colour` and `tarn classify` on a synthetic scene with a known answer.

use std::process::Command;

fn tarn(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// 120 × 90: sky (rows < 20, clipped white and pale blue), grass, and a sky-reflecting pond
/// (bright, weakly saturated) in rows 50..80, columns 30..90. Labels: 7 sky, 3 grass, 31 water.
fn scene(dir: &std::path::Path) -> (String, String) {
    let (w, h) = (120u32, 90u32);
    let mut rgb = image::RgbImage::new(w, h);
    let mut ids = image::GrayImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let n = ((x * 7 + y * 13) % 11) as u8; // texture
            let (p, id) = if y < 20 {
                (
                    if x % 3 == 0 {
                        [255, 255, 255]
                    } else {
                        [200 + n, 215 + n, 240]
                    },
                    7,
                )
            } else if (50..80).contains(&y) && (30..90).contains(&x) {
                ([170 + n, 180 + n, 200 + n], 31)
            } else {
                ([60 + n, 90 + n, 30 + n], 3)
            };
            rgb.put_pixel(x, y, image::Rgb(p));
            ids.put_pixel(x, y, image::Luma([id]));
        }
    }
    let (a, b) = (dir.join("img.png"), dir.join("ids.png"));
    rgb.save(&a).unwrap();
    ids.save(&b).unwrap();
    (a.display().to_string(), b.display().to_string())
}

#[test]
fn train_then_classify_with_horizon() {
    let dir = tempfile::tempdir().unwrap();
    let (img, ids) = scene(dir.path());
    let model = dir.path().join("m.json").display().to_string();
    let (ok, out, err) = tarn(&[
        "train-colour",
        "--image",
        &img,
        "--labels",
        &ids,
        "--water-ids",
        "31",
        "--sky-ids",
        "7",
        "--out",
        &model,
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("water") && out.contains("BIC"), "{out}");
    let mask = dir.path().join("mask.png").display().to_string();
    let lab = dir.path().join("labels.png").display().to_string();
    let (ok, out, err) = tarn(&[
        "classify",
        &img,
        "--model",
        &model,
        "--out",
        &mask,
        "--labels-out",
        &lab,
        "--horizon-row",
        "20",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("horizon: 2400 pixels above"), "{out}");
    let m = image::open(&mask).unwrap().to_luma8();
    let l = image::open(&lab).unwrap().to_luma8();
    for (x, y, p) in m.enumerate_pixels() {
        let water = (50..80).contains(&y) && (30..90).contains(&x);
        assert_eq!(p.0[0] == 255, water, "mask at ({x}, {y})");
        assert!(p.0[0] == 0 || p.0[0] == 255);
        let want = if y < 20 {
            2
        } else if water {
            1
        } else {
            0
        };
        assert_eq!(l.get_pixel(x, y).0[0], want, "label at ({x}, {y})");
    }
    // Camera form of the horizon: a level camera, 640 × 480 intrinsics scaled to this image
    // with cy = 19.5 → rows ≤ 19 above.
    let info = dir.path().join("cam.json");
    std::fs::write(&info, r#"{"width":120,"height":90,"k":[100,100,59.5,19.5],"distortion_model":"plumb_bob","d":[0,0,0,0,0]}"#).unwrap();
    let (ok, out, err) = tarn(&[
        "classify",
        &img,
        "--model",
        &model,
        "--out",
        &mask,
        "--camera-info",
        info.to_str().unwrap(),
        "--camera-pose",
        "0,0,1.5,0,0,0",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("horizon: 2400 pixels above"), "{out}");
}

#[test]
fn bad_inputs_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (img, ids) = scene(dir.path());
    let model = dir.path().join("m.json").display().to_string();
    let (ok, _, err) = tarn(&[
        "train-colour",
        "--image",
        &img,
        "--labels",
        &ids,
        "--water-ids",
        "99",
        "--out",
        &model,
    ]);
    assert!(!ok && err.contains("no pixel of the water ids 99"), "{err}");
    let (ok, _, err) = tarn(&[
        "train-colour",
        "--image",
        &img,
        "--labels",
        &ids,
        "--water-ids",
        "31",
        "--region",
        "0,0,500,10",
        "--out",
        &model,
    ]);
    assert!(!ok && err.contains("training region"), "{err}");
    assert!(!std::path::Path::new(&model).exists());
    std::fs::write(&model, "{\"format\": 1}").unwrap();
    let mask = dir.path().join("mask.png").display().to_string();
    let (ok, _, err) = tarn(&["classify", &img, "--model", &model, "--out", &mask]);
    assert!(!ok && err.contains("m.json"), "{err}");
    assert!(!std::path::Path::new(&mask).exists());
    // Without a model: the paper's Table 1 rule.
    let (ok, out, err) = tarn(&["classify", &img, "--out", &mask]);
    assert!(ok, "{err}");
    assert!(out.contains("water"), "{out}");
}
