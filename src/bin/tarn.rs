//! The `tarn` command line: parses, calls the library, prints.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{json, Value};
use tarn::build::{build_file, check_output_dir, BuildConfig, BuildReport};
use tarn::grid::{GridConfig, RangeNoise};
use tarn::io::frames::{FrameStream, LogConfig};
use tarn::io::mcap_log::{self, LogCompression, LogReader, WriteOptions};
use tarn::io::ros::{self, schema_name, Endian};

#[derive(Parser)]
#[command(
    name = "tarn",
    version,
    about = "Terrain maps and water hazards for off-road vehicles",
    long_about = "Terrain maps and water hazards for off-road vehicles.\n\n\
                  With no command, builds the default scene shipped in maps/ into out/default."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Clone, Copy, ValueEnum)]
enum Compression {
    Zstd,
    Lz4,
    None,
}

#[derive(Subcommand)]
enum Command {
    /// Build a map from a point cloud in the map frame (.ply or KITTI .bin) and write the
    /// contract files: map.ply, terrain.ply, map.png, report.json.
    Build(BuildArgs),
    /// What a ROS 2 MCAP log holds: topics, types, counts, time span, frames that would be built.
    Info {
        log: PathBuf,
        /// Print JSON: {"duration_s", "topics": [{"topic", "type", "count"}], "frames": {...}}.
        #[arg(long)]
        json: bool,
        /// With --json: also every TF, PointCloud2, Image and CameraInfo message, decoded.
        #[arg(long, requires = "json")]
        dump_messages: bool,
        /// Topic whose clouds make frames (default: the lidar topic, /lidar/points).
        #[arg(long)]
        frame_topic: Option<String>,
        /// Log configuration (JSON; fields of tarn::io::frames::LogConfig, all optional).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Decodes the TF, PointCloud2, Image and CameraInfo messages of a log and writes them
    /// again with tarn's encoder (other types are skipped and counted).
    Recode {
        input: PathBuf,
        output: PathBuf,
        #[arg(long, value_enum, default_value = "zstd")]
        compression: Compression,
        /// Write without chunks (no index, no summary of chunks).
        #[arg(long)]
        unchunked: bool,
        /// Encode CDR big endian (ROS 2 itself writes little endian).
        #[arg(long)]
        big_endian: bool,
    },
}

#[derive(Args)]
struct BuildArgs {
    /// Input cloud: .ply (ascii or binary) or KITTI .bin, in the map frame.
    input: PathBuf,
    /// Output directory (created if needed; files are replaced atomically).
    #[arg(long)]
    out: PathBuf,
    /// Cell size, metres.
    #[arg(long, default_value_t = 0.10)]
    resolution: f64,
    /// Elevation noise of the input points, metres (one σ).
    #[arg(long, default_value_t = 0.02)]
    noise_sigma: f64,
    /// Largest window side, cells; larger clouds are built in blocks.
    #[arg(long, default_value_t = 2048)]
    max_window_cells: usize,
    /// Print the report as JSON instead of a summary.
    #[arg(long)]
    json: bool,
}

/// Where the default scene lives: next to the binary's crate, or in the working directory.
fn default_scene() -> PathBuf {
    let here = PathBuf::from("maps/default.ply");
    if here.exists() {
        return here;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("maps/default.ply")
}

fn run_build(a: &BuildArgs) -> anyhow::Result<BuildReport> {
    check_output_dir(&a.out)?;
    let cfg = BuildConfig {
        grid: GridConfig {
            resolution: a.resolution,
            ..GridConfig::default()
        },
        noise: RangeNoise::constant(a.noise_sigma),
        max_window_cells: a.max_window_cells,
    };
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} fusing {bar:40} {human_pos}/{human_len} points ({eta})",
        )
        .expect("static template"),
    );
    let report = build_file(&a.input, &a.out, &cfg, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    report.with_context(|| format!("building {}", a.input.display()))
}

