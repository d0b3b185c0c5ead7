//! Reading speed of a ROS 2 MCAP log of lidar clouds: MB/s of file and messages/s, for
//! the raw message stream, for decoding every cloud, and for the full frame stream
//! (TF interpolation and matching included).
//!
//! `cargo bench --bench mcap_read`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use tarn::geom::{pose_xyz_rpy, PointCloud};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_log::mcap_log::{LogCompression, LogReader, LogWriter, WriteOptions};
use tarn_log::ros::{
    pointcloud2_to_cloud, Header, PointCloud2Msg, TfMessage, Time, TransformStamped,
};

const ROWS: usize = 32;
const COLS: usize = 1024;
const SCANS: usize = 60;

fn write_log(path: &std::path::Path, compression: LogCompression) {
    let mut w = LogWriter::create(
        path,
        &WriteOptions {
            compression,
            ..Default::default()
        },
    )
    .unwrap();
    let t0: i64 = 1_700_000_000_000_000_000;
    let ts = TransformStamped::new;
    w.write_tf(
        "/tf_static",
        &TfMessage {
            transforms: vec![ts(
                "base_link",
                "lidar",
                t0,
                pose_xyz_rpy(0.0, 0.0, 1.8, 0.0, 0.0, 0.0),
            )],
        },
        t0 as u64,
    )
    .unwrap();
    let mut seed = 12345u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    for k in 0..=SCANS * 10 {
        let ns = t0 + k as i64 * 10_000_000;
        let t = k as f64 * 0.01;
        w.write_tf(
            "/tf",
            &TfMessage {
                transforms: vec![ts(
                    "map",
                    "base_link",
                    ns,
                    pose_xyz_rpy(2.0 * t, 0.0, 0.0, 0.0, 0.0, 0.05 * t),
                )],
            },
            ns as u64,
        )
        .unwrap();
        if k % 10 == 5 && k / 10 < SCANS {
            // A ring-shaped scan with range noise, as a spinning lidar sees flat ground.
            let xyz = (0..ROWS * COLS)
                .map(|i| {
                    let (r, c) = (i / COLS, i % COLS);
                    let az = c as f32 / COLS as f32 * std::f32::consts::TAU;
                    let range = 3.0 + r as f32 * 1.5 + rnd() * 0.05;
                    if rnd() < 0.05 {
                        [f32::NAN; 3]
                    } else {
                        [range * az.cos(), range * az.sin(), -1.8 + rnd() * 0.02]
                    }
                })
                .collect();
            let mut c = PointCloud::organized(ROWS, COLS, xyz).unwrap();
            c.intensity = Some((0..ROWS * COLS).map(|_| (rnd() * 255.0).floor()).collect());
            w.write_cloud(
                "/lidar/points",
                &c,
                Header {
                    stamp: Time::from_nanos(ns),
                    frame_id: "lidar".into(),
                },
                ns as u64 + 5_000_000,
            )
            .unwrap();
        }
    }
    w.finish().unwrap();
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    for (name, comp) in [
        ("zstd", LogCompression::Zstd),
        ("none", LogCompression::None),
    ] {
        let path = dir.path().join(format!("lidar_{name}.mcap"));
        write_log(&path, comp);
        let bytes = std::fs::metadata(&path).unwrap().len();
        let messages = LogReader::open(&path).unwrap().count() as u64;
        eprintln!(
            "{name}: {} MB, {messages} messages, {SCANS} clouds of {ROWS}×{COLS}",
            bytes as f64 / 1e6
        );

        let mut g = c.benchmark_group(format!("mcap_read_{name}"));
        g.sample_size(10);
        for (unit, tp) in [
            ("MB", Throughput::Bytes(bytes)),
            ("msgs", Throughput::Elements(messages)),
        ] {
            g.throughput(tp);
            g.bench_function(format!("messages_{unit}"), |b| {
                b.iter(|| {
                    LogReader::open(&path)
                        .unwrap()
                        .map(|m| m.unwrap().data.len())
                        .sum::<usize>()
                })
            });
            g.bench_function(format!("decode_clouds_{unit}"), |b| {
                b.iter(|| {
                    let mut n = 0;
                    for m in LogReader::open(&path).unwrap() {
                        let m = m.unwrap();
                        if m.channel.topic == "/lidar/points" {
                            n += pointcloud2_to_cloud(&PointCloud2Msg::decode(&m.data).unwrap())
                                .unwrap()
                                .valid_count();
                        }
                    }
                    n
                })
            });
            g.bench_function(format!("frames_{unit}"), |b| {
                b.iter(|| {
                    FrameStream::open(&path, &LogConfig::default())
                        .unwrap()
                        .map(|f| f.unwrap().lidar.unwrap().len())
                        .sum::<usize>()
                })
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
