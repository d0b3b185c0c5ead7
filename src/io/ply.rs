//! PLY point-cloud reader: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Hand-written rather than built on `ply-rs-bw`: the reader checks every size against the
//! bytes actually present before it allocates (a header claiming 10^12 vertices is an
//! error, not an allocation), names the header line, text line or byte offset of every
//! fault, works on an in-memory byte slice ([`read_from_bytes`], for fuzzing), and decodes
//! fixed-size binary vertices straight from the file bytes with precomputed offsets.
//!
//! # What is read
//!
//! The `vertex` element must have scalar properties `x`, `y`, `z` of any numeric type
//! (`char uchar short ushort int uint float double` or the aliases `int8 uint8 int16
//! uint16 int32 uint32 float32 float64`). Optional scalar properties, any numeric type:
//!
//! - `intensity` → [`PointCloud::intensity`], `reflectivity` → [`PointCloud::reflectivity`];
//! - `red`, `green`, `blue` (all three, else colour is ignored) → [`PointCloud::rgb`]:
//!   8-bit integers as they are, `ushort` divided by 257, other integers clamped to 0..255,
//!   `float`/`double` taken as 0..1 and scaled to 0..255;
//! - `range`: when present, a point with `range == 0` or with all-zero `x y z` is a missing
//!   return (the Ouster driver's convention). Without a `range` property a point at
//!   (0, 0, 0) is kept as a real point.
//!
//! Every other property (list properties too) and every other element (`face`, `edge`,
//! ...), before or after the vertices, is skipped; its structure is still checked, so a
//! truncated `face` list is reported. Bytes after the last element are ignored.
//!
//! # Missing returns
//!
//! A vertex with a NaN or infinite coordinate keeps its slot with `[NaN; 3]`.
//!
//! # Organized clouds
//!
//! A cloud is organized only when the header declares it, with a line
//! `obj_info width W height H` or `comment width W height H` (exactly these four words):
//! then vertex `i` is row `i / W`, column `i % W`, and `W·H` must equal the vertex count.
//! A vertex count that merely matches a known scan layout (64 × 2048) is *not* guessed:
//! such a cloud reads unorganized; [`crate::io::organize_column_major`] rearranges a
//! column-major lidar scan when the caller knows the layout.
//!
//! # Large coordinates
//!
//! Points are stored as `f32` relative to a local origin `o` (in metres, `f64`), with
//! `frame_to_map = translation(o)` and `sensor_origin = −o` (the file's own origin, where
//! a scan's sensor sits). `o` is the first finite vertex rounded to whole metres when the
//! coordinates are of a type `f32` cannot hold exactly (`double`, `int`, `uint`), or when
//! that first finite vertex lies more than [`FAR_FROM_ORIGIN_M`] from the file's origin.
//! Otherwise `o = 0` and the file's `f32`-exact values are stored unchanged. A cloud
//! 5,000 km from the origin in `double` keeps sub-millimetre detail near its first point
//! (f32 steps are ≤ 0.5 mm within 4,096 m of `o`).
//!
//! A header line `comment origin X Y Z` (finite metres; earlier versions of tarn wrote it
//! into `map.ply` and `terrain.ply` of maps far from the map origin, with `float` vertices
//! relative to it; tarn now writes `double` map-frame vertices instead) says the vertices
//! are relative to that point of the map frame: it goes into `frame_to_map` (f64), never
//! into the `f32` points.

use std::path::Path;

use nalgebra::Point3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::{PointCloud, Pose};

/// Beyond this distance (metres) of the file's origin, a first finite vertex makes the
/// reader choose a local origin even for `float` coordinates. Below 2^12 m an `f32` has
/// steps of 0.49 mm or finer.
pub const FAR_FROM_ORIGIN_M: f64 = 4096.0;

/// Parses the three numbers of a `comment origin X Y Z` line: finite metres.
pub fn parse_origin(text: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|t| t.parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("origin {text:?} is not three numbers"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "origin {text:?} must be three finite numbers (metres)"
        )),
    }
}

/// Reads a PLY point cloud from a file.
pub fn read(path: &Path) -> Result<PointCloud> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_from_bytes(&bytes, path)
}

