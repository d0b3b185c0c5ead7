//! Reading `map.ply` (and `truth.ply`) back: the export contract's exact vertex schema,
//! binary little endian, with x y z all `float` or all `double`. Anything else is refused
//! with the line or byte where it differs.

use std::path::Path;

use crate::error::{Error, Result};
use crate::grid::CellKey;
use crate::hazard::{Class, Hazard, HazardMap, MapCell};

const PROPS: [&str; 11] = [
    "property float x",
    "property float y",
    "property float z",
    "property float elevation_std",
    "property float water",
    "property float depth",
    "property uchar class",
    "property uchar hazard",
    "property uchar red",
    "property uchar green",
    "property uchar blue",
];
/// Bytes of a vertex after x y z.
const REST: usize = 17;

/// Reads a contract `map.ply`. The resolution comes from its `comment resolution R` line
/// (required); cell keys are `floor(x / R)`, `floor(y / R)`. Coordinates are in the map
/// frame (`float` or `double`); a `comment origin X Y Z` line, which earlier versions wrote
/// for maps far from the origin with `float` coordinates relative to it, is still added
/// back.
pub fn read_map_ply(path: &Path) -> Result<HazardMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_map_ply(path, &bytes)
}

fn fmt(path: &Path, loc: impl Into<String>, msg: impl Into<String>) -> Error {
    Error::format(path, loc, msg)
}

/// Parses the bytes of a contract `map.ply` (`path` only names it in errors).
pub fn parse_map_ply(path: &Path, bytes: &[u8]) -> Result<HazardMap> {
    const END: &[u8] = b"end_header\n";
    let Some(end) = bytes.windows(END.len()).position(|w| w == END) else {
        return Err(fmt(path, "header", "no `end_header` line"));
    };
    let header =
        std::str::from_utf8(&bytes[..end]).map_err(|_| fmt(path, "header", "not UTF-8 text"))?;
    let h = MapHeader::parse(path, header)?;
    let count = h.count;
    let record = h.xyz_bytes() + REST;
    let body = &bytes[end + END.len()..];
    let need = count
        .checked_mul(record)
        .ok_or_else(|| fmt(path, "header", "vertex count overflows"))?;
    if body.len() != need {
        return Err(fmt(
            path,
            format!("byte {}", end + END.len()),
            format!(
                "{count} vertices need {need} bytes of data, the file has {}",
                body.len()
            ),
        ));
    }
    let mut cells = Vec::with_capacity(count);
    for (i, rec) in body.chunks_exact(record).enumerate() {
        cells.push(h.cell(path, i, rec)?);
    }
    Ok(HazardMap::new(h.resolution, cells))
}

/// What a contract `map.ply` header declares.
struct MapHeader {
    resolution: f64,
    /// `comment origin X Y Z` (zero without one): added back to every vertex.
    origin: [f64; 3],
    count: usize,
    /// x y z are `double` (else `float`).
    double: bool,
}

/// The header lines after `format`, as declared, before the contract is checked.
struct Declared<'a> {
    resolution: Option<f64>,
    origin: [f64; 3],
    count: Option<usize>,
    /// Property lines with their line numbers, in order.
    props: Vec<(usize, &'a str)>,
}

impl MapHeader {
    /// Parses the header text before `end_header`: `ply`, the binary little-endian
    /// format, then comments, the one `vertex` element and its properties, which must be
    /// the contract's.
    fn parse(path: &Path, header: &str) -> Result<Self> {
        let mut lines = header
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
        let mut next = |what: &str| {
            lines
                .next()
                .ok_or_else(|| fmt(path, "header", format!("ends before {what}")))
        };
        let (n, l) = next("`ply`")?;
        if l != "ply" {
            return Err(fmt(
                path,
                format!("header line {n}"),
                format!("{l:?} is not `ply`"),
            ));
        }
        let (n, l) = next("the format")?;
        if l != "format binary_little_endian 1.0" {
            return Err(fmt(
                path,
                format!("header line {n}"),
                format!("{l:?}: the map contract is `format binary_little_endian 1.0`"),
            ));
        }
        let declared = Declared::read(path, lines)?;
        let double = contract_props(path, &declared.props)?;
        let count = declared
            .count
            .ok_or_else(|| fmt(path, "header", "no `element vertex N`"))?;
        let resolution = declared
            .resolution
            .ok_or_else(|| fmt(path, "header", "no `comment resolution R` line"))?;
        Ok(MapHeader {
            resolution,
            origin: declared.origin,
            count,
            double,
        })
    }

