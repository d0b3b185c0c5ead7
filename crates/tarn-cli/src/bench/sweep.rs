//! `tarn bench --sweep`: the knobs that trade speed for error, each setting timed and scored.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use tarn::classify::{ColorLut, Label, RuleClassifier};
use tarn::error::{Error, Result};
use tarn::geom::PointCloud;
use tarn::grid::{GridConfig, RangeNoise, RollingGrid};
use tarn::hazard::HazardMap;
use tarn_log::build::{build_log, LogBuildConfig};
use tarn_log::frames::{FrameStream, LogConfig};
use tarn_sim::sim::synthetic_lidar_cloud;

use super::{median, BenchOptions};

/// One setting of one knob: what it cost and what error it gave.
#[derive(Debug, Clone, Serialize)]
pub struct SweepRow {
    pub knob: String,
    pub value: String,
    /// What was timed.
    pub timed: String,
    /// Median time, ms (`None`: not measured, see `note`).
    pub time_ms: Option<f64>,
    /// What the error is measured against.
    pub error_metric: String,
    pub error: Option<f64>,
    pub note: String,
}

fn row(
    knob: &str,
    value: impl ToString,
    timed: &str,
    time_ms: Option<f64>,
    metric: &str,
    error: Option<f64>,
) -> SweepRow {
    SweepRow {
        knob: knob.into(),
        value: value.to_string(),
        timed: timed.into(),
        time_ms,
        error_metric: metric.into(),
        error,
        note: String::new(),
    }
}

/// Median wall time (ms) of `reps` runs of `f`, and its last result.
fn timed<T>(reps: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut t = Vec::new();
    let mut last = None;
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        last = Some(f()?);
        t.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok((median(&mut t), last.expect("reps >= 1")))
}

/// The analytic surface of [`synthetic_lidar_cloud`] (map frame).
fn synthetic_surface(x: f64, y: f64) -> f64 {
    let r = x.hypot(y);
    0.05 * (r * 0.3).sin() - 1.8
}

/// RMS (m) of the grid's cell elevations against [`synthetic_surface`] at the cell centres,
/// over the observed cells 3–18 m out (inside the synthetic scan's ring).
pub(super) fn synthetic_rms(g: &RollingGrid) -> Option<f64> {
    let (o, n) = (g.origin(), g.size() as i64);
    let (mut s2, mut cnt) = (0.0, 0usize);
    for ky in o.y..o.y + n {
        for kx in o.x..o.x + n {
            let k = tarn::grid::CellKey::new(kx, ky);
            let (cx, cy) = g.centre_of(k);
            let r = cx.hypot(cy);
            if !(3.0..=18.0).contains(&r) {
                continue;
            }
            if let Some(m) = g.cell(k).and_then(|c| c.mean_mm()) {
                let z = g.config().z_ref + m * 1e-3;
                s2 += (z - synthetic_surface(cx, cy)).powi(2);
                cnt += 1;
            }
        }
    }
    (cnt > 0).then(|| (s2 / cnt as f64).sqrt())
}

/// Sweeps the knobs that trade speed for error (see README "Speed against error").
pub fn sweep(opts: &BenchOptions) -> Result<Vec<SweepRow>> {
    let reps = opts.reps.max(1);
    let mut rows = Vec::new();
    let tmp = tempfile::tempdir().map_err(|e| Error::io("temporary directory", e))?;

    let sim_dir = tmp.path().join("sim");
    let scene = tarn_sim::sim::Scene::load_with_rig(&opts.scene, opts.rig.as_deref())?;
    tarn_sim::sim::simulate(&scene, &sim_dir, tarn_sim::sim::SimOptions::default())?;
    let sim = Simulated {
        scene: &scene,
        dir: &sim_dir,
        log: sim_dir.join("log.mcap"),
        tmp: tmp.path(),
    };
    sweep_resolution(opts, &sim, reps, &mut rows)?;
    sweep_subsampling(opts, reps, &mut rows)?;
    sweep_lut_bits(reps, &mut rows)?;
    sweep_label_projection(&sim, &mut rows)?;
    sweep_surface_interpolation(opts, tmp.path(), reps, &mut rows)?;
    let mut r = row(
        "water surface interpolation",
        "natural neighbour",
        "–",
        None,
        "–",
        None,
    );
    r.note = "not offered: spade interpolates natural neighbours only on unconstrained \
              triangulations, and the shore constraints are kept"
        .into();
    rows.push(r);
    let mut r = row("mixture components", "–", "–", None, "–", None);
    r.note =
        "measured on the real RELLIS-3D frame: cargo run --release --example rellis_eval".into();
    rows.push(r);
    Ok(rows)
}