/// Reads a PLY point cloud from bytes in memory; `name` is used in error messages only.
pub fn read_from_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<PointCloud> {
    let path = name.as_ref();
    let header = parse_header(bytes, path)?;
    let vi = header.vertex_index(path)?;
    let vertex = &header.elements[vi];
    let plan = VertexPlan::new(vertex, path)?;

    let layout = match header.layout {
        Some(l) => {
            let n = l.width.checked_mul(l.height);
            if n.map(|n| n as u64) != Some(vertex.count) {
                return Err(Error::format(
                    path,
                    format!("header line {}", l.line),
                    format!(
                        "declared organized layout width {} height {} does not match the {} \
                         vertices of the vertex element",
                        l.width, l.height, vertex.count
                    ),
                ));
            }
            Some((l.height, l.width))
        }
        None => None,
    };

    let mut builder = Builder::new(&plan);
    match header.encoding {
        Encoding::Ascii => read_ascii(bytes, path, &header, vi, &plan, &mut builder)?,
        Encoding::Binary { big_endian } => {
            read_binary(bytes, path, &header, vi, &plan, big_endian, &mut builder)?
        }
    }
    let mut cloud = builder.finish(layout)?;
    if let Some(g) = header.origin {
        // Vertices are relative to the header's origin: keep it in the pose (f64).
        cloud.frame_to_map = Pose::translation(g[0], g[1], g[2]) * cloud.frame_to_map;
    }
    Ok(cloud)
}

// ------------------------------------------------------------------------------------
// Header

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
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
    fn from_name(s: &str) -> Option<Scalar> {
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

    fn name(self) -> &'static str {
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

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// True when every value of this type is exactly an `f32`.
    fn fits_f32(self) -> bool {
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
    fn decode(self, b: &[u8], big: bool) -> f64 {
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
    fn parse(self, tok: &str) -> Option<f64> {
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

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    /// Header line that declared the element (1-based).
    line: usize,
}

impl Element {
    /// Size in bytes of one binary record when it has no list property.
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            PropKind::Scalar(s) => Some(acc + s.size()),
            PropKind::List { .. } => None,
        })
    }

    /// Smallest possible binary record (lists empty).
    fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(s) => s.size(),
                PropKind::List { count, .. } => count.size(),
            })
            .sum()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Binary { big_endian: bool },
}

#[derive(Clone, Copy, Debug)]
struct Layout {
    width: usize,
    height: usize,
    line: usize,
}

#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the first body byte.
    body_start: usize,
    /// Number of the first body line (1-based), for ascii error messages.
    body_line: usize,
    layout: Option<Layout>,
    /// `comment origin X Y Z`: the vertices are relative to this point of the map frame.
    origin: Option<[f64; 3]>,
}

impl Header {
    fn vertex_index(&self, path: &Path) -> Result<usize> {
        let mut found = None;
        for (i, e) in self.elements.iter().enumerate() {
            if e.name == "vertex" {
                if found.is_some() {
                    return Err(Error::format(
                        path,
                        format!("header line {}", e.line),
                        "a second `vertex` element",
                    ));
                }
                found = Some(i);
            }
        }
        found.ok_or_else(|| Error::format(path, "header", "no `vertex` element"))
    }
}

