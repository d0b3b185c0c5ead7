//! A robot log built into a map through the online [`Mapper`], frame by frame.

use std::path::Path;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::frames::LogConfig;
use crate::grid::IngestStats;
use crate::mapper::{Mapper, MapperConfig, StageTimes};
use tarn::io;

use super::*;

/// Builds the map of a robot log (any storage [`crate::log::open`] reads) through the online [`Mapper`] (one code path for online
/// and offline): each frame is fused at its pose into a rolling window centred on the
/// vehicle, with the configured cues; cells that leave it go to the global tile map. At the
/// end the hazard map of everything is exported. `progress(bytes_read, bytes_total)`.
///
/// A damaged or truncated log gives the map of everything that could be read: damaged
/// chunks and records are skipped and listed in [`LogBuildReport::damaged`]. A file that
/// is not a log, or cannot be read, is an error.
pub fn build_log(
    input: &Path,
    out: &Path,
    cfg: &LogBuildConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<LogBuildReport> {
    use crate::frames::FrameStream;

    let t0 = Instant::now();
    let summary = crate::log::summarize_quick(input)?;
    let log_cfg = frame_log_config(cfg, &summary, input)?;
    let mut mapper = Mapper::new(sensors_of_log(&cfg.mapper, &log_cfg, &summary))?;
    mapper.set_publish(cfg.build.per_frame_maps);
    calibrate_on_log(&mut mapper, input, &log_cfg)?;
    let stream = FrameStream::open(input, &log_cfg)?;
    let path_step = cfg.mapper.grid.resolution;
    let (fused, read_end) = fuse_frames(&mut mapper, stream, input, path_step, progress)?;
    let ReadEnd {
        stats: stream_stats,
        damaged,
        fatal,
    } = read_end;
    if let Some(e) = fatal {
        // Not a log, or unreadable: nothing is written.
        return Err(Error::format(
            input,
            format!("topic {}", log_cfg.frame_topic),
            format!("no map built: {e}"),
        ));
    }
    if fused.frames_fused == 0 {
        return Err(no_frame_built(
            input,
            &log_cfg,
            &summary,
            &stream_stats,
            &damaged,
            &fused.errors,
        ));
    }
    let cues = mapper.config().cue_names();
    let lidar_height_m = mapper.lidar_height();
    let diagnostic_interval_m = mapper.diagnostic_interval();
    let calibration = mapper.calibration().clone();
    let fusion = mapper.config().fusion;
    let (gcfg, res) = (
        mapper.config().grid.clone(),
        mapper.config().grid.resolution,
    );
    let t_read_fuse = t0.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let mut warnings = fused.warnings();
    let (tiles, map) = mapper.finish_map()?;
    let fusion = fusion.measured(&tiles.false_alarms());
    if map.cells.is_empty() {
        return Err(nothing_observed(input, &log_cfg, &fused));
    }
    let stage = io::Staging::new(out)?;
    warnings.extend(swept_warnings(&stage));
    io::write_map_files_marked(
        stage.path(),
        &map,
        &damage_marks(input, &damaged),
        &fused.vehicle_path,
    )?;
    let extra_outputs = ExtraMaps::of(&cfg.build, &log_cfg.map_frame, summary.end_ns.unwrap_or(0))
        .write(stage.path(), &tiles)?;
    let t_export = t2.elapsed().as_secs_f64();
    let total = t0.elapsed().as_secs_f64();
    let report = LogBuildReport {
        tarn_version: env!("CARGO_PKG_VERSION").to_string(),
        input: input.to_path_buf(),
        output: out.to_path_buf(),
        resolution_m: res,
        window_cells: gcfg.size_cells,
        frame_topic: log_cfg.frame_topic.clone(),
        frames_fused: fused.frames_fused,
        log_duration_s: summary.duration_s,
        x_realtime: summary.duration_s / total.max(1e-9),
        per_frame_maps: cfg.build.per_frame_maps,
        cues,
        lidar_height_m,
        diagnostic_interval_m,
        calibration,
        fusion,
        lidar_points: fused.lidar,
        stereo_points: fused.stereo,
        cue_counts: fused.counts,
        frames: stream_stats,
        errors: fused.errors,
        warnings,
        points_beyond_max_range: fused.beyond,
        damaged,
        labels: fused.label_totals,
        cells_observed: map.cells.len(),
        tiles: tiles.tile_count(),
        elevation_range_m: io::elevation_range(&map.cells),
        water: WaterSummary::of(&map, &fusion),
        extra_outputs,
        timings_s: Timings {
            read: t_read_fuse - fused.t_fuse,
            fuse: fused.t_fuse,
            export: t_export,
            total,
        },
        stage_totals_s: fused.stage_totals,
        stage_latency_ms: stage_latency(&fused.per_frame),
    };
    crate::files::write_json(&stage.path().join("report.json"), &report)?;
    crate::interrupt::check("writing the outputs")?;
    stage.commit()?;
    Ok(report)
}

/// What the reader of a log's frames leaves: its counts, the damaged parts of the log,
/// and the error that ended reading early if one did.
struct ReadEnd {
    stats: crate::frames::FrameStats,
    damaged: Vec<crate::mcap_log::DamagedRange>,
    fatal: Option<String>,
}

/// What fusing a log's frames gathered, frame by frame.
#[derive(Default)]
struct FusedFrames {
    lidar: IngestStats,
    stereo: IngestStats,
    counts: CueCounts,
    /// Frames that could not be read or fused.
    errors: Vec<String>,
    frame_warnings: FrameWarnings,
    beyond: BeyondRange,
    frames_fused: u64,
    /// Seconds spent in [`Mapper::update`].
    t_fuse: f64,
    stage_totals: StageTimes,
    per_frame: Vec<StageTimes>,
    label_totals: Option<crate::project::FrameLabelsReport>,
    /// The vehicle's path for map.png: a point per cell travelled.
    vehicle_path: Vec<[f64; 2]>,
}

impl FusedFrames {
    /// Adds what fusing `frame` reported; `path_step` is the spacing of the vehicle's path.
    fn add(&mut self, frame: &crate::sensor::Frame, r: crate::mapper::FrameReport, path_step: f64) {
        let at = frame.base_to_map.translation.vector;
        if self
            .vehicle_path
            .last()
            .is_none_or(|p: &[f64; 2]| (p[0] - at.x).hypot(p[1] - at.y) >= path_step)
        {
            self.vehicle_path.push([at.x, at.y]);
        }
        self.beyond.lidar += r.beyond_max_range[0];
        self.beyond.stereo += r.beyond_max_range[1];
        for w in &r.warnings {
            self.frame_warnings.add(frame.stamp, w);
        }
        if let Some(s) = r.lidar_points() {
            self.lidar.merge(s);
        }
        if let Some(s) = r.stereo_points() {
            self.stereo.merge(s);
        }
        self.counts.add(&r.cues);
        if let Some(l) = &r.labels {
            crate::project::FrameLabelsReport::merge(
                self.label_totals.get_or_insert_with(Default::default),
                l,
            );
        }
        self.stage_totals.add(&r.times_s);
        self.per_frame.push(r.times_s);
        self.frames_fused += 1;
    }

    /// The build's warnings from its frames: each kind of per-frame warning once, and
    /// the frames whose MWIR labels had no solar hour.
    fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        warnings.extend(self.frame_warnings.lines());
        if let Some(m) = self.label_totals.and_then(|l| l.mwir) {
            if m.frames_no_hour > 0 {
                warnings.push(format!(
                    "mwir labels skipped in {} frames: no local solar hour (give --hour, or a \
                     longitude: labels.longitude_deg, --longitude, or a NavSatFix in the log)",
                    m.frames_no_hour
                ));
            }
        }
        warnings
    }
}

