//! The world tarn is measured in: scenes (`maps/*.toml`), a ray-casting sensor simulator
//! with the optics of [`crate::optics`], and the ground truth of every scene.
//!
//! [`simulate`] turns a [`Scene`] into `DIR/log.mcap` (the DESIGN.md contract topics, only
//! for the sensors the rig configures), `DIR/truth.ply` (the `map.ply` schema: one vertex
//! per truth cell), `DIR/truth.json` ([`TruthInfo`]) and `DIR/scene.ply` (the terrain and
//! object mesh the rays were cast against), and `DIR/rig.toml` (the rig: datasheet values
//! and mounts, which [`tarn::rig::RigSpec::mapper_config`] turns into what the mapper is told). `maps/README.md`
//! documents the formats.
//!
//! `sim` sits beside the pipeline: it uses every module, no pipeline module uses it.

mod render;
mod rng;
mod scene;
mod truth;
mod world;

#[cfg(test)]
mod tests;

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

pub use render::{
    body_to_optical, lens, mount, pinhole, radiance, render_image, sun, water_views, Band, Lidar,
    LidarReturn, Light, Radiance, Stereo, N_WATER, RIGHT_CAMERA_FRAME,
};
pub use rng::{hash, normal, unit_f64};
pub use scene::*;
pub use truth::{truth_map, water_stats, ColourView, TruthInfo, TruthPose, TruthWater};
pub use world::{Hit, Material, Surface, Terrain, WaterBody, World};

use crate::error::{Error, Result};
use crate::geom::{PointCloud, Pose};
use crate::sensor::Image;
use tarn_log::mcap_log::{LogWriter, WriteOptions};
use tarn_log::ros::{Header, NavSatFixMsg, TfMessage, Time, TransformStamped};

/// Options of a simulation run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimOptions {
    /// Sensor noise (range, disparity, dropout, pixel noise). Off: exact geometry.
    pub noise: bool,
    /// How much of the rig's calibration the log carries, as real logs vary.
    pub calibration: LogCalibration,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            noise: true,
            calibration: LogCalibration::Full,
        }
    }
}

/// How much of its calibration a simulated log carries: real logs are often recorded
/// without the right camera's `CameraInfo`, with a zero baseline in it, or with a raw
/// intensity under the name `reflectivity`. The sensors' data are the same in every case.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LogCalibration {
    /// Everything a driver publishes: both `CameraInfo`s, the lidar's channel by its name.
    #[default]
    Full,
    /// No `/camera_right/camera_info`: no baseline in the log.
    NoRightInfo,
    /// The right `CameraInfo` with `P[0][3] = 0` (a zero baseline, as RELLIS-3D ships it).
    ZeroBaseline,
    /// The lidar's raw intensity (falling as 1/r²) written as `reflectivity`.
    RawAsReflectivity,
}

impl LogCalibration {
    /// Every variant, by its name on the command line.
    pub const ALL: [(&'static str, LogCalibration); 4] = [
        ("full", LogCalibration::Full),
        ("no-right-info", LogCalibration::NoRightInfo),
        ("zero-baseline", LogCalibration::ZeroBaseline),
        ("raw-as-reflectivity", LogCalibration::RawAsReflectivity),
    ];
}

/// What [`simulate`] did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SimReport {
    pub scene: String,
    pub frames: usize,
    /// Primary rays cast per sensor kind, over all frames.
    pub lidar_beams: u64,
    pub lidar_returns: u64,
    pub stereo_rays: u64,
    pub stereo_points: u64,
    pub image_pixels: u64,
    pub truth_cells: usize,
    pub water_cells: usize,
    pub build_s: f64,
    pub render_s: f64,
    pub write_s: f64,
}

