//! Entry points shared by the `cargo fuzz` targets in `fuzz/` and by the fuzz smoke test
//! (`tests/fuzz_smoke.rs`), which runs every committed corpus file and crash regression
//! through the same functions on a stable toolchain.
//!
//! Each function takes arbitrary bytes, feeds them to one reader of outside data and then
//! uses what came back the way the pipeline would. It returns whether the input was
//! accepted; the contract is that it never panics, never loops without end and never
//! allocates more than the input can justify. Not part of the public API.

use std::path::Path;

use tarn_log::frames::{FrameStream, LogConfig};
use tarn_log::mcap_log::LogReader;
use tarn_log::ros::{
    camera_from_info, decode_image, pointcloud2_to_cloud, CameraInfoMsg, ImageMsg, NavSatFixMsg,
    PointCloud2Msg, TfMessage, Wire,
};
use tarn_log::tf::TfBuffer;

/// A point cloud in PLY, through [`crate::io::read_ply_from_bytes`], and the same bytes as
/// a contract `map.ply` through [`crate::io::parse_map_ply`].
pub fn ply(data: &[u8]) -> bool {
    let name = Path::new("fuzz.ply");
    let cloud = crate::io::read_ply_from_bytes(data, name);
    if let Ok(c) = &cloud {
        check_cloud(c);
    }
    let map = crate::io::parse_map_ply(name, data);
    if let Ok(m) = &map {
        assert!(m.resolution > 0.0 && m.resolution.is_finite());
        let _ = crate::io::elevation_range(&m.cells);
    }
    cloud.is_ok() || map.is_ok()
}