/// The simulated scene the sweeps build maps of: its log and truth in `dir`, and a
/// temporary directory for their outputs.
struct Simulated<'a> {
    scene: &'a tarn_sim::sim::Scene,
    dir: &'a Path,
    log: PathBuf,
    tmp: &'a Path,
}

/// Grid resolution on the simulated scene, scored by `tarn eval` against its truth.
fn sweep_resolution(
    opts: &BenchOptions,
    sim: &Simulated,
    reps: usize,
    rows: &mut Vec<SweepRow>,
) -> Result<()> {
    let (scene, sim_dir, log, tmp) = (sim.scene, sim.dir, sim.log.as_path(), sim.tmp);
    for res in [0.05, 0.1, 0.2, 0.4] {
        let out = tmp.join(format!("res{res}"));
        let mut mapper = scene.rig.mapper_config();
        mapper.grid = GridConfig {
            resolution: res,
            size_cells: ((40.0 / res).round() as usize).max(2),
            ..opts.grid.clone()
        };
        let cfg = LogBuildConfig {
            mapper,
            ..LogBuildConfig::default()
        };
        let (ms, _) = timed(reps.min(3), || build_log(log, &out, &cfg, &mut |_, _| {}))?;
        let e = tarn_sim::eval::evaluate_dirs(&out, sim_dir)?;
        rows.push(row(
            "grid resolution (m)",
            res,
            "build_log, whole default scene",
            Some(ms),
            "terrain RMS vs simulator truth (m)",
            e.all.terrain_rms_m,
        ));
    }
    Ok(())
}

/// Point subsampling on a synthetic lidar-like cloud against its analytic surface.
fn sweep_subsampling(opts: &BenchOptions, reps: usize, rows: &mut Vec<SweepRow>) -> Result<()> {
    let cloud = synthetic_lidar_cloud(opts.ingest_points, 7);
    for keep_every in [1usize, 2, 4, 8, 16] {
        let sub = PointCloud::unorganized(cloud.xyz.iter().step_by(keep_every).copied().collect());
        let mut g = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
        let (ms, _) = timed(reps, || {
            g = RollingGrid::new(opts.grid.clone(), 0.0, 0.0)?;
            g.ingest(&sub, &RangeNoise::LIDAR)
        })?;
        rows.push(row(
            "point subsampling (keep 1 in k)",
            keep_every,
            &format!("ingest of {} points into a fresh grid", sub.len()),
            Some(ms),
            "cell RMS vs analytic surface, 3–18 m (m)",
            synthetic_rms(&g),
        ));
    }
    Ok(())
}

/// Lookup-table size against the exact Table-1 rule it tabulates.
fn sweep_lut_bits(reps: usize, rows: &mut Vec<SweepRow>) -> Result<()> {
    let rule = RuleClassifier::default();
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let rgb: Vec<u8> = (0..640 * 480 * 3)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 56) as u8
        })
        .collect();
    let exact: Vec<Label> = rgb
        .chunks_exact(3)
        .map(|p| rule.classify_pixel([p[0], p[1], p[2]]))
        .collect();
    let mut out = vec![Label::Other; 640 * 480];
    for bits in 3u8..=8 {
        let lut = ColorLut::compile(&rule, bits)?;
        let (ms, _) = timed(reps, || lut.classify_into(&rgb, &mut out))?;
        let wrong = out.iter().zip(&exact).filter(|(a, b)| a != b).count();
        rows.push(row(
            "lookup-table bits per channel",
            bits,
            "classify 640×480 uniform-random RGB, one thread",
            Some(ms),
            "pixels labelled unlike the exact rule (fraction)",
            Some(wrong as f64 / exact.len() as f64),
        ));
    }
    Ok(())
}

