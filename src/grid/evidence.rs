//! Per-cell water evidence: exact, mergeable integer counts and sums, and the documented
//! fusion rule that turns them into a water probability at readout.
//!
//! Every field is a count or an integer sum, so merging is exactly commutative and
//! associative, like [`super::CellStats`]. The five event counts are `u16` and saturate
//! (saturating addition of non-negative numbers, `min(a + b, 65535)`, is still commutative
//! and associative); the sums that feed a mean (level, depth) are exact `u32`/`i64`/`u64`.
//!
//! "Never observed" and "observed, no return" stay apart: a cell whose only record is
//! `noret > 0` is *observed* (a lidar beam was cast into it and nothing came back), while a
//! cell with no hits and no evidence at all is unknown.
//!
//! ## Fusion rule
//!
//! The water log-odds of a cell is the prior plus, per cue, the sum over its events of the
//! log-likelihood ratio `ln P(event | water) / P(event | dry)`, each cue's total clamped to
//! `±cue_cap` (neighbouring beams and pixels of one patch are not independent; the cap
//! keeps one cue from making a cell more than `e^cap : 1` certain on its own). The
//! probabilities are sensor physics or per-scan constructions, not fitted to a scene:
//!
//! | event | P(· given water) | P(· given dry) | source |
//! | --- | --- | --- | --- |
//! | missing lidar return, ground hit inside the diagnostic interval | `1 − p_water_return` | `p_dropout` | optics: water returns nothing there, dry ground does |
//! | lidar return inside the diagnostic interval | `p_water_return` | `1 − p_dropout` | same |
//! | reflection ray (stereo or lidar specular) crossing the level here | `p_reflect_detect` | `p_reflect_false` | run geometry: below ground, gap, range wrapping |
//! | refraction-consistent bottom return | `p_bottom_detect` | `p_bottom_false` | optics: depth within what the sensor can see |
//! | cell mostly dark (normalised reflectivity below the scan's threshold) | `p_dark_wet` | `p_dark_dry` | per-scan quantile |
//! | cell mostly not dark | `1 − p_dark_wet` | `1 − p_dark_dry` | same |
//!
//! | a frame's image pixels in this cell mostly labelled water (colour / SWIR dark / MWIR thermal contrast) | `p_<cue>_detect` | `p_<cue>_false` | classifier recall and false-positive rate per cell and frame, see below |
//! | a frame's image pixels in this cell mostly labelled not water | `1 − p_<cue>_detect` | `1 − p_<cue>_false` | same |
//!
//! The reflectivity cue counts once per cell (its returns see one surface and are not
//! independent), so on its own it can never call a cell water: it tips cells that other
//! cues leave uncertain.
//!
//! The image cues count **one vote per cell and frame** (the majority of that frame's
//! pixels projected into the cell; [`crate::project::FrameLabels`]): the pixels of one patch in
//! one image are not independent, frames taken from other positions are closer to it. Each
//! image cue is capped at `±image_cap` instead of `cue_cap`: with the prior of 0.05 a cap
//! of ln 100 would keep an image-only cell at p ≤ 0.84, so a camera could never call water
//! on its own, which the paper's colour classifier does. With the defaults two agreeing
//! colour frames and none against give p = 0.94.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Water evidence of one cell. `Default` is "no evidence".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Evidence {
    /// Missing lidar beams whose ground hit falls in this cell inside the no-return
    /// diagnostic interval ("observed, no return").
    pub noret: u16,
    /// Lidar returns from this cell at a lookahead inside the diagnostic interval (beams
    /// that could have been diagnostic but returned): `noret / (noret + diag_ret)` is the
    /// no-return fraction.
    pub diag_ret: u16,
    /// Reflection rays (stereo reflections, lidar specular returns) crossing the water
    /// level in this cell.
    pub reflect: u16,
    /// Returns whose range- and incidence-normalised reflectivity is below the scan's
    /// dark threshold.
    pub dark: u16,
    /// Returns tested for reflectivity and not dark.
    pub lit: u16,
    /// Frames whose colour labels called this cell water / not water (one vote per frame).
    pub colour_water: u16,
    /// Frames whose colour labels called this cell not water.
    pub colour_dry: u16,
    /// Frames whose SWIR labels called this cell dark (water) / not dark.
    pub swir_dark: u16,
    /// Frames whose SWIR labels called this cell not dark.
    pub swir_lit: u16,
    /// Frames whose MWIR labels called this cell water (thermal contrast) / not water.
    pub mwir_water: u16,
    /// Frames whose MWIR labels called this cell not water.
    pub mwir_dry: u16,
    /// Water-level samples (mm relative to the grid's `z_ref`) that came with `noret`,
    /// `reflect` and bottom-return events: count and exact sum.
    pub level_n: u32,
    /// Sum of those water-level samples, mm relative to `z_ref`.
    pub level_sum_mm: i64,
    /// Refraction-corrected bottom returns: count and Σ depth (mm) below the level each
    /// was corrected against. Depths are clamped to 0..=65535 mm.
    pub depth_n: u32,
    /// Sum of those depths, mm.
    pub depth_sum_mm: u32,
    /// How those depths move with the level: Σ gain (thousandths) and Σ gain · level
    /// (thousandths × mm relative to `z_ref`), where a return's gain is d(depth)/d(level)
    /// ([`crate::optics::bottom_depth_gain`]). With them [`Self::depth_at_m`] gives the
    /// mean depth below any level, exactly as if every return had been corrected against
    /// it: the cue corrects against the local ground it walked, the water stage knows the
    /// water's surface.
    pub depth_gain_sum: u32,
    /// Σ gain · level, thousandths × mm relative to `z_ref`.
    pub depth_gain_level_sum: i64,
}

