use super::*;

#[test]
fn given_height_is_used_without_estimating() {
    let mut cfg = MapperConfig::default();
    cfg.lidar.as_mut().unwrap().height_m = Some(1.8);
    let m = Mapper::new(cfg).unwrap();
    assert_eq!(m.lidar_height(), Some(1.8));
    let (a, b) = m.diagnostic_interval().unwrap();
    assert!(a > 0.0 && b <= 40.0 + 1e-9 && a < b, "{a} {b}");
}

fn load_str(name: &str, text: &str) -> Result<MapperConfig> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    MapperConfig::load(&p)
}

#[test]
fn bad_configs_name_the_field() {
    let cases = [
        ("[lidar]\ndry_limit_m = -1.0\n", "lidar.dry_limit_m"),
        ("[lidar]\nheight_m = 0.0\n", "lidar.height_m"),
        ("[lidar]\nalbedo = 1.5\n", "lidar.albedo"),
        ("[fusion]\nprior = 1.5\n", "prior"),
        ("[grid]\nresolution = 0.0\n", "resolution"),
        (
            "[vehicle]\nfording_depth_m = -0.1\n",
            "vehicle.fording_depth_m",
        ),
        ("[lidar]\nwavelength = 905.0\n", "wavelength"),
        ("[lidar.cue]\nbelow_gate_m = -1.0\n", "below_gate_m"),
        (
            "[lidar.cue]\nprior_reach_m = 1e9\n",
            "lidar.cue.prior_reach_m",
        ),
        ("[lidar.cue]\nprior_reach_m = nan\n", "prior_reach_m"),
        ("[stereo]\nreflections = false\n", "stereo.mirror_check"),
        ("\n\n[sterio]\n", "sterio"),
    ];
    for (text, field) in cases {
        let e = load_str("m.toml", text).unwrap_err().to_string();
        assert!(e.contains(field), "{text:?}: {e}");
        assert!(e.contains("m.toml"), "{e}");
    }
    // Unknown keys carry their line.
    let e = load_str("m.toml", "\n\n[sterio]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 3"), "{e}");
    let e = load_str("m.json", r#"{"lidar": {"dry_limit_m": "far"}}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 1") && e.contains("m.json"), "{e}");
    let mut c = MapperConfig::default();
    let e = c.set_cues("lidar,sonar").unwrap_err().to_string();
    assert!(e.contains("sonar"), "{e}");
    let mut c = MapperConfig {
        lidar: None,
        ..MapperConfig::default()
    };
    assert!(c
        .set_cues("lidar")
        .unwrap_err()
        .to_string()
        .contains("lidar"));
}

#[test]
fn configs_round_trip_through_toml_and_cue_lists() {
    let mut c = MapperConfig::default();
    c.lidar.as_mut().unwrap().attenuation_per_m = Some(0.6);
    c.lidar.as_mut().unwrap().height_m = Some(1.0);
    c.set_cues("lidar,stereo").unwrap();
    assert_eq!(c.cue_names(), ["lidar", "stereo"]);
    let back = load_str("c.toml", &c.to_toml().unwrap()).unwrap();
    assert_eq!(back, c);
    let json = serde_json::to_string(&c).unwrap();
    assert_eq!(load_str("c.json", &json).unwrap(), c);
    c.set_cues("all").unwrap();
    assert_eq!(c.cue_names(), ["lidar", "reflectivity", "stereo", "mirror"]);
    c.set_cues("none").unwrap();
    assert!(c.cue_names().is_empty());
    // Every section round-trips, labels too.
    let mut every = MapperConfig::every_sensor();
    every.labels.as_mut().unwrap().stride = 3;
    assert_eq!(
        load_str("v.toml", &every.to_toml().unwrap()).unwrap(),
        every
    );
    // The log's and the outputs' sections are the offline builder's, not the vehicle's.
    let err = load_str("l.toml", "[log]\nmap_frame = \"odom\"\n").unwrap_err();
    assert!(err.to_string().contains("log"), "{err}");
}

