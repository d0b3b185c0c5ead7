//! A classifier compiled into a lookup table over quantised RGB.
//!
//! With `bits` bits per channel the table has 2^(3·bits) entries of one byte; each entry is
//! the label of its bin's centre colour. 8 bits is exact (16 MiB), 6 bits is 256 KiB and fits
//! a second-level cache. Classifying a pixel is three shifts and one load.
//!
//! A classifier whose label depends on a colour only through R + G + B and min(R, G, B)
//! ([`PixelClassifier::by_sum_and_min`]) compiles at 8 bits to a table over those two
//! instead: exact, 766 × 256 entries (192 KiB), a sum, a minimum and one load per pixel.

use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::gmm::PixelClassifier;
use super::{Label, LabelImage};
use crate::error::{Error, Result};

/// A lookup table of labels over quantised RGB. See the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawLut")]
pub struct ColorLut {
    bits: u8,
    /// Indexed by R + G + B and min(R, G, B) (`sum · 256 + min`), not by the quantised
    /// channels.
    #[serde(default)]
    sum_min: bool,
    table: Vec<Label>,
}

/// A [`ColorLut`] as read, before its table is checked against its bits.
#[derive(Deserialize)]
struct RawLut {
    bits: u8,
    #[serde(default)]
    sum_min: bool,
    table: Vec<Label>,
}

impl TryFrom<RawLut> for ColorLut {
    type Error = Error;

    /// A table read from elsewhere has the length its bits say: 2^(3·bits) entries, or
    /// 766 × 256 for an 8-bit (sum, min) table.
    fn try_from(r: RawLut) -> Result<Self> {
        let want = match (r.bits, r.sum_min) {
            (8, true) => Some(766 * 256),
            (1..=8, false) => Some(1usize << (3 * r.bits as u32)),
            _ => None,
        };
        if want != Some(r.table.len()) {
            return Err(Error::invalid(
                "lookup table",
                format!(
                    "{} entries for {} bits{}",
                    r.table.len(),
                    r.bits,
                    if r.sum_min { " over (sum, min)" } else { "" }
                ),
            ));
        }
        Ok(ColorLut {
            bits: r.bits,
            sum_min: r.sum_min,
            table: r.table,
        })
    }
}

impl ColorLut {
    /// Evaluates `c` at the centre of every bin. `bits` must be 1..=8.
    pub fn compile(c: &impl PixelClassifier, bits: u8) -> Result<Self> {
        if !(1..=8).contains(&bits) {
            return Err(Error::invalid(
                "lookup table bits per channel",
                format!("{bits} (must be 1..=8)"),
            ));
        }
        let n = 1usize << bits;
        let shift = 8 - bits as u32;
        // Centre of a bin of width 2^shift: q·2^shift + (2^shift − 1)/2, rounded down.
        let centre = |q: usize| ((q << shift) + ((1usize << shift) - 1) / 2) as u8;
        // The label of every (sum, min) pair, when that is all the label depends on.
        let by_sum_min: Option<Vec<Label>> = c.by_sum_and_min().then(|| {
            (0..766 * 256)
                .into_par_iter()
                .map(|k| {
                    colour_of_sum_min(k / 256, k % 256)
                        .map_or(Label::Other, |p| c.classify_pixel(p))
                })
                .collect()
        });
        if let (8, Some(table)) = (bits, &by_sum_min) {
            return Ok(ColorLut {
                bits,
                sum_min: true,
                table: table.to_vec(),
            });
        }
        let mut table = vec![Label::Other; n * n * n];
        table.par_chunks_mut(n).enumerate().for_each(|(rg, out)| {
            let (r, g) = (centre(rg / n), centre(rg % n));
            for (b, o) in out.iter_mut().enumerate() {
                let p = [r, g, centre(b)];
                *o = match &by_sum_min {
                    Some(t) => {
                        let sum = p[0] as usize + p[1] as usize + p[2] as usize;
                        t[sum * 256 + p[0].min(p[1]).min(p[2]) as usize]
                    }
                    None => c.classify_pixel(p),
                };
            }
        });
        Ok(ColorLut {
            bits,
            sum_min: false,
            table,
        })
    }

    /// Bits per channel of the table's bins, 1..=8.
    pub fn bits(&self) -> u8 {
        self.bits
    }