/// Number of `u16` event counts in [`Evidence`] (see [`Evidence::counts`]).
pub(crate) const EVIDENCE_COUNTS: usize = 11;

/// Bytes of evidence storage per cell in the window's structure-of-arrays layers: the
/// lidar's, the reflections' and the colour camera's event counts and the slot of the
/// cell's level and depth evidence. Stored apart: the level and depth evidence, which few
/// cells have, and the infrared cameras' counts (8 bytes a cell once one votes).
pub(crate) const EVIDENCE_BYTES_PER_CELL: usize = super::layers::DENSE_COUNTS * 2 + 4;

impl Evidence {
    /// Whether the cell has no evidence at all.
    #[inline]
    pub fn is_empty(&self) -> bool {
        *self == Evidence::default()
    }

    /// The commutative, associative combine.
    #[inline]
    pub fn merge(&mut self, o: &Evidence) {
        self.noret = self.noret.saturating_add(o.noret);
        self.diag_ret = self.diag_ret.saturating_add(o.diag_ret);
        self.reflect = self.reflect.saturating_add(o.reflect);
        self.dark = self.dark.saturating_add(o.dark);
        self.lit = self.lit.saturating_add(o.lit);
        self.colour_water = self.colour_water.saturating_add(o.colour_water);
        self.colour_dry = self.colour_dry.saturating_add(o.colour_dry);
        self.swir_dark = self.swir_dark.saturating_add(o.swir_dark);
        self.swir_lit = self.swir_lit.saturating_add(o.swir_lit);
        self.mwir_water = self.mwir_water.saturating_add(o.mwir_water);
        self.mwir_dry = self.mwir_dry.saturating_add(o.mwir_dry);
        self.level_n = self.level_n.saturating_add(o.level_n);
        self.level_sum_mm = self.level_sum_mm.saturating_add(o.level_sum_mm);
        self.depth_n = self.depth_n.saturating_add(o.depth_n);
        self.depth_sum_mm = self.depth_sum_mm.saturating_add(o.depth_sum_mm);
        self.depth_gain_sum = self.depth_gain_sum.saturating_add(o.depth_gain_sum);
        self.depth_gain_level_sum = self
            .depth_gain_level_sum
            .saturating_add(o.depth_gain_level_sum);
    }

    /// The `u16` event counts in storage order: noret, diag_ret, reflect, dark, lit,
    /// colour water/dry, SWIR dark/lit, MWIR water/dry.
    #[inline]
    pub fn counts(&self) -> [u16; EVIDENCE_COUNTS] {
        [
            self.noret,
            self.diag_ret,
            self.reflect,
            self.dark,
            self.lit,
            self.colour_water,
            self.colour_dry,
            self.swir_dark,
            self.swir_lit,
            self.mwir_water,
            self.mwir_dry,
        ]
    }

    /// Sets the event counts from [`Self::counts`] order.
    #[inline]
    pub(crate) fn set_counts(&mut self, c: [u16; EVIDENCE_COUNTS]) {
        [
            self.noret,
            self.diag_ret,
            self.reflect,
            self.dark,
            self.lit,
            self.colour_water,
            self.colour_dry,
            self.swir_dark,
            self.swir_lit,
            self.mwir_water,
            self.mwir_dry,
        ] = c;
    }

    /// Records one water-level sample (mm relative to `z_ref`).
    #[inline]
    pub fn add_level(&mut self, level_mm: i32) {
        self.level_n = self.level_n.saturating_add(1);
        self.level_sum_mm = self.level_sum_mm.saturating_add(level_mm as i64);
    }