/// In a config file a sensor whose section is absent is off, in TOML as in JSON: an empty
/// file reads no sensor at all; a section alone turns its sensor on with its defaults.
#[test]
fn an_absent_section_turns_its_sensor_off() {
    let none = MapperConfig {
        lidar: None,
        stereo: None,
        labels: None,
        ..MapperConfig::default()
    };
    assert_eq!(load_str("e.toml", "").unwrap(), none);
    assert_eq!(load_str("e.json", "{}").unwrap(), none);
    assert_eq!(
        load_str(
            "g.toml",
            "[grid]
size_cells = 200
"
        )
        .unwrap()
        .lidar,
        None
    );
    let l = load_str(
        "l.toml", "[lidar]
",
    )
    .unwrap();
    assert_eq!(l.lidar, Some(LidarConfig::default()));
    assert_eq!((l.stereo.is_none(), l.labels.is_none()), (true, true));
    let s = load_str(
        "s.json",
        r#"{"stereo": {}, "labels": {"sensors": ["color"]}}"#,
    )
    .unwrap();
    assert_eq!(s.stereo, Some(StereoConfig::default()));
    assert_eq!(s.lidar, None);
    assert_eq!(
        s.labels.unwrap().sensors,
        [crate::project::LabelSensor::Colour]
    );
    // MWIR labels without an hour take each frame's from its stamp and the longitude; a
    // longitude off the globe is refused and named.
    assert!(load_str("m.toml", "[labels]\nsensors = [\"mwir\"]\n").is_ok());
    let e = load_str(
        "m.toml",
        "[labels]\nsensors = [\"mwir\"]\nlongitude_deg = 200.0\n",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("longitude 200"), "{e}");
}

proptest::proptest! {
    /// The window's centre lies `ahead` of its side in front of the vehicle along its
    /// heading on the ground, whatever the yaw, pitch and roll (short of pointing straight
    /// up), so the vehicle stays inside the window and the cues' lookahead with it.
    #[test]
    fn the_window_lies_ahead_of_the_vehicle(
        x in -1e5f64..1e5, y in -1e5f64..1e5, yaw in -3.2f64..3.2,
        pitch in -1.2f64..1.2, roll in -1.0f64..1.0, ahead in 0.0f64..0.49,
    ) {
        let grid = GridConfig { ahead, ..GridConfig::default() };
        let pose = crate::geom::pose_xyz_rpy(x, y, 5.0, roll, pitch, yaw);
        let (cx, cy) = window_centre(&grid, &pose);
        let side = grid.size_cells as f64 * grid.resolution;
        let d = (cx - x).hypot(cy - y);
        proptest::prop_assert!((d - ahead * side).abs() < 1e-6 * (1.0 + x.abs() + y.abs()));
        if d > 1e-3 {
            let dir = (cy - y).atan2(cx - x);
            let diff = (dir - yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            // Roll (about the vehicle's x) never turns its nose; pitch only tilts it.
            proptest::prop_assert!(diff.abs() < 1e-6, "{} vs {}", dir, yaw);
        }
        // Straight up: no heading on the ground, the vehicle is the centre.
        let up = crate::geom::pose_xyz_rpy(x, y, 0.0, 0.0, -std::f64::consts::FRAC_PI_2, yaw);
        let (ux, uy) = window_centre(&grid, &up);
        proptest::prop_assert!((ux - x).abs() < 1e-6 * (1.0 + x.abs()) && (uy - y).abs() < 1e-6 * (1.0 + y.abs()));
    }
}

#[test]
fn a_bottom_returns_significant_depth_follows_the_lidars_noise() {
    let mut c = MapperConfig::default();
    // Stated, or the noisy end of real lidars when it is not.
    assert_eq!(c.hazard_config().water.min_bottom_depth_m, Some(0.06));
    let l = c.lidar.as_mut().unwrap();
    l.noise = Some(crate::grid::RangeNoise {
        sigma0: 0.015,
        ..crate::grid::RangeNoise::LIDAR
    });
    assert_eq!(c.hazard_config().water.min_bottom_depth_m, Some(0.03));
    c.water.min_bottom_depth_m = Some(0.1);
    assert_eq!(c.hazard_config().water.min_bottom_depth_m, Some(0.1));
    c.water.min_bottom_depth_m = None;
    c.lidar = None;
    assert_eq!(c.hazard_config().water.min_bottom_depth_m, None);
}
