//! The hazard map as a GeoTIFF (`map.tif`) that GDAL, QGIS and rasterio read: one float32
//! band per [`Layer`] (elevation, elevation σ, water probability, class, hazard, depth, in
//! that order, each named in the band description), NaN where a cell is unobserved (and
//! where a depth is unknown), declared as nodata.
//!
//! Georeference: pixel (0, 0) is the map's north-west corner, the cell of smallest x and
//! largest y; rows go south (−y), columns east (+x). `ModelTiepoint` ties the raster's
//! corner (PixelIsArea) to the map frame's coordinates and `ModelPixelScale` gives the
//! cell size, so the geotransform is `(x_min, res, 0, y_max, 0, −res)` in the map frame.
//! The map frame is taken to be the projected CRS itself (easting = x, northing = y): with
//! an EPSG code ([`GeoTiffOptions::epsg`]) the file names that CRS
//! (`ProjectedCSTypeGeoKey`); without one it has no CRS, only the geotransform.
//!
//! The file is a baseline little-endian TIFF written here rather than with the `tiff`
//! crate: the crate fixes the sample layout per image through a compile-time colour type
//! (no six-band float type), and a map needs only one uncompressed strip per band plus five
//! GeoTIFF/GDAL tags, which keeps the core library free of another dependency.

use std::io::Write;
use std::path::Path;

use super::raster::{Layer, MapRaster};
use crate::error::{Error, Result};
use crate::files::write_atomic;
use crate::hazard::HazardMap;

/// What the GeoTIFF says about its coordinates.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GeoTiffOptions {
    /// The EPSG code of the projected CRS the map frame is in (e.g. 32633, UTM 33N);
    /// `None`: no CRS is written.
    pub epsg: Option<u16>,
}

// TIFF field types.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const ASCII: u16 = 2;
const DOUBLE: u16 = 12;

/// One IFD entry: tag, type, count and its value bytes (little endian).
struct Entry {
    tag: u16,
    kind: u16,
    count: u32,
    bytes: Vec<u8>,
}