    /// Records one depth that does not depend on the water level (metres; clamped to
    /// 0..=65.535 m): a sounding, or a test's known depth.
    #[inline]
    pub fn add_depth(&mut self, depth_m: f64) {
        let mm = (depth_m * 1000.0).round().clamp(0.0, 65535.0) as u32;
        self.depth_n = self.depth_n.saturating_add(1);
        self.depth_sum_mm = self.depth_sum_mm.saturating_add(mm);
    }

    /// Records one refraction-corrected bottom return: its depth below the level it was
    /// corrected against (`level_mm`, relative to `z_ref`), and its gain d(depth)/d(level)
    /// ([`crate::optics::bottom_depth_gain`]; clamped to 0..=10⁶).
    #[inline]
    pub fn add_bottom_return(&mut self, depth_m: f64, level_mm: i32, gain: f64) {
        self.add_depth(depth_m);
        let g = (gain * 1000.0).round().clamp(0.0, 1e9) as u32;
        self.depth_gain_sum = self.depth_gain_sum.saturating_add(g);
        self.depth_gain_level_sum = self
            .depth_gain_level_sum
            .saturating_add(g as i64 * level_mm as i64);
    }

    /// Mean water level, mm relative to the grid's `z_ref`.
    pub(crate) fn level_mm(&self) -> Option<f64> {
        (self.level_n > 0).then(|| self.level_sum_mm as f64 / self.level_n as f64)
    }

    /// Mean bottom-return depth below the levels the returns were corrected against,
    /// metres.
    pub fn depth_m(&self) -> Option<f64> {
        (self.depth_n > 0).then(|| self.depth_sum_mm as f64 / self.depth_n as f64 * 1e-3)
    }

    /// Mean bottom-return depth below the level `level_mm` (relative to `z_ref`), metres:
    /// each return's depth moved by its gain times the change of level. Not clamped.
    pub fn depth_at_m(&self, level_mm: f64) -> Option<f64> {
        (self.depth_n > 0).then(|| {
            let shift = self.depth_gain_sum as f64 * 1e-3 * level_mm
                - self.depth_gain_level_sum as f64 * 1e-3;
            (self.depth_sum_mm as f64 + shift) / self.depth_n as f64 * 1e-3
        })
    }

    /// Fraction of diagnostic beams that came back empty; `None` when no beam was diagnostic.
    pub fn noret_fraction(&self) -> Option<f64> {
        let n = self.noret as u32 + self.diag_ret as u32;
        (n > 0).then(|| self.noret as f64 / n as f64)
    }

    /// A cue's two event counts: [for water, against]. The reflection and bottom-return
    /// cues count events for water only (`[n, 0]`); the reflectivity cue's pair is [dark,
    /// lit] and votes once per cell, by majority.
    #[inline]
    pub fn events(&self, cue: Cue) -> [u32; 2] {
        let n = |a: u16, b: u16| [u32::from(a), u32::from(b)];
        match cue {
            Cue::NoReturn => n(self.noret, self.diag_ret),
            Cue::Reflection => n(self.reflect, 0),
            Cue::Bottom => [self.depth_n, 0],
            Cue::Reflectivity => n(self.dark, self.lit),
            Cue::Colour => n(self.colour_water, self.colour_dry),
            Cue::Swir => n(self.swir_dark, self.swir_lit),
            Cue::Mwir => n(self.mwir_water, self.mwir_dry),
        }
    }

    /// Records one frame's vote of an image cue (colour, SWIR, MWIR): water or not.
    /// Other cues do not vote per frame; for them this does nothing.
    #[inline]
    pub fn add_image_vote(&mut self, cue: Cue, water: bool) {
        let (w, d) = match cue {
            Cue::Colour => (&mut self.colour_water, &mut self.colour_dry),
            Cue::Swir => (&mut self.swir_dark, &mut self.swir_lit),
            Cue::Mwir => (&mut self.mwir_water, &mut self.mwir_dry),
            _ => return,
        };
        let c = if water { w } else { d };
        *c = c.saturating_add(1);
    }

    /// Per-cue log-likelihood ratios (before the prior), see the module documentation.
    pub fn cue_log_odds(&self, f: &Fusion) -> CueLogOdds {
        self.cue_log_odds_in(&f.logs())
    }

    /// [`Self::cue_log_odds`] with the rule's logarithms computed once for many cells.
    pub(crate) fn cue_log_odds_in(&self, f: &FusionLogs) -> CueLogOdds {
        // n · ln(a / b), with no product for a count of 0 (most cells of a map have no
        // evidence of most cues). The sum is the same: the ratios are finite, so
        // 0 · ln(a / b) is ±0.
        let term = |n: u32, ln: f64| if n == 0 { 0.0 } else { f64::from(n) * ln };
        CueLogOdds(Cue::ALL.map(|cue| {
            let [w, d] = self.events(cue);
            let [lw, ld] = f.ln[cue as usize];
            match cue {
                // The returns of one cell see one surface: one observation, by majority.
                Cue::Reflectivity => match (w, d) {
                    (0, 0) => 0.0,
                    (d, l) if d > l => lw,
                    _ => ld,
                },
                _ => {
                    let cap = if cue.is_image() {
                        f.image_cap
                    } else {
                        f.cue_cap
                    };
                    (term(w, lw) + term(d, ld)).clamp(-cap, cap)
                }
            }
        }))
    }

