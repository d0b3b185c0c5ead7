//! `tarn info LOG` and `tarn recode`: what a robot log holds.

use std::path::PathBuf;

use anyhow::Context;
use serde_json::{json, Value};
use tarn_log::frames::{FrameStream, LogConfig, NamedTopics};
use tarn_log::mcap_log;
use tarn_log::ros::{self, schema_name};

fn f64s(v: &[f64]) -> Value {
    json!(v)
}

fn dump_message(m: &mcap_log::RawMessage) -> anyhow::Result<Option<Value>> {
    let ch = &m.channel;
    let base = |body: Value| {
        let mut o = json!({"topic": ch.topic, "type": ch.schema, "log_time": m.log_time});
        o.as_object_mut()
            .expect("object")
            .extend(body.as_object().expect("object").clone());
        o
    };
    let stamp = |h: &ros::Header| json!([h.stamp.sec, h.stamp.nanosec]);
    let at = || format!("{} at log time {} ns", ch.topic, m.log_time);
    let (Some(kind), Some(wire)) = (
        tarn_log::log::canonical_type(&ch.schema),
        tarn_log::log::wire_of(&ch.message_encoding),
    ) else {
        return Ok(None);
    };
    Ok(Some(match kind {
        schema_name::TF_MESSAGE => {
            let tf = ros::TfMessage::decode_wire(&m.data, wire).with_context(at)?;
            base(json!({"transforms": tf.transforms.iter().map(|t| {
                let v = t.child_to_parent.translation.vector;
                let q = t.child_to_parent.rotation.quaternion().coords;
                json!({"stamp": stamp(&t.header), "parent": t.header.frame_id, "child": t.child_frame_id,
                       "translation": [v.x, v.y, v.z], "rotation": [q.x, q.y, q.z, q.w]})
            }).collect::<Vec<_>>()}))
        }
        schema_name::POINT_CLOUD2 => {
            let msg = ros::PointCloud2Msg::decode_wire(&m.data, wire).with_context(at)?;
            let c = ros::pointcloud2_to_cloud(&msg)
                .map_err(anyhow::Error::msg)
                .with_context(at)?;
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "height": msg.height, "width": msg.width, "rows": c.rows, "cols": c.cols,
                "xyz": c.xyz, "intensity": c.intensity, "reflectivity": c.reflectivity}),
            )
        }
        schema_name::IMAGE => {
            let msg = ros::ImageMsg::decode_wire(&m.data, wire).with_context(at)?;
            let img = ros::decode_image(&msg)
                .map_err(anyhow::Error::msg)
                .with_context(at)?;
            let pixels: Value = match &img.pixels {
                tarn::sensor::Pixels::Rgb8(p) => json!(p),
                tarn::sensor::Pixels::Mono8(p) => json!(p),
                tarn::sensor::Pixels::Mono16(p) => json!(p),
            };
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "encoding": msg.encoding, "width": img.width, "height": img.height, "pixels": pixels}),
            )
        }
        schema_name::CAMERA_INFO => {
            let msg = ros::CameraInfoMsg::decode_wire(&m.data, wire).with_context(at)?;
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "width": msg.width, "height": msg.height, "distortion_model": msg.distortion_model,
                "d": f64s(&msg.d), "k": f64s(&msg.k), "p": f64s(&msg.p)}),
            )
        }
        schema_name::NAV_SAT_FIX => {
            let msg = ros::NavSatFixMsg::decode_wire(&m.data, wire).with_context(at)?;
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "status": msg.status, "latitude": msg.latitude, "longitude": msg.longitude,
                "altitude": msg.altitude}),
            )
        }
        _ => return Ok(None),
    }))
}