/// A KITTI `.bin` scan, unorganized and organized with 1 + `data[0] % 128` rings.
pub fn kitti(data: &[u8]) -> bool {
    let name = Path::new("fuzz.bin");
    let a = crate::io::read_kitti_from_bytes(data, name);
    if let Ok(c) = &a {
        check_cloud(c);
    }
    let rings = 1 + data.first().copied().unwrap_or(0) as usize % 128;
    let b = crate::io::read_kitti_organized_from_bytes(data, name, rings);
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

/// A ROS 1 bag ([`tarn_log::bags::Ros1Reader`]): every message read, then the frame
/// stream over it, whose decoders read the ROS 1 wire.
pub fn ros1_bag(data: &[u8]) -> bool {
    use tarn_log::bags::Ros1Reader;
    use tarn_log::log::MessageSource;
    let mut ok = true;
    let Ok(mut reader) = Ros1Reader::from_bytes(data.to_vec(), "fuzz.bag") else {
        return false;
    };
    let mut n = 0;
    while let Some(m) = reader.next_message() {
        n += 1;
        if m.is_err() || n > MAX_ITEMS {
            ok = false;
            break;
        }
    }
    for d in reader.damaged() {
        assert!(
            d.start_byte <= d.end_byte && d.end_byte <= data.len() as u64,
            "{d:?}"
        );
        ok = false;
    }
    let Ok(reader) = Ros1Reader::from_bytes(data.to_vec(), "fuzz.bag") else {
        return false;
    };
    let stream = match FrameStream::from_source(Box::new(reader), &LogConfig::default()) {
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

/// One CDR message; the first byte chooses the type (modulo 8: 0 and 4 TFMessage, 1 and 5
/// PointCloud2, 2 and 6 Image, 3 CameraInfo, 7 NavSatFix), the rest is the serialized
/// message. Decoded messages are converted the
/// way [`FrameStream`] converts them.
pub fn cdr(data: &[u8]) -> bool {
    let Some((&kind, buf)) = data.split_first() else {
        return false;
    };
    match kind % 8 {
        0 | 4 => match TfMessage::decode(buf) {
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
        1 | 5 => match PointCloud2Msg::decode(buf) {
            Ok(m) => match pointcloud2_to_cloud(&m) {
                Ok(c) => {
                    check_cloud(&c);
                    true
                }
                Err(_) => false,
            },
            Err(_) => false,
        },
        2 | 6 => match ImageMsg::decode(buf) {
            Ok(m) => decode_image(&m).is_ok(),
            Err(_) => false,
        },
        7 => match NavSatFixMsg::decode_wire(buf, Wire::Cdr) {
            // A fix that is not a place on the globe is an error the build reports.
            Ok(m) => m.position().is_ok(),
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

/// A colour model JSON ([`crate::classify::ColorModel::from_json`]); an accepted model
/// scores and labels every 16th colour of the RGB cube.
pub fn color_model_json(data: &[u8]) -> bool {
    use crate::classify::PixelClassifier;
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let Ok(model) = crate::classify::ColorModel::from_json(text, "fuzz.json") else {
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

/// Reads numbers from fuzz bytes; past the end every read gives 0.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Bytes<'a> {
    fn new(data: &'a [u8]) -> Self {
        Bytes { data, at: 0 }
    }
    fn left(&self) -> usize {
        self.data.len().saturating_sub(self.at)
    }
    fn take(&mut self, n: usize) -> &'a [u8] {
        let a = self.at.min(self.data.len());
        let b = (a + n).min(self.data.len());
        self.at = a + n;
        &self.data[a..b]
    }
    fn u8(&mut self) -> u8 {
        self.take(1).first().copied().unwrap_or(0)
    }
    fn f32(&mut self) -> f32 {
        let mut b = [0u8; 4];
        let s = self.take(4);
        b[..s.len()].copy_from_slice(s);
        f32::from_le_bytes(b)
    }
}

/// Everything tarn writes from a map, in memory (the picture, the terrain mesh's
/// triangles, the far-origin offset, the report values); with `files`, also the files of
/// `tarn build` into a fresh temporary directory.
fn exports_of(map: &crate::hazard::HazardMap, files: bool) {
    let img = tarn::io::render_map_png(map, &[]);
    assert!(
        img.width() <= tarn::io::MAP_PNG_MAX_SIDE.max(640)
            && img.height() <= tarn::io::MAP_PNG_MAX_SIDE + 200,
        "map.png of {} × {} pixels",
        img.width(),
        img.height()
    );
    let tris = crate::io::terrain_triangles(map);
    assert!(tris
        .iter()
        .flatten()
        .all(|&i| (i as usize) < map.cells.len()));
    let _ = crate::io::needs_double(map.cells.iter().map(|c| [c.x, c.y, c.z]));
    let _ = crate::io::elevation_range(&map.cells);
    let _ = map.water_report();
    if files {
        let dir = tempfile::tempdir().expect("a temporary directory");
        crate::io::write_map_files(dir.path(), map).expect("the map files are written");
    }
}

/// A cloud build: the first byte chooses the reader (PLY, KITTI, or the bytes as raw
/// little-endian `f32` x y z triples, which reach any coordinate), the window size and the
/// resolution; the cloud is built ([`tarn_log::build::build_cloud`]) and exported in memory.
pub fn cloud_build(data: &[u8]) -> bool {
    let Some((&head, rest)) = data.split_first() else {
        return false;
    };
    let cloud = match head % 3 {
        0 => crate::io::read_ply_from_bytes(rest, Path::new("fuzz.ply")),
        1 => crate::io::read_kitti_from_bytes(rest, Path::new("fuzz.bin")),
        _ => Ok(crate::geom::PointCloud::unorganized(
            rest.chunks_exact(12)
                .map(|c| {
                    let f = |i: usize| f32::from_le_bytes(c[i..i + 4].try_into().unwrap());
                    [f(0), f(4), f(8)]
                })
                .collect(),
        )),
    };
    let Ok(cloud) = cloud else {
        return false;
    };
    let cfg = tarn_log::build::BuildConfig {
        grid: crate::grid::GridConfig {
            resolution: [0.05, 0.1, 0.25, 1.0][(head >> 2) as usize % 4],
            ..Default::default()
        },
        max_window_cells: 16 << ((head >> 4) % 8),
        ..Default::default()
    };
    let b = match tarn_log::build::build_cloud(&cloud, &cfg, &mut |_, _| {}) {
        Ok(b) => b,
        Err(_) => return false,
    };
    let st = b.ingest;
    assert_eq!(st.points, cloud.len() as u64, "{st:?}");
    assert!(
        st.fused + st.below + st.nonfinite + st.outside == st.points,
        "every point is counted once: {st:?}"
    );
    assert!(b.tiles.observed_count() as u64 <= st.fused + st.below);
    let map = crate::hazard::HazardMap::from_elevation(&b.tiles);
    exports_of(&map, false);
    true
}

/// `Mapper::update` over frames decoded from the bytes: a config byte (which cues run,
/// whether the map is published every frame, how often the water prior is refreshed),
/// then per frame a stamp step, the vehicle pose (translation and a raw quaternion, which
/// need not be a rotation), and an organized lidar scan and stereo cloud of up to 16 × 48
/// points (`f32` x y z, NaN where the bytes run out). Every frame is offered; then the
/// whole map is finished and exported in memory.
pub fn mapper_update(data: &[u8]) -> bool {
    use nalgebra::{Quaternion, Translation3, UnitQuaternion};
    let mut b = Bytes::new(data);
    let head = b.u8();
    let mut cfg = crate::mapper::MapperConfig {
        grid: crate::grid::GridConfig {
            resolution: 0.25,
            size_cells: 64,
            ..Default::default()
        },
        ..crate::mapper::MapperConfig::default()
    };
    if let Some(l) = cfg.lidar.as_mut() {
        l.cues = head & 1 != 0;
        l.reflectivity = l.cues && head & 2 != 0;
        if head & 4 != 0 {
            l.height_m = Some(1.8);
        }
        // The water prior, refreshed every frame or every other one.
        l.cue.prior_every_frames = u32::from(head >> 5 & 3);
    }
    if let Some(s) = cfg.stereo.as_mut() {
        s.reflections = head & 8 != 0;
        s.mirror_check = false;
    }
    let Ok(mut mapper) = crate::mapper::Mapper::new(cfg) else {
        return false;
    };
    mapper.set_publish(head & 16 != 0);
    let cloud = |b: &mut Bytes, intensity: bool| {
        let rows = 1 + b.u8() as usize % 16;
        let cols = 1 + b.u8() as usize % 48;
        let xyz = (0..rows * cols)
            .map(|_| {
                if b.left() >= 12 {
                    [b.f32(), b.f32(), b.f32()]
                } else {
                    [f32::NAN; 3]
                }
            })
            .collect();
        let mut c = crate::geom::PointCloud::organized(rows, cols, xyz).ok()?;
        if intensity {
            c.intensity = Some((0..rows * cols).map(|i| (i % 97) as f32).collect());
        }
        Some(c)
    };
    let (mut stamp, mut fused) = (0.0f64, 0);
    for _ in 0..4 {
        if b.left() == 0 {
            break;
        }
        stamp += b.f32() as f64;
        let t = [b.f32(), b.f32(), b.f32()].map(|v| v as f64);
        let [w, x, y, z] = [b.f32(), b.f32(), b.f32(), b.f32()].map(|v| v as f64);
        let q = Quaternion::new(w, x, y, z);
        let base_to_map = crate::geom::Pose::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::new_unchecked(q),
        );
        let which = b.u8();
        let mut lidar = (which & 1 != 0)
            .then(|| cloud(&mut b, which & 4 != 0))
            .flatten();
        let mut stereo = (which & 2 != 0).then(|| cloud(&mut b, false)).flatten();
        for c in [&mut lidar, &mut stereo].into_iter().flatten() {
            c.frame_to_map = base_to_map;
            c.stamp = stamp;
        }
        let frame = crate::sensor::Frame {
            stamp,
            base_to_map,
            lidar,
            stereo,
            image: None,
            swir: None,
            mwir: None,
            stereo_baseline_m: None,
            geo: None,
        };
        if let Ok(r) = mapper.update(&frame) {
            fused += 1;
            assert_eq!(r.frame_index, fused);
        }
    }
    match mapper.finish_map() {
        Ok((_, map)) => exports_of(&map, false),
        Err(_) => return false,
    }
    fused > 0
}

/// The exports of a map with water: points and per-cell water evidence decoded from the
/// bytes are fused into a 64² window placed anywhere in the map (up to ±1e8 m), the water
/// stage makes bodies and hazards ([`crate::hazard::HazardMap::from_tiles`]), and every
/// output is produced, the files included.
pub fn exports(data: &[u8]) -> bool {
    use crate::grid::{CellKey, Evidence, RollingGrid, TileMap};
    let mut b = Bytes::new(data);
    let res = 0.25;
    let far = |v: f32| (v as f64).clamp(-1e8, 1e8);
    let (cx, cy) = (far(b.f32()), far(b.f32()));
    let cx = if cx.is_nan() { 0.0 } else { cx };
    let cy = if cy.is_nan() { 0.0 } else { cy };
    let gcfg = crate::grid::GridConfig {
        resolution: res,
        size_cells: 64,
        ..Default::default()
    };
    let Ok(mut grid) = RollingGrid::new(gcfg, cx, cy) else {
        return false;
    };
    let mut tiles = TileMap::for_grid(&grid);
    let o = grid.origin();
    // Cells: (column, row, height in cm, evidence counts).
    let mut pts = Vec::new();
    let mut ev = Vec::new();
    while b.left() >= 4 && pts.len() < 4096 {
        let (i, j) = (b.u8() as i64 % 64, b.u8() as i64 % 64);
        let z = b.u8() as i8 as f64 * 0.05;
        let kind = b.u8();
        let k = CellKey::new(o.x + i, o.y + j);
        let (x, y) = crate::grid::centre_of(res, k);
        pts.push([(x - cx) as f32, (y - cy) as f32, z as f32]);
        if kind & 0x80 != 0 {
            let mut e = Evidence::default();
            let c = (kind & 0x0f) as u16;
            e.noret = c;
            e.reflect = c * ((kind >> 4) & 1) as u16;
            e.colour_water = c * ((kind >> 5) & 1) as u16;
            e.add_level(((z - 0.1) * 1000.0) as i32);
            if kind & 0x40 != 0 {
                e.add_bottom_return(0.05 * (kind & 7) as f64, ((z - 0.1) * 1000.0) as i32, 1.0);
            }
            ev.push((k, e));
        }
    }
    let mut cloud = crate::geom::PointCloud::unorganized(pts);
    cloud.frame_to_map = crate::geom::pose_xyz_rpy(cx, cy, 0.0, 0.0, 0.0, 0.0);
    if grid
        .ingest(&cloud, &crate::grid::RangeNoise::constant(0.02))
        .is_err()
    {
        return false;
    }
    grid.apply_evidence(&ev);
    grid.flush(&mut tiles);
    let Ok(map) = crate::hazard::HazardMap::from_tiles(&tiles, &Default::default()) else {
        return false;
    };
    exports_of(&map, true);
    !map.cells.is_empty()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tarn_log::ros::{Endian, Header};

    /// The corpus seed of the NavSatFix kind: a fix's payload behind the kind byte 7
    /// (`TARN_WRITE_SEED=1 cargo test -p tarn-sim --lib nav_sat_fix` writes it).
    fn nav_sat_fix_seed() -> Vec<u8> {
        let m = NavSatFixMsg {
            header: Header::new("gps", 1_700_000_000_000_000_000),
            status: 0,
            service: 1,
            latitude: 30.6,
            longitude: -96.3,
            altitude: 100.0,
            position_covariance: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 4.0],
            position_covariance_type: 2,
        };
        let mut v = vec![7];
        v.extend(m.encode(Endian::Little));
        v
    }

    #[test]
    fn the_cdr_entry_reads_a_nav_sat_fix_and_the_corpus_holds_one() {
        let seed = nav_sat_fix_seed();
        assert!(cdr(&seed));
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/cdr/nav_sat_fix");
        if std::env::var_os("TARN_WRITE_SEED").is_some() {
            std::fs::write(&path, &seed).unwrap();
        }
        assert_eq!(std::fs::read(&path).unwrap(), seed, "{}", path.display());
        // Not a place on the globe: decoded, and refused.
        let mut far = seed.clone();
        let lat_at = far.len() - 8 * 9 - 1 - 8 * 3;
        far[lat_at..lat_at + 8].copy_from_slice(&1e9f64.to_le_bytes());
        assert!(!cdr(&far));
    }
}
