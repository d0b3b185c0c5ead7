//! Writes synthetic ROS 2 logs with tarn's writer and reads them back as frames: poses,
//! matching, compression and endianness variants, and bad input.

use std::path::Path;

use nalgebra::Point3;
use tarn::geom::{pose_xyz_rpy, CameraModel, Distortion, PointCloud, Pose};
use tarn::sensor::{Frame, Image, Pixels};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_log::mcap_log::{
    summarize, summarize_quick, LogCompression, LogReader, LogWriter, WriteOptions,
};
use tarn_log::ros::{cloud_to_pointcloud2, Endian, Header, ImageMsg, TfMessage, TransformStamped};

const NS: i64 = 1_000_000_000;
const T0: i64 = 1_700_000_000 * NS;

fn base_pose(t: f64) -> Pose {
    pose_xyz_rpy(2.0 * t, 0.0, 0.0, 0.0, 0.0, 0.1 * t)
}

fn lidar_ext() -> Pose {
    pose_xyz_rpy(0.5, 0.0, 1.8, 0.0, 0.0, 0.0)
}

fn cam_ext() -> Pose {
    // Optical frame: z forward, x right, y down.
    pose_xyz_rpy(
        0.3,
        0.1,
        1.5,
        -std::f64::consts::FRAC_PI_2,
        0.0,
        -std::f64::consts::FRAC_PI_2,
    )
}

fn hdr(ns: i64, f: &str) -> Header {
    Header::new(f, ns)
}

fn ts(parent: &str, child: &str, ns: i64, p: Pose) -> TransformStamped {
    TransformStamped::new(parent, child, ns, p)
}

fn scan(k: usize) -> PointCloud {
    let (rows, cols) = (4, 8);
    let xyz = (0..rows * cols)
        .map(|i| match (i + k) % 7 {
            0 => [f32::NAN; 3],
            3 => [0.0; 3],
            _ => [
                5.0 + i as f32 * 0.25,
                k as f32 * 0.5 - 1.0,
                -1.0 + (i % cols) as f32 * 0.01,
            ],
        })
        .collect();
    let mut c = PointCloud::organized(rows, cols, xyz).unwrap();
    c.intensity = Some((0..rows * cols).map(|i| (i * 3 + k) as f32).collect());
    c
}

fn image(k: usize) -> Image {
    Image {
        width: 6,
        height: 4,
        pixels: Pixels::Rgb8((0..24).map(|i| [i as u8, k as u8, 200]).collect()),
        frame_id: "camera_optical".into(),
        stamp: 0.0,
    }
}

/// Scan k is stamped 0.05 + 0.1 k s after T0; TF runs from 0 to `tf_end_s` at 100 Hz.
struct Spec {
    scans: usize,
    tf_end_s: f64,
    opts: WriteOptions,
    unknown: usize,
    bad_cloud_at: Option<usize>,
    bad_image_at: Option<usize>,
}

impl Default for Spec {
    fn default() -> Self {
        Spec {
            scans: 20,
            tf_end_s: 2.1,
            opts: WriteOptions::default(),
            unknown: 3,
            bad_cloud_at: None,
            bad_image_at: None,
        }
    }
}

fn scan_ns(k: usize) -> i64 {
    T0 + (0.05 * NS as f64) as i64 + k as i64 * NS / 10
}

