//! The bench report as Markdown: the stage table, the headline numbers and the targets.

use super::BenchReport;

impl BenchReport {
    /// A Markdown table of the stages and the headline numbers.
    pub fn markdown(&self) -> String {
        let mut s = String::from("| stage | median ms |\n| --- | ---: |\n");
        for (k, v) in &self.stages_ms {
            s.push_str(&format!("| {k} | {v:.3} |\n"));
        }
        s.push_str("\n| stage of `Mapper::update` | median ms |\n| --- | ---: |\n");
        for (k, v) in &self.frame_stages_ms {
            s.push_str(&format!("| {k} | {v:.3} |\n"));
        }
        s.push_str(&format!(
            "\nframe {:.2} ms ({}), ingest {:.1} M points/s, classify 640×480 {:.3} ms, \
             offline {:.1}× real time, peak memory {} MiB, {} bytes per cell, {} threads, {} reps\n",
            self.frame_ms,
            self.frame_ms_method,
            self.ingest_points_per_s / 1e6,
            self.classify_ms_640x480,
            self.offline_x_realtime,
            self.peak_memory_bytes.map_or("?".into(), |b| (b >> 20).to_string()),
            self.bytes_per_cell,
            self.threads,
            self.reps,
        ));
        let f = |v: Option<f64>, scale: f64, d: usize| {
            v.map_or("–".to_string(), |v| format!("{:.d$}", v / scale))
        };
        s.push_str(&format!(
            "one thread, M points/s: ingest of the frame's {} scan {} (plain binning {}, ratio {}); \
             dense batch {:.1} (plain {:.1}, ratio {:.2})\n\
             page faults per frame {} (steady state), {} (whole online build); \
             {:.1} bytes per window cell over all per-cell allocations\n\
             snapshot cells changed per frame {} %, or beside a changed one {} %\n",
            self.frame_lidar_shape
                .map_or("–".into(), |(r, c)| format!("{r}×{c}")),
            f(self.ingest_scan_points_per_s_1t, 1e6, 1),
            f(self.plain_scan_points_per_s_1t, 1e6, 1),
            f(self.ingest_vs_plain_scan, 1.0, 2),
            self.ingest_dense_points_per_s_1t / 1e6,
            self.plain_dense_points_per_s_1t / 1e6,
            self.ingest_vs_plain_dense,
            f(self.page_faults_per_frame, 1.0, 0),
            f(self.page_faults_per_frame_build, 1.0, 0),
            self.bytes_per_cell_all,
            f(self.snapshot_cells_changed, 0.01, 1),
            f(self.snapshot_cells_changed_or_beside, 0.01, 1),
        ));
        s.push_str(&self.targets_markdown());
        s
    }

    /// The ratios the speed targets are stated in, each beside its target, all from this
    /// run.
    pub fn targets_markdown(&self) -> String {
        let f = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
        let rows = [
            (
                "offline build / the same log with `--cues none --labels none`",
                format!(
                    "{} ({:.2} s / {:.2} s)",
                    f(Some(self.offline_over_bare), 2),
                    self.offline_build_s,
                    self.offline_bare_build_s
                ),
                "≤ 2.0",
            ),
            (
                "ingest of the frame's scan, one thread / plain binning",
                f(self.ingest_vs_plain_scan, 2),
                "≥ 0.5",
            ),
            (
                "cores kept busy by the offline build",
                format!("{} of {}", f(self.offline_cores_busy, 2), self.threads),
                "≥ 1.8 of 2",
            ),
            (
                "bytes per window cell, every per-cell allocation",
                format!("{:.0}", self.bytes_per_cell_all),
                "≤ 64",
            ),
        ];
        let mut s = String::from("\n| ratio (this run) | value | target |\n| --- | ---: | --- |\n");
        for (what, v, target) in rows {
            s.push_str(&format!("| {what} | {v} | {target} |\n"));
        }
        s
    }
}