fn show(bytes: &[u8]) -> String {
    let cut = &bytes[..bytes.len().min(24)];
    format!("{:?}", String::from_utf8_lossy(cut))
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    if bytes.is_empty() {
        return Err(Error::format(path, "byte 0", "empty file (0 bytes)"));
    }
    let line_at = |pos: usize| -> (&[u8], usize) {
        let rest = &bytes[pos..];
        match rest.iter().position(|&b| b == b'\n') {
            Some(k) => (&rest[..k], pos + k + 1),
            None => (rest, bytes.len()),
        }
    };
    let strip_cr = |l: &'_ [u8]| -> usize { l.len() - usize::from(l.last() == Some(&b'\r')) };

    let (first, mut pos) = line_at(0);
    if &first[..strip_cr(first)] != b"ply" {
        return Err(Error::format(
            path,
            "line 1",
            format!(
                "not a PLY file: the first line must be `ply`, found {}",
                show(first)
            ),
        ));
    }

    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut layout = None;
    let mut origin = None;
    let mut line_no = 1;
    loop {
        if pos >= bytes.len() {
            return Err(Error::format(
                path,
                format!("header line {line_no}"),
                "malformed header: the file ends before `end_header`",
            ));
        }
        line_no += 1;
        let loc = || format!("header line {line_no}");
        let (raw, next) = line_at(pos);
        pos = next;
        let line = &raw[..strip_cr(raw)];
        if line.starts_with(b"comment") && std::str::from_utf8(line).is_err() {
            // A comment in a legacy encoding (Latin-1...) says nothing we read.
            continue;
        }
        let text = std::str::from_utf8(line).map_err(|_| {
            Error::format(
                path,
                loc(),
                format!(
                    "malformed header: line is not text ({}); is `end_header` missing?",
                    show(raw)
                ),
            )
        })?;
        let toks: Vec<&str> = text.split_ascii_whitespace().collect();
        let bad = |msg: String| Error::format(path, loc(), format!("malformed header: {msg}"));
        match toks.first().copied() {
            None => continue,
            Some("end_header") => {
                if toks.len() != 1 {
                    return Err(bad(format!("unexpected words after end_header: {text:?}")));
                }
                break;
            }
            Some("format") => {
                if encoding.is_some() {
                    return Err(bad("a second `format` line".into()));
                }
                if toks.len() != 3 {
                    return Err(bad(format!(
                        "expected `format <ascii|binary_little_endian|binary_big_endian> 1.0`, \
                         found {text:?}"
                    )));
                }
                encoding = Some(match toks[1] {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Binary { big_endian: false },
                    "binary_big_endian" => Encoding::Binary { big_endian: true },
                    other => return Err(bad(format!("unknown format `{other}`"))),
                });
                if toks[2] != "1.0" {
                    return Err(bad(format!("unsupported PLY version `{}`", toks[2])));
                }
            }
            Some("comment") if toks.get(1) == Some(&"origin") => {
                origin = Some(parse_origin(&toks[2..].join(" ")).map_err(bad)?);
            }
            Some("comment") | Some("obj_info") => {
                if let [_, "width", w, "height", h] = toks.as_slice() {
                    if let (Ok(width), Ok(height)) = (w.parse(), h.parse()) {
                        layout = Some(Layout {
                            width,
                            height,
                            line: line_no,
                        });
                    }
                }
            }
            Some("element") => {
                if toks.len() != 3 {
                    return Err(bad(format!(
                        "expected `element <name> <count>`, found {text:?}"
                    )));
                }
                let count: u64 = toks[2]
                    .parse()
                    .map_err(|_| bad(format!("bad element count `{}`", toks[2])))?;
                if elements.iter().any(|e| e.name == toks[1]) && toks[1] == "vertex" {
                    return Err(bad("a second `vertex` element".into()));
                }
                elements.push(Element {
                    name: toks[1].to_string(),
                    count,
                    props: Vec::new(),
                    line: line_no,
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("`property` before any `element`".into()));
                };
                let ty = |s: &str| {
                    Scalar::from_name(s).ok_or_else(|| bad(format!("unknown property type `{s}`")))
                };
                let (kind, name) = match toks.as_slice() {
                    [_, "list", c, i, name] => {
                        let count = ty(c)?;
                        if !count.is_integer() {
                            return Err(bad(format!(
                                "list count type must be an integer type, found `{c}`"
                            )));
                        }
                        (
                            PropKind::List {
                                count,
                                item: ty(i)?,
                            },
                            *name,
                        )
                    }
                    [_, t, name] if *t != "list" => (PropKind::Scalar(ty(t)?), *name),
                    _ => {
                        return Err(bad(format!(
                            "expected `property <type> <name>` or `property list <count type> \
                             <item type> <name>`, found {text:?}"
                        )))
                    }
                };
                if el.props.iter().any(|p| p.name == name) {
                    return Err(bad(format!(
                        "property `{name}` appears twice in element `{}`",
                        el.name
                    )));
                }
                el.props.push(Property {
                    name: name.to_string(),
                    kind,
                });
            }
            Some(other) => return Err(bad(format!("unknown header keyword `{other}`"))),
        }
    }
    let encoding = encoding
        .ok_or_else(|| Error::format(path, "header", "malformed header: no `format` line"))?;
    Ok(Header {
        encoding,
        elements,
        body_start: pos,
        body_line: line_no + 1,
        layout,
        origin,
    })
}