fn write_log(path: &Path, spec: &Spec) {
    let mut w = LogWriter::create(path, &spec.opts).unwrap();
    let statics = TfMessage {
        transforms: vec![
            ts("base_link", "lidar", T0, lidar_ext()),
            ts("base_link", "camera_optical", T0, cam_ext()),
        ],
    };
    w.write_tf("/tf_static", &statics, T0 as u64).unwrap();
    let cam = CameraModel::new(
        6,
        4,
        [5.0, 5.0, 2.5, 1.5],
        Distortion::PlumbBob([0.01, 0.0, 0.0, 0.0, 0.0]),
        "camera_optical",
    )
    .unwrap();
    w.write_camera(
        "/camera/camera_info",
        &cam,
        hdr(T0, "camera_optical"),
        T0 as u64,
    )
    .unwrap();
    // Interleave by log time: TF every 10 ms, sensor messages logged 20 ms after their stamp.
    let mut events: Vec<(i64, u8, usize)> = Vec::new();
    let n_tf = (spec.tf_end_s * 100.0).round() as usize;
    for i in 0..=n_tf {
        events.push((T0 + i as i64 * NS / 100, 0, i));
    }
    for k in 0..spec.scans {
        events.push((scan_ns(k) + NS / 50, 1, k));
        events.push((scan_ns(k) + NS / 100 + NS / 50, 2, k));
        events.push((scan_ns(k) + NS / 50 + NS / 50, 3, k));
    }
    for u in 0..spec.unknown {
        events.push((T0 + u as i64 * NS / 10, 4, u));
    }
    events.sort();
    for (log_ns, kind, k) in events {
        match kind {
            0 => {
                let t = k as f64 / 100.0;
                let m = TfMessage {
                    transforms: vec![ts(
                        "map",
                        "base_link",
                        T0 + k as i64 * NS / 100,
                        base_pose(t),
                    )],
                };
                w.write_tf("/tf", &m, log_ns as u64).unwrap();
            }
            1 => {
                let mut m = cloud_to_pointcloud2(&scan(k), hdr(scan_ns(k), "lidar"));
                if spec.bad_cloud_at == Some(k) {
                    m.height += 1;
                }
                w.write_pointcloud2("/lidar/points", &m, log_ns as u64)
                    .unwrap();
            }
            2 => {
                let mut m = tarn_log::ros::convert::encode_image(
                    &image(k),
                    hdr(scan_ns(k) + NS / 100, "camera_optical"),
                );
                if spec.bad_image_at == Some(k) {
                    m.step += 1;
                }
                w.write_image_msg("/camera/image", &m, log_ns as u64)
                    .unwrap();
            }
            3 => {
                let c = PointCloud::organized(1, 2, vec![[1.0, 0.0, 4.0], [f32::NAN; 3]]).unwrap();
                w.write_cloud(
                    "/stereo/points",
                    &c,
                    hdr(scan_ns(k) + NS / 50, "camera_optical"),
                    log_ns as u64,
                )
                .unwrap();
            }
            _ => {
                w.write_raw(
                    "/diagnostics",
                    "diagnostic_msgs/msg/DiagnosticArray",
                    "std_msgs/Header header\n",
                    log_ns as u64,
                    &[0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0],
                )
                .unwrap();
            }
        }
    }
    w.finish().unwrap();
}

fn close(a: &Pose, b: &Pose, tol: f64) -> bool {
    (a.to_homogeneous() - b.to_homogeneous()).norm() < tol
}

fn check_frame(f: &Frame, k: usize) {
    let t = 0.05 + 0.1 * k as f64;
    assert!((f.stamp - (T0 as f64 * 1e-9 + t)).abs() < 1e-6);
    assert!(
        close(&f.base_to_map, &base_pose(t), 1e-9),
        "frame {k}: {} vs {}",
        f.base_to_map,
        base_pose(t)
    );
    let lidar = f.lidar.as_ref().unwrap();
    assert!(close(
        &lidar.frame_to_map,
        &(base_pose(t) * lidar_ext()),
        1e-9
    ));
    assert_eq!(lidar.sensor_origin, Point3::origin());
    let want = scan(k);
    assert_eq!((lidar.rows, lidar.cols), (4, 8));
    for i in 0..want.len() {
        let missing = !want.is_valid(i) || want.xyz[i] == [0.0; 3];
        assert_eq!(lidar.is_valid(i), !missing, "point {i}");
        if !missing {
            assert_eq!(lidar.xyz[i], want.xyz[i]);
        }
    }
    assert_eq!(lidar.intensity, want.intensity);
    let img = f.image.as_ref().expect("image matched");
    assert_eq!(img.image.pixels, image(k).pixels);
    assert!((img.image.stamp - f.stamp - 0.01).abs() < 1e-6);
    assert!(close(
        img.frame_to_map.as_ref().unwrap(),
        &(base_pose(t + 0.01) * cam_ext()),
        1e-9
    ));
    assert_eq!(img.camera.as_ref().unwrap().fx, 5.0);
    let st = f.stereo.as_ref().expect("stereo matched");
    assert!(close(
        &st.frame_to_map,
        &(base_pose(t + 0.02) * cam_ext()),
        1e-9
    ));
    assert!(f.swir.is_none() && f.mwir.is_none());
}

