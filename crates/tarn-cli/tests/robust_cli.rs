//! Robustness of the `tarn` command: an interrupted build (SIGINT) leaves the previous
//! outputs or complete new ones and no temporary files; `map.ply` is byte-identical across
//! runs and thread counts; and the catalogue of bad input in README ("Bad input") — each
//! row is a test here that checks the message on stderr and the failing exit code.

mod drive_common;
use drive_common::{base, lidar_ext, log_with_mount, scan, write_vehicle_tf};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::Point3;
use tarn_log::ros::Header;

const NS: u64 = 1_000_000_000;

fn tarn() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tarn"))
}

fn run(args: &[&str]) -> Output {
    tarn().args(args).output().unwrap()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// What a test log holds besides a plain drive.
#[derive(Default, Clone, Copy)]
struct Twist {
    /// TF of this frame has a NaN translation.
    nan_pose_at: Option<u64>,
    /// Scan stamps run backwards from this frame on.
    backwards_from: Option<u64>,
}

/// A drive of `frames` scans (10 Hz) with TF at every scan.
fn write_log(path: &Path, frames: u64, rings: usize, cols: usize, tw: Twist) {
    let mut w = log_with_mount(path);
    for k in 0..=frames {
        let ns = k * NS / 10;
        let t = ns as f64 * 1e-9;
        let mut pose = base(t);
        if tw.nan_pose_at == Some(k) {
            pose.translation.vector.x = f64::NAN;
        }
        write_vehicle_tf(&mut w, ns, pose);
        if k > 0 && k < frames {
            let stamp = match tw.backwards_from {
                Some(b) if k >= b => ns - (k - b + 1) * NS / 5,
                _ => ns,
            };
            let c = scan(&(base(t) * lidar_ext()), rings, cols);
            w.write_cloud("/lidar/points", &c, Header::new("lidar", stamp as i64), ns)
                .unwrap();
        }
    }
    w.finish().unwrap();
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `tarn ARGS`, expects failure with exit code 1 and every `needles` on stderr.
fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let o = run(args);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "tarn {args:?}: {e}");
    for n in needles {
        assert!(e.contains(n), "tarn {args:?}: stderr lacks {n:?}: {e}");
    }
    assert!(!e.contains("panicked"), "{e}");
    e
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = match std::fs::read_dir(dir) {
        Ok(r) => r.map(|e| e.unwrap().path()).collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

fn no_temp_files(dir: &Path) {
    for f in files(dir) {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.starts_with(".tarn-"), "temporary file left: {name}");
    }
}

// ------------------------------------------------------------------------------------
// SIGINT

/// Starts `tarn build LOG --out OUT`, sends SIGINT after `after_ms`, returns its output.
fn build_interrupted(log: &Path, out: &Path, after_ms: u64) -> Output {
    let child = tarn()
        .args(["build", p(log), "--out", p(out)])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(after_ms));
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    child.wait_with_output().unwrap()
}

#[test]
fn sigint_keeps_previous_outputs_and_leaves_no_partial_file() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.mcap");
    write_log(&small, 5, 8, 64, Twist::default());
    // A long log: hundreds of frames of 32 × 1024 points take seconds in any build.
    let long = dir.path().join("long.mcap");
    write_log(&long, 600, 32, 1024, Twist::default());
    let out = dir.path().join("out");
    let o = run(&["build", p(&small), "--out", p(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before: Vec<(PathBuf, Vec<u8>)> = files(&out)
        .into_iter()
        .map(|f| {
            let b = std::fs::read(&f).unwrap();
            (f, b)
        })
        .collect();
    // map.ply, terrain.ply, water.ply, map.png, report.json
    assert_eq!(before.len(), 5, "{before:?}");

    let o = build_interrupted(&long, &out, 700);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(130), "{e}");
    assert!(e.contains("interrupted while reading the log"), "{e}");
    // Exactly the old files, byte for byte, and nothing else.
    let after: Vec<(PathBuf, Vec<u8>)> = files(&out)
        .into_iter()
        .map(|f| {
            let b = std::fs::read(&f).unwrap();
            (f, b)
        })
        .collect();
    assert!(before == after, "outputs changed after SIGINT");

    // Into an empty directory: nothing at all.
    let fresh = dir.path().join("fresh");
    let o = build_interrupted(&long, &fresh, 700);
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(files(&fresh).is_empty(), "{:?}", files(&fresh));
}

// ------------------------------------------------------------------------------------
// Determinism

fn map_bytes(args: &[&str], threads: &str) -> Vec<u8> {
    let out = tempfile::tempdir().unwrap();
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--out", p(out.path())]);
    let o = tarn()
        .args(&all)
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    no_temp_files(out.path());
    std::fs::read(out.path().join("map.ply")).unwrap()
}

#[test]
fn map_ply_is_identical_across_runs_and_thread_counts() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("drive.mcap");
    write_log(&log, 40, 16, 360, Twist::default());
    // A cloud in the map frame: every lidar point of the drive, as a double PLY.
    let cloud = dir.path().join("cloud.ply");
    let mut body = Vec::new();
    let mut n = 0;
    for k in 1..40u64 {
        let t = k as f64 / 10.0;
        let s2m = base(t) * lidar_ext();
        let c = scan(&s2m, 16, 360);
        for i in 0..c.len() {
            if c.is_valid(i) {
                let [x, y, z] = c.xyz[i];
                let q = s2m * Point3::new(x as f64, y as f64, z as f64);
                for v in [q.x, q.y, q.z] {
                    body.extend_from_slice(&v.to_le_bytes());
                }
                n += 1;
            }
        }
    }
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\n\
         property double y\nproperty double z\nend_header\n"
    )
    .into_bytes();
    bytes.extend_from_slice(&body);
    std::fs::write(&cloud, bytes).unwrap();

    for input in [&log, &cloud] {
        let args = ["build", p(input), "--resolution", "0.2"];
        let a = map_bytes(&args, "1");
        assert!(a.len() > 1000, "{} bytes", a.len());
        for threads in ["1", "2", "2"] {
            let b = map_bytes(&args, threads);
            assert!(
                a == b,
                "{}: map.ply differs with {threads} threads",
                input.display()
            );
        }
    }
}