    /// Fused water log-odds: the prior plus every cue's capped log-likelihood ratio.
    pub fn water_log_odds(&self, f: &Fusion) -> f64 {
        self.water_log_odds_in(&f.logs())
    }

    /// [`Self::water_log_odds`] with the rule's logarithms computed once for many cells.
    pub(crate) fn water_log_odds_in(&self, f: &FusionLogs) -> f64 {
        self.cue_log_odds_in(f).0.iter().fold(f.prior, |l, c| l + c)
    }

    /// Fused water probability, 0..1.
    pub fn water_probability(&self, f: &Fusion) -> f64 {
        // No evidence: the prior (most cells of a map), without a logarithm.
        if *self == Evidence::default() {
            return f.prior;
        }
        self.water_probability_in(&f.logs())
    }

    /// [`Self::water_probability`] with the rule's logarithms computed once for many cells
    /// (the water stage asks every observed cell every frame): the same value, bit for bit.
    pub fn water_probability_in(&self, f: &FusionLogs) -> f64 {
        if *self == Evidence::default() {
            return f.prior_p;
        }
        let l = self.water_log_odds_in(f);
        1.0 / (1.0 + (-l).exp())
    }

    /// [`Self::water_probability_in`] without the bottom returns' term: what the cell's
    /// other evidence says where the water stage found its bottom returns no evidence.
    pub(crate) fn water_probability_without_bottom_in(&self, f: &FusionLogs) -> f64 {
        Evidence {
            depth_n: 0,
            ..*self
        }
        .water_probability_in(f)
    }
}

/// One term of the fusion rule: a kind of water evidence. It indexes a cell's event
/// counts ([`Evidence::events`]), the rule's logarithms ([`Fusion::logs`]) and each cue's
/// contribution ([`CueLogOdds`]), and names them in reports. [`Cue::ALL`] is the order in
/// which the contributions are added.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cue {
    /// Missing and present diagnostic lidar returns.
    NoReturn,
    /// Reflection rays (stereo reflections, lidar specular returns) crossing the level.
    Reflection,
    /// Refraction-consistent bottom returns.
    Bottom,
    /// Dark and lit reflectivity returns.
    Reflectivity,
    /// Colour image votes.
    Colour,
    /// SWIR image votes.
    Swir,
    /// MWIR image votes.
    Mwir,
}

impl Cue {
    /// Every cue, in the order their log-odds are added.
    pub const ALL: [Cue; 7] = [
        Cue::NoReturn,
        Cue::Reflection,
        Cue::Bottom,
        Cue::Reflectivity,
        Cue::Colour,
        Cue::Swir,
        Cue::Mwir,
    ];

    /// The cue's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Cue::NoReturn => "noret",
            Cue::Reflection => "reflect",
            Cue::Bottom => "bottom",
            Cue::Reflectivity => "reflectivity",
            Cue::Colour => "colour",
            Cue::Swir => "swir",
            Cue::Mwir => "mwir",
        }
    }

    /// Whether the cue is an image's per-frame vote (capped at `image_cap`, not `cue_cap`).
    pub(crate) const fn is_image(self) -> bool {
        matches!(self, Cue::Colour | Cue::Swir | Cue::Mwir)
    }
}

/// The logarithms of a [`Fusion`] rule: each cue's log-likelihood ratio per observation,
/// ln(P(obs | water) / P(obs | dry)), and the prior's log-odds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionLogs {
    prior_p: f64,
    prior: f64,
    /// Per cue, indexed by [`Cue`]: the ratio of an event for water and of one against
    /// ([`Evidence::events`]; 0 where the cue has no event against).
    ln: [[f64; 2]; 7],
    cue_cap: f64,
    image_cap: f64,
}

/// Each cue's contribution to a cell's log-odds (natural log), indexed by [`Cue`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CueLogOdds(pub [f64; 7]);

impl std::ops::Index<Cue> for CueLogOdds {
    type Output = f64;
    fn index(&self, cue: Cue) -> &f64 {
        &self.0[cue as usize]
    }
}