fn frames(path: &Path) -> (Vec<tarn::Result<Frame>>, tarn_log::frames::FrameStats) {
    let mut s = FrameStream::open(path, &LogConfig::default()).unwrap();
    let v: Vec<_> = s.by_ref().collect();
    (v, s.stats().clone())
}

#[test]
fn every_variant_gives_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (compression, chunked, endian)) in [
        (LogCompression::Zstd, true, Endian::Little),
        (LogCompression::Lz4, true, Endian::Little),
        (LogCompression::None, true, Endian::Big),
        (LogCompression::None, false, Endian::Little),
        (LogCompression::Zstd, true, Endian::Big),
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.path().join(format!("log{i}.mcap"));
        let opts = WriteOptions {
            compression,
            chunked,
            endian,
            chunk_size: Some(4096),
        };
        write_log(
            &p,
            &Spec {
                opts,
                ..Default::default()
            },
        );
        let (fr, stats) = frames(&p);
        assert_eq!(fr.len(), 20, "variant {i}");
        for (k, f) in fr.iter().enumerate() {
            check_frame(f.as_ref().unwrap(), k);
        }
        assert_eq!(stats.frames_built, 20);
        assert_eq!(stats.frames_skipped_no_tf, 0);
        assert_eq!(stats.unknown_type_total(), 3);
        assert_eq!(
            stats.unknown_type.keys().next().unwrap(),
            "/diagnostics (diagnostic_msgs/msg/DiagnosticArray)"
        );
        let sum = summarize(&p).unwrap();
        // The summary section the writer appends says the same as streaming the messages
        // (topics, schemas, counts, time span); a whole log's frame stream meets no damage.
        assert_eq!(summarize_quick(&p).unwrap(), sum, "variant {i}");
        let mut st = FrameStream::open(&p, &LogConfig::default()).unwrap();
        for _ in st.by_ref() {}
        assert!(sum.damaged.is_empty() && st.damaged().is_empty());
        let count = |t: &str| sum.topics.iter().find(|x| x.topic == t).unwrap().count;
        assert_eq!(
            (
                count("/lidar/points"),
                count("/camera/image"),
                count("/tf"),
                count("/diagnostics")
            ),
            (20, 20, 211, 3)
        );
    }
}

#[test]
fn missing_transform_skips_and_reports_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("short_tf.mcap");
    // TF ends at 1.5 s: scans at 1.55 … 1.95 s have no pose.
    write_log(
        &p,
        &Spec {
            tf_end_s: 1.5,
            ..Default::default()
        },
    );
    let (fr, stats) = frames(&p);
    assert_eq!(fr.len(), 15);
    assert!(fr.iter().all(|f| f.is_ok()));
    assert_eq!(stats.frames_built, 15);
    assert_eq!(stats.frames_skipped_no_tf, 5);
    assert_eq!(stats.skip_reasons.len(), 5);
    assert!(
        stats.skip_reasons[0].contains("outside the buffered time"),
        "{}",
        stats.skip_reasons[0]
    );
    assert!(
        stats.skip_reasons[0].contains("/lidar/points at 1700000001.55"),
        "{}",
        stats.skip_reasons[0]
    );
}

