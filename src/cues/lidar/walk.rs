//! The walk along one scan line, in order of lookahead: the local ground level it keeps
//! (and the slope and spread of the ground behind it), and what each slot contributes
//! ([`Event`]): a missing beam cast against the level, a ground return, or a return below
//! the level read through the water ([`super::below`]).

use std::collections::VecDeque;

use nalgebra::{Point3, Vector3};

use super::below::{mirror_refuted, ScanLine};
use super::bright::{bright_reference, BED_BRIGHTER, BRIGHT_WINDOW};
use super::LidarCueModel;
use crate::cues::{normalised_reflectivity, ReflectivityConfig, WaterPrior};
use crate::geom::PointCloud;

impl LidarCueModel {
    /// Walks one scan `line` (slots in order of lookahead) from the ground under the sensor
    /// at `level0`: what each slot contributed, and the farthest lookahead dry ground
    /// returned from along the line.
    pub(super) fn walk(
        &self,
        cloud: &PointCloud,
        dirs: &[Option<Vector3<f64>>],
        line: &[u32],
        o: Point3<f64>,
        level0: f64,
        prior: Option<&WaterPrior>,
    ) -> (Vec<Event>, f64) {
        let scan_line = ScanLine {
            cloud,
            dirs,
            slots: line,
            o,
        };
        let mut walk = Walk::new(self, scan_line, level0, prior);
        for &s in line {
            let s = s as usize;
            if cloud.is_valid(s) {
                walk.valid_return(s);
            } else if let Some(u) = dirs[s] {
                walk.missing_beam(u);
            }
        }
        (walk.out, walk.far)
    }
}

/// The state of one scan line's walk.
struct Walk<'a> {
    model: &'a LidarCueModel,
    line: ScanLine<'a>,
    prior: Option<&'a WaterPrior>,
    /// The local ground: `level` at lookahead `d_level`, falling or rising with `slope`
    /// beyond it. Under the vehicle the slope is not known yet: the first return may lie
    /// anywhere within ±g_max of level ground.
    level: f64,
    d_level: f64,
    slope: Option<f64>,
    /// (lookahead, z) of the ground returns of the last SLOPE_WINDOW_M, starting with the
    /// ground under the sensor: the slope is their least-squares line, so 1 cm of range
    /// noise does not tilt it by the 6 % it would between two returns 25 cm apart.
    recent: SlopeWindow,
    /// The farthest lookahead dry ground returned from along this line.
    far: f64,
    /// The reflectivity channel's settings (the defaults without the reflectivity cue).
    channel: ReflectivityConfig,
    /// Normalised reflectivity of the line's last ground returns (`BRIGHT_WINDOW`): the
    /// brightest is what the bottom of water there could at most return, before the
    /// water's losses.
    bright: VecDeque<f64>,
    /// How far the line's last ground returns fell from the level they were judged by
    /// (`GATE_WINDOW`): the dry ground's own spread, for the below-level gate.
    drops: VecDeque<f64>,
    out: Vec<Event>,
}

impl<'a> Walk<'a> {
    fn new(
        model: &'a LidarCueModel,
        line: ScanLine<'a>,
        level0: f64,
        prior: Option<&'a WaterPrior>,
    ) -> Self {
        Walk {
            model,
            line,
            prior,
            level: level0,
            d_level: 0.0,
            slope: None,
            recent: SlopeWindow::new((0.0, level0)),
            far: 0.0f64,
            channel: model.reflectivity.unwrap_or_default(),
            bright: VecDeque::with_capacity(BRIGHT_WINDOW),
            drops: VecDeque::with_capacity(GATE_WINDOW),
            out: Vec::new(),
        }
    }

    /// A return at slot `s`: judged against the ground expected at its lookahead (the
    /// level, carried down the falling slope, with slack for the unknown slope under the
    /// vehicle): under the prior's water, below the level by more than the gate, ground,
    /// or above the ground (nothing).
    fn valid_return(&mut self, s: usize) {
        let model = self.model;
        let cfg = &model.cfg;
        let g_max = cfg.max_ground_slope;
        let o = self.line.o;
        let p = self.line.cloud.point_in_map(s);
        let v = p - o;
        let range = v.norm();
        let d = crate::geom::hypot(v.x, v.y);
        let cos_inc = if range > 0.0 { -v.z / range } else { 0.0 };
        let run = (d - self.d_level).max(0.0);
        // Only a falling slope is followed: ground rising ahead moves the level up
        // through the above-gate anyway, while a rising slope carried over a long
        // run would put level ground beyond it "below" and call it a bottom.
        let expected = self.level + self.slope.unwrap_or(0.0).min(0.0) * run;
        let slack = if self.slope.is_some() {
            0.0
        } else {
            g_max * run
        };
        let dz = p.z - expected;
        // The gate is never negative: only a return below the level and its slack
        // needs it measured.
        let drops = &self.drops;
        let gate = || {
            let sigma_v = model.noise.sigma(range) * (-v.z / range.max(1e-9)).max(0.0);
            below_gate(drops, sigma_v, cfg.below_gate_m)
        };
        if let Some(e) = self.prior.and_then(|w| model.under_prior(w, s, o, p, gate)) {
            self.out.push(e);
            return;
        }
        let below = v.z < 0.0 && o.z > self.level && dz < -slack && dz < -(gate() + slack);
        let ground = if below {
            match self.below_level(s, p, range) {
                Some(ground) => ground,
                None => return,
            }
        } else {
            dz <= cfg.above_gate_m + slack
        };
        if ground {
            self.ground_return(s, p, d, dz, cos_inc, range);
        }
    }