fn print_summary(r: &BuildReport) {
    let p = &r.points;
    println!(
        "tarn {}: {} -> {}",
        r.tarn_version,
        r.input.display(),
        r.output.display()
    );
    println!(
        "  points {}: fused {}, below surface {}, non-finite {}, outside {}",
        p.points, p.fused, p.below, p.nonfinite, p.outside
    );
    println!(
        "  cells observed {} at {} m ({} tiles, {} window blocks of {} cells)",
        r.cells_observed, r.resolution_m, r.tiles, r.blocks, r.window_cells
    );
    if let (Some((lo, hi)), Some(e)) = (r.elevation_range_m, r.extent_m) {
        println!(
            "  extent x {:.2}..{:.2} m, y {:.2}..{:.2} m, elevation {:.3}..{:.3} m",
            e[0], e[2], e[1], e[3], lo, hi
        );
    }
    let t = &r.timings_s;
    println!(
        "  time read {:.3} s, fuse {:.3} s ({:.1} M points/s), export {:.3} s, total {:.3} s",
        t.read,
        t.fuse,
        p.points as f64 / t.fuse.max(1e-9) / 1e6,
        t.export,
        t.total
    );
    println!("  wrote map.ply terrain.ply map.png report.json");
}

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
    Ok(Some(match ch.schema.as_str() {
        schema_name::TF_MESSAGE => {
            let tf = ros::TfMessage::decode(&m.data).with_context(at)?;
            base(json!({"transforms": tf.transforms.iter().map(|t| {
                let v = t.child_to_parent.translation.vector;
                let q = t.child_to_parent.rotation.quaternion().coords;
                json!({"stamp": stamp(&t.header), "parent": t.header.frame_id, "child": t.child_frame_id,
                       "translation": [v.x, v.y, v.z], "rotation": [q.x, q.y, q.z, q.w]})
            }).collect::<Vec<_>>()}))
        }
        schema_name::POINT_CLOUD2 => {
            let msg = ros::PointCloud2Msg::decode(&m.data).with_context(at)?;
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
            let msg = ros::ImageMsg::decode(&m.data).with_context(at)?;
            let img = ros::decode_image(&msg)
                .map_err(anyhow::Error::msg)
                .with_context(at)?;
            let pixels: Value = match &img.pixels {
                ros::Pixels::Rgb8(p) => json!(p),
                ros::Pixels::Mono8(p) => json!(p),
                ros::Pixels::Mono16(p) => json!(p),
            };
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "encoding": msg.encoding, "width": img.width, "height": img.height, "pixels": pixels}),
            )
        }
        schema_name::CAMERA_INFO => {
            let msg = ros::CameraInfoMsg::decode(&m.data).with_context(at)?;
            base(
                json!({"stamp": stamp(&msg.header), "frame_id": msg.header.frame_id,
                "width": msg.width, "height": msg.height, "distortion_model": msg.distortion_model,
                "d": f64s(&msg.d), "k": f64s(&msg.k), "p": f64s(&msg.p)}),
            )
        }
        _ => return Ok(None),
    }))
}

fn info(log: PathBuf, as_json: bool, dump: bool, cfg: LogConfig) -> anyhow::Result<()> {
    let summary = mcap_log::summarize(&log)?;
    let mut stream = FrameStream::open(&log, &cfg)?;
    let mut frame_errors = Vec::new();
    for f in stream.by_ref() {
        if let Err(e) = f {
            frame_errors.push(e.to_string());
        }
    }
    let stats = stream.stats().clone();
    if as_json {
        let mut out = json!({
            "duration_s": summary.duration_s,
            "start_ns": summary.start_ns,
            "end_ns": summary.end_ns,
            "messages": summary.messages,
            "topics": summary.topics,
            "frame_topic": cfg.frame_topic,
            "frames": stats,
            "errors": frame_errors,
        });
        if dump {
            let mut msgs = Vec::new();
            for m in LogReader::open(&log)? {
                if let Some(v) = dump_message(&m?)? {
                    msgs.push(v);
                }
            }
            out["messages_decoded"] = Value::Array(msgs);
        }
        println!("{}", serde_json::to_string(&out)?);
        return Ok(());
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
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        None => {
            let a = BuildArgs {
                input: default_scene(),
                out: PathBuf::from("out/default"),
                resolution: 0.10,
                noise_sigma: 0.02,
                max_window_cells: 2048,
                json: false,
            };
            print_summary(&run_build(&a)?);
            Ok(())
        }
        Some(Command::Build(a)) => {
            let r = run_build(&a)?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                print_summary(&r);
            }
            Ok(())
        }
        Some(Command::Info {
            log,
            json,
            dump_messages,
            frame_topic,
            config,
        }) => {
            let mut cfg = match config {
                Some(p) => {
                    let text =
                        std::fs::read_to_string(&p).with_context(|| p.display().to_string())?;
                    serde_json::from_str(&text)
                        .with_context(|| format!("{}: not a log config", p.display()))?
                }
                None => LogConfig::default(),
            };
            if let Some(t) = frame_topic {
                cfg.frame_topic = t;
            }
            info(log, json, dump_messages, cfg)
        }
        Some(Command::Recode {
            input,
            output,
            compression,
            unchunked,
            big_endian,
        }) => {
            let opts = WriteOptions {
                compression: match compression {
                    Compression::Zstd => LogCompression::Zstd,
                    Compression::Lz4 => LogCompression::Lz4,
                    Compression::None => LogCompression::None,
                },
                chunked: !unchunked,
                endian: if big_endian {
                    Endian::Big
                } else {
                    Endian::Little
                },
                ..Default::default()
            };
            let s = mcap_log::recode(&input, &output, &opts)?;
            println!("wrote {} messages to {}", s.written, output.display());
            for (t, n) in &s.skipped_unknown {
                println!("skipped {n} messages of unknown type on {t}");
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("tarn: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
