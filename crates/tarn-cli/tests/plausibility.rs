//! Plausibility gates and bounded cost on absurd input: a pose that jumps faster than the
//! vehicle moves is refused with a message; a transform whose quaternion is not a rotation
//! is refused; points at 1e12 m and 1e20 m in a PLY, a KITTI scan or a log build cleanly
//! under a 2 GB address-space limit, dropped and counted.

mod drive_common;
use drive_common::{base, lidar_ext, log_with_mount, scan, write_vehicle_tf};

use std::path::Path;
use std::process::{Command, Output};

use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use tarn::geom::Pose;
use tarn_log::ros::Header;

const NS: u64 = 1_000_000_000;

/// Runs `tarn ARGS` with its address space limited to 2 GB.
fn run_capped(args: &[&str]) -> Output {
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg("ulimit -v 2000000 && exec \"$@\"")
        .arg("sh")
        .arg(env!("CARGO_BIN_EXE_tarn"))
        .args(args);
    cmd.output().unwrap()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[derive(Default, Clone, Copy)]
struct Twist {
    /// The vehicle's TF at this frame is 100 km off.
    jump_at: Option<u64>,
    /// The vehicle's TF at this frame has a NaN quaternion.
    nan_quaternion_at: Option<u64>,
    /// Every scan has points at 1e12 m and 1e20 m.
    far_points: bool,
}

/// A drive of `frames` scans (10 Hz) with TF at every scan.
fn write_log(path: &Path, frames: u64, tw: Twist) {
    let mut w = log_with_mount(path);
    for k in 0..=frames {
        let ns = k * NS / 10;
        let t = ns as f64 * 1e-9;
        let mut pose = base(t);
        if tw.jump_at == Some(k) {
            pose.translation.vector.x += 1e5;
        }
        if tw.nan_quaternion_at == Some(k) {
            pose = Pose::from_parts(
                pose.translation,
                UnitQuaternion::new_unchecked(Quaternion::new(f64::NAN, 0.0, 0.0, 0.0)),
            );
        }
        write_vehicle_tf(&mut w, ns, pose);
        if k > 0 && k < frames {
            let mut c = scan(&(base(t) * lidar_ext()), 8, 64);
            if tw.far_points {
                c.xyz[3] = [1e12, 0.0, -1.8];
                c.xyz[9] = [0.0, -1e20, -1.8];
            }
            w.write_cloud("/lidar/points", &c, Header::new("lidar", ns as i64), ns)
                .unwrap();
        }
    }
    w.finish().unwrap();
}

fn report(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap()
}

#[test]
fn a_pose_jump_is_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let (log, out) = (dir.path().join("jump.mcap"), dir.path().join("out"));
    write_log(
        &log,
        20,
        Twist {
            jump_at: Some(8),
            ..Default::default()
        },
    );
    let o = run_capped(&["build", p(&log), "--out", p(&out)]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    // The message names the frame, the distance and the limit.
    assert!(err.contains("/lidar/points at 0.800000000 s"), "{err}");
    assert!(err.contains("moved 100000."), "{err}");
    assert!(err.contains("log.max_speed_mps 30 m/s"), "{err}");
    let r = report(&out);
    assert_eq!(r["frames"]["frames_refused_pose_jump"], 1, "{r}");
    assert_eq!(r["frames_fused"], 18, "{r}");
    // The map is the drive's, not 100 km wide.
    let png = image::open(out.join("map.png")).unwrap();
    assert!(png.width() < 1000, "{} px", png.width());

    // A looser limit lets it through (and the map is drawn at a capped size).
    let cfg = dir.path().join("fast.toml");
    std::fs::write(&cfg, "[lidar]\n[log]\nmax_speed_mps = 1e7\n").unwrap();
    let out2 = dir.path().join("out2");
    let o = run_capped(&["build", p(&log), "--out", p(&out2), "--config", p(&cfg)]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    assert_eq!(report(&out2)["frames"]["frames_refused_pose_jump"], 0);
    let png = image::open(out2.join("map.png")).unwrap();
    assert!(png.width() <= 4096, "{} px", png.width());
}

#[test]
fn a_nan_quaternion_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (log, out) = (dir.path().join("nanq.mcap"), dir.path().join("out"));
    write_log(
        &log,
        12,
        Twist {
            nan_quaternion_at: Some(5),
            ..Default::default()
        },
    );
    let o = run_capped(&["build", p(&log), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let r = report(&out);
    let errors = r["errors"].to_string();
    assert!(
        errors.contains("/tf") && errors.contains("its rotation is not finite"),
        "{r}"
    );

    // The mapper refuses such a pose in a frame handed to it directly.
    let mut mapper = tarn::mapper::Mapper::new(tarn::mapper::MapperConfig::default()).unwrap();
    let bad = Pose::from_parts(
        Translation3::new(1.0, 2.0, 0.0),
        UnitQuaternion::new_unchecked(Quaternion::new(f64::NAN, 0.0, 0.0, 0.0)),
    );
    let mut cloud = scan(&lidar_ext(), 8, 64);
    cloud.frame_to_map = lidar_ext();
    let frame = tarn::sensor::Frame {
        stamp: 3.5,
        base_to_map: bad,
        lidar: Some(cloud),
        stereo: None,
        image: None,
        swir: None,
        mwir: None,
        stereo_baseline_m: None,
        geo: None,
    };
    let e = mapper.update(&frame).unwrap_err().to_string();
    assert!(
        e.contains("frame at 3.500000 s") && e.contains("not a unit quaternion"),
        "{e}"
    );
}

#[test]
fn far_points_in_a_log_are_dropped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let (log, out) = (dir.path().join("far.mcap"), dir.path().join("out"));
    write_log(
        &log,
        10,
        Twist {
            far_points: true,
            ..Default::default()
        },
    );
    let o = run_capped(&["build", p(&log), "--out", p(&out)]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(
        err.contains("lidar.max_range_m = 300 m dropped (farthest 1.0000e20 m)"),
        "{err}"
    );
    let r = report(&out);
    assert_eq!(r["points_beyond_max_range"]["lidar"], 18, "{r}");
    // One line for the nine frames that dropped points, with their span.
    let w = r["warnings"].as_array().unwrap();
    assert_eq!(w.len(), 1, "{r}");
    assert!(w[0].as_str().unwrap().starts_with("9 frames from "), "{r}");
}

#[test]
fn far_points_in_clouds_build_with_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut pts: Vec<[f32; 3]> = Vec::new();
    for j in 0..50 {
        for i in 0..50 {
            // Off the origin: a KITTI point at (0, 0, 0) is a missing return.
            pts.push([
                0.05 + i as f32 * 0.1,
                0.05 + j as f32 * 0.1,
                0.01 * i as f32,
            ]);
        }
    }
    for v in [1e12f32, -1e12, 1e20, -1e20] {
        pts.push([v, 1.0, 0.0]);
        pts.push([1.0, v, 0.0]);
        pts.push([v, v, v]);
    }
    // A binary PLY and a KITTI scan of the same points.
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        pts.len()
    )
    .into_bytes();
    let mut kitti = Vec::new();
    for q in &pts {
        for v in q {
            ply.extend_from_slice(&v.to_le_bytes());
            kitti.extend_from_slice(&v.to_le_bytes());
        }
        kitti.extend_from_slice(&0.5f32.to_le_bytes());
    }
    for (name, bytes) in [("far.ply", &ply), ("far.bin", &kitti)] {
        let f = d.join(name);
        std::fs::write(&f, bytes).unwrap();
        let out = d.join(format!("out-{name}"));
        let o = run_capped(&["build", p(&f), "--out", p(&out), "--json"]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", text(&o.stderr));
        let r = report(&out);
        assert_eq!(r["points"]["fused"], 2500, "{name}: {r}");
        assert_eq!(r["points"]["outside"], 12, "{name}: {r}");
        let png = image::open(out.join("map.png")).unwrap();
        assert!(png.width() < 1000 && png.height() < 1000);
    }
}

/// Logs whose Schema or Channel records carry a corrupted length prefix (a string claiming
/// 2–3 GB inside a record of a few hundred bytes, in a chunk or in the summary section):
/// `tarn info` and `tarn build` read around them under a 2 GB address-space limit instead
/// of asking for the claimed size.
#[test]
fn corrupted_length_prefixes_in_logs_allocate_nothing_they_claim() {
    let dir =
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("fuzz/regressions/mcap");
    let out = tempfile::tempdir().unwrap();
    for name in [
        "channel-string-claims-gigabytes.mcap",
        "record-string-claims-gigabytes.mcap",
    ] {
        let log = dir.join(name);
        for args in [
            vec!["info", p(&log)],
            vec!["build", p(&log), "--out", p(out.path())],
        ] {
            let o = run_capped(&args);
            let err = text(&o.stderr);
            assert!(
                matches!(o.status.code(), Some(0 | 1 | 3)),
                "{name} {args:?}: {:?}\n{err}",
                o.status
            );
            assert!(!err.contains("memory allocation"), "{name}: {err}");
        }
    }
}