/// The likelihoods of the fusion rule (see the module documentation). The defaults are
/// stated assumptions about sensors, not fits to a scene:
///
/// * `p_dropout = 0.05`: a dry ground beam returns nothing 5 % of the time (the RELLIS-3D
///   Ouster ground rings lose 1–6 %);
/// * `p_water_return = 0.10`: a water beam inside the interval still returns (a ripple, a
///   floating leaf) 10 % of the time;
/// * reflections: a confirmed run (below ground, behind a gap, range wrapping backward) is
///   found on 80 % of reflecting water rays and on 2 % of dry rays (stereo mismatches);
/// * bottom returns: 80 % against 10 % (a return below the shore level, at a depth the
///   optics say is visible, on dry ground needs a hole, a ditch or rough ground);
/// * reflectivity: the dark threshold is set so that about 15 % of dry ground is dark, and
///   wet ground is dark 60 % of the time: a weak cue by design;
/// * image cues, per cell and frame (the majority of the frame's pixels in the cell):
///   colour 0.8 against 0.05 (the paper's Table 1 rule found 0.806 pixel precision and
///   0.414 recall on the RELLIS-3D puddles, where the label polygon includes wet mud; on
///   whole cells of open water seen from several metres it finds most of them); the 0.05
///   stands only where the log cannot measure the colour labels' false alarms: where its
///   lidar samples dry ground in the colour image, the measured rate's 95 % upper
///   bound replaces it ([`Fusion::measured`]); SWIR dark
///   0.8 against 0.05 (a reflection of the measured sky at the pixel's incidence; where the
///   colour camera votes on the same cell, a water vote of either stands only where the
///   other agrees, so dark dry surfaces and pale sky-coloured ones do not vote water); MWIR 0.7 against 0.05 (the
///   contrast test at 3 σ of the local terrain band);
/// * `prior = 0.05`, `cue_cap = ln 100`, `image_cap = ln 1000` (see the module documentation).
///
/// `docs/cues.md` counts each cue's events on true water and on dry ground over the
/// evaluation matrix beside these (`tarn build --tiles`, `tarn eval`), and `docs/limits.md`
/// says where and why the defaults differ from those counts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Fusion {
    /// Prior probability that a cell is water, before any evidence.
    pub prior: f64,
    /// Probability that a diagnostic lidar beam on dry ground returns nothing.
    pub p_dropout: f64,
    /// Probability that a diagnostic lidar beam on water still returns.
    pub p_water_return: f64,
    /// Probability that a reflection ray is found on reflecting water.
    pub p_reflect_detect: f64,
    /// Probability that a reflection ray is found on dry ground.
    pub p_reflect_false: f64,
    /// Probability of a refraction-consistent bottom return on water.
    pub p_bottom_detect: f64,
    /// Probability of such a return on dry ground.
    pub p_bottom_false: f64,
    /// Probability that wet ground reads dark in reflectivity.
    pub p_dark_wet: f64,
    /// Probability that dry ground reads dark (keep equal to the reflectivity cue's
    /// `dark_quantile`).
    pub p_dark_dry: f64,
    /// Probability that a frame's colour labels call a water cell water.
    pub p_colour_detect: f64,
    /// Probability that a frame's colour labels call a dry cell water: the stated rate,
    /// used where the log cannot measure it (see `colour_false_from_log`).
    pub p_colour_false: f64,
    /// Probability that a frame's SWIR labels call a water cell dark.
    pub p_swir_detect: f64,
    /// Probability that a frame's SWIR labels call a dry cell dark: the stated rate, used
    /// where the log cannot measure it (see `swir_false_from_log`).
    pub p_swir_false: f64,
    /// Probability that a frame's MWIR labels call a water cell water.
    pub p_mwir_detect: f64,
    /// Probability that a frame's MWIR labels call a dry cell water.
    pub p_mwir_false: f64,
    /// Largest magnitude of one non-image cue's log-odds (natural log).
    pub cue_cap: f64,
    /// Largest magnitude of one image cue's log-odds (natural log).
    pub image_cap: f64,
    /// Whether the colour cue's false-alarm rate is measured from the log where its lidar
    /// sampled dry ground in the colour image ([`Fusion::measured`]), in place of
    /// `p_colour_false`.
    pub colour_false_from_log: bool,
    /// The same for the SWIR cue's rate, where the lidar sampled dry ground in the SWIR
    /// image, in place of `p_swir_false`.
    pub swir_false_from_log: bool,
}

impl Default for Fusion {
    fn default() -> Self {
        Fusion {
            prior: 0.05,
            p_dropout: 0.05,
            p_water_return: 0.10,
            p_reflect_detect: 0.8,
            p_reflect_false: 0.02,
            p_bottom_detect: 0.8,
            p_bottom_false: 0.10,
            p_dark_wet: 0.6,
            p_dark_dry: 0.15,
            p_colour_detect: 0.8,
            p_colour_false: 0.05,
            p_swir_detect: 0.8,
            p_swir_false: 0.05,
            p_mwir_detect: 0.7,
            p_mwir_false: 0.05,
            cue_cap: 100f64.ln(),
            image_cap: 1000f64.ln(),
            colour_false_from_log: true,
            swir_false_from_log: true,
        }
    }
}

