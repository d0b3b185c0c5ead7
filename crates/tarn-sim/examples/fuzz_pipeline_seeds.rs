//! Writes the seed inputs of the pipeline fuzz targets (`cloud_build`, `mapper_update`,
//! `exports`) into `fuzz/corpus/<target>/seed-*`, in the byte layouts their entry points in
//! `tarn_sim::fuzzing` decode.
//!
//! `cargo run --example fuzz_pipeline_seeds`

use std::path::Path;

fn put(target: &str, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .join("fuzz/corpus")
        .join(target);
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join(format!("seed-{name}")), bytes)?;
    Ok(())
}

fn f32s(out: &mut Vec<u8>, v: &[f32]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// An organized scan of level ground from a sensor `h` above it: `rows` rings from −3° to
/// −25°, `cols` azimuths over 360°; beams that would hit a pond 8–12 m ahead return
/// nothing.
fn scan(rows: usize, cols: usize, h: f32) -> Vec<[f32; 3]> {
    let mut v = Vec::new();
    for r in 0..rows {
        let el = (-3.0 - 22.0 * r as f32 / (rows - 1).max(1) as f32).to_radians();
        for c in 0..cols {
            let az = (c as f32 / cols as f32 * 360.0).to_radians();
            let d = h / (-el).tan();
            let (x, y) = (d * az.cos(), d * az.sin());
            if (8.0..12.0).contains(&x) && y.abs() < 3.0 {
                v.push([f32::NAN; 3]);
            } else {
                v.push([x, y, -h]);
            }
        }
    }
    v
}

fn main() -> anyhow::Result<()> {
    // cloud_build: a head byte (reader, resolution, window), then the file.
    let corpus = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("fuzz/corpus");
    for (reader, head) in [("ply", 0u8), ("kitti", 1u8)] {
        let mut names: Vec<_> = std::fs::read_dir(corpus.join(reader))?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()?;
        names.sort();
        for p in names.iter().filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("seed-"))
        }) {
            let mut d = vec![head | 0x14];
            d.extend(std::fs::read(p)?);
            let name = p.file_name().unwrap().to_string_lossy();
            put("cloud_build", &format!("{reader}-{}", &name[5..]), &d)?;
        }
    }
    // Raw triples: a 10 m ramp at 0.25 m, and the same with points far away.
    let mut ramp = Vec::new();
    for j in 0..40 {
        for i in 0..40 {
            ramp.push([i as f32 * 0.25, j as f32 * 0.25, 0.05 * i as f32]);
        }
    }
    let mut d = vec![2u8 | 0x24];
    f32s(&mut d, &ramp.concat());
    put("cloud_build", "raw-ramp", &d)?;
    for (name, far) in [
        ("raw-far-1e6", 1e6f32),
        ("raw-far-1e12", 1e12),
        ("raw-far-1e30", -1e30),
    ] {
        let mut d = vec![2u8 | 0x14];
        f32s(&mut d, &ramp[..200].concat());
        f32s(&mut d, &[far, 1.0, 0.0, 1.0, far, 0.0, far, -far, 5.0]);
        put("cloud_build", name, &d)?;
    }

    // mapper_update: a config byte, then frames (stamp step, pose, which clouds, clouds).
    for (name, head, frames) in [
        ("lidar-cues", 0x07u8, 3usize),
        ("lidar-cues-prior", 0x27, 3),
        ("stereo-publish", 0x18, 2),
        ("raw", 0x00, 4),
    ] {
        let mut d = vec![head];
        for f in 0..frames {
            f32s(&mut d, &[0.1, f as f32 * 0.5, 0.0, 1.8, 1.0, 0.0, 0.0, 0.0]);
            d.push(if head & 8 != 0 { 3 } else { 5 });
            let s = scan(16, 48, 1.8);
            d.push(15);
            d.push(47);
            f32s(&mut d, &s.concat());
            if head & 8 != 0 {
                // A stereo cloud in the same frame: the ground and its mirror image below.
                d.push(7);
                d.push(15);
                let mut st = Vec::new();
                for r in 0..8 {
                    for c in 0..16 {
                        let x = 4.0 + r as f32 * 1.5;
                        let z = if (8.0..12.0).contains(&x) { -2.3 } else { -1.8 };
                        st.push([x, c as f32 * 0.3 - 2.4, z]);
                    }
                }
                f32s(&mut d, &st.concat());
            }
        }
        put("mapper_update", name, &d)?;
    }
    // A pose jump, a NaN quaternion and a point at 1e20 m.
    let mut d = vec![0x05u8];
    for (x, q) in [
        (0.0f32, [1.0f32, 0.0, 0.0, 0.0]),
        (1e5, [1.0, 0.0, 0.0, 0.0]),
        (0.5, [f32::NAN, 0.0, 0.0, 0.0]),
    ] {
        f32s(&mut d, &[0.1, x, 0.0, 1.8]);
        f32s(&mut d, &q);
        d.push(1);
        let mut s = scan(4, 12, 1.8);
        s[5] = [1e20, 0.0, -1.8];
        d.push(3);
        d.push(11);
        f32s(&mut d, &s.concat());
    }
    put("mapper_update", "implausible", &d)?;

    // exports: the window's centre, then cells (column, row, height, evidence).
    for (name, cx, cy) in [("pond", 0.0f32, 0.0f32), ("pond-far", 5.0e6, 4.0e6)] {
        let mut d = Vec::new();
        f32s(&mut d, &[cx, cy]);
        for j in 10..40u8 {
            for i in 10..40u8 {
                let (di, dj) = (i as i32 - 25, j as i32 - 25);
                let inside = di * di + dj * dj < 64;
                let z = if inside { -4i8 } else { (i / 8) as i8 };
                let kind = if inside {
                    0x80 | 0x40 | 0x20 | 0x10 | 0x0c
                } else {
                    0
                };
                d.extend_from_slice(&[i, j, z as u8, kind]);
            }
        }
        put("exports", name, &d)?;
    }
    Ok(())
}
