//! [`Scalar`]: the numeric types of PLY properties, their sizes, and decoding one value
//! from binary bytes or an ascii token.

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    pub(super) fn from_name(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// True when every value of this type is exactly an `f32`.
    pub(super) fn fits_f32(self) -> bool {
        !matches!(self, Scalar::I32 | Scalar::U32 | Scalar::F64)
    }

    fn range(self) -> (f64, f64) {
        match self {
            Scalar::I8 => (i8::MIN as f64, i8::MAX as f64),
            Scalar::U8 => (0.0, u8::MAX as f64),
            Scalar::I16 => (i16::MIN as f64, i16::MAX as f64),
            Scalar::U16 => (0.0, u16::MAX as f64),
            Scalar::I32 => (i32::MIN as f64, i32::MAX as f64),
            Scalar::U32 => (0.0, u32::MAX as f64),
            Scalar::F32 | Scalar::F64 => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }

    /// Decodes one value; `b` must hold at least `self.size()` bytes.
    #[inline(always)]
    pub(super) fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2) as f64,
            Scalar::U16 => get!(u16, 2) as f64,
            Scalar::I32 => get!(i32, 4) as f64,
            Scalar::U32 => get!(u32, 4) as f64,
            Scalar::F32 => get!(f32, 4) as f64,
            Scalar::F64 => get!(f64, 8),
        }
    }

    /// Parses one ascii token of this type.
    pub(super) fn parse(self, tok: &str) -> Option<f64> {
        match self {
            Scalar::F32 => tok.parse::<f32>().ok().map(|v| v as f64),
            Scalar::F64 => tok.parse::<f64>().ok(),
            _ => {
                let v = tok.parse::<i64>().ok()? as f64;
                let (lo, hi) = self.range();
                (lo..=hi).contains(&v).then_some(v)
            }
        }
    }
}
