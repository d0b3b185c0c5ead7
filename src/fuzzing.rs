//! Entry points shared by the `cargo fuzz` targets in `fuzz/` and by the fuzz smoke test
//! (`tests/fuzz_smoke.rs`), which runs every committed corpus file and crash regression
//! through the same functions on a stable toolchain.
//!
//! Each function takes arbitrary bytes, feeds them to one reader of outside data and then
//! uses what came back the way the pipeline would. It returns whether the input was
//! accepted; the contract is that it never panics, never loops without end and never
//! allocates more than the input can justify. Not part of the public API.

use std::path::Path;

use crate::io::frames::{FrameStream, LogConfig};
use crate::io::mcap_log::LogReader;
use crate::io::ros::{
    camera_from_info, decode_image, pointcloud2_to_cloud, CameraInfoMsg, ImageMsg, PointCloud2Msg,
    TfMessage,
};
use crate::io::tf::TfBuffer;

/// A point cloud in PLY, through [`crate::io::ply::read_from_bytes`], and the same bytes as
/// a contract `map.ply` through [`crate::io::mapfile::parse_map_ply`].
pub fn ply(data: &[u8]) -> bool {
    let name = Path::new("fuzz.ply");
    let cloud = crate::io::ply::read_from_bytes(data, name);
    if let Ok(c) = &cloud {
        check_cloud(c);
    }
    let map = crate::io::mapfile::parse_map_ply(name, data);
    if let Ok(m) = &map {
        assert!(m.resolution > 0.0 && m.resolution.is_finite());
        let _ = crate::io::export::elevation_range(&m.cells);
    }
    cloud.is_ok() || map.is_ok()
}

/// A KITTI `.bin` scan, unorganized and organized with 1 + `data[0] % 128` rings.
pub fn kitti(data: &[u8]) -> bool {
    let name = Path::new("fuzz.bin");
    let a = crate::io::kitti::read_from_bytes(data, name);
    if let Ok(c) = &a {
        check_cloud(c);
    }
    let rings = 1 + data.first().copied().unwrap_or(0) as usize % 128;
    let b = crate::io::kitti::read_organized_from_bytes(data, name, rings);
    if let Ok(c) = &b {
        check_cloud(c);
    }
    a.is_ok()
}

/// Messages are not allowed to pile up without bound while fuzzing.
const MAX_ITEMS: usize = 100_000;

/// A whole MCAP log, through [`LogReader`] (every message) and then through
/// [`FrameStream`] (every frame) with the default topics.
pub fn mcap(data: &[u8]) -> bool {
    let mut ok = true;
    let mut reader = LogReader::from_bytes(data.to_vec(), "fuzz.mcap");
    for m in reader.by_ref().take(MAX_ITEMS) {
        if m.is_err() {
            ok = false;
        }
    }
    for d in reader.damaged() {
        // Ranges are inside the file and name what was wrong.
        assert!(
            d.start_byte <= d.end_byte && d.end_byte <= data.len() as u64,
            "{d:?}"
        );
        ok = false;
    }
    let reader = LogReader::from_bytes(data.to_vec(), "fuzz.mcap");
    let stream = match FrameStream::from_reader(reader, &LogConfig::default()) {
        Ok(s) => s,
        Err(_) => return false,
    };
    for f in stream.take(MAX_ITEMS) {
        match f {
            Ok(f) => {
                assert!(f.stamp.is_finite(), "frame stamp {}", f.stamp);
                for c in [&f.lidar, &f.stereo].into_iter().flatten() {
                    check_cloud(c);
                }
            }
            Err(_) => ok = false,
        }
    }
    ok
}

/// One CDR message; the first byte chooses the type (TFMessage, PointCloud2, Image,
/// CameraInfo), the rest is the serialized message. Decoded messages are converted the
/// way [`FrameStream`] converts them.
pub fn cdr(data: &[u8]) -> bool {
    let Some((&kind, buf)) = data.split_first() else {
        return false;
    };
    match kind % 4 {
        0 => match TfMessage::decode(buf) {
            Ok(m) => {
                let mut tf = TfBuffer::new();
                for t in &m.transforms {
                    tf.insert(t, kind & 4 != 0);
                }
                for t in &m.transforms {
                    let _ = tf.lookup(
                        &t.header.frame_id,
                        &t.child_frame_id,
                        t.header.stamp.to_nanos(),
                    );
                }
                true
            }
            Err(_) => false,
        },
        1 => match PointCloud2Msg::decode(buf) {
            Ok(m) => match pointcloud2_to_cloud(&m) {
                Ok(c) => {
                    check_cloud(&c);
                    true
                }
                Err(_) => false,
            },
            Err(_) => false,
        },
        2 => match ImageMsg::decode(buf) {
            Ok(m) => decode_image(&m).is_ok(),
            Err(_) => false,
        },
        _ => match CameraInfoMsg::decode(buf) {
            Ok(m) => match camera_from_info(&m) {
                Ok(cam) => {
                    let _ = cam.pixel_ray(0.5 * cam.width as f64, 0.5 * cam.height as f64);
                    true
                }
                Err(_) => false,
            },
            Err(_) => false,
        },
    }
}

/// A scene TOML ([`crate::sim::Scene::from_toml_str`]); an accepted scene is built
/// into a world and its trajectory sampled, as `tarn simulate` does before rendering.
pub fn scene_toml(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let Ok(scene) = crate::sim::Scene::from_toml_str(text) else {
        return false;
    };
    match crate::sim::World::build(&scene) {
        Ok(w) => {
            let _ = crate::sim::trajectory(&w);
            true
        }
        Err(_) => false,
    }
}

/// A colour model JSON ([`crate::classify::gmm::ColorModel::from_json`]); an accepted model
/// scores and labels every 16th colour of the RGB cube.
pub fn color_model_json(data: &[u8]) -> bool {
    use crate::classify::gmm::PixelClassifier;
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let Ok(model) = crate::classify::gmm::ColorModel::from_json(text, "fuzz.json") else {
        return false;
    };
    let mut scores = Vec::new();
    for r in (0..=255u8).step_by(16) {
        for g in (0..=255u8).step_by(16) {
            for b in (0..=255u8).step_by(16) {
                model.log_scores([r, g, b], &mut scores);
                let _ = model.classify_pixel([r, g, b]);
            }
        }
    }
    true
}

/// What every reader promises about a cloud it returns.
fn check_cloud(c: &crate::geom::PointCloud) {
    if let Err(e) = c.validate() {
        panic!("a reader returned an inconsistent cloud: {e}");
    }
}
