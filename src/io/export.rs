//! The export contract (DESIGN.md, "Map export"): `map.ply`, `terrain.ply`, `map.png`,
//! `report.json`. Every file is written to a temporary name beside its destination and
//! renamed into place only when complete, so a reader never sees a partial file.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use image::{Rgb, RgbImage};

use crate::error::{Error, Result};
use crate::grid::CellKey;
use crate::hazard::{Class, HazardMap, MapCell};

/// Writes `path` through `body` atomically: a temporary file in the same directory, renamed
/// over `path` only after `body` succeeded and the data reached the disk.
pub fn write_atomic(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<&mut File>) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".tarn-").suffix(".partial");
    // Outputs are ordinary files (tempfile's default is owner-only).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        body(&mut w).map_err(|e| Error::io(path, e))?;
        w.flush().map_err(|e| Error::io(path, e))?;
    }
    tmp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        w.write_all(b"\n")
    })
}

/// `map.ply`: binary little-endian, one vertex per observed cell, the contract's schema.
/// The offset written as `comment origin X Y 0` into `map.ply` and `terrain.ply` when the
/// map lies far from the map frame's origin (UTM-like coordinates): `float` holds 0.5 m
/// steps at 5,000 km, so vertices are then stored relative to this origin (whole metres,
/// the centre of the map's extent) and readers add it back ([`crate::io::ply`] and
/// [`crate::io::mapfile`] do). `[0, 0]` — and no comment line — when every cell centre lies
/// within [`crate::io::ply::FAR_FROM_ORIGIN_M`] of the origin, as in every simulated scene.
pub fn map_origin(map: &HazardMap) -> [f64; 2] {
    let far = crate::io::ply::FAR_FROM_ORIGIN_M;
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for c in &map.cells {
        lo = [lo[0].min(c.x), lo[1].min(c.y)];
        hi = [hi[0].max(c.x), hi[1].max(c.y)];
    }
    if map.cells.is_empty() || (0..2).all(|i| lo[i] >= -far && hi[i] <= far) {
        return [0.0; 2];
    }
    [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])].map(f64::round)
}

fn origin_comment(o: [f64; 2]) -> String {
    if o == [0.0; 2] {
        String::new()
    } else {
        format!("comment origin {} {} 0\n", o[0], o[1])
    }
}

pub fn write_map_ply(path: &Path, map: &HazardMap) -> Result<()> {
    let o = map_origin(map);
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment tarn map: one vertex per observed cell\n\
             comment class 0 unknown 1 ground 2 water 3 vegetation 4 obstacle 5 snow/ice\n\
             comment hazard 0 free 1 shallow water 2 deep or unknown-depth water 3 obstacle\n\
             comment resolution {}\n{}element vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property float elevation_std\nproperty float water\nproperty float depth\n\
             property uchar class\nproperty uchar hazard\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
            map.resolution,
            origin_comment(o),
            map.cells.len()
        )?;
        let mut rec = [0u8; 29];
        for c in &map.cells {
            let f = [
                (c.x - o[0]) as f32,
                (c.y - o[1]) as f32,
                c.z as f32,
                c.elevation_std as f32,
                c.water,
                c.depth,
            ];
            for (j, v) in f.iter().enumerate() {
                rec[4 * j..4 * j + 4].copy_from_slice(&v.to_le_bytes());
            }
            let [r, g, b] = c.class.colour();
            rec[24..29].copy_from_slice(&[c.class as u8, c.hazard as u8, r, g, b]);
            w.write_all(&rec)?;
        }
        Ok(())
    })
}

