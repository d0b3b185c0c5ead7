//! Writes `maps/default.ply`, the default scene of `tarn` with no arguments until the
//! simulator's scenes replace it: a 24 m × 24 m patch of rolling terrain with a dry
//! depression, a ditch and a mound, sampled at 4 points per 0.1 m cell with 2 cm noise.
//!
//! `cargo run --example demo_cloud` (deterministic: the same file every time).

use std::io::Write;
use std::path::Path;

fn terrain(x: f64, y: f64) -> f64 {
    let hills = 0.4 * (x / 5.0).sin() * (y / 7.0).cos() + 0.02 * x;
    let depression = -0.6 * (-((x - 4.0).powi(2) + (y + 3.0).powi(2)) / 8.0).exp();
    let ditch = if (y - 6.0).abs() < 0.6 {
        -0.35 * (1.0 - ((y - 6.0) / 0.6).powi(2))
    } else {
        0.0
    };
    let mound = 0.5 * (-((x + 6.0).powi(2) + (y + 5.0).powi(2)) / 2.0).exp();
    hills + depression + ditch + mound
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (side, per_cell, res) = (24.0, 4, 0.1);
    let cells = (side / res) as usize;
    let mut pts = Vec::with_capacity(cells * cells * per_cell);
    for _ in 0..cells * cells * per_cell {
        let x = (uniform() - 0.5) * side;
        let y = (uniform() - 0.5) * side;
        // Box–Muller noise, σ = 2 cm.
        let n = (-2.0 * uniform().max(1e-300).ln()).sqrt()
            * (2.0 * std::f64::consts::PI * uniform()).cos();
        pts.push([x as f32, y as f32, (terrain(x, y) + 0.02 * n) as f32]);
    }
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("maps/default.ply");
    tarn::files::write_atomic(&path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment tarn demo terrain (examples/demo_cloud.rs)\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            pts.len()
        )?;
        for p in &pts {
            for v in p {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        Ok(())
    })?;
    println!("wrote {} points to {}", pts.len(), path.display());
    Ok(())
}