/// The vehicle poses: along the waypoints at `speed`, one per 1/`rate_hz` s, on the
/// terrain (base_link at ground level, heading along the path, no roll or pitch).
pub fn trajectory(w: &World) -> Vec<TruthPose> {
    let tr = &w.scene.trajectory;
    let pts = &tr.waypoints;
    let seg: Vec<f64> = pts
        .windows(2)
        .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
        .collect();
    let total: f64 = seg.iter().sum();
    let step = tr.speed / tr.rate_hz;
    let n_max = (total / step).floor() as usize + 1;
    let n = tr.frames.map_or(n_max, |f| f.min(n_max));
    (0..n)
        .map(|i| {
            let mut s = i as f64 * step;
            let mut k = 0;
            while k + 1 < seg.len() && s > seg[k] {
                s -= seg[k];
                k += 1;
            }
            let (a, b) = (pts[k], pts[k + 1]);
            let f = if seg[k] > 0.0 {
                (s / seg[k]).min(1.0)
            } else {
                0.0
            };
            let (x, y) = (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]));
            TruthPose {
                stamp: tr.start_time + i as f64 / tr.rate_hz,
                x,
                y,
                z: w.terrain.height(x, y),
                yaw: (b[1] - a[1]).atan2(b[0] - a[0]),
            }
        })
        .collect()
}

/// base_link → map of a trajectory pose.
pub fn pose_of(p: &TruthPose) -> Pose {
    crate::geom::pose_xyz_rpy(p.x, p.y, p.z, 0.0, 0.0, p.yaw)
}

/// The longitude (degrees east, within ±180°) where local apparent solar time is `hours`
/// at `unix_s` seconds since the epoch (UTC).
pub fn longitude_at(unix_s: f64, hours: f64) -> f64 {
    let utc_h = unix_s.rem_euclid(86_400.0) / 3600.0;
    let eot_h = crate::classify::equation_of_time_min(unix_s) / 60.0;
    let lon = (15.0 * (hours - utc_h - eot_h) + 180.0).rem_euclid(360.0) - 180.0;
    // A longitude that rounds to +180 is the same meridian as −180.
    if lon >= 180.0 {
        -180.0
    } else {
        lon
    }
}

fn stamp_ns(t: f64) -> i64 {
    (t * 1e9).round() as i64
}

fn header(t: f64, frame: &str) -> Header {
    Header {
        stamp: Time::from_nanos(stamp_ns(t)),
        frame_id: frame.into(),
    }
}

fn tf(t: f64, parent: &str, child: &str, pose: Pose) -> TransformStamped {
    TransformStamped::new(parent, child, stamp_ns(t), pose)
}

/// Frame names of the simulated sensors.
pub const LIDAR_FRAME: &str = "lidar";
pub const CAMERA_FRAME: &str = "camera_left_optical";
pub const SWIR_FRAME: &str = "swir_optical";
pub const MWIR_FRAME: &str = "mwir_optical";

/// Writes the scene mesh (terrain + objects; what the rays hit) as a binary PLY.
pub fn write_scene_mesh(w: &World, path: &Path) -> Result<()> {
    let verts: Vec<_> = w
        .vertices
        .iter()
        .map(|v| {
            (
                [v[0] as f32, v[1] as f32, v[2] as f32],
                [150u8, 140, 120],
                1u8,
            )
        })
        .collect();
    crate::io::write_mesh_ply(
        path,
        "tarn simulator scene mesh (terrain and objects)",
        &verts,
        &w.triangles,
    )
}