#[test]
fn bad_cloud_and_image_are_errors_and_the_stream_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.mcap");
    write_log(
        &p,
        &Spec {
            bad_cloud_at: Some(4),
            bad_image_at: Some(9),
            ..Default::default()
        },
    );
    let (fr, stats) = frames(&p);
    let errs: Vec<String> = fr
        .iter()
        .filter_map(|f| f.as_ref().err().map(|e| e.to_string()))
        .collect();
    assert_eq!(errs.len(), 2, "{errs:?}");
    assert!(
        errs[0].contains("/lidar/points") && errs[0].contains("declared sizes exceed the data"),
        "{}",
        errs[0]
    );
    assert!(
        errs[1].contains("/camera/image")
            && errs[1].contains("× height 4")
            && errs[1].contains("exceeds the data"),
        "{}",
        errs[1]
    );
    assert_eq!(stats.decode_errors, 2);
    assert_eq!(stats.frames_built, 19);
    // Frame 9 has no image (it was bad) but is still built.
    let ok: Vec<&Frame> = fr.iter().filter_map(|f| f.as_ref().ok()).collect();
    assert!(ok
        .iter()
        .any(|f| (f.stamp - (T0 as f64 * 1e-9 + 0.95)).abs() < 1e-6 && f.image.is_none()));
}

#[test]
fn truncated_file_reads_what_precedes_the_damage_then_says_where() {
    let dir = tempfile::tempdir().unwrap();
    for chunked in [false, true] {
        let p = dir.path().join("full.mcap");
        let opts = WriteOptions {
            chunked,
            chunk_size: Some(4096),
            ..Default::default()
        };
        write_log(
            &p,
            &Spec {
                opts,
                ..Default::default()
            },
        );
        let bytes = std::fs::read(&p).unwrap();
        let cut = bytes.len() * 6 / 10;
        let q = dir.path().join("cut.mcap");
        std::fs::write(&q, &bytes[..cut]).unwrap();

        // Every message before the cut, then the end: the cut is a damaged range that runs
        // to the end of the file, from the first byte of the record it cut.
        let mut r = LogReader::open(&q).unwrap();
        let mut n = 0;
        while let Some(m) = r.next_message() {
            m.unwrap();
            n += 1;
        }
        assert!(
            n > 100,
            "chunked {chunked}: only {n} messages before the damage"
        );
        let d = r.damaged().to_vec();
        assert_eq!(d.len(), 1, "chunked {chunked}: {d:?}");
        assert_eq!(d[0].end_byte, cut as u64);
        assert!(
            d[0].start_byte < cut as u64 && d[0].what.contains("truncated"),
            "{d:?}"
        );
        // The range starts exactly at the record the cut went through.
        let s = d[0].start_byte as usize;
        let len = u64::from_le_bytes(bytes[s + 1..s + 9].try_into().unwrap()) as usize;
        assert!(s + 9 + len > cut && (1..=0x0f).contains(&bytes[s]), "{d:?}");
        assert!(r.next_message().is_none());

        let sum = summarize(&q).unwrap();
        assert_eq!(sum.messages, n);
        assert_eq!(sum.damaged, d);
        // No footer, so no summary section: the quick summary streams and finds the same.
        assert_eq!(summarize_quick(&q).unwrap(), sum);
        // The frame stream says where the damage is too, and ends without an error.
        let mut st = FrameStream::open(&q, &LogConfig::default()).unwrap();
        for _ in st.by_ref() {}
        assert_eq!(st.damaged(), sum.damaged.as_slice());
        assert!(st.fatal_error().is_none());

        let (fr, _) = frames(&q);
        assert!(fr.len() >= 5, "chunked {chunked}: {} frames", fr.len());
        // The last scans before the cut may have lost their image or stereo cloud to it.
        for (k, f) in fr.iter().enumerate() {
            let f = f.as_ref().unwrap();
            if k + 2 < fr.len() {
                check_frame(f, k);
            } else {
                assert!(close(
                    &f.base_to_map,
                    &base_pose(0.05 + 0.1 * k as f64),
                    1e-9
                ));
            }
        }
    }
}