/// Label projection: every `stride`-th pixel in x and y is classified and placed on the
/// map (the rest fill the quads between agreeing samples), and with `wide_rows` every row
/// whose ground footprint is wider than a cell too. Colour labels by the Table 1 rule on
/// the default scene with the main job's 80 m window; the error is the water the map
/// misses.
fn sweep_label_projection(sim: &Simulated, rows: &mut Vec<SweepRow>) -> Result<()> {
    let (scene, sim_dir, log, tmp) = (sim.scene, sim.dir, sim.log.as_path(), sim.tmp);
    let mut label_runs = Vec::new();
    for (stride, wide_rows) in [
        (1usize, false),
        (2, false),
        (4, false),
        (8, false),
        (2, true),
    ] {
        let out = tmp.join(format!("stride{stride}-{wide_rows}"));
        let mut mapper = scene.rig.mapper_config();
        mapper.grid.size_cells = 800;
        mapper.label_models = Some(tarn::project::FrameLabelConfig {
            colour: Some(ColorLut::compile(&RuleClassifier::default(), 8)?),
            ray_stride: stride,
            wide_rows,
            ..tarn::project::FrameLabelConfig::default()
        });
        let cfg = LogBuildConfig {
            mapper,
            ..LogBuildConfig::default()
        };
        let (_, rep) = timed(1, || build_log(log, &out, &cfg, &mut |_, _| {}))?;
        let e = tarn_sim::eval::evaluate_dirs(&out, sim_dir)?;
        let labels_ms = rep
            .stage_latency_ms
            .iter()
            .find(|l| l.stage == "labels")
            .map(|l| l.median_ms);
        label_runs.push((
            stride,
            wide_rows,
            labels_ms,
            e.all.water_recall.map(|r| 1.0 - r),
        ));
    }
    let label_row = |knob: &str, value: String, &(_, _, ms, missed): &(usize, bool, _, _)| {
        row(
            knob,
            value,
            "labels stage per frame (median), default scene",
            ms,
            "water cells missed (1 − recall, all ranges)",
            missed,
        )
    };
    for r in label_runs.iter().filter(|r| !r.1) {
        rows.push(label_row(
            "label ray-cast stride (pixels)",
            r.0.to_string(),
            r,
        ));
    }
    for r in label_runs.iter().filter(|r| r.0 == 2) {
        let value = if r.1 { "all" } else { "every 2nd" };
        rows.push(label_row(
            "label rows wider than a cell (stride 2)",
            value.into(),
            r,
        ));
    }
    Ok(())
}

/// Water surface interpolation on the stream scene (a surface that is not level): the
/// same fused tile map, its water bodies given a level plane or the constrained Delaunay
/// surface with barycentric interpolation; error against the true water surface.
fn sweep_surface_interpolation(
    opts: &BenchOptions,
    tmp: &Path,
    reps: usize,
    rows: &mut Vec<SweepRow>,
) -> Result<()> {
    let stream = tarn_sim::sim::Scene::load(&opts.scene.with_file_name("stream_slope.toml"))?;
    let stream_dir = tmp.join("stream");
    tarn_sim::sim::simulate(&stream, &stream_dir, tarn_sim::sim::SimOptions::default())?;
    let mut mapper = tarn::mapper::Mapper::new(stream.rig.mapper_config())?;
    for f in FrameStream::open(stream_dir.join("log.mcap"), &LogConfig::default())? {
        mapper.update(&f?)?;
    }
    let tiles = mapper.finish();
    // The Delaunay surface (barycentric) with its vertices as measured ("raw") and at the
    // median of their 1.5 m of shore (the default).
    let default_radius = tarn::water::WaterConfig::default().vertex_median_radius_m;
    for (i, (name, level_residual_m, vertex_median_radius_m)) in [
        ("level plane", 1e9, default_radius),
        ("Delaunay, raw", 0.0, 0.0),
        ("Delaunay, medians", 0.0, default_radius),
    ]
    .into_iter()
    .enumerate()
    {
        let mut hc = stream.rig.mapper_config().hazard_config();
        hc.water.level_residual_m = level_residual_m;
        hc.water.vertex_median_radius_m = vertex_median_radius_m;
        let (ms, map) = timed(reps, || HazardMap::from_tiles(&tiles, &hc))?;
        let out = tmp.join(format!("surface-{i}"));
        tarn::io::write_map_files(&out, &map)?;
        let e = tarn_sim::eval::evaluate_dirs(&out, &stream_dir)?;
        rows.push(row(
            "water surface interpolation",
            name,
            "water bodies and hazards of the stream scene's map",
            Some(ms),
            "water surface RMS vs simulator truth (m)",
            e.all.surface_rms_m,
        ));
    }
    Ok(())
}