/// Reads the frames of `stream` and fuses each through `mapper`, reporting
/// `progress(bytes_read, bytes_total)`.
///
/// Frames are read and decoded on a second thread while this one fuses the previous
/// frame: the order, and so the map, is the log's. A bounded queue keeps at most two
/// decoded frames waiting.
fn fuse_frames(
    mapper: &mut Mapper,
    mut stream: crate::frames::FrameStream,
    input: &Path,
    path_step: f64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(FusedFrames, ReadEnd)> {
    let mut fused = FusedFrames::default();
    let (tx, rx) = std::sync::mpsc::sync_channel(2);
    let read_end = std::thread::scope(|scope| -> Result<ReadEnd> {
        // Owned here, so that an early return drops it and the reader's next send fails.
        let rx = rx;
        let reader = scope.spawn(move || {
            while let Some(item) = stream.next() {
                // The fusing side stopped (an interrupt): stop reading.
                if tx.send((item, stream.progress())).is_err() {
                    break;
                }
            }
            ReadEnd {
                stats: stream.stats().clone(),
                damaged: stream.damaged().to_vec(),
                fatal: stream.fatal_error().map(str::to_string),
            }
        });
        for (item, (done, total)) in rx.iter() {
            crate::interrupt::check("reading the log")?;
            progress(done, total);
            let frame = match item {
                Ok(f) => f,
                Err(e) => {
                    fused.errors.push(e.to_string());
                    continue;
                }
            };
            let t = Instant::now();
            match mapper.update(&frame) {
                Ok(r) => fused.add(&frame, r, path_step),
                Err(e) => fused
                    .errors
                    .push(format!("frame at {:.6} s: {e}", frame.stamp)),
            }
            fused.t_fuse += t.elapsed().as_secs_f64();
        }
        reader.join().map_err(|_| {
            Error::format(
                input,
                "frames",
                "the thread reading the log stopped unexpectedly",
            )
        })
    })?;
    Ok((fused, read_end))
}

/// The error of a build that fused no frame: nothing to map, so it refuses rather than
/// replace a previous map with an empty one. It names the first damage, else the first
/// error, else why frames were skipped.
fn no_frame_built(
    input: &Path,
    log_cfg: &LogConfig,
    summary: &crate::mcap_log::LogSummary,
    stream_stats: &crate::frames::FrameStats,
    damaged: &[crate::mcap_log::DamagedRange],
    errors: &[String],
) -> Error {
    let why = damaged
        .first()
        .map(|d| format!("{}: {d}", input.display()))
        .or_else(|| errors.first().cloned())
        .unwrap_or_else(|| {
            format!(
                "{} messages, {} frames skipped without a transform to {}",
                summary.messages, stream_stats.frames_skipped_no_tf, log_cfg.map_frame
            )
        });
    Error::format(
        input,
        format!("topic {}", log_cfg.frame_topic),
        format!("no frame could be built: {why}"),
    )
}

/// The error of a build whose frames observed no cell, with what became of their points.
fn nothing_observed(input: &Path, log_cfg: &LogConfig, fused: &FusedFrames) -> Error {
    let pts = |p: &IngestStats| {
        format!(
            "{} points, {} fused, {} non-finite, {} outside the window",
            p.points, p.fused, p.nonfinite, p.outside
        )
    };
    Error::format(
        input,
        format!("topic {}", log_cfg.frame_topic),
        format!(
            "nothing built: {} frames read, and no cell observed (lidar: {}; \
             stereo: {})",
            fused.frames_fused,
            pts(&fused.lidar),
            pts(&fused.stereo)
        ),
    )
}

/// Per-frame warnings gathered by kind (the text with its numbers left out), so that a
/// warning repeated in every frame is one line: the first frame's text, with how many
/// frames and which span of time.
#[derive(Default)]
struct FrameWarnings {
    /// Kind → (first text, first and last stamp, frames), in order of first appearance.
    kinds: Vec<(String, String, f64, f64, u64)>,
}

impl FrameWarnings {
    fn kind(w: &str) -> String {
        let mut k = String::with_capacity(w.len());
        let mut in_number = false;
        for c in w.chars() {
            let numeric = c.is_ascii_digit() || (in_number && ".e+-".contains(c));
            if numeric && !in_number {
                k.push('#');
            } else if !numeric {
                k.push(c);
            }
            in_number = numeric;
        }
        k
    }

    fn add(&mut self, stamp: f64, w: &str) {
        let kind = Self::kind(w);
        let full = self.kinds.len() >= MAX_WARNINGS;
        match self.kinds.iter_mut().find(|e| e.0 == kind) {
            Some(e) => {
                e.3 = stamp;
                e.4 += 1;
            }
            None if !full => self.kinds.push((kind, w.to_string(), stamp, stamp, 1)),
            None => {}
        }
    }

    fn lines(&self) -> impl Iterator<Item = String> + '_ {
        self.kinds.iter().map(|(_, w, t0, t1, n)| match n {
            1 => format!("frame at {t0:.6} s: {w}"),
            _ => format!("{n} frames from {t0:.6} s to {t1:.6} s, the first: {w}"),
        })
    }
}

