//! PLY point-cloud reader: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Hand-written rather than built on `ply-rs-bw`: the reader checks every size against the
//! bytes actually present before it allocates (a header claiming 10^12 vertices is an
//! error, not an allocation), names the header line, text line or byte offset of every
//! fault, works on an in-memory byte slice ([`read_from_bytes`], for fuzzing), and decodes
//! fixed-size binary vertices straight from the file bytes with precomputed offsets.
//!
//! The scalar types, the header, the vertex plan and builder, and the binary and ascii
//! bodies each have a submodule; this file holds the entry points.
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

use crate::error::{Error, Result};
use crate::geom::{PointCloud, Pose};

mod ascii;
mod binary;
mod header;
mod scalar;
mod vertex;

use ascii::read_ascii;
use binary::read_binary;
use header::{parse_header, Encoding};
use vertex::{Builder, VertexPlan};

/// Beyond this distance (metres) of the file's origin, a first finite vertex makes the
/// reader choose a local origin even for `float` coordinates. Below 2^12 m an `f32` has
/// steps of 0.49 mm or finer.
pub(crate) const FAR_FROM_ORIGIN_M: f64 = 4096.0;

/// Parses the three numbers of a `comment origin X Y Z` line: finite metres.
pub(crate) fn parse_origin(text: &str) -> std::result::Result<[f64; 3], String> {
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

#[cfg(test)]
#[path = "ply_tests.rs"]
pub(super) mod tests;
