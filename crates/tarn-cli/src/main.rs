//! The `tarn` command line: parses, calls the library, prints. One file per command.

mod bench;
mod bench_cmd;
mod build_cmd;
mod classify_cmd;
mod cloud_cmd;
mod cues_cmd;
mod log_cmd;
mod main_job;
mod maps_out;
mod optics_cmd;
mod plot;
mod sim_cmd;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use tarn_log::frames::LogConfig;
use tarn_log::mcap_log::{self, LogCompression, WriteOptions};
use tarn_log::ros::Endian;

use build_cmd::BuildArgs;

#[derive(Parser)]
#[command(
    name = "tarn",
    version,
    about = "Terrain maps and water hazards for off-road vehicles",
    long_about = "Terrain maps and water hazards for off-road vehicles.\n\n\
                  With no command: simulates maps/default.toml into out/default/sim, builds its \
                  map into out/default, scores it against the truth, and prints what it found."
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
    /// Build a map from a robot log (.mcap, rosbag2 directory or .db3, ROS 1 .bag: the full
    /// pipeline with water cues) or a point cloud in the map frame (.ply or KITTI .bin) and
    /// write the contract files: map.ply, terrain.ply, water.ply, map.png, report.json.
    Build(Box<BuildArgs>),
    /// Lidar propagation over water: bottom returns, maximum measurable depth, and the
    /// lookahead interval where a missing return is diagnostic of water.
    LidarModel(optics_cmd::LidarModelArgs),
    /// Water cues of one organized lidar scan: no-return evidence inside the optics'
    /// diagnostic interval, bottom and specular returns, reflectivity drop.
    Cues(cues_cmd::CuesArgs),
    /// Per-stage time per frame (medians), whole-log throughput, peak memory, bytes per cell.
    Bench(bench_cmd::BenchArgs),
    /// What a file holds. A robot log (.mcap, rosbag2 directory or .db3, ROS 1 .bag): topics,
    /// types, counts, time span, frames that would be built. A point cloud (.ply, KITTI
    /// .bin): points, returns, channels, bounds.
    Info {
        input: PathBuf,
        /// (log) Print JSON: {"duration_s", "topics": [{"topic", "type", "count"}], "frames": {...}}.
        #[arg(long)]
        json: bool,
        /// (log) With --json: also every TF, PointCloud2, Image and CameraInfo message, decoded.
        #[arg(long, requires = "json")]
        dump_messages: bool,
        /// (log) Topic whose clouds make frames (default: the lidar, or the stereo cloud when
        /// the log has no lidar).
        #[arg(long)]
        frame_topic: Option<String>,
        /// (log) The lidar's PointCloud2 topic (default: found by type, as `tarn build`).
        #[arg(long)]
        lidar_topic: Option<String>,
        /// (log) The stereo PointCloud2 topic.
        #[arg(long)]
        stereo_topic: Option<String>,
        /// (log) The colour camera's Image topic.
        #[arg(long)]
        camera_topic: Option<String>,
        /// (log) Log configuration (JSON; fields of tarn_log::frames::LogConfig, all optional).
        #[arg(long)]
        log_config: Option<PathBuf>,
        /// (cloud) The file is a column-major lidar scan with this many rings (point = column ×
        /// rings + ring, as Ouster and RELLIS-3D write it): show it organized.
        #[arg(long)]
        rings: Option<usize>,
    },
    /// Simulate a scene (maps/*.toml): writes DIR/log.mcap, DIR/truth.ply, DIR/truth.json
    /// and DIR/scene.ply.
    Simulate(sim_cmd::SimulateArgs),
    /// Score a map (MAPDIR/map.ply) against the ground truth of a simulated scene, by range
    /// from the vehicle's path.
    Eval(sim_cmd::EvalArgs),
    /// Train the colour water classifier (one Gaussian mixture per class in RGB, components
    /// by BIC) from an image and a label image of class ids; writes a JSON model.
    #[command(name = "train-colour")]
    TrainColour(classify_cmd::TrainArgs),
    /// Classify an image's pixels as water or not (8-bit mask, 255 = water).
    Classify(classify_cmd::ClassifyArgs),
    /// Decodes the TF, PointCloud2, Image and CameraInfo messages of a log (any input log:
    /// MCAP, rosbag2, ROS 1 bag) and writes them to an MCAP log with tarn's encoder (other
    /// types are skipped and counted).
    Recode {
        input: PathBuf,
        /// The MCAP log to write.
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum, default_value = "zstd")]
        compression: Compression,
        /// Write without chunks (no index, no summary of chunks).
        #[arg(long)]
        unchunked: bool,
        /// Encode CDR big endian (ROS 2 itself writes little endian).
        #[arg(long)]
        big_endian: bool,
        /// Print what was written, skipped and damaged as JSON.
        #[arg(long)]
        json: bool,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        None => main_job::run(
            &main_job::default_scene_toml(),
            &PathBuf::from("out/default"),
        ),
        Some(Command::Build(a)) => build_cmd::run(&a),
        Some(Command::Simulate(a)) => sim_cmd::run_simulate(&a),
        Some(Command::Eval(a)) => sim_cmd::run_eval(&a),
        Some(Command::LidarModel(a)) => optics_cmd::lidar_model(a),
        Some(Command::TrainColour(a)) => classify_cmd::train(a),
        Some(Command::Classify(a)) => classify_cmd::classify(a),
        Some(Command::Cues(a)) => cues_cmd::run(&a),
        Some(Command::Bench(a)) => bench_cmd::run_bench(&a),
        Some(Command::Info {
            input,
            json,
            dump_messages,
            frame_topic,
            lidar_topic,
            stereo_topic,
            camera_topic,
            log_config,
            rings,
        }) => {
            if !tarn_log::log::is_log(&input) {
                return cloud_cmd::info(&input, rings);
            }
            let cfg = match log_config {
                Some(p) => build_cmd::load_log_config(&p)?,
                None => LogConfig::default(),
            };
            let named = tarn_log::frames::NamedTopics {
                lidar: lidar_topic,
                stereo: stereo_topic,
                camera: camera_topic,
                frame: frame_topic.or_else(|| {
                    (cfg.frame_topic != LogConfig::default().frame_topic)
                        .then(|| cfg.frame_topic.clone())
                }),
            };
            log_cmd::info(input, json, dump_messages, cfg, &named)
        }
        Some(Command::Recode {
            input,
            out,
            compression,
            unchunked,
            big_endian,
            json,
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
            let s = mcap_log::recode(&input, &out, &opts)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                println!("wrote {} messages to {}", s.written, out.display());
                for (t, n) in &s.skipped_unknown {
                    println!("skipped {n} messages of unknown type on {t}");
                }
            }
            build_cmd::damaged_input(&input, "wrote", &s.damaged)
        }
    }
}