// ------------------------------------------------------------------------------------
// The catalogue of bad input (README, "Bad input")

#[test]
fn bad_clouds_are_refused_with_the_place_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let w = |name: &str, bytes: &[u8]| {
        let f = d.join(name);
        std::fs::write(&f, bytes).unwrap();
        f
    };
    let hdr = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
               property float y\nproperty float z\nend_header\n";
    // empty
    let f = w("empty.ply", b"");
    fails_with(&["build", p(&f), "--out", p(&out)], &["empty.ply"]);
    let f = w("empty.bin", b"");
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["empty.bin", "empty file"],
    );
    // truncated: 3 vertices declared, 1.5 present
    let mut t = hdr.as_bytes().to_vec();
    t.extend_from_slice(&[0u8; 18]);
    let f = w("truncated.ply", &t);
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["truncated.ply", "byte"],
    );
    let f = w("truncated.bin", &[0u8; 24]);
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["truncated.bin", "16-byte"],
    );
    // malformed header
    let f = w(
        "malformed.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex three\nend_header\n",
    );
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["malformed.ply", "header line 3"],
    );
    // wrong types: x as a list, and an unknown scalar type
    let f = w(
        "list.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n1 1 2 3\n",
    );
    fails_with(&["build", p(&f), "--out", p(&out)], &["list.ply", "x"]);
    let f = w(
        "type.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nproperty float y\nproperty float z\nend_header\n1 2 3\n",
    );
    fails_with(&["build", p(&f), "--out", p(&out)], &["type.ply", "quad"]);
    // a size that lies: 10^12 vertices in a few bytes
    let f = w(
        "lies.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0",
    );
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["lies.ply", "1000000000000"],
    );
    // NaN and inf everywhere
    let mut nan = hdr.as_bytes().to_vec();
    for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY].repeat(3) {
        nan.extend_from_slice(&v.to_le_bytes());
    }
    let f = w("nan.ply", &nan);
    fails_with(
        &["build", p(&f), "--out", p(&out)],
        &["nan.ply", "no finite point"],
    );
    // nothing was written for any of these
    assert!(files(&out).is_empty(), "{:?}", files(&out));
}

