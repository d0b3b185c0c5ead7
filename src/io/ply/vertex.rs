//! What the reader takes from each vertex ([`VertexPlan`]) and [`Builder`], which turns
//! decoded vertices into a [`PointCloud`] with its local origin chosen.

use std::path::Path;

use nalgebra::Point3;
use rayon::prelude::*;

use super::header::{Element, PropKind};
use super::scalar::Scalar;
use super::FAR_FROM_ORIGIN_M;
use crate::error::{Error, Result};
use crate::geom::{PointCloud, Pose};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    X,
    Y,
    Z,
    Intensity,
    Reflectivity,
    Red,
    Green,
    Blue,
    Range,
    Skip,
}

#[derive(Clone, Copy, Debug)]
pub(super) enum ColorConv {
    Byte,
    Ushort,
    Clamp,
    Unit,
}

impl ColorConv {
    fn for_type(s: Scalar) -> Self {
        match s {
            Scalar::U8 | Scalar::I8 => ColorConv::Byte,
            Scalar::U16 => ColorConv::Ushort,
            Scalar::F32 | Scalar::F64 => ColorConv::Unit,
            _ => ColorConv::Clamp,
        }
    }

    #[inline]
    fn apply(self, v: f64) -> u8 {
        let v = match self {
            ColorConv::Byte | ColorConv::Clamp => v,
            ColorConv::Ushort => (v / 257.0).round(),
            ColorConv::Unit => (v * 255.0).round(),
        };
        if v.is_nan() {
            0
        } else {
            v.clamp(0.0, 255.0) as u8
        }
    }
}

/// What to take from each vertex property.
pub(super) struct VertexPlan {
    pub(super) roles: Vec<Role>,
    pub(super) has_intensity: bool,
    pub(super) has_reflectivity: bool,
    pub(super) has_rgb: bool,
    pub(super) has_range: bool,
    pub(super) rgb_conv: [ColorConv; 3],
    /// Coordinates need a local origin whatever their size (`double`, `int`, `uint`).
    xyz_beyond_f32: bool,
}

impl VertexPlan {
    pub(super) fn new(el: &Element, path: &Path) -> Result<Self> {
        let mut roles = Vec::with_capacity(el.props.len());
        let mut conv = [ColorConv::Byte; 3];
        let mut seen = [false; 9];
        let mut xyz_beyond_f32 = false;
        for p in &el.props {
            let role = match p.name.as_str() {
                "x" => Role::X,
                "y" => Role::Y,
                "z" => Role::Z,
                "intensity" => Role::Intensity,
                "reflectivity" => Role::Reflectivity,
                "red" => Role::Red,
                "green" => Role::Green,
                "blue" => Role::Blue,
                "range" => Role::Range,
                _ => Role::Skip,
            };
            let role = match (role, p.kind) {
                (Role::Skip, _) => Role::Skip,
                (r, PropKind::Scalar(s)) => {
                    match r {
                        Role::X | Role::Y | Role::Z => xyz_beyond_f32 |= !s.fits_f32(),
                        Role::Red => conv[0] = ColorConv::for_type(s),
                        Role::Green => conv[1] = ColorConv::for_type(s),
                        Role::Blue => conv[2] = ColorConv::for_type(s),
                        _ => {}
                    }
                    seen[r as usize] = true;
                    r
                }
                (Role::X | Role::Y | Role::Z, PropKind::List { .. }) => {
                    return Err(Error::format(
                        path,
                        format!("header line {}", el.line),
                        format!("vertex property `{}` is a list, not a number", p.name),
                    ))
                }
                // A list named like an optional channel is not that channel: skip it.
                (_, PropKind::List { .. }) => Role::Skip,
            };
            roles.push(role);
        }
        for (r, n) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
            if !seen[r as usize] {
                return Err(Error::format(
                    path,
                    format!("header line {}", el.line),
                    format!("malformed header: the vertex element has no property `{n}`"),
                ));
            }
        }
        Ok(VertexPlan {
            roles,
            has_intensity: seen[Role::Intensity as usize],
            has_reflectivity: seen[Role::Reflectivity as usize],
            has_rgb: seen[Role::Red as usize]
                && seen[Role::Green as usize]
                && seen[Role::Blue as usize],
            has_range: seen[Role::Range as usize],
            rgb_conv: conv,
            xyz_beyond_f32,
        })
    }
}

#[derive(Clone, Copy, Default)]
pub(super) struct RawVertex {
    pub(super) xyz: [f64; 3],
    pub(super) intensity: f64,
    pub(super) reflectivity: f64,
    pub(super) rgb: [f64; 3],
    pub(super) range: f64,
}