    /// A return below the level: bottom or specular, or ground below the level. Whether
    /// it is ground; `None` when it cannot be read through the level.
    fn below_level(&mut self, s: usize, p: Point3<f64>, range: f64) -> Option<bool> {
        let model = self.model;
        let cfg = &model.cfg;
        let level = self.level;
        let (c, bottom) = model.against_level(s, self.line.o, p, level, false)?;
        Some(if let Some(e) = bottom {
            self.out.push(e);
            false
        } else if level - p.z < cfg.specular_min_depth_m {
            self.out.push(Event::Unexplained);
            false
        } else if mirror_refuted(
            &self.line,
            p,
            level,
            model.noise.sigma(range),
            cfg.above_gate_m,
        ) {
            self.out.push(Event::BelowGround);
            true
        } else {
            self.out.push(Event::Specular {
                slot: s,
                cx: c.x,
                cy: c.y,
                level,
            });
            false
        })
    }

    /// Ground at slot `s` (point `p`, lookahead `d`, `dz` from the expected ground): it
    /// moves the level, the slope and the line's spread, and is a diagnostic return inside
    /// the interval or when brighter than water allows.
    fn ground_return(
        &mut self,
        s: usize,
        p: Point3<f64>,
        d: f64,
        dz: f64,
        cos_inc: f64,
        range: f64,
    ) {
        let model = self.model;
        let g_max = model.cfg.max_ground_slope;
        // The slope of the recent ground, once it spans enough lookahead to measure one,
        // clamped to what ground does.
        if self.drops.len() == GATE_WINDOW {
            self.drops.pop_front();
        }
        self.drops.push_back(dz.abs());
        self.recent.push((d, p.z));
        if let Some(g) = self.recent.slope() {
            self.slope = Some(g.clamp(-g_max, g_max));
        }
        self.level = p.z;
        self.d_level = d;
        self.far = self.far.max(d);
        let r = normalised_reflectivity(self.line.cloud, s, cos_inc, range, &self.channel);
        // Brighter than the bottom of even the shallowest water there could
        // return, with a bed [`BED_BRIGHTER`] than the recent ground: a return
        // water would not give, as one inside the interval.
        let dry_bright = r.is_some_and(|r| {
            bright_reference(&self.bright)
                .is_some_and(|b| r > BED_BRIGHTER * b * model.shallowest_loss(d))
        });
        if let Some(r) = r {
            if self.bright.len() == BRIGHT_WINDOW {
                self.bright.pop_front();
            }
            self.bright.push_back(r);
        }
        let diag = model.in_interval(d) || dry_bright;
        // A ground return outside the interval matters only to the
        // reflectivity cue: no event (and no allocation) without it.
        if !diag && model.reflectivity.is_none() {
            return;
        }
        self.out.push(Event::Ground {
            slot: s,
            x: p.x,
            y: p.y,
            diag,
            bright: dry_bright,
            cos_inc,
            range,
        });
    }

    /// A missing beam along `u`, cast against the level: a no-return where it meets it
    /// inside the diagnostic interval, a cast beam that says nothing outside it.
    fn missing_beam(&mut self, u: Vector3<f64>) {
        let (o, level) = (self.line.o, self.level);
        if u.z >= -1e-6 || o.z <= level {
            return;
        }
        let t = (o.z - level) / -u.z;
        let hit = o + u * t;
        let d = crate::geom::hypot(hit.x - o.x, hit.y - o.y);
        if self.model.in_interval(d) {
            self.out.push(Event::NoRet {
                x: hit.x,
                y: hit.y,
                level,
                d,
            });
        } else {
            self.out.push(Event::MissingCast);
        }
    }
}

/// What one slot of a scan line contributed.
#[derive(Debug, Clone, Copy)]
pub(super) enum Event {
    MissingCast,
    Unexplained,
    /// A below-level return that the scan line saw nothing above ([`mirror_refuted`]):
    /// ground below the walked level, kept in the terrain.
    BelowGround,
    NoRet {
        x: f64,
        y: f64,
        level: f64,
        /// Lookahead of the ground hit (m).
        d: f64,
    },
    Ground {
        slot: usize,
        x: f64,
        y: f64,
        /// Inside the diagnostic interval, or brighter than water allows.
        diag: bool,
        /// Brighter than water allows.
        bright: bool,
        cos_inc: f64,
        range: f64,
    },
    Bottom {
        slot: usize,
        x: f64,
        y: f64,
        level: f64,
        depth: f64,
        /// d(depth)/d(level): how the depth would move against another level.
        gain: f64,
        /// Found under the prior's water level, not the walked level.
        prior: bool,
    },
    Specular {
        slot: usize,
        cx: f64,
        cy: f64,
        level: f64,
    },
}

