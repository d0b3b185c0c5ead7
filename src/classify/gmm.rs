//! Supervised colour classifier: one Gaussian mixture per class in RGB.
//!
//! Training ([`ColorModel::train`]) fits each class by EM with full covariances, started from
//! k-means++ seeds refined by a few Lloyd steps, for 1..=`max_components` components, and
//! keeps the count with the lowest BIC (−2 ln L + p ln n, p = 10k − 1 free parameters).
//! Samples are the class's distinct colours with their pixel counts (weighted EM), so a
//! million-pixel region costs what its palette costs.
//!
//! Regularisation: every covariance gets `reg_eps`·I added and its eigenvalues floored at
//! `min_var` (both in 8-bit units²), so a class of one colour — clipped sky is
//! (255, 255, 255) everywhere — or a component that collapses onto a plane of colours stays
//! a proper density. Components that lose all their mass are dropped.
//!
//! Classification picks the class with the highest prior × likelihood. Models are JSON
//! (serde); loading checks every number and rebuilds the cached inverses.

use std::path::Path;

use image::RgbImage;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Label, LabelImage};
use crate::error::{Error, Result};

/// Anything that labels one RGB colour.
pub trait PixelClassifier: Sync {
    /// The label of an RGB colour (8 bits per channel).
    fn classify_pixel(&self, rgb: [u8; 3]) -> Label;

    /// True when the label depends on the colour only through R + G + B and min(R, G, B)
    /// (brightness and saturation): a lookup table is then compiled from one evaluation
    /// per (sum, min) pair, 766 × 256, instead of one per bin (2^24 at 8 bits).
    fn by_sum_and_min(&self) -> bool {
        false
    }
}

impl PixelClassifier for super::color::RuleClassifier {
    fn classify_pixel(&self, rgb: [u8; 3]) -> Label {
        super::color::RuleClassifier::classify_pixel(self, rgb)
    }

    fn by_sum_and_min(&self) -> bool {
        true
    }
}

/// Labels a whole image with any pixel classifier (rows in parallel).
pub(crate) fn classify_image(c: &impl PixelClassifier, img: &RgbImage) -> LabelImage {
    let w = (img.width() as usize).max(1);
    let raw = img.as_raw();
    let mut data = vec![Label::Other; raw.len() / 3];
    data.par_chunks_mut(w)
        .zip(raw.par_chunks(3 * w))
        .for_each(|(out, row)| {
            for (o, p) in out.iter_mut().zip(row.chunks_exact(3)) {
                *o = c.classify_pixel([p[0], p[1], p[2]]);
            }
        });
    LabelImage {
        width: img.width() as usize,
        height: img.height() as usize,
        data,
    }
}

/// Training parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Largest number of components tried per class (BIC picks 1..=this).
    pub max_components: usize,
    /// EM iterations at most.
    pub max_iter: usize,
    /// EM stops when the mean log-likelihood per pixel improves by less than this.
    pub tol: f64,
    /// Added to every covariance diagonal (8-bit units²).
    pub reg_eps: f64,
    /// Smallest eigenvalue of a covariance (8-bit units²).
    pub min_var: f64,
    /// At most this many pixels per class are used (an even stride through the class's
    /// pixels), before they are reduced to distinct colours.
    pub max_samples: usize,
    /// Class priors from the training pixel counts (true) or equal (false).
    pub priors_from_counts: bool,
    /// Seed of the k-means++ draws (training is deterministic for a seed).
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            max_components: 6,
            max_iter: 200,
            tol: 1e-6,
            reg_eps: 0.5,
            min_var: 1.0,
            max_samples: 200_000,
            priors_from_counts: true,
            seed: 0x7a_72_6e,
        }
    }
}

impl TrainConfig {
    /// Checks every parameter's range; an `Error::Invalid` names the first one out of range.
    pub fn validate(&self) -> Result<()> {
        let bad = |w: &str, m: String| Err(Error::invalid(format!("train config {w}"), m));
        if self.max_components == 0 || self.max_components > 64 {
            return bad(
                "max_components",
                format!("{} (must be 1..=64)", self.max_components),
            );
        }
        if self.max_iter == 0 {
            return bad("max_iter", "0".into());
        }
        if !(self.tol.is_finite() && self.tol >= 0.0) {
            return bad("tol", format!("{}", self.tol));
        }
        if !(self.reg_eps.is_finite() && self.reg_eps >= 0.0) {
            return bad("reg_eps", format!("{}", self.reg_eps));
        }
        if !(self.min_var.is_finite() && self.min_var > 0.0) {
            return bad("min_var", format!("{} (must be positive)", self.min_var));
        }
        if self.max_samples == 0 {
            return bad("max_samples", "0".into());
        }
        Ok(())
    }
}