pub fn info(
    log: PathBuf,
    as_json: bool,
    dump: bool,
    cfg: LogConfig,
    named: &NamedTopics,
) -> anyhow::Result<()> {
    let summary = tarn_log::log::summarize(&log)?;
    let cfg = cfg.with_topics_of(&summary, named, &log)?;
    let mut stream = FrameStream::open(&log, &cfg)?;
    let mut frame_errors = Vec::new();
    // The sensors' calibration as `tarn build LOG` measures it, over the first frames.
    let mut mapper = tarn::mapper::Mapper::new(tarn_log::build::sensors_of_log(
        &tarn::mapper::MapperConfig::every_sensor(),
        &cfg,
        &summary,
    ))?;
    mapper.set_publish(false);
    for f in stream.by_ref() {
        match f {
            Ok(frame) if mapper.frames() < CALIBRATION_FRAMES => {
                if let Err(e) = mapper.update(&frame) {
                    frame_errors.push(format!("frame at {:.6} s: {e}", frame.stamp));
                }
            }
            Ok(_) => {}
            Err(e) => frame_errors.push(e.to_string()),
        }
    }
    let calibration = mapper.calibration().clone();
    let stats = stream.stats().clone();
    if as_json {
        let mut out = json!({
            "duration_s": summary.duration_s,
            "start_ns": summary.start_ns,
            "end_ns": summary.end_ns,
            "messages": summary.messages,
            "topics": summary.topics,
            "frame_topic": cfg.frame_topic,
            "sensor_topics": {"lidar": cfg.lidar_topic, "stereo": cfg.stereo_topic,
                "camera": cfg.image_topic, "camera_info": cfg.camera_info_topic},
            "frames": stats,
            "errors": frame_errors,
            "damaged": summary.damaged,
            "calibration": calibration,
        });
        if dump {
            let mut msgs = Vec::new();
            let mut r = tarn_log::log::open(&log)?;
            while let Some(m) = r.next_message() {
                if let Some(v) = dump_message(&m?)? {
                    msgs.push(v);
                }
            }
            out["messages_decoded"] = Value::Array(msgs);
        }
        println!("{}", serde_json::to_string(&out)?);
        no_frames_warning(&cfg, &stats);
        return crate::build_cmd::damaged_input(&log, "counted", &summary.damaged);
    }
    println!("{}", log.display());
    println!(
        "  {} messages over {:.3} s",
        summary.messages, summary.duration_s
    );
    let w = summary
        .topics
        .iter()
        .map(|t| t.topic.len())
        .max()
        .unwrap_or(5);
    for t in &summary.topics {
        println!("  {:<w$}  {:>8}  {}", t.topic, t.count, t.schema);
    }
    // The sensors the log has, on the topics a build reads them from.
    let has = |t: &str| summary.has_messages(t);
    let sensors: Vec<String> = [
        ("lidar", &cfg.lidar_topic),
        ("stereo", &cfg.stereo_topic),
        ("camera", &cfg.image_topic),
        ("swir", &cfg.swir_topic),
        ("mwir", &cfg.mwir_topic),
        ("gps", &cfg.gps_topic),
    ]
    .into_iter()
    .filter(|(_, t)| has(t))
    .map(|(n, t)| format!("{n} {t}"))
    .collect();
    println!(
        "  sensors: {}",
        if sensors.is_empty() {
            "none tarn reads".to_string()
        } else {
            sensors.join(", ")
        }
    );
    println!(
        "  frames (from {}): {} would be built, {} skipped for want of a transform",
        cfg.frame_topic, stats.frames_built, stats.frames_skipped_no_tf
    );
    for r in &stats.skip_reasons {
        println!("    skipped: {r}");
    }
    if stats.secondary_dropped_no_tf > 0 {
        println!(
            "  {} matched images/clouds without a transform",
            stats.secondary_dropped_no_tf
        );
    }
    for (k, n) in &stats.unknown_type {
        println!("  skipped {n} messages of unknown type on {k}");
    }
    for e in &frame_errors {
        println!("  error: {e}");
    }
    print_calibration(&calibration);
    no_frames_warning(&cfg, &stats);
    crate::build_cmd::damaged_input(&log, "counted", &summary.damaged)
}

