//! The real RELLIS-3D Ouster scan (../shared/data, test-only licence) through the mapper as
//! `tarn build` runs it with nothing stated: its calibration section gives the lidar's range
//! noise and intensity law measured from the scan, and the lidar's height, and says that
//! nothing was assumed for them.

use std::path::Path;

use tarn::calib::Source;
use tarn::geom::Pose;
use tarn::mapper::{Mapper, MapperConfig};
use tarn::sensor::Frame;

const DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/rellis3d-puddle-frame/"
);

#[test]
fn rellis_calibration_is_measured_from_the_scan() {
    if !Path::new(DIR)
        .join("frame000104-1581624663_170.ply")
        .exists()
    {
        eprintln!("skipped: {DIR} is absent (shared test data, kept beside the repository)");
        return;
    }
    let raw = tarn::io::read_ply(Path::new(&format!("{DIR}frame000104-1581624663_170.ply")))
        .expect("RELLIS-3D PLY");
    let cloud = tarn::io::organize_column_major(&raw, 64).unwrap();
    let cfg = MapperConfig {
        stereo: None,
        ..Default::default()
    };
    let mut m = Mapper::new(cfg).unwrap();
    m.set_publish(false);
    let frame = Frame {
        stamp: 0.0,
        base_to_map: Pose::identity(),
        lidar: Some(cloud),
        stereo: None,
        image: None,
        swir: None,
        mwir: None,
        stereo_baseline_m: None,
        geo: None,
    };
    m.update(&frame).unwrap();
    let cal = m.calibration();
    eprintln!("{}", serde_json::to_string_pretty(cal).unwrap());
    assert!(cal.stereo.is_none());
    let l = cal.lidar.as_ref().unwrap();
    let noise = l
        .measured
        .expect("range noise measured from one scan")
        .noise;
    // An OS1-64's datasheet precision is 1–5 cm; grass and gravel add their roughness.
    assert!((0.003..0.1).contains(&noise.sigma(10.0)), "{noise:?}");
    assert_eq!(l.used_sigma0_m.unwrap().source, Source::Measured);
    assert_eq!(l.stated_sigma0_m, None);
    let h = l.height_m.unwrap();
    assert_eq!(h.source, Source::Measured);
    assert!((0.5..3.0).contains(&h.value), "{h:?}");
    // The Ouster's `reflectivity` is range-compensated: it falls only with incidence.
    let law = l
        .intensity_law
        .as_ref()
        .expect("intensity law of the scan's ground");
    assert_eq!(law.channel, "reflectivity");
    assert!(law.range_compensated, "{law:?}");
    assert!(cal.warnings.is_empty(), "{:?}", cal.warnings);
}