/// Simulates `scene` into `out_dir` (created if missing).
pub fn simulate(scene: &Scene, out_dir: &Path, opts: SimOptions) -> Result<SimReport> {
    let t0 = Instant::now();
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
    let w = World::build(scene)?;
    let poses = trajectory(&w);
    let rig = &scene.rig;
    let raw_as_reflectivity = opts.calibration == LogCalibration::RawAsReflectivity;
    let lidar = rig
        .lidar
        .as_ref()
        .map(|spec| {
            let mut spec = spec.clone();
            if raw_as_reflectivity {
                spec.intensity = IntensityKind::Raw;
            }
            Lidar::new(&spec)
        })
        .transpose()?;
    let stereo = rig.stereo.as_ref().map(Stereo::new).transpose()?;
    let camera = rig
        .camera
        .as_ref()
        .map(|c| render::camera_of(c, CAMERA_FRAME))
        .transpose()?;
    let swir = rig
        .swir
        .as_ref()
        .map(|c| render::camera_of(c, SWIR_FRAME))
        .transpose()?;
    let mwir = rig
        .mwir
        .as_ref()
        .map(|c| render::camera_of(c, MWIR_FRAME))
        .transpose()?;
    let light = Light::new(&w);
    let mut rep = SimReport {
        scene: scene.name.clone(),
        frames: poses.len(),
        ..Default::default()
    };
    rep.build_s = t0.elapsed().as_secs_f64();

    let mut topics = Vec::new();
    let mut log = LogWriter::create(out_dir.join("log.mcap"), &WriteOptions::default())?;
    let start = poses.first().map(|p| p.stamp).unwrap_or(0.0);
    let mut statics = Vec::new();
    if let Some(l) = &lidar {
        statics.push(tf(start, "base_link", LIDAR_FRAME, l.mount));
        topics.push("/lidar/points".to_string());
    }
    if let Some(s) = &stereo {
        statics.push(tf(start, "base_link", CAMERA_FRAME, s.optical_mount));
        // The right camera sits B to the right of the left one (+x of the optical frame).
        let right = s.optical_mount
            * Pose::from_parts(
                nalgebra::Translation3::new(s.spec.baseline_m, 0.0, 0.0),
                nalgebra::UnitQuaternion::identity(),
            );
        statics.push(tf(start, "base_link", RIGHT_CAMERA_FRAME, right));
        topics.extend(["/stereo/points", "/camera/image", "/camera/camera_info"].map(String::from));
        if opts.calibration != LogCalibration::NoRightInfo {
            topics.push("/camera_right/camera_info".to_string());
        }
    }
    if let Some((_, m)) = &camera {
        statics.push(tf(start, "base_link", CAMERA_FRAME, *m));
        topics.extend(["/camera/image", "/camera/camera_info"].map(String::from));
    }
    if let Some((_, m)) = &swir {
        statics.push(tf(start, "base_link", SWIR_FRAME, *m));
        topics.extend(["/swir/image", "/swir/camera_info"].map(String::from));
    }
    if let Some((_, m)) = &mwir {
        statics.push(tf(start, "base_link", MWIR_FRAME, *m));
        topics.extend(["/mwir/image", "/mwir/camera_info"].map(String::from));
    }
    let gps = rig
        .gps
        .map(|g| (g.latitude_deg, longitude_at(start, scene.sky.time_of_day)));
    if gps.is_some() {
        topics.push("/gps/fix".to_string());
    }
    let ns0 = stamp_ns(start) as u64;
    log.write_tf(
        "/tf_static",
        &TfMessage {
            transforms: statics,
        },
        ns0,
    )?;
    let (mut render_s, mut write_s) = (0.0, 0.0);
    // Per truth cell of water the colour camera saw: whether any pixel of any frame saw a
    // sky reflection there. A BTreeMap: the lists come out in key order.
    let mut views: std::collections::BTreeMap<[i64; 2], bool> = Default::default();
    // Truth cells of water that some lidar beam or camera pixel met first.
    let mut seen: std::collections::BTreeSet<[i64; 2]> = Default::default();
    let tres = scene.truth_resolution;
    let key = |x: f64, y: f64| [(x / tres).floor() as i64, (y / tres).floor() as i64];
    for (fi, p) in poses.iter().enumerate() {
        let base = pose_of(p);
        let ns = stamp_ns(p.stamp) as u64;
        let f = fi as u64;
        let tw = Instant::now();
        log.write_tf(
            "/tf",
            &TfMessage {
                transforms: vec![tf(p.stamp, "map", "base_link", base)],
            },
            ns,
        )?;
        if let Some((latitude, longitude)) = gps {
            let fix = NavSatFixMsg {
                header: header(p.stamp, "gps"),
                status: 0,
                service: 1,
                latitude,
                longitude,
                altitude: p.z,
                position_covariance: [4.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 16.0],
                position_covariance_type: 2,
            };
            log.write_nav_sat_fix("/gps/fix", &fix, ns)?;
        }
        write_s += tw.elapsed().as_secs_f64();
        if let Some(l) = &lidar {
            let tr = Instant::now();
            let (mut cloud, water) = l.scan_with_water(&w, &(base * l.mount), f, opts.noise)?;
            if raw_as_reflectivity {
                cloud.reflectivity = cloud.intensity.take();
            }
            seen.extend(water.iter().map(|p| key(p[0], p[1])));
            render_s += tr.elapsed().as_secs_f64();
            rep.lidar_beams += cloud.len() as u64;
            rep.lidar_returns += cloud.valid_count() as u64;
            let tw = Instant::now();
            log.write_cloud("/lidar/points", &cloud, header(p.stamp, LIDAR_FRAME), ns)?;
            write_s += tw.elapsed().as_secs_f64();
        }
        if let Some(s) = &stereo {
            let tr = Instant::now();
            let opt = base * s.optical_mount;
            let cloud = s.cloud(&w, &opt, f, opts.noise)?;
            let px = render_image(
                &w,
                &light,
                &s.camera,
                &opt,
                Band::Rgb(s.spec.encoding),
                s.spec.image_noise,
                f,
                opts.noise,
            );
            for (x, y, sky) in water_views(&w, &s.camera, &opt, s.spec.max_range_m) {
                *views.entry(key(x, y)).or_default() |= sky;
            }
            render_s += tr.elapsed().as_secs_f64();
            rep.stereo_rays += cloud.len() as u64;
            rep.stereo_points += cloud.valid_count() as u64;
            rep.image_pixels += (s.camera.width * s.camera.height) as u64;
            let tw = Instant::now();
            log.write_cloud("/stereo/points", &cloud, header(p.stamp, CAMERA_FRAME), ns)?;
            let img = Image {
                width: s.camera.width,
                height: s.camera.height,
                pixels: px,
                frame_id: CAMERA_FRAME.into(),
                stamp: p.stamp,
            };
            log.write_image("/camera/image", &img, header(p.stamp, CAMERA_FRAME), ns)?;
            log.write_camera(
                "/camera/camera_info",
                &s.camera,
                header(p.stamp, CAMERA_FRAME),
                ns,
            )?;
            if opts.calibration != LogCalibration::NoRightInfo {
                let mut info = s.right_info(header(p.stamp, RIGHT_CAMERA_FRAME));
                if opts.calibration == LogCalibration::ZeroBaseline {
                    info.p[3] = 0.0;
                }
                log.write_camera_info_msg("/camera_right/camera_info", &info, ns)?;
            }
            write_s += tw.elapsed().as_secs_f64();
        }
        // The single cameras: colour (without a stereo partner), SWIR, MWIR.
        for (cam, topic, info, frame, spec) in [
            (
                &camera,
                "/camera/image",
                "/camera/camera_info",
                CAMERA_FRAME,
                &rig.camera,
            ),
            (
                &swir,
                "/swir/image",
                "/swir/camera_info",
                SWIR_FRAME,
                &rig.swir,
            ),
            (
                &mwir,
                "/mwir/image",
                "/mwir/camera_info",
                MWIR_FRAME,
                &rig.mwir,
            ),
        ] {
            let (Some((model, m)), Some(spec)) = (cam, spec) else {
                continue;
            };
            let band = match frame {
                SWIR_FRAME => Band::Swir,
                MWIR_FRAME => Band::Mwir,
                _ => Band::Rgb(spec.encoding),
            };
            let tr = Instant::now();
            let opt = base * m;
            if matches!(band, Band::Rgb(_)) {
                for (x, y, sky) in water_views(&w, model, &opt, 120.0) {
                    *views.entry(key(x, y)).or_default() |= sky;
                }
            }
            let px = render_image(
                &w,
                &light,
                model,
                &opt,
                band,
                spec.image_noise,
                f,
                opts.noise,
            );
            render_s += tr.elapsed().as_secs_f64();
            rep.image_pixels += (model.width * model.height) as u64;
            let tw = Instant::now();
            let img = Image {
                width: model.width,
                height: model.height,
                pixels: px,
                frame_id: frame.into(),
                stamp: p.stamp,
            };
            log.write_image(topic, &img, header(p.stamp, frame), ns)?;
            log.write_camera(info, model, header(p.stamp, frame), ns)?;
            write_s += tw.elapsed().as_secs_f64();
        }
    }
    let tw = Instant::now();
    log.finish()?;
    let truth = truth_map(&w);
    crate::io::write_map_ply(&out_dir.join("truth.ply"), &truth)?;
    let counts = truth.class_counts();
    rep.truth_cells = truth.cells.len();
    rep.water_cells = counts[crate::hazard::Class::Water as usize];
    let info = TruthInfo {
        scene: scene.name.clone(),
        description: scene.description.clone(),
        seed: scene.seed,
        resolution: truth.resolution,
        fording_depth_m: scene.fording_depth,
        origin: scene.terrain.origin,
        size: scene.terrain.size,
        trajectory: poses,
        water_bodies: water_stats(&w, &truth),
        class_counts: counts,
        topics,
        colour_view: (stereo.is_some() || camera.is_some()).then(|| ColourView {
            sky: views.iter().filter(|v| *v.1).map(|v| *v.0).collect(),
            terrain: views.iter().filter(|v| !*v.1).map(|v| *v.0).collect(),
        }),
        seen_water: Some({
            seen.extend(views.keys().copied());
            seen.into_iter().collect()
        }),
    };
    tarn::files::write_json(&out_dir.join("truth.json"), &info)?;
    let rig_text = toml::to_string(&scene.rig)
        .map_err(|e| Error::invalid("rig", format!("cannot be written as TOML: {e}")))?;
    tarn::files::write_atomic(&out_dir.join("rig.toml"), |w| {
        w.write_all(
            format!(
                "# The rig the log was recorded with (tarn simulate): datasheet values and\n\
                 # mounts, nothing of the scene. `tarn build LOG --rig` reads it.\n{rig_text}"
            )
            .as_bytes(),
        )
    })?;
    write_scene_mesh(&w, &out_dir.join("scene.ply"))?;
    write_s += tw.elapsed().as_secs_f64();
    rep.render_s = render_s;
    rep.write_s = write_s;
    Ok(rep)
}