#[test]
fn nonsense_parameters_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let log = d.join("drive.mcap");
    write_log(&log, 4, 8, 64, Twist::default());
    for r in ["0", "-0.1", "NaN", "inf"] {
        fails_with(
            &[
                "build",
                p(&log),
                "--out",
                p(&out),
                &format!("--resolution={r}"),
            ],
            &["resolution"],
        );
    }
    fails_with(
        &["build", p(&log), "--out", p(&out), "--window-cells", "0"],
        &["grid size"],
    );
    // nonsense log configs: a negative tolerance, a misspelt key, a wrong type
    for (name, text, needle) in [
        ("neg.json", r#"{"tolerance_s": -1}"#, "tolerance_s"),
        ("typo.json", r#"{"lidar_topik": "/x"}"#, "lidar_topik"),
        (
            "type.json",
            r#"{"tolerance_s": "soon"}"#,
            "expected f64 at line 1 column",
        ),
    ] {
        let c = d.join(name);
        std::fs::write(&c, text).unwrap();
        fails_with(
            &["build", p(&log), "--out", p(&out), "--log-config", p(&c)],
            &[name, needle],
        );
    }
    // nonsense mapper configs: a probability of 2, a negative fording depth, a misspelt key
    for (name, text, needle) in [
        ("prior.toml", "[fusion]\nprior = 2.0\n", "fusion"),
        (
            "ford.toml",
            "[vehicle]\nfording_depth_m = -1.0\n",
            "vehicle.fording_depth_m",
        ),
        ("key.toml", "[water]\np_hihg = 0.9\n", "p_hihg"),
    ] {
        let c = d.join(name);
        std::fs::write(&c, text).unwrap();
        fails_with(
            &["build", p(&log), "--out", p(&out), "--config", p(&c)],
            &[name, needle],
        );
    }
    // a nonsense scene
    let s = d.join("scene.toml");
    std::fs::write(&s, "name = \"x\"\ntruth_resolution = -1\n").unwrap();
    fails_with(
        &["simulate", p(&s), "--out", p(&d.join("sim"))],
        &["scene.toml"],
    );
    // a colour model that is not one
    let m = d.join("model.json");
    std::fs::write(&m, r#"{"format": "tarn-color-gmm-1", "classes": [{"label": "water", "name": "w", "prior": 1, "components": [{"weight": 1, "mean": [0,0,0], "cov": [[0,0,0],[0,0,0],[0,0,0]]}]}]}"#).unwrap();
    let img = d.join("img.png");
    image::RgbImage::new(4, 4).save(&img).unwrap();
    fails_with(
        &[
            "classify",
            p(&img),
            "--model",
            p(&m),
            "--out",
            p(&d.join("mask.png")),
        ],
        &["model.json", "positive definite"],
    );
    assert!(files(&out).is_empty());
}

#[test]
fn bad_logs_are_refused_or_reported() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    // empty and not a log
    let f = d.join("empty.mcap");
    std::fs::write(&f, b"").unwrap();
    fails_with(&["build", p(&f), "--out", p(&out)], &["empty.mcap"]);
    let f = d.join("text.mcap");
    std::fs::write(&f, b"this is not an MCAP file at all").unwrap();
    fails_with(&["build", p(&f), "--out", p(&out)], &["text.mcap", "byte"]);
    assert!(files(&out).is_empty());

    // poses with NaN: the frame at that pose is skipped and named, the rest is built
    let f = d.join("nanpose.mcap");
    write_log(
        &f,
        10,
        8,
        64,
        Twist {
            nan_pose_at: Some(5),
            ..Default::default()
        },
    );
    let o = run(&["build", p(&f), "--out", p(&out), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let skipped = r["frames"]["frames_skipped_no_tf"].as_u64().unwrap()
        + r["errors"].as_array().unwrap().len() as u64;
    assert!(skipped >= 1, "{r}");
    let text = r.to_string();
    assert!(
        text.contains("not finite") || text.contains("NaN"),
        "{text}"
    );

    // timestamps going backwards: scans older than the buffered transforms are skipped and
    // named (report.json, `frames.skip_reasons`); the rest is built
    let f = d.join("backwards.mcap");
    write_log(
        &f,
        12,
        8,
        64,
        Twist {
            backwards_from: Some(8),
            ..Default::default()
        },
    );
    let o = run(&["build", p(&f), "--out", p(&d.join("out2")), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let fused = r["frames_fused"].as_u64().unwrap();
    let skipped = r["frames"]["frames_skipped_no_tf"].as_u64().unwrap();
    assert_eq!(fused + skipped, 11, "{r}");
    assert!(fused >= 7 && skipped >= 1, "{r}");
    assert!(r.to_string().contains("outside the buffered time"), "{r}");
}

// ------------------------------------------------------------------------------------
// Outputs appear together

fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files(dir)
        .into_iter()
        .map(|f| {
            let b = std::fs::read(&f).unwrap();
            (f, b)
        })
        .collect()
}

/// Staging folders (`.NAME.tarn-stage-*`) left in `parent`.
fn staging_left(parent: &Path) -> Vec<String> {
    files(parent)
        .into_iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tarn-stage-"))
        .collect()
}

/// A binary PLY of `n` points of a sloped plane over a `side`-metre square.
fn write_plane_ply(path: &Path, n: usize, side: f64) {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n\
         property float y\nproperty float z\nend_header\n"
    )
    .into_bytes();
    let k = (n as f64).sqrt().ceil() as usize;
    for i in 0..n {
        let (x, y) = (
            (i % k) as f64 * side / k as f64,
            (i / k) as f64 * side / k as f64,
        );
        for v in [x, y, 0.05 * x + 0.01 * ((i * 7919) % 13) as f64] {
            bytes.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn sigint_during_a_cloud_rebuild_keeps_the_previous_outputs_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.ply");
    write_plane_ply(&small, 10_000, 20.0);
    // Millions of points over 300 m: reading, fusing in blocks and exporting take seconds.
    let big = dir.path().join("big.ply");
    write_plane_ply(&big, 3_000_000, 300.0);
    let out = dir.path().join("out");
    let o = run(&["build", p(&small), "--out", p(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = snapshot(&out);
    assert_eq!(before.len(), 5);
    for after_ms in [150, 1500, 4000] {
        let t = std::time::Instant::now();
        let o = build_interrupted(&big, &out, after_ms);
        let e = stderr(&o);
        if o.status.success() {
            // The machine was fast enough to finish first: nothing to check at this time.
            eprintln!("build finished before SIGINT at {after_ms} ms");
            std::fs::remove_dir_all(&out).unwrap();
            let o = run(&["build", p(&small), "--out", p(&out)]);
            assert!(o.status.success(), "{}", stderr(&o));
            continue;
        }
        assert_eq!(o.status.code(), Some(130), "{e}");
        assert!(e.contains("interrupted while"), "{e}");
        let stopped_after = t.elapsed().as_secs_f64() - after_ms as f64 * 1e-3;
        eprintln!("SIGINT at {after_ms} ms: stopped {stopped_after:.2} s later: {e}");
        assert!(
            snapshot(&out) == before,
            "outputs changed after SIGINT at {after_ms} ms"
        );
        assert!(
            staging_left(dir.path()).is_empty(),
            "{:?}",
            files(dir.path())
        );
    }
}

/// A negative number is a value, and a bad one is exit 1 with the reason, not a usage error.
#[test]
fn a_negative_value_is_read_as_a_value_and_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = dir.path().join("c.ply");
    write_plane_ply(&cloud, 100, 2.0);
    for flag in [["--resolution", "-1"], ["--noise-sigma", "-0.02"]] {
        let out = dir.path().join("out");
        let o = run(&["build", p(&cloud), "--out", p(&out), flag[0], flag[1]]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{flag:?}: {e}");
        assert!(e.contains(flag[1]) && !e.contains("tip:"), "{flag:?}: {e}");
        assert!(!out.exists());
    }
}

#[test]
fn a_build_killed_outright_leaves_a_staging_folder_that_the_next_build_removes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let big = d.join("big.ply");
    write_plane_ply(&big, 3_000_000, 300.0);
    let out = d.join("out");
    let mut child = tarn()
        .args(["build", p(&big), "--out", p(&out)])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // SIGKILL as soon as the export has begun: the staging folder exists.
    let t = std::time::Instant::now();
    while staging_left(d).is_empty() && t.elapsed().as_secs() < 60 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let _ = child.kill();
    let status = child.wait().unwrap();
    let left = staging_left(d);
    if status.success() || left.is_empty() {
        eprintln!("the build finished before it could be killed: nothing to check");
        return;
    }
    let small = d.join("small.ply");
    write_plane_ply(&small, 10_000, 20.0);
    let o = run(&["build", p(&small), "--out", p(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("removed {}", d.join(&left[0]).display())),
        "{}",
        stderr(&o)
    );
    assert!(staging_left(d).is_empty(), "{:?}", files(d));
    let report = std::fs::read_to_string(out.join("report.json")).unwrap();
    assert!(report.contains("killed before it finished"), "{report}");
}

#[test]
fn a_failed_build_leaves_no_output_and_no_staging_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let garbage = d.join("garbage.mcap");
    std::fs::write(&garbage, b"not a log, not at all").unwrap();
    let nan = d.join("nan.ply");
    std::fs::write(
        &nan,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
         property float z\nend_header\nnan 0 0\n0 nan 0\n",
    )
    .unwrap();
    // Finite points, every one beyond the map's ±1e8 m domain: nothing to build.
    let far = d.join("far.ply");
    std::fs::write(
        &far,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
         property float z\nend_header\n2e8 0 0\n0 -3e9 1\n",
    )
    .unwrap();
    let good = d.join("good.ply");
    write_plane_ply(&good, 10_000, 20.0);
    let kept = d.join("kept");
    let o = run(&["build", p(&good), "--out", p(&kept)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = snapshot(&kept);
    let o = run(&["build", p(&far), "--out", p(&d.join("fresh"))]);
    assert!(
        stderr(&o).contains("nothing built: none of the 2 points lies within the map's domain"),
        "{}",
        stderr(&o)
    );
    for input in [&garbage, &nan, &far] {
        let fresh = d.join("fresh");
        let o = run(&["build", p(input), "--out", p(&fresh)]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(!fresh.exists(), "{input:?}: {:?}", files(&fresh));
        let o = run(&["build", p(input), "--out", p(&kept)]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(
            snapshot(&kept) == before,
            "{input:?} changed the previous outputs"
        );
        assert!(staging_left(d).is_empty(), "{:?}", files(d));
    }
    assert!(staging_left(d).is_empty(), "{:?}", files(d));
}