/// Frames `tarn info` measures the sensors' calibration over.
const CALIBRATION_FRAMES: u64 = 20;

/// The calibration section, as lines a person reads.
pub fn print_calibration(c: &tarn::calib::CalibrationReport) {
    use tarn::calib::Source;
    let src = |s: Source| match s {
        Source::Log => "log",
        Source::Config => "config/rig",
        Source::Measured => "measured",
        Source::Default => "assumed (noisy end)",
    };
    let opt = |v: Option<f64>, unit: &str| {
        v.map_or("—".to_string(), |v| {
            format!("{v:.4} {unit}").trim_end().to_string()
        })
    };
    println!("  calibration:");
    if let Some(s) = &c.stereo {
        println!(
            "    stereo: focal {}, binning {}, baseline {}, σ_d {}",
            opt(s.stated.focal_px, "px"),
            s.stated.binning.map_or("—".into(), |k| k.to_string()),
            s.stated.baseline_m.map_or("none".into(), |b| format!(
                "{:.4} m ({})",
                b.value,
                src(b.source)
            )),
            s.stated
                .disparity_noise_px
                .map_or("not stated".into(), |d| format!(
                    "{:.3} px ({})",
                    d.value,
                    src(d.source)
                )),
        );
        println!(
            "    stereo noise c (σ_z = a + c·z², 1/m): stated {}, measured {} over {} frames \
             (against the lidar {}, local planes {}), used {}",
            opt(s.stated_per_m2, ""),
            opt(s.measured.map(|m| m.per_m2), ""),
            s.measured_frames,
            opt(s.measured_by_lidar_per_m2, ""),
            opt(s.measured_by_planes_per_m2, ""),
            s.used_per_m2.map_or("—".into(), |u| format!(
                "{:.4} ({})",
                u.value,
                src(u.source)
            )),
        );
        if let Some(d) = s.implied_disparity_noise_px {
            println!("    σ_d implied by the measurement: {d:.3} px");
        }
    }
    if let Some(l) = &c.lidar {
        println!(
            "    lidar range noise σ0: stated {}, measured {} over {} scans, used {}",
            opt(l.stated_sigma0_m, "m"),
            l.measured.map_or("—".into(), |m| format!(
                "{:.4} m + {:.5}·r",
                m.noise.sigma0, m.noise.per_m
            )),
            l.measured_frames,
            l.used_sigma0_m.map_or("—".into(), |u| format!(
                "{:.4} m ({})",
                u.value,
                src(u.source)
            )),
        );
        if let Some(h) = l.height_m {
            println!("    lidar height: {:.2} m ({})", h.value, src(h.source));
        }
        if let Some(law) = &l.intensity_law {
            println!(
                "    lidar `{}` falls as r^{:.2} over the ground: {}, incidence exponent {}",
                law.channel,
                law.falloff_exponent,
                if law.range_compensated {
                    "range-compensated"
                } else {
                    "raw (not range-compensated)"
                },
                law.incidence_exponent.map_or(
                    "not determined (the mix of surfaces decides)".into(),
                    |m| format!("{m:.2}")
                )
            );
        }
    }
    if !c.assumed.is_empty() {
        println!("    assumed: {}", c.assumed.join(", "));
    }
    for w in &c.waited {
        println!("    waited: {w}");
    }
    for w in &c.warnings {
        println!("    warning: {w}");
    }
}

/// On stderr when no frame would be built: `tarn build` would refuse the log.
fn no_frames_warning(cfg: &LogConfig, stats: &tarn_log::frames::FrameStats) {
    if stats.frames_built == 0 {
        eprintln!(
            "warning: no frame would be built from {} ({} skipped without a transform); \
             `tarn build` would exit 1",
            cfg.frame_topic, stats.frames_skipped_no_tf
        );
    }
}
