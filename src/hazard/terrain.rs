//! The rules of a dry cell read from the dry cells around it: its class and hazard from
//! steps and slopes ([`terrain_hazard`]), and the σ of its elevation at its centre.

use super::{Class, Hazard};

/// The dry 3 × 3 neighbourhood of a cell (itself included), row by row from its lower-left
/// neighbour: elevation and σ, NaN elevation where the neighbour is not a dry cell.
pub type Neighbourhood = [(f64, f64); 9];

/// The dry 5 × 5 window around a cell (itself at index 12), row by row from its lower-left
/// cell: elevation and weight (the inverse variance of its vertical σ and the millimetre,
/// [`dry_terrain`](super::dry::dry_terrain)), NaN elevation where the cell is not dry. What
/// the cell's σ reads its terrain's gradient from.
pub(super) type Window = [(f64, f64); 25];

/// Class and hazard of a dry cell with elevation `z` ± `sz` from its dry neighbourhood
/// `nb`: the upper side of a step higher than `max_step` is an obstacle (class and
/// hazard), a slope steeper than `max_grad` (rise over run) is a hazard on ground. Only
/// what the elevations show beyond their noise counts: each difference to a neighbour is
/// shrunk towards zero by two standard deviations of that difference, so far cells seen by
/// a few noisy stereo points do not turn into obstacles.
///
/// The slope along each axis is read on both sides of the cell: the mean rise from the
/// column (row) of neighbours behind it and from the one ahead. The tilt is their mean
/// (the least-squares slope) when both sides rise the same way, and none when one side is
/// level or they disagree: a single cell above or
/// below the cell (a step, a post, a phantom bump or hole of misplaced returns) tilts only
/// one side and is the step test's business, not a slope of the cell. Where one side has
/// no dry neighbour (the edge of what was seen) there is no tilt along that axis: one side
/// cannot tell a slope from a bump.
#[inline]
pub fn terrain_hazard(
    nb: &Neighbourhood,
    (z, sz): (f64, f64),
    res: f64,
    max_step: f64,
    max_grad: f64,
) -> (Class, Hazard) {
    // The margins apart from the sums below, so that they vectorise.
    let margin: [f64; 9] = std::array::from_fn(|j| {
        let sn = nb[j].1;
        2.0 * (sz * sz + sn * sn).sqrt()
    });
    // Sums and counts of the shrunk rises towards −x, +x, −y, +y.
    let mut step = 0.0f64;
    let (mut sum, mut n) = ([0.0f64; 4], [0u32; 4]);
    for (j, (&(zn, _), &margin)) in nb.iter().zip(&margin).enumerate() {
        if zn.is_nan() {
            continue;
        }
        let (dx, dy) = (j as i64 % 3 - 1, j as i64 / 3 - 1);
        let d = zn - z;
        let d = d.signum() * (d.abs() - margin).max(0.0);
        step = step.max(-d);
        for (side, on) in [(0, dx < 0), (1, dx > 0), (2, dy < 0), (3, dy > 0)] {
            if on {
                sum[side] += d;
                n[side] += 1;
            }
        }
    }
    if step > max_step {
        return (Class::Obstacle, Hazard::Obstacle);
    }
    // Rise per metre going forward along the axis, from the side behind (−) and ahead (+).
    let tilt = |behind: usize, ahead: usize| {
        let g = |side: usize, sign: f64| {
            (n[side] > 0).then(|| sign * sum[side] / (n[side] as f64 * res))
        };
        match (g(behind, -1.0), g(ahead, 1.0)) {
            (Some(a), Some(b)) if a * b > 0.0 => 0.5 * (a + b),
            _ => 0.0,
        }
    };
    let grad = tilt(0, 1).hypot(tilt(2, 3));
    if grad > max_grad {
        (Class::Ground, Hazard::Obstacle)
    } else {
        (Class::Ground, Hazard::Free)
    }
}