/// glibc's malloc hands a large block to the kernel when it is freed (mmap above a
/// threshold that adapts to the sizes freed so far, and a heap trimmed past 128 KiB), so a
/// build that allocates a frame's clouds and buffers anew every frame takes fresh, zeroed
/// pages every frame, and how many depends on what happened to be freed first. Fixed
/// thresholds keep freed blocks up to 64 MiB for reuse: on the default scene's log a build
/// takes about a quarter fewer page faults, on the `wide` rig's about half and the same
/// number from run to run (docs/speed.md).
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

fn main() -> ExitCode {
    // A closed stdout (`tarn eval ... | head`) ends the process as it ends every Unix tool,
    // instead of a panic in println!. Rust sets SIGPIPE to "ignore" before main.
    #[cfg(unix)]
    // SAFETY: called first in main, before any other thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    keep_freed_memory();
    // SIGINT asks a running build to stop between frames; it then writes nothing, so the
    // output directory keeps its previous files (tarn::interrupt).
    if let Err(e) = ctrlc::set_handler(tarn::interrupt::request_stop) {
        eprintln!("tarn: warning: cannot handle SIGINT: {e}");
    }
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        // Built, from a damaged input: the outputs are written and name what was skipped.
        Err(e) if e.downcast_ref::<build_cmd::DamagedInput>().is_some() => {
            eprintln!("tarn: warning: {}", chain_message(&e));
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("tarn: error: {}", chain_message(&e));
            let interrupted = e
                .chain()
                .any(|c| matches!(c.downcast_ref(), Some(tarn::Error::Interrupted(_))));
            // 128 + SIGINT, as a shell reports a process stopped by Ctrl-C.
            ExitCode::from(if interrupted { 130 } else { 1 })
        }
    }
}

/// An error and its causes, as `{:#}` joins them (": "), but leaving out a cause whose
/// text its parent already ends with: the library's I/O errors say what the operating
/// system said and also give it as their source, and it would be printed twice.
fn chain_message(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if msg.ends_with(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

#[cfg(test)]
mod chain_tests {
    use super::chain_message;

    #[test]
    fn a_cause_its_parent_quotes_is_printed_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e =
            anyhow::Error::new(tarn::Error::io("/x/mapper.toml", io)).context("building log.mcap");
        assert_eq!(
            chain_message(&e),
            "building log.mcap: /x/mapper.toml: no such file"
        );
        // Causes that are not quoted are all kept, in order.
        let e = anyhow::anyhow!("inner").context("middle").context("outer");
        assert_eq!(chain_message(&e), "outer: middle: inner");
    }
}