impl Fusion {
    /// The rule's logarithms, for [`Evidence::water_probability_in`] over many cells.
    pub fn logs(&self) -> FusionLogs {
        let ln = |a: f64, b: f64| (a / b).ln();
        // A cue whose events are complementary: for water with P(pw | water), P(pd | dry),
        // against with the complements.
        let pair = |pw: f64, pd: f64| [ln(pw, pd), ln(1.0 - pw, 1.0 - pd)];
        FusionLogs {
            prior_p: self.prior,
            prior: ln(self.prior, 1.0 - self.prior),
            ln: Cue::ALL.map(|cue| match cue {
                Cue::NoReturn => [
                    ln(1.0 - self.p_water_return, self.p_dropout),
                    ln(self.p_water_return, 1.0 - self.p_dropout),
                ],
                Cue::Reflection => [ln(self.p_reflect_detect, self.p_reflect_false), 0.0],
                Cue::Bottom => [ln(self.p_bottom_detect, self.p_bottom_false), 0.0],
                Cue::Reflectivity => pair(self.p_dark_wet, self.p_dark_dry),
                Cue::Colour => pair(self.p_colour_detect, self.p_colour_false),
                Cue::Swir => pair(self.p_swir_detect, self.p_swir_false),
                Cue::Mwir => pair(self.p_mwir_detect, self.p_mwir_false),
            }),
            cue_cap: self.cue_cap,
            image_cap: self.image_cap,
        }
    }

