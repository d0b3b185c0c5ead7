//! `tarn info CLOUD`: what a point cloud file holds.

pub fn info(input: &std::path::Path, rings: Option<usize>) -> anyhow::Result<()> {
    let mut cloud = tarn_log::log::read_cloud(input)?;
    if let Some(r) = rings {
        cloud = tarn::io::organize_column_major(&cloud, r)?;
    }
    let n = cloud.len();
    let valid = cloud.valid_count();
    println!("file      {}", input.display());
    if cloud.is_organized() {
        println!(
            "points    {n} ({} rows × {} columns)",
            cloud.rows, cloud.cols
        );
    } else {
        println!("points    {n} (unorganized)");
    }
    let pct = |k: usize| {
        if n == 0 {
            0.0
        } else {
            100.0 * k as f64 / n as f64
        }
    };
    println!(
        "returns   {valid} valid, {} missing ({:.1} %)",
        n - valid,
        pct(n - valid)
    );
    let mut channels = Vec::new();
    for (name, present) in [
        ("intensity", cloud.intensity.is_some()),
        ("reflectivity", cloud.reflectivity.is_some()),
        ("rgb", cloud.rgb.is_some()),
    ] {
        if present {
            channels.push(name);
        }
    }
    if channels.is_empty() {
        channels.push("none");
    }
    println!("channels  {}", channels.join(", "));
    let t = cloud.frame_to_map.translation.vector;
    println!(
        "origin    {:.3} {:.3} {:.3} (cloud frame in map frame)",
        t.x, t.y, t.z
    );
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for i in (0..n).filter(|&i| cloud.is_valid(i)) {
        let p = cloud.point_in_map(i);
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if valid > 0 {
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            println!("{axis} (map)   {:.3} .. {:.3}", lo[k], hi[k]);
        }
    }
    for (name, v) in [
        ("intensity", cloud.intensity.as_deref()),
        ("reflect.", cloud.reflectivity.as_deref()),
    ] {
        if let Some(v) = v {
            let (a, b) = v
                .iter()
                .filter(|x| x.is_finite())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            if a <= b {
                println!("{name: <9} {a} .. {b}");
            }
        }
    }
    Ok(())
}
