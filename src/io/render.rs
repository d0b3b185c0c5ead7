//! `map.png`: the hazard map drawn top-down for a person, with a legend and a scale bar
//! (feature `render`).

use std::collections::HashMap;
use std::path::Path;

use image::{Rgb, RgbImage};

use super::export::{elevation_range, write_atomic};
use crate::error::Result;
use crate::grid::CellKey;
use crate::hazard::{Class, Hazard, HazardMap, MapCell};

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

/// Colour of a cell in `map.png`: water by hazard (light blue shallow, dark blue deep,
/// violet where the depth is unknown), geometric obstacles red, other classes in their
/// colours; drivable ground keeps its class colour.
fn map_colour(c: &MapCell) -> [u8; 3] {
    match (c.class, c.hazard) {
        (Class::Water, Hazard::ShallowWater) => SHALLOW,
        (Class::Water, _) if c.depth.is_nan() => UNKNOWN_DEPTH,
        (Class::Water, _) => DEEP,
        (_, Hazard::Obstacle) => OBSTACLE,
        (class, _) => class.colour(),
    }
}

const SHALLOW: [u8; 3] = [110, 200, 250];
const DEEP: [u8; 3] = [20, 50, 160];
const UNKNOWN_DEPTH: [u8; 3] = [130, 70, 200];
const OBSTACLE: [u8; 3] = [220, 40, 30];