/// Triangles of the terrain mesh over observed cells: each 2×2 block of cells gives two
/// triangles when all four are observed, one when three are, none otherwise, so no
/// triangle ever spans an unknown cell. Counter-clockwise seen from above (normals up).
pub fn terrain_triangles(map: &HazardMap) -> Vec<[u32; 3]> {
    let index: HashMap<CellKey, u32> = map
        .cells
        .iter()
        .enumerate()
        .map(|(i, c)| (c.key, i as u32))
        .collect();
    let mut tris = Vec::new();
    for c in &map.cells {
        let k = c.key;
        let at = |dx, dy| index.get(&CellKey::new(k.x + dx, k.y + dy)).copied();
        // The block whose lower-left corner is this cell...
        let (a, b, cc, d) = (at(0, 0), at(1, 0), at(1, 1), at(0, 1));
        // ...and the block whose lower-left corner is missing while this cell is its
        // lower-right one (no observed cell would visit it otherwise).
        if let (None, Some(b), Some(c), Some(d)) = (at(-1, 0), at(0, 0), at(0, 1), at(-1, 1)) {
            tris.push([b, c, d]);
        }
        match (a, b, cc, d) {
            (Some(a), Some(b), Some(c), Some(d)) => {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
            (Some(a), Some(b), Some(c), None) => tris.push([a, b, c]),
            (Some(a), Some(b), None, Some(d)) => tris.push([a, b, d]),
            (Some(a), None, Some(c), Some(d)) => tris.push([a, c, d]),
            _ => {}
        }
    }
    tris
}

/// Writes a binary PLY triangle mesh with per-vertex colours and class.
pub fn write_mesh_ply(
    path: &Path,
    comment: &str,
    vertices: &[([f32; 3], [u8; 3], u8)],
    triangles: &[[u32; 3]],
) -> Result<()> {
    if let Some(bad) = triangles
        .iter()
        .flatten()
        .find(|&&i| i as usize >= vertices.len())
    {
        return Err(Error::invalid(
            "mesh",
            format!("triangle index {bad} beyond {} vertices", vertices.len()),
        ));
    }
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar class\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            vertices.len(),
            triangles.len()
        )?;
        for (p, rgb, class) in vertices {
            for v in p {
                w.write_all(&v.to_le_bytes())?;
            }
            w.write_all(rgb)?;
            w.write_all(&[*class])?;
        }
        for t in triangles {
            w.write_all(&[3])?;
            for &i in t {
                w.write_all(&(i as i32).to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// `terrain.ply`: the terrain surface over observed cells, coloured by class.
pub fn write_terrain_ply(path: &Path, map: &HazardMap) -> Result<()> {
    let o = map_origin(map);
    let verts: Vec<_> = map
        .cells
        .iter()
        .map(|c| {
            (
                [(c.x - o[0]) as f32, (c.y - o[1]) as f32, c.z as f32],
                c.class.colour(),
                c.class as u8,
            )
        })
        .collect();
    let comment = format!("tarn terrain surface\n{}", origin_comment(o));
    write_mesh_ply(path, comment.trim_end(), &verts, &terrain_triangles(map))
}

/// Draws `text` with the 8×8 font at `(x, y)`, `scale` pixels per font pixel.
fn draw_text(img: &mut RgbImage, x: u32, y: u32, text: &str, scale: u32, colour: [u8; 3]) {
    use font8x8::UnicodeFonts;
    for (ci, ch) in text.chars().enumerate() {
        let Some(glyph) = font8x8::BASIC_FONTS.get(ch) else {
            continue;
        };
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8u32 {
                if bits & (1 << col) != 0 {
                    for sy in 0..scale {
                        for sx in 0..scale {
                            let px = x + (ci as u32 * 8 + col) * scale + sx;
                            let py = y + row as u32 * scale + sy;
                            if px < img.width() && py < img.height() {
                                img.put_pixel(px, py, Rgb(colour));
                            }
                        }
                    }
                }
            }
        }
    }
}

fn fill_rect(img: &mut RgbImage, x: u32, y: u32, w: u32, h: u32, colour: [u8; 3]) {
    for py in y..(y + h).min(img.height()) {
        for px in x..(x + w).min(img.width()) {
            img.put_pixel(px, py, Rgb(colour));
        }
    }
}

/// The largest "nice" length (1, 2 or 5 × 10^k metres) not longer than `max_m`.
fn nice_length(max_m: f64) -> f64 {
    let p = 10f64.powf(max_m.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&l| l <= max_m)
        .unwrap_or(p)
}

/// Renders the map top-down: +x to the right, +y up. Classes in their colours, shaded by a
/// hillshade of the elevation (light from the upper left); hazards outlined; a legend and a
/// scale bar below the map.
pub fn render_map_png(map: &HazardMap) -> RgbImage {
    const BG: [u8; 3] = [24, 24, 28];
    let Some((lo, hi)) = map.key_bounds() else {
        let mut img = RgbImage::from_pixel(320, 60, Rgb(BG));
        draw_text(&mut img, 10, 25, "no observed cells", 1, [220, 220, 220]);
        return img;
    };
    let (wc, hc) = ((hi.x - lo.x + 1) as u32, (hi.y - lo.y + 1) as u32);
    let s = (900 / wc.max(hc)).clamp(1, 8);
    let (mw, mh) = (wc * s, hc * s);
    let legend_h = 64;
    let width = mw.max(560);
    let mut img = RgbImage::from_pixel(width, mh + legend_h, Rgb(BG));

    let elev: HashMap<CellKey, f64> = map.cells.iter().map(|c| (c.key, c.z)).collect();
    let res = map.resolution;
    let (zlo, zhi) = elevation_range(&map.cells).unwrap_or((0.0, 1.0));
    let zspan = (zhi - zlo).max(1e-6);
    // Light from the upper left (north-west), 45° up.
    let l = nalgebra::Vector3::new(-1.0, 1.0, 2f64.sqrt()).normalize();
    for c in &map.cells {
        // Slopes over two cells each way (where observed) to keep per-cell noise down.
        let z = |dx: i64, dy: i64| elev.get(&CellKey::new(c.key.x + dx, c.key.y + dy)).copied();
        let slope = |pts: [(i64, Option<f64>); 4]| {
            let (mut num, mut den) = (0.0, 0.0);
            for (d, v) in pts {
                if let Some(v) = v {
                    num += (v - c.z) * d as f64;
                    den += (d * d) as f64;
                }
            }
            if den > 0.0 {
                num / (den * res)
            } else {
                0.0
            }
        };
        let gx = slope([(-2, z(-2, 0)), (-1, z(-1, 0)), (1, z(1, 0)), (2, z(2, 0))]);
        let gy = slope([(-2, z(0, -2)), (-1, z(0, -1)), (1, z(0, 1)), (2, z(0, 2))]);
        let n = nalgebra::Vector3::new(-gx, -gy, 1.0).normalize();
        // Flat ground has shade 1; slopes facing the light are brighter, others darker;
        // higher ground is a little lighter.
        let shade = (0.45 + 0.55 * n.dot(&l).max(0.0) / l.z) * (0.8 + 0.35 * (c.z - zlo) / zspan);
        let base = c.class.colour();
        let col = base.map(|v| (v as f64 * shade.clamp(0.0, 1.2)).min(255.0) as u8);
        let px = (c.key.x - lo.x) as u32 * s;
        let py = (hi.y - c.key.y) as u32 * s;
        fill_rect(&mut img, px, py, s, s, col);
        if c.hazard as u8 >= 2 && s >= 3 {
            let mark = if c.hazard as u8 == 3 {
                [255, 60, 40]
            } else {
                [255, 255, 255]
            };
            img.put_pixel(px + s / 2, py + s / 2, Rgb(mark));
        }
    }

    // Legend: class swatches, then the scale bar.
    let counts = map.class_counts();
    let ly = mh + 8;
    let mut lx = 8;
    for class in Class::ALL.into_iter().skip(1) {
        if counts[class as usize] == 0 {
            continue;
        }
        fill_rect(&mut img, lx, ly, 12, 12, class.colour());
        draw_text(&mut img, lx + 16, ly + 2, class.name(), 1, [230, 230, 230]);
        lx += 16 + 8 * class.name().len() as u32 + 14;
    }
    let bar_m = nice_length(0.35 * wc as f64 * res);
    let bar_px = ((bar_m / res) as u32 * s).max(1);
    let by = ly + 28;
    fill_rect(&mut img, 8, by, bar_px, 4, [240, 240, 240]);
    fill_rect(&mut img, 8, by - 4, 2, 12, [240, 240, 240]);
    fill_rect(
        &mut img,
        8 + bar_px.saturating_sub(2),
        by - 4,
        2,
        12,
        [240, 240, 240],
    );
    let label = if bar_m >= 1.0 {
        format!("{bar_m:.0} m")
    } else {
        format!("{:.0} cm", bar_m * 100.0)
    };
    draw_text(&mut img, 16 + bar_px, by - 2, &label, 1, [240, 240, 240]);
    let info = format!(
        "{} cells at {:.2} m   +x right, +y up",
        map.cells.len(),
        res
    );
    draw_text(&mut img, 8, by + 14, &info, 1, [170, 170, 170]);
    img
}

/// `map.png`, atomically.
pub fn write_map_png(path: &Path, map: &HazardMap) -> Result<()> {
    let img = render_map_png(map);
    write_atomic(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
}

/// Writes `map.ply`, `terrain.ply` and `map.png` into `dir` (created if needed).
pub fn write_map_files(dir: &Path, map: &HazardMap) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_map_ply(&dir.join("map.ply"), map)?;
    write_terrain_ply(&dir.join("terrain.ply"), map)?;
    write_map_png(&dir.join("map.png"), map)?;
    Ok(())
}

/// Summary of a [`MapCell`] slice used by reports.
pub fn elevation_range(cells: &[MapCell]) -> Option<(f64, f64)> {
    cells.iter().map(|c| c.z).fold(None, |acc, z| match acc {
        None => Some((z, z)),
        Some((lo, hi)) => Some((lo.min(z), hi.max(z))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hazard::Hazard;

    fn cell(x: i64, y: i64, z: f64) -> MapCell {
        MapCell {
            key: CellKey::new(x, y),
            x: (x as f64 + 0.5) * 0.1,
            y: (y as f64 + 0.5) * 0.1,
            z,
            elevation_std: 0.01,
            water: 0.0,
            depth: 0.0,
            class: Class::Ground,
            hazard: Hazard::Free,
            hits: 1,
            below: 0,
        }
    }

    #[test]
    fn no_triangle_spans_an_unknown_cell() {
        // A 3×3 block with the centre unknown: each 2×2 block has three observed cells and
        // gives the one triangle between them, which only touches the unknown cell's corner.
        let mut cells = vec![];
        for y in 0..3 {
            for x in 0..3 {
                if (x, y) != (1, 1) {
                    cells.push(cell(x, y, 0.0));
                }
            }
        }
        let map = HazardMap {
            resolution: 0.1,
            cells,
        };
        let tris = terrain_triangles(&map);
        assert_eq!(tris.len(), 4, "{tris:?}");
        // A row with a gap: no triangle at all.
        let gap = HazardMap {
            resolution: 0.1,
            cells: vec![
                cell(0, 0, 0.0),
                cell(2, 0, 0.0),
                cell(0, 1, 0.0),
                cell(2, 1, 0.0),
            ],
        };
        assert!(terrain_triangles(&gap).is_empty());
        let full = HazardMap {
            resolution: 0.1,
            cells: (0..3)
                .flat_map(|y| (0..3).map(move |x| cell(x, y, 0.0)))
                .collect(),
        };
        let tris = terrain_triangles(&full);
        assert_eq!(tris.len(), 8);
        // Counter-clockwise from above: positive signed area.
        for t in tris {
            let p = t.map(|i| (full.cells[i as usize].x, full.cells[i as usize].y));
            let area =
                (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
            assert!(area > 0.0);
        }
    }

    #[test]
    fn atomic_write_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.bin");
        let r = write_atomic(&p, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        std::fs::write(&p, b"old").unwrap();
        let _ = write_atomic(&p, |_| Err(std::io::Error::other("boom")));
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
    }

    #[test]
    fn map_ply_has_the_contract_layout() {
        let map = HazardMap {
            resolution: 0.1,
            cells: vec![cell(3, -2, 1.5)],
        };
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        write_map_ply(&p, &map).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let h = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        assert_eq!(bytes.len() - h, 29);
        let f = |o: usize| f32::from_le_bytes(bytes[h + o..h + o + 4].try_into().unwrap());
        assert_eq!(f(0), 0.35);
        assert_eq!(f(4), -0.15);
        assert_eq!(f(8), 1.5);
        assert_eq!(bytes[h + 24], 1);
    }

    #[test]
    fn png_of_an_empty_map_is_still_a_picture() {
        let img = render_map_png(&HazardMap {
            resolution: 0.1,
            cells: vec![],
        });
        assert!(img.width() > 0);
    }
}
