//! Pixel classifiers (paper sections 2.1, 4, 5): water that reflects the sky is bright and
//! weakly saturated; SWIR sees water, snow and ice dark at moderate incidence; MWIR sees water
//! warmer than the land at night and cooler by day. Pixels whose ray points above the
//! horizontal plane cannot be water.
//!
//! - The paper's brightness/saturation features ([`brightness`], [`saturation`]) and its
//!   Table 1 statistics as a rule baseline ([`RuleClassifier`], of [`ClassStats`]).
//! - A supervised classifier with one Gaussian mixture per class in RGB ([`ColorModel`]),
//!   trained by EM (k-means++ start, full covariances, regularised; [`TrainConfig`],
//!   [`training_samples`], [`TrainReport`] with its [`BicRow`]s), components chosen by BIC;
//!   JSON model files ([`ColorModelData`], [`ClassModel`], [`Component`]); compiled into a
//!   [`ColorLut`] over quantised RGB for speed. Each is a [`PixelClassifier`].
//! - The horizon from the camera's attitude or a given row ([`Horizon`], [`HorizonStats`],
//!   [`optical_pose`]), and per-pixel incidence angle and range against a level ground plane.
//! - The equation of time ([`equation_of_time_min`]): local solar time from a UTC stamp and a
//!   longitude, for the MWIR regime.
//! - SWIR water as a reflection of the sky measured in the same image, Fresnel reflectance
//!   at each pixel's incidence, no incidence gate ([`SwirConfig`]); MWIR contrast against local
//!   terrain statistics by time of day with a lookahead limit ([`MwirConfig`]).
//!
//! Every classifier writes a [`LabelImage`] of [`Label`] values ([`MonoImage`] for one band;
//! [`save_gray_png`]); [`Confusion`] scores one against the truth.

mod color;
mod gmm;
pub(crate) mod horizon;
mod lut;
pub(crate) mod mwir;
pub(crate) mod solar;
pub(crate) mod swir;
pub(crate) mod thermal;

pub use color::{brightness, saturation, ClassStats, RuleClassifier};
pub use gmm::{
    training_samples, BicRow, ClassModel, ColorModel, ColorModelData, Component, PixelClassifier,
    TrainConfig, TrainReport,
};
pub use horizon::{optical_pose, Horizon, HorizonStats};
pub use lut::ColorLut;
pub use mwir::MwirConfig;
pub use solar::equation_of_time_min;
pub use swir::SwirConfig;

use image::ImageEncoder;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// What a pixel shows. The discriminants are the values written into label PNGs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
#[serde(rename_all = "snake_case")]
pub enum Label {
    /// Anything that is not water, sky, snow or ice (terrain, vegetation, objects).
    Other = 0,
    /// A water surface.
    Water = 1,
    /// Open sky.
    Sky = 2,
    /// Snow or ice (dark in SWIR, bright in the visible).
    SnowIce = 3,
    /// No decision (outside a sensor's valid geometry, e.g. grazing incidence in SWIR).
    Unknown = 255,
}

impl Label {
    /// All labels that carry a decision, in vote-index order (see [`Label::index`]).
    pub(crate) const DECIDED: [Label; 4] = [Label::Other, Label::Water, Label::Sky, Label::SnowIce];

    /// Index 0..4 for decided labels, `None` for [`Label::Unknown`].
    pub fn index(self) -> Option<usize> {
        match self {
            Label::Other => Some(0),
            Label::Water => Some(1),
            Label::Sky => Some(2),
            Label::SnowIce => Some(3),
            Label::Unknown => None,
        }
    }

    /// The label a byte of a label image stands for.
    pub fn from_u8(v: u8) -> Option<Label> {
        match v {
            0 => Some(Label::Other),
            1 => Some(Label::Water),
            2 => Some(Label::Sky),
            3 => Some(Label::SnowIce),
            255 => Some(Label::Unknown),
            _ => None,
        }
    }
}

/// A row-major image of labels.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelImage {
    /// Columns, pixels.
    pub width: usize,
    /// Rows, pixels.
    pub height: usize,
    /// Labels, row major, `width × height` of them.
    pub data: Vec<Label>,
}

impl LabelImage {
    /// An image filled with one label.
    pub fn filled(width: usize, height: usize, l: Label) -> Self {
        LabelImage {
            width,
            height,
            data: vec![l; width * height],
        }
    }

    /// Checks that `data` holds `width × height` labels.
    pub fn validate(&self) -> Result<()> {
        if self.data.len() != self.width * self.height {
            return Err(Error::invalid(
                "label image",
                format!(
                    "{} labels for {} × {} pixels",
                    self.data.len(),
                    self.width,
                    self.height
                ),
            ));
        }
        Ok(())
    }

