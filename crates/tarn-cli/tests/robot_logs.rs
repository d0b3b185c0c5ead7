//! Logs as robots record them: the lidar on a driver's topic (`/ouster/points`), found by
//! its type or named with `--lidar-topic`; several candidate topics refused with the
//! choice named; and unorganized scans (height 1, as Velodyne and Ouster drivers publish
//! them) organized by their `ring` field so that the lidar cues see the same scan, or,
//! without one, a warning that the cues cannot run.

mod drive_common;
use drive_common::{base, lidar_ext, log_with_mount, write_vehicle_tf};

use std::path::Path;
use std::process::{Command, Output};

use nalgebra::{Point3, Vector3};
use tarn::geom::{PointCloud, Pose};
use tarn_log::ros::msgs::datatype;
use tarn_log::ros::{Header, PointCloud2Msg, PointField};

const NS: u64 = 1_000_000_000;
const RINGS: usize = 32;
const COLS: usize = 360;

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args(args)
        .output()
        .unwrap()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A `RINGS` × `COLS` scan of level ground with a pond (no returns) 19.5–28 m ahead of the
/// vehicle, seen from `sensor_to_map`; intensity 10 + ring.
fn scan(sensor_to_map: &Pose) -> PointCloud {
    let o = sensor_to_map * Point3::origin();
    let fwd = sensor_to_map * Vector3::x();
    let mut xyz = Vec::new();
    let mut inten = Vec::new();
    for r in 0..RINGS {
        let el = (-25.0 + 23.0 * r as f64 / (RINGS - 1) as f64).to_radians();
        for c in 0..COLS {
            let az = (c as f64 * 360.0 / COLS as f64).to_radians();
            let ds = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let d = sensor_to_map * ds;
            let t = -o.z / d.z;
            let hit = o + d * t;
            let ahead = (hit - o).dot(&fwd);
            let side = (hit - o - fwd * ahead).norm();
            let pond = (19.5..28.0).contains(&ahead) && side < 4.0;
            xyz.push(if t > 0.5 && t < 30.0 && !pond {
                let q = ds * t;
                [q.x as f32, q.y as f32, q.z as f32]
            } else {
                [f32::NAN; 3]
            });
            inten.push(10.0 + r as f32);
        }
    }
    let mut c = PointCloud::organized(RINGS, COLS, xyz).unwrap();
    c.intensity = Some(inten);
    c
}

/// How the lidar's scans are published.
#[derive(Clone, Copy, PartialEq)]
enum Layout {
    /// height = rings, width = columns.
    Organized,
    /// Height 1, ring by ring, every slot kept (missing returns NaN), with `ring`.
    FlatRing,
    /// Height 1, missing returns dropped, with `ring` (a dense driver).
    DenseRing,
    /// Height 1, every slot kept, no `ring` field.
    FlatNoRing,
}

fn pointcloud2(c: &PointCloud, layout: Layout, header: Header) -> PointCloud2Msg {
    let f = |name: &str, offset, dt| PointField {
        name: name.into(),
        offset,
        datatype: dt,
        count: 1,
    };
    let mut fields = vec![
        f("x", 0, datatype::FLOAT32),
        f("y", 4, datatype::FLOAT32),
        f("z", 8, datatype::FLOAT32),
        f("intensity", 12, datatype::FLOAT32),
    ];
    if layout != Layout::FlatNoRing {
        fields.push(f("ring", 16, datatype::UINT16));
    }
    let step = 20u32;
    let mut data = Vec::new();
    let mut n = 0u32;
    for i in 0..c.len() {
        if layout == Layout::DenseRing && !c.is_valid(i) {
            continue;
        }
        for v in c.xyz[i] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.extend_from_slice(&c.intensity.as_ref().unwrap()[i].to_le_bytes());
        data.extend_from_slice(&((i / c.cols) as u16).to_le_bytes());
        data.extend_from_slice(&[0, 0]);
        n += 1;
    }
    let (height, width) = match layout {
        Layout::Organized => (c.rows as u32, c.cols as u32),
        _ => (1, n),
    };
    PointCloud2Msg {
        header,
        height,
        width,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: step * width,
        data,
        is_dense: layout == Layout::DenseRing,
    }
}

/// A 10 Hz drive of 12 scans on each of `topics`, TF at every scan.
fn write_log(path: &Path, topics: &[&str], layout: Layout) {
    let mut w = log_with_mount(path);
    let frames = 13u64;
    for k in 0..=frames {
        let ns = k * NS / 10;
        let t = ns as f64 * 1e-9;
        write_vehicle_tf(&mut w, ns, base(t));
        if k > 0 && k < frames {
            let c = scan(&(base(t) * lidar_ext()));
            let m = pointcloud2(&c, layout, Header::new("lidar", ns as i64));
            for topic in topics {
                w.write_pointcloud2(topic, &m, ns).unwrap();
            }
        }
    }
    w.finish().unwrap();
}

fn build(log: &Path, out: &Path, extra: &[&str]) -> (Output, serde_json::Value) {
    let mut args = vec!["build", p(log), "--out", p(out), "--json"];
    args.extend_from_slice(extra);
    let o = run(&args);
    let rep = serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null);
    (o, rep)
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "{:?}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
}

/// map.ply without its header comments (they name the input).
fn map_body(out: &Path) -> Vec<u8> {
    let data = std::fs::read(out.join("map.ply")).unwrap();
    let text_end = data.windows(11).position(|w| w == b"end_header\n").unwrap();
    let head: Vec<&[u8]> = data[..text_end]
        .split(|&b| b == b'\n')
        .filter(|l| !l.starts_with(b"comment"))
        .collect();
    let mut v = head.join(&b'\n');
    v.extend_from_slice(&data[text_end..]);
    v
}