/// Casts `n` lidar-like rays from a point above the middle of the scene's terrain (a
/// workload for measuring rays per second): returns how many hit.
pub fn cast_fan(w: &World, n: usize) -> usize {
    use rayon::prelude::*;
    let t = &w.terrain;
    let cx = t.origin[0] + 0.5 * (t.nx - 1) as f64 * t.resolution;
    let cy = t.origin[1] + 0.5 * (t.ny - 1) as f64 * t.resolution;
    let o = Point3::new(cx, cy, t.height(cx, cy) + 2.0);
    (0..n)
        .into_par_iter()
        .filter(|&i| {
            let az = i as f64 * 2.399_963; // golden angle
            let el = -0.5 * (i % 64) as f64 / 64.0 - 0.02;
            let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            w.cast(&o, &d, 120.0).is_some()
        })
        .count()
}

/// A lidar-like ground cloud of `n` points (rings of a spinning sensor 1.8 m up, 2–19 m
/// out, gentle relief and 2 cm noise), in the order a spinning lidar emits them.
pub fn synthetic_lidar_cloud(n: usize, seed: u64) -> PointCloud {
    let mut s = seed | 1;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f32 / (1u64 << 53) as f32
    };
    let pts = (0..n)
        .map(|i| {
            let az = (i as f32 / n as f32) * 64.0 * std::f32::consts::TAU;
            let r = 2.0 + 17.0 * u();
            [
                r * az.cos(),
                r * az.sin(),
                0.05 * (r * 0.3).sin() + 0.02 * (u() - 0.5) - 1.8,
            ]
        })
        .collect();
    PointCloud::unorganized(pts)
}