/// The σ of a dry cell's elevation as the elevation of its centre, from the cell's vertical
/// σ `sd` ([`elevation_std_m`](crate::grid::CellStats::elevation_std_m)) and its
/// range-bound σ `s_rb` ([`range_bound_std_m`](crate::grid::CellStats::range_bound_std_m)),
/// on terrain of gradient g read from the dry cells of its 5 × 5 window
/// ([`window_gradient`]):
///
/// * a point moved along its ray by a range error lands in the map at another place, where
///   sloping terrain stands higher or lower: against the terrain there, the error is the
///   range error times `s + g_r·c` (s, c the ray's vertical and horizontal shares, g_r the
///   gradient along the ray), not times the vertical share s alone. Over the cell's points
///   that is at most `sd + |g|·s_rb` (Cauchy–Schwarz over the points, c ≤ 1): a bank seen
///   at grazing incidence is as uncertain as its range errors, level ground only by their
///   vertical part. Only a slope the window shows beyond three σ of its own noise counts
///   here (each axis's g² less nine times its estimate's variance), or noisy far cells on
///   level ground would read a slope out of their noise and multiply it by a range-bound σ
///   of decimetres;
/// * the points' mean lies where they fell in the cell, not at its centre: g times an
///   offset spread over the cell, variance `g²·res²/12` along each axis;
/// * the terrain varies within the cell beyond that plane (roughness, a kerb's edge): the
///   centre differs from the points' mean by what their spread shows beyond their noise
///   (`excess`, [`excess_spread_var_m2`](crate::grid::CellStats::excess_spread_var_m2))
///   less the plane's `g²·res²/12`;
/// * the elevations are whole millimetres (variance 1/12 mm²).
pub(super) fn centre_std(sd: f64, s_rb: f64, excess: f64, win: &Window, res: f64) -> f64 {
    let (g2, slope2) = window_gradient(win, res);
    let along_rays = sd + slope2.sqrt() * s_rb.max(sd);
    let across = g2 * res * res / 12.0;
    let rough = (excess - across).max(0.0);
    (along_rays * along_rays + across + rough + 1e-6 / 12.0).sqrt()
}

/// The terrain's squared gradient at the centre of `win` and the part of it beyond three
/// σ of the estimate's noise: `(|g|², Σ_axes max(0, g_a² − 9·var(g_a)))`. The gradient is
/// the least-squares plane through the window's dry cells (the centre's own among them),
/// each weighted by its own vertical σ and the millimetre, so that a lidar cell amid far
/// stereo cells reads its slope from its like and not from their noise. A sparse scan (the
/// rings of a far lidar, metres apart; its columns, every other cell) leaves many cells
/// without a neighbour on some side of the 3 × 3 around them, but seldom without one in the
/// 5 × 5. Where the window's cells lie on a line, the slope across it is not seen, and is
/// taken as the one along it (no direction of slope preferred); with no neighbour at all
/// there is none.
pub(super) fn window_gradient(win: &Window, res: f64) -> (f64, f64) {
    // The dry cells: (dx, dy) in cells, dz (m), weight 1/σ² (m⁻²).
    let mut at = [(0.0, 0.0, 0.0, 0.0); 25];
    let mut len = 0;
    for (j, &(z, w)) in win.iter().enumerate() {
        if !z.is_nan() {
            let (dx, dy) = ((j % 5) as f64 - 2.0, (j / 5) as f64 - 2.0);
            at[len] = (dx, dy, z - win[12].0, w);
            len += 1;
        }
    }
    let cells = &at[..len];
    let (mut n, mut sw, mut sx, mut sy, mut sz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(dx, dy, dz, w) in cells {
        n += 1.0;
        sw += w;
        sx += w * dx;
        sy += w * dy;
        sz += w * dz;
    }
    if n < 2.0 {
        return (0.0, 0.0);
    }
    let (mx, my, mz) = (sx / sw, sy / sw, sz / sw);
    // Weighted centred moments, offsets in cells (the gradient per cell, scaled below),
    // and the unweighted determinant of the cells' layout.
    let (mut xx, mut xy, mut yy, mut xz, mut yz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut ux, mut uy, mut uxx, mut uxy, mut uyy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(dx, dy, dz, w) in cells {
        (ux, uy, uxx, uxy, uyy) = (
            ux + dx,
            uy + dy,
            uxx + dx * dx,
            uxy + dx * dy,
            uyy + dy * dy,
        );
        let (dx, dy, dz) = (dx - mx, dy - my, dz - mz);
        xx += w * dx * dx;
        xy += w * dx * dy;
        yy += w * dy * dy;
        xz += w * dx * dz;
        yz += w * dy * dz;
    }
    // n²·det of the unweighted layout is n times the sum of the squared doubled areas of
    // the triangles the cells make (Binet–Cauchy): at least n unless they lie on a line.
    let layout = (n * uxx - ux * ux) * (n * uyy - uy * uy) - (n * uxy - ux * uy).powi(2);
    let beyond = |g: f64, v: f64| (g * g - 9.0 * v).max(0.0);
    let (g2, slope2) = if layout > 0.5 * n {
        let det = xx * yy - xy * xy;
        let (gx, gy) = ((yy * xz - xy * yz) / det, (xx * yz - xy * xz) / det);
        let (vx, vy) = (yy / det, xx / det);
        (gx * gx + gy * gy, beyond(gx, vx) + beyond(gy, vy))
    } else {
        // On a line through the cells: the slope along it, taken across it too.
        let l = xx + yy;
        let g = (xz * xx.sqrt() + yz * xy.signum() * yy.sqrt()) / (l * l.sqrt());
        (2.0 * g * g, 2.0 * beyond(g, 1.0 / l))
    };
    (g2 / (res * res), slope2 / (res * res))
}
