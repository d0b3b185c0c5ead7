//! The scan's geometry: the map-frame direction of every beam (missing ones included,
//! from the beam model), the scan lines in order of lookahead, and the sensor's height
//! over the ground the scan sees.

use nalgebra::Vector3;

use super::BeamModel;
use crate::geom::PointCloud;

/// Least-squares line through (x, y) pairs: (mean x, mean y, slope dy/dx); `None` without
/// spread in x.
pub(super) fn fit_line(pts: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64, f64)> {
    let n = pts.clone().count() as f64;
    let (mx, my) = pts
        .clone()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = pts.fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    (sxx > 1e-12).then(|| (mx, my, sxy / sxx))
}

/// Map-frame unit direction of every slot: from the point for real returns, from the beam
/// model for missing ones (`None` where it cannot be known).
pub fn beam_directions(cloud: &PointCloud, model: &BeamModel) -> Vec<Option<Vector3<f64>>> {
    let mut out = Vec::new();
    beam_directions_into(cloud, model, &mut out);
    out
}

/// [`beam_directions`] into `local`'s storage (its contents replaced).
pub(super) fn beam_directions_into(
    cloud: &PointCloud,
    model: &BeamModel,
    local: &mut Vec<Option<Vector3<f64>>>,
) {
    let rot = cloud.frame_to_map.rotation;
    let so = cloud.sensor_origin;
    let (rows, cols) = (cloud.rows, cloud.cols);
    let from_point = |i: usize| {
        let [x, y, z] = cloud.xyz[i];
        let v = Vector3::new(x as f64 - so.x, y as f64 - so.y, z as f64 - so.z);
        let nv = v.norm();
        (nv > 0.0).then(|| v / nv)
    };
    local.clear();
    local.extend((0..cloud.len()).map(|i| {
        if cloud.is_valid(i) {
            from_point(i)
        } else {
            None
        }
    }));
    match model {
        BeamModel::Directions(d) => {
            for (i, l) in local.iter_mut().enumerate() {
                if l.is_none() {
                    let v = Vector3::new(d[i][0] as f64, d[i][1] as f64, d[i][2] as f64);
                    let nv = v.norm();
                    *l = (nv > 0.0).then(|| v / nv);
                }
            }
        }
        BeamModel::Spinning {
            elevations_rad,
            azimuth0_rad,
            clockwise,
        } => {
            let sign = if *clockwise { -1.0 } else { 1.0 };
            for (r, &el) in elevations_rad.iter().enumerate().take(rows) {
                for c in 0..cols {
                    let i = r * cols + c;
                    if local[i].is_none() {
                        let az = azimuth0_rad
                            + sign * 2.0 * std::f64::consts::PI * c as f64 / cols as f64;
                        local[i] = Some(from_angles(az, el));
                    }
                }
            }
        }
        BeamModel::Infer { .. } if cols == 1 && rows > 2 => {
            infer_single_column(local);
        }
        BeamModel::Infer { max_gap_fraction } => {
            infer_from_rows(local, rows, cols, *max_gap_fraction);
        }
    }
    for d in local.iter_mut() {
        *d = d.map(|v| rot * v);
    }
}

/// The unit direction of azimuth `az` and elevation `el` (radians).
fn from_angles(az: f64, el: f64) -> Vector3<f64> {
    Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
}

/// Fills the missing beams of each row (sensor frame) by interpolating azimuth and
/// elevation, linearly in column index, between the nearest valid beams either side, across
/// gaps of at most `max_gap_fraction` of the row (cyclic across the row's ends when the
/// scan has more than one row).
fn infer_from_rows(
    local: &mut [Option<Vector3<f64>>],
    rows: usize,
    cols: usize,
    max_gap_fraction: f64,
) {
    let cyclic = rows > 1;
    let max_gap = ((cols as f64 * max_gap_fraction).floor() as usize).max(1);
    let angles = |v: &Vector3<f64>| (v.y.atan2(v.x), v.z.clamp(-1.0, 1.0).asin());
    for r in 0..rows {
        let row = &local[r * cols..(r + 1) * cols];
        let valid: Vec<usize> = (0..cols).filter(|&c| row[c].is_some()).collect();
        if valid.is_empty() {
            continue;
        }
        let mut fill: Vec<(usize, Vector3<f64>)> = Vec::new();
        // Consecutive valid pairs (and the wrap-around pair when cyclic).
        let mut pairs: Vec<(usize, usize)> = valid.windows(2).map(|w| (w[0], w[1])).collect();
        if cyclic {
            pairs.push((valid[valid.len() - 1], valid[0] + cols));
        }
        for (a, b) in pairs {
            let gap = b - a;
            if gap < 2 || gap - 1 > max_gap {
                continue;
            }
            let (az_a, el_a) = angles(&row[a].unwrap());
            let (az_b, el_b) = angles(&row[b % cols].unwrap());
            let mut daz = az_b - az_a;
            let tau = 2.0 * std::f64::consts::PI;
            daz -= tau * (daz / tau).round();
            for k in 1..gap {
                let t = k as f64 / gap as f64;
                fill.push((
                    (a + k) % cols,
                    from_angles(az_a + daz * t, el_a + (el_b - el_a) * t),
                ));
            }
        }
        for (c, v) in fill {
            local[r * cols + c] = Some(v);
        }
    }
}

