//! Reading a 5 M-vertex binary PLY (the RELLIS-3D Ouster layout, 29 bytes per vertex:
//! x y z intensity float, t uint, reflectivity ushort, ring uchar, noise ushort, range uint)
//! and the same points as a KITTI `.bin`.
//!
//! `cargo bench --bench ply_read`

use std::hint::black_box;
use std::io::Write;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const N: usize = 5_000_000;

/// A deterministic scan-like cloud: 64 rings × columns, some missing returns.
fn ply_bytes(n: usize, big_endian: bool) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\nproperty float intensity\nproperty uint t\n\
         property ushort reflectivity\nproperty uchar ring\nproperty ushort noise\n\
         property uint range\nend_header\n"
    )
    .into_bytes();
    out.reserve(n * 29);
    macro_rules! put {
        ($v:expr) => {{
            let v = $v;
            out.extend_from_slice(&if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }};
    }
    for i in 0..n {
        let ring = (i % 64) as u8;
        let col = (i / 64) as f32;
        let r = if i % 7 == 3 {
            0.0
        } else {
            5.0 + (ring as f32) * 0.3
        };
        let az = col * 0.003;
        put!(r * az.cos());
        put!(r * az.sin());
        put!(-1.5 + ring as f32 * 0.02);
        put!((i % 1000) as f32);
        put!(i as u32);
        put!((i % 4000) as u16);
        put!(ring);
        put!((i % 50) as u16);
        put!((r * 1000.0) as u32);
    }
    out
}

fn kitti_bytes(n: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(n * 16);
    for i in 0..n {
        let v = [
            (i % 997) as f32 * 0.1,
            (i % 13) as f32,
            -1.0,
            (i % 255) as f32,
        ];
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("read_5M");
    g.sample_size(10);
    g.throughput(Throughput::Elements(N as u64));

    let le = ply_bytes(N, false);
    let be = ply_bytes(N, true);
    g.bench_function("ply_binary_le_from_bytes", |b| {
        b.iter(|| tarn::io::read_ply_from_bytes(black_box(&le), "bench.ply").unwrap())
    });
    g.bench_function("ply_binary_be_from_bytes", |b| {
        b.iter(|| tarn::io::read_ply_from_bytes(black_box(&be), "bench.ply").unwrap())
    });

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.ply");
    std::fs::File::create(&path)
        .unwrap()
        .write_all(&le)
        .unwrap();
    drop(be);
    g.bench_function("ply_binary_le_from_file", |b| {
        b.iter(|| tarn::io::read_ply(black_box(&path)).unwrap())
    });
    drop(le);

    let kitti = kitti_bytes(N);
    g.bench_function("kitti_from_bytes", |b| {
        b.iter(|| tarn::io::read_kitti_from_bytes(black_box(&kitti), "bench.bin").unwrap())
    });
    g.finish();

    // Ascii is not meant for big clouds; 500 k vertices give its per-vertex cost.
    let mut g = c.benchmark_group("read_500k_ascii");
    g.sample_size(10);
    g.throughput(Throughput::Elements(500_000));
    let cloud = tarn::io::read_ply_from_bytes(&ply_bytes(500_000, false), "x.ply").unwrap();
    let mut ascii = String::from(
        "ply\nformat ascii 1.0\nelement vertex 500000\nproperty float x\nproperty float y\n\
         property float z\nproperty float intensity\nend_header\n",
    );
    let int = cloud.intensity.as_deref().unwrap();
    for (p, i) in cloud.xyz.iter().zip(int) {
        ascii += &format!("{} {} {} {i}\n", p[0], p[1], p[2]);
    }
    g.bench_function("ply_ascii_from_bytes", |b| {
        b.iter(|| tarn::io::read_ply_from_bytes(black_box(ascii.as_bytes()), "a.ply").unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