    /// Bytes of x y z in a vertex.
    fn xyz_bytes(&self) -> usize {
        if self.double {
            24
        } else {
            12
        }
    }

    /// The cell of vertex `i`, whose record is `rec`.
    fn cell(&self, path: &Path, i: usize, rec: &[u8]) -> Result<MapCell> {
        let (double, origin, resolution) = (self.double, self.origin, self.resolution);
        let c = |j: usize| -> f64 {
            if double {
                f64::from_le_bytes(rec[8 * j..8 * j + 8].try_into().expect("8 bytes"))
            } else {
                f32::from_le_bytes(rec[4 * j..4 * j + 4].try_into().expect("4 bytes")) as f64
            }
        };
        let r = &rec[self.xyz_bytes()..];
        let f = |j: usize| f32::from_le_bytes([r[4 * j], r[4 * j + 1], r[4 * j + 2], r[4 * j + 3]]);
        let class = *Class::ALL.get(r[12] as usize).ok_or_else(|| {
            fmt(
                path,
                format!("vertex {i}"),
                format!("class {} is not a contract class (0..=5)", r[12]),
            )
        })?;
        let hazard = match r[13] {
            0 => Hazard::Free,
            1 => Hazard::ShallowWater,
            2 => Hazard::DeepWater,
            3 => Hazard::Obstacle,
            h => {
                return Err(fmt(
                    path,
                    format!("vertex {i}"),
                    format!("hazard {h} is not a contract hazard (0..=3)"),
                ))
            }
        };
        let (x, y) = (c(0) + origin[0], c(1) + origin[1]);
        if !(x.is_finite() && y.is_finite()) {
            return Err(fmt(path, format!("vertex {i}"), "x or y is not finite"));
        }
        Ok(MapCell {
            key: CellKey::new(
                (x / resolution).floor() as i64,
                (y / resolution).floor() as i64,
            ),
            x,
            y,
            z: c(2) + origin[2],
            elevation_std: f(0) as f64,
            water: f(1),
            depth: f(2),
            class,
            hazard,
            hits: 0,
            below: 0,
        })
    }
}

