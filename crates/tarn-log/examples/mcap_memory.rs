//! Peak memory of streaming frames from a log, to show it does not grow with the log's
//! length. Run each step in its own process (peak RSS only grows within a process):
//!
//! ```text
//! cargo run --release --example mcap_memory -- write 100 /tmp/short.mcap
//! cargo run --release --example mcap_memory -- read /tmp/short.mcap
//! cargo run --release --example mcap_memory -- write 1000 /tmp/long.mcap
//! cargo run --release --example mcap_memory -- read /tmp/long.mcap
//! ```

use tarn::geom::{pose_xyz_rpy, PointCloud};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_log::mcap_log::{LogWriter, WriteOptions};
use tarn_log::ros::{Header, TfMessage, Time, TransformStamped};

fn vm_hwm_kb() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn write(scans: usize, path: &str) -> tarn::Result<()> {
    let mut w = LogWriter::create(path, &WriteOptions::default())?;
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
    )?;
    for k in 0..=scans * 10 {
        let ns = t0 + k as i64 * 10_000_000;
        let t = k as f64 * 0.01;
        w.write_tf(
            "/tf",
            &TfMessage {
                transforms: vec![ts(
                    "map",
                    "base_link",
                    ns,
                    pose_xyz_rpy(2.0 * t, 0.0, 0.0, 0.0, 0.0, 0.0),
                )],
            },
            ns as u64,
        )?;
        if k % 10 == 5 && k / 10 < scans {
            let xyz = (0..32 * 1024)
                .map(|i| [(i % 1024) as f32 * 0.01 + k as f32, (i / 1024) as f32, -1.8])
                .collect();
            let c = PointCloud::organized(32, 1024, xyz)?;
            w.write_cloud(
                "/lidar/points",
                &c,
                Header {
                    stamp: Time::from_nanos(ns),
                    frame_id: "lidar".into(),
                },
                ns as u64 + 5_000_000,
            )?;
        }
    }
    w.finish()
}

fn read(path: &str) -> tarn::Result<()> {
    let before = vm_hwm_kb();
    let mut s = FrameStream::open(path, &LogConfig::default())?;
    let (mut frames, mut max_buffered) = (0u64, 0usize);
    while let Some(f) = s.next() {
        f?;
        frames += 1;
        max_buffered = max_buffered.max(s.buffered());
    }
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    println!(
        "{path}: {:.1} MB, {frames} frames, at most {max_buffered} messages buffered, VmHWM {} kB before reading, {} kB after",
        size as f64 / 1e6,
        before.unwrap_or(0),
        vm_hwm_kb().unwrap_or(0)
    );
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let r = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["write", n, path] => match n.parse() {
            Ok(n) => write(n, path),
            Err(_) => Err(tarn::Error::invalid(
                "scan count",
                format!("{n:?} is not a number"),
            )),
        },
        ["read", path] => read(path),
        _ => Err(tarn::Error::invalid(
            "arguments",
            "write N PATH | read PATH",
        )),
    };
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