impl RawVertex {
    #[inline(always)]
    pub(super) fn set(&mut self, role: Role, v: f64) {
        match role {
            Role::X => self.xyz[0] = v,
            Role::Y => self.xyz[1] = v,
            Role::Z => self.xyz[2] = v,
            Role::Intensity => self.intensity = v,
            Role::Reflectivity => self.reflectivity = v,
            Role::Red => self.rgb[0] = v,
            Role::Green => self.rgb[1] = v,
            Role::Blue => self.rgb[2] = v,
            Role::Range => self.range = v,
            Role::Skip => {}
        }
    }
}

pub(super) struct Builder {
    pub(super) always_shift: bool,
    pub(super) origin: Option<[f64; 3]>,
    pub(super) zero_is_missing: bool,
    pub(super) rgb_conv: [ColorConv; 3],
    pub(super) xyz: Vec<[f32; 3]>,
    pub(super) intensity: Option<Vec<f32>>,
    pub(super) reflectivity: Option<Vec<f32>>,
    pub(super) rgb: Option<Vec<[u8; 3]>>,
}

impl Builder {
    pub(super) fn new(plan: &VertexPlan) -> Self {
        Builder {
            always_shift: plan.xyz_beyond_f32,
            origin: None,
            zero_is_missing: plan.has_range,
            rgb_conv: plan.rgb_conv,
            xyz: Vec::new(),
            intensity: plan.has_intensity.then(Vec::new),
            reflectivity: plan.has_reflectivity.then(Vec::new),
            rgb: plan.has_rgb.then(Vec::new),
        }
    }

    pub(super) fn reserve(&mut self, n: usize) {
        self.xyz.reserve_exact(n);
        if let Some(v) = &mut self.intensity {
            v.reserve_exact(n);
        }
        if let Some(v) = &mut self.reflectivity {
            v.reserve_exact(n);
        }
        if let Some(v) = &mut self.rgb {
            v.reserve_exact(n);
        }
    }