    /// Bytes of table.
    pub fn table_bytes(&self) -> usize {
        self.table.len()
    }

    #[inline(always)]
    fn index(&self, r: u8, g: u8, b: u8) -> usize {
        if self.sum_min {
            return sum_min_index(r, g, b);
        }
        let s = 8 - self.bits as u32;
        let bits = self.bits as u32;
        (((r as usize) >> s) << (2 * bits)) | (((g as usize) >> s) << bits) | ((b as usize) >> s)
    }

    /// Labels a packed RGB buffer into `out` on the calling thread (no parallelism). One
    /// pass, no allocation: per pixel three shifts, two ors and one table load (the index is
    /// masked to the table's power-of-two length, so the load needs no bounds branch), or
    /// for a (sum, min) table a sum, a minimum and one load.
    pub fn classify_into(&self, rgb: &[u8], out: &mut [Label]) -> Result<()> {
        if rgb.len() != 3 * out.len() {
            return Err(Error::invalid(
                "lookup table input",
                format!("{} bytes of RGB for {} labels", rgb.len(), out.len()),
            ));
        }
        let table = &self.table[..];
        if self.sum_min {
            // Its length is checked where a table is made or read (`compile`, `RawLut`).
            let table: &[Label; 766 * 256] = table.try_into().expect("a (sum, min) table");
            for (o, px) in out.iter_mut().zip(rgb.chunks_exact(3)) {
                *o = table[sum_min_index(px[0], px[1], px[2])];
            }
            return Ok(());
        }
        let s = 8 - self.bits as u32;
        let (bg, br) = (self.bits as u32, 2 * self.bits as u32);
        let mask = table.len() - 1;
        for (o, px) in out.iter_mut().zip(rgb.chunks_exact(3)) {
            let (r, g, b) = (px[0], px[1], px[2]);
            let i = (((r >> s) as usize) << br) | (((g >> s) as usize) << bg) | ((b >> s) as usize);
            *o = table[i & mask];
        }
        Ok(())
    }

    /// Labels an image (rows in parallel).
    pub fn classify(&self, img: &RgbImage) -> LabelImage {
        let w = (img.width() as usize).max(1);
        let mut data = vec![Label::Other; (img.width() * img.height()) as usize];
        data.par_chunks_mut(w)
            .zip(img.as_raw().par_chunks(3 * w))
            .for_each(|(o, row)| {
                self.classify_into(row, o).expect("row lengths match");
            });
        LabelImage {
            width: img.width() as usize,
            height: img.height() as usize,
            data,
        }
    }
}

impl PixelClassifier for ColorLut {
    fn classify_pixel(&self, rgb: [u8; 3]) -> Label {
        self.table[self.index(rgb[0], rgb[1], rgb[2])]
    }
}

/// The (sum, min) table's index of a colour: `(R + G + B) · 256 + min(R, G, B)`.
#[inline(always)]
fn sum_min_index(r: u8, g: u8, b: u8) -> usize {
    (r as usize + g as usize + b as usize) * 256 + r.min(g).min(b) as usize
}