#[test]
fn a_lidar_on_a_driver_topic_is_found_by_type_or_named() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("ouster.mcap");
    write_log(&log, &["/ouster/points"], Layout::Organized);

    let (o, rep) = build(&log, &d.path().join("found"), &[]);
    ok(&o);
    assert_eq!(rep["frame_topic"], "/ouster/points");
    assert_eq!(rep["frames_fused"], 12);
    assert!(
        rep["cue_counts"]["lidar_noret"].as_u64().unwrap() > 0,
        "{rep}"
    );

    let (o, rep) = build(
        &log,
        &d.path().join("named"),
        &["--lidar-topic", "/ouster/points"],
    );
    ok(&o);
    assert_eq!(rep["frames_fused"], 12);
    assert_eq!(
        map_body(&d.path().join("found")),
        map_body(&d.path().join("named"))
    );

    let o = run(&["info", p(&log)]);
    ok(&o);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("lidar /ouster/points"), "{out}");
    assert!(out.contains("12 would be built"), "{out}");

    // A named topic the log does not have: refused, with the topics it has.
    let o = run(&[
        "build",
        p(&log),
        "--out",
        p(&d.path().join("x")),
        "--lidar-topic",
        "/velodyne_points",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("/velodyne_points") && err.contains("/ouster/points"),
        "{err}"
    );
}

#[test]
fn two_candidate_lidars_are_refused_with_the_choice_named() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("two.mcap");
    write_log(
        &log,
        &["/ouster/points", "/velodyne_points"],
        Layout::Organized,
    );
    for cmd in ["build", "info"] {
        let out = d.path().join("out");
        let mut args = vec![cmd, p(&log)];
        if cmd == "build" {
            args.extend(["--out", p(&out)]);
        }
        let o = run(&args);
        assert_eq!(o.status.code(), Some(1), "{cmd}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("/ouster/points")
                && err.contains("/velodyne_points")
                && err.contains("--lidar-topic")
                && err.contains("two.mcap"),
            "{cmd}: {err}"
        );
    }
    let (o, rep) = build(
        &log,
        &d.path().join("chosen"),
        &["--lidar-topic", "/velodyne_points"],
    );
    ok(&o);
    assert_eq!(rep["frame_topic"], "/velodyne_points");
    // The other cloud is then taken for nothing else: no stereo topic is guessed from it.
    assert_eq!(rep["stereo_points"]["points"], 0);
}

#[test]
fn unorganized_scans_with_a_ring_field_give_the_organized_map() {
    let d = tempfile::tempdir().unwrap();
    let mut bodies = Vec::new();
    let mut noret = Vec::new();
    for (name, layout) in [
        ("organized", Layout::Organized),
        ("flat", Layout::FlatRing),
        ("dense", Layout::DenseRing),
    ] {
        let log = d.path().join(format!("{name}.mcap"));
        write_log(&log, &["/lidar/points"], layout);
        let out = d.path().join(name);
        let (o, rep) = build(&log, &out, &[]);
        ok(&o);
        assert_eq!(rep["frames_fused"], 12, "{name}");
        assert!(
            rep["warnings"].as_array().unwrap().is_empty(),
            "{name}: {}",
            rep["warnings"]
        );
        bodies.push(map_body(&out));
        noret.push(rep["cue_counts"]["lidar_noret"].as_u64().unwrap());
    }
    assert!(noret[0] > 0);
    assert_eq!(noret[1], noret[0], "ring order, every slot kept");
    assert!(
        bodies[1] == bodies[0],
        "ring order, every slot kept: map.ply differs"
    );
    // Returns dropped by the driver: the azimuth bins put every return back in its column.
    assert_eq!(noret[2], noret[0], "dense scan organized by azimuth");
    assert!(bodies[2] == bodies[0], "dense scan: map.ply differs");
}

#[test]
fn an_unorganized_scan_without_ring_warns_that_the_lidar_cues_cannot_run() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("noring.mcap");
    write_log(&log, &["/lidar/points"], Layout::FlatNoRing);
    let (o, rep) = build(&log, &d.path().join("json"), &[]);
    ok(&o);
    let w = rep["warnings"].to_string();
    assert!(
        w.contains("no `ring` field") && w.contains("cannot run"),
        "{w}"
    );
    assert_eq!(rep["cue_counts"]["lidar_noret"], 0);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no `ring` field"), "{err}");
    // Without --json the summary's warnings go to stderr too.
    let o = run(&["build", p(&log), "--out", p(&d.path().join("text"))]);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("lidar cues") && err.contains("no `ring` field"),
        "{err}"
    );
}

#[test]
fn unknown_inputs_name_the_supported_formats() {
    let d = tempfile::tempdir().unwrap();
    let odd = d.path().join("drive.xyz");
    std::fs::write(&odd, b"x").unwrap();
    let empty_dir = d.path().join("not_a_bag");
    std::fs::create_dir(&empty_dir).unwrap();
    for input in [&odd, &empty_dir] {
        for args in [
            vec!["info", p(input)],
            vec!["build", p(input), "--out", p(&d.path().join("out"))],
        ] {
            let o = run(&args);
            assert_eq!(o.status.code(), Some(1), "{args:?}");
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(
                err.contains("supported: .mcap, .db3, rosbag2 directory, .bag, .ply, .bin")
                    && err.contains(input.file_name().unwrap().to_str().unwrap()),
                "{args:?}: {err}"
            );
        }
    }
}
