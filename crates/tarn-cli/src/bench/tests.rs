use super::sweep::synthetic_rms;
use super::*;

#[test]
fn median_of_odd_and_even_samples() {
    assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
    assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
    assert!(median(&mut []).is_nan());
}

#[test]
fn bench_on_the_default_scene_reports_every_required_field() {
    let opts = BenchOptions {
        reps: 1,
        ingest_points: 50_000,
        ..BenchOptions::default()
    };
    let r = run(&opts).unwrap();
    // The default scene has a colour camera: its labels are part of the full frame.
    assert!(
        r.frame_ms_method.contains("colour labels"),
        "{}",
        r.frame_ms_method
    );
    for s in [
        "ingest_lidar",
        "cue_lidar",
        "classify_640x480",
        "labels_colour",
        "water_window",
        "export_map (whole map)",
    ] {
        let v = r.stages_ms[s];
        assert!(v.is_finite() && v > 0.0, "{s}: {v}");
    }
    assert!(r.frame_stages.iter().all(|s| r.stages_ms.contains_key(s)));
    // The mapper's own stages, with the rig's cues and labels all running.
    for s in ["lidar", "stereo", "labels", "water"] {
        let v = r.frame_stages_ms[s];
        assert!(v.is_finite() && v > 0.0 && v < r.frame_ms, "{s}: {v}");
    }
    assert!(r.stages_ms["cue_stereo"] > 0.0);
    assert!(r.frame_ms.is_finite() && r.frame_ms > 0.0, "{}", r.frame_ms);
    assert!(r.ingest_points_per_s > 0.0 && r.offline_x_realtime > 0.0);
    assert!(r.offline_over_bare.is_finite() && r.offline_over_bare > 0.0);
    assert!((r.offline_over_bare - r.offline_build_s / r.offline_bare_build_s).abs() < 1e-12);
    // CPU time over wall time: some of a core at least, never more than the machine's
    // cores (and a little for the clocks' granularity).
    let cores = std::thread::available_parallelism().map_or(r.threads, |n| n.get());
    #[cfg(unix)]
    assert!(r
        .offline_cores_busy
        .is_some_and(|c| c > 0.0 && c <= cores as f64 + 0.25));
    assert!(r
        .markdown()
        .contains("cores kept busy by the offline build"));
    assert!(r.log_duration_s > 0.0);
    assert_eq!(r.bytes_per_cell, RollingGrid::bytes_per_cell());
    // Every per-cell allocation counts: at least the layers, and the owners add up.
    assert!(r.bytes_per_cell_all >= r.bytes_per_cell as f64);
    let owners: f64 = r.bytes_per_cell_by_owner.values().sum();
    assert!((owners - r.bytes_per_cell_all).abs() < 1e-6);
    assert!(r.ingest_vs_plain_scan.is_some_and(|v| v > 0.0));
    assert!(r.ingest_vs_plain_dense > 0.0);
    assert!(r.frame_lidar_shape.is_some_and(|(rows, _)| rows > 1));
    // A drive changes some of the window's records every frame, not all, and the
    // neighbours of the changed ones add to them.
    let (c, b) = (
        r.snapshot_cells_changed.unwrap(),
        r.snapshot_cells_changed_or_beside.unwrap(),
    );
    assert!(c > 0.0 && c < 1.0 && b >= c && b <= 1.0, "{c} {b}");
    #[cfg(unix)]
    assert!(r.page_faults_per_frame.is_some() && r.page_faults_per_frame_build.is_some());
    let json = serde_json::to_value(&r).unwrap();
    for k in [
        "ingest_points_per_s",
        "frame_ms",
        "frame_ms_method",
        "classify_ms_640x480",
        "offline_x_realtime",
        "offline_over_bare",
        "peak_memory_bytes",
        "bytes_per_cell",
        "stages_ms",
    ] {
        assert!(json.get(k).is_some_and(|v| !v.is_null()), "{k} missing");
    }
}

#[test]
fn synthetic_cloud_builds_match_their_analytic_surface() {
    let c = synthetic_lidar_cloud(200_000, 3);
    let mut g = RollingGrid::new(GridConfig::default(), 0.0, 0.0).unwrap();
    g.ingest(&c, &RangeNoise::LIDAR).unwrap();
    // 2 cm uniform noise (σ 5.8 mm) averaged over a few points per cell, plus the
    // surface's variation across a 0.1 m cell: well under a centimetre.
    let rms = synthetic_rms(&g).unwrap();
    assert!(rms < 0.01, "{rms}");
    let b = cloud_build(100_000, 20.0).unwrap();
    assert_eq!(b.points, 100_000);
    assert!(b.cells_observed > 30_000 && b.cells_observed <= 40_401);
}

#[test]
fn minor_faults_grow_with_fresh_pages() {
    let Some(before) = minor_faults() else { return };
    let v = vec![1u8; 64 << 20];
    assert!(v.iter().all(|&b| b == 1));
    let after = minor_faults().unwrap();
    // 64 MiB, above the allocator's largest mmap threshold: always fresh pages.
    assert!(after > before, "{before} -> {after}");
}

#[test]
fn peak_memory_grows_with_a_touched_allocation() {
    let before = peak_memory_bytes().unwrap();
    let v = vec![1u8; 64 << 20];
    let after = peak_memory_bytes().unwrap();
    assert!(v.iter().all(|&b| b == 1));
    assert!(after >= before.max(64 << 20), "{before} -> {after}");
}