/// Shortest run over which the local ground's slope is measured (m).
pub(super) const SLOPE_BASELINE_M: f64 = 1.0;
/// The local ground's slope is that of the ground returns of this much lookahead (m).
pub(super) const SLOPE_WINDOW_M: f64 = 3.0;

/// The ground returns of a scan line's last [`SLOPE_WINDOW_M`] with running sums, so that
/// their least-squares slope costs the same however many returns the window holds (the
/// steep rings of a 64-ring lidar put 20 returns within 3 m, and refitting them at every
/// return was most of the walk). Sums are of offsets from the first point, so that a map
/// kilometres from its origin, or a level far from zero, loses no precision to them.
#[derive(Debug)]
pub(super) struct SlopeWindow {
    pub(super) pts: VecDeque<(f64, f64)>,
    origin: (f64, f64),
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
}

impl SlopeWindow {
    pub(super) fn new(first: (f64, f64)) -> SlopeWindow {
        SlopeWindow {
            pts: VecDeque::from([first]),
            origin: first,
            sx: 0.0,
            sy: 0.0,
            sxx: 0.0,
            sxy: 0.0,
        }
    }

    fn offset(&self, (x, y): (f64, f64)) -> (f64, f64) {
        (x - self.origin.0, y - self.origin.1)
    }

    /// Adds the return `p` = (lookahead, z), then drops the oldest while more than two
    /// remain and the oldest lies more than [`SLOPE_WINDOW_M`] behind `p`.
    pub(super) fn push(&mut self, p: (f64, f64)) {
        let (x, y) = self.offset(p);
        (self.sx, self.sy, self.sxx, self.sxy) =
            (self.sx + x, self.sy + y, self.sxx + x * x, self.sxy + x * y);
        self.pts.push_back(p);
        while self.pts.len() > 2 && self.pts.front().is_some_and(|f| p.0 - f.0 > SLOPE_WINDOW_M) {
            if let Some(f) = self.pts.pop_front() {
                let (x, y) = self.offset(f);
                (self.sx, self.sy, self.sxx, self.sxy) =
                    (self.sx - x, self.sy - y, self.sxx - x * x, self.sxy - x * y);
            }
        }
    }

    /// The least-squares slope dy/dx of the window once it spans [`SLOPE_BASELINE_M`] of
    /// lookahead; `None` before, or without spread in x.
    pub(super) fn slope(&self) -> Option<f64> {
        let (first, last) = (self.pts.front()?, self.pts.back()?);
        if last.0 - first.0 < SLOPE_BASELINE_M {
            return None;
        }
        let n = self.pts.len() as f64;
        let sxx = self.sxx - self.sx * self.sx / n;
        let sxy = self.sxy - self.sx * self.sy / n;
        (sxx > 1e-12).then(|| sxy / sxx)
    }
}

/// Ground returns along a scan line whose spread about the walked level sets the
/// below-level gate ([`below_gate`]).
pub(super) const GATE_WINDOW: usize = 16;

/// Fewest such returns for a measured spread.
pub(super) const GATE_MIN: usize = 5;

/// The depth below the walked level (m) beyond which a return is a below-level return:
/// three standard deviations of how far dry ground there falls from the level it is judged
/// by, and never more than `ceiling` (`below_gate_m`). That spread is the larger of the
/// range noise's vertical part `sigma_v` (times √2: the level is a return too) and the
/// spread the line's last [`GATE_WINDOW`] ground returns showed (1.4826 × their median
/// absolute fall `drops`: rough ground and noise together, measured on this scan). A line
/// with fewer than [`GATE_MIN`] ground returns so far uses the ceiling. Bottom returns of
/// a puddle 5 to 15 cm deep lie 1 to 4 cm below its surface at grazing incidence: a fixed
/// 10 cm gate fused them as ground and no depth was ever found.
///
/// Only ground returns are counted: with the returns below the gate counted too, a line
/// crossing a few metres of shallow water widened its gate to the ceiling after eight
/// bottom returns and fused the rest as ground. Dips in rough ground that fall beyond three
/// standard deviations become bottom returns here; the water stage keeps a cell's bottom
/// evidence only where it lies below the surface its body's shore gives.
pub(super) fn below_gate(drops: &VecDeque<f64>, sigma_v: f64, ceiling: f64) -> f64 {
    let n = drops.len();
    if n < GATE_MIN {
        return ceiling;
    }
    let mut d = [0.0; GATE_WINDOW];
    for (a, b) in d.iter_mut().zip(drops) {
        *a = *b;
    }
    let med = *d[..n]
        .select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b))
        .1;
    // `f64::max` and `min` take the other operand over a NaN: a NaN σ gives the measured
    // spread, never a NaN gate.
    let spread = (1.4826 * med).max(std::f64::consts::SQRT_2 * sigma_v);
    (3.0 * spread).min(ceiling)
}