#[test]
fn writer_leaves_nothing_behind_on_drop() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("never.mcap");
    {
        let mut w = LogWriter::create(&p, &WriteOptions::default()).unwrap();
        w.write_tf("/tf", &TfMessage::default(), 0).unwrap();
    }
    assert!(!p.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn garbage_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("junk.mcap");
    std::fs::write(&p, b"this is not an mcap file at all").unwrap();
    let e = LogReader::open(&p)
        .unwrap()
        .next_message()
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(e.contains("junk.mcap") && e.contains("byte"), "{e}");
    let _ = ImageMsg::decode; // (type is part of the public API)
}

#[test]
fn stereo_can_drive_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("stereo.mcap");
    write_log(&p, &Spec::default());
    let cfg = LogConfig {
        frame_topic: "/stereo/points".into(),
        ..LogConfig::default()
    };
    let mut s = FrameStream::open(&p, &cfg).unwrap();
    let fr: Vec<Frame> = s.by_ref().map(|f| f.unwrap()).collect();
    assert_eq!(fr.len(), 20);
    for (k, f) in fr.iter().enumerate() {
        let t = 0.07 + 0.1 * k as f64;
        assert!(close(&f.base_to_map, &base_pose(t), 1e-9));
        let st = f.stereo.as_ref().unwrap();
        assert!(close(&st.frame_to_map, &(base_pose(t) * cam_ext()), 1e-9));
        // The lidar scan 20 ms earlier is matched, with its pose at its own stamp.
        let l = f.lidar.as_ref().unwrap();
        assert!(close(
            &l.frame_to_map,
            &(base_pose(t - 0.02) * lidar_ext()),
            1e-9
        ));
    }
    let bad = LogConfig {
        frame_topic: "/nope".into(),
        ..LogConfig::default()
    };
    assert!(FrameStream::open(&p, &bad).is_err());
}

#[test]
fn log_without_summary_or_indexes_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bare.mcap");
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&p).unwrap());
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .emit_summary_records(false)
            .emit_summary_offsets(false)
            .emit_statistics(false)
            .emit_message_indexes(false)
            .emit_chunk_indexes(false)
            .create(f)
            .unwrap();
        let text = |s| tarn_log::ros::schema_text(s).unwrap();
        let s_tf = w
            .add_schema(
                "tf2_msgs/msg/TFMessage",
                "ros2msg",
                text("tf2_msgs/msg/TFMessage").as_bytes(),
            )
            .unwrap();
        let s_pc = w
            .add_schema(
                "sensor_msgs/msg/PointCloud2",
                "ros2msg",
                text("sensor_msgs/msg/PointCloud2").as_bytes(),
            )
            .unwrap();
        let c_st = w
            .add_channel(s_tf, "/tf_static", "cdr", &Default::default())
            .unwrap();
        let c_tf = w
            .add_channel(s_tf, "/tf", "cdr", &Default::default())
            .unwrap();
        let c_pc = w
            .add_channel(s_pc, "/lidar/points", "cdr", &Default::default())
            .unwrap();
        let mut put = |ch, ns: i64, data: Vec<u8>| {
            let h = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: ns as u64,
                publish_time: ns as u64,
            };
            w.write_to_known_channel(&h, &data).unwrap();
        };
        put(
            c_st,
            T0,
            TfMessage {
                transforms: vec![ts("base_link", "lidar", T0, lidar_ext())],
            }
            .encode(Endian::Big),
        );
        for i in 0..3 {
            let ns = T0 + i * NS / 10;
            put(
                c_tf,
                ns,
                TfMessage {
                    transforms: vec![ts("map", "base_link", ns, base_pose(i as f64 * 0.1))],
                }
                .encode(Endian::Little),
            );
        }
        put(
            c_pc,
            T0 + NS / 10,
            cloud_to_pointcloud2(&scan(0), hdr(T0 + NS / 20, "lidar")).encode(Endian::Little),
        );
        w.finish().unwrap();
    }
    let (fr, stats) = frames(&p);
    assert_eq!(fr.len(), 1);
    assert!(close(
        &fr[0].as_ref().unwrap().base_to_map,
        &base_pose(0.05),
        1e-9
    ));
    assert_eq!(stats.messages, 5);
}