impl<'a> Declared<'a> {
    /// Reads the header lines after `format` (numbered): `comment resolution R`,
    /// `comment origin X Y Z` (other comments and `obj_info` are ignored), one
    /// `element vertex N`, and `property` lines; anything else is refused.
    fn read(path: &Path, lines: impl Iterator<Item = (usize, &'a str)>) -> Result<Self> {
        let mut resolution = None;
        let mut origin = [0.0f64; 3];
        let mut count = None;
        let mut props = Vec::new();
        for (n, l) in lines {
            if let Some(c) = l.strip_prefix("comment ") {
                if let Some(r) = c.strip_prefix("resolution ") {
                    let r: f64 = r.trim().parse().map_err(|_| {
                        fmt(
                            path,
                            format!("header line {n}"),
                            format!("bad resolution {r:?}"),
                        )
                    })?;
                    if !(r.is_finite() && r > 0.0) {
                        return Err(fmt(
                            path,
                            format!("header line {n}"),
                            format!("resolution {r} must be > 0"),
                        ));
                    }
                    resolution = Some(r);
                }
                if let Some(o) = c.strip_prefix("origin ") {
                    origin = super::ply::parse_origin(o)
                        .map_err(|m| fmt(path, format!("header line {n}"), m))?;
                }
                continue;
            }
            if let Some(e) = l.strip_prefix("element ") {
                let mut it = e.split_whitespace();
                if it.next() != Some("vertex") || count.is_some() {
                    return Err(fmt(
                        path,
                        format!("header line {n}"),
                        format!("{l:?}: the map contract has one element, `vertex`"),
                    ));
                }
                let c: usize = it.next().and_then(|c| c.parse().ok()).ok_or_else(|| {
                    fmt(
                        path,
                        format!("header line {n}"),
                        format!("bad vertex count in {l:?}"),
                    )
                })?;
                count = Some(c);
                continue;
            }
            if l.starts_with("property ") {
                props.push((n, l));
                continue;
            }
            if l.starts_with("obj_info") {
                continue;
            }
            return Err(fmt(
                path,
                format!("header line {n}"),
                format!("unexpected {l:?}"),
            ));
        }
        Ok(Declared {
            resolution,
            origin,
            count,
            props,
        })
    }
}

/// Checks the property lines against [`PROPS`], in order and nothing more; x y z may all
/// be `double` instead of `float`. Returns whether they are.
fn contract_props(path: &Path, props: &[(usize, &str)]) -> Result<bool> {
    let double = props
        .first()
        .is_some_and(|(_, l)| *l == "property double x");
    for (i, want) in PROPS.iter().enumerate() {
        let want_double = want.replace("float", "double");
        let want = if double && i < 3 { &want_double } else { *want };
        match props.get(i) {
            Some((_, got)) if *got == want => {}
            Some((n, got)) => {
                return Err(fmt(
                    path,
                    format!("header line {n}"),
                    format!("{got:?} where the map contract has {want:?}"),
                ))
            }
            None => return Err(fmt(path, "header", format!("missing {want:?}"))),
        }
    }
    if let Some((n, extra)) = props.get(PROPS.len()) {
        return Err(fmt(
            path,
            format!("header line {n}"),
            format!("{extra:?} is not in the map contract"),
        ));
    }
    Ok(double)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hazard::{Class, Hazard, HazardMap, MapCell};

    fn sample() -> HazardMap {
        let cell = |kx: i64, ky: i64, class, hazard, depth| MapCell {
            key: CellKey::new(kx, ky),
            x: (kx as f64 + 0.5) * 0.25,
            y: (ky as f64 + 0.5) * 0.25,
            z: -0.125 * kx as f64,
            elevation_std: 0.01,
            water: if class == Class::Water { 0.9 } else { 0.0 },
            depth,
            class,
            hazard,
            hits: 0,
            below: 0,
        };
        HazardMap {
            resolution: 0.25,
            cells: vec![
                cell(-3, 2, Class::Ground, Hazard::Free, 0.0),
                cell(4, -7, Class::Water, Hazard::DeepWater, f32::NAN),
                cell(5, 5, Class::Obstacle, Hazard::Obstacle, 0.0),
            ],
            bodies: Vec::new(),
        }
    }

    #[test]
    fn reads_back_what_write_map_ply_wrote() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        let m = sample();
        crate::io::write_map_ply(&p, &m).unwrap();
        let r = read_map_ply(&p).unwrap();
        assert_eq!(r.resolution, 0.25);
        assert_eq!(r.cells.len(), 3);
        for (a, b) in m.cells.iter().zip(&r.cells) {
            assert_eq!((a.key, a.class, a.hazard), (b.key, b.class, b.hazard));
            assert_eq!((a.x, a.y, a.z), (b.x, b.y, b.z));
            assert!(a.depth == b.depth || (a.depth.is_nan() && b.depth.is_nan()));
        }
    }

    #[test]
    fn refuses_what_is_not_the_contract() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        crate::io::write_map_ply(&p, &sample()).unwrap();
        let good = std::fs::read(&p).unwrap();
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        let swap = |from: &str, to: &str| {
            let s = text(&good);
            let i = s.find("end_header").unwrap();
            let mut out = s[..i].replacen(from, to, 1).into_bytes();
            out.extend_from_slice(&good[i..]);
            out
        };
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (
                swap("binary_little_endian", "ascii"),
                "binary_little_endian",
            ),
            (
                swap("property float depth", "property double depth"),
                "header line",
            ),
            (swap("comment resolution 0.25\n", ""), "resolution"),
            (swap("element vertex 3", "element vertex 4"), "need"),
            (good[..good.len() - 1].to_vec(), "need"),
            (b"ply\n".to_vec(), "end_header"),
        ];
        for (bytes, want) in cases {
            let e = parse_map_ply(&p, &bytes).unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
        let mut bad_class = good.clone();
        let n = bad_class.len();
        bad_class[n - 5] = 9;
        let e = parse_map_ply(&p, &bad_class).unwrap_err().to_string();
        assert!(e.contains("vertex 2") && e.contains("class 9"), "{e}");
    }
}