/// Frames of a log's start an offline build reads to measure the sensors' noise, at most.
pub(crate) const CALIBRATION_MAX_FRAMES: usize = 200;

/// Shows the first frames of the log to `mapper` ([`Mapper::calibrate`]) until its
/// calibration is settled, at most [`CALIBRATION_MAX_FRAMES`], and holds what it measured:
/// every build of the log, whole or in time chunks, then fuses every frame with the same
/// noise. Frames that cannot be read are left to the build, which reports them.
pub(crate) fn calibrate_on_log(
    mapper: &mut Mapper,
    input: &Path,
    log_cfg: &LogConfig,
) -> Result<()> {
    let stream = crate::frames::FrameStream::open(input, log_cfg)?;
    for frame in stream.take(CALIBRATION_MAX_FRAMES).flatten() {
        crate::interrupt::check("measuring the sensors' noise")?;
        // A frame the mapper refuses (an implausible pose) is refused again, and reported,
        // when the build reaches it.
        let _ = mapper.calibrate(&frame);
        if mapper.calibration_settled() {
            break;
        }
    }
    mapper.hold_calibration();
    Ok(())
}

/// `cfg` with the sensors the log has no messages of left out (its lidar, stereo cloud,
/// colour, SWIR and MWIR images, on the topics `log` chose): a sensor the log lacks adds
/// nothing to the map, and the report then names only what the log has and what the
/// mapper assumed of it.
pub fn sensors_of_log(
    cfg: &MapperConfig,
    log: &LogConfig,
    summary: &crate::mcap_log::LogSummary,
) -> MapperConfig {
    use crate::project::LabelSensor;
    let has = |t: &str| summary.has_messages(t);
    let mut c = cfg.clone();
    if !has(&log.lidar_topic) {
        c.lidar = None;
    }
    if !has(&log.stereo_topic) {
        c.stereo = None;
    }
    if let Some(l) = &mut c.labels {
        l.sensors.retain(|s| match s {
            LabelSensor::Colour => has(&log.image_topic),
            LabelSensor::Swir => has(&log.swir_topic),
            LabelSensor::Mwir => has(&log.mwir_topic),
        });
        if l.sensors.is_empty() {
            c.labels = None;
            c.label_models = None;
        }
    }
    // Compiled models stand for `labels` or are given alone (a library user's, the bench's).
    if let Some(m) = &mut c.label_models {
        if !has(&log.image_topic) {
            m.colour = None;
        }
        if !has(&log.swir_topic) {
            m.swir = None;
        }
        if !has(&log.mwir_topic) {
            m.mwir = None;
        }
        if m.colour.is_none() && m.swir.is_none() && m.mwir.is_none() {
            c.label_models = None;
        }
    }
    c
}

