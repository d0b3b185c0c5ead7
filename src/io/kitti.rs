//! KITTI `.bin` lidar scans: little-endian `f32` x, y, z, intensity per point (16 bytes),
//! in the sensor frame.
//!
//! An all-zero x, y, z is how drivers that fill every beam slot (Ouster, the RELLIS-3D
//! scans) mark a missing return: the readers turn it into `[NaN; 3]`, keeping its slot and
//! its intensity. NaN or infinite coordinates become `[NaN; 3]` as well.

use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::PointCloud;

/// Bytes per point: four little-endian `f32`.
pub(crate) const POINT_BYTES: usize = 16;

/// Reads a KITTI scan as an unorganized cloud with intensity.
pub fn read(path: &Path) -> Result<PointCloud> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_from_bytes(&bytes, path)
}

/// Reads a KITTI scan from bytes in memory; `name` is used in error messages only.
pub fn read_from_bytes(bytes: &[u8], name: impl AsRef<Path>) -> Result<PointCloud> {
    let path = name.as_ref();
    if bytes.is_empty() {
        return Err(Error::format(path, "byte 0", "empty file (0 bytes)"));
    }
    if bytes.len() % POINT_BYTES != 0 {
        return Err(Error::format(
            path,
            format!("byte {}", bytes.len() - bytes.len() % POINT_BYTES),
            format!(
                "{} bytes is not a whole number of 16-byte KITTI points (x, y, z, intensity \
                 as f32); {} bytes are left over",
                bytes.len(),
                bytes.len() % POINT_BYTES
            ),
        ));
    }
    let f = |rec: &[u8], k: usize| f32::from_le_bytes([rec[k], rec[k + 1], rec[k + 2], rec[k + 3]]);
    let (mut xyz, mut intensity) = (Vec::new(), Vec::new());
    bytes
        .par_chunks_exact(POINT_BYTES)
        .map(|rec| {
            let p = [f(rec, 0), f(rec, 4), f(rec, 8)];
            let missing = p == [0.0; 3] || !p.iter().all(|c| c.is_finite());
            if missing {
                [f32::NAN; 3]
            } else {
                p
            }
        })
        .collect_into_vec(&mut xyz);
    bytes
        .par_chunks_exact(POINT_BYTES)
        .map(|rec| f(rec, 12))
        .collect_into_vec(&mut intensity);
    let mut cloud = PointCloud::unorganized(xyz);
    cloud.intensity = Some(intensity);
    Ok(cloud)
}

/// Reads a column-major KITTI scan of a spinning lidar (point `column * rings + ring`, as
/// the Ouster driver and RELLIS-3D write it) as an organized cloud of `rings` rows (row 0 =
/// ring 0, the top beam on an Ouster) × `n / rings` columns.
pub fn read_organized(path: &Path, rings: usize) -> Result<PointCloud> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_organized_from_bytes(&bytes, path, rings)
}