    /// A missing return: a non-finite coordinate, or (with a `range` property) zero range
    /// or all-zero coordinates.
    #[inline]
    fn is_missing(&self, v: &RawVertex) -> bool {
        let p = v.xyz;
        !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite())
            || (self.zero_is_missing && (v.range == 0.0 || p == [0.0; 3]))
    }

    /// The local origin chosen from the first real return `p`.
    fn choose_origin(&self, p: [f64; 3]) -> [f64; 3] {
        let far = p.iter().any(|c| c.abs() > FAR_FROM_ORIGIN_M);
        if self.always_shift || far {
            p.map(f64::round)
        } else {
            [0.0; 3]
        }
    }

    #[inline]
    fn relative(p: [f64; 3], o: [f64; 3]) -> [f32; 3] {
        [
            (p[0] - o[0]) as f32,
            (p[1] - o[1]) as f32,
            (p[2] - o[2]) as f32,
        ]
    }

    #[inline]
    pub(super) fn push(&mut self, v: &RawVertex) {
        if self.is_missing(v) {
            self.xyz.push([f32::NAN; 3]);
        } else {
            let o = match self.origin {
                Some(o) => o,
                None => *self.origin.insert(self.choose_origin(v.xyz)),
            };
            self.xyz.push(Self::relative(v.xyz, o));
        }
        if let Some(i) = &mut self.intensity {
            i.push(v.intensity as f32);
        }
        if let Some(r) = &mut self.reflectivity {
            r.push(v.reflectivity as f32);
        }
        if let Some(c) = &mut self.rgb {
            let k = self.rgb_conv;
            c.push([
                k[0].apply(v.rgb[0]),
                k[1].apply(v.rgb[1]),
                k[2].apply(v.rgb[2]),
            ]);
        }
    }

    /// Decodes all vertices of fixed size `stride` from `recs` (the builder must be empty),
    /// in parallel: each output value depends only on its record and on the origin, which
    /// is chosen first, sequentially, so the result does not depend on the thread count.
    pub(super) fn fill_fixed(
        &mut self,
        recs: &[u8],
        stride: usize,
        fields: &[(usize, Scalar, Role)],
        big: bool,
    ) {
        debug_assert!(self.xyz.is_empty() && stride > 0);
        let field = |role: Role| fields.iter().find(|f| f.2 == role).map(|f| (f.0, f.1));
        let geometry: Vec<_> = fields
            .iter()
            .filter(|f| matches!(f.2, Role::X | Role::Y | Role::Z | Role::Range))
            .copied()
            .collect();
        let decode = |rec: &[u8]| {
            let mut v = RawVertex::default();
            for &(off, s, r) in &geometry {
                v.set(r, s.decode(&rec[off..], big));
            }
            v
        };
        if self.origin.is_none() {
            if let Some(v) = recs
                .chunks_exact(stride)
                .map(decode)
                .find(|v| !self.is_missing(v))
            {
                self.origin = Some(self.choose_origin(v.xyz));
            }
        }
        // Without a real return every point is missing and the origin is never used.
        let o = self.origin.unwrap_or([0.0; 3]);
        let this = &*self;
        let mut xyz = Vec::new();
        recs.par_chunks_exact(stride)
            .map(|rec| {
                let v = decode(rec);
                if this.is_missing(&v) {
                    [f32::NAN; 3]
                } else {
                    Self::relative(v.xyz, o)
                }
            })
            .collect_into_vec(&mut xyz);
        let column = |(off, s): (usize, Scalar)| column_f32(recs, stride, off, s, big);
        let intensity = self
            .intensity
            .is_some()
            .then(|| field(Role::Intensity))
            .flatten();
        let reflectivity = self
            .reflectivity
            .is_some()
            .then(|| field(Role::Reflectivity))
            .flatten();
        self.intensity = intensity.map(column);
        self.reflectivity = reflectivity.map(column);
        if self.rgb.is_some() {
            if let (Some(r), Some(g), Some(b)) =
                (field(Role::Red), field(Role::Green), field(Role::Blue))
            {
                let k = self.rgb_conv;
                let mut rgb = Vec::new();
                recs.par_chunks_exact(stride)
                    .map(|rec| {
                        [
                            k[0].apply(r.1.decode(&rec[r.0..], big)),
                            k[1].apply(g.1.decode(&rec[g.0..], big)),
                            k[2].apply(b.1.decode(&rec[b.0..], big)),
                        ]
                    })
                    .collect_into_vec(&mut rgb);
                self.rgb = Some(rgb);
            }
        }
        self.xyz = xyz;
    }

    pub(super) fn finish(self, layout: Option<(usize, usize)>) -> Result<PointCloud> {
        let mut cloud = match layout {
            Some((rows, cols)) => PointCloud::organized(rows, cols, self.xyz)?,
            None => PointCloud::unorganized(self.xyz),
        };
        cloud.intensity = self.intensity;
        cloud.reflectivity = self.reflectivity;
        cloud.rgb = self.rgb;
        let o = self.origin.unwrap_or([0.0; 3]);
        cloud.frame_to_map = Pose::translation(o[0], o[1], o[2]);
        cloud.sensor_origin = Point3::new(-o[0], -o[1], -o[2]);
        Ok(cloud)
    }
}

/// One scalar property of every fixed-size record, as `f32`; the type dispatch sits outside
/// the loop so that each loop is specialised to one type and byte order.
fn column_f32(recs: &[u8], stride: usize, off: usize, s: Scalar, big: bool) -> Vec<f32> {
    let mut out = Vec::new();
    macro_rules! go {
        ($t:ty, $n:expr, $from:ident) => {
            recs.par_chunks_exact(stride)
                .map(|rec| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(&rec[off..off + $n]);
                    <$t>::$from(a) as f32
                })
                .collect_into_vec(&mut out)
        };
    }
    match (s, big) {
        (Scalar::I8, _) => go!(i8, 1, from_le_bytes),
        (Scalar::U8, _) => go!(u8, 1, from_le_bytes),
        (Scalar::I16, false) => go!(i16, 2, from_le_bytes),
        (Scalar::I16, true) => go!(i16, 2, from_be_bytes),
        (Scalar::U16, false) => go!(u16, 2, from_le_bytes),
        (Scalar::U16, true) => go!(u16, 2, from_be_bytes),
        (Scalar::I32, false) => go!(i32, 4, from_le_bytes),
        (Scalar::I32, true) => go!(i32, 4, from_be_bytes),
        (Scalar::U32, false) => go!(u32, 4, from_le_bytes),
        (Scalar::U32, true) => go!(u32, 4, from_be_bytes),
        (Scalar::F32, false) => go!(f32, 4, from_le_bytes),
        (Scalar::F32, true) => go!(f32, 4, from_be_bytes),
        (Scalar::F64, false) => go!(f64, 8, from_le_bytes),
        (Scalar::F64, true) => go!(f64, 8, from_be_bytes),
    }
    out
}