/// The log settings of a build: [`LogBuildConfig::log`] with its sensor topics chosen
/// ([`LogConfig::with_topics_of`]: named ones, else by message type).
pub fn frame_log_config(
    cfg: &LogBuildConfig,
    summary: &crate::mcap_log::LogSummary,
    input: &Path,
) -> Result<LogConfig> {
    let mut named = cfg.topics.clone();
    if named.frame.is_none() && cfg.log.frame_topic != LogConfig::default().frame_topic {
        named.frame = Some(cfg.log.frame_topic.clone());
    }
    cfg.log.with_topics_of(summary, &named, input)
}

/// The comment lines that mark `map.ply` of a map built from a damaged log: the input, how
/// many ranges were skipped, and the first few of them (`report.json` lists them all).
fn damage_marks(input: &Path, damaged: &[crate::mcap_log::DamagedRange]) -> Vec<String> {
    const SHOWN: usize = 16;
    if damaged.is_empty() {
        return Vec::new();
    }
    let mut v = vec![format!(
        "damaged input: {} had {} damaged range(s), skipped; report.json lists them",
        input.file_name().unwrap_or_default().to_string_lossy(),
        damaged.len()
    )];
    v.extend(
        damaged
            .iter()
            .take(SHOWN)
            .map(|d| format!("damaged bytes {}..{}", d.start_byte, d.end_byte)),
    );
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warning_repeated_in_every_frame_is_one_line() {
        let mut w = FrameWarnings::default();
        for (i, t) in [100.0, 100.2, 100.4].iter().enumerate() {
            w.add(
                *t,
                &format!(
                    "{} stereo points beyond stereo.max_range_m = 132 m dropped (farthest 1.7{i}e2 m)",
                    150 + i
                ),
            );
        }
        w.add(
            100.4,
            "lidar cues cannot run: the scan is unorganized (5 points in one row)",
        );
        let lines: Vec<String> = w.lines().collect();
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert_eq!(
            lines[0],
            "3 frames from 100.000000 s to 100.400000 s, the first: 150 stereo points beyond \
             stereo.max_range_m = 132 m dropped (farthest 1.70e2 m)"
        );
        assert!(lines[1].starts_with("frame at 100.400000 s: lidar cues"));
    }

    /// Compiled label models given without a `[labels]` section (a library user's) label
    /// the log's cameras; only the sensors the log lacks are dropped.
    #[test]
    fn compiled_label_models_alone_keep_the_cameras_the_log_has() {
        use crate::mcap_log::LogSummary;
        use tarn::classify::{ColorLut, RuleClassifier};
        let log = LogConfig::default();
        let summary = |topics: &[&str]| {
            LogSummary::of(
                topics
                    .iter()
                    .map(|t| (t.to_string(), ("schema".to_string(), 3)))
                    .collect(),
                Some(0),
                Some(1),
                Vec::new(),
            )
        };
        let cfg = MapperConfig {
            labels: None,
            label_models: Some(crate::project::FrameLabelConfig {
                colour: Some(ColorLut::compile(&RuleClassifier::default(), 5).unwrap()),
                ..Default::default()
            }),
            ..MapperConfig::default()
        };
        let with = sensors_of_log(&cfg, &log, &summary(&[&log.image_topic]));
        assert!(with.label_models.is_some_and(|m| m.colour.is_some()));
        let without = sensors_of_log(&cfg, &log, &summary(&[&log.lidar_topic]));
        assert!(without.label_models.is_none());
    }
}