/// One Gaussian component as stored in model files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Component {
    /// Mixture weight within the class, positive.
    pub weight: f64,
    /// Mean colour, RGB in 8-bit units.
    pub mean: [f64; 3],
    /// Full covariance, row-major, symmetric, 8-bit units².
    pub cov: [[f64; 3]; 3],
}

/// One class: its label, a name, its prior and its mixture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassModel {
    /// The label this class gives a pixel (not [`Label::Unknown`]).
    pub label: Label,
    /// Name of the class, used in messages.
    pub name: String,
    /// Prior weight of the class, positive.
    pub prior: f64,
    /// The class's Gaussian components (at least one).
    pub components: Vec<Component>,
}

/// The stored form of a [`ColorModel`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColorModelData {
    /// Format tag, `tarn-color-gmm-1`.
    pub format: String,
    /// One entry per class, labels distinct.
    pub classes: Vec<ClassModel>,
}

const FORMAT: &str = "tarn-color-gmm-1";

/// A component ready to evaluate: ln(weight) − ½ ln((2π)³ det Σ), mean, Σ⁻¹.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Dens {
    log_coef: f64,
    mean: [f64; 3],
    /// Σ⁻¹ as (xx, yy, zz, xy, xz, yz).
    prec: [f64; 6],
}

impl Dens {
    fn new(c: &Component) -> Result<Dens> {
        let m = Matrix3::from_fn(|i, j| c.cov[i][j]);
        let asym = (m - m.transpose()).abs().max();
        let ok = c.weight.is_finite()
            && c.weight > 0.0
            && c.mean.iter().all(|v| v.is_finite())
            && m.iter().all(|v| v.is_finite())
            && asym <= 1e-6 * m.abs().max().max(1.0);
        if !ok {
            return Err(Error::invalid(
                "mixture component",
                format!("weight {}, mean {:?}, cov {:?}: weight must be positive and everything finite and symmetric", c.weight, c.mean, c.cov),
            ));
        }
        let chol = m.cholesky().ok_or_else(|| {
            Error::invalid(
                "mixture component",
                format!("covariance {:?} is not positive definite", c.cov),
            )
        })?;
        let det: f64 = chol.l().diagonal().iter().map(|d| d * d).product();
        let p = chol.inverse();
        Ok(Dens {
            log_coef: c.weight.ln() - 0.5 * (3.0 * (2.0 * std::f64::consts::PI).ln() + det.ln()),
            mean: c.mean,
            prec: [
                p[(0, 0)],
                p[(1, 1)],
                p[(2, 2)],
                p[(0, 1)],
                p[(0, 2)],
                p[(1, 2)],
            ],
        })
    }

    #[inline]
    fn log_pdf(&self, x: &[f64; 3]) -> f64 {
        let (a, b, c) = (
            x[0] - self.mean[0],
            x[1] - self.mean[1],
            x[2] - self.mean[2],
        );
        let p = &self.prec;
        let q = a * a * p[0]
            + b * b * p[1]
            + c * c * p[2]
            + 2.0 * (a * b * p[3] + a * c * p[4] + b * c * p[5]);
        self.log_coef - 0.5 * q
    }
}

fn log_sum_exp(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + v.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}

/// A trained colour model. See the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct ColorModel {
    data: ColorModelData,
    dens: Vec<(f64, Vec<Dens>)>,
}

/// Per-class BIC table of a training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BicRow {
    /// The class fitted.
    pub label: Label,
    /// Components fitted.
    pub components: usize,
    /// Total log-likelihood of the class's pixels under the fit (natural log).
    pub log_likelihood: f64,
    /// Bayesian information criterion, `−2 ln L + p ln n` over the pixel count; lowest wins.
    pub bic: f64,
    /// EM iterations run.
    pub iterations: usize,
}

/// What training did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Every (class, k) fitted.
    pub bic: Vec<BicRow>,
    /// Pixels and distinct colours used per class.
    pub samples: Vec<(Label, u64, usize)>,
}