/// The sweep as a Markdown table.
pub fn sweep_markdown(rows: &[SweepRow]) -> String {
    let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
    let mut s = String::from(
        "| knob | value | time (ms) | timed | error | error metric |\n| --- | ---: | ---: | --- | ---: | --- |\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            r.knob,
            r.value,
            f(r.time_ms, 3),
            if r.note.is_empty() { &r.timed } else { &r.note },
            f(r.error, 5),
            r.error_metric
        ));
    }
    s
}

/// Error against time, one panel per measured knob (log-scaled time).
pub fn sweep_plot(rows: &[SweepRow], path: &Path) -> Result<()> {
    use plotters::prelude::*;
    static FONT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let font_ok = *FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if !font_ok {
        return Err(Error::invalid(
            "sweep plot",
            "the embedded DejaVu Sans font did not load",
        ));
    }
    let knobs: Vec<&str> = {
        let mut k: Vec<&str> = rows
            .iter()
            .filter(|r| r.time_ms.is_some() && r.error.is_some())
            .map(|r| r.knob.as_str())
            .collect();
        k.dedup();
        k
    };
    let err = |e: Box<dyn std::error::Error>| Error::invalid("sweep plot", e.to_string());
    // Three significant digits, no trailing zeros.
    let short = |v: f64| {
        let d = (2 - v.abs().max(1e-9).log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.d$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    // Room for each knob's caption.
    let (w, h) = (320 * knobs.len().max(1) as u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(Box::new(e)))?;
        let panels = root.split_evenly((1, knobs.len().max(1)));
        for (knob, area) in knobs.iter().zip(panels.iter()) {
            let pts: Vec<(f64, f64, String)> = rows
                .iter()
                .filter(|r| r.knob == *knob)
                .filter_map(|r| Some((r.time_ms?, r.error?, r.value.clone())))
                .collect();
            let (t0, t1) = pts
                .iter()
                .fold((f64::INFINITY, 0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let e1 = pts.iter().fold(0f64, |a, p| a.max(p.1));
            let metric = rows
                .iter()
                .find(|r| r.knob == *knob)
                .map(|r| r.error_metric.clone());
            let mut chart = ChartBuilder::on(area)
                .caption(*knob, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d((t0 * 0.7..t1 * 2.5).log_scale(), 0.0..e1 * 1.15 + 1e-9)
                .map_err(|e| err(Box::new(e)))?;
            // A few labels on the log axis (its default key points crowd a decade with
            // labels that overlap); each point says its own time.
            chart
                .configure_mesh()
                .x_labels(6)
                .x_label_formatter(&|v| short(*v))
                .x_desc("time (ms, log)")
                .y_desc(metric.unwrap_or_default())
                .label_style(("sans-serif", 12))
                .draw()
                .map_err(|e| err(Box::new(e)))?;
            chart
                .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), &BLUE))
                .map_err(|e| err(Box::new(e)))?;
            chart
                .draw_series(pts.iter().map(|p| {
                    EmptyElement::at((p.0, p.1))
                        + Circle::new((0, 0), 4, BLUE.filled())
                        + Text::new(
                            format!("{} ({} ms)", p.2, short(p.0)),
                            (6, -14),
                            ("sans-serif", 13),
                        )
                }))
                .map_err(|e| err(Box::new(e)))?;
        }
        root.present().map_err(|e| err(Box::new(e)))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| Error::invalid("sweep plot", "buffer size"))?;
    img.save(path)
        .map_err(|e| Error::invalid(format!("sweep plot {}", path.display()), e.to_string()))
}