/// A colour with channel sum `sum` and smallest channel `min`, if there is one.
fn colour_of_sum_min(sum: usize, min: usize) -> Option<[u8; 3]> {
    let rest = sum.checked_sub(min)?;
    if rest < 2 * min || rest > 510 {
        return None;
    }
    let g = (rest - min).min(255);
    Some([min as u8, g as u8, (rest - g) as u8])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::RuleClassifier;
    use proptest::prelude::*;

    #[test]
    fn rejects_bad_bits() {
        let r = RuleClassifier::default();
        assert!(ColorLut::compile(&r, 0).is_err());
        assert!(ColorLut::compile(&r, 9).is_err());
        let l = ColorLut::compile(&r, 3).unwrap();
        assert!(l.classify_into(&[0; 5], &mut [Label::Other; 2]).is_err());
    }

    /// A table read back is the table; one whose length does not match its bits is an
    /// error when read, not a panic when used.
    #[test]
    fn a_table_read_back_is_checked() {
        let r = RuleClassifier::default();
        for l in [
            ColorLut::compile(&r, 3).unwrap(),
            ColorLut::compile(&r, 8).unwrap(),
        ] {
            let json = serde_json::to_string(&l).unwrap();
            assert_eq!(serde_json::from_str::<ColorLut>(&json).unwrap(), l);
        }
        for bad in [
            r#"{"bits": 3, "table": []}"#,
            r#"{"bits": 8, "sum_min": true, "table": ["water"]}"#,
            r#"{"bits": 0, "table": []}"#,
            r#"{"bits": 9, "table": []}"#,
            r#"{"bits": 2, "sum_min": true, "table": []}"#,
        ] {
            let e = serde_json::from_str::<ColorLut>(bad)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("lookup table") || e.contains("bits"),
                "{bad}: {e}"
            );
        }
    }

    /// The rule without its promise to depend on sum and min only.
    struct Full(RuleClassifier);
    impl PixelClassifier for Full {
        fn classify_pixel(&self, rgb: [u8; 3]) -> Label {
            self.0.classify_pixel(rgb)
        }
    }

    /// A classifier that says it depends on sum and min only compiles to the same table as
    /// one evaluated at every bin.
    #[test]
    fn sum_min_compile_is_the_full_compile() {
        let r = RuleClassifier::default();
        for bits in [1, 4, 6] {
            assert_eq!(
                ColorLut::compile(&r, bits).unwrap(),
                ColorLut::compile(&Full(r), bits).unwrap()
            );
        }
    }

    /// A (sum, min) classifier's exact table is the small one, and the same labels as the
    /// cube of every colour a classifier without that promise compiles to.
    #[test]
    fn an_exact_sum_min_table_is_small_and_the_full_cube() {
        let r = RuleClassifier::default();
        let small = ColorLut::compile(&r, 8).unwrap();
        assert_eq!(small.table_bytes(), 766 * 256);
        let cube = ColorLut::compile(&Full(r), 8).unwrap();
        assert_eq!(cube.table_bytes(), 1 << 24);
        let rgb: Vec<u8> = (0..1u32 << 24)
            .step_by(7)
            .flat_map(|c| [(c >> 16) as u8, (c >> 8) as u8, c as u8])
            .collect();
        let (mut a, mut b) = (
            vec![Label::Other; rgb.len() / 3],
            vec![Label::Other; rgb.len() / 3],
        );
        small.classify_into(&rgb, &mut a).unwrap();
        cube.classify_into(&rgb, &mut b).unwrap();
        assert!(a == b, "the (sum, min) table and the cube disagree");
        assert!(a.contains(&Label::Water) && a.contains(&Label::Sky));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Every (sum, min) pair a colour has is found, with a colour that has it.
        #[test]
        fn colour_of_sum_min_finds_a_colour(p in any::<[u8; 3]>()) {
            let sum = p.iter().map(|&v| v as usize).sum::<usize>();
            let min = *p.iter().min().unwrap() as usize;
            let q = colour_of_sum_min(sum, min).unwrap();
            prop_assert_eq!(q.iter().map(|&v| v as usize).sum::<usize>(), sum);
            prop_assert_eq!(*q.iter().min().unwrap() as usize, min);
        }

        /// An 8-bit table is the classifier itself; a coarser one agrees at bin centres.
        #[test]
        fn lut_agrees_with_source(p in any::<[u8; 3]>(), bits in 1u8..=7) {
            static L8: std::sync::OnceLock<ColorLut> = std::sync::OnceLock::new();
            let r = RuleClassifier::default();
            let l8 = L8.get_or_init(|| ColorLut::compile(&r, 8).unwrap());
            prop_assert_eq!(l8.classify_pixel(p), r.classify_pixel(p));
            let l = ColorLut::compile(&r, bits).unwrap();
            let s = 8 - bits as u32;
            let c = |v: u8| ((((v as u32) >> s) << s) + ((1u32 << s) - 1) / 2) as u8;
            prop_assert_eq!(l.classify_pixel(p), r.classify_pixel([c(p[0]), c(p[1]), c(p[2])]));
        }

        #[test]
        fn image_equals_pixels(px in proptest::collection::vec(any::<u8>(), 3 * 15)) {
            let r = RuleClassifier::default();
            let l = ColorLut::compile(&r, 5).unwrap();
            let img = RgbImage::from_raw(5, 3, px.clone()).unwrap();
            let out = l.classify(&img);
            for (i, p) in px.chunks(3).enumerate() {
                prop_assert_eq!(out.data[i], l.classify_pixel([p[0], p[1], p[2]]));
            }
        }
    }
}