/// Renders the map top-down: +x to the right, +y up. Drivable cells in their class colours
/// shaded by a hillshade of the elevation (light from the upper left); water coloured by
/// hazard (shallow within the fording depth, deep, depth unknown); geometric obstacles
/// red; each water body labelled with its id and depth at its centre; a legend of what is
/// shown and a scale bar below the map.
///
/// The picture's size does not follow the map's extent beyond [`MAP_PNG_MAX_SIDE`] pixels:
/// a wider map is drawn with several cells per pixel (water and obstacles drawn over the
/// rest, so a hazard never disappears), and the scale bar says so.
pub fn render_map_png(map: &HazardMap) -> RgbImage {
    const BG: [u8; 3] = [24, 24, 28];
    let Some((lo, hi)) = map.key_bounds() else {
        let mut img = RgbImage::from_pixel(320, 60, Rgb(BG));
        draw_text(&mut img, 10, 25, "no observed cells", 1, [220, 220, 220]);
        return img;
    };
    // Extents in i128: keys of any i64 value cannot overflow here.
    let span = |a: i64, b: i64| (b as i128 - a as i128 + 1) as u128;
    let (wc, hc) = (span(lo.x, hi.x), span(lo.y, hi.y));
    let long = wc.max(hc);
    // Cells per pixel side (d) and pixels per cell side (s): one of them is 1.
    let d = long.div_ceil(MAP_PNG_MAX_SIDE as u128).max(1);
    let s = if d > 1 {
        1
    } else {
        (900 / long as u32).clamp(1, 8)
    };
    let (wc, hc) = (wc.div_ceil(d) as u32, hc.div_ceil(d) as u32);
    let d64 = d as i128;
    // Pixel column and row of a cell (row 0 at the top).
    let pixel_of = |k: CellKey| {
        (
            ((k.x as i128 - lo.x as i128) / d64) as u32 * s,
            ((hi.y as i128 - k.y as i128) / d64) as u32 * s,
        )
    };
    let (mw, mh) = (wc * s, hc * s);
    let legend_h = 96;
    let width = mw.max(640);
    let mut img = RgbImage::from_pixel(width, mh + legend_h, Rgb(BG));

    let elev: HashMap<CellKey, f64> = map.cells.iter().map(|c| (c.key, c.z)).collect();
    let res = map.resolution;
    let (zlo, zhi) = elevation_range(&map.cells).unwrap_or((0.0, 1.0));
    let zspan = (zhi - zlo).max(1e-6);
    // Light from the upper left (north-west), 45° up.
    let l = nalgebra::Vector3::new(-1.0, 1.0, 2f64.sqrt()).normalize();
    // Several cells per pixel: drivable cells first, hazards over them.
    let mut order: Vec<usize> = (0..map.cells.len()).collect();
    if d > 1 {
        let hazard = |c: &MapCell| c.class == Class::Water || c.hazard != Hazard::Free;
        order.sort_by_key(|&i| hazard(&map.cells[i]));
    }
    for (n, c) in order.into_iter().map(|i| &map.cells[i]).enumerate() {
        // A stop request leaves the picture unfinished; `write_map_png` then writes nothing.
        if n % 65_536 == 0 && crate::interrupt::stop_requested() {
            break;
        }
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
        let base = map_colour(c);
        let col = if c.class == Class::Water || c.hazard == Hazard::Obstacle {
            // Flat colours: hazards must read at a glance.
            base
        } else {
            let gx = slope([(-2, z(-2, 0)), (-1, z(-1, 0)), (1, z(1, 0)), (2, z(2, 0))]);
            let gy = slope([(-2, z(0, -2)), (-1, z(0, -1)), (1, z(0, 1)), (2, z(0, 2))]);
            let n = nalgebra::Vector3::new(-gx, -gy, 1.0).normalize();
            // Flat ground has shade 1; slopes facing the light are brighter, others darker;
            // higher ground is a little lighter.
            let shade =
                (0.45 + 0.55 * n.dot(&l).max(0.0) / l.z) * (0.8 + 0.35 * (c.z - zlo) / zspan);
            base.map(|v| (v as f64 * shade.clamp(0.0, 1.2)).min(255.0) as u8)
        };
        let (px, py) = pixel_of(c.key);
        fill_rect(&mut img, px, py, s, s, col);
    }

    // Body labels: "#id" and the depth, centred above the body (below it when there is no
    // room above), so the label never hides the water it names.
    let text_scale = if mw >= 400 { 2 } else { 1 };
    for b in &map.bodies {
        let n = b.cells.len().max(1) as f64;
        // Body position in pixels (cells divided by the cells per pixel).
        let cx = b.cells.iter().map(|k| k.x as f64).sum::<f64>() / n;
        let top = b.cells.iter().map(|k| k.y).max().unwrap_or(hi.y);
        let bottom = b.cells.iter().map(|k| k.y).min().unwrap_or(lo.y);
        let rows_above = ((hi.y as i128 - top as i128) / d64) as i64;
        let rows_below = ((hi.y as i128 - bottom as i128) / d64) as i64;
        let depth = match (b.depth.max_m, b.depth.unknown_cells) {
            (Some(d), 0) => format!("max {d:.2} m"),
            (Some(d), _) => format!("max {d:.2} m+?"),
            (None, _) => "depth ?".to_string(),
        };
        let px = ((cx - lo.x as f64 + 0.5) / d as f64 * s as f64) as i64;
        let line = 9 * text_scale as i64;
        let above = rows_above * s as i64 - 2 * line - 2;
        let y0 = if above >= 0 {
            above
        } else {
            (rows_below + 1) * s as i64 + 2
        };
        for (row, text) in [format!("#{}", b.id), depth].iter().enumerate() {
            let tw = (text.len() as u32 * 8 * text_scale) as i64;
            let x = (px - tw / 2).clamp(0, (width as i64 - tw).max(0)) as u32;
            let y = (y0 + row as i64 * line).clamp(0, mh.saturating_sub(8) as i64) as u32;
            // A dark box behind the text keeps it readable on any colour.
            fill_rect(
                &mut img,
                x.saturating_sub(1),
                y.saturating_sub(1),
                tw as u32 + 2,
                8 * text_scale + 2,
                [0, 0, 0],
            );
            draw_text(&mut img, x, y, text, text_scale, [255, 255, 255]);
        }
    }

    // Legend: what is drivable, the water by hazard, the other classes; then the scale bar.
    let counts = map.class_counts();
    let has = |h: Hazard| map.cells.iter().any(|c| c.hazard == h);
    let has_unknown = map
        .cells
        .iter()
        .any(|c| c.class == Class::Water && c.hazard != Hazard::ShallowWater && c.depth.is_nan());
    let has_deep = map
        .cells
        .iter()
        .any(|c| c.class == Class::Water && c.hazard == Hazard::DeepWater && !c.depth.is_nan());
    let mut items: Vec<([u8; 3], String)> = Vec::new();
    for class in [
        Class::Ground,
        Class::Vegetation,
        Class::SnowIce,
        Class::Unknown,
    ] {
        if counts[class as usize] > 0 {
            items.push((class.colour(), format!("{} (drivable)", class.name())));
        }
    }
    if has(Hazard::ShallowWater) {
        items.push((SHALLOW, "shallow water (fordable)".into()));
    }
    if has_deep {
        items.push((DEEP, "deep water".into()));
    }
    if has_unknown {
        items.push((UNKNOWN_DEPTH, "water, depth unknown".into()));
    }
    if has(Hazard::Obstacle) {
        items.push((OBSTACLE, "obstacle (step/slope)".into()));
    }
    let (mut lx, mut ly) = (8u32, mh + 8);
    for (colour, name) in &items {
        let w = 16 + 8 * name.len() as u32 + 14;
        if lx + w > width {
            lx = 8;
            ly += 18;
        }
        fill_rect(&mut img, lx, ly, 12, 12, *colour);
        draw_text(&mut img, lx + 16, ly + 2, name, 1, [230, 230, 230]);
        lx += w;
    }
    // Metres per pixel.
    let mpp = res * d as f64 / s as f64;
    let bar_m = nice_length(0.35 * mw as f64 * mpp);
    let bar_px = ((bar_m / mpp) as u32).max(1);
    let by = ly + 30;
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
    let per_pixel = if d > 1 {
        format!(" ({d}x{d} cells per pixel)")
    } else {
        String::new()
    };
    let info = format!(
        "{} cells at {:.2} m{per_pixel}, {} water bodies   +x right, +y up",
        map.cells.len(),
        res,
        map.bodies.len()
    );
    draw_text(&mut img, 8, by + 14, &info, 1, [170, 170, 170]);
    img
}

/// Longest side of the map part of `map.png`, pixels.
pub const MAP_PNG_MAX_SIDE: u32 = 4096;

/// `map.png`, atomically.
pub fn write_map_png(path: &Path, map: &HazardMap) -> Result<()> {
    crate::interrupt::check(&format!("writing {}", path.display()))?;
    let img = render_map_png(map);
    // Rendering stops early on a stop request: an unfinished picture is not written.
    crate::interrupt::check(&format!("writing {}", path.display()))?;
    write_atomic(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_of_an_empty_map_is_still_a_picture() {
        let img = render_map_png(&HazardMap {
            resolution: 0.1,
            cells: vec![],
            bodies: vec![],
        });
        assert!(img.width() > 0);
    }
}
