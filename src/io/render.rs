//! `map.png`: the hazard map drawn top-down for a person, with a legend and a scale bar
//! (feature `render`).

use std::collections::HashMap;
use std::path::Path;

use image::{Rgb, RgbImage};

use super::export::elevation_range;
use crate::error::Result;
use crate::files::write_atomic;
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

/// A line `thick` pixels wide from `a` to `b` (pixel coordinates), clipped to the map part
/// of the picture (`w` × `h`).
fn draw_line(
    img: &mut RgbImage,
    a: (f64, f64),
    b: (f64, f64),
    thick: u32,
    w: u32,
    h: u32,
    colour: [u8; 3],
) {
    let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 1 << 16);
    let half = (thick / 2) as f64;
    for i in 0..=steps {
        let f = i as f64 / steps as f64;
        let (x, y) = (a.0 + f * (b.0 - a.0) - half, a.1 + f * (b.1 - a.1) - half);
        if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
            continue;
        }
        let (x, y) = (x as u32, y as u32);
        for py in y..(y + thick).min(h) {
            for px in x..(x + thick).min(w) {
                img.put_pixel(px, py, Rgb(colour));
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

/// The elevation ramp of drivable cells, low to high: greens through ochre to pale sand, no
/// blue (water) and no red (obstacles), and lighter with height so it reads in grey too.
const RAMP: [[u8; 3]; 5] = [
    [34, 68, 52],
    [70, 112, 60],
    [150, 150, 70],
    [200, 170, 110],
    [240, 228, 200],
];

/// The ramp's colour at `t` in [0, 1] (clamped; NaN is the low end).
fn ramp(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (RAMP.len() - 1) as f64;
    let i = (x.floor() as usize).min(RAMP.len() - 2);
    let f = x - i as f64;
    std::array::from_fn(|k| {
        (RAMP[i][k] as f64 + f * (RAMP[i + 1][k] as f64 - RAMP[i][k] as f64)).round() as u8
    })
}

/// The elevations the ramp spans: the 2nd and 98th percentiles of the drivable cells (a few
/// stray cells metres off would otherwise flatten every colour), the full range when
/// there are no drivable cells, (0, 1) with no cells.
fn ramp_range(cells: &[MapCell]) -> (f64, f64) {
    let mut z: Vec<f64> = cells
        .iter()
        .filter(|c| c.class != Class::Water && c.hazard != Hazard::Obstacle && c.z.is_finite())
        .map(|c| c.z)
        .collect();
    if z.is_empty() {
        return elevation_range(cells).unwrap_or((0.0, 1.0));
    }
    z.sort_by(f64::total_cmp);
    let at = |q: f64| z[((z.len() - 1) as f64 * q).round() as usize];
    (at(0.02), at(0.98))
}

/// `a` moved a fraction `f` of the way to `b`.
fn blend(a: [u8; 3], b: [u8; 3], f: f64) -> [u8; 3] {
    std::array::from_fn(|k| (a[k] as f64 + f * (b[k] as f64 - a[k] as f64)).round() as u8)
}

/// Colour of a cell in `map.png`: water by hazard (light blue shallow, dark blue deep,
/// violet where the depth is unknown), geometric obstacles red; a drivable cell by its
/// elevation (`t`: its place between the map's lowest and highest cell) on the ramp,
/// tinted by its class (vegetation greener, snow and ice whiter, no class grey).
fn map_colour(c: &MapCell, t: f64) -> [u8; 3] {
    match (c.class, c.hazard) {
        (Class::Water, Hazard::ShallowWater) => SHALLOW,
        (Class::Water, _) if c.depth.is_nan() => UNKNOWN_DEPTH,
        (Class::Water, _) => DEEP,
        (_, Hazard::Obstacle) => OBSTACLE,
        (class, _) => drivable_colour(class, t),
    }
}

fn drivable_colour(class: Class, t: f64) -> [u8; 3] {
    let base = ramp(t);
    match class {
        Class::Vegetation => blend(base, VEGETATION, 0.45),
        Class::SnowIce => blend(base, SNOW, 0.6),
        Class::Unknown => {
            let g = ((base[0] as u32 + base[1] as u32 + base[2] as u32) / 3) as u8;
            [g, g, g]
        }
        _ => base,
    }
}

const SHALLOW: [u8; 3] = [110, 200, 250];
const DEEP: [u8; 3] = [20, 50, 160];
const UNKNOWN_DEPTH: [u8; 3] = [130, 70, 200];
const OBSTACLE: [u8; 3] = [220, 40, 30];
const VEGETATION: [u8; 3] = [20, 170, 40];
const SNOW: [u8; 3] = [235, 245, 255];
const PATH: [u8; 3] = [255, 70, 220];
/// Unobserved cells: the picture's background.
const BG: [u8; 3] = [24, 24, 28];

/// Renders the map top-down: +x to the right, +y up. Drivable cells coloured by elevation
/// (a ramp with its colourbar, tinted by class) and shaded by a hillshade (light from the
/// upper left); cells never observed stay the dark background; water coloured by hazard
/// (shallow within the fording depth, deep, depth unknown); geometric obstacles red; the
/// vehicle's `path` (map-frame x, y in metres, in order; may be empty) as a magenta line
/// from a square at its start; each water body labelled with its id and depth at its
/// centre; a legend of what is shown, the colourbar and a scale bar below the map.
///
/// The picture's size does not follow the map's extent beyond [`MAP_PNG_MAX_SIDE`] pixels:
/// a wider map is drawn with several cells per pixel (water and obstacles drawn over the
/// rest, so a hazard never disappears), and the scale bar says so.
pub fn render_map_png(map: &HazardMap, path: &[[f64; 2]]) -> RgbImage {
    let Some(layout) = Layout::of(map) else {
        let mut img = RgbImage::from_pixel(320, 60, Rgb(BG));
        draw_text(&mut img, 10, 25, "no observed cells", 1, [220, 220, 220]);
        return img;
    };
    let mut img = RgbImage::from_pixel(layout.width, layout.mh + LEGEND_H, Rgb(BG));
    let (zlo, zhi) = ramp_range(&map.cells);
    draw_cells(&mut img, map, &layout, zlo, zhi);
    let path_points = draw_path(&mut img, path, &layout);
    draw_body_labels(&mut img, map, &layout);
    let ly = draw_legend_items(&mut img, map, &layout, path_points > 1);
    let by = draw_colourbar(&mut img, &layout, ly, zlo, zhi);
    draw_scale_bar(&mut img, map, &layout, by);
    img
}

/// Where the map's cells fall in the picture.
struct Layout {
    /// The lowest and highest cell keys of the map.
    lo: CellKey,
    hi: CellKey,
    /// Cells per pixel side (d) and pixels per cell side (s): one of them is 1.
    d: u128,
    s: u32,
    /// The map part of the picture, pixels (the legend goes below it).
    mw: u32,
    mh: u32,
    /// The picture's width: the map's, and at least the legend's.
    width: u32,
    /// The map's cell edge length, metres.
    res: f64,
}

impl Layout {
    /// The layout of `map`'s cells; `None` when it has none.
    fn of(map: &HazardMap) -> Option<Self> {
        let (lo, hi) = map.key_bounds()?;
        // Extents in i128: keys of any i64 value cannot overflow here.
        let span = |a: i64, b: i64| (b as i128 - a as i128 + 1) as u128;
        let (wc, hc) = (span(lo.x, hi.x), span(lo.y, hi.y));
        let long = wc.max(hc);
        let d = long.div_ceil(MAP_PNG_MAX_SIDE as u128).max(1);
        let s = if d > 1 {
            1
        } else {
            (900 / long as u32).clamp(1, 8)
        };
        let (wc, hc) = (wc.div_ceil(d) as u32, hc.div_ceil(d) as u32);
        let (mw, mh) = (wc * s, hc * s);
        Some(Layout {
            lo,
            hi,
            d,
            s,
            mw,
            mh,
            width: mw.max(640),
            res: map.resolution,
        })
    }

    /// Pixel column and row of a cell (row 0 at the top).
    fn pixel_of(&self, k: CellKey) -> (u32, u32) {
        let d64 = self.d as i128;
        (
            ((k.x as i128 - self.lo.x as i128) / d64) as u32 * self.s,
            ((self.hi.y as i128 - k.y as i128) / d64) as u32 * self.s,
        )
    }

    /// Pixel coordinates of the centre of the cell holding map point `p` (x, y metres).
    fn to_pixel(&self, p: &[f64; 2]) -> (f64, f64) {
        let (d, s, res) = (self.d, self.s, self.res);
        (
            ((p[0] / res).floor() - self.lo.x as f64 + 0.5) / d as f64 * s as f64,
            (self.hi.y as f64 - (p[1] / res).floor() + 0.5) / d as f64 * s as f64,
        )
    }
}

/// The cells: each filled with its colour ([`map_colour`], the elevation ramp spanning
/// `zlo..zhi`), drivable ones shaded by a hillshade, hazards flat.
fn draw_cells(img: &mut RgbImage, map: &HazardMap, layout: &Layout, zlo: f64, zhi: f64) {
    let elev: HashMap<CellKey, f64> = map.cells.iter().map(|c| (c.key, c.z)).collect();
    let res = layout.res;
    let zspan = (zhi - zlo).max(1e-6);
    // Light from the upper left (north-west), 45° up.
    let l = nalgebra::Vector3::new(-1.0, 1.0, 2f64.sqrt()).normalize();
    // Several cells per pixel: drivable cells first, hazards over them.
    let mut order: Vec<usize> = (0..map.cells.len()).collect();
    if layout.d > 1 {
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
        let base = map_colour(c, (c.z - zlo) / zspan);
        let col = if c.class == Class::Water || c.hazard == Hazard::Obstacle {
            // Flat colours: hazards must read at a glance.
            base
        } else {
            let gx = slope([(-2, z(-2, 0)), (-1, z(-1, 0)), (1, z(1, 0)), (2, z(2, 0))]);
            let gy = slope([(-2, z(0, -2)), (-1, z(0, -1)), (1, z(0, 1)), (2, z(0, 2))]);
            let n = nalgebra::Vector3::new(-gx, -gy, 1.0).normalize();
            // Flat ground has shade 1; slopes facing the light are brighter, others darker.
            let shade = 0.45 + 0.55 * n.dot(&l).max(0.0) / l.z;
            base.map(|v| (v as f64 * shade.clamp(0.0, 1.2)).min(255.0) as u8)
        };
        let (px, py) = layout.pixel_of(c.key);
        fill_rect(img, px, py, layout.s, layout.s, col);
    }
}

/// The vehicle's path over the cells (under the labels): a line through its finite points
/// from a square at the first. Returns how many points it has.
fn draw_path(img: &mut RgbImage, path: &[[f64; 2]], layout: &Layout) -> usize {
    let pts: Vec<(f64, f64)> = path
        .iter()
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .map(|p| layout.to_pixel(p))
        .collect();
    let thick = (layout.s / 2).max(1) + 1;
    for w in pts.windows(2) {
        draw_line(img, w[0], w[1], thick, layout.mw, layout.mh, PATH);
    }
    if let Some(&(x, y)) = pts.first() {
        let r = 2 * thick;
        if x >= 0.0 && y >= 0.0 {
            fill_rect(
                img,
                (x as u32).saturating_sub(r),
                (y as u32).saturating_sub(r),
                2 * r,
                2 * r,
                PATH,
            );
        }
    }
    pts.len()
}

/// Body labels: "#id" and the depth, centred above the body (below it when there is no
/// room above), so the label never hides the water it names; the largest bodies first,
/// and a label that would cover another or leave the map is not drawn ([`place_labels`]).
fn draw_body_labels(img: &mut RgbImage, map: &HazardMap, layout: &Layout) {
    let Layout { lo, hi, d, s, .. } = *layout;
    let d64 = d as i128;
    let text_scale = if layout.mw >= 400 { 2 } else { 1 };
    let line = 9 * text_scale as i64;
    let wanted: Vec<LabelWanted> = map
        .bodies
        .iter()
        .map(|b| {
            let n = b.cells.len().max(1) as f64;
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
            let lines = [format!("#{}", b.id), depth];
            let tw =
                lines.iter().map(|t| t.len()).max().unwrap_or(0) as i64 * 8 * text_scale as i64;
            LabelWanted {
                size: b.cells.len(),
                x: ((cx - lo.x as f64 + 0.5) / d as f64 * s as f64) as i64 - tw / 2,
                above: rows_above * s as i64 - 2 * line - 2,
                below: (rows_below + 1) * s as i64 + 2,
                w: tw + 2,
                h: 2 * line,
                lines,
            }
        })
        .collect();
    for (l, x, y) in place_labels(&wanted, layout.width as i64, layout.mh as i64) {
        for (row, text) in l.lines.iter().enumerate() {
            let tw = text.len() as u32 * 8 * text_scale;
            let y = y as u32 + row as u32 * line as u32;
            // A dark box behind the text keeps it readable on any colour.
            fill_rect(img, x as u32, y, tw + 2, 8 * text_scale + 2, [0, 0, 0]);
            draw_text(img, x as u32 + 1, y + 1, text, text_scale, [255, 255, 255]);
        }
    }
}

/// The legend's swatches below the map: what is drivable, the water by hazard, the other
/// classes, the path when `has_path`. Returns the row of the last line of swatches.
fn draw_legend_items(img: &mut RgbImage, map: &HazardMap, layout: &Layout, has_path: bool) -> u32 {
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
    let mid = 0.5;
    for (class, name) in [
        (Class::Vegetation, "vegetation"),
        (Class::SnowIce, "snow/ice"),
        (Class::Unknown, "no class"),
    ] {
        if counts[class as usize] > 0 {
            items.push((drivable_colour(class, mid), format!("{name} (drivable)")));
        }
    }
    items.push((BG, "unobserved".into()));
    if has_path {
        items.push((PATH, "vehicle path".into()));
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
    if !map.bodies.is_empty() {
        items.push((
            [0, 0, 0],
            "#id: water body, its deepest measured cell (+?: some depth unknown)".into(),
        ));
    }
    let (mut lx, mut ly) = (8u32, layout.mh + 8);
    for (colour, name) in &items {
        let w = 16 + 8 * name.len() as u32 + 14;
        if lx + w > layout.width {
            lx = 8;
            ly += 18;
        }
        // A light frame, so the background's swatch shows.
        fill_rect(img, lx, ly, 12, 12, [200, 200, 200]);
        fill_rect(img, lx + 1, ly + 1, 10, 10, *colour);
        draw_text(img, lx + 16, ly + 2, name, 1, [230, 230, 230]);
        lx += w;
    }
    ly
}

/// The elevation colourbar of drivable cells, lowest (`zlo`) to highest (`zhi`), on the
/// line below the swatches' last row `ly`. Returns the colourbar's row.
fn draw_colourbar(img: &mut RgbImage, layout: &Layout, ly: u32, zlo: f64, zhi: f64) -> u32 {
    let ly = ly + 20;
    let bar_w = 200.min(layout.width.saturating_sub(200)).max(64);
    let low = format!("<{zlo:.2} m");
    draw_text(img, 8, ly + 2, &low, 1, [230, 230, 230]);
    let bx = 16 + 8 * low.len() as u32;
    for i in 0..bar_w {
        fill_rect(img, bx + i, ly, 1, 12, ramp(i as f64 / (bar_w - 1) as f64));
    }
    draw_text(
        img,
        bx + bar_w + 8,
        ly + 2,
        &format!(">{zhi:.2} m  elevation of drivable cells"),
        1,
        [230, 230, 230],
    );
    ly
}

/// The scale bar (a nice length near a third of the map's width) below the colourbar at
/// row `ly`, and the map's size in cells and water bodies under it.
fn draw_scale_bar(img: &mut RgbImage, map: &HazardMap, layout: &Layout, ly: u32) {
    let (d, s, res) = (layout.d, layout.s, layout.res);
    // Metres per pixel.
    let mpp = res * d as f64 / s as f64;
    let bar_m = nice_length(0.35 * layout.mw as f64 * mpp);
    let bar_px = ((bar_m / mpp) as u32).max(1);
    let by = ly + 34;
    fill_rect(img, 8, by, bar_px, 4, [240, 240, 240]);
    fill_rect(img, 8, by - 4, 2, 12, [240, 240, 240]);
    fill_rect(
        img,
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
    draw_text(img, 16 + bar_px, by - 2, &label, 1, [240, 240, 240]);
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
    draw_text(img, 8, by + 14, &info, 1, [170, 170, 170]);
}

/// A water body's label as it would be drawn: two lines of text in a box `w` × `h`
/// pixels, at column `x` and at row `above` (over the body) or `below` (under it).
struct LabelWanted {
    size: usize,
    x: i64,
    above: i64,
    below: i64,
    w: i64,
    h: i64,
    lines: [String; 2],
}

/// Where the labels go: largest bodies first, each above its body or else below it, moved
/// sideways into the picture, and left out where it would leave the map (`width` × `mh`
/// pixels, the legend below excluded) or cover a label already placed.
fn place_labels(wanted: &[LabelWanted], width: i64, mh: i64) -> Vec<(&LabelWanted, i64, i64)> {
    let mut order: Vec<&LabelWanted> = wanted.iter().collect();
    order.sort_by_key(|l| std::cmp::Reverse(l.size));
    let mut placed: Vec<(&LabelWanted, i64, i64)> = Vec::new();
    for l in order {
        let x = l.x.clamp(0, (width - l.w).max(0));
        let free = |y: i64| {
            y >= 0
                && y + l.h <= mh
                && x + l.w <= width
                && placed.iter().all(|(o, ox, oy)| {
                    x + l.w <= *ox || *ox + o.w <= x || y + l.h <= *oy || *oy + o.h <= y
                })
        };
        if let Some(y) = [l.above, l.below].into_iter().find(|&y| free(y)) {
            placed.push((l, x, y));
        }
    }
    placed
}

/// Height of the legend under the map, pixels: three rows of swatches, the colourbar, the
/// scale bar and the map's size.
const LEGEND_H: u32 = 134;

/// Longest side of the map part of `map.png`, pixels.
pub const MAP_PNG_MAX_SIDE: u32 = 4096;

/// `map.png` ([`render_map_png`] with the vehicle's path), atomically.
pub(crate) fn write_map_png(path: &Path, map: &HazardMap, vehicle_path: &[[f64; 2]]) -> Result<()> {
    crate::interrupt::check(&format!("writing {}", path.display()))?;
    let img = render_map_png(map, vehicle_path);
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

    /// Labels never cover each other or leave the map; the largest bodies get theirs first,
    /// and a label with no room above its body goes below it.
    #[test]
    fn body_labels_do_not_overlap_and_the_largest_come_first() {
        let label = |size: usize, x: i64, above: i64| LabelWanted {
            size,
            x,
            above,
            below: above + 60,
            w: 80,
            h: 36,
            lines: [format!("#{size}"), "max 0.10 m".into()],
        };
        // Five small bodies crowded around one spot, one large one among them, one body
        // at the map's top edge and one past its right edge.
        let mut wanted: Vec<LabelWanted> = (0..5)
            .map(|i| label(10 + i, 100 + 7 * i as i64, 100))
            .collect();
        wanted.push(label(500, 110, 104));
        wanted.push(label(50, 300, -20));
        wanted.push(label(40, 900, 200));
        let placed = place_labels(&wanted, 640, 400);
        assert_eq!(placed[0].0.size, 500);
        for (i, (a, ax, ay)) in placed.iter().enumerate() {
            assert!(*ax >= 0 && ax + a.w <= 640 && *ay >= 0 && ay + a.h <= 400);
            for (b, bx, by) in &placed[i + 1..] {
                let apart =
                    ax + a.w <= *bx || bx + b.w <= *ax || ay + a.h <= *by || by + b.h <= *ay;
                assert!(apart, "#{} and #{} overlap", a.size, b.size);
            }
        }
        // The top-edge body is labelled below itself; the crowd keeps one or two labels.
        let top = placed.iter().find(|p| p.0.size == 50).unwrap();
        assert_eq!(top.2, 40);
        assert!(placed.iter().any(|p| p.0.size == 40 && p.1 == 560));
        assert!(placed.len() < wanted.len());
    }

    #[test]
    fn png_of_an_empty_map_is_still_a_picture() {
        let img = render_map_png(
            &HazardMap {
                resolution: 0.1,
                cells: vec![],
                bodies: vec![],
            },
            &[],
        );
        assert!(img.width() > 0);
    }

    fn cell(x: i64, y: i64, z: f64, class: Class) -> MapCell {
        MapCell {
            class,
            ..crate::io::export::tests::cell(x, y, z)
        }
    }

    /// Elevation sets a drivable cell's colour, an unobserved cell keeps the background, and
    /// the path is drawn where the vehicle went.
    #[test]
    fn elevation_path_and_unobserved_cells_are_drawn() {
        // A 40 × 40 ramp rising along x, with a hole at (20..25, 20..25).
        let cells = (0..40)
            .flat_map(|x| (0..40).map(move |y| (x, y)))
            .filter(|&(x, y)| !((20..25).contains(&x) && (20..25).contains(&y)))
            .map(|(x, y)| cell(x, y, x as f64 * 0.05, Class::Ground))
            .collect();
        let map = HazardMap {
            resolution: 0.1,
            cells,
            bodies: vec![],
        };
        let path = [[0.05, 0.05], [0.05, 3.95]];
        let img = render_map_png(&map, &path);
        // 900 / 40 cells: 8 pixels per cell (capped), row 0 at the top (y = 39).
        let px = |x: u32, y: u32| img.get_pixel(x * 8 + 4, (39 - y) * 8 + 4).0;
        let brightness = |c: [u8; 3]| c.iter().map(|&v| v as u32).sum::<u32>();
        assert!(
            brightness(px(35, 10)) > brightness(px(5, 10)) + 100,
            "higher is lighter"
        );
        assert_eq!(px(22, 22), BG, "unobserved");
        assert_eq!(px(0, 20), PATH, "path");
        assert_ne!(px(10, 20), PATH);
        // The colourbar is in the legend.
        let legend = (img.height() - LEGEND_H)..img.height();
        let ramp_end = ramp(1.0);
        assert!(legend
            .into_iter()
            .any(|y| (0..img.width()).any(|x| img.get_pixel(x, y).0 == ramp_end)));
    }
}
