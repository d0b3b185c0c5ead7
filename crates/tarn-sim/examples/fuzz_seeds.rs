//! Writes the seed inputs of the fuzz targets into `fuzz/corpus/<target>/seed-*`: small,
//! valid files of every format tarn reads, made with tarn's own writers.
//!
//! `cargo run --example fuzz_seeds` (then `cargo fuzz run <target>` grows the corpus, and
//! `cargo fuzz cmin <target>` minimises it).

use std::f64::consts::FRAC_PI_2;
use std::path::Path;

use tarn::classify::{ClassModel, ColorModel, ColorModelData, Component, Label};
use tarn::geom::{pose_xyz_rpy, CameraModel, Distortion, PointCloud};
use tarn::sensor::{Image, Pixels};
use tarn_log::mcap_log::{LogCompression, LogWriter, WriteOptions};
use tarn_log::ros::{
    camera_to_info, cloud_to_pointcloud2, encode_image, Endian, Header, TfMessage, TransformStamped,
};

const NS: i64 = 1_000_000_000;

fn put(target: &str, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .join("fuzz/corpus")
        .join(target);
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join(format!("seed-{name}")), bytes)?;
    Ok(())
}

fn cloud() -> PointCloud {
    let xyz = (0..8)
        .map(|i| match i {
            2 => [f32::NAN; 3],
            5 => [0.0; 3],
            _ => [4.0 + i as f32, 0.5 * i as f32, -1.5],
        })
        .collect();
    let mut c = PointCloud::organized(2, 4, xyz).unwrap();
    c.intensity = Some((0..8).map(|i| i as f32 * 10.0).collect());
    c
}

fn camera() -> CameraModel {
    CameraModel::new(
        4,
        2,
        [3.0, 3.0, 2.0, 1.0],
        Distortion::PlumbBob([0.01, 0.0, 0.0, 0.0, 0.0]),
        "camera_optical",
    )
    .unwrap()
}

fn image() -> Image {
    Image {
        width: 4,
        height: 2,
        pixels: Pixels::Rgb8((0..8).map(|i| [i as u8 * 30, 90, 200]).collect()),
        frame_id: "camera_optical".into(),
        stamp: 0.0,
    }
}

fn tf(ns: i64, x: f64) -> TfMessage {
    TfMessage {
        transforms: vec![TransformStamped::new(
            "map",
            "base_link",
            ns,
            pose_xyz_rpy(x, 0.0, 0.0, 0.0, 0.0, 0.1),
        )],
    }
}

fn log(path: &Path, opts: &WriteOptions) -> anyhow::Result<()> {
    let mut w = LogWriter::create(path, opts)?;
    let statics = TfMessage {
        transforms: vec![
            TransformStamped::new(
                "base_link",
                "lidar",
                0,
                pose_xyz_rpy(0.5, 0.0, 1.8, 0.0, 0.0, 0.0),
            ),
            TransformStamped::new(
                "base_link",
                "camera_optical",
                0,
                pose_xyz_rpy(0.3, 0.0, 1.5, -FRAC_PI_2, 0.0, -FRAC_PI_2),
            ),
        ],
    };
    w.write_tf("/tf_static", &statics, 0)?;
    w.write_camera(
        "/camera/camera_info",
        &camera(),
        Header::new("camera_optical", 0),
        0,
    )?;
    for k in 0..3i64 {
        let t = k * NS / 10;
        w.write_tf("/tf", &tf(t, 0.2 * k as f64), t as u64)?;
        w.write_cloud(
            "/lidar/points",
            &cloud(),
            Header::new("lidar", t),
            t as u64 + 1,
        )?;
        w.write_cloud(
            "/stereo/points",
            &cloud(),
            Header::new("camera_optical", t),
            t as u64 + 2,
        )?;
        w.write_image(
            "/camera/image",
            &image(),
            Header::new("camera_optical", t),
            t as u64 + 3,
        )?;
    }
    w.write_tf("/tf", &tf(NS, 1.0), NS as u64)?;
    w.finish()?;
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    ply_seeds(tmp.path())?;
    kitti_seeds()?;
    mcap_seeds(tmp.path())?;
    cdr_seeds()?;
    scene_seeds()?;
    colour_model_seeds(tmp.path())?;
    Ok(())
}

/// PLY point clouds, and a map.ply.
fn ply_seeds(tmp: &Path) -> anyhow::Result<()> {
    // PLY point clouds.
    put(
        "ply",
        "ascii.ply",
        b"ply\nformat ascii 1.0\ncomment width 2 height 2\nelement vertex 4\nproperty float x\n\
property float y\nproperty float z\nproperty uchar intensity\nproperty float range\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n\
1 2 3 4 5\n0 0 0 1 0\nnan 1 1 2 3\n4 5 6 7 8\n3 0 1 2\n",
    )?;
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\n\
property double y\nproperty double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
end_header\n"
        .to_vec();
    for i in 0..3 {
        for v in [5.0e6 + i as f64, 4.0e6, 100.0 + i as f64] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        bin.extend_from_slice(&[10, 20, 30]);
    }
    put("ply", "binary-double.ply", &bin)?;
    let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n\
property float y\nproperty float z\nproperty ushort reflectivity\nend_header\n"
        .to_vec();
    for i in 0..2 {
        for v in [1.0f32 + i as f32, 2.0, 3.0] {
            be.extend_from_slice(&v.to_be_bytes());
        }
        be.extend_from_slice(&(500u16 * i).to_be_bytes());
    }
    put("ply", "binary-be.ply", &be)?;
    let map = tarn_sim::sim::truth_map(&tarn_sim::sim::World::build(&tarn_sim::sim::Scene::load(
        &Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join("maps/vertical_scanner.toml"),
    )?)?);
    let small = tarn::hazard::HazardMap::new(
        map.resolution,
        map.cells
            .iter()
            .step_by(map.cells.len().max(8) / 8)
            .take(8)
            .cloned()
            .collect(),
    );
    tarn::io::write_map_ply(&tmp.join("map.ply"), &small)?;
    put("ply", "map.ply", &std::fs::read(tmp.join("map.ply"))?)?;
    Ok(())
}