fn shorts(tag: u16, v: &[u16]) -> Entry {
    Entry {
        tag,
        kind: SHORT,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn longs(tag: u16, v: &[u32]) -> Entry {
    Entry {
        tag,
        kind: LONG,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn doubles(tag: u16, v: &[f64]) -> Entry {
    Entry {
        tag,
        kind: DOUBLE,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn ascii(tag: u16, s: &str) -> Entry {
    let mut bytes = s.as_bytes().to_vec();
    bytes.push(0);
    Entry {
        tag,
        kind: ASCII,
        count: bytes.len() as u32,
        bytes,
    }
}

/// The GDAL metadata XML naming each band.
fn band_names() -> String {
    let mut s = String::from("<GDALMetadata>\n");
    for (i, l) in Layer::ALL.iter().enumerate() {
        s.push_str(&format!(
            "  <Item name=\"DESCRIPTION\" sample=\"{i}\" role=\"description\">{}</Item>\n",
            l.name()
        ));
    }
    s.push_str("</GDALMetadata>\n");
    s
}

/// The bytes of the GeoTIFF of `map`.
pub(crate) fn encode_geotiff(map: &HazardMap, opts: &GeoTiffOptions) -> Result<Vec<u8>> {
    let raster = MapRaster::new(map)?;
    let (w, h) = (raster.nx, raster.ny);
    if w == 0 {
        return Err(Error::invalid(
            "GeoTIFF",
            "the map has no observed cell: an image needs at least one pixel",
        ));
    }
    let bands = Layer::ALL.len();
    let band_bytes = 4 * w * h;
    let data_end = 8 + bands * band_bytes;
    // Classic TIFF addresses 4 GiB; leave room for the tags after the pixels.
    if data_end as u64 + 65_536 > u32::MAX as u64 {
        return Err(Error::invalid(
            "GeoTIFF",
            format!("{w} × {h} cells × {bands} bands do not fit a classic TIFF (4 GiB)"),
        ));
    }
    let res = raster.resolution();
    let [x0, y0] = raster.corner_min();
    let y_max = y0 + h as f64 * res;

    let n = bands as u16;
    let mut entries = vec![
        longs(256, &[w as u32]),       // ImageWidth
        longs(257, &[h as u32]),       // ImageLength
        shorts(258, &vec![32; bands]), // BitsPerSample
        shorts(259, &[1]),             // Compression: none
        shorts(262, &[1]),             // Photometric: BlackIsZero
        longs(
            273, // StripOffsets: one strip per band
            &(0..bands)
                .map(|b| (8 + b * band_bytes) as u32)
                .collect::<Vec<_>>(),
        ),
        shorts(277, &[n]),                                // SamplesPerPixel
        longs(278, &[h as u32]),                          // RowsPerStrip
        longs(279, &vec![band_bytes as u32; bands]),      // StripByteCounts
        shorts(284, &[2]),                                // PlanarConfiguration: separate bands
        shorts(338, &vec![0; bands - 1]),                 // ExtraSamples: unspecified
        shorts(339, &vec![3; bands]),                     // SampleFormat: IEEE float
        doubles(33550, &[res, res, 0.0]),                 // ModelPixelScale
        doubles(33922, &[0.0, 0.0, 0.0, x0, y_max, 0.0]), // ModelTiepoint
        ascii(42112, &band_names()),                      // GDAL_METADATA
        ascii(42113, "nan"),                              // GDAL_NODATA
    ];
    if let Some(epsg) = opts.epsg {
        // GeoKeyDirectory 1.1.0: GTModelType projected, GTRasterType PixelIsArea,
        // ProjectedCSType = the EPSG code, ProjLinearUnits metre.
        entries.push(shorts(
            34735,
            &[
                1, 1, 0, 4, //
                1024, 0, 1, 1, //
                1025, 0, 1, 1, //
                3072, 0, 1, epsg, //
                3076, 0, 1, 9001,
            ],
        ));
    }
    entries.sort_by_key(|e| e.tag);

    let mut out = Vec::with_capacity(data_end + 4096);
    out.extend_from_slice(b"II*\0");
    out.extend_from_slice(&[0; 4]); // IFD offset, patched below
    for layer in Layer::ALL {
        // Rows from the north (largest y), columns from the west.
        for row in 0..h {
            let iy = h - 1 - row;
            for ix in 0..w {
                out.extend_from_slice(&raster.value(layer, ix, iy).to_le_bytes());
            }
        }
    }
    // Values longer than 4 bytes, word-aligned, then the IFD.
    let mut offsets = Vec::with_capacity(entries.len());
    for e in &entries {
        if e.bytes.len() > 4 {
            if out.len() % 2 == 1 {
                out.push(0);
            }
            offsets.push(Some(out.len() as u32));
            out.extend_from_slice(&e.bytes);
        } else {
            offsets.push(None);
        }
    }
    if out.len() % 2 == 1 {
        out.push(0);
    }
    let ifd = out.len() as u32;
    out[4..8].copy_from_slice(&ifd.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (e, off) in entries.iter().zip(&offsets) {
        out.extend_from_slice(&e.tag.to_le_bytes());
        out.extend_from_slice(&e.kind.to_le_bytes());
        out.extend_from_slice(&e.count.to_le_bytes());
        match off {
            Some(o) => out.extend_from_slice(&o.to_le_bytes()),
            None => {
                let mut v = [0u8; 4];
                v[..e.bytes.len()].copy_from_slice(&e.bytes);
                out.extend_from_slice(&v);
            }
        }
    }
    out.extend_from_slice(&[0; 4]); // no next IFD
    Ok(out)
}

/// Writes the GeoTIFF of `map` to `path`, atomically.
pub fn write_geotiff(path: &Path, map: &HazardMap, opts: &GeoTiffOptions) -> Result<()> {
    let bytes = encode_geotiff(map, opts)?;
    write_atomic(path, |w| w.write_all(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hazard::Hazard;
    use crate::io::raster::tests::cell;

    fn u16_at(b: &[u8], o: usize) -> u16 {
        u16::from_le_bytes([b[o], b[o + 1]])
    }
    fn u32_at(b: &[u8], o: usize) -> u32 {
        u32::from_le_bytes(b[o..o + 4].try_into().unwrap())
    }

    /// The IFD as tag → (type, count, value or offset).
    fn ifd(b: &[u8]) -> std::collections::BTreeMap<u16, (u16, u32, u32)> {
        let at = u32_at(b, 4) as usize;
        (0..u16_at(b, at) as usize)
            .map(|i| {
                let e = at + 2 + 12 * i;
                (
                    u16_at(b, e),
                    (u16_at(b, e + 2), u32_at(b, e + 4), u32_at(b, e + 8)),
                )
            })
            .collect()
    }

    #[test]
    fn bands_georeference_and_crs() {
        let map = HazardMap {
            resolution: 0.5,
            cells: vec![
                cell(4, -1, 1.0, Hazard::Free),
                cell(6, 0, 6.0, Hazard::DeepWater),
            ],
            bodies: Vec::new(),
        };
        let b = encode_geotiff(&map, &GeoTiffOptions { epsg: Some(32633) }).unwrap();
        assert_eq!(&b[..4], b"II*\0");
        let t = ifd(&b);
        let tags: Vec<u16> = t.keys().copied().collect();
        let mut sorted = tags.clone();
        sorted.sort();
        assert_eq!(tags, sorted, "IFD entries must be sorted by tag");
        assert_eq!((t[&256].2, t[&257].2, t[&277].2 & 0xffff), (3, 2, 6));
        // Elevation band: row 0 is the north row (key y 0): NaN, NaN, 6.
        let strip = t[&273].2 as usize; // offset of the offsets
        let band0 = u32_at(&b, strip) as usize;
        let px = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        assert!(px(band0).is_nan());
        assert_eq!(px(band0 + 8), 6.0);
        assert_eq!(px(band0 + 12), 1.0); // south row, west column
                                         // Tiepoint: raster corner at (x 2.0, y 0.5).
        let tp = t[&33922].2 as usize;
        let d = |i: usize| f64::from_le_bytes(b[tp + 8 * i..tp + 8 * i + 8].try_into().unwrap());
        assert_eq!((d(3), d(4)), (2.0, 0.5));
        let gk = t[&34735];
        assert_eq!(gk.1, 20);
        assert_eq!(u16_at(&b, gk.2 as usize + 2 * 15), 32633);
        // Without a code: no CRS.
        let b = encode_geotiff(&map, &GeoTiffOptions::default()).unwrap();
        assert!(!ifd(&b).contains_key(&34735));
    }

    #[test]
    fn an_empty_map_is_refused() {
        let map = HazardMap {
            resolution: 0.5,
            cells: Vec::new(),
            bodies: Vec::new(),
        };
        assert!(encode_geotiff(&map, &GeoTiffOptions::default()).is_err());
    }
}