    /// Every probability must lie strictly inside (0, 1) and the cap be positive.
    pub fn validate(&self) -> Result<()> {
        for (name, p) in [
            ("prior", self.prior),
            ("p_dropout", self.p_dropout),
            ("p_water_return", self.p_water_return),
            ("p_reflect_detect", self.p_reflect_detect),
            ("p_reflect_false", self.p_reflect_false),
            ("p_bottom_detect", self.p_bottom_detect),
            ("p_bottom_false", self.p_bottom_false),
            ("p_dark_wet", self.p_dark_wet),
            ("p_dark_dry", self.p_dark_dry),
            ("p_colour_detect", self.p_colour_detect),
            ("p_colour_false", self.p_colour_false),
            ("p_swir_detect", self.p_swir_detect),
            ("p_swir_false", self.p_swir_false),
            ("p_mwir_detect", self.p_mwir_detect),
            ("p_mwir_false", self.p_mwir_false),
        ] {
            if !(p > 0.0 && p < 1.0) {
                return Err(Error::invalid(
                    format!("fusion {name}"),
                    format!("{p} is not a probability strictly between 0 and 1"),
                ));
            }
        }
        for (name, cap) in [("cue_cap", self.cue_cap), ("image_cap", self.image_cap)] {
            if !(cap.is_finite() && cap > 0.0) {
                return Err(Error::invalid(
                    format!("fusion {name}"),
                    format!("{cap} is not a finite positive number"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn arb_evidence() -> impl Strategy<Value = Evidence> {
        (
            prop::array::uniform11(any::<u16>()),
            0u32..1000,
            -1_000_000i64..1_000_000,
            prop::collection::vec((0.0f64..3.0, -5000i32..5000, 0.0f64..20.0), 0..5),
        )
            .prop_map(|(c, ln, ls, depths)| {
                let mut e = Evidence {
                    level_n: ln,
                    level_sum_mm: ls,
                    ..Evidence::default()
                };
                e.set_counts(c);
                for (d, level, gain) in depths {
                    e.add_bottom_return(d, level, gain);
                }
                e
            })
    }

    proptest! {
        #[test]
        fn merge_is_commutative_and_associative(
            a in arb_evidence(), b in arb_evidence(), c in arb_evidence()
        ) {
            let mut ab_c = a; ab_c.merge(&b); ab_c.merge(&c);
            let mut bc = b; bc.merge(&c);
            let mut a_bc = a; a_bc.merge(&bc);
            let mut cba = c; cba.merge(&b); cba.merge(&a);
            prop_assert_eq!(ab_c, a_bc);
            prop_assert_eq!(ab_c, cba);
        }

        #[test]
        fn more_no_returns_never_lower_the_water_probability(n in 0u16..200, r in 0u16..200) {
            let f = Fusion::default();
            let e = Evidence { noret: n, diag_ret: r, ..Evidence::default() };
            let e2 = Evidence { noret: n + 1, diag_ret: r, ..Evidence::default() };
            prop_assert!(e2.water_probability(&f) >= e.water_probability(&f));
            let e3 = Evidence { noret: n, diag_ret: r + 1, ..Evidence::default() };
            prop_assert!(e3.water_probability(&f) <= e.water_probability(&f));
        }
    }

    #[test]
    fn no_evidence_reads_the_prior_and_one_cue_is_capped() {
        let f = Fusion::default();
        assert!((Evidence::default().water_probability(&f) - f.prior).abs() < 1e-12);
        let e = Evidence {
            reflect: 1000,
            ..Evidence::default()
        };
        // ln(0.05/0.95) + ln 100 = ln(100/19): p = 100/119.
        assert!((e.water_probability(&f) - 100.0 / 119.0).abs() < 1e-9);
        // One no-return and one return inside the interval: ln(0.9/0.05) + ln(0.1/0.95).
        let e = Evidence {
            noret: 1,
            diag_ret: 1,
            ..Evidence::default()
        };
        let l = e.cue_log_odds(&f)[Cue::NoReturn];
        assert!((l - (18.0f64 * 0.1 / 0.95).ln()).abs() < 1e-12);
    }

    #[test]
    fn storage_per_cell() {
        assert_eq!(EVIDENCE_BYTES_PER_CELL, 18);
        // Occupancy, the elevation record (one cache line), evidence.
        assert_eq!(crate::grid::RollingGrid::bytes_per_cell(), 1 + 64 + 18);
        let mut e = Evidence::default();
        let c: [u16; EVIDENCE_COUNTS] = std::array::from_fn(|i| i as u16 + 1);
        e.set_counts(c);
        assert_eq!(e.counts(), c);
        assert_eq!((e.noret, e.lit, e.mwir_dry), (1, 5, 11));
        eprintln!(
            "tile map cell: {} bytes (CellStats), evidence {} bytes (Evidence)",
            std::mem::size_of::<crate::grid::CellStats>(),
            std::mem::size_of::<Evidence>()
        );
    }

    #[test]
    fn image_votes_per_frame() {
        let f = Fusion::default();
        // Two colour frames for water, none against: ln 0.05/0.95 + 2 ln 16 → p = 256/275.
        let e = Evidence {
            colour_water: 2,
            ..Evidence::default()
        };
        assert!((e.water_probability(&f) - 256.0 / 275.0).abs() < 1e-12);
        assert!(e.water_probability(&f) >= 0.9);
        // One frame: not enough on its own (16/35).
        let e1 = Evidence {
            colour_water: 1,
            ..Evidence::default()
        };
        assert!((e1.water_probability(&f) - 16.0 / 35.0).abs() < 1e-12);
        // Capped at ln 1000 whatever the number of frames.
        let many = Evidence {
            swir_dark: 500,
            ..Evidence::default()
        };
        assert!((many.cue_log_odds(&f)[Cue::Swir] - 1000f64.ln()).abs() < 1e-12);
        let against = Evidence {
            mwir_dry: 500,
            ..Evidence::default()
        };
        assert!((against.cue_log_odds(&f)[Cue::Mwir] + 1000f64.ln()).abs() < 1e-12);
        // A frame against offsets more than half a frame for.
        let mixed = Evidence {
            colour_water: 1,
            colour_dry: 1,
            ..Evidence::default()
        };
        assert!((mixed.cue_log_odds(&f)[Cue::Colour] - (16.0f64 * 0.2 / 0.95).ln()).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn more_image_votes_for_water_never_lower_the_probability(
            w in 0u16..50, d in 0u16..50, cue in 0usize..3
        ) {
            let f = Fusion::default();
            let mut c = [0u16; EVIDENCE_COUNTS];
            c[5 + 2 * cue] = w;
            c[6 + 2 * cue] = d;
            let mut e = Evidence::default();
            e.set_counts(c);
            let mut more = e;
            c[5 + 2 * cue] = w + 1;
            more.set_counts(c);
            prop_assert!(more.water_probability(&f) >= e.water_probability(&f));
            let mut against = e;
            c[5 + 2 * cue] = w;
            c[6 + 2 * cue] = d + 1;
            against.set_counts(c);
            prop_assert!(against.water_probability(&f) <= e.water_probability(&f));
        }
    }

    /// The fusion rule as first written, each logarithm taken where it is used: the
    /// reference for the rule's logarithms computed once ([`Fusion::logs`]).
    fn reference_probability(e: &Evidence, f: &Fusion) -> f64 {
        if *e == Evidence::default() {
            return f.prior;
        }
        let cap = |v: f64| v.clamp(-f.cue_cap, f.cue_cap);
        let ln = |a: f64, b: f64| (a / b).ln();
        let term = |n: u32, a: f64, b: f64| if n == 0 { 0.0 } else { f64::from(n) * ln(a, b) };
        let image = |w: u16, d: u16, pd: f64, pf: f64| {
            (term(w.into(), pd, pf) + term(d.into(), 1.0 - pd, 1.0 - pf))
                .clamp(-f.image_cap, f.image_cap)
        };
        let colour = image(
            e.colour_water,
            e.colour_dry,
            f.p_colour_detect,
            f.p_colour_false,
        );
        let swir = image(e.swir_dark, e.swir_lit, f.p_swir_detect, f.p_swir_false);
        let mwir = image(e.mwir_water, e.mwir_dry, f.p_mwir_detect, f.p_mwir_false);
        let noret = cap(term(e.noret.into(), 1.0 - f.p_water_return, f.p_dropout)
            + term(e.diag_ret.into(), f.p_water_return, 1.0 - f.p_dropout));
        let reflect = cap(term(
            e.reflect.into(),
            f.p_reflect_detect,
            f.p_reflect_false,
        ));
        let bottom = cap(term(e.depth_n, f.p_bottom_detect, f.p_bottom_false));
        let reflectivity = match (e.dark, e.lit) {
            (0, 0) => 0.0,
            (d, l) if d > l => ln(f.p_dark_wet, f.p_dark_dry),
            _ => ln(1.0 - f.p_dark_wet, 1.0 - f.p_dark_dry),
        };
        let l = (f.prior / (1.0 - f.prior)).ln()
            + noret
            + reflect
            + bottom
            + reflectivity
            + colour
            + swir
            + mwir;
        1.0 / (1.0 + (-l).exp())
    }

    proptest! {
        #[test]
        fn logs_computed_once_give_the_rule_bit_for_bit(
            e in arb_evidence(),
            small in prop::array::uniform11(any::<bool>()),
            p in prop::array::uniform15(0.001f64..0.999),
            caps in (0.1f64..20.0, 0.1f64..20.0),
        ) {
            // Most cells hold few kinds of evidence and small counts (ties among them).
            let mut e = e;
            let c = e.counts();
            e.set_counts(std::array::from_fn(|j| if small[j] { c[j] % 3 } else { c[j] }));
            let f = Fusion {
                prior: p[0],
                p_dropout: p[1],
                p_water_return: p[2],
                p_reflect_detect: p[3],
                p_reflect_false: p[4],
                p_bottom_detect: p[5],
                p_bottom_false: p[6],
                p_dark_wet: p[7],
                p_dark_dry: p[8],
                p_colour_detect: p[9],
                p_colour_false: p[10],
                p_swir_detect: p[11],
                p_swir_false: p[12],
                p_mwir_detect: p[13],
                p_mwir_false: p[14],
                cue_cap: caps.0,
                image_cap: caps.1,
                colour_false_from_log: true,
                swir_false_from_log: true,
            };
            let r = reference_probability(&e, &f);
            prop_assert_eq!(e.water_probability(&f).to_bits(), r.to_bits());
            prop_assert_eq!(e.water_probability_in(&f.logs()).to_bits(), r.to_bits());
        }
    }

    #[test]
    fn depth_statistics_of_known_samples() {
        let mut e = Evidence::default();
        for d in [0.10, 0.20, 0.30] {
            e.add_depth(d);
        }
        assert!((e.depth_m().unwrap() - 0.2).abs() < 1e-12);
        // Level-independent depths stay where they are whatever the level.
        assert!((e.depth_at_m(-300.0).unwrap() - 0.2).abs() < 1e-12);
        e.add_depth(-1.0);
        assert_eq!(e.depth_n, 4);
        assert_eq!(e.depth_sum_mm, 600);
        assert_eq!(Evidence::default().depth_at_m(0.0), None);
    }

    #[test]
    fn bottom_returns_move_with_the_level_by_their_gain() {
        let mut e = Evidence::default();
        // 0.50 m below a level of +200 mm with gain 2, 0.30 m below −100 mm with gain 1.
        e.add_bottom_return(0.50, 200, 2.0);
        e.add_bottom_return(0.30, -100, 1.0);
        // At each one's own level the mean of the two moved depths.
        assert!((e.depth_at_m(200.0).unwrap() - (0.50 + (0.30 + 0.30)) / 2.0).abs() < 1e-9);
        assert!((e.depth_at_m(-100.0).unwrap() - ((0.50 - 0.60) + 0.30) / 2.0).abs() < 1e-9);
        // At level 0: (0.5 − 0.4 + 0.3 + 0.1) / 2.
        assert!((e.depth_at_m(0.0).unwrap() - 0.25).abs() < 1e-9);
        assert!((e.depth_m().unwrap() - 0.40).abs() < 1e-12);
    }

    #[test]
    fn invalid_fusion_is_rejected() {
        let f = Fusion {
            p_dropout: 0.0,
            ..Fusion::default()
        };
        let e = f.validate().unwrap_err().to_string();
        assert!(e.contains("p_dropout"), "{e}");
    }
}