    /// The label at column `x`, row `y`. Panics outside the image.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Label {
        self.data[y * self.width + x]
    }

    /// 8-bit water mask: 255 water, 0 anything else.
    pub fn water_mask(&self) -> Result<image::GrayImage> {
        self.gray(|l| if l == Label::Water { 255 } else { 0 })
    }

    /// 8-bit image of label values ([`Label`] discriminants).
    pub fn to_gray(&self) -> Result<image::GrayImage> {
        self.gray(|l| l as u8)
    }

    fn gray(&self, f: impl Fn(Label) -> u8) -> Result<image::GrayImage> {
        self.validate()?;
        let (w, h) = (u32::try_from(self.width), u32::try_from(self.height));
        let px = self.data.iter().map(|&l| f(l)).collect();
        match (w, h) {
            (Ok(w), Ok(h)) => image::GrayImage::from_raw(w, h, px),
            _ => None,
        }
        .ok_or_else(|| {
            Error::invalid(
                "label image",
                format!("{} × {} is too large for an image", self.width, self.height),
            )
        })
    }

    /// Reads back [`Self::to_gray`]; `name` is used in errors.
    pub fn from_gray(img: &image::GrayImage, name: &str) -> Result<Self> {
        let mut data = Vec::with_capacity(img.len());
        for (i, &v) in img.as_raw().iter().enumerate() {
            data.push(Label::from_u8(v).ok_or_else(|| {
                Error::format(
                    name,
                    format!("pixel {i}"),
                    format!("{v} is not a label value (0, 1, 2, 3 or 255)"),
                )
            })?);
        }
        Ok(LabelImage {
            width: img.width() as usize,
            height: img.height() as usize,
            data,
        })
    }
}

/// A single-channel image (SWIR, MWIR) as `f32` values in sensor units; NaN = no data.
#[derive(Debug, Clone, PartialEq)]
pub struct MonoImage {
    /// Columns, pixels.
    pub width: usize,
    /// Rows, pixels.
    pub height: usize,
    /// Values, row major, `width × height` of them; NaN where there is no data.
    pub data: Vec<f32>,
}

impl MonoImage {
    /// Checks that the buffer is `width × height` long.
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<Self> {
        if data.len() != width * height {
            return Err(Error::invalid(
                "mono image",
                format!("{} values for {width} × {height} pixels", data.len()),
            ));
        }
        Ok(MonoImage {
            width,
            height,
            data,
        })
    }

    /// An 8-bit image, values 0..=255 unchanged.
    pub fn from_gray8(img: &image::GrayImage) -> Self {
        MonoImage {
            width: img.width() as usize,
            height: img.height() as usize,
            data: img.as_raw().iter().map(|&v| v as f32).collect(),
        }
    }

    /// A 16-bit image, values 0..=65535 unchanged.
    pub fn from_gray16(img: &image::ImageBuffer<image::Luma<u16>, Vec<u16>>) -> Self {
        MonoImage {
            width: img.width() as usize,
            height: img.height() as usize,
            data: img.as_raw().iter().map(|&v| v as f32).collect(),
        }
    }
}

/// Writes an 8-bit PNG atomically (temporary file, then rename).
pub fn save_gray_png(path: &std::path::Path, img: &image::GrayImage) -> Result<()> {
    crate::files::write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(
                img.as_raw(),
                img.width(),
                img.height(),
                image::ExtendedColorType::L8,
            )
            .map_err(std::io::Error::other)
    })
}

/// Pixel-level agreement of a predicted water mask with a reference one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Confusion {
    /// Pixels predicted water that are water.
    pub tp: u64,
    /// Pixels predicted water that are not.
    pub fp: u64,
    /// Water pixels predicted not water (false negatives).
    pub fn_: u64,
    /// Pixels predicted not water that are not.
    pub tn: u64,
}

impl Confusion {
    /// Counts one pixel: its prediction and its reference.
    pub fn add(&mut self, predicted: bool, truth: bool) {
        match (predicted, truth) {
            (true, true) => self.tp += 1,
            (true, false) => self.fp += 1,
            (false, true) => self.fn_ += 1,
            (false, false) => self.tn += 1,
        }
    }
    /// `tp / (tp + fp)`, 0 when nothing was predicted water.
    pub fn precision(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fp).max(1) as f64
    }
    /// `tp / (tp + fn)`, 0 when the reference has no water.
    pub fn recall(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fn_).max(1) as f64
    }
    /// Intersection over union of the water masks, `tp / (tp + fp + fn)`; 0 when both are empty.
    pub fn iou(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fp + self.fn_).max(1) as f64
    }
    /// Fraction of true negatives called positive.
    pub fn false_positive_rate(&self) -> f64 {
        self.fp as f64 / (self.fp + self.tn).max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_bytes_round_trip() {
        for l in Label::DECIDED.into_iter().chain([Label::Unknown]) {
            assert_eq!(Label::from_u8(l as u8), Some(l));
        }
        assert_eq!(Label::from_u8(7), None);
        let img = image::GrayImage::from_raw(2, 1, vec![1, 9]).unwrap();
        let e = LabelImage::from_gray(&img, "x.png")
            .unwrap_err()
            .to_string();
        assert!(e.contains("pixel 1") && e.contains('9'), "{e}");
        let bad = LabelImage {
            width: 3,
            height: 2,
            data: vec![Label::Water; 5],
        };
        assert!(bad
            .water_mask()
            .unwrap_err()
            .to_string()
            .contains("5 labels for 3 × 2"));
        let good = LabelImage::filled(3, 2, Label::Water);
        assert_eq!(
            LabelImage::from_gray(&good.to_gray().unwrap(), "g").unwrap(),
            good
        );
        assert!(good
            .water_mask()
            .unwrap()
            .as_raw()
            .iter()
            .all(|&v| v == 255));
    }

    #[test]
    fn confusion_metrics() {
        let mut c = Confusion::default();
        for (p, t) in [
            (true, true),
            (true, false),
            (false, true),
            (false, false),
            (true, true),
        ] {
            c.add(p, t);
        }
        assert!((c.precision() - 2.0 / 3.0).abs() < 1e-12);
        assert!((c.recall() - 2.0 / 3.0).abs() < 1e-12);
        assert!((c.iou() - 0.5).abs() < 1e-12);
        assert!((c.false_positive_rate() - 0.5).abs() < 1e-12);
    }
}