/// KITTI scans.
fn kitti_seeds() -> anyhow::Result<()> {
    // KITTI scans.
    let mut k = Vec::new();
    for p in [
        [1.0f32, 2.0, 3.0, 0.5],
        [0.0, 0.0, 0.0, 0.1],
        [f32::NAN, 1.0, 1.0, 0.0],
        [4.0, 5.0, 6.0, 1.0],
    ] {
        for v in p {
            k.extend_from_slice(&v.to_le_bytes());
        }
    }
    put("kitti", "scan.bin", &k)?;
    Ok(())
}

/// MCAP logs: uncompressed unchunked, zstd and lz4 chunked, big-endian CDR.
fn mcap_seeds(tmp: &Path) -> anyhow::Result<()> {
    // MCAP logs: uncompressed unchunked, zstd and lz4 chunked, big-endian CDR.
    for (name, opts) in [
        (
            "plain.mcap",
            WriteOptions {
                compression: LogCompression::None,
                chunked: false,
                chunk_size: None,
                endian: Endian::Little,
            },
        ),
        (
            "zstd.mcap",
            WriteOptions {
                compression: LogCompression::Zstd,
                chunked: true,
                chunk_size: Some(2048),
                endian: Endian::Little,
            },
        ),
        (
            "lz4-be.mcap",
            WriteOptions {
                compression: LogCompression::Lz4,
                chunked: true,
                chunk_size: None,
                endian: Endian::Big,
            },
        ),
    ] {
        let p = tmp.join(name);
        log(&p, &opts)?;
        put("mcap", name, &std::fs::read(&p)?)?;
    }
    Ok(())
}

/// CDR messages, a type byte before each.
fn cdr_seeds() -> anyhow::Result<()> {
    // CDR messages: one type byte (0 TF, 1 PointCloud2, 2 Image, 3 CameraInfo), then the message.
    for (endian, e) in [(Endian::Little, "le"), (Endian::Big, "be")] {
        let msgs: [(u8, Vec<u8>); 4] = [
            (0, tf(5, 1.0).encode(endian)),
            (
                1,
                cloud_to_pointcloud2(&cloud(), Header::new("lidar", 5)).encode(endian),
            ),
            (
                2,
                encode_image(&image(), Header::new("camera_optical", 5)).encode(endian),
            ),
            (
                3,
                camera_to_info(&camera(), Header::new("camera_optical", 5)).encode(endian),
            ),
        ];
        for (kind, bytes) in msgs {
            let mut v = vec![kind];
            v.extend_from_slice(&bytes);
            put("cdr", &format!("{kind}-{e}.cdr"), &v)?;
        }
    }
    Ok(())
}

/// Scenes: the repository's maps.
fn scene_seeds() -> anyhow::Result<()> {
    // Scenes: the repository's maps.
    for entry in
        std::fs::read_dir(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("maps"))?
    {
        let p = entry?.path();
        if p.extension().is_some_and(|e| e == "toml") {
            put(
                "scene_toml",
                &p.file_name().unwrap().to_string_lossy(),
                &std::fs::read(&p)?,
            )?;
        }
    }
    Ok(())
}

/// A colour model JSON.
fn colour_model_seeds(tmp: &Path) -> anyhow::Result<()> {
    // Colour model JSON.
    let comp = |m: [f64; 3], v: f64| Component {
        weight: 0.5,
        mean: m,
        cov: [[v, 1.0, 0.0], [1.0, v, 0.0], [0.0, 0.0, v]],
    };
    let data = ColorModelData {
        format: "tarn-color-gmm-1".into(),
        classes: vec![
            ClassModel {
                label: Label::Water,
                name: "water".into(),
                prior: 0.3,
                components: vec![
                    comp([200.0, 200.0, 210.0], 40.0),
                    comp([90.0, 100.0, 120.0], 80.0),
                ],
            },
            ClassModel {
                label: Label::Other,
                name: "ground".into(),
                prior: 0.7,
                components: vec![comp([120.0, 90.0, 60.0], 300.0)],
            },
        ],
    };
    let model = ColorModel::from_data(data)?;
    model.save(&tmp.join("model.json"))?;
    put(
        "color_model_json",
        "model.json",
        &std::fs::read(tmp.join("model.json"))?,
    )?;
    Ok(())
}