/// [`read_organized`] on bytes in memory; `name` is used in error messages only.
pub fn read_organized_from_bytes(
    bytes: &[u8],
    name: impl AsRef<Path>,
    rings: usize,
) -> Result<PointCloud> {
    let path = name.as_ref();
    let cloud = read_from_bytes(bytes, path)?;
    if rings == 0 || cloud.len() % rings != 0 {
        return Err(Error::format(
            path,
            "whole file",
            format!(
                "{} points cannot be split into {rings} rings of equal length",
                cloud.len()
            ),
        ));
    }
    super::organize_column_major(&cloud, rings)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn bytes_of(points: &[[f32; 4]]) -> Vec<u8> {
        points
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }

    const RELLIS_BIN: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/rellis3d-puddle-frame/000104.bin"
    );

    #[test]
    fn zero_and_non_finite_points_are_missing_returns() {
        let pts = [
            [1.0, 2.0, 3.0, 0.5],
            [0.0, -0.0, 0.0, 0.25],
            [f32::NAN, 1.0, 1.0, 0.0],
            [0.0, 0.0, 1.0, 7.0],
        ];
        let c = read_from_bytes(&bytes_of(&pts), "t.bin").unwrap();
        assert_eq!(c.len(), 4);
        assert_eq!(c.xyz[0], [1.0, 2.0, 3.0]);
        assert!(!c.is_valid(1) && !c.is_valid(2));
        assert_eq!(c.xyz[3], [0.0, 0.0, 1.0]);
        assert_eq!(c.intensity.unwrap(), vec![0.5, 0.25, 0.0, 7.0]);
    }

    #[test]
    fn a_length_that_is_not_a_multiple_of_16_names_the_byte_count() {
        let mut b = bytes_of(&[[1.0; 4]; 3]);
        b.truncate(45);
        match read_from_bytes(&b, "t.bin") {
            Err(Error::Format {
                location, message, ..
            }) => {
                assert_eq!(location, "byte 32");
                assert!(
                    message.contains("45 bytes") && message.contains("13 bytes"),
                    "{message}"
                );
            }
            other => panic!("{other:?}"),
        }
        assert!(read_from_bytes(&[], "t.bin")
            .unwrap_err()
            .to_string()
            .contains("empty"));
    }

    #[test]
    fn organized_reading_is_column_major() {
        // 3 rings × 4 columns; point (ring r, column c) at index c*3 + r.
        let pts: Vec<[f32; 4]> = (0..12)
            .map(|i| {
                let (c, r) = (i / 3, i % 3);
                [c as f32 + 1.0, r as f32, 1.0, (10 * r + c) as f32]
            })
            .collect();
        let cloud = read_organized_from_bytes(&bytes_of(&pts), "t.bin", 3).unwrap();
        assert_eq!((cloud.rows, cloud.cols), (3, 4));
        for r in 0..3 {
            for c in 0..4 {
                let i = cloud.index(r, c);
                assert_eq!(cloud.xyz[i], [c as f32 + 1.0, r as f32, 1.0]);
                assert_eq!(cloud.intensity.as_ref().unwrap()[i], (10 * r + c) as f32);
            }
        }
        assert!(read_organized_from_bytes(&bytes_of(&pts), "t.bin", 5).is_err());
        assert!(read_organized_from_bytes(&bytes_of(&pts), "t.bin", 0).is_err());
    }

    #[test]
    fn rellis_ouster_scan() {
        let Some(bin) = crate::io::test_data(RELLIS_BIN) else {
            return;
        };
        let c = read(bin).unwrap();
        assert_eq!(c.len(), 131_072);
        assert_eq!(c.len() - c.valid_count(), 53_364);
        let o = read_organized(bin, 64).unwrap();
        assert_eq!((o.rows, o.cols), (64, 2048));
        assert_eq!(o.valid_count(), c.valid_count());
        // Column 1000, ring 40 is file point 1000*64 + 40 (value read with Python's struct).
        assert_eq!(
            o.xyz[o.index(40, 1000)],
            [-12.577_561, -0.228_051_25, -0.903_043_15]
        );
        assert_eq!(
            o.intensity.as_ref().unwrap()[o.index(40, 1000)],
            0.003_265_430_7
        );
        // The top rings see the sky: far more missing returns than the bottom rings.
        let missing = |rows: std::ops::Range<usize>| {
            rows.flat_map(|r| (0..2048).map(move |c| (r, c)))
                .filter(|&(r, c)| !o.is_valid(o.index(r, c)))
                .count()
        };
        assert!(missing(0..8) > 10 * missing(56..64));
    }

    #[test]
    fn the_ply_and_the_bin_of_the_same_scan_agree() {
        let (Some(ply), Some(bin)) = (
            crate::io::test_data(crate::io::ply::tests::RELLIS_PLY),
            crate::io::test_data(RELLIS_BIN),
        ) else {
            return;
        };
        let ply = crate::io::read_ply(ply).unwrap();
        let ply = crate::io::organize_column_major(&ply, 64).unwrap();
        let bin = read_organized(bin, 64).unwrap();
        assert_eq!((ply.rows, ply.cols), (bin.rows, bin.cols));
        for i in 0..bin.len() {
            assert_eq!(ply.is_valid(i), bin.is_valid(i), "point {i}");
            if bin.is_valid(i) {
                assert_eq!(ply.xyz[i], bin.xyz[i], "point {i}");
            }
        }
    }

    proptest! {
        #[test]
        fn random_scans_round_trip(
            pts in prop::collection::vec(prop::array::uniform4(-500.0f32..500.0), 1..200),
        ) {
            let c = read_from_bytes(&bytes_of(&pts), "t.bin").unwrap();
            prop_assert_eq!(c.len(), pts.len());
            for (i, p) in pts.iter().enumerate() {
                prop_assert_eq!(c.xyz[i], [p[0], p[1], p[2]]);
                prop_assert_eq!(c.intensity.as_ref().unwrap()[i], p[3]);
            }
        }

        #[test]
        fn any_bytes_give_a_cloud_or_an_error(b in prop::collection::vec(any::<u8>(), 0..200)) {
            match read_from_bytes(&b, "t.bin") {
                Ok(c) => prop_assert_eq!(c.len() * 16, b.len()),
                Err(_) => prop_assert!(b.is_empty() || b.len() % 16 != 0),
            }
        }
    }
}