// ------------------------------------------------------------------------------------
// Vertex plan and builder

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
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
enum ColorConv {
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
struct VertexPlan {
    roles: Vec<Role>,
    has_intensity: bool,
    has_reflectivity: bool,
    has_rgb: bool,
    has_range: bool,
    rgb_conv: [ColorConv; 3],
    /// Coordinates need a local origin whatever their size (`double`, `int`, `uint`).
    xyz_beyond_f32: bool,
}

impl VertexPlan {
    fn new(el: &Element, path: &Path) -> Result<Self> {
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
struct RawVertex {
    xyz: [f64; 3],
    intensity: f64,
    reflectivity: f64,
    rgb: [f64; 3],
    range: f64,
}

impl RawVertex {
    #[inline(always)]
    fn set(&mut self, role: Role, v: f64) {
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

struct Builder {
    always_shift: bool,
    origin: Option<[f64; 3]>,
    zero_is_missing: bool,
    rgb_conv: [ColorConv; 3],
    xyz: Vec<[f32; 3]>,
    intensity: Option<Vec<f32>>,
    reflectivity: Option<Vec<f32>>,
    rgb: Option<Vec<[u8; 3]>>,
}

impl Builder {
    fn new(plan: &VertexPlan) -> Self {
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

    fn reserve(&mut self, n: usize) {
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
    fn push(&mut self, v: &RawVertex) {
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
    fn fill_fixed(
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

    fn finish(self, layout: Option<(usize, usize)>) -> Result<PointCloud> {
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

// ------------------------------------------------------------------------------------
// Binary body

fn too_many(path: &Path, el: &Element, per: usize, pos: usize, remaining: usize) -> Error {
    let need = (el.count as u128) * (per as u128);
    Error::format(
        path,
        format!("byte {pos}"),
        format!(
            "header declares {} `{}` records of at least {per} bytes ({need} bytes) but only \
             {remaining} bytes remain in the file",
            el.count, el.name
        ),
    )
}

fn truncated(path: &Path, el: &Element, index: u64, pos: usize, len: usize) -> Error {
    Error::format(
        path,
        format!("byte {pos}"),
        format!(
            "truncated body: `{}` record {index} of {} runs past the end of the file ({len} bytes)",
            el.name, el.count
        ),
    )
}

/// Checks `count × min_size ≤ remaining` and returns the count as `usize`.
fn check_count(path: &Path, el: &Element, min: usize, pos: usize, len: usize) -> Result<usize> {
    let remaining = len - pos;
    match (el.count as u128).checked_mul(min as u128) {
        Some(need) if need <= remaining as u128 => {}
        _ => return Err(too_many(path, el, min, pos, remaining)),
    }
    if min == 0 {
        // Records without properties take no bytes; their count does not matter.
        return Ok(0);
    }
    Ok(el.count as usize)
}

/// Reads a list's length at `pos`.
fn list_len(
    bytes: &[u8],
    pos: usize,
    count: Scalar,
    big: bool,
    path: &Path,
    prop: &str,
) -> Result<Option<usize>> {
    let Some(b) = bytes.get(pos..pos + count.size()) else {
        return Ok(None);
    };
    let n = count.decode(b, big);
    if n < 0.0 {
        return Err(Error::format(
            path,
            format!("byte {pos}"),
            format!("list `{prop}` has negative length {n}"),
        ));
    }
    Ok(Some(n as usize))
}

/// Walks one variable-size binary record starting at `pos`, setting roled values into `v`.
/// Returns the position after the record, or `None` when the file ends inside it.
fn walk_record(
    bytes: &[u8],
    mut pos: usize,
    el: &Element,
    roles: Option<&[Role]>,
    big: bool,
    v: &mut RawVertex,
    path: &Path,
) -> Result<Option<usize>> {
    for (k, p) in el.props.iter().enumerate() {
        match p.kind {
            PropKind::Scalar(s) => {
                let Some(b) = bytes.get(pos..pos + s.size()) else {
                    return Ok(None);
                };
                if let Some(roles) = roles {
                    if roles[k] != Role::Skip {
                        v.set(roles[k], s.decode(b, big));
                    }
                }
                pos += s.size();
            }
            PropKind::List { count, item } => {
                let Some(n) = list_len(bytes, pos, count, big, path, &p.name)? else {
                    return Ok(None);
                };
                pos += count.size();
                let skip = n.checked_mul(item.size());
                match skip.and_then(|s| pos.checked_add(s)) {
                    Some(end) if end <= bytes.len() => pos = end,
                    _ => return Ok(None),
                }
            }
        }
    }
    Ok(Some(pos))
}

fn read_binary(
    bytes: &[u8],
    path: &Path,
    header: &Header,
    vi: usize,
    plan: &VertexPlan,
    big: bool,
    builder: &mut Builder,
) -> Result<()> {
    let len = bytes.len();
    let mut pos = header.body_start;
    for (ei, el) in header.elements.iter().enumerate() {
        let count = check_count(path, el, el.min_binary_size(), pos, len)?;
        let is_vertex = ei == vi;
        if is_vertex {
            builder.reserve(count);
        }
        match el.fixed_size() {
            Some(stride) => {
                // check_count has proved count × stride ≤ remaining.
                let end = pos + count * stride;
                if is_vertex {
                    let fields: Vec<(usize, Scalar, Role)> = {
                        let mut off = 0;
                        let mut f = Vec::new();
                        for (p, &r) in el.props.iter().zip(&plan.roles) {
                            if let PropKind::Scalar(s) = p.kind {
                                if r != Role::Skip {
                                    f.push((off, s, r));
                                }
                                off += s.size();
                            }
                        }
                        f
                    };
                    builder.fill_fixed(&bytes[pos..end], stride, &fields, big);
                }
                pos = end;
            }
            None => {
                let roles = is_vertex.then_some(plan.roles.as_slice());
                let mut v = RawVertex::default();
                for i in 0..count as u64 {
                    match walk_record(bytes, pos, el, roles, big, &mut v, path)? {
                        Some(next) => pos = next,
                        None => return Err(truncated(path, el, i, pos, len)),
                    }
                    if is_vertex {
                        builder.push(&v);
                    }
                }
            }
        }
    }
    Ok(())
}

// ------------------------------------------------------------------------------------
// Ascii body

struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Number of the line at `pos` (1-based).
    line: usize,
}

impl<'a> Lines<'a> {
    /// The next non-blank line and its number.
    fn next_line(&mut self, path: &Path) -> Result<Option<(usize, &'a str)>> {
        while self.pos < self.bytes.len() {
            let rest = &self.bytes[self.pos..];
            let (raw, adv) = match rest.iter().position(|&b| b == b'\n') {
                Some(k) => (&rest[..k], k + 1),
                None => (rest, rest.len()),
            };
            let no = self.line;
            self.pos += adv;
            self.line += 1;
            let text = std::str::from_utf8(raw).map_err(|_| {
                Error::format(
                    path,
                    format!("line {no}"),
                    format!("not text: {}", show(raw)),
                )
            })?;
            if !text.trim_ascii().is_empty() {
                return Ok(Some((no, text)));
            }
        }
        Ok(None)
    }
}

fn read_ascii(
    bytes: &[u8],
    path: &Path,
    header: &Header,
    vi: usize,
    plan: &VertexPlan,
    builder: &mut Builder,
) -> Result<()> {
    let mut lines = Lines {
        bytes,
        pos: header.body_start,
        line: header.body_line,
    };
    for (ei, el) in header.elements.iter().enumerate() {
        if el.props.is_empty() {
            continue;
        }
        // Each record is a line of at least one character and a newline (the last one may
        // lack its newline). This bounds what the count may make us reserve.
        let per = 2;
        let remaining = bytes.len() - lines.pos;
        if (el.count as u128) * (per as u128) > remaining as u128 + 1 {
            return Err(too_many(path, el, per, lines.pos, remaining));
        }
        let is_vertex = ei == vi;
        if is_vertex {
            builder.reserve(el.count as usize);
        }
        let mut v = RawVertex::default();
        for i in 0..el.count {
            // A long text body answers a stop request (SIGINT) within a fraction of a second.
            if i % 65_536 == 0 {
                crate::interrupt::check("reading the cloud")?;
            }
            let Some((no, text)) = lines.next_line(path)? else {
                return Err(Error::format(
                    path,
                    format!("line {}", lines.line),
                    format!(
                        "truncated body: the file ends after {i} of {} `{}` records",
                        el.count, el.name
                    ),
                ));
            };
            let mut toks = text.split_ascii_whitespace();
            let mut value = |s: Scalar, what: &str| -> Result<f64> {
                let tok = toks.next().ok_or_else(|| {
                    Error::format(
                        path,
                        format!("line {no}"),
                        format!(
                            "too few values for `{}` record {i}: {what} is missing",
                            el.name
                        ),
                    )
                })?;
                s.parse(tok).ok_or_else(|| {
                    Error::format(
                        path,
                        format!("line {no}"),
                        format!("`{tok}` is not a valid {} for {what}", s.name()),
                    )
                })
            };
            for (k, p) in el.props.iter().enumerate() {
                match p.kind {
                    PropKind::Scalar(s) => {
                        let x = value(s, &format!("property `{}`", p.name))?;
                        if is_vertex {
                            v.set(plan.roles[k], x);
                        }
                    }
                    PropKind::List { count, item } => {
                        let n = value(count, &format!("the length of list `{}`", p.name))?;
                        if n < 0.0 {
                            return Err(Error::format(
                                path,
                                format!("line {no}"),
                                format!("list `{}` has negative length {n}", p.name),
                            ));
                        }
                        for j in 0..n as u64 {
                            value(item, &format!("item {j} of list `{}`", p.name))?;
                        }
                    }
                }
            }
            if toks.next().is_some() {
                return Err(Error::format(
                    path,
                    format!("line {no}"),
                    format!(
                        "too many values for `{}` record {i} ({} properties declared)",
                        el.name,
                        el.props.len()
                    ),
                ));
            }
            if is_vertex {
                builder.push(&v);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
#[path = "ply_tests.rs"]
pub(super) mod tests;
