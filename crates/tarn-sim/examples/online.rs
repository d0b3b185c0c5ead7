//! The online mapper fed from a log at real time: each frame goes to `Mapper::update` when
//! the log's clock says it arrives, then the planner's side takes `Mapper::hazard_map()`;
//! at the end, the per-frame latency of each stage (median, p95, max).
//!
//! ```text
//! cargo run --release --bin tarn -- simulate maps/default.toml --out out/sim
//! cargo run --release --example online -- out/sim/log.mcap [--config out/sim/mapper.toml] [--fast]
//! ```
//!
//! `--fast` does not sleep to the log's stamps (frames back to back); without it a frame
//! that takes longer than the gap to the next one is counted as late.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use tarn::mapper::{Mapper, MapperConfig};
use tarn_log::build::stage_latency;
use tarn_log::frames::{FrameStream, LogConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut log: Option<PathBuf> = None;
    let mut config: Option<PathBuf> = None;
    let mut fast = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--fast" => fast = true,
            "--config" => config = Some(args.next().ok_or("--config needs a file")?.into()),
            s if s.starts_with("--") => return Err(format!("unknown option {s}").into()),
            s => log = Some(s.into()),
        }
    }
    let log = log.ok_or(
        "usage: online LOG.mcap [--config mapper.toml] [--fast]\n\
         (make a log with: tarn simulate maps/default.toml --out out/sim)",
    )?;
    let cfg = match &config {
        Some(p) => MapperConfig::load(p)?,
        None => MapperConfig::default(),
    };
    let mut mapper = Mapper::new(cfg)?;
    let stream = FrameStream::open(&log, &LogConfig::default())?;
    let (mut t_log0, wall0) = (None, Instant::now());
    let (mut times, mut late, mut snapshot_ns) = (Vec::new(), 0usize, Vec::new());
    for frame in stream {
        let frame = frame?;
        let t0 = *t_log0.get_or_insert(frame.stamp);
        if !fast {
            let due = Duration::from_secs_f64((frame.stamp - t0).max(0.0));
            match due.checked_sub(wall0.elapsed()) {
                Some(wait) => std::thread::sleep(wait),
                None => late += 1,
            }
        }
        let r = mapper.update(&frame)?;
        let t = Instant::now();
        let map = mapper.hazard_map();
        snapshot_ns.push(t.elapsed().as_nanos() as f64);
        println!(
            "frame {:3} at {:8.3} s: {:6} cells, {:5} water; update {:6.1} ms",
            r.frame_index,
            frame.stamp,
            map.cells.len(),
            r.snapshot_water_cells,
            r.times_s.total * 1e3
        );
        times.push(r.times_s);
    }
    println!(
        "\n{} frames{}; per-frame latency (ms):",
        times.len(),
        if fast {
            String::new()
        } else {
            format!(" at real time, {late} arrived while the previous one was still being fused")
        }
    );
    println!("| stage | median | p95 | max |\n| --- | ---: | ---: | ---: |");
    for s in stage_latency(&times) {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} |",
            s.stage, s.median_ms, s.p95_ms, s.max_ms
        );
    }
    snapshot_ns.sort_by(f64::total_cmp);
    if let Some(m) = snapshot_ns.get(snapshot_ns.len() / 2) {
        println!("hazard_map() snapshot: median {m:.0} ns");
    }
    Ok(())
}