impl ColorModel {
    /// Builds a model from stored data, checking every component.
    pub fn from_data(data: ColorModelData) -> Result<Self> {
        if data.format != FORMAT {
            return Err(Error::invalid(
                "colour model",
                format!("format {:?}, expected {FORMAT:?}", data.format),
            ));
        }
        if data.classes.is_empty() {
            return Err(Error::invalid("colour model", "no classes"));
        }
        let mut dens = Vec::new();
        for (i, c) in data.classes.iter().enumerate() {
            if c.label == Label::Unknown {
                return Err(Error::invalid(
                    format!("colour model class {i}"),
                    "label `unknown` cannot be a class",
                ));
            }
            if data.classes[..i].iter().any(|o| o.label == c.label) {
                return Err(Error::invalid(
                    format!("colour model class {i}"),
                    format!("label {:?} appears twice", c.label),
                ));
            }
            if !(c.prior.is_finite() && c.prior > 0.0) || c.components.is_empty() {
                return Err(Error::invalid(
                    format!("colour model class {i} ({})", c.name),
                    format!(
                        "prior {} must be positive and there must be components",
                        c.prior
                    ),
                ));
            }
            let d = c
                .components
                .iter()
                .enumerate()
                .map(|(k, comp)| {
                    Dens::new(comp).map_err(|e| {
                        Error::invalid(
                            format!("colour model class {i} ({}) component {k}", c.name),
                            e.to_string(),
                        )
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            dens.push((c.prior.ln(), d));
        }
        Ok(ColorModel { data, dens })
    }

    /// The stored form of the model.
    pub fn data(&self) -> &ColorModelData {
        &self.data
    }

    /// Parses a JSON model; `name` is used in errors.
    pub fn from_json(text: &str, name: &str) -> Result<Self> {
        let d: ColorModelData = serde_json::from_str(text).map_err(|e| {
            Error::format(
                name,
                format!("line {} column {}", e.line(), e.column()),
                e.to_string(),
            )
        })?;
        Self::from_data(d).map_err(|e| Error::format(name, "model", e.to_string()))
    }

    /// Reads and parses a JSON model file. Fails when the file cannot be read or is not a
    /// valid model.
    pub fn load(path: &Path) -> Result<Self> {
        let t = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_json(&t, &path.display().to_string())
    }

    /// Writes the model as JSON (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::files::write_json(path, &self.data)
    }

    /// ln(prior · p(rgb | class)) for every class, in model order.
    pub fn log_scores(&self, rgb: [u8; 3], out: &mut Vec<f64>) {
        let x = [rgb[0] as f64, rgb[1] as f64, rgb[2] as f64];
        out.clear();
        let mut tmp = [0f64; 64];
        for (lp, ds) in &self.dens {
            for (t, d) in tmp.iter_mut().zip(ds) {
                *t = d.log_pdf(&x);
            }
            out.push(lp + log_sum_exp(&tmp[..ds.len()]));
        }
    }

    /// The labels of the classes, in model order.
    pub fn labels(&self) -> Vec<Label> {
        self.data.classes.iter().map(|c| c.label).collect()
    }

    /// Trains one mixture per class. `samples` pairs a label with that class's pixels.
    pub fn train(
        samples: &[(Label, &[[u8; 3]])],
        cfg: &TrainConfig,
    ) -> Result<(Self, TrainReport)> {
        cfg.validate()?;
        if samples.is_empty() {
            return Err(Error::invalid("training set", "no classes"));
        }
        let total: usize = samples.iter().map(|(_, s)| s.len()).sum();
        let mut classes = Vec::new();
        let mut report = TrainReport {
            bic: Vec::new(),
            samples: Vec::new(),
        };
        for (ci, (label, px)) in samples.iter().enumerate() {
            if px.is_empty() {
                return Err(Error::invalid(
                    "training set",
                    format!("class {label:?} has no pixels"),
                ));
            }
            let (x, n) = distinct_colours(px, cfg.max_samples);
            report.samples.push((*label, n as u64, x.len()));
            let mut best: Option<(f64, Vec<Component>)> = None;
            for k in 1..=cfg.max_components {
                if k > x.len() {
                    break;
                }
                let mut rng = SplitMix(cfg.seed ^ ((ci as u64) << 32) ^ k as u64);
                let (comps, ll, iters) = fit_em(&x, k, cfg, &mut rng);
                let kk = comps.len() as f64;
                let p = 10.0 * kk - 1.0;
                let bic = -2.0 * ll + p * (n as f64).ln();
                report.bic.push(BicRow {
                    label: *label,
                    components: comps.len(),
                    log_likelihood: ll,
                    bic,
                    iterations: iters,
                });
                if best.as_ref().is_none_or(|(b, _)| bic < *b) {
                    best = Some((bic, comps));
                }
            }
            let (_, components) = best.expect("k = 1 always fits");
            classes.push(ClassModel {
                label: *label,
                name: format!("{label:?}").to_lowercase(),
                prior: if cfg.priors_from_counts {
                    px.len() as f64 / total as f64
                } else {
                    1.0 / samples.len() as f64
                },
                components,
            });
        }
        let m = Self::from_data(ColorModelData {
            format: FORMAT.into(),
            classes,
        })?;
        Ok((m, report))
    }
}

impl PixelClassifier for ColorModel {
    fn classify_pixel(&self, rgb: [u8; 3]) -> Label {
        let x = [rgb[0] as f64, rgb[1] as f64, rgb[2] as f64];
        let mut best = (f64::NEG_INFINITY, Label::Other);
        let mut tmp = [0f64; 64];
        for ((lp, ds), c) in self.dens.iter().zip(&self.data.classes) {
            for (t, d) in tmp.iter_mut().zip(ds) {
                *t = d.log_pdf(&x);
            }
            let s = lp + log_sum_exp(&tmp[..ds.len()]);
            if s > best.0 {
                best = (s, c.label);
            }
        }
        best.1
    }
}

/// Distinct colours of (an even stride through) `px`, with their pixel counts as weights;
/// returns the weighted samples and the number of pixels they stand for.
fn distinct_colours(px: &[[u8; 3]], max_samples: usize) -> (Vec<([f64; 3], f64)>, usize) {
    let stride = px.len().div_ceil(max_samples).max(1);
    let mut keys: Vec<u32> = px
        .iter()
        .step_by(stride)
        .map(|p| (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32)
        .collect();
    let n = keys.len();
    keys.sort_unstable();
    let mut out: Vec<([f64; 3], f64)> = Vec::new();
    for k in keys {
        let c = [(k >> 16) as f64, ((k >> 8) & 255) as f64, (k & 255) as f64];
        match out.last_mut() {
            Some((lc, w)) if *lc == c => *w += 1.0,
            _ => out.push((c, 1.0)),
        }
    }
    (out, n)
}

/// Deterministic 64-bit generator (SplitMix64).
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn d2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Draws an index with probability ∝ `p` (all non-negative); `None` when all are zero.
fn draw(p: &[f64], rng: &mut SplitMix) -> Option<usize> {
    let s: f64 = p.iter().sum();
    if s.is_nan() || s <= 0.0 {
        return None;
    }
    let mut t = rng.next_f64() * s;
    for (i, v) in p.iter().enumerate() {
        t -= v;
        if t < 0.0 {
            return Some(i);
        }
    }
    p.iter().rposition(|&v| v > 0.0)
}

/// Symmetrises, adds `reg_eps`·I, floors eigenvalues at `min_var`.
fn regularise(m: Matrix3<f64>, cfg: &TrainConfig) -> [[f64; 3]; 3] {
    let s = (m + m.transpose()) * 0.5 + Matrix3::identity() * cfg.reg_eps;
    let mut e = SymmetricEigen::new(s);
    for v in e.eigenvalues.iter_mut() {
        if v.is_nan() || *v < cfg.min_var {
            *v = cfg.min_var;
        }
    }
    let r = e.recompose();
    let r = (r + r.transpose()) * 0.5;
    [
        [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
        [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
        [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
    ]
}

const CHUNK: usize = 4096;

/// Sufficient statistics of one component: Σr, Σr·x, Σr·xxᵀ.
#[derive(Clone, Copy)]
struct Suff {
    n: f64,
    s: Vector3<f64>,
    ss: Matrix3<f64>,
}

impl Suff {
    fn zero() -> Self {
        Suff {
            n: 0.0,
            s: Vector3::zeros(),
            ss: Matrix3::zeros(),
        }
    }
}

/// M-step from sufficient statistics; drops empty components.
fn m_step(st: &[Suff], total: f64, cfg: &TrainConfig) -> Vec<Component> {
    st.iter()
        .filter(|s| s.n > 1e-9 * total)
        .map(|s| {
            let mean = s.s / s.n;
            let cov = s.ss / s.n - mean * mean.transpose();
            Component {
                weight: s.n / total,
                mean: [mean[0], mean[1], mean[2]],
                cov: regularise(cov, cfg),
            }
        })
        .collect()
}

/// k-means++ seeds, 10 Lloyd steps, then EM. Returns components, total log-likelihood and
/// EM iterations.
fn fit_em(
    x: &[([f64; 3], f64)],
    k: usize,
    cfg: &TrainConfig,
    rng: &mut SplitMix,
) -> (Vec<Component>, f64, usize) {
    let total: f64 = x.iter().map(|(_, w)| w).sum();
    // k-means++ (weighted).
    let w: Vec<f64> = x.iter().map(|(_, w)| *w).collect();
    let mut centres = vec![x[draw(&w, rng).unwrap_or(0)].0];
    let mut dist: Vec<f64> = x.iter().map(|(p, _)| d2(p, &centres[0])).collect();
    while centres.len() < k {
        let p: Vec<f64> = dist.iter().zip(&w).map(|(d, w)| d * w).collect();
        let Some(i) = draw(&p, rng) else { break };
        centres.push(x[i].0);
        for (d, (p, _)) in dist.iter_mut().zip(x) {
            *d = d.min(d2(p, &x[i].0));
        }
    }
    // Lloyd steps: hard assignments give the starting means, covariances and weights.
    let mut st = vec![Suff::zero(); centres.len()];
    for _ in 0..10 {
        st = x
            .par_chunks(CHUNK)
            .map(|ch| {
                let mut st = vec![Suff::zero(); centres.len()];
                for (p, w) in ch {
                    let j = (0..centres.len())
                        .min_by(|&a, &b| d2(p, &centres[a]).total_cmp(&d2(p, &centres[b])))
                        .unwrap_or(0);
                    accumulate(&mut st[j], p, *w);
                }
                st
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold(vec![Suff::zero(); centres.len()], add_suff);
        for (c, s) in centres.iter_mut().zip(&st) {
            if s.n > 0.0 {
                *c = [s.s[0] / s.n, s.s[1] / s.n, s.s[2] / s.n];
            }
        }
    }
    let mut comps = m_step(&st, total, cfg);
    let mut ll_prev = f64::NEG_INFINITY;
    let mut iters = 0;
    let mut ll = f64::NEG_INFINITY;
    for it in 0..cfg.max_iter {
        iters = it + 1;
        let dens: Vec<Dens> = comps
            .iter()
            .map(|c| Dens::new(c).expect("regularised covariances are positive definite"))
            .collect();
        let parts: Vec<(Vec<Suff>, f64)> = x
            .par_chunks(CHUNK)
            .map(|ch| {
                let mut st = vec![Suff::zero(); dens.len()];
                let mut ll = 0.0;
                let mut lp = vec![0.0; dens.len()];
                for (p, w) in ch {
                    for (l, d) in lp.iter_mut().zip(&dens) {
                        *l = d.log_pdf(p);
                    }
                    let lse = log_sum_exp(&lp);
                    ll += w * lse;
                    for (s, l) in st.iter_mut().zip(&lp) {
                        accumulate(s, p, w * (l - lse).exp());
                    }
                }
                (st, ll)
            })
            .collect();
        ll = parts.iter().map(|(_, l)| l).sum();
        let st = parts
            .into_iter()
            .map(|(s, _)| s)
            .fold(vec![Suff::zero(); dens.len()], add_suff);
        comps = m_step(&st, total, cfg);
        if (ll - ll_prev) / total < cfg.tol {
            break;
        }
        ll_prev = ll;
    }
    // Log-likelihood of the final parameters.
    let dens: Vec<Dens> = comps
        .iter()
        .map(|c| Dens::new(c).expect("regularised"))
        .collect();
    let ll_final: f64 = x
        .par_chunks(CHUNK)
        .map(|ch| {
            let mut lp = vec![0.0; dens.len()];
            ch.iter()
                .map(|(p, w)| {
                    for (l, d) in lp.iter_mut().zip(&dens) {
                        *l = d.log_pdf(p);
                    }
                    w * log_sum_exp(&lp)
                })
                .sum::<f64>()
        })
        .collect::<Vec<_>>()
        .iter()
        .sum();
    let _ = ll;
    (comps, ll_final, iters)
}

#[inline]
fn accumulate(s: &mut Suff, p: &[f64; 3], w: f64) {
    let v = Vector3::new(p[0], p[1], p[2]);
    s.n += w;
    s.s += v * w;
    s.ss += v * v.transpose() * w;
}

fn add_suff(mut a: Vec<Suff>, b: Vec<Suff>) -> Vec<Suff> {
    for (x, y) in a.iter_mut().zip(b) {
        x.n += y.n;
        x.s += y.s;
        x.ss += y.ss;
    }
    a
}

/// Training pixels from an image and a label image of class ids: ids in `class_of` go to
/// their label, every other id to [`Label::Other`]. `region` = [x0, y0, x1, y1) limits the
/// pixels used. Returns one entry per label that has pixels, in label order.
pub fn training_samples(
    rgb: &RgbImage,
    ids: &image::GrayImage,
    region: Option<[u32; 4]>,
    class_of: &std::collections::HashMap<u8, Label>,
) -> Result<Vec<(Label, Vec<[u8; 3]>)>> {
    if rgb.dimensions() != ids.dimensions() {
        return Err(Error::invalid(
            "label image",
            format!(
                "{:?} pixels for a {:?} image",
                ids.dimensions(),
                rgb.dimensions()
            ),
        ));
    }
    let (w, h) = rgb.dimensions();
    let [x0, y0, x1, y1] = region.unwrap_or([0, 0, w, h]);
    if !(x0 < x1 && y0 < y1 && x1 <= w && y1 <= h) {
        return Err(Error::invalid(
            "training region",
            format!("[{x0}, {y0}, {x1}, {y1}) is empty or outside the {w} × {h} image"),
        ));
    }
    let mut by: std::collections::BTreeMap<Label, Vec<[u8; 3]>> = Default::default();
    for y in y0..y1 {
        for x in x0..x1 {
            let l = class_of
                .get(&ids.get_pixel(x, y).0[0])
                .copied()
                .unwrap_or(Label::Other);
            by.entry(l).or_default().push(rgb.get_pixel(x, y).0);
        }
    }
    Ok(by.into_iter().collect())
}

/// Labels a whole image by direct evaluation of the mixtures (slow; see [`super::ColorLut`]).
impl ColorModel {
    /// Labels every pixel by direct evaluation of the mixtures.
    pub fn classify(&self, img: &RgbImage) -> LabelImage {
        classify_image(self, img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Deterministic Gaussian samples (Box–Muller on SplitMix).
    fn gauss(rng: &mut SplitMix, mean: [f64; 3], std: f64, n: usize) -> Vec<[u8; 3]> {
        (0..n)
            .map(|_| {
                let mut p = [0u8; 3];
                for (c, m) in p.iter_mut().zip(mean) {
                    let (u1, u2) = (rng.next_f64().max(1e-12), rng.next_f64());
                    let z = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
                    *c = (m + std * z).round().clamp(0.0, 255.0) as u8;
                }
                p
            })
            .collect()
    }

    #[test]
    fn bic_finds_two_clusters_and_classifies() {
        let mut rng = SplitMix(1);
        let mut water = gauss(&mut rng, [60.0, 80.0, 200.0], 6.0, 3000);
        water.extend(gauss(&mut rng, [200.0, 200.0, 210.0], 6.0, 3000));
        let other = gauss(&mut rng, [90.0, 120.0, 40.0], 10.0, 5000);
        let (m, rep) = ColorModel::train(
            &[(Label::Water, &water), (Label::Other, &other)],
            &TrainConfig::default(),
        )
        .unwrap();
        assert_eq!(m.data().classes[0].components.len(), 2, "{:?}", rep.bic);
        assert_eq!(m.data().classes[1].components.len(), 1, "{:?}", rep.bic);
        let mut means: Vec<[f64; 3]> = m.data().classes[0]
            .components
            .iter()
            .map(|c| c.mean)
            .collect();
        means.sort_by(|a, b| a[0].total_cmp(&b[0]));
        assert!(d2(&means[0], &[60.0, 80.0, 200.0]) < 1.0, "{means:?}");
        assert!(d2(&means[1], &[200.0, 200.0, 210.0]) < 1.0, "{means:?}");
        assert_eq!(m.classify_pixel([60, 80, 200]), Label::Water);
        assert_eq!(m.classify_pixel([200, 200, 210]), Label::Water);
        assert_eq!(m.classify_pixel([90, 120, 40]), Label::Other);
    }

    #[test]
    fn single_colour_class_clipped_sky() {
        // Clipped sky: one colour only. Without regularisation the covariance is zero.
        let sky = vec![[255u8, 255, 255]; 5000];
        let mut rng = SplitMix(2);
        let other = gauss(&mut rng, [100.0, 110.0, 60.0], 20.0, 5000);
        let (m, _) = ColorModel::train(
            &[(Label::Sky, &sky), (Label::Other, &other)],
            &TrainConfig::default(),
        )
        .unwrap();
        assert_eq!(m.data().classes[0].components.len(), 1);
        for r in m.data().classes[0].components[0].cov.iter().enumerate() {
            assert!(r.1[r.0] >= 1.0);
        }
        assert_eq!(m.classify_pixel([255, 255, 255]), Label::Sky);
        assert_eq!(m.classify_pixel([100, 110, 60]), Label::Other);
    }

    #[test]
    fn planar_class_stays_proper() {
        // Grey ramp: all samples on the line r = g = b (rank-1 covariance).
        let grey: Vec<[u8; 3]> = (0..3000)
            .map(|i| {
                let v = (i % 200) as u8 + 20;
                [v, v, v]
            })
            .collect();
        let (m, _) = ColorModel::train(&[(Label::Other, &grey)], &TrainConfig::default()).unwrap();
        let json = serde_json::to_string(m.data()).unwrap();
        let back = ColorModel::from_json(&json, "m.json").unwrap();
        assert_eq!(back.data(), m.data());
    }

    #[test]
    fn training_is_deterministic_across_thread_counts() {
        let mut rng = SplitMix(3);
        let a = gauss(&mut rng, [50.0, 60.0, 70.0], 15.0, 20000);
        let b = gauss(&mut rng, [150.0, 160.0, 170.0], 25.0, 20000);
        let run = |t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap()
                .install(|| {
                    ColorModel::train(
                        &[(Label::Water, &a), (Label::Other, &b)],
                        &TrainConfig::default(),
                    )
                    .unwrap()
                    .0
                })
        };
        assert_eq!(run(1).data(), run(3).data());
    }

    #[test]
    fn bad_model_files_are_refused() {
        assert!(ColorModel::from_json("{", "m.json")
            .unwrap_err()
            .to_string()
            .contains("m.json"));
        let bad = r#"{"format":"tarn-color-gmm-1","classes":[{"label":"water","name":"w","prior":1.0,
            "components":[{"weight":1.0,"mean":[0,0,0],"cov":[[1,0,0],[0,-1,0],[0,0,1]]}]}]}"#;
        let e = ColorModel::from_json(bad, "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("positive definite") && e.contains("component 0"),
            "{e}"
        );
        let dup = r#"{"format":"tarn-color-gmm-1","classes":[
            {"label":"water","name":"w","prior":1.0,"components":[{"weight":1.0,"mean":[0,0,0],"cov":[[1,0,0],[0,1,0],[0,0,1]]}]},
            {"label":"water","name":"v","prior":1.0,"components":[{"weight":1.0,"mean":[0,0,0],"cov":[[1,0,0],[0,1,0],[0,0,1]]}]}]}"#;
        assert!(ColorModel::from_json(dup, "m.json")
            .unwrap_err()
            .to_string()
            .contains("twice"));
        assert!(ColorModel::train(&[(Label::Water, &[])], &TrainConfig::default()).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]
        #[test]
        fn any_training_set_gives_a_valid_model(
            a in proptest::collection::vec(any::<[u8; 3]>(), 1..60),
            b in proptest::collection::vec(any::<[u8; 3]>(), 1..60),
        ) {
            let cfg = TrainConfig { max_components: 3, ..Default::default() };
            let (m, _) = ColorModel::train(&[(Label::Water, &a), (Label::Other, &b)], &cfg).unwrap();
            // Round trip through JSON and every training pixel gets a decided label.
            let back = ColorModel::from_json(&serde_json::to_string(m.data()).unwrap(), "m").unwrap();
            for p in a.iter().chain(&b) {
                let l = back.classify_pixel(*p);
                prop_assert!(l == Label::Water || l == Label::Other);
            }
        }
    }
}