/// Fills the missing beams of a single-column scan (sensor frame, one beam per row) from
/// the least-squares line of elevation against row through the valid beams, at their median
/// azimuth; leaves them unknown when fewer than 3 beams returned or the beams do not lie on
/// a line within 0.1° RMS (not an evenly spaced scanner).
fn infer_single_column(local: &mut [Option<Vector3<f64>>]) {
    let pts: Vec<(f64, f64, f64)> = local
        .iter()
        .enumerate()
        .filter_map(|(r, v)| v.map(|v| (r as f64, v.z.clamp(-1.0, 1.0).asin(), v.y.atan2(v.x))))
        .collect();
    if pts.len() < 3 {
        return;
    }
    let n = pts.len() as f64;
    let Some((mr, me, slope)) = fit_line(pts.iter().map(|p| (p.0, p.1))) else {
        return;
    };
    let el = |r: f64| me + slope * (r - mr);
    let rms = (pts.iter().map(|p| (p.1 - el(p.0)).powi(2)).sum::<f64>() / n).sqrt();
    // Also refuses a NaN residual.
    if rms.is_nan() || rms > 0.1f64.to_radians() {
        return;
    }
    let mut az: Vec<f64> = pts.iter().map(|p| p.2).collect();
    let m = az.len() / 2;
    az.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    let az = az[m];
    for (r, v) in local.iter_mut().enumerate() {
        if v.is_none() {
            let e = el(r as f64);
            if e.abs() < std::f64::consts::FRAC_PI_2 {
                *v = Some(Vector3::new(
                    e.cos() * az.cos(),
                    e.cos() * az.sin(),
                    e.sin(),
                ));
            }
        }
    }
}

/// Scan lines in order of increasing lookahead: columns ordered by each row's median
/// elevation (multi-row scans), or the single row ordered by slot elevation.
pub(super) fn scan_lines(cloud: &PointCloud, dirs: &[Option<Vector3<f64>>]) -> Vec<Vec<u32>> {
    let (rows, cols) = (cloud.rows, cloud.cols);
    if rows <= 1 {
        let mut line: Vec<(f64, u32)> = dirs
            .iter()
            .enumerate()
            .filter_map(|(i, d)| d.map(|v| (v.z, i as u32)))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        return vec![line.into_iter().map(|(_, i)| i).collect()];
    }
    let mut order: Vec<(f64, usize)> = (0..rows)
        .filter_map(|r| {
            let mut el: Vec<f64> = (0..cols)
                .filter_map(|c| dirs[r * cols + c].map(|v| v.z))
                .collect();
            if el.is_empty() {
                return None;
            }
            let m = el.len() / 2;
            el.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
            Some((el[m], r))
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    (0..cols)
        .map(|c| {
            order
                .iter()
                .map(|&(_, r)| (r * cols + c) as u32)
                .filter(|&i| dirs[i as usize].is_some())
                .collect()
        })
        .collect()
}

/// The sensor's height above the ground, estimated from the scan itself: the median of
/// `sensor z − point z` over the returns of the steepest downward beams (depression
/// between 10° and 45°, the ground ring around the vehicle), in the map frame. `None`
/// when fewer than 20 such returns exist.
pub fn estimate_sensor_height(cloud: &PointCloud) -> Option<f64> {
    let o = cloud.sensor_origin_in_map();
    let (lo, hi) = (10f64.to_radians().sin(), 45f64.to_radians().sin());
    let mut h: Vec<f64> = (0..cloud.len())
        .filter(|&i| cloud.is_valid(i))
        .filter_map(|i| {
            let v = cloud.point_in_map(i) - o;
            let s = -v.z / v.norm();
            (s >= lo && s <= hi).then_some(-v.z)
        })
        .collect();
    if h.len() < 20 {
        return None;
    }
    // The ground is the lowest surface: take the median of the lower half, which ignores
    // vegetation and obstacles above it.
    h.sort_by(|a, b| b.total_cmp(a));
    let lower = &h[..h.len() / 2];
    Some(lower[lower.len() / 2])
}
